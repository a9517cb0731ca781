/* fm_sincos, fm_atan2, fm_wrap_pi against libm in double precision. */
#include "check.h"
#include "fastmath.h"

static void sincos_error_bound(void **state)
{
    (void)state;
    double worst = 0.0;
    for (int n = -400000; n <= 400000; ++n) {
        float th = (float)(4.0 * PI_D * n / 400000.0);
        float s, c;
        fm_sincos(th, &s, &c);
        double es = fabs((double)s - sin((double)th));
        double ec = fabs((double)c - cos((double)th));
        worst = fmax(worst, fmax(es, ec));
    }
    if (!(worst <= FM_SINCOS_MAX_ERR)) {
        fail_msg("sincos worst error %.3g above bound %.3g", worst, (double)FM_SINCOS_MAX_ERR);
    }
    /* the bound is not loose by orders of magnitude */
    assert_true(worst > 1e-8);
}

static void sincos_quadrants_exact_points(void **state)
{
    (void)state;
    float s, c;
    fm_sincos(0.0f, &s, &c);
    assert_true(s == 0.0f && c == 1.0f);
    fm_sincos(FM_HALF_PI, &s, &c);
    assert_near(s, 1.0, 1e-7);
    assert_near(c, 0.0, 1e-7);
    fm_sincos(-FM_PI, &s, &c);
    assert_near(s, 0.0, 1e-7);
    assert_near(c, -1.0, 1e-7);
    fm_sincos(-3.0f * FM_HALF_PI, &s, &c);
    assert_near(s, 1.0, 1e-7);
}

static void atan2_error_bound(void **state)
{
    (void)state;
    double worst = 0.0;
    uint32_t seed = 12345u;
    for (int n = 0; n < 400000; ++n) {
        double th = -PI_D + 2.0 * PI_D * n / 400000.0;
        double r = exp(check_uniform(&seed, -12.0, 8.0));
        float y = (float)(r * sin(th));
        float x = (float)(r * cos(th));
        double ref = atan2((double)y, (double)x);
        double got = (double)fm_atan2(y, x);
        double e = fabs(got - ref);
        if (e > PI_D) {
            e = fabs(e - 2.0 * PI_D); /* +-pi on the negative x axis */
        }
        worst = fmax(worst, e);
    }
    if (!(worst <= FM_ATAN2_MAX_ERR)) {
        fail_msg("atan2 worst error %.3g above bound %.3g", worst, (double)FM_ATAN2_MAX_ERR);
    }
    assert_true(worst > 1e-8);
}

static void atan2_axes_and_origin(void **state)
{
    (void)state;
    assert_true(fm_atan2(0.0f, 0.0f) == 0.0f);
    const double e = FM_ATAN2_MAX_ERR;
    assert_near(fm_atan2(0.0f, 1.0f), 0.0, e);
    assert_near(fm_atan2(1.0f, 0.0f), PI_D / 2, e);
    assert_near(fm_atan2(-1.0f, 0.0f), -PI_D / 2, e);
    assert_near(fm_atan2(0.0f, -1.0f), PI_D, e);
    assert_near(fm_atan2(1.0f, 1.0f), PI_D / 4, e);
    assert_near(fm_atan2(-1.0f, -1.0f), -3 * PI_D / 4, e);
    assert_near(fm_atan2(-1e-30f, -1.0f), -PI_D, e); /* just below the negative x axis */
}

static void sin_error_bound(void **state)
{
    (void)state;
    double worst = 0.0;
    for (int n = -400000; n <= 400000; ++n) {
        float th = (float)(4.0 * PI_D * n / 400000.0);
        worst = fmax(worst, fabs((double)fm_sin(th) - sin((double)th)));
    }
    if (!(worst <= FM_SIN_MAX_ERR)) {
        fail_msg("sin worst error %.3g above bound %.3g", worst, (double)FM_SIN_MAX_ERR);
    }
    assert_true(worst > 1e-7);
}

