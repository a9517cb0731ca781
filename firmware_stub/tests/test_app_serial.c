/* The application layer over the serial framing: every message of the session
 * flow of protocol/SPEC.md section 2, through the real codec. */
#include "app_helpers.h"

static void hello_answered_with_build_name(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    hil_msg h = msg_hello();
    bench_send(&b, &h);
    assert_int_equal(b.n_replies, 1);
    const hil_hello *r = &b.replies[0].u.hello;
    assert_int_equal(b.replies[0].type, HIL_MSG_HELLO);
    assert_int_equal(r->proto_version, HIL_PROTO_VERSION);
    assert_int_equal(r->role, HIL_ROLE_CONTROLLER);
    assert_int_equal(r->capabilities, HIL_CAP_GATES | HIL_CAP_DUTY | HIL_CAP_TELEMETRY | HIL_CAP_CAN);
    assert_int_equal(r->control_period_ns, 50000u);
    assert_true(r->name_len <= HIL_NAME_MAX);
    assert_int_equal(r->name_len, strlen(hil_stub_name()));
    assert_memory_equal(r->name, hil_stub_name(), r->name_len);
    assert_memory_equal(r->name, "hil-stub " HIL_STUB_VERSION " ", 13);
    assert_int_equal(b.replies[0].seq, 0); /* the controller's first frame */
    /* every HELLO is answered (the bench may retry) */
    bench_send(&b, &h);
    assert_int_equal(bench_count(&b, HIL_MSG_HELLO), 2);
    assert_int_equal(b.replies[1].seq, 1);
    bench_close(&b);
}

/* The period is a parameter: the stub takes the one the bench's HELLO announces when it is
 * in CONTROL_PERIOD_S's range (and says so), keeps its own otherwise. */
static void hello_period_taken_when_in_range(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    hil_msg h = msg_hello();
    h.u.hello.control_period_ns = 5000u;
    bench_send(&b, &h);
    assert_int_equal(b.replies[0].u.hello.control_period_ns, 5000u);
    h.u.hello.control_period_ns = 20000000u;       /* 20 ms: above the 10 ms maximum */
    bench_send(&b, &h);
    assert_int_equal(b.replies[1].u.hello.control_period_ns, 5000u);
    h.u.hello.control_period_ns = 0u;              /* none announced: ours stays */
    bench_send(&b, &h);
    assert_int_equal(b.replies[2].u.hello.control_period_ns, 5000u);
    bench_close(&b);
}

/* A HEARTBEAT frame of header version 2, CRC and COBS by hand (the codec encodes version 1
 * only): into wire (16 bytes), leading and trailing delimiter; returns its length. */
static size_t other_version_frame(uint8_t *wire)
{
    uint8_t raw[] = {2, HIL_MSG_HEARTBEAT, 0, 4, 1, 0, 0, 0, 0, 0};
    uint16_t crc = hil_crc16(raw, 8);
    raw[8] = (uint8_t)crc;
    raw[9] = (uint8_t)(crc >> 8);
    size_t w = 0, code_at = 0;
    wire[w++] = 0;
    uint8_t code = 1;
    for (size_t i = 0; i < sizeof raw; ++i) {
        if (raw[i] == 0) {
            wire[code_at] = code;
            code_at = w++;
            code = 1;
        } else {
            wire[w++] = raw[i];
            code++;
        }
    }
    wire[code_at] = code;
    wire[w++] = 0;
    return w;
}

static void other_version_gets_hello_and_nothing_else(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    hil_msg h = msg_hello();
    h.u.hello.proto_version = 2;
    bench_send(&b, &h);
    assert_int_equal(bench_count(&b, HIL_MSG_HELLO), 1);
    hil_msg s = msg_sample(0, 0, 0, 0);
    bench_send(&b, &s);
    assert_int_equal(b.n_replies, 1); /* no GATES */
    /* a frame with another header version: counted, answered with our HELLO */
    uint8_t wire[16];
    size_t w = other_version_frame(wire);
    bench_send_bytes(&b, wire, w);
    assert_int_equal(bench_count(&b, HIL_MSG_HELLO), 2);
    bench_close(&b);
}

