/* Unit tests of the Hall six-step blocks (src/hall_sixstep.c): Hall decoding
 * against SPEC.md 1.1's sensor convention, commutation against a trapezoidal
 * back-EMF computed here, Hall speed, the current regulator against the pair's
 * exact RL response, legs, the speed PI, the Hall and stall watches. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include "hall_sixstep.h"
#include "hil_proto.h"

#define M_PI 3.14159265358979323846 /* not in strict C99 <math.h> */
#define DEG (M_PI / 180.0)

static double wrap_pi(double x)
{
    while (x > M_PI) x -= 2.0 * M_PI;
    while (x <= -M_PI) x += 2.0 * M_PI;
    return x;
}

/* SPEC.md 1.1: Hall x reads 1 while cos(theta_e - x 120 deg - error_x) > 0. */
static uint8_t hall_word_at(double theta_e, const double error_rad[3])
{
    uint8_t word = 0u;
    for (int x = 0; x < 3; ++x) {
        if (cos(theta_e - x * 120.0 * DEG - error_rad[x]) > 0.0) {
            word = (uint8_t)(word | (1u << x));
        }
    }
    return word;
}

/* Phase-x back-EMF per unit (peak 1) with a 120-degree flat top: the zero
 * crossings and peaks of -sin(theta_e - x 120 deg), linear in between. */
static double trapezoid_emf(double theta_e, int x)
{
    double s = wrap_pi(theta_e - x * 120.0 * DEG);
    double ramp = (fabs(s) <= M_PI / 2.0) ? s : ((s > 0.0 ? M_PI : -M_PI) - s);
    double e = ramp * 6.0 / M_PI;
    return -(e > 1.0 ? 1.0 : (e < -1.0 ? -1.0 : e));
}

static const double no_error[3] = {0.0, 0.0, 0.0};

/* Every legal word maps to the sector whose span holds the angles that give it;
 * the sectors count up with positive rotation; 0 and 7 are illegal. */
static void hall_words_give_the_sector_of_their_angle(void **state)
{
    (void)state;
    for (int k = 0; k < 3600; ++k) {
        double theta = -2.0 * M_PI + k * (4.0 * M_PI / 3600.0) + 0.05 * DEG; /* never on an edge */
        uint8_t s = hs_sector_of_hall(hall_word_at(theta, no_error));
        assert_in_range(s, 1, 6);
        /* sector s spans theta_e in [60 s - 150, 60 s - 90) degrees */
        double centre = (60.0 * s - 120.0) * DEG;
        if (fabs(wrap_pi(theta - centre)) > 30.0 * DEG + 1e-9) {
            fail_msg("theta_e %.2f deg: word %u gave sector %u", theta / DEG, hall_word_at(theta, no_error), s);
        }
    }
    /* the SPEC's sequence for positive rotation, 1, 3, 2, 6, 4, 5, counts sectors up */
    static const uint8_t sequence[6] = {1u, 3u, 2u, 6u, 4u, 5u};
    for (int i = 0; i < 6; ++i) {
        uint8_t now = hs_sector_of_hall(sequence[i]);
        uint8_t next = hs_sector_of_hall(sequence[(i + 1) % 6]);
        assert_int_equal(next, now % 6u + 1u);
    }
    assert_int_equal(hs_sector_of_hall(1u), 2u); /* (-30, 30) degrees */
    assert_int_equal(hs_sector_of_hall(0u), 0u);
    assert_int_equal(hs_sector_of_hall(7u), 0u);
    assert_int_equal(hs_sector_of_hall(0xF8u | 7u), 0u); /* reserved bits ignored */
    assert_int_equal(hs_sector_of_hall(0xF8u | 1u), 2u);
}

/* Inside every sector the commuted pair sits on the flat tops, +E in and -E
 * out: line EMF 2E, the most any pair gives, so 2 p psi per ampere. */
