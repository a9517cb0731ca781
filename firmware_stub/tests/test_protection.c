/* Overcurrent, plant comparator bits and encoder-loss detection. */
#include "check.h"
#include "protection.h"

static prot_cfg CFG;

static int setup(void **state)
{
    (void)state;
    prot_cfg cfg = {20.0f, 0.01f, 10.0f, 50e-6f, 0u};
    prot_derive(&cfg);
    CFG = cfg;
    return 0;
}

static void overcurrent_threshold_and_bits(void **state)
{
    (void)state;
    float v = -1.0f;
    assert_int_equal(prot_hardware(&CFG, 19.9f, 70.0f, 0u, &v), PROT_FAULT_NONE);
    assert_int_equal(prot_hardware(&CFG, 20.1f, 70.0f, 0u, &v), PROT_FAULT_OVERCURRENT);
    assert_near(v, 20.1, 1e-6);
    assert_int_equal(prot_hardware(&CFG, 3.0f, 70.0f, PROT_STATUS_OVERCURRENT, &v), PROT_FAULT_OVERCURRENT);
    assert_int_equal(prot_hardware(&CFG, 3.0f, 70.0f, PROT_STATUS_GATE_FAULT, &v), PROT_FAULT_OVERCURRENT);
    assert_int_equal(prot_hardware(&CFG, 3.0f, 95.0f, PROT_STATUS_OVERVOLTAGE, &v), PROT_FAULT_DC_LINK);
    assert_near(v, 95.0, 1e-6);
    /* the index pulse bit is not a fault */
    assert_int_equal(prot_hardware(&CFG, 3.0f, 70.0f, 0x01u, &v), PROT_FAULT_NONE);
}

/* Steps until the trip with the counter frozen at 7; -1 if none within max. */
static int steps_to_trip(prot_state *st, float speed, int encoder_selected, int max)
{
    float v;
    for (int n = 1; n <= max; ++n) {
        if (prot_encoder_loss(&CFG, st, 7u, speed, encoder_selected, &v) == PROT_FAULT_ENCODER_LOSS) {
            assert_near(v, n * 50e-6, 1e-9); /* seconds without an edge */
            return n;
        }
    }
    return -1;
}

static void encoder_loss_after_timeout(void **state)
{
    (void)state;
    prot_state st;
    prot_reset(&st, 7u);
    /* 0.01 s = 200 periods; trips on the first period beyond */
    assert_int_equal(CFG.encoder_loss_timeout_periods, 200);
    assert_int_equal(steps_to_trip(&st, -50.0f, 1, 1000), 201);
}

static void encoder_loss_needs_turning_and_encoder_feedback(void **state)
{
    (void)state;
    prot_state st;
    prot_reset(&st, 7u);
    assert_int_equal(steps_to_trip(&st, 5.0f, 1, 2000), -1);   /* below the minimum speed */
    assert_int_equal(steps_to_trip(&st, 300.0f, 0, 2000), -1); /* sensorless: not watched */
}

static void moving_counter_resets_timer(void **state)
{
    (void)state;
    prot_state st;
    prot_reset(&st, 7u);
    float v;
    for (int n = 0; n < 150; ++n) {
        assert_int_equal(prot_encoder_loss(&CFG, &st, 7u, 100.0f, 1, &v), PROT_FAULT_NONE);
    }
    assert_int_equal(prot_encoder_loss(&CFG, &st, 8u, 100.0f, 1, &v), PROT_FAULT_NONE);
    for (int n = 0; n < 150; ++n) {
        assert_int_equal(prot_encoder_loss(&CFG, &st, 8u, 100.0f, 1, &v), PROT_FAULT_NONE);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(overcurrent_threshold_and_bits),
        cmocka_unit_test(encoder_loss_after_timeout),
        cmocka_unit_test(encoder_loss_needs_turning_and_encoder_feedback),
        cmocka_unit_test(moving_counter_resets_timer),
    };
    return cmocka_run_group_tests_name("protection", tests, setup, NULL);
}
