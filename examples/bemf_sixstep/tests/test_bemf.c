/* Unit tests of the sensorless six-step blocks (src/bemf.c): the commutation
 * table against the back-EMF waveforms, zero-cross detection on synthetic
 * comparator sequences (blanking, demagnetisation, direction, confirmation),
 * the 30-degree commutation delay and the speed on a synthetic rotor, the
 * open-loop ramp, the regulators against their design, and the protections. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "bemf.h"

#define M_PI 3.14159265358979323846 /* not in strict C99 <math.h> */
#define DEG (M_PI / 180.0)

/* Phase x's back-EMF per unit at theta_e, the SPEC 1.1 convention written out
 * here independently of the code: -sin(theta_e - x 120 deg), trapezoid with
 * 120-deg flat tops (same zero crossings, same sign). */
static double emf(int x, double theta_e)
{
    double s = -sin(theta_e - x * 120.0 * DEG);
    double t = s / sin(30.0 * DEG);
    return t > 1.0 ? 1.0 : (t < -1.0 ? -1.0 : t);
}

/* Every step drives current in at the phase whose EMF is highest and out at the
 * lowest over the whole step, and floats the third, whose EMF crosses zero in
 * the middle of the step in the direction the table says. */
static void steps_follow_the_back_emf(void **state)
{
    (void)state;
    for (uint8_t s = 1; s <= 6; ++s) {
        bemf_step st = bemf_commutation(s);
        assert_int_not_equal(st.high, st.low);
        assert_int_equal(st.high + st.low + st.floating, 3);
        double mid = (60.0 * s - 120.0) * DEG;
        for (int k = -29; k <= 29; ++k) {
            double th = mid + k * DEG;
            /* both driven phases on their flat tops: the line EMF is 2 */
            assert_true(emf(st.high, th) - emf(st.low, th) > 2.0 - 1e-9);
        }
        double before = emf(st.floating, mid - 5.0 * DEG);
        double after = emf(st.floating, mid + 5.0 * DEG);
        assert_true(fabs(emf(st.floating, mid)) < 1e-9);
        if (st.rising) {
            assert_true(before < 0.0 && after > 0.0);
        } else {
            assert_true(before > 0.0 && after < 0.0);
        }
        assert_int_equal(bemf_next_step(s), s == 6 ? 1 : s + 1);
    }
}

static const bemf_zc_config zc_cfg = {3u, 0.1f, 20u, 2u};

/* A floating terminal `v` volts from the neutral, clean or clamped to a rail. */
static bemf_terminal term(float v)
{
    bemf_terminal t = {v, 0u};
    return t;
}
static bemf_terminal railed(float v)
{
    bemf_terminal t = {v, 1u};
    return t;
}

/* Step 1: b floats, rising (0 -> 1). */
static void zero_cross_waits_for_blanking_and_demagnetisation(void **state)
{
    (void)state;
    bemf_zc_detector zc;
    bemf_zc_arm(&zc, bemf_commutation(1), 100u);
    bemf_instant at = {0u, 0.0f};
    /* blanking: the level after the cross (1) during ticks 100..102 is not looked at */
    for (uint32_t t = 100u; t < 103u; ++t) {
        assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x02u, 0.0f, term(5.0f), t, &at), 0);
    }
    /* demagnetisation: the floating phase still carries current, its terminal
     * sits on a rail and reads 1: no cross */
    assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x02u, -2.0f, term(12.0f), 103u, &at), 0);
    assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x02u, -0.5f, term(12.0f), 104u, &at), 0);
    /* current out at 105: the comparator needs one more sample (a period's average) */
    assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x02u, 0.0f, term(3.0f), 105u, &at), 0);
    assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x00u, 0.0f, term(-1.0f), 106u, &at), 0);
    /* other phases' bits do not matter */
    assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x05u, 0.01f, term(-0.8f), 107u, &at), 0);
    /* one sample at 1 then back to 0: a glitch, not confirmed */
    assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x02u, 0.0f, term(0.1f), 108u, &at), 0);
    assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x00u, 0.0f, term(-0.3f), 109u, &at), 0);
    /* the cross: 1 at 110 and 111, confirmed at 111; between samples 109 (-0.3 V)
     * and 110 (+0.1 V) the terminal crossed the neutral three quarters of the way */
    assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x02u, 0.0f, term(0.1f), 110u, &at), 0);
    assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x07u, 0.0f, term(0.5f), 111u, &at), 1);
    assert_int_equal(at.tick, 109u);
    assert_float_equal(at.frac, 0.75, 1e-6);
    /* once per step */
    assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x02u, 0.0f, term(0.9f), 112u, &at), 0);
}

