/* Clarke transform eq. (8)-(9) from ADC counts, for each measured phase pair. */
#include "check.h"
#include "clarke.h"

static const float A_PER_COUNT = 0.01220703125f;
static const float OFFSET = 2048.0f;

static uint16_t counts_of(double amps) { return (uint16_t)lround(OFFSET + amps / A_PER_COUNT); }

/* A balanced set i_k = I cos(theta - k 2pi/3) has i_alpha = I cos theta and
 * i_beta = I sin theta (eq. 7). */
static void balanced_set_for_pair(uint8_t phases)
{
    clarke_cfg cfg = {A_PER_COUNT, OFFSET, phases, 0, 0, 0, 0, 0, 0};
    clarke_derive(&cfg);
    const double amp = 12.0;
    /* one count of quantisation on each input: i_beta sums up to 3/sqrt3 of them */
    const double tol = 1.8 * A_PER_COUNT;
    for (int n = 0; n < 360; n += 7) {
        double th = n * PI_D / 180.0;
        double ph[3] = {amp * cos(th), amp * cos(th - 2 * PI_D / 3), amp * cos(th + 2 * PI_D / 3)};
        int first = phases == CLARKE_PHASES_BC ? 1 : 0;
        int second = phases == CLARKE_PHASES_AB ? 1 : 2;
        clarke_out out;
        clarke_from_adc(&cfg, counts_of(ph[first]), counts_of(ph[second]), &out);
        assert_near(out.i_alpha_a, amp * cos(th), tol);
        assert_near(out.i_beta_a, amp * sin(th), tol);
        double peak = fmax(fabs(ph[0]), fmax(fabs(ph[1]), fabs(ph[2])));
        assert_near(out.i_peak_a, peak, tol);
    }
}

static void pair_ab(void **state) { (void)state; balanced_set_for_pair(CLARKE_PHASES_AB); }
static void pair_ac(void **state) { (void)state; balanced_set_for_pair(CLARKE_PHASES_AC); }
static void pair_bc(void **state) { (void)state; balanced_set_for_pair(CLARKE_PHASES_BC); }

static void scaling_and_offset(void **state)
{
    (void)state;
    clarke_cfg cfg = {0.5f, 100.0f, CLARKE_PHASES_AB, 0, 0, 0, 0, 0, 0};
    clarke_derive(&cfg);
    clarke_out out;
    clarke_from_adc(&cfg, 104u, 100u, &out); /* i_a = 2 A, i_b = 0 */
    assert_near(out.i_alpha_a, 2.0, 1e-6);
    assert_near(out.i_beta_a, 2.0 / sqrt(3.0), 1e-6);
    assert_near(out.i_peak_a, 2.0, 1e-6); /* i_c = -2 A */
    clarke_from_adc(&cfg, 100u, 100u, &out);
    assert_near(out.i_alpha_a, 0.0, 0.0);
    assert_near(out.i_beta_a, 0.0, 0.0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(pair_ab),
        cmocka_unit_test(pair_ac),
        cmocka_unit_test(pair_bc),
        cmocka_unit_test(scaling_and_offset),
    };
    return cmocka_run_group_tests_name("clarke", tests, NULL, NULL);
}
