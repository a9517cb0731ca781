/* The application layer's side of NON_FINITE (SPEC.md 9.6): a COMMAND whose reference is NaN
 * or infinite is refused with FAULT 6, value 8 (COMMAND), and the drive answers GATES 0;
 * a PARAM_SET of NaN is answered OUT_OF_RANGE with the old value. */
#include "app_helpers.h"

static void nonfinite_command_reference_is_a_nonfinite_fault(void **state)
{
    (void)state;
    const float bad[] = {NAN, INFINITY, -INFINITY};
    for (int k = 0; k < 3; ++k) {
        bench b;
        bench_open(&b);
        hil_msg m = msg_sample(0, 0, 0, 0);
        bench_send(&b, &m);
        m = msg_command(HIL_CMD_ENABLE, HIL_SPEED_ENCODER, bad[k]);
        bench_send(&b, &m);
        int f = bench_find(&b, HIL_MSG_FAULT, 0);
        assert_true(f >= 0);
        assert_int_equal(b.replies[f].u.fault.code, HIL_FAULT_NON_FINITE);
        assert_near(b.replies[f].u.fault.value, (double)HIL_NONFINITE_COMMAND, 0.0);
        int st = bench_find(&b, HIL_MSG_STATUS, (size_t)f);
        assert_true(st > f);
        assert_int_equal(b.replies[st].u.status.state, HIL_STATE_FAULT);
        assert_int_equal(b.replies[st].u.status.fault_code, HIL_FAULT_NON_FINITE);
        size_t before = b.n_replies;
        m = msg_sample(1, 3.0, -1.0, 0);
        bench_send(&b, &m);
        int g = bench_find(&b, HIL_MSG_GATES, before);
        assert_true(g >= 0);
        assert_int_equal(b.replies[g].u.gates.gates, 0u);
        bench_close(&b);
    }
}

static void nan_parameter_is_out_of_range(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    hil_msg m = msg_param(HIL_MSG_PARAM_SET, HIL_PARAM_OVERCURRENT_A, NAN);
    bench_send(&b, &m);
    int v = bench_find(&b, HIL_MSG_PARAM_VALUE, 0);
    assert_true(v >= 0);
    assert_int_equal(b.replies[v].u.param_value.status, HIL_PARAM_OUT_OF_RANGE);
    assert_near(b.replies[v].u.param_value.value, 20.0, 0.0); /* the default, kept */
    bench_close(&b);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(nonfinite_command_reference_is_a_nonfinite_fault),
        cmocka_unit_test(nan_parameter_is_out_of_range),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
