/* The firmware through its public ABI (hil_fw_abi.h), frames built with the
 * reference codec: what the bench's lib: link will do. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "hil_fw_abi.h"
#include "hil_proto.h"

static uint64_t mem[4096]; /* 8-byte aligned; create needs 16 */

static void *new_fw(void)
{
    uint8_t *base = (uint8_t *)mem;
    uintptr_t off = (16u - ((uintptr_t)base % 16u)) % 16u;
    void *fw = hil_fw_create(base + off, sizeof mem - 16u);
    assert_non_null(fw);
    return fw;
}

/* Sends one message, decodes every answer into out[]; returns how many. */
static int exchange(void *fw, hil_msg *in, hil_msg *out, int max_out)
{
    static uint8_t seq;
    uint8_t wire[HIL_MAX_ENCODED_FRAME];
    in->seq = seq++;
    int n = hil_frame_encode(in, wire, sizeof wire);
    assert_true(n > 0);
    uint8_t tx[64]; /* small on purpose: answers must come out over several calls */
    hil_decoder dec;
    hil_decoder_init(&dec);
    int got = 0;
    size_t k = hil_fw_exchange(fw, wire, (size_t)n, tx, sizeof tx);
    while (k > 0u) {
        for (size_t i = 0; i < k; ++i) {
            if (hil_decoder_feed(&dec, tx[i], &out[got]) && got < max_out - 1) {
                got++;
            }
        }
        k = hil_fw_exchange(fw, NULL, 0u, tx, sizeof tx);
    }
    assert_int_equal(dec.crc_errors + dec.framing_errors + dec.length_errors, 0);
    return got;
}

static void abi_version_and_create_refusals(void **state)
{
    (void)state;
    assert_int_equal(hil_fw_abi_version(), HIL_FW_ABI_VERSION);
    assert_true(strlen(hil_fw_name()) <= HIL_NAME_MAX);
    uint8_t *base = (uint8_t *)mem;
    uintptr_t off = (16u - ((uintptr_t)base % 16u)) % 16u;
    assert_null(hil_fw_create(base + off, hil_fw_instance_size() - 1u)); /* too small */
    assert_null(hil_fw_create(base + off + 8u, sizeof mem - 32u));       /* misaligned */
    assert_null(hil_fw_create(NULL, 0u));
}

static void hello_params_sample_shutdown(void **state)
{
    (void)state;
    void *fw = new_fw();
    hil_msg m, out[8];
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_HELLO;
    m.u.hello.proto_version = HIL_PROTO_VERSION;
    m.u.hello.control_period_ns = 50000u;
    assert_int_equal(exchange(fw, &m, out, 8), 1);
    assert_int_equal(out[0].type, HIL_MSG_HELLO);
    assert_int_equal(out[0].u.hello.role, HIL_ROLE_CONTROLLER);
    assert_int_equal(out[0].u.hello.capabilities, HIL_CAP_DUTY_LEGS | HIL_CAP_TELEMETRY);

    /* every parameter the bench pushes at session start is accepted and read back */
    static const struct { uint16_t id; float v; } pushed[] = {
        {1, 50e-6f}, {2, 0.01220703125f}, {3, 2048.0f}, {7, 0.0f}, {4, 0.0244140625f},
        {5, 0.0f}, {6, 4096.0f}, {10, 1.0f}, {40, 1.0f}, {23, 2.0f}};
    for (size_t i = 0; i < sizeof pushed / sizeof pushed[0]; ++i) {
        m.type = HIL_MSG_PARAM_SET;
        m.u.param_set.id = pushed[i].id;
        m.u.param_set.value = pushed[i].v;
        assert_int_equal(exchange(fw, &m, out, 8), 1);
        assert_int_equal(out[0].u.param_value.status, HIL_PARAM_OK);
        assert_true(out[0].u.param_value.value == pushed[i].v);
    }
    m.type = HIL_MSG_PARAM_SET; /* refused: old value reported */
    m.u.param_set.id = HIL_PARAM_ENCODER_COUNTS_PER_REV;
    m.u.param_set.value = 4096.5f;
    exchange(fw, &m, out, 8);
    assert_int_equal(out[0].u.param_value.status, HIL_PARAM_OUT_OF_RANGE);
    assert_true(out[0].u.param_value.value == 4096.0f);
    m.type = HIL_MSG_PARAM_GET; /* a DTC parameter this drive does not have */
    m.u.param_get.id = HIL_PARAM_FLUX_BAND_WB;
    exchange(fw, &m, out, 8);
    assert_int_equal(out[0].u.param_value.status, HIL_PARAM_UNKNOWN);
    assert_true(out[0].u.param_value.value == 0.0f);

    /* enabled, rotor at theta = 0 (count 0), speed wanted: sector 2 drives b -> c */
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_COMMAND;
    m.u.command.flags = HIL_CMD_ENABLE;
    m.u.command.speed_ref_rad_s = 100.0f;
    assert_int_equal(exchange(fw, &m, out, 8), 1);
    assert_int_equal(out[0].type, HIL_MSG_STATUS);
    assert_int_equal(out[0].u.status.state, HIL_STATE_RUNNING);
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_SAMPLE;
    m.u.sample.period = 7u;
    m.u.sample.adc_i1 = m.u.sample.adc_i2 = 2048u;
    m.u.sample.adc_vdc = 2867u;
    assert_int_equal(exchange(fw, &m, out, 8), 2);
    /* B high all period, C low all period, A floated */
    assert_int_equal(out[0].type, HIL_MSG_DUTY_LEGS);
    assert_int_equal(out[0].u.duty_legs.period, 7u);
    assert_int_equal(out[0].u.duty_legs.leg_enable, HIL_LEG_B | HIL_LEG_C);
    assert_int_equal(out[0].u.duty_legs.duty[1], 65535u);
    assert_int_equal(out[0].u.duty_legs.duty[2], 0u);
    assert_int_equal(out[1].type, HIL_MSG_TELEMETRY);
    assert_int_equal(out[1].u.telemetry.sector, 2);
    assert_int_equal(out[1].u.telemetry.gates, 0x3Cu); /* legs B and C switching */

    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_SHUTDOWN;
    exchange(fw, &m, out, 8);
    assert_int_equal(out[0].type, HIL_MSG_STATUS);
    assert_int_equal(out[0].u.status.state, HIL_STATE_IDLE);
    assert_int_equal(hil_fw_shutdown_requested(fw), 1);
    m.type = HIL_MSG_SAMPLE;
    m.u.sample.period = 8u;
    m.u.sample.adc_i1 = m.u.sample.adc_i2 = 2048u;
    exchange(fw, &m, out, 8);
    assert_int_equal(out[0].type, HIL_MSG_DUTY_LEGS);
    assert_int_equal(out[0].u.duty_legs.leg_enable, 0u); /* switching stopped: every leg floated */
    hil_fw_destroy(fw);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(abi_version_and_create_refusals),
        cmocka_unit_test(hello_params_sample_shutdown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