/* Frames in one buffer are answered in their order: each frame of another version gets its
 * HELLO where it ended, before what the frames after it are answered with. */
static void answers_in_frame_order_within_one_buffer(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    uint8_t buf[64];
    size_t n = other_version_frame(buf);
    hil_msg get = msg_param(HIL_MSG_PARAM_GET, HIL_PARAM_TORQUE_LIMIT_NM, 0.0f);
    n += bench_encode(&b, &get, buf + n, sizeof buf - n);
    n += other_version_frame(buf + n);
    bench_send_bytes(&b, buf, n);
    assert_int_equal(b.n_replies, 3);
    assert_int_equal(b.replies[0].type, HIL_MSG_HELLO);
    assert_int_equal(b.replies[1].type, HIL_MSG_PARAM_VALUE);
    assert_int_equal(b.replies[2].type, HIL_MSG_HELLO);
    bench_close(&b);
}

static void parameter_round_trip_and_statuses(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    hil_msg m = msg_param(HIL_MSG_PARAM_SET, HIL_PARAM_TORQUE_LIMIT_NM, 1.5f);
    bench_send(&b, &m);
    m = msg_param(HIL_MSG_PARAM_GET, HIL_PARAM_TORQUE_LIMIT_NM, 0.0f);
    bench_send(&b, &m);
    m = msg_param(HIL_MSG_PARAM_SET, 77u, 1.0f);
    bench_send(&b, &m);
    m = msg_param(HIL_MSG_PARAM_SET, HIL_PARAM_CURRENT_PHASES, 5.0f);
    bench_send(&b, &m);
    m = msg_param(HIL_MSG_PARAM_SET, HIL_PARAM_CONTROL_STEP_CYCLES, 5.0f);
    bench_send(&b, &m);
    assert_int_equal(b.n_replies, 5);
    const struct {
        uint16_t id;
        uint8_t status;
        float value;
    } expect[5] = {
        {HIL_PARAM_TORQUE_LIMIT_NM, HIL_PARAM_OK, 1.5f},
        {HIL_PARAM_TORQUE_LIMIT_NM, HIL_PARAM_OK, 1.5f},
        {77u, HIL_PARAM_UNKNOWN, 0.0f},
        {HIL_PARAM_CURRENT_PHASES, HIL_PARAM_OUT_OF_RANGE, 0.0f},
        {HIL_PARAM_CONTROL_STEP_CYCLES, HIL_PARAM_READ_ONLY, 0.0f},
    };
    for (int i = 0; i < 5; ++i) {
        assert_int_equal(b.replies[i].type, HIL_MSG_PARAM_VALUE);
        assert_int_equal(b.replies[i].u.param_value.id, expect[i].id);
        assert_int_equal(b.replies[i].u.param_value.status, expect[i].status);
        assert_true(b.replies[i].u.param_value.value == expect[i].value);
    }
    bench_close(&b);
}