static void commutation_puts_the_pair_on_the_flat_tops(void **state)
{
    (void)state;
    for (int k = 0; k < 7200; ++k) {
        double theta = -2.0 * M_PI + k * (4.0 * M_PI / 7200.0) + 0.025 * DEG;
        uint8_t s = hs_sector_of_hall(hall_word_at(theta, no_error));
        hs_pair p = hs_commutation(s);
        assert_int_not_equal(p.high, p.low);
        double line = trapezoid_emf(theta, p.high) - trapezoid_emf(theta, p.low);
        if (fabs(line - 2.0) > 1e-9) {
            fail_msg("theta_e %.3f deg, sector %u: line EMF %.4f of 2", theta / DEG, s, line);
        }
    }
    /* theta_e = 0: b -> c */
    hs_pair p = hs_commutation(2u);
    assert_int_equal(p.high, 1);
    assert_int_equal(p.low, 2);
    /* in a sector: the pair's current; the floating phase carries none */
    float steady[3] = {0.0f, 2.0f, -2.0f};
    assert_float_equal(hs_pair_current(steady, hs_commutation(2u)), 2.0f, 1e-6f);
    assert_float_equal(hs_pair_current(steady, hs_commutation(5u)), -2.0f, 1e-6f); /* c -> b: braking */
    /* just after sector 2 -> 3 (b -> c becomes b -> a): c still decaying, a rising; the
     * torque is 2 E i_b with e_c still -E, so the common phase b's current counts */
    float commutating[3] = {-0.5f, 2.0f, -1.5f};
    assert_float_equal(hs_pair_current(commutating, hs_commutation(3u)), 2.0f, 1e-6f);
    assert_float_equal(hs_torque_constant(4u, 0.006f), 0.048f, 1e-7f);
}

/* A rotor at constant speed through the SPEC's Hall sensors: the estimate after
 * the second edge is one edge angle over the whole periods between edges. */
static void hall_speed(double w_mech, const double error_rad[3], double tolerance_rel, double tolerance_window)
{
    const float dt = 50e-6f;
    const uint32_t p = 4u;
    hs_hall_speed s;
    hs_hall_speed_reset(&s);
    int edges = 0;
    double worst = 0.0;
    for (long k = 0; k < 20000; ++k) {
        double theta_e = p * (0.3 + w_mech * k * (double)dt);
        int edge = hs_hall_speed_step(&s, hs_sector_of_hall(hall_word_at(theta_e, error_rad)), p, dt);
        if (edge != 0) {
            assert_int_equal(edge, w_mech > 0.0 ? 1 : -1);
            edges++;
        }
        if (edges >= 2) {
            double err = fabs(s.speed_rad_s - w_mech) / fabs(w_mech);
            worst = err > worst ? err : worst;
            /* three whole intervals: half an electrical turn, edges of one sensor at both ends */
            if (edges >= 4 && err > tolerance_window) {
                fail_msg("speed %.1f rad/s, %d edges: relative error %.4f > %.4f", w_mech, edges, err,
                         tolerance_window);
            }
        } else {
            assert_float_equal(s.speed_rad_s, 0.0f, 0.0f); /* no whole interval yet */
        }
    }
    assert_true(edges > 10);
    if (worst > tolerance_rel) {
        fail_msg("speed %.1f rad/s: worst relative error %.4f > %.4f", w_mech, worst, tolerance_rel);
    }
}

static void hall_speed_from_edge_intervals(void **state)
{
    (void)state;
    /* 2000 rpm: 60 deg_e = 1.25 ms = 25 periods; one period of quantisation is 4 % of an
     * interval, 1.3 % of three */
    hall_speed(209.44, no_error, 1.0 / 24.0, 1.0 / 74.0);
    hall_speed(-209.44, no_error, 1.0 / 24.0, 1.0 / 74.0);
    /* 500 rpm: 100 periods an edge, 1 % */
    hall_speed(52.36, no_error, 1.0 / 99.0, 1.0 / 299.0);
    /* sensors 3 and 2 degrees off: one interval may be 55 degrees (9 %); three span
     * 180 degrees between two edges of one sensor, exact up to the quantisation */
    const double off[3] = {0.0, 3.0 * DEG, -2.0 * DEG};
    hall_speed(52.36, off, 5.0 / 55.0 + 1.0 / 99.0, 1.0 / 299.0);
    hall_speed(-52.36, off, 5.0 / 55.0 + 1.0 / 99.0, 1.0 / 299.0);
}