/* Step 2: a floats, falling: only 1 -> 0 is its cross; a bit stuck at 1 never gives one;
 * a rotor already past its cross shows it on the first sample looked at. */
static void zero_cross_direction_and_stuck_comparator(void **state)
{
    (void)state;
    bemf_zc_detector zc;
    bemf_instant at = {0u, 0.0f};
    bemf_zc_arm(&zc, bemf_commutation(2), 0u);
    for (uint32_t t = 0u; t < 200u; ++t) {
        assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x01u, 0.0f, term(-1.0f), t, &at), 0);
    }
    bemf_zc_arm(&zc, bemf_commutation(2), 200u);
    int found = 0;
    for (uint32_t t = 200u; t < 220u && !found; ++t) {
        found = bemf_zc_feed(&zc_cfg, &zc, t < 210u ? 0x01u : 0x00u, 0.0f, term(t < 210u ? 0.2f : -0.2f), t, &at);
    }
    assert_true(found);
    assert_int_equal(at.tick, 209u);
    assert_float_equal(at.frac, 0.5, 1e-6);
    /* already past: 0 from the first sample looked at (tick 305: blanking 3, one quiet sample) */
    bemf_zc_arm(&zc, bemf_commutation(2), 300u);
    found = 0;
    uint32_t t = 300u;
    for (; t < 320u && !found; ++t) {
        found = bemf_zc_feed(&zc_cfg, &zc, 0x00u, 0.0f, term(-2.0f), t, &at);
    }
    assert_true(found);
    assert_int_equal(t - 1u, 305u); /* confirmed on the second sample */
    assert_int_equal(at.tick, 303u);
    assert_float_equal(at.frac, 1.0, 0.0); /* dated at its first sample, 304 */
    /* a clamped sample after the cross (the floating terminal on DC- through its
     * diode): dated by extrapolating the two clean samples before it; falling, so
     * +0.5 then +0.2 V: 0.2 / 0.3 of the period after the second */
    bemf_zc_arm(&zc, bemf_commutation(2), 340u);
    found = 0;
    for (t = 340u; t < 360u && !found; ++t) {
        bemf_terminal v = t < 348u ? term(1.0f) : t == 348u ? term(0.5f) : t == 349u ? term(0.2f) : railed(-3.0f);
        found = bemf_zc_feed(&zc_cfg, &zc, t < 350u ? 0x01u : 0x00u, 0.0f, v, t, &at);
    }
    assert_true(found);
    assert_int_equal(at.tick, 349u);
    assert_float_equal(at.frac, 0.2 / 0.3, 1e-5);
    /* rising (step 1, b) with the sample before clamped: backwards from the two
     * after it, +0.1 then +0.5 V: a quarter period before the first */
    bemf_zc_arm(&zc, bemf_commutation(1), 360u);
    found = 0;
    for (t = 360u; t < 380u && !found; ++t) {
        bemf_terminal v = t < 369u ? term(-1.0f) : t == 369u ? railed(-3.0f) : t == 370u ? term(0.1f) : term(0.5f);
        found = bemf_zc_feed(&zc_cfg, &zc, t < 370u ? 0x00u : 0x02u, 0.0f, v, t, &at);
    }
    assert_true(found);
    assert_int_equal(at.tick, 369u);
    assert_float_equal(at.frac, 0.75, 1e-5);
    /* NaN current is treated as current flowing: no cross before the demagnetisation limit */
    bemf_zc_arm(&zc, bemf_commutation(2), 400u);
    for (t = 400u; t < 420u; ++t) {
        assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x00u, NAN, term(-1.0f), t, &at), 0);
    }
    /* a floating phase still conducting at the limit (20 periods): a rotor
     * ahead of the step, its diode's rail read as the level after the cross */
    assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x00u, 1.0f, term(-1.0f), 420u, &at), 0);
    assert_int_equal(bemf_zc_feed(&zc_cfg, &zc, 0x00u, 1.0f, term(-1.0f), 421u, &at), 1);
    assert_int_equal(at.tick, 419u);
}

