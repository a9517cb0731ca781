/* Unit tests of the six-step blocks (src/sixstep.c): commutation against the
 * machine's torque equation, sectors, chopper and gates, encoder tracking,
 * the speed PI against its design, encoder-loss detection. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include "hil_proto.h"
#include "sixstep.h"

#define DEG (SIXSTEP_PI / 180.0f)
#define M_PI 3.14159265358979323846 /* not in strict C99 <math.h> */

/* Torque per unit (3/2 p psi = 1) of a pair carrying 1 A in at `high`, out at
 * `low`, with the rotor at theta_e: eq. (6), psi x i, amplitude-invariant Clarke. */
static double pair_torque(sixstep_pair pair, double theta_e)
{
    double i[3] = {0.0, 0.0, 0.0};
    i[pair.high] = 1.0;
    i[pair.low] = -1.0;
    double i_alpha = i[0];
    double i_beta = (i[0] + 2.0 * i[1]) / sqrt(3.0);
    return cos(theta_e) * i_beta - sin(theta_e) * i_alpha;
}

/* The commuted pair's torque never falls below cos 30 deg of its best (the
 * current vector, 2/sqrt 3 long, stays within 30 deg of the q-axis), at every
 * angle, both directions: a wrong table entry or an offset sector fails here. */
static void commutation_keeps_current_within_30_deg_of_q_axis(void **state)
{
    (void)state;
    const double best = 2.0 / sqrt(3.0);
    for (int k = 0; k < 7200; ++k) {
        double theta = -4.0 * M_PI + k * (8.0 * M_PI / 7200.0);
        uint8_t s = sixstep_sector((float)theta);
        assert_in_range(s, 1, 6);
        double t_pos = pair_torque(sixstep_commutation(s, 0), theta);
        double t_neg = pair_torque(sixstep_commutation(s, 1), theta);
        if (t_pos < best * cos(30.0 * M_PI / 180.0) - 1e-3 || t_neg > -best * cos(30.0 * M_PI / 180.0) + 1e-3) {
            fail_msg("theta_e %.4f rad, sector %u: torque %+.3f / %+.3f", theta, s, t_pos, t_neg);
        }
    }
}

/* Sector edges at 30 + 60 n degrees, sector 2 centred on theta_e = 0. */
static void sectors_switch_where_hall_sensors_would(void **state)
{
    (void)state;
    assert_int_equal(sixstep_sector(0.0f), 2);
    assert_int_equal(sixstep_sector(29.9f * DEG), 2);
    assert_int_equal(sixstep_sector(30.1f * DEG), 3);
    assert_int_equal(sixstep_sector(-30.1f * DEG), 1);
    assert_int_equal(sixstep_sector(-90.1f * DEG), 6);
    assert_int_equal(sixstep_sector(150.1f * DEG), 5);
    assert_int_equal(sixstep_sector(210.1f * DEG), 6);
    assert_int_equal(sixstep_sector(359.99f * DEG), 2);
    assert_int_equal(sixstep_sector(4.0f * SIXSTEP_TWO_PI), 2);
    /* theta_e = 0: the q-axis is at 90 deg, b -> c puts the current there */
    sixstep_pair p = sixstep_commutation(2, 0);
    assert_int_equal(p.high, 1);
    assert_int_equal(p.low, 2);
}

static void gates_never_shoot_through(void **state)
{
    (void)state;
    for (uint8_t s = 1; s <= 6; ++s) {
        for (int neg = 0; neg <= 1; ++neg) {
            sixstep_pair p = sixstep_commutation(s, neg);
            assert_int_not_equal(p.high, p.low);
            uint8_t drive = sixstep_gates(p, SIXSTEP_DRIVE);
            uint8_t fw = sixstep_gates(p, SIXSTEP_FREEWHEEL);
            for (int leg = 0; leg < 3; ++leg) {
                assert_int_not_equal((drive >> (2 * leg)) & 3u, 3u);
            }
            assert_int_equal(drive, (HIL_GATE_A_HIGH << (2 * p.high)) | (HIL_GATE_A_LOW << (2 * p.low)));
            assert_int_equal(fw, HIL_GATE_A_LOW << (2 * p.low));
            assert_int_equal(sixstep_gates(p, SIXSTEP_OFF), 0);
        }
    }
    /* sector 2, positive torque: B high + C low */
    assert_int_equal(sixstep_gates(sixstep_commutation(2, 0), SIXSTEP_DRIVE), HIL_GATE_B_HIGH | HIL_GATE_C_LOW);
}