static void hall_speed_falls_when_edges_stop(void **state)
{
    (void)state;
    const float dt = 50e-6f;
    hs_hall_speed s;
    hs_hall_speed_reset(&s);
    /* edges every 10 periods, sectors 1, 2, 3: 60 deg_e / 4 pole pairs per 0.5 ms */
    uint8_t sector = 1u;
    for (int k = 0; k < 30; ++k) {
        if (k % 10 == 0) {
            sector = (uint8_t)(sector % 6u + 1u);
        }
        (void)hs_hall_speed_step(&s, sector, 4u, dt);
    }
    float edge_angle = (float)(M_PI / 3.0 / 4.0);
    assert_float_equal(s.speed_rad_s, edge_angle / (10.0f * dt), 1e-3f);
    assert_int_equal(s.intervals, 1u); /* the first edge (k = 10) opened the window */
    /* then nothing: the estimate is capped by edge_angle / elapsed, then 0 */
    for (int k = 0; k < 100; ++k) {
        (void)hs_hall_speed_step(&s, sector, 4u, dt);
    }
    uint32_t elapsed = s.periods_since_edge;
    assert_float_equal(s.speed_rad_s, edge_angle / ((float)elapsed * dt), 1e-3f);
    for (int k = 0; k < 2000; ++k) {
        (void)hs_hall_speed_step(&s, 0u, 4u, dt); /* illegal words do not move it either */
    }
    assert_float_equal(s.speed_rad_s, 0.0f, 0.0f);
    /* a reversal inside a sector is no interval */
    int edge = hs_hall_speed_step(&s, (uint8_t)(sector == 1u ? 6u : sector - 1u), 4u, dt);
    assert_int_equal(edge, -1);
    assert_float_equal(s.speed_rad_s, 0.0f, 0.0f);
}

/* The pair (2R, 2L, line EMF) under the regulator's voltage held over each
 * period, integrated exactly: the current answers a step like the first-order
 * design, 1 - exp(-w_c t), with no steady-state error, at standstill and at
 * speed (the EMF feed-forward). */
static void current_regulator_follows_its_design(double speed_rad_s)
{
    const float dt = 50e-6f;
    const double r = 0.25, l = 0.3e-3, psi = 0.006;
    const uint32_t p = 4u;
    hs_current_gains g = hs_current_design((float)r, (float)l, p, (float)psi, 1000.0f);
    assert_float_equal(g.kp_v_per_a, 2.0f * 0.3e-3f * 2.0f * (float)M_PI * 1000.0f, 1e-5f);
    assert_float_equal(g.ki_v_per_a_s, 2.0f * 0.25f * 2.0f * (float)M_PI * 1000.0f, 1e-2f);
    hs_current_pi pi = {0.0f};
    double i = 0.0, worst = 0.0;
    const double wc = 2.0 * M_PI * 1000.0, tau = l / r, emf = 2.0 * p * psi * speed_rad_s;
    for (int k = 0; k < 400; ++k) {
        double t = k * (double)dt;
        if (k > 0) {
            double y = 1.0 - exp(-wc * t);
            /* a sampled loop runs up to a period behind its continuous design */
            double y_late = 1.0 - exp(-wc * (t - (double)dt));
            double err = i / 4.0 < y_late ? y_late - i / 4.0 : (i / 4.0 > y ? i / 4.0 - y : 0.0);
            worst = err > worst ? err : worst;
        }
        float v = hs_current_step(&g, &pi, 4.0f, (float)i, (float)speed_rad_s, 24.0f, dt);
        assert_true(fabsf(v) <= 24.0f);
        double i_final = (v - emf) / (2.0 * r);
        i = i_final + (i - i_final) * exp(-(double)dt / tau);
    }
    if (worst > 0.08) {
        fail_msg("speed %.0f rad/s: current departs from the design by %.3f of the step", speed_rad_s, worst);
    }
    assert_true(fabs(i - 4.0) < 0.01);
}

