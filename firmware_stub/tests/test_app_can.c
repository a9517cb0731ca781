/* The application layer over the CAN mapping (protocol/SPEC.md section 7). */
#include "app_helpers.h"

typedef struct {
    void *stub;
    uint8_t counter; /* segmentation counter of the bench's messages */
    hil_can_rx rx;   /* the bench's reassembler */
    hil_msg replies[MAX_REPLIES];
    size_t n_replies;
    hil_can_frame last_frames[64];
    size_t n_last;
} can_bench;

static void can_open(can_bench *b, uint16_t base)
{
    b->stub = malloc(hil_stub_instance_size());
    assert_non_null(b->stub);
    hil_stub_init(b->stub);
    if (base != HIL_CAN_DEFAULT_BASE_ID) {
        hil_stub_set_can_base(b->stub, base);
    }
    b->counter = 0;
    hil_can_rx_init(&b->rx, base);
    b->n_replies = 0;
}

static void can_send(can_bench *b, hil_msg *m, uint16_t base)
{
    hil_can_frame frames[HIL_CAN_MAX_FRAMES];
    m->seq = b->counter++;
    int n = hil_can_pack(m, HIL_ROLE_BENCH, base, frames, HIL_CAN_MAX_FRAMES);
    assert_true(n > 0);
    b->n_last = 0;
    size_t got = hil_stub_can_exchange(b->stub, frames, (size_t)n, b->last_frames, 64);
    while (got > 0) {
        for (size_t i = 0; i < got; ++i) {
            hil_msg out;
            uint8_t role = 0xFF;
            if (hil_can_rx_feed(&b->rx, &b->last_frames[b->n_last + i], &out, &role)) {
                assert_int_equal(role, HIL_ROLE_CONTROLLER);
                b->replies[b->n_replies++] = out;
            }
        }
        b->n_last += got;
        got = hil_stub_can_exchange(b->stub, NULL, 0, b->last_frames + b->n_last, 64 - b->n_last);
    }
}

static void session_over_can(void **state)
{
    (void)state;
    can_bench b;
    can_open(&b, HIL_CAN_DEFAULT_BASE_ID);
    hil_msg m = msg_hello();
    can_send(&b, &m, HIL_CAN_DEFAULT_BASE_ID);
    assert_int_equal(b.n_replies, 1);
    assert_int_equal(b.replies[0].type, HIL_MSG_HELLO);
    assert_int_equal(b.replies[0].u.hello.role, HIL_ROLE_CONTROLLER);
    assert_memory_equal(b.replies[0].u.hello.name, hil_stub_name(), b.replies[0].u.hello.name_len);
    /* segmented: 9 + name_len bytes in 7-byte chunks, id 0x121 */
    assert_int_equal(b.n_last, (9u + strlen(hil_stub_name()) + 6u) / 7u);
    assert_int_equal(b.last_frames[0].id, 0x121);

    m = msg_param(HIL_MSG_PARAM_SET, HIL_PARAM_OVERCURRENT_A, 18.0f);
    can_send(&b, &m, HIL_CAN_DEFAULT_BASE_ID);
    assert_int_equal(b.replies[1].type, HIL_MSG_PARAM_VALUE);
    assert_true(b.replies[1].u.param_value.value == 18.0f);
    assert_int_equal(b.last_frames[0].id, 0x129);

    m = msg_command(HIL_CMD_ENABLE, HIL_SPEED_CONVENTIONAL, 80.0f);
    can_send(&b, &m, HIL_CAN_DEFAULT_BASE_ID);
    assert_int_equal(b.replies[2].type, HIL_MSG_STATUS);
    assert_int_equal(b.replies[2].u.status.state, HIL_STATE_RUNNING);

    /* SAMPLE carries 8 bits of the period; the GATES answer has all 32 */
    for (uint32_t k = 0; k < 300; ++k) {
        b.n_replies = 0;
        m = msg_sample(k, 0.0, 0.0, 0u);
        can_send(&b, &m, HIL_CAN_DEFAULT_BASE_ID);
        assert_int_equal(b.replies[0].type, HIL_MSG_GATES);
        assert_int_equal(b.replies[0].u.gates.period, k);
        assert_int_equal(b.last_frames[0].id, 0x123);
        assert_int_equal(b.last_frames[0].dlc, 5);
        if (k % 10 == 0) {
            assert_int_equal(b.n_replies, 2);
            assert_int_equal(b.replies[1].type, HIL_MSG_TELEMETRY);
            assert_int_equal(b.replies[1].u.telemetry.period, k);
            assert_int_equal(b.n_last, 1 + 8); /* GATES + 8 TELEMETRY frames */
        } else {
            assert_int_equal(b.n_replies, 1);
        }
    }
    assert_int_equal(b.rx.sequence_errors + b.rx.length_errors + b.rx.unknown_types, 0);
    free(b.stub);
}

static void other_base_and_foreign_frames(void **state)
{
    (void)state;
    can_bench b;
    can_open(&b, 0x340);
    /* frames at the default base are not ours any more */
    hil_msg m = msg_hello();
    can_send(&b, &m, HIL_CAN_DEFAULT_BASE_ID);
    assert_int_equal(b.n_replies, 0);
    m = msg_hello();
    can_send(&b, &m, 0x340);
    assert_int_equal(b.n_replies, 1);
    assert_int_equal(b.last_frames[0].id, 0x361);
    /* the controller's own frames echoed back are ignored */
    hil_can_frame echo = b.last_frames[0];
    hil_can_frame out[8];
    assert_int_equal(hil_stub_can_exchange(b.stub, &echo, 1, out, 8), 0);
    hil_stub_counters c;
    hil_stub_get_counters(b.stub, &c);
    assert_int_equal(c.frames_in, 1);
    free(b.stub);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(session_over_can),
        cmocka_unit_test(other_base_and_foreign_frames),
    };
    return cmocka_run_group_tests_name("app_can", tests, NULL, NULL);
}