static void timing_commutes_half_an_interval_after_the_cross(void **state)
{
    (void)state;
    bemf_timing t;
    bemf_instant z0 = {1000u, 0.0f};
    bemf_timing_seed(&t, 20.0f, z0);
    /* cross at 1017.5: interval 17.5; due at 1017.5 + 8.75 - lag 0.7 = 1025.55 -> 1026 */
    bemf_instant z1 = {1017u, 0.5f};
    assert_int_equal(bemf_timing_zero_cross(&t, z1, 0.7f, 1018u), 1026u);
    assert_float_equal(bemf_timing_last_interval(&t), 17.5, 1e-5);
    /* speed: two 60-degree intervals (the seeded 20 and 17.5) are 120 electrical degrees */
    float w = bemf_timing_speed_rad_s(&t, 4u, 50e-6f);
    assert_float_equal(w, (2.0 * M_PI / 3.0) / (4.0 * (20.0 + 17.5) * 50e-6), 1e-2);
    bemf_instant z2 = {1035u, 0.0f};
    bemf_timing_zero_cross(&t, z2, 0.7f, 1036u);
    assert_float_equal(bemf_timing_speed_rad_s(&t, 4u, 50e-6f), (2.0 * M_PI / 3.0) / (4.0 * 35.0 * 50e-6), 1e-2);
    /* a cross found late: never due in the past */
    bemf_instant z3 = {2000u, 0.0f};
    assert_int_equal(bemf_timing_zero_cross(&t, z3, 0.7f, 2500u), 2500u);
}

/* The drive's configuration for the synthetic rotor: the shared BLDC. */
static bemf_config test_config(void)
{
    bemf_config c;
    memset(&c, 0, sizeof c);
    c.control_period_s = 50e-6f;
    c.pole_pairs = 4u;
    c.resistance_ohm = 0.25f;
    c.magnet_flux_wb = 0.006f;
    c.overcurrent_a = 20.0f;
    c.zc_timeout_periods = 400u;
    c.align_step = 6u;
    c.align_current_a = 3.0f;
    c.ramp_current_a = 3.0f;
    c.handover_zero_crosses = 6u;
    c.zc_lag_periods = 0.5f; /* the synthetic comparator: a period's average, no filter */
    c.blanking_fraction = 0.25f;
    c.min_blanking_periods = 2u;
    c.ramp.align_periods = 100u;
    c.ramp.ramp_start_rad_s = 10.0f;
    c.ramp.ramp_end_rad_s = 50.0f;
    c.ramp.ramp_periods = 400u;
    c.zc.blanking_periods = 2u;
    c.zc.demag_current_a = 0.1f;
    c.zc.demag_limit_periods = 20u;
    c.zc.confirm_samples = 1u;
    c.speed_gains = bemf_speed_pi_design(2e-5f, 10.0f, 0.24f);
    c.current_gains = bemf_current_pi_design(0.25f, 0.3e-3f, 500.0f);
    c.torque_constant_nm_per_a = bemf_torque_constant(4u, 0.006f);
    return c;
}

/* Comparator bits of a rotor at theta_e (a floating terminal above the neutral
 * while its EMF is positive), sampled at the middle of the period just ended:
 * what a period-averaged, lightly filtered comparator shows. */
static uint8_t comparators_at(double theta_e)
{
    uint8_t bits = 0u;
    for (int x = 0; x < 3; ++x) {
        if (emf(x, theta_e) > 0.0) {
            bits = (uint8_t)(bits | (1u << x));
        }
    }
    return bits;
}

/* A synthetic rotor at a constant 2000 rpm, in step with the drive (closed
 * loop from the start): every commutation falls 30 electrical degrees after
 * the floating phase's cross, i.e. on the step boundaries 60 s - 150 deg,
 * within half a period (a period is 4.8 electrical deg at this speed), and the
 * speed from the crosses is the rotor's. */
