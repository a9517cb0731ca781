/* Sector and Table 3, checked against the geometry of Fig. 2. */
#include "check.h"
#include "flux_observer.h"
#include "switching_table.h"
#include "vsi.h"

static void sector_of_angle(void **state)
{
    (void)state;
    for (int k = 1; k <= 6; ++k) {
        double centre = (k - 1) * PI_D / 3;
        for (int d = -29; d <= 29; d += 2) {
            double th = centre + d * PI_D / 180;
            for (int m = 0; m < 3; ++m) {
                double r = m == 0 ? 1e-3 : (m == 1 ? 0.1 : 5.0);
                assert_int_equal(swtab_sector((float)(r * cos(th)), (float)(r * sin(th))), k);
            }
        }
    }
}

/* The angle form (what ctl_step uses, from the eq. (10) angle) agrees with the
 * vector form on a dense grid of angles, except within 1e-5 rad of a sector
 * boundary, where either answer is right; -pi and pi are both sector IV. */
static void sector_of_angle_matches_vector_form(void **state)
{
    (void)state;
    int checked = 0;
    for (int n = 0; n <= 200000; ++n) {
        double th = -PI_D + n * (2.0 * PI_D / 200000.0);
        double to_boundary = fmod(th + PI_D / 6.0 + 4.0 * PI_D, PI_D / 3.0);
        if (to_boundary < 1e-5 || PI_D / 3.0 - to_boundary < 1e-5) {
            continue;
        }
        float thf = (float)th;
        assert_int_equal(swtab_sector_of_angle(thf), swtab_sector(cosf(thf), sinf(thf)));
        ++checked;
    }
    assert_true(checked > 199000);
    assert_int_equal(swtab_sector_of_angle(-(float)PI_D), 4);
    assert_int_equal(swtab_sector_of_angle((float)PI_D), 4);
    /* outside [-pi, pi] and NaN: clamped, never a read outside the table */
    assert_true(swtab_sector_of_angle(100.0f) >= 1 && swtab_sector_of_angle(100.0f) <= 6);
    assert_true(swtab_sector_of_angle(-100.0f) >= 1 && swtab_sector_of_angle(-100.0f) <= 6);
    assert_true(swtab_sector_of_angle(NAN) >= 1 && swtab_sector_of_angle(NAN) <= 6);
}

static void table_is_the_rotation_rule(void **state)
{
    (void)state;
    /* sector k: (1,1) -> k+1, (1,0) -> k-1, (0,1) -> k+2, (0,0) -> k-2 */
    const int offset[4] = {1, -1, 2, -2};
    for (int k = 1; k <= 6; ++k) {
        for (int col = 0; col < 4; ++col) {
            int expect = ((k - 1 + offset[col] + 6) % 6) + 1;
            assert_int_equal(swtab_table3[k - 1][col], expect);
            uint8_t flux_up = col < 2, torque_up = (col % 2) == 0;
            assert_int_equal(swtab_vector((uint8_t)k, flux_up, torque_up), expect);
        }
    }
}

/* Fig. 2: for a flux anywhere inside sector k, the chosen vector's component
 * along the flux has the sign of the flux column and its component across the
 * flux (counter-clockwise) the sign of the torque column. */
static void vectors_move_flux_and_angle_as_promised(void **state)
{
    (void)state;
    for (int k = 1; k <= 6; ++k) {
        for (int d = -29; d <= 29; d += 1) {
            double th = (k - 1) * PI_D / 3 + d * PI_D / 180;
            float pa = (float)(0.1 * cos(th)), pb = (float)(0.1 * sin(th));
            uint8_t sector = swtab_sector(pa, pb);
            for (int col = 0; col < 4; ++col) {
                uint8_t flux_up = col < 2, torque_up = (col % 2) == 0;
                uint8_t v = swtab_vector(sector, flux_up, torque_up);
                float ua, ub;
                vsi_voltage(vsi_gates_of_vector(v), 70.0f, &ua, &ub);
                double along = ua * cos(th) + ub * sin(th);
                double across = -ua * sin(th) + ub * cos(th);
                assert_true(flux_up ? along > 0 : along < 0);
                assert_true(torque_up ? across > 0 : across < 0);
            }
        }
    }
}

/* The same promise on a surface-magnet motor: one 50-us period of the chosen
 * vector changes |psi| and the torque of eq. (6) (currents from
 * i = (psi - psi_f e^{j theta_r}) / Ls, rotor still) in the promised direction.
 * For the torque this holds for load angles up to 30 degrees: with the flux at
 * the start of its sector, V(k-1) is only 30 degrees behind the stator flux,
 * i.e. 30 - delta behind the rotor flux, and the torque falls only while that
 * is positive. Beyond 30 degrees the promise holds for the flux angle. */
static void one_period_on_a_motor(void **state)
{
    (void)state;
    const double psi_f = 0.0928, ls = 4.8e-3, t = 50e-6, vdc = 70.0;
    const double deltas[3] = {5.0, 15.0, 28.0};
    for (int k = 1; k <= 6; ++k) {
        for (int d = -29; d <= 29; d += 2) {
            for (int m = 0; m < 3; ++m) {
                double ths = (k - 1) * PI_D / 3 + d * PI_D / 180;
                double thr = ths - deltas[m] * PI_D / 180;
                double pa = 0.099 * cos(ths), pb = 0.099 * sin(ths);
                double ra = psi_f * cos(thr), rb = psi_f * sin(thr);
                double t0 = torque_estimate(1.0f, (float)pa, (float)pb, (float)((pa - ra) / ls),
                                            (float)((pb - rb) / ls));
                for (int col = 0; col < 4; ++col) {
                    uint8_t flux_up = col < 2, torque_up = (col % 2) == 0;
                    uint8_t v = swtab_vector(swtab_sector((float)pa, (float)pb), flux_up, torque_up);
                    float ua, ub;
                    vsi_voltage(vsi_gates_of_vector(v), (float)vdc, &ua, &ub);
                    double na = pa + t * ua, nb = pb + t * ub;
                    double t1 = torque_estimate(1.0f, (float)na, (float)nb, (float)((na - ra) / ls),
                                                (float)((nb - rb) / ls));
                    double dmag = hypot(na, nb) - 0.099;
                    assert_true(flux_up ? dmag > 0 : dmag < 0);
                    assert_true(torque_up ? t1 > t0 : t1 < t0);
                }
            }
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(sector_of_angle),
        cmocka_unit_test(sector_of_angle_matches_vector_form),
        cmocka_unit_test(table_is_the_rotation_rule),
        cmocka_unit_test(vectors_move_flux_and_angle_as_promised),
        cmocka_unit_test(one_period_on_a_motor),
    };
    return cmocka_run_group_tests_name("switching_table", tests, NULL, NULL);
}