static void current_regulator_step_response(void **state)
{
    (void)state;
    current_regulator_follows_its_design(0.0);
    current_regulator_follows_its_design(200.0); /* line EMF 9.6 V */
}

static void current_regulator_limits_to_the_link_without_winding_up(void **state)
{
    (void)state;
    hs_current_gains g = hs_current_design(0.25f, 0.3e-3f, 4u, 0.006f, 1000.0f);
    hs_current_pi pi = {0.0f};
    for (int k = 0; k < 1000; ++k) {
        assert_float_equal(hs_current_step(&g, &pi, 100.0f, 0.0f, 0.0f, 24.0f, 50e-6f), 24.0f, 0.0f);
    }
    assert_true(pi.integral_v <= 48.0f);
    /* the error reverses: the output leaves the limit at once */
    assert_true(hs_current_step(&g, &pi, 0.0f, 10.0f, 0.0f, 24.0f, 50e-6f) < 24.0f);
    assert_float_equal(hs_current_step(&g, &pi, -100.0f, 0.0f, 0.0f, 24.0f, 50e-6f), -24.0f, 0.0f);
}

static void legs_switch_the_pair_and_float_the_third(void **state)
{
    (void)state;
    hs_pair bc = {1u, 2u};
    hs_legs legs = hs_legs_for_pair_voltage(bc, 6.0f, 24.0f);
    assert_int_equal(legs.leg_enable, HIL_LEG_B | HIL_LEG_C);
    assert_float_equal(legs.duty[1], 0.25f, 1e-7f);
    assert_float_equal(legs.duty[2], 0.0f, 0.0f);
    legs = hs_legs_for_pair_voltage(bc, -12.0f, 24.0f); /* reversed: c PWM'd, b low */
    assert_int_equal(legs.leg_enable, HIL_LEG_B | HIL_LEG_C);
    assert_float_equal(legs.duty[1], 0.0f, 0.0f);
    assert_float_equal(legs.duty[2], 0.5f, 1e-7f);
    hs_pair ab = {0u, 1u};
    legs = hs_legs_for_pair_voltage(ab, 24.0f, 24.0f);
    assert_int_equal(legs.leg_enable, HIL_LEG_A | HIL_LEG_B);
    assert_float_equal(legs.duty[0], 1.0f, 0.0f);
    /* nothing it cannot do: more than the link, NaN, no link */
    assert_int_equal(hs_legs_for_pair_voltage(ab, 24.5f, 24.0f).leg_enable, 0u);
    assert_int_equal(hs_legs_for_pair_voltage(ab, NAN, 24.0f).leg_enable, 0u);
    assert_int_equal(hs_legs_for_pair_voltage(ab, 0.0f, 0.0f).leg_enable, 0u);
    assert_int_equal(hs_legs_for_pair_voltage(ab, 1.0f, NAN).leg_enable, 0u);
    assert_int_equal(hs_legs_off().leg_enable, 0u);
}

static void speed_pi_design_places_double_pole(void **state)
{
    (void)state;
    const float j = 2e-5f;
    hs_speed_gains g = hs_speed_pi_design(j, 10.0f, 0.3f);
    float w = 2.0f * (float)M_PI * 10.0f;
    assert_float_equal(g.kp_nm_per_rad_s, 2.0f * j * w, 1e-9f);
    assert_float_equal(g.ki_nm_per_rad, j * w * w, 1e-6f);
    /* closed loop J dw/dt = T on an unsaturated step: y = 1 - e^(-wt) (1 - wt) */
    hs_speed_pi pi = {0.0f};
    const float dt = 50e-6f;
    double speed = 0.0, worst = 0.0;
    for (int k = 1; k <= 4000; ++k) {
        float t_ref = hs_speed_pi_step(&g, &pi, (float)(1.0 - speed), dt);
        speed += t_ref / (double)j * dt;
        double t = k * (double)dt;
        double y = 1.0 - exp(-w * t) * (1.0 - w * t);
        worst = fabs(speed - y) > worst ? fabs(speed - y) : worst;
    }
    if (worst > 0.01) {
        fail_msg("closed speed loop departs from the design by %.4f of the step", worst);
    }
    /* saturated: holds at the limit, the integrator does not wind up */
    hs_speed_pi sat = {0.0f};
    for (int k = 0; k < 10000; ++k) {
        assert_float_equal(hs_speed_pi_step(&g, &sat, 1000.0f, dt), 0.3f, 0.0f);
    }
    assert_true(sat.integral_nm <= 0.3f);
    assert_true(hs_speed_pi_step(&g, &sat, -50.0f, dt) < 0.3f);
}

