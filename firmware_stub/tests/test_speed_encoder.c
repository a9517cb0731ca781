/* Encoder speed over a window and absolute electrical angle. */
#include "check.h"
#include "speed_encoder.h"

static enc_cfg make_cfg(float cpr, float pole_pairs)
{
    enc_cfg cfg = {cpr, pole_pairs, 50e-6f, 0, 0.0f, 0.0f};
    enc_derive(&cfg);
    return cfg;
}

/* Counter of a rotor turning at w (mechanical rad/s) from angle 0, floor-quantised. */
static uint16_t counter(double w, int n, double cpr, double start)
{
    double counts = floor(start + w * n * 50e-6 * cpr / (2 * PI_D));
    return (uint16_t)(int64_t)llround(counts);
}

static void constant_speed_within_resolution(void **state)
{
    (void)state;
    enc_cfg cfg = make_cfg(4096.0f, 1.0f);
    const double res = 2 * PI_D / (4096 * 64 * 50e-6); /* 0.479 rad/s */
    assert_near(cfg.speed_rad_s_per_count, res, 1e-5);
    const double speeds[4] = {314.159, -157.0, 3.0, 0.0};
    for (int k = 0; k < 4; ++k) {
        enc_state st;
        enc_reset(&cfg, &st, counter(speeds[k], 0, 4096, 100000.0));
        for (int n = 1; n < 3000; ++n) { /* crosses the 16-bit wrap */
            enc_step(&cfg, &st, counter(speeds[k], n, 4096, 100000.0));
            if (n >= 64) {
                assert_near(st.speed_rad_s, speeds[k], res * 1.0001);
            }
        }
    }
}

static void angle_from_counts(void **state)
{
    (void)state;
    enc_cfg cfg = make_cfg(4096.0f, 1.0f);
    const enc_cfg *cfg_now = &cfg;
    enc_state st;
    enc_reset(&cfg, &st, 0u);
    assert_near(enc_angle_e(cfg_now, &st), 0.0, 0.0);
    enc_step(&cfg, &st, 1024u);
    assert_near(enc_angle_e(cfg_now, &st), PI_D / 2, 1e-6);
    enc_step(&cfg, &st, 3072u);
    assert_near(enc_angle_e(cfg_now, &st), -PI_D / 2, 1e-6);
    /* two pole pairs: a quarter turn is half an electrical turn */
    enc_cfg cfg2 = make_cfg(4096.0f, 2.0f);
    cfg_now = &cfg2;
    enc_reset(&cfg2, &st, 1024u);
    assert_near(fabs(enc_angle_e(cfg_now, &st)), PI_D, 1e-6);
    enc_step(&cfg2, &st, 512u);
    assert_near(enc_angle_e(cfg_now, &st), PI_D / 2, 1e-6);
}

static void non_power_of_two_counts_across_wrap(void **state)
{
    (void)state;
    /* 1000 counts/rev: 65536 is not a multiple, so the angle must come from
     * accumulated differences, not from the raw counter */
    enc_cfg cfg = make_cfg(1000.0f, 1.0f);
    const enc_cfg *cfg_now = &cfg;
    enc_state st;
    enc_reset(&cfg, &st, 0u);
    uint32_t total = 0;
    for (int n = 1; n <= 20000; ++n) {
        total += 7u; /* 7 counts per period */
        enc_step(&cfg, &st, (uint16_t)total);
    }
    double expect = remainder(2 * PI_D * (double)(total % 1000u) / 1000.0, 2 * PI_D);
    assert_near(enc_angle_e(cfg_now, &st), expect, 1e-5);
    assert_near(st.speed_rad_s, 7 * 2 * PI_D / 1000 / 50e-6, 1e-2);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(constant_speed_within_resolution),
        cmocka_unit_test(angle_from_counts),
        cmocka_unit_test(non_power_of_two_counts_across_wrap),
    };
    return cmocka_run_group_tests_name("speed_encoder", tests, NULL, NULL);
}
