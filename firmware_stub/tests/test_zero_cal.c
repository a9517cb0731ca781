/* Start-up zero calibration of the current ADCs (control.c, CURRENT_ZERO_CAL_PERIODS):
 * after an enable the bridge stays off for N periods, the mean of what each channel
 * reads becomes its zero, and only then does the drive run. Expected values by hand. */
#include <string.h>

#include "check.h"
#include "control.h"

static const double A_PER_COUNT = 0.01220703125;

static hil_sample idle_sample(uint32_t period, uint16_t adc1, uint16_t adc2)
{
    hil_sample s;
    memset(&s, 0, sizeof s);
    s.period = period;
    s.adc_i1 = adc1;
    s.adc_i2 = adc2;
    s.adc_vdc = 2867u; /* 69.995 V */
    s.encoder = 0u;
    s.status = 0u;
    return s;
}

static void enable(ctl *c)
{
    hil_command cmd;
    memset(&cmd, 0, sizeof cmd);
    cmd.flags = HIL_CMD_ENABLE;
    cmd.speed_source = HIL_SPEED_ENCODER;
    cmd.speed_ref_rad_s = 100.0f;
    assert_int_equal(ctl_set_command(c, &cmd), 0);
}

static void calibrates_each_channel_then_runs(void **state)
{
    (void)state;
    ctl c;
    ctl_init(&c);
    float v;
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CURRENT_ZERO_CAL_PERIODS, 4.0f, &v), HIL_PARAM_OK);
    ctl_step(&c, &(hil_sample){0}, NULL); /* first SAMPLE: initialises, idle */
    enable(&c);
    /* channel 1 reads 2052, 2053, 2051, 2052 (mean 2052); channel 2 2045 twice, 2046 twice
     * (mean 2045.5): the zero moves from the nominal 2048 to those means */
    const uint16_t ch1[4] = {2052u, 2053u, 2051u, 2052u}, ch2[4] = {2045u, 2046u, 2045u, 2046u};
    for (uint32_t k = 0; k < 4u; ++k) {
        hil_sample s = idle_sample(k + 1u, ch1[k], ch2[k]);
        hil_telemetry tm;
        uint8_t gates = ctl_step(&c, &s, &tm);
        assert_int_equal(gates, 0u); /* the bridge stays off while it measures */
        assert_near(tm.torque_ref_nm, 0.0, 0.0);
    }
    assert_near(c.cfg.clarke.offset1_counts, 2052.0, 1e-4);
    assert_near(c.cfg.clarke.offset2_counts, 2045.5, 1e-4);
    /* now the drive runs: the speed error asks for torque and a vector is applied */
    hil_sample s = idle_sample(5u, 2052u, 2046u);
    hil_telemetry tm;
    uint8_t gates = ctl_step(&c, &s, &tm);
    assert_true(gates != 0u);
    assert_true(tm.torque_ref_nm > 0.0f);
    /* and a reading at the measured zero is zero current: i_alpha = (2052 - 2052) A/count */
    clarke_out i;
    clarke_from_adc(&c.cfg.clarke, 2052u, 2045u, &i);
    assert_near(i.i_alpha_a, 0.0, 1e-6);
    assert_near(i.i_beta_a, (2.0 * (-0.5 * A_PER_COUNT)) / 1.7320508075688772, 1e-6);
}

/* A parameter written after the calibration (a gain changed mid-run) re-derives the board's
 * configuration; the measured zero must survive it, as on a drive, unless the nominal zero
 * itself is what was written. */
static void the_measured_zero_survives_a_later_parameter_write(void **state)
{
    (void)state;
    ctl c;
    ctl_init(&c);
    float v;
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CURRENT_ZERO_CAL_PERIODS, 2.0f, &v), HIL_PARAM_OK);
    ctl_step(&c, &(hil_sample){0}, NULL);
    enable(&c);
    for (uint32_t k = 0; k < 2u; ++k) {
        hil_sample s = idle_sample(k + 1u, 2056u, 2040u);
        ctl_step(&c, &s, NULL);
    }
    assert_near(c.cfg.clarke.offset1_counts, 2056.0, 1e-4);
    assert_near(c.cfg.clarke.offset2_counts, 2040.0, 1e-4);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_FLUX_BAND_WB, 0.002f, &v), HIL_PARAM_OK);
    assert_near(c.cfg.clarke.offset1_counts, 2056.0, 1e-4);   /* kept */
    assert_near(c.cfg.clarke.offset2_counts, 2040.0, 1e-4);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CURRENT_A_PER_COUNT, 0.0125f, &v), HIL_PARAM_OK);
    assert_near(c.cfg.clarke.offset1_counts, 2056.0, 1e-4);   /* a scale is not a zero */
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CURRENT_OFFSET_COUNTS, 2050.0f, &v), HIL_PARAM_OK);
    assert_near(c.cfg.clarke.offset1_counts, 2050.0, 1e-4);   /* the zero written wins */
    assert_near(c.cfg.clarke.offset2_counts, 2050.0, 1e-4);
}

static void off_by_default_and_bounded(void **state)
{
    (void)state;
    ctl c;
    ctl_init(&c);
    float v;
    assert_int_equal(ctl_param_get(&c, HIL_PARAM_CURRENT_ZERO_CAL_PERIODS, &v), HIL_PARAM_OK);
    assert_near(v, 0.0, 0.0);
    ctl_step(&c, &(hil_sample){0}, NULL);
    enable(&c);
    hil_sample s = idle_sample(1u, 2060u, 2060u);
    assert_true(ctl_step(&c, &s, NULL) != 0u);        /* no calibration: drives at once */
    assert_near(c.cfg.clarke.offset1_counts, 2048.0, 0.0); /* the nominal zero stays */
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CURRENT_ZERO_CAL_PERIODS, 70000.0f, &v),
                     HIL_PARAM_OUT_OF_RANGE);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CURRENT_ZERO_CAL_PERIODS, 2.5f, &v), HIL_PARAM_OUT_OF_RANGE);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(calibrates_each_channel_then_runs),
        cmocka_unit_test(the_measured_zero_survives_a_later_parameter_write),
        cmocka_unit_test(off_by_default_and_bounded),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
