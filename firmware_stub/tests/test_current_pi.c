/* d-q current PI: gains from the bandwidth, first-order closed loop,
 * decoupling, voltage limit and anti-windup. */
#include "check.h"
#include "current_pi.h"
#include "motor_model.h"

static cpi_cfg make_cfg(float bandwidth_hz)
{
    cpi_cfg cfg = {bandwidth_hz, (float)MM_R, (float)MM_LS, (float)MM_PSI_F, (float)MM_T, 0.0f, 0.0f, 0.0f};
    cpi_derive(&cfg);
    return cfg;
}

static void gains_from_bandwidth(void **state)
{
    (void)state;
    cpi_cfg cfg = make_cfg(1000.0f);
    double wc = 2.0 * PI_D * 1000.0;
    assert_near(cfg.kp_v_per_a, MM_LS * wc, 1e-4);  /* 30.16 V/A */
    assert_near(cfg.ki_v_per_a_s, MM_R * wc, 1e-2); /* 2928 V/(A s) */
    assert_near(cfg.ki_per_step_v_per_a, MM_R * wc * MM_T, 1e-6);
}

/* Rotor-frame loop on the motor model at a fixed speed: (u_d, u_q) applied
 * at the period's mid angle, as foc.c does. */
static void run_loop(const cpi_cfg *cfg, cpi_state *st, motor_model *m, double id_ref, double iq_ref, float u_max,
                     int periods, double *id_out, double *iq_out)
{
    for (int k = 0; k < periods; ++k) {
        double id, iq;
        mm_dq(m, &id, &iq);
        cpi_out u;
        cpi_step(cfg, st, (float)id, (float)iq, (float)id_ref, (float)iq_ref, (float)m->speed_e, u_max, &u);
        double th = m->theta + m->speed_e * MM_T / 2;
        mm_period(m, cos(th) * u.u_d_v - sin(th) * u.u_q_v, sin(th) * u.u_d_v + cos(th) * u.u_q_v);
        if (id_out) {
            mm_dq(m, &id_out[k], &iq_out[k]);
        }
    }
}

static void first_order_step_without_overshoot(void **state)
{
    (void)state;
    cpi_cfg cfg = make_cfg(1000.0f);
    cpi_state st;
    cpi_reset(&st);
    /* 3000 rpm; a 0.2 A step keeps |u| = Kp 0.2 A + w psi_f = 35 V inside
     * the 40.4 V limit (a 7 A step would need 240 V: voltage-limited) */
    motor_model m = {0.0, 0.0, 0.3, 314.159};
    static double id[400], iq[400];
    run_loop(&cfg, &st, &m, 0.0, 0.2, 40.4f, 400, id, iq);
    /* Discrete time, the pole-zero cancellation leaves one closed-loop pole
     * at z = 1 - wc T (Kp T / Ls = wc T = 0.314; e^(-wc T) to first order):
     * i_q / i_q_ref = 1 - (1 - wc T)^(k+1) after k + 1 periods */
    double a = 1.0 - 2.0 * PI_D * 1000.0 * MM_T;
    for (int k = 0; k < 30; ++k) {
        assert_near(iq[k] / 0.2, 1.0 - pow(a, k + 1), 0.01);
    }
    double peak = 0.0;
    for (int k = 0; k < 400; ++k) {
        peak = fmax(peak, iq[k]);
        assert_near(id[k], 0.0, 0.004); /* decoupled: the q step barely moves d */
    }
    assert_true(peak <= 0.2 * 1.01);
    assert_near(iq[399], 0.2, 1e-4);
    assert_near(id[399], 0.0, 1e-4);
}

static void decoupling_removes_the_cross_terms(void **state)
{
    (void)state;
    /* with the integrators stopped (Ki = 0: bandwidth on Kp alone) the
     * steady state of a P loop with exact feed-forward is the P loop of
     * 1/(Ls s + R): i = Kp/(Kp + R) i_ref on each axis, no cross term */
    cpi_cfg cfg = make_cfg(1000.0f);
    cfg.ki_per_step_v_per_a = 0.0f;
    cpi_state st;
    cpi_reset(&st);
    motor_model m = {0.0, 0.0, 0.0, 314.159};
    static double id[2000], iq[2000];
    run_loop(&cfg, &st, &m, 0.0, 0.2, 40.4f, 2000, id, iq);
    double kp = cfg.kp_v_per_a;
    assert_near(iq[1999], 0.2 * kp / (kp + MM_R), 5e-4);
    assert_near(id[1999], 0.0, 5e-4);
}

static void limited_to_the_circle_without_windup(void **state)
{
    (void)state;
    cpi_cfg cfg = make_cfg(1000.0f);
    cpi_state st;
    cpi_reset(&st);
    cpi_out u;
    /* far from the reference for 1 s: the output stays on the circle and the
     * integrators stay within it */
    for (int k = 0; k < 20000; ++k) {
        cpi_step(&cfg, &st, 0.0f, 0.0f, 0.0f, 100.0f, 314.159f, 40.4f, &u);
        assert_true(u.limited);
        assert_near(sqrt((double)u.u_d_v * u.u_d_v + (double)u.u_q_v * u.u_q_v), 40.4, 1e-3);
    }
    assert_true(fabsf(st.integral_q_v) <= 40.4f);
    assert_true(fabsf(st.integral_d_v) <= 40.4f);
    /* the reference drops below the measurement: the output leaves the limit
     * and reverses on the next step (no integral to unwind: a wound-up one
     * would hold u_q at +40 V for Ki-limited time) */
    cpi_step(&cfg, &st, 0.0f, 1.0f, 0.0f, 0.0f, 0.0f, 40.4f, &u);
    assert_false(u.limited);
    assert_true(u.u_q_v < 0.0f);
}

static void integrates_when_not_limited(void **state)
{
    (void)state;
    cpi_cfg cfg = make_cfg(1000.0f);
    cpi_state st;
    cpi_reset(&st);
    cpi_out u;
    cpi_step(&cfg, &st, 0.0f, 0.0f, 0.0f, 0.1f, 0.0f, 40.4f, &u);
    assert_false(u.limited);
    assert_near(st.integral_q_v, cfg.ki_per_step_v_per_a * 0.1f, 1e-7);
    assert_near(u.u_q_v, cfg.kp_v_per_a * 0.1f + st.integral_q_v, 1e-6);
    /* feed-forward: back-EMF on q, -w Ls i_q on d */
    cpi_reset(&st);
    cpi_step(&cfg, &st, 0.0f, 2.0f, 0.0f, 2.0f, 100.0f, 40.4f, &u);
    assert_near(u.u_q_v, 100.0 * MM_PSI_F, 1e-5);
    assert_near(u.u_d_v, -100.0 * MM_LS * 2.0, 1e-5);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(gains_from_bandwidth),
        cmocka_unit_test(first_order_step_without_overshoot),
        cmocka_unit_test(decoupling_removes_the_cross_terms),
        cmocka_unit_test(limited_to_the_circle_without_windup),
        cmocka_unit_test(integrates_when_not_limited),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