static void samples_answered_with_gates_and_telemetry(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    hil_msg m = msg_command(HIL_CMD_ENABLE, HIL_SPEED_EKF, 100.0f);
    bench_send(&b, &m);
    assert_int_equal(b.n_replies, 1);
    assert_int_equal(b.replies[0].type, HIL_MSG_STATUS);
    assert_int_equal(b.replies[0].u.status.state, HIL_STATE_RUNNING);
    size_t first = b.n_replies;
    for (uint32_t k = 0; k < 21; ++k) {
        hil_msg s = msg_sample(k, 0.0, 0.0, 0u);
        size_t before = b.n_replies;
        bench_send(&b, &s);
        /* GATES first, for period k, an active vector */
        assert_true(b.n_replies > before);
        assert_int_equal(b.replies[before].type, HIL_MSG_GATES);
        assert_int_equal(b.replies[before].u.gates.period, k);
        assert_true(b.replies[before].u.gates.gates != 0);
        /* TELEMETRY for k % 10 == 0 (default divider), right after */
        if (k % 10 == 0) {
            assert_int_equal(b.replies[before + 1].type, HIL_MSG_TELEMETRY);
            assert_int_equal(b.replies[before + 1].u.telemetry.period, k);
            assert_int_equal(b.replies[before + 1].u.telemetry.gates, b.replies[before].u.gates.gates);
            assert_int_equal(b.replies[before + 1].u.telemetry.speed_source, HIL_SPEED_EKF);
        }
    }
    assert_int_equal(b.n_replies - first, 21 + 3);
    /* divider 0: no telemetry; divider 4: k % 4 == 0 */
    m = msg_param(HIL_MSG_PARAM_SET, HIL_PARAM_TELEMETRY_DIVIDER, 0.0f);
    bench_send(&b, &m);
    size_t tm_before = bench_count(&b, HIL_MSG_TELEMETRY);
    for (uint32_t k = 21; k < 41; ++k) {
        hil_msg s = msg_sample(k, 0.0, 0.0, 0u);
        bench_send(&b, &s);
    }
    assert_int_equal(bench_count(&b, HIL_MSG_TELEMETRY), tm_before);
    /* every frame numbered 0, 1, 2, ...: the bench decoder saw no gap */
    assert_int_equal(b.dec.seq_gaps, 0);
    assert_int_equal(b.dec.frames_ok, b.n_replies);
    bench_close(&b);
}

/* SPEC.md 2.8.1: the bench resends SAMPLE(k) when it lost the answer; the board answers the
 * copy with the same GATES and does not step its controller again (a second step would change
 * the run). Compared with a board that got each SAMPLE once. */
static void resent_sample_gets_the_same_answer_without_a_second_step(void **state)
{
    (void)state;
    bench once, twice;
    bench_open(&once);
    bench_open(&twice);
    hil_msg m = msg_command(HIL_CMD_ENABLE, HIL_SPEED_EKF, 100.0f);
    bench_send(&once, &m);
    bench_send(&twice, &m);
    for (uint32_t k = 0; k < 30; ++k) {
        hil_msg s = msg_sample(k, 0.3 * k, 0.1, (uint16_t)(7u * k));
        bench_send(&once, &s);
        size_t before = twice.n_replies;
        bench_send(&twice, &s);
        size_t first_answer = twice.n_replies;
        bench_send(&twice, &s); /* the resend */
        assert_int_equal(twice.n_replies, first_answer + 1u); /* the answer only, no TELEMETRY */
        assert_int_equal(twice.replies[first_answer].type, HIL_MSG_GATES);
        assert_int_equal(twice.replies[first_answer].u.gates.period, k);
        assert_int_equal(twice.replies[first_answer].u.gates.gates, twice.replies[before].u.gates.gates);
    }
    /* the controller stepped once per period: the same answers as the board without resends
     * (twice's GATES come in pairs: the answer and its repeat) */
    size_t gi = 0, pairs = 0;
    for (size_t i = 0; i < once.n_replies; ++i) {
        if (once.replies[i].type != HIL_MSG_GATES) {
            continue;
        }
        for (int copy = 0; copy < 2; ++copy) {
            while (twice.replies[gi].type != HIL_MSG_GATES) {
                ++gi;
            }
            assert_int_equal(twice.replies[gi].u.gates.period, once.replies[i].u.gates.period);
            assert_int_equal(twice.replies[gi].u.gates.gates, once.replies[i].u.gates.gates);
            ++gi;
        }
        ++pairs;
    }
    assert_int_equal(pairs, 30);
    bench_close(&once);
    bench_close(&twice);
}

