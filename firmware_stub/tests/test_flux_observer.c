/* Flux observer eq. (3)-(4), drift compensation, |psi| eq. (5), torque eq. (6). */
#include "check.h"
#include "flux_observer.h"

static const float T = 50e-6f;
static const double R = 0.466, LS = 4.8e-3, PSI_F = 0.0928;

static fluxobs_cfg make_cfg(float cutoff_hz)
{
    fluxobs_cfg cfg = {(float)R, (float)LS, (float)PSI_F, T, cutoff_hz, 0.0f, 0.0f, 0.0f};
    fluxobs_derive(&cfg);
    return cfg;
}

static void pure_integrator_ramps(void **state)
{
    (void)state;
    fluxobs_cfg cfg = make_cfg(0.0f);
    fluxobs_state st;
    fluxobs_reset(&st, 0.05f, -0.02f, 0.0f, 0.0f);
    for (int n = 0; n < 200; ++n) {
        fluxobs_step(&cfg, &st, 46.0f, -23.0f, 0.0f, 0.0f);
    }
    assert_near(st.psi_alpha_wb, 0.05 + 200 * 50e-6 * 46.0, 1e-5);
    assert_near(st.psi_beta_wb, -0.02 - 200 * 50e-6 * 23.0, 1e-5);
}

static void resistive_drop_cancels(void **state)
{
    (void)state;
    fluxobs_cfg cfg = make_cfg(0.0f);
    fluxobs_state st;
    fluxobs_reset(&st, 0.1f, 0.0f, 5.0f, -3.0f);
    for (int n = 0; n < 1000; ++n) {
        fluxobs_step(&cfg, &st, (float)(R * 5.0), (float)(-R * 3.0), 5.0f, -3.0f);
    }
    assert_near(st.psi_alpha_wb, 0.1, 1e-6);
    assert_near(st.psi_beta_wb, 0.0, 1e-6);
    /* the R i term is trapezoidal in the current: a ramp in i is integrated exactly */
    fluxobs_reset(&st, 0.0f, 0.0f, 0.0f, 0.0f);
    fluxobs_step(&cfg, &st, 0.0f, 0.0f, 2.0f, 0.0f);
    assert_near(st.psi_alpha_wb, -R * 1.0 * 50e-6, 1e-9);
}

/* A surface-magnet motor at constant electrical speed w with a constant
 * q-axis current: psi_r = psi_f e^{j w t}, i = iq j e^{j w t},
 * psi = psi_r + Ls i. The observer gets u (exact step average of dpsi/dt + R i)
 * and the current plus a constant measurement offset i0. Returns the mean
 * error psi_est - psi over the last electrical period and the largest error
 * in that period. */
typedef struct {
    double mean_a, mean_b, worst; /* over the last electrical period */
    double last_a, last_b, last;  /* at the last step */
} run_result;

static run_result run_motor(const fluxobs_cfg *cfg, double w, double iq, double i0a, double i0b, double err0a,
                            double err0b, int steps)
{
    fluxobs_state st;
    double psi0a = PSI_F, psi0b = LS * iq; /* t = 0 */
    fluxobs_reset(&st, (float)(psi0a + err0a), (float)(psi0b + err0b), (float)i0a, (float)(iq + i0b));
    int period_steps = w > 0 ? (int)lround(2 * PI_D / (w * 50e-6)) : 1;
    run_result r = {0, 0, 0, 0, 0, 0};
    for (int n = 0; n < steps; ++n) {
        double t0 = n * 50e-6, t1 = (n + 1) * 50e-6;
        double c0 = cos(w * t0), s0 = sin(w * t0), c1 = cos(w * t1), s1 = sin(w * t1);
        /* psi = (psi_f + j Ls iq) e^{j w t} */
        double pa0 = PSI_F * c0 - LS * iq * s0, pb0 = PSI_F * s0 + LS * iq * c0;
        double pa1 = PSI_F * c1 - LS * iq * s1, pb1 = PSI_F * s1 + LS * iq * c1;
        double ia0 = -iq * s0, ib0 = iq * c0, ia1 = -iq * s1, ib1 = iq * c1;
        double ua = (pa1 - pa0) / 50e-6 + R * 0.5 * (ia0 + ia1);
        double ub = (pb1 - pb0) / 50e-6 + R * 0.5 * (ib0 + ib1);
        fluxobs_step(cfg, &st, (float)ua, (float)ub, (float)(ia1 + i0a), (float)(ib1 + i0b));
        if (n >= steps - period_steps) {
            double ea = st.psi_alpha_wb - pa1, eb = st.psi_beta_wb - pb1;
            r.mean_a += ea / period_steps;
            r.mean_b += eb / period_steps;
            r.worst = fmax(r.worst, hypot(ea, eb));
            r.last_a = ea;
            r.last_b = eb;
            r.last = hypot(ea, eb);
        }
    }
    return r;
}