static void hall_watch_trips_on_the_second_illegal_word(void **state)
{
    (void)state;
    hs_hall_watch w = {0u};
    assert_int_equal(hs_hall_watch_step(&w, 3u), 0);
    assert_int_equal(hs_hall_watch_step(&w, 0u), 0); /* one illegal sample: legs off, no trip yet */
    assert_int_equal(hs_hall_watch_step(&w, 4u), 0); /* a legal one resets */
    assert_int_equal(hs_hall_watch_step(&w, 0u), 0);
    assert_int_equal(hs_hall_watch_step(&w, 0u), 1);
    assert_int_equal(w.illegal_periods, HS_HALL_ILLEGAL_PERIODS);
}

static void stall_watch_trips_after_timeout_under_torque_only(void **state)
{
    (void)state;
    /* half the limit or more all along: trips on the 201st silent period of a 200-period timeout */
    hs_stall_watch w = {0u, 0u};
    assert_int_equal(hs_stall_watch_step(&w, 1, 0.3f, 0.3f, 200u), 0);
    for (int k = 1; k <= 200; ++k) {
        assert_int_equal(hs_stall_watch_step(&w, 0, 0.15f, 0.3f, 200u), 0);
    }
    assert_int_equal(hs_stall_watch_step(&w, 0, -0.3f, 0.3f, 200u), 1);
    /* standing still with little torque asked for is normal */
    hs_stall_watch still = {0u, 0u};
    for (int k = 0; k < 10000; ++k) {
        assert_int_equal(hs_stall_watch_step(&still, 0, 0.149f, 0.3f, 200u), 0);
    }
    /* an edge, or a dip in the demand, starts the count again */
    hs_stall_watch edges = {0u, 0u};
    for (int k = 0; k < 10000; ++k) {
        assert_int_equal(hs_stall_watch_step(&edges, k % 150 == 0, 0.3f, 0.3f, 200u), 0);
    }
    hs_stall_watch dips = {0u, 0u};
    for (int k = 0; k < 10000; ++k) {
        assert_int_equal(hs_stall_watch_step(&dips, 0, k % 150 == 0 ? 0.0f : 0.3f, 0.3f, 200u), 0);
    }
    /* timeout 0: off */
    hs_stall_watch off = {0u, 0u};
    for (int k = 0; k < 10000; ++k) {
        assert_int_equal(hs_stall_watch_step(&off, 0, 0.3f, 0.3f, 0u), 0);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(hall_words_give_the_sector_of_their_angle),
        cmocka_unit_test(commutation_puts_the_pair_on_the_flat_tops),
        cmocka_unit_test(hall_speed_from_edge_intervals),
        cmocka_unit_test(hall_speed_falls_when_edges_stop),
        cmocka_unit_test(current_regulator_step_response),
        cmocka_unit_test(current_regulator_limits_to_the_link_without_winding_up),
        cmocka_unit_test(legs_switch_the_pair_and_float_the_third),
        cmocka_unit_test(speed_pi_design_places_double_pole),
        cmocka_unit_test(hall_watch_trips_on_the_second_illegal_word),
        cmocka_unit_test(stall_watch_trips_after_timeout_under_torque_only),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
