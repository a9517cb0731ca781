/* The firmware through its public ABI (hil_fw_abi.h): what the bench's lib:
 * link does. SAMPLE_SENSORS frames are built byte by byte from the layout in
 * protocol/SPEC.md (period u32, sensor_set u16, status u8, then the fields of
 * each set bit in bit order), COBS-framed here; the answers are decoded with
 * the reference codec. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "hil_fw_abi.h"
#include "hil_proto.h"

static uint64_t mem[8192]; /* 8-byte aligned; create needs 16 */

static void *new_fw(void)
{
    uint8_t *base = (uint8_t *)mem;
    uintptr_t off = (16u - ((uintptr_t)base % 16u)) % 16u;
    void *fw = hil_fw_create(base + off, sizeof mem - 16u);
    assert_non_null(fw);
    return fw;
}

/* Feeds raw wire bytes, decodes every answer into out[]; returns how many. */
static int feed(void *fw, const uint8_t *wire, size_t n, hil_msg *out, int max_out)
{
    uint8_t tx[64]; /* small on purpose: answers must come out over several calls */
    hil_decoder dec;
    hil_decoder_init(&dec);
    int got = 0;
    size_t k = hil_fw_exchange(fw, wire, n, tx, sizeof tx);
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

static uint8_t seq;

static int exchange(void *fw, hil_msg *in, hil_msg *out, int max_out)
{
    uint8_t wire[HIL_MAX_ENCODED_FRAME];
    in->seq = seq++;
    int n = hil_frame_encode(in, wire, sizeof wire);
    assert_true(n > 0);
    return feed(fw, wire, (size_t)n, out, max_out);
}

/* ---- a SAMPLE_SENSORS frame by hand (SPEC 3, 6.13) ---- */

static size_t put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)(v >> 8);
    return 2u;
}

/* COBS (SPEC 3.2) of raw[0..n) into out, with the 0x00 delimiter; returns the length. */
static size_t cobs(const uint8_t *raw, size_t n, uint8_t *out)
{
    size_t o = 1u, code_at = 0u;
    uint8_t code = 1u;
    for (size_t i = 0; i < n; ++i) {
        if (raw[i] == 0u) {
            out[code_at] = code;
            code_at = o++;
            code = 1u;
        } else {
            out[o++] = raw[i];
            if (++code == 0xFFu) {
                out[code_at] = code;
                code_at = o++;
                code = 1u;
            }
        }
    }
    out[code_at] = code;
    out[o++] = 0u;
    return o;
}

typedef struct {
    uint32_t period;
    uint16_t sensor_set;
    uint8_t status;
    uint16_t ia, ib, ic, vdc, va, vb, vc;
    uint8_t comparators;
} sensors;

/* The bits this board reads: currents A, B, C, VDC, TERMINAL_VOLTAGES, BEMF_COMPARATORS. */
#define BOARD_SET 0x00CFu

static size_t sample_sensors_frame(const sensors *s, uint8_t *wire)
{
    uint8_t raw[4 + 31 + 2];
    uint8_t *p = raw + 4;
    size_t n = 0;
    p[n++] = (uint8_t)(s->period & 0xFFu);
    p[n++] = (uint8_t)((s->period >> 8) & 0xFFu);
    p[n++] = (uint8_t)((s->period >> 16) & 0xFFu);
    p[n++] = (uint8_t)(s->period >> 24);
    n += put_u16(p + n, s->sensor_set);
    p[n++] = s->status;
    if (s->sensor_set & 0x0001u) n += put_u16(p + n, s->ia);
    if (s->sensor_set & 0x0002u) n += put_u16(p + n, s->ib);
    if (s->sensor_set & 0x0004u) n += put_u16(p + n, s->ic);
    if (s->sensor_set & 0x0008u) n += put_u16(p + n, s->vdc);
    if (s->sensor_set & 0x0040u) {
        n += put_u16(p + n, s->va);
        n += put_u16(p + n, s->vb);
        n += put_u16(p + n, s->vc);
    }
    if (s->sensor_set & 0x0080u) p[n++] = s->comparators;
    raw[0] = 1u;    /* version */
    raw[1] = 0x10u; /* SAMPLE_SENSORS */
    raw[2] = seq++;
    raw[3] = (uint8_t)n;
    uint16_t crc = hil_crc16(raw, 4u + n);
    raw[4 + n] = (uint8_t)(crc & 0xFFu);
    raw[5 + n] = (uint8_t)(crc >> 8);
    return cobs(raw, 6u + n, wire);
}

static int send_sensors(void *fw, const sensors *s, hil_msg *out, int max_out)
{
    uint8_t wire[64];
    size_t n = sample_sensors_frame(s, wire);
    return feed(fw, wire, n, out, max_out);
}

static void set_param(void *fw, uint16_t id, float v, uint8_t status)
{
    hil_msg m, out[4];
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_PARAM_SET;
    m.u.param_set.id = id;
    m.u.param_set.value = v;
    assert_int_equal(exchange(fw, &m, out, 4), 1);
    assert_int_equal(out[0].type, HIL_MSG_PARAM_VALUE);
    assert_int_equal(out[0].u.param_value.status, status);
}