static void chopper_drives_below_reference_and_decays_above(void **state)
{
    (void)state;
    assert_int_equal(sixstep_chopper(1.0f, 2.0f, 1), SIXSTEP_DRIVE);
    assert_int_equal(sixstep_chopper(1.0f, -2.0f, 0), SIXSTEP_DRIVE); /* magnitude */
    assert_int_equal(sixstep_chopper(2.0f, 2.0f, 1), SIXSTEP_FREEWHEEL);
    assert_int_equal(sixstep_chopper(2.5f, 2.0f, 0), SIXSTEP_OFF); /* braking: never short the pair */
    assert_int_equal(sixstep_chopper(0.0f, 0.0f, 1), SIXSTEP_FREEWHEEL);
    float i[3] = {3.0f, -1.0f, -2.0f};
    sixstep_pair p = {0u, 2u};
    assert_float_equal(sixstep_pair_current(i, p), 2.5f, 1e-6f);
    /* (3 sqrt 3 / pi) p psi, Table 1 */
    assert_float_equal(sixstep_torque_constant(1u, 0.0928f), 0.15349f, 1e-4f);
}

static void electrical_angle_follows_pole_pairs(void **state)
{
    (void)state;
    assert_float_equal(sixstep_electrical_angle(0u, 4096u, 1u), 0.0f, 1e-7f);
    assert_float_equal(sixstep_electrical_angle(1024u, 4096u, 1u), 0.5f * SIXSTEP_PI, 1e-6f);
    assert_float_equal(sixstep_electrical_angle(1024u, 4096u, 2u), SIXSTEP_PI, 1e-6f);
    assert_float_equal(sixstep_electrical_angle(3072u, 4096u, 4u), 0.0f, 1e-7f);
    assert_float_equal(sixstep_electrical_angle(999u, 1000u, 3u), SIXSTEP_TWO_PI * 997.0f / 1000.0f, 1e-5f);
}

/* A shaft turning at w: the counter the plant would produce (docs/plant.md). */
static uint16_t counter_at(double theta_m, uint32_t cpr)
{
    long long c = (long long)floor(theta_m * cpr / (2.0 * M_PI));
    return (uint16_t)(c & 0xFFFF);
}

static void tracker_speed_and_position(double w, uint32_t cpr, double seconds)
{
    const float dt = 50e-6f;
    sixstep_tracker_gains g = sixstep_tracker_design(SIXSTEP_TRACKER_BANDWIDTH_HZ);
    sixstep_tracker tr;
    sixstep_tracker_reset(&tr);
    long n = (long)(seconds / dt);
    double worst_speed = 0.0;
    for (long k = 0; k <= n; ++k) {
        double theta = w * k * (double)dt;
        (void)sixstep_tracker_step(&g, &tr, counter_at(theta, cpr), cpr, dt);
        long long whole = (long long)floor(theta * cpr / (2.0 * M_PI));
        long long pos = ((whole % (long long)cpr) + cpr) % cpr;
        assert_int_equal(tr.position_counts, (uint32_t)pos);
        if (k * dt > 0.03) { /* after the tracking loop's transient (~5 / w_n) */
            double err = fabs(tr.speed_rad_s - w);
            worst_speed = err > worst_speed ? err : worst_speed;
        }
    }
    /* one count per period is 2 pi / (cpr T) = 30.7 rad/s raw; the 200 Hz loop
     * averages the quantisation down to well under 1 % of rated speed */
    if (worst_speed > 1.0) {
        fail_msg("speed error %.3f rad/s at %.1f rad/s, cpr %u", worst_speed, w, cpr);
    }
}

static void tracker_follows_speed_across_counter_wrap(void **state)
{
    (void)state;
    tracker_speed_and_position(314.159, 4096u, 0.2);   /* 3000 rpm, the 16-bit counter wraps 10 times */
    tracker_speed_and_position(-157.08, 4096u, 0.1);   /* backwards */
    tracker_speed_and_position(100.0, 1000u, 0.2);     /* counts per rev that do not divide 65536 */
}

