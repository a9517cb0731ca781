/* The DTC path's inverter and delay compensation (flux_observer.h invcomp_*,
 * fluxobs_predict; control.c): dead time and device drop by current sign in the
 * voltage the observer integrates, and the one-period delay. Expected values
 * are worked out by hand from the leg-voltage argument in flux_observer.h. */
#include <string.h>

#include "check.h"
#include "control.h"
#include "flux_observer.h"

static const double T = 50e-6, TD = 2e-6, VDC = 70.0, UD = 1.5;
static const double SQRT3 = 1.7320508075688772;

static invcomp_cfg make_cfg(float td, float ud)
{
    invcomp_cfg cfg = {td, ud, (float)T, 0.1f, 0.0f, 0.0f};
    invcomp_derive(&cfg);
    return cfg;
}

/* (alpha, beta) of phase currents (ia, ib), eq. (8)-(9) */
static void ab_of(double ia, double ib, float *al, float *be)
{
    *al = (float)ia;
    *be = (float)((ia + 2.0 * ib) / SQRT3);
}

static void dead_time_only_on_a_switching_leg_against_its_current(void **state)
{
    (void)state;
    invcomp_cfg cfg = make_cfg((float)TD, 0.0f);
    float al, be;
    /* V2 (110) -> V1 (100): leg b turns its high switch off. With i_b < 0 the
     * high diode carries it through the dead time: b stays at DC+ for Td, so
     * e_b = +Td/T Vdc = 2.8 V; e_alpha = -e_b/3, e_beta = e_b/sqrt3. */
    ab_of(3.0, -2.0, &al, &be);
    float ua = 0.0f, ub = 0.0f;
    invcomp_correct(&cfg, 3u, 1u, (float)VDC, al, be, al, be, &ua, &ub);
    double eb = TD / T * VDC;
    assert_near(ua, -eb / 3.0, 1e-5);
    assert_near(ub, eb / SQRT3, 1e-5);
    /* with i_b > 0 the low diode takes over at once: the leg is already where it is told */
    ab_of(-3.0, 2.0, &al, &be);
    ua = ub = 0.0f;
    invcomp_correct(&cfg, 3u, 1u, (float)VDC, al, be, al, be, &ua, &ub);
    assert_near(ua, 0.0, 1e-6);
    assert_near(ub, 0.0, 1e-6);
    /* V1 -> V2: leg b turns on; with i_b > 0 it stays at DC- for Td: e_b = -2.8 V */
    invcomp_correct(&cfg, 1u, 3u, (float)VDC, al, be, al, be, &ua, &ub);
    assert_near(ua, eb / 3.0, 1e-5);
    assert_near(ub, -eb / SQRT3, 1e-5);
    /* no leg switches: nothing to correct, whatever the currents */
    ua = ub = 0.0f;
    invcomp_correct(&cfg, 1u, 1u, (float)VDC, al, be, al, be, &ua, &ub);
    assert_near(ua, 0.0, 1e-6);
    assert_near(ub, 0.0, 1e-6);
    /* coming from all switches off the diodes set the voltage: no dead-time term */
    invcomp_correct(&cfg, INVCOMP_LEGS_OFF, 3u, (float)VDC, al, be, al, be, &ua, &ub);
    assert_near(ua, 0.0, 1e-6);
    assert_near(ub, 0.0, 1e-6);
}

static void device_drop_opposes_every_phase_current(void **state)
{
    (void)state;
    invcomp_cfg cfg = make_cfg(0.0f, (float)UD);
    float al, be;
    /* i_a = 4, i_b = i_c = -2: e = (-Ud, +Ud, +Ud), e_alpha = -4/3 Ud, e_beta = 0:
     * the stator sees 2 Ud against the current, as two devices in series do */
    ab_of(4.0, -2.0, &al, &be);
    float ua = 10.0f, ub = -5.0f;
    invcomp_correct(&cfg, 1u, 1u, (float)VDC, al, be, al, be, &ua, &ub);
    assert_near(ua, 10.0 - 4.0 / 3.0 * UD, 1e-5);
    assert_near(ub, -5.0, 1e-5);
    /* inside the +-0.1 A band the sign is linear: i_a = 0.05 A gives half the drop on a */
    ab_of(0.05, -2.0, &al, &be); /* i_c = 1.95 */
    ua = ub = 0.0f;
    invcomp_correct(&cfg, 1u, 1u, (float)VDC, al, be, al, be, &ua, &ub);
    double ea = -0.5 * UD, eb = UD, ec = -UD;
    assert_near(ua, (2 * ea - eb - ec) / 3.0, 1e-5);
    assert_near(ub, (eb - ec) / SQRT3, 1e-5);
}