static void closed_loop_commutes_30_deg_after_each_cross(void **state)
{
    (void)state;
    bemf_config c = test_config();
    bemf_drive d;
    bemf_drive_enable(&d, &c);
    const double w_m = 2000.0 * 2.0 * M_PI / 60.0;
    const double w_e = 4.0 * w_m;
    const double T = 50e-6;
    /* start the drive in closed loop in step 2 (rotor in [330, 30) deg), as a hand-over would */
    double theta0 = -20.0 * DEG;
    d.mode = BEMF_CLOSED;
    d.step = 2u;
    bemf_zc_arm(&d.zc, bemf_commutation(2u), 0u);
    d.blanking_periods = 2u;
    float interval = (float)((M_PI / 3.0) / (w_e * T));
    bemf_instant z0 = {0u, 0.0f};
    bemf_timing_seed(&d.timing, interval, z0);
    d.last_zc_tick = 0u;
    d.commutate_tick = 1000000u;
    bemf_inputs in;
    memset(&in, 0, sizeof in);
    in.vdc_v = 24.0f;
    in.speed_ref_rad_s = (float)w_m;
    int commutations = 0;
    double worst = 0.0;
    uint8_t last_step = d.step;
    for (uint32_t k = 0u; k < 4000u; ++k) {
        double th_sample = theta0 + w_e * T * ((double)k - 0.5);
        in.comparators = comparators_at(th_sample);
        for (int x = 0; x < 3; ++x) {
            in.terminal_v[x] = 12.0f + (float)emf(x, th_sample); /* about mid-link: no rail */
        }
        bemf_output out = bemf_drive_step(&c, &d, &in);
        assert_int_equal(d.mode, BEMF_CLOSED);
        if (out.step != last_step) {
            /* the new step acts from t_k: its ideal start is 60 s - 150 deg */
            double th = theta0 + w_e * T * (double)k;
            double ideal = (60.0 * out.step - 150.0) * DEG;
            double err = remainder(th - ideal, 2.0 * M_PI) / DEG;
            if (k > 200u) { /* after the first turn (seeded intervals) */
                worst = fmax(worst, fabs(err));
                commutations++;
            }
            assert_int_equal(out.step, bemf_next_step(last_step));
            last_step = out.step;
        }
    }
    /* 4000 periods at 2000 rpm x 4 pole pairs: 26.7 electrical turns, 160 steps */
    assert_true(commutations > 150);
    /* the crosses are interpolated (the EMF is linear about its zero): the
     * commutation lands within half a period (2.4 deg) of 30 deg after the cross */
    assert_true(worst <= 2.4 + 0.3);
    assert_float_equal(d.speed_rad_s, w_m, 0.02 * w_m);
}

/* The whole start on a synthetic rotor that follows the field: aligned at
 * -30 deg, then turning with the ramp's commutation (so every step's cross
 * falls in its middle), then on at the end speed. The closed loop takes over at
 * the 6th consecutive step with a cross at the end speed, within
 * ramp end + (N - 1) .. (N + 1) steps of 60 deg, and then commutates on the
 * rotor's crosses: 30 deg after each, within a period (1.2 deg at 50 rad/s). */