static void asin_error_bound(void **state)
{
    (void)state;
    double worst = 0.0;
    for (int n = -200000; n <= 200000; ++n) {
        float x = (float)(n / 200000.0);
        worst = fmax(worst, fabs((double)fm_asin(x) - asin((double)x)));
    }
    if (!(worst <= FM_ASIN_MAX_ERR)) {
        fail_msg("asin worst error %.3g above bound %.3g", worst, (double)FM_ASIN_MAX_ERR);
    }
    assert_true(worst > 1e-7);
    /* clamped outside [-1, 1] */
    assert_near(fm_asin(1.5f), PI_D / 2, FM_ASIN_MAX_ERR);
    assert_near(fm_asin(-7.0f), -PI_D / 2, FM_ASIN_MAX_ERR);
}

static void wrap_into_range(void **state)
{
    (void)state;
    assert_near(fm_wrap_pi(0.5f), 0.5, 0.0);
    assert_near(fm_wrap_pi(FM_PI + 0.25f), -PI_D + 0.25, 1e-6);
    assert_near(fm_wrap_pi(-FM_PI - 0.25f), PI_D - 0.25, 1e-6);
    assert_near(fm_wrap_pi(7.0f * FM_TWO_PI + 1.0f), 1.0, 1e-5);
    assert_near(fm_wrap_pi(-1000.0f), remainder(-1000.0, 2 * PI_D), 1e-4);
    for (int n = -2000; n <= 2000; ++n) {
        float w = fm_wrap_pi(0.37f * (float)n);
        assert_true(w >= -FM_PI && w <= FM_PI);
    }
}

/* The saturating conversions: a C cast where it is defined, the type's limits beyond it, 0
 * for NaN (under -fsanitize=float-cast-overflow a plain cast of these stops the test). */
static void float_to_int_saturates(void **state)
{
    (void)state;
    assert_int_equal(fm_trunc_sat_i32(2.9f), 2);
    assert_int_equal(fm_trunc_sat_i32(-2.9f), -2);
    assert_int_equal(fm_trunc_sat_i32(2147483520.0f), 2147483520); /* the largest float below 2^31 */
    assert_int_equal(fm_trunc_sat_i32(2147483648.0f), INT32_MAX);
    assert_int_equal(fm_trunc_sat_i32(-2147483648.0f), INT32_MIN); /* exactly representable */
    assert_int_equal(fm_trunc_sat_i32(-3e9f), INT32_MIN);
    assert_int_equal(fm_trunc_sat_i32(INFINITY), INT32_MAX);
    assert_int_equal(fm_trunc_sat_i32(-INFINITY), INT32_MIN);
    assert_int_equal(fm_trunc_sat_i32(NAN), 0);
    assert_int_equal(fm_trunc_sat_u32(4294967040.0f), 4294967040u); /* the largest float below 2^32 */
    assert_int_equal(fm_trunc_sat_u32(4294967296.0f), UINT32_MAX);
    assert_int_equal(fm_trunc_sat_u32(INFINITY), UINT32_MAX);
    assert_int_equal(fm_trunc_sat_u32(-0.5f), 0u);
    assert_int_equal(fm_trunc_sat_u32(-INFINITY), 0u);
    assert_int_equal(fm_trunc_sat_u32(NAN), 0u);
}

/* A NaN or infinite angle gives a non-finite result, not undefined behaviour: the caller's
 * check (control.c) sees it. */
static void nonfinite_angles_give_nan(void **state)
{
    (void)state;
    const float bad[] = {NAN, INFINITY, -INFINITY};
    for (int k = 0; k < 3; ++k) {
        float s = 0.0f, c = 0.0f;
        fm_sincos(bad[k], &s, &c);
        assert_false(isfinite(s) && isfinite(c));
        assert_false(isfinite(fm_wrap_pi(bad[k])));
        assert_false(isfinite(fm_sin(bad[k])));
    }
    /* finite but far outside the documented range: saturated, so defined, and finite */
    float s = 0.0f, c = 0.0f;
    fm_sincos(1e30f, &s, &c);
    assert_true(isfinite(fm_wrap_pi_slow(1e30f)));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(sincos_error_bound),
        cmocka_unit_test(sincos_quadrants_exact_points),
        cmocka_unit_test(atan2_error_bound),
        cmocka_unit_test(atan2_axes_and_origin),
        cmocka_unit_test(sin_error_bound),
        cmocka_unit_test(asin_error_bound),
        cmocka_unit_test(wrap_into_range),
        cmocka_unit_test(float_to_int_saturates),
        cmocka_unit_test(nonfinite_angles_give_nan),
    };
    return cmocka_run_group_tests_name("fastmath", tests, NULL, NULL);
}