/* Surface-magnet motor at electrical speed w, constant q current: the
 * prediction one period ahead against the exact state at t + T. */
static void prediction_matches_the_motor_one_period_ahead(void **state)
{
    (void)state;
    const double R = 0.466, LS = 4.8e-3, PSI_F = 0.0928, IQ = 7.0, W = 314.16;
    fluxobs_cfg cfg = {(float)R, (float)LS, (float)PSI_F, (float)T, 0.0f, 0.0f, 0.0f, 0.0f};
    fluxobs_derive(&cfg);
    double th0 = 0.7;
    /* psi = (psi_f + j Ls iq) e^{j th}, i = j iq e^{j th} */
    double psi_r = PSI_F, psi_i = LS * IQ;
    double c0 = cos(th0), s0 = sin(th0), c1 = cos(th0 + W * T), s1 = sin(th0 + W * T);
    fluxobs_state st;
    fluxobs_reset(&st, (float)(psi_r * c0 - psi_i * s0), (float)(psi_r * s0 + psi_i * c0), (float)(-IQ * s0),
                  (float)(IQ * c0));
    /* the exact mean of dpsi/dt + R i over [t, t+T] */
    double dpa = (psi_r * c1 - psi_i * s1) - (psi_r * c0 - psi_i * s0);
    double dpb = (psi_r * s1 + psi_i * c1) - (psi_r * s0 + psi_i * c0);
    double mia = -IQ * (cos(th0) - cos(th0 + W * T)) / (W * T); /* mean of -iq sin */
    double mib = IQ * (sin(th0 + W * T) - sin(th0)) / (W * T);
    float ua = (float)(dpa / T + R * mia), ub = (float)(dpb / T + R * mib);
    float pa, pb, ia, ib;
    fluxobs_predict(&cfg, &st, ua, ub, (float)W, &pa, &pb, &ia, &ib);
    /* Euler's R i error: R |di| T / 2 = 0.466 x 2.2 A x 25 us = 2.6e-5 Wb; the
     * rotation's third-order error is psi_f (wT)^3/6 = 6e-8 Wb */
    assert_near(pa, psi_r * c1 - psi_i * s1, 3e-5);
    assert_near(pb, psi_r * s1 + psi_i * c1, 3e-5);
    /* current: flux errors / Ls = 6e-3 A, against the 2.2 A it moves in one period */
    assert_near(ia, -IQ * s1, 8e-3);
    assert_near(ib, IQ * c1, 8e-3);
    /* the rotor flux's turn matters: predicting with w = 0 misses psi_f w T / Ls = 0.3 A */
    fluxobs_predict(&cfg, &st, ua, ub, 0.0f, &pa, &pb, &ia, &ib);
    assert_true(hypot(ia + IQ * s1, ib - IQ * c1) > 0.25);
}

/* ---- in ctl_step ---- */

static const double A_PER_COUNT = 0.01220703125;

static hil_sample sample_of(uint32_t period, double ia, double ib)
{
    hil_sample s;
    s.period = period;
    s.adc_i1 = (uint16_t)lround(2048.0 + ia / A_PER_COUNT);
    s.adc_i2 = (uint16_t)lround(2048.0 + ib / A_PER_COUNT);
    s.adc_vdc = 2867u; /* 69.995 V */
    s.encoder = 0u;
    s.status = 0u;
    return s;
}

/* A running controller with R = 0 and a pure integrator, so one step moves psi
 * by exactly T u; the step is given the vector history and a current. Returns
 * the flux change. */