static void compensation_adds_no_error_at_any_speed(void **state)
{
    (void)state;
    /* the true rotor flux has length psi_f exactly: nothing to correct, unlike a
     * leaky integrator, whose gain error would be (w0/w)^2 */
    fluxobs_cfg cfg = make_cfg(10.0f);
    const double speeds[4] = {0.0, 6.0, 60.0, 314.0};
    for (int k = 0; k < 4; ++k) {
        run_result r = run_motor(&cfg, speeds[k], 10.0, 0, 0, 0, 0, 20000);
        assert_true(r.worst < 2e-5);
    }
}

static void drift_grows_without_compensation(void **state)
{
    (void)state;
    fluxobs_cfg cfg = make_cfg(0.0f);
    const double i0a = 0.05, i0b = 0.085;
    run_result r = run_motor(&cfg, 157.0, 5.0, i0a, i0b, 0, 0, 40000); /* 2 s */
    /* e0 t with e0 = -R i0 */
    assert_near(r.mean_a, -R * i0a * 2.0, 0.002);
    assert_near(r.mean_b, -R * i0b * 2.0, 0.002);
}

static void drift_bounded_with_compensation(void **state)
{
    (void)state;
    const double f0 = 10.0, w0 = 2 * PI_D * f0, w = 157.0, i0a = 0.05, i0b = 0.085;
    fluxobs_cfg cfg = make_cfg((float)f0);
    run_result r = run_motor(&cfg, w, 5.0, i0a, i0b, 0, 0, 40000);
    /* linearised error in the rotor frame, steady state: with e0 = -R i0,
     * e = e0 (1/w0 + j/(2w)) + Ls i0 (the offset also shifts eta) */
    double e0a = -R * i0a, e0b = -R * i0b;
    double ea = e0a / w0 - e0b / (2 * w) + LS * i0a;
    double eb = e0b / w0 + e0a / (2 * w) + LS * i0b;
    double tol = 0.05 * hypot(e0a, e0b) / w0;
    assert_near(r.mean_a, ea, tol);
    assert_near(r.mean_b, eb, tol);
    assert_true(hypot(r.mean_a, r.mean_b) < 4e-4); /* against 0.09 Wb with no compensation */
}

static void initial_error_decays_at_cutoff(void **state)
{
    (void)state;
    const double f0 = 10.0, w0 = 2 * PI_D * f0;
    fluxobs_cfg cfg = make_cfg((float)f0);
    /* rotating: every direction of the error decays as e^{-w0 t} */
    const double t_end = 0.05;
    run_result r = run_motor(&cfg, 314.0, 5.0, 0, 0, 0.004, -0.003, (int)(t_end / 50e-6));
    double expect = 0.005 * exp(-w0 * t_end);
    assert_near(r.last, expect, 0.1 * expect);
    /* standstill: the radial part (along psi_f, alpha here) decays at 2 w0; the
     * tangential part is unobservable and stays */
    r = run_motor(&cfg, 0.0, 0.0, 0, 0, 0.002, -0.0005, (int)(0.02 / 50e-6));
    assert_near(r.last_a, 0.002 * exp(-2 * w0 * 0.02), 0.1 * 0.002 * exp(-2 * w0 * 0.02));
    assert_near(r.last_b, -0.0005, 0.03 * 0.0005); /* only the radial scaling of eta touches it */
}

static void magnitude_and_torque(void **state)
{
    (void)state;
    assert_near(flux_magnitude(0.06f, -0.08f), 0.1, 1e-7);
    /* psi along alpha, current along beta: T = 3/2 p psi i */
    assert_near(torque_estimate(1.0f, 0.1f, 0.0f, 0.0f, 10.0f), 1.5, 1e-6);
    assert_near(torque_estimate(3.0f, 0.1f, 0.0f, 0.0f, 10.0f), 4.5, 1e-5);
    /* rotation invariance */
    double th = 1.1;
    float pa = (float)(0.1 * cos(th)), pb = (float)(0.1 * sin(th));
    float ia = (float)(10 * cos(th + PI_D / 2)), ib = (float)(10 * sin(th + PI_D / 2));
    assert_near(torque_estimate(1.0f, pa, pb, ia, ib), 1.5, 1e-5);
    assert_near(torque_estimate(1.0f, pa, pb, -ia, -ib), -1.5, 1e-5);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(pure_integrator_ramps),
        cmocka_unit_test(resistive_drop_cancels),
        cmocka_unit_test(compensation_adds_no_error_at_any_speed),
        cmocka_unit_test(drift_grows_without_compensation),
        cmocka_unit_test(drift_bounded_with_compensation),
        cmocka_unit_test(initial_error_decays_at_cutoff),
        cmocka_unit_test(magnitude_and_torque),
    };
    return cmocka_run_group_tests_name("flux_observer", tests, NULL, NULL);
}
