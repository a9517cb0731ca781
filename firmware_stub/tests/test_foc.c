/* The FOC law (foc.c): Park, closed loop through SVPWM duties on a motor
 * model, the mid-period angle, and its place in ctl_step (DUTY vs GATES). */
#include <string.h>

#include "check.h"
#include "control.h"
#include "foc.h"
#include "motor_model.h"

static foc_cfg make_cfg(void)
{
    foc_cfg cfg;
    memset(&cfg, 0, sizeof cfg);
    cfg.current.bandwidth_hz = 1000.0f;
    cfg.current.stator_resistance_ohm = (float)MM_R;
    cfg.current.stator_inductance_h = (float)MM_LS;
    cfg.current.magnet_flux_wb = (float)MM_PSI_F;
    cfg.pwm.comp_band_a = 0.1f;
    cfg.pole_pairs = 1.0f;
    cfg.control_period_s = (float)MM_T;
    foc_derive(&cfg);
    return cfg;
}

/* The average stator voltage of the quantised duties the board sends. */
static void applied_voltage(const float duty[3], double vdc, double *ua, double *ub)
{
    double d[3];
    for (int x = 0; x < 3; ++x) {
        d[x] = svpwm_duty_u16(duty[x]) / 65535.0;
    }
    *ua = vdc * (2.0 * d[0] - d[1] - d[2]) / 3.0;
    *ub = vdc * (d[1] - d[2]) / sqrt(3.0);
}

static void park_of_the_measured_currents(void **state)
{
    (void)state;
    foc_cfg cfg = make_cfg();
    foc_state st;
    foc_reset(&st);
    uint32_t seed = 7u;
    for (int n = 0; n < 1000; ++n) {
        double th = check_uniform(&seed, -PI_D, PI_D), phi = check_uniform(&seed, -PI_D, PI_D);
        double mag = check_uniform(&seed, 0.0, 15.0);
        float duty[3];
        foc_step(&cfg, &st, (float)th, 0.0f, (float)(mag * cos(th + phi)), (float)(mag * sin(th + phi)), 0.0f,
                 70.0f, duty);
        assert_near(st.i_d_a, mag * cos(phi), 2e-5 * 15);
        assert_near(st.i_q_a, mag * sin(phi), 2e-5 * 15);
    }
}

static void torque_reference_reached_at_3000_rpm(void **state)
{
    (void)state;
    foc_cfg cfg = make_cfg();
    foc_state st;
    foc_reset(&st);
    motor_model m = {0.0, 0.0, 1.0, 314.159};
    const double torque = 1.0, iq_ref = torque / (1.5 * MM_PSI_F); /* 7.18 A */
    double id = 0.0, iq = 0.0, peak = 0.0;
    for (int k = 0; k < 600; ++k) {
        float duty[3];
        foc_step(&cfg, &st, (float)remainder(m.theta, 2 * PI_D), (float)m.speed_e, (float)m.i_alpha,
                 (float)m.i_beta, (float)torque, 70.0f, duty);
        double ua, ub;
        applied_voltage(duty, 70.0, &ua, &ub);
        mm_period(&m, ua, ub);
        mm_dq(&m, &id, &iq);
        peak = fmax(peak, iq);
    }
    assert_near(st.i_q_ref_a, iq_ref, 1e-5);
    assert_near(iq, iq_ref, 0.01);
    assert_near(id, 0.0, 0.01);
    assert_true(peak <= iq_ref * 1.01); /* no overshoot (voltage-limited start, then first order) */
}

static void voltage_applied_at_the_mid_period_angle(void **state)
{
    (void)state;
    /* zero currents, zero reference: the request is the feed-forward back-EMF
     * w psi_f on q, which must point at theta + w T/2 + 90 deg */
    foc_cfg cfg = make_cfg();
    foc_state st;
    foc_reset(&st);
    float duty[3];
    const double th = 0.7, w = 314.159;
    foc_step(&cfg, &st, (float)th, (float)w, 0.0f, 0.0f, 0.0f, 70.0f, duty);
    double ang = atan2(st.u_beta_v, st.u_alpha_v);
    assert_near(ang, th + w * MM_T / 2 + PI_D / 2, 1e-5);
    assert_near(hypot(st.u_alpha_v, st.u_beta_v), w * MM_PSI_F, 1e-4);
    double ua, ub;
    applied_voltage(duty, 70.0, &ua, &ub);
    assert_near(ua, st.u_alpha_v, 70.0 / 65535.0);
    assert_near(ub, st.u_beta_v, 70.0 / 65535.0);
}

/* ---- ctl_step: the dispatch ---- */

static hil_sample sample_of(uint32_t period, uint16_t encoder)
{
    hil_sample s = {period, 2048u, 2048u, 2867u /* 70 V */, encoder, 0u};
    return s;
}

