/* ctl_step and the parameter table: the blocks wired together. */
#include <string.h>

#include "check.h"
#include "control.h"

static const double A_PER_COUNT = 0.01220703125;

static hil_sample sample_of(uint32_t period, double ia, double ib, uint16_t encoder)
{
    hil_sample s;
    s.period = period;
    s.adc_i1 = (uint16_t)lround(2048.0 + ia / A_PER_COUNT);
    s.adc_i2 = (uint16_t)lround(2048.0 + ib / A_PER_COUNT);
    s.adc_vdc = 2867u; /* 70 V */
    s.encoder = encoder;
    s.status = 0u;
    return s;
}

static hil_command command_of(uint8_t flags, uint8_t source, float speed, float torque)
{
    hil_command c = {flags, source, speed, torque, 0.0f};
    return c;
}

static void defaults_derived_from_design_inputs(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    const ctl_params *p = &c.params;
    /* i_d = 0 flux at half the torque limit: sqrt(psi_f^2 + (Ls T/(1.5 p psi_f) / 2)^2) */
    double iq = 1.0 / (1.5 * 0.0928);
    assert_near(p->flux_ref_wb, sqrt(0.0928 * 0.0928 + (4.8e-3 * iq) * (4.8e-3 * iq)), 1e-7);
    assert_near(p->flux_band_wb, 2.0 / 3.0 * 70.0 * 50e-6, 1e-9);
    assert_near(p->torque_band_nm, 1.5 * 0.0928 * 70.0 / sqrt(3.0) * 50e-6 / 4.8e-3, 1e-7);
    double wb = 2 * PI_D * 5.0;
    assert_near(p->speed_kp_nm_per_rad_s, 2 * 8e-4 * wb, 1e-7);
    assert_near(p->speed_ki_nm_per_rad, 8e-4 * wb * wb, 1e-5);
    assert_near(p->speed_lpf_cutoff_hz, 20.0, 0.0);
    assert_int_equal(p->telemetry_divider, 10);
    /* the composed table is Table 3 */
    for (uint8_t sector = 1; sector <= 6; ++sector) {
        for (int col = 0; col < 4; ++col) {
            assert_int_equal(c.cfg.vector_of[sector][col], swtab_table3[sector - 1][col]);
        }
    }
}

static void idle_tracks_encoder_and_keeps_switches_off(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    hil_telemetry tm;
    /* rotor turning at 4 counts per period: 2 pi 4 / 4096 / 50 us = 122.7 rad/s */
    for (uint32_t k = 0; k < 200; ++k) {
        hil_sample s = sample_of(k, 0.0, 0.0, (uint16_t)(1000u + 4u * k));
        assert_int_equal(ctl_step(&c, &s, &tm), 0);
        assert_int_equal(tm.sector, 0);
        assert_int_equal(tm.state, HIL_STATE_IDLE);
    }
    double w = 2 * PI_D * 4 / 4096 / 50e-6;
    assert_near(tm.speed_encoder_rad_s, w, 1e-3);
    assert_near(tm.speed_ekf_rad_s, w, 1e-3);
    double theta = remainder(2 * PI_D * (1000.0 + 4 * 199) / 4096, 2 * PI_D);
    assert_near(tm.flux_angle_rad, theta, 1e-5); /* zero current: psi = psi_f at the rotor angle */
    assert_near(tm.flux_mag_wb, 0.0928, 1e-6);
    assert_near(tm.rotor_pos_conv_rad, theta, 1e-5);
}

/* The switching vector picked for a flux at the encoder angle, zero current. */
static uint8_t first_vector(uint8_t flags, float speed, float torque, uint16_t encoder, uint8_t *sector)
{
    static ctl c;
    ctl_init(&c);
    hil_telemetry tm;
    hil_sample s = sample_of(0, 0.0, 0.0, encoder);
    ctl_step(&c, &s, &tm);
    hil_command cmd = command_of(flags, HIL_SPEED_ENCODER, speed, torque);
    assert_int_equal(ctl_set_command(&c, &cmd), 0);
    s.period = 1;
    uint8_t gates = ctl_step(&c, &s, &tm);
    assert_int_equal(tm.state, HIL_STATE_RUNNING);
    assert_int_equal(tm.gates, gates);
    *sector = tm.sector;
    for (uint8_t v = 1; v <= 6; ++v) {
        if (vsi_gates_of_vector(v) == gates) {
            return v;
        }
    }
    fail_msg("gates %02x are not an active vector", gates);
    return 0;
}