static void command(void *fw, uint8_t flags, float speed_ref, hil_msg *out)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_COMMAND;
    m.u.command.flags = flags;
    m.u.command.speed_ref_rad_s = speed_ref;
    assert_int_equal(exchange(fw, &m, out, 4), 1);
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

/* HELLO advertises SENSOR_SET, DUTY_LEGS and TELEMETRY; parameter 8 answers the
 * set's mask and refuses a PARAM_SET as read-only; the pushed parameters are taken. */
static void hello_and_the_sensor_set_parameter(void **state)
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
    assert_int_equal(out[0].u.hello.capabilities, 0x0020u | 0x0010u | 0x0004u);

    m.type = HIL_MSG_PARAM_GET;
    m.u.param_get.id = 8u;
    assert_int_equal(exchange(fw, &m, out, 8), 1);
    assert_int_equal(out[0].u.param_value.status, HIL_PARAM_OK);
    assert_true(out[0].u.param_value.value == (float)BOARD_SET);
    m.type = HIL_MSG_PARAM_SET;
    m.u.param_set.id = 8u;
    m.u.param_set.value = 3.0f;
    assert_int_equal(exchange(fw, &m, out, 8), 1);
    assert_int_equal(out[0].u.param_value.status, HIL_PARAM_READ_ONLY);
    assert_true(out[0].u.param_value.value == (float)BOARD_SET);

    static const struct { uint16_t id; float v; } pushed[] = {
        {1, 50e-6f}, {2, 0.01220703125f}, {3, 2048.0f}, {7, 0.0f}, {4, 0.0244140625f},
        {5, 0.0f}, {6, 4096.0f}, {10, 4.0f}, {40, 1.0f}, {11, 0.25f}, {12, 0.3e-3f},
        {13, 0.006f}, {14, 0.0244140625f}, {23, 0.24f}, {43, 0.02f}};
    for (size_t i = 0; i < sizeof pushed / sizeof pushed[0]; ++i) {
        set_param(fw, pushed[i].id, pushed[i].v, HIL_PARAM_OK);
    }
    set_param(fw, HIL_PARAM_STALL_TIMEOUT_S, NAN, HIL_PARAM_OUT_OF_RANGE);
    set_param(fw, HIL_PARAM_STALL_TIMEOUT_S, 0.0f, HIL_PARAM_OUT_OF_RANGE); /* > 0 (SPEC.md 8) */
    /* no encoder: the stall timeout is STALL_TIMEOUT_S, not ENCODER_LOSS_TIMEOUT_S */
    set_param(fw, HIL_PARAM_ENCODER_LOSS_TIMEOUT_S, 0.02f, HIL_PARAM_UNKNOWN);
    set_param(fw, HIL_PARAM_FLUX_BAND_WB, 1.0f, HIL_PARAM_UNKNOWN);
    hil_fw_destroy(fw);
}

/* Enabled: STARTING, the align step (6: a -> b, c floated) at the duty that
 * drives the align current through 2 R; TELEMETRY says so; a frame missing
 * the comparators trips FAULT PROTOCOL and opens the bridge. */