static void one_step(uint8_t delay_comp, float td, uint8_t v3, uint8_t v2, uint8_t v1, double ia, double ib,
                     double *dpa, double *dpb)
{
    static ctl c;
    float v;
    ctl_init(&c);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_STATOR_RESISTANCE_OHM, 0.0f, &v), HIL_PARAM_OK);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_FLUX_DRIFT_CUTOFF_HZ, 0.0f, &v), HIL_PARAM_OK);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_DEAD_TIME_COMP_S, td, &v), HIL_PARAM_OK);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_DELAY_COMP_PERIODS, (float)delay_comp, &v), HIL_PARAM_OK);
    hil_sample s = sample_of(0u, ia, ib);
    (void)ctl_step(&c, &s, NULL); /* first sample: initialises */
    hil_command cmd = {HIL_CMD_ENABLE, HIL_SPEED_ENCODER, 0.0f, 0.0f, 0.0f};
    assert_int_equal(ctl_set_command(&c, &cmd), 0);
    c.st.vector_prev3 = v3;
    c.st.vector_prev2 = v2;
    c.st.vector_prev = v1;
    double pa = c.st.flux.psi_alpha_wb, pb = c.st.flux.psi_beta_wb;
    s.period = 1u;
    (void)ctl_step(&c, &s, NULL);
    *dpa = c.st.flux.psi_alpha_wb - pa;
    *dpb = c.st.flux.psi_beta_wb - pb;
}

static void observer_integrates_the_vector_that_acted(void **state)
{
    (void)state;
    double vdc = 2867 * 0.0244140625, dpa, dpb;
    /* no delay: the answer to the previous SAMPLE (V1) acted */
    one_step(0u, 0.0f, 3u, 3u, 1u, 0.0, 0.0, &dpa, &dpb);
    assert_near(dpa, T * 2.0 / 3.0 * vdc, 1e-8);
    assert_near(dpb, 0.0, 1e-8);
    /* one period of delay: the answer before it (V3) acted */
    one_step(1u, 0.0f, 3u, 3u, 1u, 0.0, 0.0, &dpa, &dpb);
    assert_near(dpa, -T / 3.0 * vdc, 1e-8);
    assert_near(dpb, T / SQRT3 * vdc, 1e-8);
}

static void observer_compensates_dead_time_by_current_sign(void **state)
{
    (void)state;
    double vdc = 2867 * 0.0244140625, dpa, dpb;
    double eb = TD / T * vdc;
    /* V2 -> V1 with i_b = -2 A: leg b held at DC+ for Td */
    one_step(0u, (float)TD, 2u, 2u, 1u, 0.0, -2.0, &dpa, &dpb);
    assert_near(dpa, T * (2.0 / 3.0 * vdc - eb / 3.0), 1e-8);
    assert_near(dpb, T * eb / SQRT3, 1e-8);
    /* the same history one period later when the answer acts one period late */
    one_step(1u, (float)TD, 2u, 1u, 4u, 0.0, -2.0, &dpa, &dpb);
    assert_near(dpa, T * (2.0 / 3.0 * vdc - eb / 3.0), 1e-8);
    assert_near(dpb, T * eb / SQRT3, 1e-8);
}

static void compensation_parameters(void **state)
{
    (void)state;
    static ctl c;
    float v;
    ctl_init(&c);
    assert_int_equal(ctl_param_get(&c, HIL_PARAM_DEVICE_DROP_COMP_V, &v), HIL_PARAM_OK);
    assert_near(v, 0.0, 0.0);
    assert_int_equal(ctl_param_get(&c, HIL_PARAM_DELAY_COMP_PERIODS, &v), HIL_PARAM_OK);
    assert_near(v, 0.0, 0.0);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_DEVICE_DROP_COMP_V, 1.5f, &v), HIL_PARAM_OK);
    assert_near(c.cfg.inv.device_drop_v, 1.5, 0.0);
    assert_int_equal(c.cfg.inv_comp_on, 1);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_DEVICE_DROP_COMP_V, 11.0f, &v), HIL_PARAM_OUT_OF_RANGE);
    assert_near(v, 1.5, 0.0);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_DELAY_COMP_PERIODS, 0.5f, &v), HIL_PARAM_OUT_OF_RANGE);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_DELAY_COMP_PERIODS, 2.0f, &v), HIL_PARAM_OUT_OF_RANGE);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_DELAY_COMP_PERIODS, 1.0f, &v), HIL_PARAM_OK);
    assert_int_equal(c.cfg.delay_comp, 1);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_DEAD_TIME_COMP_S, 2e-6f, &v), HIL_PARAM_OK);
    assert_near(c.cfg.inv.td_over_t, 0.04, 1e-7);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(dead_time_only_on_a_switching_leg_against_its_current),
        cmocka_unit_test(device_drop_opposes_every_phase_current),
        cmocka_unit_test(prediction_matches_the_motor_one_period_ahead),
        cmocka_unit_test(observer_integrates_the_vector_that_acted),
        cmocka_unit_test(observer_compensates_dead_time_by_current_sign),
        cmocka_unit_test(compensation_parameters),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
