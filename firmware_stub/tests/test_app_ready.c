/* The board's start-up as the bench sees it (SPEC.md 2 item 5, 6.8, 9.4): STATUS(STARTING)
 * at the enable while the zero calibration and the resistance identification run, TELEMETRY
 * state STARTING meanwhile, then STATUS(RUNNING) naming the first period that controls (the
 * board is ready); without a start-up phase IDLE -> RUNNING at once; a trip while starting is
 * FAULT, never RUNNING. Period counts from the parameters set here and SPEC row 67's 1 ms. */
#include <math.h>

#include "app_helpers.h"

static const double CONTROL_PERIOD_S = 50e-6; /* the stub's default, not changed here */

/* Periods the bridge stays open after the two identification levels: SPEC 8 row 67's 1 ms. */
static uint32_t rs_id_off_periods(void) { return (uint32_t)lround(1e-3 / CONTROL_PERIOD_S); }

static void set_param(bench *b, uint16_t id, float value)
{
    hil_msg m = msg_param(HIL_MSG_PARAM_SET, id, value);
    size_t before = b->n_replies;
    bench_send(b, &m);
    assert_int_equal(b->n_replies, before + 1u);
    assert_int_equal(b->replies[before].u.param_value.status, HIL_PARAM_OK);
}

/* Sends SAMPLE k at standstill (no current, encoder still, optional status bits); the replies
 * of this period only are left in b->replies. */
static void sample(bench *b, uint32_t k, uint8_t status_bits)
{
    b->n_replies = 0;
    hil_msg s = msg_sample(k, 0.0, 0.0, 0u);
    s.u.sample.status = status_bits;
    bench_send(b, &s);
    assert_true(b->n_replies >= 2u); /* the answer and (divider 1) the TELEMETRY */
    assert_int_equal(b->replies[1].type, HIL_MSG_TELEMETRY);
    assert_int_equal(b->replies[1].u.telemetry.period, k);
}

static uint8_t telemetry_state(const bench *b) { return b->replies[1].u.telemetry.state; }

static void enable(bench *b, uint8_t flags)
{
    hil_msg m = msg_command(flags, HIL_SPEED_ENCODER, 100.0f);
    b->n_replies = 0;
    bench_send(b, &m);
}

static void expect_status(const bench *b, size_t at, uint8_t state, uint32_t period)
{
    assert_true(at < b->n_replies);
    assert_int_equal(b->replies[at].type, HIL_MSG_STATUS);
    assert_int_equal(b->replies[at].u.status.state, state);
    assert_int_equal(b->replies[at].u.status.period, period);
}

static void without_start_up_idle_to_running_at_once(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    set_param(&b, HIL_PARAM_TELEMETRY_DIVIDER, 1.0f);
    sample(&b, 0u, 0u);
    assert_int_equal(telemetry_state(&b), HIL_STATE_IDLE);
    enable(&b, HIL_CMD_ENABLE);
    assert_int_equal(b.n_replies, 1u);
    expect_status(&b, 0u, HIL_STATE_RUNNING, 1u); /* from the next SAMPLE on: ready */
    for (uint32_t k = 1u; k < 4u; ++k) {
        sample(&b, k, 0u);
        assert_int_equal(telemetry_state(&b), HIL_STATE_RUNNING);
        assert_int_equal(bench_count(&b, HIL_MSG_STATUS), 0u);
    }
    bench_close(&b);
}

