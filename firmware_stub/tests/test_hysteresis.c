/* Two-level hysteresis comparator. */
#include "check.h"
#include "hysteresis.h"

static void switches_at_band_edges_and_holds_inside(void **state)
{
    (void)state;
    hyst_cfg cfg = {0.2f, 0.0f};
    hyst_derive(&cfg);
    hyst_state st = {1u};
    const float ref = 1.0f;
    assert_int_equal(hyst_step(&cfg, &st, ref, 0.5f), 1);
    assert_int_equal(hyst_step(&cfg, &st, ref, 1.05f), 1);  /* inside: holds 1 */
    assert_int_equal(hyst_step(&cfg, &st, ref, 1.099f), 1); /* still inside */
    assert_int_equal(hyst_step(&cfg, &st, ref, 1.101f), 0); /* above ref + band/2 */
    assert_int_equal(hyst_step(&cfg, &st, ref, 0.95f), 0);  /* inside: holds 0 */
    assert_int_equal(hyst_step(&cfg, &st, ref, 0.901f), 0);
    assert_int_equal(hyst_step(&cfg, &st, ref, 0.899f), 1); /* below ref - band/2 */
}

static void zero_band_is_a_plain_comparator(void **state)
{
    (void)state;
    hyst_cfg cfg = {0.0f, 0.0f};
    hyst_derive(&cfg);
    hyst_state st = {0u};
    assert_int_equal(hyst_step(&cfg, &st, 0.0f, -1e-6f), 1);
    assert_int_equal(hyst_step(&cfg, &st, 0.0f, 1e-6f), 0);
    assert_int_equal(hyst_step(&cfg, &st, 0.0f, 0.0f), 0); /* exactly at ref: holds */
}

static void ripple_of_a_triangle_follows_band(void **state)
{
    (void)state;
    /* a value driven up or down by a fixed slope under the comparator stays
     * within the band plus one step on each side */
    hyst_cfg cfg = {0.1f, 0.0f};
    hyst_derive(&cfg);
    hyst_state st = {1u};
    float v = 0.0f, lo = 1e9f, hi = -1e9f;
    const float step = 0.01f;
    for (int n = 0; n < 2000; ++n) {
        uint8_t up = hyst_step(&cfg, &st, 0.0f, v);
        v += up ? step : -step;
        if (n > 100) {
            lo = v < lo ? v : lo;
            hi = v > hi ? v : hi;
        }
    }
    assert_near(hi, 0.05 + step, 1.5 * step);
    assert_near(lo, -0.05 - step, 1.5 * step);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(switches_at_band_edges_and_holds_inside),
        cmocka_unit_test(zero_band_is_a_plain_comparator),
        cmocka_unit_test(ripple_of_a_triangle_follows_band),
    };
    return cmocka_run_group_tests_name("hysteresis", tests, NULL, NULL);
}
