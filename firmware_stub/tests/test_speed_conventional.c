/* Conventional speed estimate eq. (10)-(11) and its low-pass filter. */
#include "check.h"
#include "speed_conventional.h"

static conv_cfg make_cfg(float fc)
{
    conv_cfg cfg = {50e-6f, fc, 0.0f, 0.0f};
    conv_derive(&cfg);
    return cfg;
}

static void raw_speed_is_angle_difference(void **state)
{
    (void)state;
    conv_cfg cfg = make_cfg(20.0f);
    conv_state st;
    const double w = -300.0;
    conv_reset(&st, 0.0f, 0.0f);
    for (int n = 1; n < 2000; ++n) { /* several turns through the +-pi wrap */
        double th = remainder(w * n * 50e-6, 2 * PI_D);
        conv_step(&cfg, &st, (float)th);
        assert_near(st.speed_raw_rad_s, w, 0.1); /* float angle over 50 us */
    }
}

static void filter_step_response(void **state)
{
    (void)state;
    const double fc = 20.0;
    conv_cfg cfg = make_cfg((float)fc);
    assert_near(cfg.lpf_alpha, 1 - exp(-2 * PI_D * fc * 50e-6), 1e-7);
    conv_state st;
    conv_reset(&st, 0.0f, 0.0f);
    const double w = 200.0;
    for (int n = 1; n <= 400; ++n) {
        conv_step(&cfg, &st, (float)remainder(w * n * 50e-6, 2 * PI_D));
    }
    /* first order: 1 - exp(-t/tau) after t = 20 ms */
    double expect = w * (1 - exp(-2 * PI_D * fc * 400 * 50e-6));
    assert_near(st.speed_lpf_rad_s, expect, 0.1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(raw_speed_is_angle_difference),
        cmocka_unit_test(filter_step_response),
    };
    return cmocka_run_group_tests_name("speed_conventional", tests, NULL, NULL);
}