static void default_law_is_dtc_answering_gates(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    assert_int_equal(c.params.control_law, CTL_LAW_DTC);
    hil_command on = {HIL_CMD_ENABLE, HIL_SPEED_ENCODER, 100.0f, 0.0f, 0.0f};
    hil_sample s = sample_of(0, 0);
    (void)ctl_step(&c, &s, NULL);
    assert_int_equal(ctl_set_command(&c, &on), 0);
    s = sample_of(1, 0);
    assert_int_not_equal(ctl_step(&c, &s, NULL), 0);
    assert_int_equal(c.st.answer_duty, 0);
}

static void foc_answers_duty_while_running_only(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    float now;
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CONTROL_LAW, 1.0f, &now), HIL_PARAM_OK);
    hil_telemetry tm;
    hil_sample s = sample_of(0, 0);
    assert_int_equal(ctl_step(&c, &s, &tm), 0);
    assert_int_equal(c.st.answer_duty, 0); /* idle: GATES 0, every switch off */
    assert_int_equal(tm.gates, 0);
    hil_command on = {HIL_CMD_ENABLE, HIL_SPEED_ENCODER, 100.0f, 0.0f, 0.0f};
    assert_int_equal(ctl_set_command(&c, &on), 0);
    s = sample_of(1, 0);
    assert_int_equal(ctl_step(&c, &s, &tm), 0);
    assert_int_equal(c.st.answer_duty, 1);
    assert_int_equal(tm.gates, CTL_GATES_PWM);
    /* speed error 100 rad/s: the speed PI saturates at +2 Nm, i_q_ref > 0;
     * rotor at theta_e = 0, so q is beta: phase b's duty above phase c's */
    assert_near(c.st.foc.i_q_ref_a, 2.0 / (1.5 * 0.0928), 1e-4);
    assert_true(c.st.duty[1] > c.st.duty[2]);
    assert_int_equal((c.st.duty[0] > c.st.duty[1] ? c.st.duty[0] : c.st.duty[1]) +
                         (c.st.duty[0] < c.st.duty[2] ? c.st.duty[0] : c.st.duty[2]),
                     65535); /* centred: max + min = full scale */
    hil_command off = {0u, HIL_SPEED_ENCODER, 0.0f, 0.0f, 0.0f};
    assert_int_equal(ctl_set_command(&c, &off), 0);
    s = sample_of(2, 0);
    assert_int_equal(ctl_step(&c, &s, &tm), 0);
    assert_int_equal(c.st.answer_duty, 0);
    assert_true(c.st.foc.u_alpha_v == 0.0f && c.st.foc.current.integral_q_v == 0.0f); /* reset while idle */
}

static void foc_trip_answers_gates_off(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    float now;
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CONTROL_LAW, 1.0f, &now), HIL_PARAM_OK);
    hil_sample s = sample_of(0, 0);
    (void)ctl_step(&c, &s, NULL);
    hil_command on = {HIL_CMD_ENABLE, HIL_SPEED_ENCODER, 0.0f, 0.0f, 0.0f};
    assert_int_equal(ctl_set_command(&c, &on), 0);
    s = sample_of(1, 0);
    s.status = HIL_STATUS_OVERCURRENT;
    assert_int_equal(ctl_step(&c, &s, NULL), 0);
    assert_int_equal(c.st.state, HIL_STATE_FAULT);
    assert_int_equal(c.st.answer_duty, 0); /* not a DUTY of zeros: that shorts the motor */
}

static void foc_parameters(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    float v;
    assert_int_equal(ctl_param_get(&c, HIL_PARAM_CURRENT_BANDWIDTH_HZ, &v), HIL_PARAM_OK);
    assert_near(v, 1000.0, 0.0);
    /* gains follow the motor and the bandwidth */
    assert_near(c.cfg.foc.current.kp_v_per_a, 4.8e-3 * 2 * PI_D * 1000.0, 1e-4);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_STATOR_INDUCTANCE_H, 2.4e-3f, &v), HIL_PARAM_OK);
    assert_near(c.cfg.foc.current.kp_v_per_a, 2.4e-3 * 2 * PI_D * 1000.0, 1e-4);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CONTROL_LAW, 2.0f, &v), HIL_PARAM_OUT_OF_RANGE);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CONTROL_LAW, 0.5f, &v), HIL_PARAM_OUT_OF_RANGE);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_FOC_ANGLE_SOURCE, 1.0f, &v), HIL_PARAM_OK);
    assert_int_equal(c.cfg.foc_angle_source, CTL_FOC_ANGLE_EKF);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_DEAD_TIME_COMP_S, 1e-6f, &v), HIL_PARAM_OK);
    assert_near(c.cfg.foc.pwm.dead_time_duty, 0.02, 1e-7);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_DEAD_TIME_COMP_S, 1e-4f, &v), HIL_PARAM_OUT_OF_RANGE);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(park_of_the_measured_currents),
        cmocka_unit_test(torque_reference_reached_at_3000_rpm),
        cmocka_unit_test(voltage_applied_at_the_mid_period_angle),
        cmocka_unit_test(default_law_is_dtc_answering_gates),
        cmocka_unit_test(foc_answers_duty_while_running_only),
        cmocka_unit_test(foc_trip_answers_gates_off),
        cmocka_unit_test(foc_parameters),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
