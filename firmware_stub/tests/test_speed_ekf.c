/* Simplified EKF eq. (20)-(23) on a synthetic rotating unit vector. */
#include "check.h"
#include "defaults.h"
#include "speed_ekf.h"

static const ekf_cfg CFG = {50e-6f, CTL_DEFAULT_EKF_K1, CTL_DEFAULT_EKF_K2_RAD_S, CTL_DEFAULT_EKF_K3_RAD_S};

static void one_step_matches_equations(void **state)
{
    (void)state;
    ekf_state st;
    ekf_reset(&st, 0.3f, 100.0f);
    st.speed_increment_rad_s = 0.01f;
    double th = 0.35; /* measured angle */
    ekf_step(&CFG, &st, (float)cos(th), (float)sin(th));
    double eps = sin(th) * cos(0.3) - cos(th) * sin(0.3); /* eq. (20) = sin(0.05) */
    assert_near(eps, sin(0.05), 1e-12);
    assert_near(st.theta_rad, 0.3 + 50e-6 * 100.0 + CFG.k1 * eps, 1e-6);
    assert_near(st.speed_rad_s, 100.0 + 0.01 + CFG.k2_rad_s * eps, 1e-4);
    assert_near(st.speed_increment_rad_s, 0.01 + CFG.k3_rad_s * eps, 1e-6);
    assert_near(st.theta_filtered_rad, 0.3 + CFG.k1 * eps, 1e-6);
}

/* Runs the EKF on theta(t) = theta0 + w0 t + a t^2 / 2 from a given initial
 * estimate; returns the final speed and angle errors. */
static void track(double w0, double accel, double est_speed, int steps, double *speed_err, double *angle_err,
                  double *worst_speed_err_after)
{
    ekf_state st;
    ekf_reset(&st, 0.0f, (float)est_speed);
    *worst_speed_err_after = 0.0;
    for (int n = 0; n < steps; ++n) {
        double t = n * 50e-6;
        double th = w0 * t + 0.5 * accel * t * t;
        ekf_step(&CFG, &st, (float)cos(th), (float)sin(th));
        double w_true = w0 + accel * (t + 50e-6);
        double err = st.speed_rad_s - w_true;
        if (n > steps / 2) {
            *worst_speed_err_after = fmax(*worst_speed_err_after, fabs(err));
        }
        *speed_err = err;
        *angle_err = remainder(st.theta_rad - (w0 * (t + 50e-6) + 0.5 * accel * (t + 50e-6) * (t + 50e-6)), 2 * PI_D);
    }
}

static void tracks_constant_speed(void **state)
{
    (void)state;
    double se, ae, worst;
    track(314.159, 0.0, 314.159, 4000, &se, &ae, &worst);
    assert_near(se, 0.0, 0.05);
    assert_near(ae, 0.0, 1e-4);
}

static void converges_from_wrong_initial_speed(void **state)
{
    (void)state;
    const double wrong[3] = {0.0, 150.0, -100.0};
    for (int k = 0; k < 3; ++k) {
        double se, ae, worst;
        track(314.159, 0.0, wrong[k], 4000, &se, &ae, &worst); /* 0.2 s */
        assert_near(se, 0.0, 0.05);
        assert_near(ae, 0.0, 1e-4);
        assert_true(worst < 0.5);
    }
}

static void tracks_speed_ramp(void **state)
{
    (void)state;
    /* the torque limit's acceleration, 2 Nm / 8e-4 kg m^2: a type-3 loop follows
     * a speed ramp with no steady-state error */
    double se, ae, worst;
    track(0.0, 2500.0, 0.0, 4000, &se, &ae, &worst);
    assert_near(se, 0.0, 0.1);
    assert_near(ae, 0.0, 1e-3);
    assert_true(worst < 0.2);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(one_step_matches_equations),
        cmocka_unit_test(tracks_constant_speed),
        cmocka_unit_test(converges_from_wrong_initial_speed),
        cmocka_unit_test(tracks_speed_ramp),
    };
    return cmocka_run_group_tests_name("speed_ekf", tests, NULL, NULL);
}