static void pi_design_places_double_pole(void **state)
{
    (void)state;
    sixstep_pi_gains g = sixstep_speed_pi_design(8e-4f, 10.0f, 2.0f);
    float w = SIXSTEP_TWO_PI * 10.0f;
    assert_float_equal(g.kp_nm_per_rad_s, 2.0f * 8e-4f * w, 1e-6f);
    assert_float_equal(g.ki_nm_per_rad, 8e-4f * w * w, 1e-4f);
    /* closed loop J dw/dt = T on a step small enough not to saturate: the
     * response of (2 w s + w^2) / (s + w)^2, y = 1 - e^(-wt) (1 - wt) */
    sixstep_pi pi = {0.0f};
    const float dt = 50e-6f;
    double speed = 0.0;
    double worst = 0.0;
    for (int k = 1; k <= 4000; ++k) {
        float t_ref = sixstep_pi_step(&g, &pi, (float)(1.0 - speed), dt);
        speed += t_ref / 8e-4 * dt;
        double t = k * (double)dt;
        double y = 1.0 - exp(-w * t) * (1.0 - w * t);
        worst = fabs(speed - y) > worst ? fabs(speed - y) : worst;
    }
    if (worst > 0.01) {
        fail_msg("closed speed loop departs from the design by %.4f of the step", worst);
    }
}

static void pi_saturates_without_winding_up(void **state)
{
    (void)state;
    sixstep_pi_gains g = {0.1f, 3.0f, 2.0f};
    sixstep_pi pi = {0.0f};
    for (int k = 0; k < 10000; ++k) {
        assert_float_equal(sixstep_pi_step(&g, &pi, 100.0f, 50e-6f), 2.0f, 0.0f);
    }
    /* the integrator stopped where it was: the output leaves the limit as soon as the error reverses */
    assert_true(pi.integral_nm <= 2.0f);
    float out = sixstep_pi_step(&g, &pi, -25.0f, 50e-6f);
    assert_true(out < 0.0f);
    assert_float_equal(sixstep_pi_step(&g, &pi, -1000.0f, 50e-6f), -2.0f, 0.0f);
}

static void encoder_watch_trips_after_timeout(void **state)
{
    (void)state;
    /* turning at 150 rad/s, then the counter freezes: trip on the 201st silent period of a 200-period timeout */
    sixstep_encoder_watch w = {0u, 0u, 0.0f};
    assert_int_equal(sixstep_encoder_watch_step(&w, 5, 150.0f, 0.1f, 2.0f, 4096u, 200u, 50e-6f), 0);
    for (int k = 1; k <= 200; ++k) {
        assert_int_equal(sixstep_encoder_watch_step(&w, 0, 150.0f, 0.1f, 2.0f, 4096u, 200u, 50e-6f), 0);
    }
    assert_int_equal(sixstep_encoder_watch_step(&w, 0, 150.0f, 0.1f, 2.0f, 4096u, 200u, 50e-6f), 1);

    /* at standstill with little torque asked for, silence is normal */
    sixstep_encoder_watch still = {0u, 0u, 0.0f};
    for (int k = 0; k < 10000; ++k) {
        assert_int_equal(sixstep_encoder_watch_step(&still, 0, 0.0f, 0.2f, 2.0f, 4096u, 200u, 50e-6f), 0);
    }
    /* ... but not with half the torque limit asked for all along (stalled or blind) */
    int tripped_at = -1;
    for (int k = 1; k <= 400 && tripped_at < 0; ++k) {
        if (sixstep_encoder_watch_step(&still, 0, 0.0f, 1.0f, 2.0f, 4096u, 200u, 50e-6f)) {
            tripped_at = k;
        }
    }
    assert_int_equal(tripped_at, 201);
    /* timeout 0 disables the check */
    sixstep_encoder_watch off = {0u, 0u, 150.0f};
    for (int k = 0; k < 1000; ++k) {
        assert_int_equal(sixstep_encoder_watch_step(&off, 0, 150.0f, 2.0f, 2.0f, 4096u, 0u, 50e-6f), 0);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(commutation_keeps_current_within_30_deg_of_q_axis),
        cmocka_unit_test(sectors_switch_where_hall_sensors_would),
        cmocka_unit_test(gates_never_shoot_through),
        cmocka_unit_test(chopper_drives_below_reference_and_decays_above),
        cmocka_unit_test(electrical_angle_follows_pole_pairs),
        cmocka_unit_test(tracker_follows_speed_across_counter_wrap),
        cmocka_unit_test(pi_design_places_double_pole),
        cmocka_unit_test(pi_saturates_without_winding_up),
        cmocka_unit_test(encoder_watch_trips_after_timeout),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
