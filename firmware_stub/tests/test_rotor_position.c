/* Load angle eq. (25) and rotor position eq. (26) on a surface-magnet motor,
 * where eq. (24) is exact: T = 3p/(2Ls) |psi_s| psi_r sin(theta_s - theta_r). */
#include "check.h"
#include "fastmath.h"
#include "flux_observer.h"
#include "rotor_position.h"

static void recovers_rotor_angle(void **state)
{
    (void)state;
    const float ls = 4.8e-3f, psi_f = 0.0928f;
    const float pole_pairs[2] = {1.0f, 3.0f};
    for (int pp = 0; pp < 2; ++pp) {
        rotor_cfg cfg = {ls, psi_f, pole_pairs[pp], 0.0f};
        rotor_derive(&cfg);
        for (int a = -170; a <= 180; a += 25) {
            for (int d = -60; d <= 60; d += 10) {
                for (int m = 0; m < 2; ++m) {
                    double thr = a * PI_D / 180;
                    double ths = thr + d * PI_D / 180;
                    double mag = m ? 0.099 : 0.13;
                    double pa = mag * cos(ths), pb = mag * sin(ths);
                    /* stator current of the SPM motor for this flux and rotor */
                    double ia = (pa - psi_f * cos(thr)) / ls, ib = (pb - psi_f * sin(thr)) / ls;
                    float t = torque_estimate(cfg.pole_pairs, (float)pa, (float)pb, (float)ia, (float)ib);
                    float delta = rotor_load_angle(&cfg, t, flux_magnitude((float)pa, (float)pb));
                    assert_near(delta, d * PI_D / 180, 2e-5);
                    double thr_est = (double)fm_atan2((float)pb, (float)pa) - delta;
                    assert_near(remainder(thr_est - thr, 2 * PI_D), 0.0, 3e-5);
                }
            }
        }
    }
}

static void clamps_beyond_pull_out_and_zero_flux(void **state)
{
    (void)state;
    rotor_cfg cfg = {4.8e-3f, 0.0928f, 1.0f, 0.0f};
    rotor_derive(&cfg);
    assert_near(rotor_load_angle(&cfg, 100.0f, 0.1f), PI_D / 2, 1e-6);
    assert_near(rotor_load_angle(&cfg, -100.0f, 0.1f), -PI_D / 2, 1e-6);
    assert_near(rotor_load_angle(&cfg, 1.0f, 0.0f), 0.0, 0.0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(recovers_rotor_angle),
        cmocka_unit_test(clamps_beyond_pull_out_and_zero_flux),
    };
    return cmocka_run_group_tests_name("rotor_position", tests, NULL, NULL);
}
