/* Space-vector PWM: the average voltage equals the request, linear range,
 * limit, dead-time compensation, DUTY quantisation. */
#include "check.h"
#include "svpwm.h"

#define VDC 70.0f

/* The inverter's average stator voltage for leg duties (Table 2 averaged):
 * u_alpha = Vdc (2 da - db - dc)/3, u_beta = Vdc (db - dc)/sqrt3. */
static void applied(const float d[3], double *ua, double *ub)
{
    *ua = VDC * (2.0 * d[0] - d[1] - d[2]) / 3.0;
    *ub = VDC * ((double)d[1] - d[2]) / sqrt(3.0);
}

static void average_voltage_equals_request(void **state)
{
    (void)state;
    uint32_t seed = 1u;
    for (int n = 0; n < 20000; ++n) {
        double r = check_uniform(&seed, 0.0, VDC / sqrt(3.0));
        double th = check_uniform(&seed, -PI_D, PI_D);
        float ua = (float)(r * cos(th)), ub = (float)(r * sin(th));
        float d[3];
        svpwm_duties(ua, ub, VDC, d);
        double aa, ab;
        applied(d, &aa, &ab);
        assert_near(aa, ua, 2e-5 * VDC);
        assert_near(ab, ub, 2e-5 * VDC);
        for (int x = 0; x < 3; ++x) {
            assert_true(d[x] >= -1e-6f && d[x] <= 1.0f + 1e-6f);
        }
        /* min-max zero sequence: the pulses are centred in the period */
        float hi = fmaxf(d[0], fmaxf(d[1], d[2])), lo = fminf(d[0], fminf(d[1], d[2]));
        assert_near(hi + lo, 1.0, 1e-6);
    }
}

static void linear_range_is_the_inscribed_circle(void **state)
{
    (void)state;
    /* on the circle |u| = Vdc/sqrt3 the duties span exactly 0..1 where the
     * circle touches the hexagon (30 deg between V1 and V2), less elsewhere */
    float d[3];
    float r = VDC / sqrtf(3.0f);
    svpwm_duties(r * cosf((float)(PI_D / 6)), r * sinf((float)(PI_D / 6)), VDC, d);
    assert_near(fmaxf(d[0], fmaxf(d[1], d[2])), 1.0, 1e-6);
    assert_near(fminf(d[0], fminf(d[1], d[2])), 0.0, 1e-6);
    svpwm_duties(r, 0.0f, VDC, d); /* along V1: sqrt3/2 of the span */
    assert_near(d[0] - d[1], sqrt(3.0) / 2.0, 1e-6);
}

static void limit_scales_onto_the_circle(void **state)
{
    (void)state;
    float ua = 60.0f, ub = -45.0f; /* 75 V, beyond 40.4 V */
    assert_int_equal(svpwm_limit(VDC, &ua, &ub), 1);
    assert_near(sqrt((double)ua * ua + (double)ub * ub), VDC / sqrt(3.0), 1e-4);
    assert_near(atan2(ub, ua), atan2(-45.0, 60.0), 1e-6);
    float va = 20.0f, vb = 10.0f;
    assert_int_equal(svpwm_limit(VDC, &va, &vb), 0);
    assert_true(va == 20.0f && vb == 10.0f);
}

static void dead_time_compensation_by_current_sign(void **state)
{
    (void)state;
    svpwm_cfg cfg = {50e-6f, 1e-6f, 0.1f, 0.0f, 0.0f};
    svpwm_derive(&cfg);
    assert_near(cfg.dead_time_duty, 0.02, 1e-7);
    float d[3] = {0.5f, 0.5f, 0.995f};
    const float i[3] = {5.0f, -0.05f, 3.0f};
    svpwm_dead_time_comp(&cfg, i, d);
    assert_near(d[0], 0.52, 1e-6);  /* current out of the leg: + Td/T */
    assert_near(d[1], 0.49, 1e-6);  /* inside the band: linear, -0.05/0.1 x Td/T */
    assert_near(d[2], 1.0, 0.0);    /* clamped */
    svpwm_cfg off = {50e-6f, 0.0f, 0.1f, 0.0f, 0.0f};
    svpwm_derive(&off);
    float e[3] = {0.3f, 0.4f, 0.5f};
    svpwm_dead_time_comp(&off, i, e);
    assert_true(e[0] == 0.3f && e[1] == 0.4f && e[2] == 0.5f);
}

static void duty_quantisation(void **state)
{
    (void)state;
    assert_int_equal(svpwm_duty_u16(0.0f), 0);
    assert_int_equal(svpwm_duty_u16(1.0f), 65535);
    assert_int_equal(svpwm_duty_u16(0.5f), 32768);
    assert_int_equal(svpwm_duty_u16(-0.1f), 0);
    assert_int_equal(svpwm_duty_u16(1.5f), 65535);
    assert_int_equal(svpwm_duty_u16(NAN), 0);
    assert_int_equal(svpwm_duty_u16(1.0f / 65535.0f), 1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(average_voltage_equals_request),
        cmocka_unit_test(linear_range_is_the_inscribed_circle),
        cmocka_unit_test(limit_scales_onto_the_circle),
        cmocka_unit_test(dead_time_compensation_by_current_sign),
        cmocka_unit_test(duty_quantisation),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