static void start_hands_over_after_n_crosses_at_the_end_speed(void **state)
{
    (void)state;
    bemf_config c = test_config();
    /* longer than the hand-over's N + 1 steps at the end speed (7 x 105 periods) */
    c.zc_timeout_periods = 800u;
    bemf_drive d;
    bemf_drive_enable(&d, &c);
    bemf_inputs in;
    memset(&in, 0, sizeof in);
    in.vdc_v = 24.0f;
    in.speed_ref_rad_s = 50.0f; /* hold the hand-over speed */
    const double T = 50e-6, p = 4.0;
    double theta = -30.0 * DEG, theta_prev = theta;
    uint32_t handover = 0u, ramp_start = 0u;
    double worst = 0.0;
    int closed_commutations = 0;
    uint8_t last_step = 0u;
    for (uint32_t k = 0u; k < 6000u; ++k) {
        double th_sample = 0.5 * (theta + theta_prev); /* a period's average */
        in.comparators = comparators_at(th_sample);
        for (int x = 0; x < 3; ++x) {
            in.terminal_v[x] = 12.0f + (float)emf(x, th_sample);
        }
        uint8_t mode_before = d.mode;
        bemf_output out = bemf_drive_step(&c, &d, &in);
        assert_int_not_equal(d.mode, BEMF_TRIPPED);
        if (mode_before == BEMF_ALIGN && d.mode == BEMF_RAMP) {
            ramp_start = k;
        }
        if (mode_before != BEMF_CLOSED && d.mode == BEMF_CLOSED) {
            handover = k;
        }
        if (d.mode == BEMF_CLOSED && out.step != last_step && k > handover) {
            double ideal = (60.0 * out.step - 150.0) * DEG;
            worst = fmax(worst, fabs(remainder(theta - ideal, 2.0 * M_PI)) / DEG);
            closed_commutations++;
        }
        last_step = out.step;
        /* the rotor: still while aligned, then at the ramp's speed (the field's), then held */
        theta_prev = theta;
        if (d.mode != BEMF_ALIGN) {
            double w = d.mode == BEMF_RAMP ? d.ramp.speed_rad_s : c.ramp.ramp_end_rad_s;
            theta += p * w * T;
        }
    }
    assert_int_equal(ramp_start, c.ramp.align_periods);
    double t60 = (M_PI / 3.0) / (p * c.ramp.ramp_end_rad_s * T); /* periods */
    uint32_t ramp_end = ramp_start + c.ramp.ramp_periods;
    assert_true(handover >= ramp_end + (uint32_t)((c.handover_zero_crosses - 1u) * t60) - 2u);
    assert_true(handover <= ramp_end + (uint32_t)((c.handover_zero_crosses + 1u) * t60));
    assert_true(closed_commutations > 20);
    assert_true(worst <= 1.2 + 0.3);
}

/* Open loop: align on step 6 for align_periods, then the ramp starts in step 2
 * and commutates every 60 electrical degrees of its speed profile. */
static void start_aligns_then_ramps(void **state)
{
    (void)state;
    bemf_config c = test_config();
    bemf_drive d;
    bemf_drive_enable(&d, &c);
    bemf_inputs in;
    memset(&in, 0, sizeof in);
    in.vdc_v = 24.0f;
    in.comparators = 0u; /* a rotor that does not move: no crosses */
    for (uint32_t k = 0u; k < c.ramp.align_periods; ++k) {
        bemf_output out = bemf_drive_step(&c, &d, &in);
        assert_int_equal(out.step, 6u);
        assert_float_equal(out.duty, 2.0 * 0.25 * 3.0 / 24.0, 1e-6);
    }
    bemf_output out = bemf_drive_step(&c, &d, &in);
    assert_int_equal(d.mode, BEMF_RAMP);
    assert_int_equal(out.step, 2u);
    /* the angle the ramp turns: integral of p w(t) over the ramp, one step per 60 deg */
    uint32_t steps = 0u;
    uint8_t last = out.step;
    for (uint32_t k = 1u; k < c.ramp.ramp_periods; ++k) {
        out = bemf_drive_step(&c, &d, &in);
        if (out.step != last) {
            steps++;
            last = out.step;
        }
    }
    double angle = 4.0 * 0.5 * (10.0 + 50.0) * (400 * 50e-6); /* rad electrical */
    assert_int_equal(steps, (uint32_t)(angle / (M_PI / 3.0)));
    /* the ramp's voltage: 2 R I + the line EMF 2 p psi w at the end speed */
    assert_float_equal(out.duty, (2.0 * 0.25 * 3.0 + 2.0 * 4 * 0.006 * 50.0) / 24.0, 1e-3);
}

/* A locked rotor (no crosses) at the end speed: FAULT desync once the end
 * speed has been held for the timeout, and the bridge opens. */
static void start_without_crosses_trips_after_the_timeout(void **state)
{
    (void)state;
    bemf_config c = test_config();
    bemf_drive d;
    bemf_drive_enable(&d, &c);
    bemf_inputs in;
    memset(&in, 0, sizeof in);
    in.vdc_v = 24.0f;
    in.comparators = 0x05u; /* stuck bits: a and c high, b low */
    uint32_t k = 0u;
    bemf_output out = {1u, 0.0f};
    while (d.mode != BEMF_TRIPPED && k < 10000u) {
        out = bemf_drive_step(&c, &d, &in);
        k++;
    }
    assert_int_equal(d.trip, BEMF_TRIP_DESYNC);
    /* align 100 + ramp 400 + timeout 400 periods, tripping on the next */
    assert_int_equal(k, c.ramp.align_periods + 1u + c.ramp.ramp_periods + c.zc_timeout_periods + 1u);
    assert_int_equal(out.step, 0u);
    assert_float_equal(d.trip_value, (c.zc_timeout_periods + 1u) * 50e-6, 1e-6);
}