static void byte_at_a_time_same_as_whole(void **state)
{
    (void)state;
    bench whole, bytes;
    bench_open(&whole);
    bench_open(&bytes);
    uint8_t stream[512];
    size_t len = 0;
    hil_msg msgs[4] = {msg_hello(), msg_command(HIL_CMD_ENABLE, HIL_SPEED_ENCODER, 50.0f),
                       msg_sample(0, 1.0, -0.5, 3u), msg_sample(1, 1.2, -0.4, 5u)};
    for (int i = 0; i < 4; ++i) {
        len += bench_encode(&whole, &msgs[i], stream + len, sizeof stream - len);
    }
    uint8_t garbage[] = {0x55, 0x13, 0x77};
    bench_send_bytes(&bytes, garbage, sizeof garbage); /* resynchronises at the next 0x00 */
    bench_send_bytes(&whole, stream, len);
    for (size_t i = 0; i < len; ++i) {
        bench_send_bytes(&bytes, stream + i, 1);
    }
    /* the garbage joins the first candidate frame and costs it: HELLO lost */
    assert_int_equal(bytes.n_replies + 1, whole.n_replies);
    assert_int_equal(bench_count(&bytes, HIL_MSG_GATES), 2);
    hil_stub_counters c;
    hil_stub_get_counters(bytes.stub, &c);
    assert_int_equal(c.decode_errors, 1);
    for (size_t i = 0; i < bytes.n_replies; ++i) {
        assert_int_equal(bytes.replies[i].type, whole.replies[i + 1].type);
    }
    bench_close(&whole);
    bench_close(&bytes);
}

static void small_output_buffer_drains_later(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    uint8_t buf[HIL_MAX_ENCODED_FRAME];
    hil_msg m = msg_sample(0, 0, 0, 0); /* period 0: GATES + TELEMETRY */
    size_t n = bench_encode(&b, &m, buf, sizeof buf);
    uint8_t tx[5];
    size_t got = hil_stub_exchange(b.stub, buf, n, tx, sizeof tx);
    assert_int_equal(got, 5);
    bench_take(&b, tx, got);
    assert_true(hil_stub_pending(b.stub) > 0);
    while ((got = hil_stub_exchange(b.stub, NULL, 0, tx, sizeof tx)) > 0) {
        bench_take(&b, tx, got);
    }
    assert_int_equal(hil_stub_pending(b.stub), 0);
    assert_int_equal(b.n_replies, 2);
    assert_int_equal(b.replies[0].type, HIL_MSG_GATES);
    assert_int_equal(b.replies[1].type, HIL_MSG_TELEMETRY);
    bench_close(&b);
}

static void fault_reported_once_then_status(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    hil_msg m = msg_command(HIL_CMD_ENABLE, HIL_SPEED_ENCODER, 50.0f);
    bench_send(&b, &m);
    m = msg_sample(1, 0, 0, 0);
    bench_send(&b, &m);
    size_t before = b.n_replies;
    m = msg_sample(2, 22.0, -11.0, 0);
    bench_send(&b, &m);
    int g = bench_find(&b, HIL_MSG_GATES, before);
    int f = bench_find(&b, HIL_MSG_FAULT, before);
    int st = bench_find(&b, HIL_MSG_STATUS, before);
    assert_true(g >= 0 && f > g && st > f);
    assert_int_equal(b.replies[g].u.gates.gates, 0);
    assert_int_equal(b.replies[f].u.fault.code, HIL_FAULT_OVERCURRENT);
    assert_int_equal(b.replies[f].u.fault.period, 2);
    assert_near(b.replies[f].u.fault.value, 22.0, 0.02);
    assert_int_equal(b.replies[st].u.status.state, HIL_STATE_FAULT);
    assert_int_equal(b.replies[st].u.status.fault_code, HIL_FAULT_OVERCURRENT);
    /* latched, reported once */
    m = msg_sample(3, 0, 0, 0);
    bench_send(&b, &m);
    assert_int_equal(bench_count(&b, HIL_MSG_FAULT), 1);
    /* disable clears: STATUS IDLE */
    m = msg_command(0, HIL_SPEED_ENCODER, 0.0f);
    bench_send(&b, &m);
    assert_int_equal(b.replies[b.n_replies - 1].u.status.state, HIL_STATE_IDLE);
    assert_int_equal(b.replies[b.n_replies - 1].u.status.fault_code, 0);
    bench_close(&b);
}