static void starting_through_the_calibrations_then_running(void **state)
{
    (void)state;
    const uint32_t zero_cal = 4u, rs_id = 8u;
    bench b;
    bench_open(&b);
    set_param(&b, HIL_PARAM_TELEMETRY_DIVIDER, 1.0f);
    set_param(&b, HIL_PARAM_CURRENT_ZERO_CAL_PERIODS, (float)zero_cal);
    set_param(&b, HIL_PARAM_RS_ID_PERIODS, (float)rs_id);
    for (uint32_t k = 0u; k < 3u; ++k) {
        sample(&b, k, 0u);
    }
    const uint32_t enabled_at = 3u;
    enable(&b, HIL_CMD_ENABLE);
    assert_int_equal(b.n_replies, 1u);
    expect_status(&b, 0u, HIL_STATE_STARTING, enabled_at);
    /* zero calibration, two identification levels, the bridge open: all STARTING */
    const uint32_t ready_at = enabled_at + zero_cal + 2u * rs_id + rs_id_off_periods();
    for (uint32_t k = enabled_at; k < ready_at; ++k) {
        sample(&b, k, 0u);
        assert_int_equal(telemetry_state(&b), HIL_STATE_STARTING);
        assert_int_equal(bench_count(&b, HIL_MSG_STATUS), 0u);
    }
    /* the first period that controls: its TELEMETRY says RUNNING, and STATUS(RUNNING) for it
     * follows the answer */
    sample(&b, ready_at, 0u);
    assert_int_equal(telemetry_state(&b), HIL_STATE_RUNNING);
    assert_int_equal(bench_count(&b, HIL_MSG_STATUS), 1u);
    expect_status(&b, b.n_replies - 1u, HIL_STATE_RUNNING, ready_at);
    assert_int_equal(b.replies[b.n_replies - 1u].u.status.fault_code, HIL_FAULT_NONE);
    sample(&b, ready_at + 1u, 0u);
    assert_int_equal(bench_count(&b, HIL_MSG_STATUS), 0u);

    /* disabled and enabled again: IDLE, then STARTING for the zero calibration only (the
     * resistance is identified once) */
    enable(&b, 0u);
    expect_status(&b, 0u, HIL_STATE_IDLE, ready_at + 2u);
    enable(&b, HIL_CMD_ENABLE);
    expect_status(&b, 0u, HIL_STATE_STARTING, ready_at + 2u);
    for (uint32_t k = ready_at + 2u; k < ready_at + 2u + zero_cal; ++k) {
        sample(&b, k, 0u);
        assert_int_equal(telemetry_state(&b), HIL_STATE_STARTING);
        assert_int_equal(bench_count(&b, HIL_MSG_STATUS), 0u);
    }
    sample(&b, ready_at + 2u + zero_cal, 0u);
    expect_status(&b, b.n_replies - 1u, HIL_STATE_RUNNING, ready_at + 2u + zero_cal);
    bench_close(&b);
}

/* A resent SAMPLE of the period that became ready gets its answer again, not a second STATUS. */
static void resent_ready_sample_repeats_only_the_answer(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    set_param(&b, HIL_PARAM_TELEMETRY_DIVIDER, 1.0f);
    set_param(&b, HIL_PARAM_CURRENT_ZERO_CAL_PERIODS, 2.0f);
    enable(&b, HIL_CMD_ENABLE);
    expect_status(&b, 0u, HIL_STATE_STARTING, 0u);
    sample(&b, 0u, 0u);
    sample(&b, 1u, 0u);
    sample(&b, 2u, 0u);
    expect_status(&b, b.n_replies - 1u, HIL_STATE_RUNNING, 2u);
    b.n_replies = 0;
    hil_msg again = msg_sample(2u, 0.0, 0.0, 0u);
    bench_send(&b, &again);
    assert_int_equal(b.n_replies, 1u);
    assert_int_equal(b.replies[0].type, HIL_MSG_GATES);
    bench_close(&b);
}

/* A protection that trips while starting (the identification drives current: the hardware
 * overcurrent line is armed) ends the start-up in FAULT: FAULT, STATUS(FAULT), never RUNNING. */
static void trip_while_starting_is_fault_not_running(void **state)
{
    (void)state;
    const uint32_t zero_cal = 2u;
    bench b;
    bench_open(&b);
    set_param(&b, HIL_PARAM_TELEMETRY_DIVIDER, 1.0f);
    set_param(&b, HIL_PARAM_CURRENT_ZERO_CAL_PERIODS, (float)zero_cal);
    set_param(&b, HIL_PARAM_RS_ID_PERIODS, 8.0f);
    enable(&b, HIL_CMD_ENABLE);
    expect_status(&b, 0u, HIL_STATE_STARTING, 0u);
    for (uint32_t k = 0u; k < zero_cal + 1u; ++k) {
        sample(&b, k, 0u);
        assert_int_equal(telemetry_state(&b), HIL_STATE_STARTING);
    }
    const uint32_t trip_at = zero_cal + 1u; /* the second identification period */
    sample(&b, trip_at, HIL_STATUS_OVERCURRENT);
    assert_int_equal(telemetry_state(&b), HIL_STATE_FAULT);
    int f = bench_find(&b, HIL_MSG_FAULT, 0u);
    assert_true(f >= 0);
    assert_int_equal(b.replies[f].u.fault.code, HIL_FAULT_OVERCURRENT);
    assert_int_equal(bench_count(&b, HIL_MSG_STATUS), 1u);
    expect_status(&b, (size_t)bench_find(&b, HIL_MSG_STATUS, 0u), HIL_STATE_FAULT, trip_at);
    for (uint32_t k = trip_at + 1u; k < trip_at + 40u; ++k) {
        sample(&b, k, 0u);
        assert_int_equal(telemetry_state(&b), HIL_STATE_FAULT);
        assert_int_equal(bench_count(&b, HIL_MSG_STATUS), 0u);
    }
    bench_close(&b);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(without_start_up_idle_to_running_at_once),
        cmocka_unit_test(starting_through_the_calibrations_then_running),
        cmocka_unit_test(resent_ready_sample_repeats_only_the_answer),
        cmocka_unit_test(trip_while_starting_is_fault_not_running),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