static void running_picks_table3_vectors(void **state)
{
    (void)state;
    uint8_t sector;
    /* flux psi_f = 0.0928 Wb below the 0.099 Wb reference: flux up. Encoder 0:
     * sector I. Speed reference above zero: torque up -> V2. */
    assert_int_equal(first_vector(HIL_CMD_ENABLE, 100.0f, 0.0f, 0u, &sector), 2);
    assert_int_equal(sector, 1);
    /* torque mode, negative torque: torque down -> V6 */
    assert_int_equal(first_vector(HIL_CMD_ENABLE | HIL_CMD_TORQUE_MODE, 0.0f, -1.0f, 0u, &sector), 6);
    /* rotor at 120 degrees (count 1365): sector III, flux up torque up -> V4 */
    assert_int_equal(first_vector(HIL_CMD_ENABLE, 100.0f, 0.0f, 1365u, &sector), 4);
    assert_int_equal(sector, 3);
}

static void torque_mode_clamps_to_limit(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    hil_telemetry tm;
    hil_sample s = sample_of(0, 0.0, 0.0, 0u);
    ctl_step(&c, &s, &tm);
    hil_command cmd = command_of(HIL_CMD_ENABLE | HIL_CMD_TORQUE_MODE, HIL_SPEED_EKF, 0.0f, 5.0f);
    ctl_set_command(&c, &cmd);
    ctl_step(&c, &s, &tm);
    assert_near(tm.torque_ref_nm, 2.0, 0.0);
    /* back to speed mode: the integrator starts from the torque it had */
    cmd = command_of(HIL_CMD_ENABLE, HIL_SPEED_EKF, 0.0f, 0.0f);
    ctl_set_command(&c, &cmd);
    assert_near(c.st.pi.integral_nm, 2.0, 0.0);
}

static void overcurrent_trips_latches_and_clears(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    hil_telemetry tm;
    hil_sample s = sample_of(0, 0.0, 0.0, 0u);
    ctl_step(&c, &s, &tm);
    hil_command on = command_of(HIL_CMD_ENABLE, HIL_SPEED_ENCODER, 50.0f, 0.0f);
    ctl_set_command(&c, &on);
    s = sample_of(1, 0.0, 0.0, 0u);
    assert_true(ctl_step(&c, &s, &tm) != 0);
    /* i_a = 21 A, i_b = -10 A: i_c = -11 A; peak 21 A over the 20 A default */
    s = sample_of(2, 21.0, -10.0, 0u);
    assert_int_equal(ctl_step(&c, &s, &tm), 0);
    assert_int_equal(tm.state, HIL_STATE_FAULT);
    assert_int_equal(c.st.fault_code, HIL_FAULT_OVERCURRENT);
    assert_near(c.st.fault_value, 21.0, 0.02);
    assert_int_equal(c.st.fault_period, 2);
    /* latched: normal samples keep the switches off */
    s = sample_of(3, 0.0, 0.0, 0u);
    assert_int_equal(ctl_step(&c, &s, &tm), 0);
    assert_int_equal(tm.state, HIL_STATE_FAULT);
    /* enabling again does not clear it; disabling does, and then it runs */
    ctl_set_command(&c, &on);
    assert_int_equal(c.st.state, HIL_STATE_FAULT);
    hil_command off = command_of(0u, HIL_SPEED_ENCODER, 0.0f, 0.0f);
    ctl_set_command(&c, &off);
    assert_int_equal(c.st.state, HIL_STATE_IDLE);
    assert_int_equal(c.st.fault_code, HIL_FAULT_NONE);
    ctl_set_command(&c, &on);
    s = sample_of(4, 0.0, 0.0, 0u);
    assert_true(ctl_step(&c, &s, &tm) != 0);
}

