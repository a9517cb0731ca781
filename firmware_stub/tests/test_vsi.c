/* Gate bits of the six vectors and the stator voltage of Table 2. */
#include "check.h"
#include "vsi.h"

static void table2_voltages(void **state)
{
    (void)state;
    const double vdc = 70.0;
    const double expect[7][2] = {
        {0, 0},
        {2 * vdc / 3, 0},
        {vdc / 3, vdc / sqrt(3.0)},
        {-vdc / 3, vdc / sqrt(3.0)},
        {-2 * vdc / 3, 0},
        {-vdc / 3, -vdc / sqrt(3.0)},
        {vdc / 3, -vdc / sqrt(3.0)},
    };
    for (uint8_t k = 1; k <= 6; ++k) {
        float ua, ub;
        vsi_voltage(vsi_gates_of_vector(k), (float)vdc, &ua, &ub);
        assert_near(ua, expect[k][0], 1e-4);
        assert_near(ub, expect[k][1], 1e-4);
        /* Fig. 2: vector k sits at (k-1) 60 degrees with length 2/3 Vdc */
        assert_near(atan2(ub, ua), remainder((k - 1) * PI_D / 3, 2 * PI_D), 1e-6);
        assert_near(hypot(ua, ub), 2 * vdc / 3, 1e-4);
    }
}

static void gates_complementary(void **state)
{
    (void)state;
    const uint8_t legs[3][2] = {{VSI_GATE_A_HIGH, VSI_GATE_A_LOW},
                                {VSI_GATE_B_HIGH, VSI_GATE_B_LOW},
                                {VSI_GATE_C_HIGH, VSI_GATE_C_LOW}};
    /* switching state strings of Table 2, phase a first */
    const char *states[7] = {"", "100", "110", "010", "011", "001", "101"};
    for (uint8_t k = 1; k <= 6; ++k) {
        uint8_t g = vsi_gates_of_vector(k);
        for (int leg = 0; leg < 3; ++leg) {
            int high = (g & legs[leg][0]) != 0;
            int low = (g & legs[leg][1]) != 0;
            assert_int_equal(high + low, 1);
            assert_int_equal(high, states[k][leg] == '1');
        }
    }
    assert_int_equal(vsi_gates_of_vector(0), 0);
    assert_int_equal(vsi_gates_of_vector(7), 0);
}

static void all_off_is_zero_voltage(void **state)
{
    (void)state;
    float ua = 1.0f, ub = 1.0f;
    vsi_voltage(0u, 70.0f, &ua, &ub);
    assert_true(ua == 0.0f && ub == 0.0f);
    vsi_voltage(VSI_GATE_A_HIGH | VSI_GATE_B_HIGH | VSI_GATE_C_HIGH, 70.0f, &ua, &ub);
    assert_near(ua, 0.0, 1e-6);
    assert_near(ub, 0.0, 1e-6);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(table2_voltages),
        cmocka_unit_test(gates_complementary),
        cmocka_unit_test(all_off_is_zero_voltage),
    };
    return cmocka_run_group_tests_name("vsi", tests, NULL, NULL);
}