static void unknown_speed_source_is_a_protocol_fault(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    hil_msg m = msg_command(HIL_CMD_ENABLE, 9u, 50.0f);
    bench_send(&b, &m);
    int f = bench_find(&b, HIL_MSG_FAULT, 0);
    assert_true(f >= 0);
    assert_int_equal(b.replies[f].u.fault.code, HIL_FAULT_PROTOCOL);
    assert_near(b.replies[f].u.fault.value, 9.0, 0.0);
    m = msg_sample(0, 0, 0, 0);
    bench_send(&b, &m);
    assert_int_equal(b.replies[bench_find(&b, HIL_MSG_GATES, 0)].u.gates.gates, 0);
    bench_close(&b);
}

static void heartbeat_and_shutdown(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_HEARTBEAT;
    m.u.heartbeat.counter = 41;
    bench_send(&b, &m);
    bench_send(&b, &m);
    assert_int_equal(bench_count(&b, HIL_MSG_HEARTBEAT), 2);
    assert_int_equal(b.replies[0].u.heartbeat.counter, 0); /* our own count */
    assert_int_equal(b.replies[1].u.heartbeat.counter, 1);
    m = msg_command(HIL_CMD_ENABLE, HIL_SPEED_EKF, 50.0f);
    bench_send(&b, &m);
    assert_int_equal(hil_stub_shutdown_requested(b.stub), 0);
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_SHUTDOWN;
    bench_send(&b, &m);
    assert_int_equal(hil_stub_shutdown_requested(b.stub), 1);
    assert_int_equal(b.replies[b.n_replies - 1].type, HIL_MSG_STATUS);
    assert_int_equal(b.replies[b.n_replies - 1].u.status.state, HIL_STATE_IDLE);
    m = msg_sample(5, 0, 0, 0);
    bench_send(&b, &m);
    assert_int_equal(b.replies[b.n_replies - 1].type, HIL_MSG_GATES);
    assert_int_equal(b.replies[b.n_replies - 1].u.gates.gates, 0); /* switches open */
    bench_close(&b);
}

static uint32_t fake_cycles;
static uint32_t read_fake_cycles(void)
{
    fake_cycles += 1000u; /* each read 1000 cycles later */
    return fake_cycles;
}

static void cycle_counter_hook(void **state)
{
    (void)state;
    bench b;
    bench_open(&b);
    hil_stub_set_cycle_counter(b.stub, read_fake_cycles);
    hil_msg m = msg_sample(1, 0, 0, 0);
    bench_send(&b, &m);
    m = msg_param(HIL_MSG_PARAM_GET, HIL_PARAM_CONTROL_STEP_CYCLES, 0.0f);
    bench_send(&b, &m);
    int p = bench_find(&b, HIL_MSG_PARAM_VALUE, 0);
    assert_int_equal(b.replies[p].u.param_value.status, HIL_PARAM_OK);
    assert_near(b.replies[p].u.param_value.value, 1000.0, 0.0);
    bench_close(&b);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(hello_answered_with_build_name),
        cmocka_unit_test(hello_period_taken_when_in_range),
        cmocka_unit_test(other_version_gets_hello_and_nothing_else),
        cmocka_unit_test(answers_in_frame_order_within_one_buffer),
        cmocka_unit_test(parameter_round_trip_and_statuses),
        cmocka_unit_test(samples_answered_with_gates_and_telemetry),
        cmocka_unit_test(resent_sample_gets_the_same_answer_without_a_second_step),
        cmocka_unit_test(byte_at_a_time_same_as_whole),
        cmocka_unit_test(small_output_buffer_drains_later),
        cmocka_unit_test(fault_reported_once_then_status),
        cmocka_unit_test(unknown_speed_source_is_a_protocol_fault),
        cmocka_unit_test(heartbeat_and_shutdown),
        cmocka_unit_test(cycle_counter_hook),
    };
    return cmocka_run_group_tests_name("app_serial", tests, NULL, NULL);
}