static void plant_comparator_bits(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    hil_telemetry tm;
    hil_sample s = sample_of(0, 0.0, 0.0, 0u);
    ctl_step(&c, &s, &tm);
    hil_command on = command_of(HIL_CMD_ENABLE, HIL_SPEED_ENCODER, 50.0f, 0.0f);
    ctl_set_command(&c, &on);
    s.status = HIL_STATUS_OVERVOLTAGE;
    assert_int_equal(ctl_step(&c, &s, NULL), 0);
    assert_int_equal(c.st.fault_code, HIL_FAULT_DC_LINK);
    assert_near(c.st.fault_value, 2867 * 0.0244140625, 1e-4);
}

/* Zero current samples and a still counter: the DTC turns the flux (nothing
 * resists it), the flux speed rises, and with the encoder closing the loop
 * that contradiction is an encoder loss. */
static uint32_t run_frozen_encoder(uint8_t source, uint32_t periods)
{
    static ctl c;
    ctl_init(&c);
    hil_sample s = sample_of(0, 0.0, 0.0, 77u);
    ctl_step(&c, &s, NULL);
    hil_command on = command_of(HIL_CMD_ENABLE, source, 100.0f, 0.0f);
    ctl_set_command(&c, &on);
    for (uint32_t k = 1; k < periods; ++k) {
        s.period = k;
        ctl_step(&c, &s, NULL);
        if (c.st.state == HIL_STATE_FAULT) {
            assert_int_equal(c.st.fault_code, HIL_FAULT_ENCODER_LOSS);
            assert_near(c.st.fault_value, 201 * 50e-6, 1e-7); /* seconds without an edge */
            return k;
        }
    }
    return 0;
}

static void encoder_loss_only_with_encoder_feedback(void **state)
{
    (void)state;
    uint32_t k = run_frozen_encoder(HIL_SPEED_ENCODER, 2000);
    /* 10 ms timeout (200 periods) after the flux speed passes 10 rad/s */
    assert_in_range(k, 201, 400);
    assert_int_equal(run_frozen_encoder(HIL_SPEED_EKF, 2000), 0);
    assert_int_equal(run_frozen_encoder(HIL_SPEED_CONVENTIONAL, 2000), 0);
}

static void bad_speed_source_rejected(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    hil_command cmd = command_of(HIL_CMD_ENABLE, 3u, 10.0f, 0.0f);
    assert_int_equal(ctl_set_command(&c, &cmd), -1);
    assert_int_equal(c.st.state, HIL_STATE_IDLE);
    assert_int_equal(c.cmd.enable, 0);
}

static void flux_reference_from_command_or_param(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    hil_command cmd = command_of(HIL_CMD_ENABLE, HIL_SPEED_EKF, 10.0f, 0.0f);
    ctl_set_command(&c, &cmd);
    assert_near(c.flux_ref_wb, c.params.flux_ref_wb, 0.0);
    cmd.flux_ref_wb = 0.12f;
    ctl_set_command(&c, &cmd);
    assert_near(c.flux_ref_wb, 0.12f, 0.0);
    float now;
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_FLUX_REF_WB, 0.08f, &now), HIL_PARAM_OK);
    assert_near(c.flux_ref_wb, 0.12f, 0.0); /* the command's still rules */
    cmd.flux_ref_wb = 0.0f;
    ctl_set_command(&c, &cmd);
    assert_near(c.flux_ref_wb, 0.08f, 0.0);
}