static void sample_sensors_drive_the_align_step(void **state)
{
    (void)state;
    void *fw = new_fw();
    hil_msg out[8];
    command(fw, HIL_CMD_ENABLE, 200.0f, out);
    assert_int_equal(out[0].type, HIL_MSG_STATUS);
    assert_int_equal(out[0].u.status.state, HIL_STATE_STARTING);

    sensors s = {7u, BOARD_SET, 0u, 2048u, 2048u, 2048u, 983u /* 24.0 V */, 0u, 0u, 0u, 0x05u};
    assert_int_equal(send_sensors(fw, &s, out, 8), 2);
    assert_int_equal(out[0].type, HIL_MSG_DUTY_LEGS);
    assert_int_equal(out[0].u.duty_legs.period, 7u);
    assert_int_equal(out[0].u.duty_legs.leg_enable, HIL_LEG_A | HIL_LEG_B);
    /* 2 x 0.25 ohm x 3 A / (983 x 100/4096 V) */
    double duty = 2.0 * 0.25 * 3.0 / (983.0 * 100.0 / 4096.0);
    assert_int_equal(out[0].u.duty_legs.duty[0], (uint16_t)(duty * 65535.0 + 0.5));
    assert_int_equal(out[0].u.duty_legs.duty[1], 0u);
    assert_int_equal(out[0].u.duty_legs.duty[2], 0u);
    assert_int_equal(out[1].type, HIL_MSG_TELEMETRY);
    assert_int_equal(out[1].u.telemetry.sector, 6);
    assert_int_equal(out[1].u.telemetry.state, HIL_STATE_STARTING);
    assert_int_equal(out[1].u.telemetry.gates, 0x0Fu);

    /* the same frame without BEMF_COMPARATORS (one byte shorter) */
    s.period = 8u;
    s.sensor_set = BOARD_SET & ~0x0080u;
    int n = send_sensors(fw, &s, out, 8);
    assert_true(n >= 3);
    assert_int_equal(out[0].type, HIL_MSG_FAULT);
    assert_int_equal(out[0].u.fault.code, HIL_FAULT_PROTOCOL);
    assert_int_equal(out[1].type, HIL_MSG_STATUS);
    assert_int_equal(out[1].u.status.state, HIL_STATE_FAULT);
    assert_int_equal(out[2].type, HIL_MSG_DUTY_LEGS);
    assert_int_equal(out[2].u.duty_legs.leg_enable, 0u);

    /* disable clears the fault; a phase current over the trip level trips FAULT 1 */
    command(fw, 0u, 0.0f, out);
    assert_int_equal(out[0].u.status.state, HIL_STATE_IDLE);
    command(fw, HIL_CMD_ENABLE, 200.0f, out);
    s.period = 9u;
    s.sensor_set = BOARD_SET;
    s.ib = 2048u + 1720u; /* 21 A */
    n = send_sensors(fw, &s, out, 8);
    assert_true(n >= 3);
    assert_int_equal(out[0].type, HIL_MSG_FAULT);
    assert_int_equal(out[0].u.fault.code, HIL_FAULT_OVERCURRENT);
    assert_float_equal(out[0].u.fault.value, 1720.0 * 25.0 / 2048.0, 1e-3);
    assert_int_equal(out[2].u.duty_legs.leg_enable, 0u);

    /* a NaN speed reference is refused with FAULT NON_FINITE (COMMAND, 8) */
    command(fw, 0u, 0.0f, out);
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_COMMAND;
    m.u.command.flags = HIL_CMD_ENABLE;
    m.u.command.speed_ref_rad_s = NAN;
    assert_int_equal(exchange(fw, &m, out, 8), 2);
    assert_int_equal(out[0].type, HIL_MSG_FAULT);
    assert_int_equal(out[0].u.fault.code, HIL_FAULT_NON_FINITE);
    assert_float_equal(out[0].u.fault.value, 8.0, 0.0);

    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_SHUTDOWN;
    exchange(fw, &m, out, 8);
    assert_int_equal(out[0].u.status.state, HIL_STATE_IDLE);
    assert_int_equal(hil_fw_shutdown_requested(fw), 1);
    hil_fw_destroy(fw);
}

/* A locked rotor: no back-EMF, the comparators hold their offsets' word, no zero cross ever
 * comes. With a 1 ms align, a 1 ms ramp and a 2 ms STALL_TIMEOUT_S the start fails with FAULT 7
 * STALL (not 2: no position sensor failed, the rotor does not follow the drive), value the
 * seconds at the end speed without the hand-over, and the bridge opens. */
static void locked_rotor_start_trips_stall(void **state)
{
    (void)state;
    void *fw = new_fw();
    hil_msg out[8];
    set_param(fw, 100u, 0.001f, HIL_PARAM_OK); /* align_time_s: 20 periods */
    set_param(fw, 104u, 0.001f, HIL_PARAM_OK); /* ramp_time_s: 20 periods */
    set_param(fw, HIL_PARAM_STALL_TIMEOUT_S, 0.002f, HIL_PARAM_OK); /* 40 periods */
    command(fw, HIL_CMD_ENABLE, 200.0f, out);
    assert_int_equal(out[0].u.status.state, HIL_STATE_STARTING);
    /* at rest: the three terminals read alike (no back-EMF) and the comparators hold their
     * offsets' word, a 0, b 1, c 0 */
    sensors s = {1u, BOARD_SET, 0u, 2048u, 2048u, 2048u, 983u /* 24.0 V */, 1000u, 1000u, 1000u, 0x02u};
    int n = 0;
    for (; s.period < 1000u; ++s.period) {
        n = send_sensors(fw, &s, out, 8);
        if (n >= 1 && out[0].type == HIL_MSG_FAULT) break;
    }
    assert_true(s.period < 1000u);
    assert_int_equal(out[0].u.fault.code, HIL_FAULT_STALL);
    /* the trip comes once the end speed was held longer than the timeout: value > 2 ms,
     * within a few periods of it */
    assert_true(out[0].u.fault.value > 0.002f);
    assert_true(out[0].u.fault.value < 0.002f + 3.0f * 50e-6f);
    assert_true(s.period > 20u + 20u + 40u);
    assert_int_equal(out[1].type, HIL_MSG_STATUS);
    assert_int_equal(out[1].u.status.state, HIL_STATE_FAULT);
    assert_int_equal(out[2].type, HIL_MSG_DUTY_LEGS);
    assert_int_equal(out[2].u.duty_legs.leg_enable, 0u);
    hil_fw_destroy(fw);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(abi_version_and_create_refusals),
        cmocka_unit_test(hello_and_the_sensor_set_parameter),
        cmocka_unit_test(sample_sensors_drive_the_align_step),
        cmocka_unit_test(locked_rotor_start_trips_stall),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
