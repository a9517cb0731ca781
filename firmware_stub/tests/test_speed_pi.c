/* PI speed regulator: gains, torque limit, anti-windup. */
#include "check.h"
#include "speed_pi.h"

static spi_cfg make_cfg(float kp, float ki)
{
    spi_cfg cfg = {kp, ki, 2.0f, 50e-6f, 0.0f};
    spi_derive(&cfg);
    return cfg;
}

static spi_cfg CFG;

static int setup(void **state)
{
    (void)state;
    CFG = make_cfg(0.05f, 0.8f);
    return 0;
}

static void proportional_plus_integral(void **state)
{
    (void)state;
    spi_state st = {0.0f};
    float out = 0.0f;
    for (int n = 0; n < 1000; ++n) {
        out = spi_step(&CFG, &st, 10.0f, 0.0f);
    }
    /* Kp e + Ki T e n */
    assert_near(out, 0.05 * 10 + 0.8 * 50e-6 * 10 * 1000, 1e-4);
    assert_near(st.integral_nm, 0.8 * 50e-6 * 10 * 1000, 1e-4);
}

static void output_limited(void **state)
{
    (void)state;
    spi_state st = {0.0f};
    assert_near(spi_step(&CFG, &st, 1000.0f, 0.0f), 2.0, 0.0);
    assert_near(spi_step(&CFG, &st, -1000.0f, 0.0f), -2.0, 0.0);
}

static void no_windup_during_saturation(void **state)
{
    (void)state;
    spi_state st = {0.0f};
    /* Kp e = 1 Nm: the integrator fills the remaining 1 Nm, then stops; one
     * second saturated would otherwise take it to Ki e t = 16 Nm */
    for (int n = 0; n < 20000; ++n) {
        assert_true(spi_step(&CFG, &st, 20.0f, 0.0f) <= 2.0f);
    }
    assert_true(st.integral_nm <= 1.0f + 1e-6f);
    assert_true(st.integral_nm >= 1.0f - 0.8f * 50e-6f * 20.0f);
    /* speed overshoot: the output leaves saturation at once */
    float out = spi_step(&CFG, &st, 20.0f, 21.0f);
    assert_near(out, -0.05 + st.integral_nm, 1e-6);
    assert_true(out < 1.0f);
}

static void saturated_by_kp_alone_freezes_integrator(void **state)
{
    (void)state;
    spi_state st = {0.0f};
    for (int n = 0; n < 1000; ++n) {
        assert_near(spi_step(&CFG, &st, 100.0f, 0.0f), 2.0, 0.0);
    }
    assert_near(st.integral_nm, 0.0, 0.0);
}

static void integral_clamped_to_limit(void **state)
{
    (void)state;
    spi_state st = {0.0f};
    /* small error that never saturates the output through Kp, for long enough
     * that Ki T e summed exceeds the limit */
    const spi_cfg cfg = make_cfg(0.0f, 100.0f);
    for (int n = 0; n < 20000; ++n) {
        spi_step(&cfg, &st, 1.0f, 0.0f);
    }
    /* stops within one increment Ki T e below the limit, never above */
    assert_true(st.integral_nm <= 2.0f);
    assert_true(st.integral_nm >= 2.0f - 100.0f * 50e-6f);
    /* and unwinds at once when the error reverses */
    float before = st.integral_nm;
    float out = spi_step(&cfg, &st, 0.0f, 1.0f);
    assert_near(out, before - 100.0 * 50e-6, 1e-6);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(proportional_plus_integral),
        cmocka_unit_test(output_limited),
        cmocka_unit_test(no_windup_during_saturation),
        cmocka_unit_test(saturated_by_kp_alone_freezes_integrator),
        cmocka_unit_test(integral_clamped_to_limit),
    };
    return cmocka_run_group_tests_name("speed_pi", tests, setup, NULL);
}