static void parameter_table(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    float v = -1.0f;
    assert_int_equal(ctl_param_get(&c, HIL_PARAM_CURRENT_A_PER_COUNT, &v), HIL_PARAM_OK);
    assert_near(v, A_PER_COUNT, 0.0);
    assert_int_equal(ctl_param_get(&c, 999u, &v), HIL_PARAM_UNKNOWN);
    assert_int_equal(ctl_param_set(&c, 999u, 1.0f, &v), HIL_PARAM_UNKNOWN);
    /* out of range and not a whole number: refused, old value reported */
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CURRENT_PHASES, 3.0f, &v), HIL_PARAM_OUT_OF_RANGE);
    assert_near(v, 0.0, 0.0);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CURRENT_PHASES, 1.5f, &v), HIL_PARAM_OUT_OF_RANGE);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_STATOR_RESISTANCE_OHM, NAN, &v), HIL_PARAM_OUT_OF_RANGE);
    assert_near(v, 0.466, 1e-7);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_TORQUE_LIMIT_NM, -1.0f, &v), HIL_PARAM_OUT_OF_RANGE);
    /* read-only */
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CONTROL_STEP_CYCLES, 5.0f, &v), HIL_PARAM_READ_ONLY);
    c.st.step_cycles = 1234u;
    assert_int_equal(ctl_param_get(&c, HIL_PARAM_CONTROL_STEP_CYCLES, &v), HIL_PARAM_OK);
    assert_near(v, 1234.0, 0.0);
    /* a set reaches the derived block configuration */
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_SPEED_LPF_CUTOFF_HZ, 100.0f, &v), HIL_PARAM_OK);
    assert_near(v, 100.0, 0.0);
    assert_near(c.cfg.conv.lpf_alpha, 1.0 - exp(-2 * PI_D * 100.0 * 50e-6), 1e-7);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_TELEMETRY_DIVIDER, 25.0f, &v), HIL_PARAM_OK);
    assert_int_equal(c.params.telemetry_divider, 25);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_ENCODER_LOSS_TIMEOUT_S, 0.02f, &v), HIL_PARAM_OK);
    assert_int_equal(c.cfg.prot.encoder_loss_timeout_periods, 400);
    /* every id of the header is known */
    const uint16_t ids[] = {1, 2, 3, 4, 5, 6, 7, 10, 11, 12, 13, 20, 21, 22, 23, 24, 25, 26, 30, 31, 32, 33, 40, 41, 42, 50};
    for (size_t n = 0; n < sizeof ids / sizeof ids[0]; ++n) {
        assert_int_equal(ctl_param_get(&c, ids[n], &v), HIL_PARAM_OK);
        if (ids[n] != HIL_PARAM_CONTROL_STEP_CYCLES) {
            float back;
            assert_int_equal(ctl_param_set(&c, ids[n], v, &back), HIL_PARAM_OK); /* its own value is in range */
            assert_true(back == v);
        }
    }
}

static void phase_pair_parameter(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    float v;
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CURRENT_PHASES, 2.0f, &v), HIL_PARAM_OK);
    /* b,c measured: i_b = 250 counts, i_c = -80 counts, so i_a = -170 counts */
    double ib = 250 * A_PER_COUNT, ic = -80 * A_PER_COUNT, ia = -ib - ic;
    hil_sample s = sample_of(0, ib, ic, 0u);
    hil_telemetry tm;
    ctl_step(&c, &s, &tm);
    /* idle: psi = psi_f + Ls i, so the flux angle shows the current */
    double pa = 0.0928 + 4.8e-3 * ia, pb = 4.8e-3 * (ia + 2 * ib) / sqrt(3.0);
    assert_near(tm.flux_angle_rad, atan2(pb, pa), 1e-4);
}

static void telemetry_is_optional_and_changes_nothing(void **state)
{
    (void)state;
    static ctl a, b;
    ctl_init(&a);
    ctl_init(&b);
    hil_command on = command_of(HIL_CMD_ENABLE, HIL_SPEED_EKF, 100.0f, 0.0f);
    hil_telemetry tm;
    for (uint32_t k = 0; k < 500; ++k) {
        hil_sample s = sample_of(k, 3.0 * sin(0.01 * k), 2.0 * cos(0.013 * k), (uint16_t)(3u * k));
        if (k == 1) {
            ctl_set_command(&a, &on);
            ctl_set_command(&b, &on);
        }
        assert_int_equal(ctl_step(&a, &s, &tm), ctl_step(&b, &s, NULL));
    }
    assert_true(memcmp(&a.st, &b.st, sizeof a.st) == 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(defaults_derived_from_design_inputs),
        cmocka_unit_test(idle_tracks_encoder_and_keeps_switches_off),
        cmocka_unit_test(running_picks_table3_vectors),
        cmocka_unit_test(torque_mode_clamps_to_limit),
        cmocka_unit_test(overcurrent_trips_latches_and_clears),
        cmocka_unit_test(plant_comparator_bits),
        cmocka_unit_test(encoder_loss_only_with_encoder_feedback),
        cmocka_unit_test(bad_speed_source_rejected),
        cmocka_unit_test(flux_reference_from_command_or_param),
        cmocka_unit_test(parameter_table),
        cmocka_unit_test(phase_pair_parameter),
        cmocka_unit_test(telemetry_is_optional_and_changes_nothing),
    };
    return cmocka_run_group_tests_name("control", tests, NULL, NULL);
}