/* Closed loop: a comparator that stops switching leaves the drive waiting in
 * one step; FAULT desync timeout periods after the last cross. */
static void closed_loop_trip_from(uint32_t start)
{
    bemf_config c = test_config();
    bemf_drive d;
    bemf_drive_enable(&d, &c);
    d.mode = BEMF_CLOSED;
    d.step = 2u;
    d.tick = start;
    bemf_zc_arm(&d.zc, bemf_commutation(2u), start);
    bemf_instant z0 = {start, 0.0f};
    bemf_timing_seed(&d.timing, 20.0f, z0);
    d.last_zc_tick = start;
    d.blanking_periods = 2u;
    bemf_inputs in;
    memset(&in, 0, sizeof in);
    in.vdc_v = 24.0f;
    in.comparators = 0x01u; /* a (falling in step 2) stuck high */
    uint32_t k = 0u;
    while (d.mode != BEMF_TRIPPED && k < 10000u) {
        bemf_output out = bemf_drive_step(&c, &d, &in);
        /* driving step 2 until two intervals (20 periods) plus the blanking
         * (min 2) are over without a cross, then coasting with the bridge open */
        assert_int_equal(out.step, k <= 2u * 20u + 2u ? 2u : 0u);
        k++;
    }
    assert_int_equal(d.trip, BEMF_TRIP_DESYNC);
    assert_int_equal(k, c.zc_timeout_periods + 2u); /* tick timeout + 1 is the first beyond */
}

static void closed_loop_without_crosses_trips_after_the_timeout(void **state)
{
    (void)state;
    closed_loop_trip_from(0u);
    /* the same across the period counter's wrap (2.5 days at 50 us) */
    closed_loop_trip_from(UINT32_MAX - 100u);
}

static void overcurrent_and_nan_trip(void **state)
{
    (void)state;
    bemf_config c = test_config();
    bemf_drive d;
    bemf_inputs in;
    memset(&in, 0, sizeof in);
    in.vdc_v = 24.0f;
    bemf_drive_enable(&d, &c);
    in.phase_current_a[2] = -20.5f;
    bemf_output out = bemf_drive_step(&c, &d, &in);
    assert_int_equal(d.trip, BEMF_TRIP_OVERCURRENT);
    assert_float_equal(d.trip_value, 20.5, 1e-6);
    assert_int_equal(out.step, 0u);
    bemf_drive_enable(&d, &c);
    in.phase_current_a[2] = 19.9f;
    bemf_drive_step(&c, &d, &in);
    assert_int_equal(d.mode, BEMF_ALIGN);
    in.phase_current_a[1] = NAN;
    bemf_drive_step(&c, &d, &in);
    assert_int_equal(d.trip, BEMF_TRIP_OVERCURRENT);
    bemf_drive_enable(&d, &c);
    in.phase_current_a[1] = 0.0f;
    in.overcurrent_flag = 1u;
    bemf_drive_step(&c, &d, &in);
    assert_int_equal(d.trip, BEMF_TRIP_OVERCURRENT);
}

/* The current PI on the pair model 2 L di/dt = v - 2 R i - e: a step of the
 * reference follows w_c / (s + w_c) (no overshoot; 63 % after one time
 * constant), and an error in the back-EMF estimate is integrated away. */
static void current_pi_follows_its_design(void **state)
{
    (void)state;
    const float R = 0.25f, L = 0.3e-3f, dt = 50e-6f, e = 10.0f;
    const double wc = 2.0 * M_PI * 500.0;
    bemf_current_pi_gains g = bemf_current_pi_design(R, L, 500.0f);
    assert_float_equal(g.kp_v_per_a, 2.0 * L * wc, 1e-4);
    bemf_current_pi pi = {0.0f, 0.0f, 0u};
    double i = 0.0, peak = 0.0;
    for (int k = 0; k < 400; ++k) {
        float v = bemf_current_pi_step(&g, &pi, 4.0f, (float)i, e, 24.0f, dt);
        assert_true(v >= 0.0f && v <= 24.0f);
        for (int j = 0; j < 50; ++j) {
            i += (v - 2.0 * R * i - e) / (2.0 * L) * (dt / 50.0);
        }
        peak = fmax(peak, i);
        if (k == (int)(1.0 / (wc * dt))) { /* one time constant (6.4 periods): 1 - 1/e */
            assert_float_equal(i, 4.0 * (1.0 - exp(-(k + 1) * dt * wc)), 0.4);
        }
    }
    assert_true(peak <= 4.0 * 1.01);
    assert_float_equal(i, 4.0, 0.01);
    /* the back-EMF estimate steps by 1 V (a speed update): the voltage does not jump */
    bemf_current_pi held = pi;
    float v0 = bemf_current_pi_step(&g, &held, 4.0f, (float)i, e, 24.0f, dt);
    held = pi;
    float v1 = bemf_current_pi_step(&g, &held, 4.0f, (float)i, e + 1.0f, 24.0f, dt);
    assert_float_equal(v1, v0, 1e-4);
    /* the back-EMF estimate is 1 V off: the integrator removes it */
    for (int k = 0; k < 400; ++k) {
        float v = bemf_current_pi_step(&g, &pi, 4.0f, (float)i, e - 1.0f, 24.0f, dt);
        for (int j = 0; j < 50; ++j) {
            i += (v - 2.0 * R * i - e) / (2.0 * L) * (dt / 50.0);
        }
    }
    assert_float_equal(i, 4.0, 0.05);
    bemf_speed_pi_gains s = bemf_speed_pi_design(2e-5f, 10.0f, 0.24f);
    assert_float_equal(s.kp_nm_per_rad_s, 2.0 * 2e-5 * 2.0 * M_PI * 10.0, 1e-7);
    assert_float_equal(s.ki_nm_per_rad, 2e-5 * pow(2.0 * M_PI * 10.0, 2), 1e-6);
    bemf_speed_pi sp = {0.0f};
    assert_float_equal(bemf_speed_pi_step(&s, &sp, 1000.0f, 50e-6f), 0.24, 1e-6);
    assert_float_equal(sp.integral_nm, 0.0, 1e-9); /* held while saturated */
    assert_float_equal(bemf_torque_constant(4u, 0.006f), 0.048, 1e-6);
}

/* Commutating 1 (a -> c) to 2 (b -> c) with a's current still decaying: the
 * torque is 2 E i_c, so the regulated current is c's, not the mean of b's and c's. */
static void pair_current_is_the_shared_phase_through_a_commutation(void **state)
{
    (void)state;
    const float steady[3] = {3.0f, 0.0f, -3.0f};
    assert_float_equal(bemf_pair_current(1u, steady), 3.0, 1e-6);
    const float commutating[3] = {2.0f, 1.0f, -3.0f};
    assert_float_equal(bemf_pair_current(2u, commutating), 3.0, 1e-6);
    /* 2 (b -> c) to 3 (b -> a): b is shared */
    const float low_changing[3] = {-1.0f, 3.0f, -2.0f};
    assert_float_equal(bemf_pair_current(3u, low_changing), 3.0, 1e-6);
    /* braking: current out at `high`, in at `low` */
    const float braking[3] = {-2.5f, 0.0f, 2.5f};
    assert_float_equal(bemf_pair_current(1u, braking), -2.5, 1e-6);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(steps_follow_the_back_emf),
        cmocka_unit_test(zero_cross_waits_for_blanking_and_demagnetisation),
        cmocka_unit_test(zero_cross_direction_and_stuck_comparator),
        cmocka_unit_test(timing_commutes_half_an_interval_after_the_cross),
        cmocka_unit_test(closed_loop_commutes_30_deg_after_each_cross),
        cmocka_unit_test(start_aligns_then_ramps),
        cmocka_unit_test(start_hands_over_after_n_crosses_at_the_end_speed),
        cmocka_unit_test(start_without_crosses_trips_after_the_timeout),
        cmocka_unit_test(closed_loop_without_crosses_trips_after_the_timeout),
        cmocka_unit_test(overcurrent_and_nan_trip),
        cmocka_unit_test(current_pi_follows_its_design),
        cmocka_unit_test(pair_current_is_the_shared_phase_through_a_commutation),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
