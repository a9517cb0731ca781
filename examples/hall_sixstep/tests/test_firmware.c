/* The firmware through its public ABI (hil_fw_abi.h), what the bench's lib:
 * link does. SAMPLE_SENSORS frames are built here byte by byte from SPEC.md's
 * layout (period u32, sensor_set u16, status u8, then the fields of the set
 * bits in bit order), with the CRC of SPEC.md 3.1 and COBS done here, so the
 * firmware's decoding of them is checked against the text, not against the
 * codec's own encoder. The other messages use the reference codec. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "hil_fw_abi.h"
#include "hil_proto.h"

static uint64_t mem[4096]; /* 8-byte aligned; create needs 16 */
static uint8_t bench_seq;

static void *new_fw(void)
{
    uint8_t *base = (uint8_t *)mem;
    uintptr_t off = (16u - ((uintptr_t)base % 16u)) % 16u;
    void *fw = hil_fw_create(base + off, sizeof mem - 16u);
    assert_non_null(fw);
    return fw;
}

/* Feeds wire bytes, decodes every answer into out[]; returns how many. */
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

static int exchange(void *fw, hil_msg *in, hil_msg *out, int max_out)
{
    uint8_t wire[HIL_MAX_ENCODED_FRAME];
    in->seq = bench_seq++;
    int n = hil_frame_encode(in, wire, sizeof wire);
    assert_true(n > 0);
    return feed(fw, wire, (size_t)n, out, max_out);
}

/* CRC-16/CCITT-FALSE (SPEC.md 3.1), bit by bit */
static uint16_t crc16(const uint8_t *p, size_t n)
{
    uint16_t crc = 0xFFFFu;
    for (size_t i = 0; i < n; ++i) {
        crc ^= (uint16_t)(p[i] << 8);
        for (int b = 0; b < 8; ++b) {
            crc = (uint16_t)((crc & 0x8000u) ? ((unsigned)crc << 1) ^ 0x1021u : (unsigned)crc << 1);
        }
    }
    return crc;
}

/* COBS of raw (under 254 bytes), then the 0x00 delimiter */
static size_t cobs(const uint8_t *raw, size_t n, uint8_t *wire)
{
    size_t code_at = 0, w = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < n; ++i) {
        if (raw[i] == 0u) {
            wire[code_at] = code;
            code_at = w++;
            code = 1;
        } else {
            wire[w++] = raw[i];
            code++;
        }
    }
    wire[code_at] = code;
    wire[w++] = 0u;
    return w;
}

/* Set bits of the board's sensor set: CURRENT_A 0x01, CURRENT_B 0x02, CURRENT_C 0x04,
 * VDC 0x08, HALL 0x20 */
#define SET_CURRENTS_VDC_HALL 0x002Fu

typedef struct {
    uint32_t period;
    uint16_t sensor_set;
    uint8_t status;
    uint16_t ia, ib, ic, vdc;
    uint8_t hall;
} sensors;

/* SAMPLE_SENSORS (type 0x10) of the board's set, built from SPEC.md 6.13: header,
 * payload and CRC (before COBS); returns its length. */
static size_t sample_sensors_raw(const sensors *s, uint8_t seq, uint8_t *raw)
{
    size_t n = 4;
    raw[n++] = (uint8_t)s->period;
    raw[n++] = (uint8_t)(s->period >> 8);
    raw[n++] = (uint8_t)(s->period >> 16);
    raw[n++] = (uint8_t)(s->period >> 24);
    raw[n++] = (uint8_t)s->sensor_set;
    raw[n++] = (uint8_t)(s->sensor_set >> 8);
    raw[n++] = s->status;
    const uint16_t counts[4] = {s->ia, s->ib, s->ic, s->vdc};
    for (int bit = 0; bit < 4; ++bit) { /* CURRENT_A .. VDC, u16 each */
        if (s->sensor_set & (1u << bit)) {
            raw[n++] = (uint8_t)counts[bit];
            raw[n++] = (uint8_t)(counts[bit] >> 8);
        }
    }
    if (s->sensor_set & 0x0010u) { /* ENCODER: this board does not read it */
        raw[n++] = 0x34u;
        raw[n++] = 0x12u;
    }
    if (s->sensor_set & 0x0020u) { /* HALL u8 */
        raw[n++] = s->hall;
    }
    raw[0] = 1u;    /* version */
    raw[1] = 0x10u; /* SAMPLE_SENSORS */
    raw[2] = seq;
    raw[3] = (uint8_t)(n - 4u);
    uint16_t crc = crc16(raw, n);
    raw[n++] = (uint8_t)crc;
    raw[n++] = (uint8_t)(crc >> 8);
    return n;
}

static size_t sample_sensors_frame(const sensors *s, uint8_t *wire)
{
    uint8_t raw[64];
    size_t n = sample_sensors_raw(s, bench_seq++, raw);
    return cobs(raw, n, wire);
}

static int sample(void *fw, const sensors *s, hil_msg *out, int max_out)
{
    uint8_t wire[80];
    size_t n = sample_sensors_frame(s, wire);
    return feed(fw, wire, n, out, max_out);
}

/* 24 V on the default 100 V / 4096 scale; 0 A at 2048 counts, 25 A / 2048 per count */
static sensors at_rest(uint32_t period, uint8_t hall)
{
    sensors s = {period, SET_CURRENTS_VDC_HALL, 0u, 2048u, 2048u, 2048u, 983u, hall};
    return s;
}

static void hello_and_enable(void *fw, float speed_ref_rad_s)
{
    hil_msg m, out[8];
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_HELLO;
    m.u.hello.proto_version = HIL_PROTO_VERSION;
    m.u.hello.control_period_ns = 50000u;
    assert_int_equal(exchange(fw, &m, out, 8), 1);
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_COMMAND;
    m.u.command.flags = HIL_CMD_ENABLE;
    m.u.command.speed_ref_rad_s = speed_ref_rad_s;
    assert_int_equal(exchange(fw, &m, out, 8), 1);
    assert_int_equal(out[0].type, HIL_MSG_STATUS);
    assert_int_equal(out[0].u.status.state, HIL_STATE_RUNNING);
}

static void param(void *fw, uint8_t type, uint16_t id, float value, hil_msg *answer)
{
    hil_msg m, out[4];
    memset(&m, 0, sizeof m);
    m.type = type;
    if (type == HIL_MSG_PARAM_SET) {
        m.u.param_set.id = id;
        m.u.param_set.value = value;
    } else {
        m.u.param_get.id = id;
    }
    assert_int_equal(exchange(fw, &m, out, 4), 1);
    assert_int_equal(out[0].type, HIL_MSG_PARAM_VALUE);
    *answer = out[0];
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

/* The frames these tests send are the SPEC's: the hand-built vector hb_sample_sensors_hall
 * (protocol/vectors/handbuilt.txt, this board's set) byte for byte. */
static void frame_builder_matches_the_handbuilt_vector(void **state)
{
    (void)state;
    static const uint8_t vector[] = {0x01, 0x10, 0x15, 0x10, 0x70, 0x11, 0x01, 0x00, 0x2f, 0x00, 0x00,
                                     0x34, 0x08, 0xc6, 0x07, 0x06, 0x08, 0xd7, 0x03, 0x03, 0x68, 0xb4};
    sensors s = {70000u, SET_CURRENTS_VDC_HALL, 0u, 2100u, 1990u, 2054u, 983u, 3u};
    uint8_t raw[64];
    assert_int_equal(sample_sensors_raw(&s, 21u, raw), sizeof vector);
    assert_memory_equal(raw, vector, sizeof vector);
}

/* HELLO declares SENSOR_SET (0x0020) + DUTY_LEGS (0x0010) + TELEMETRY (0x0004); the
 * read-only parameter SENSOR_SET (8) holds the mask 0x002F = 47. */
static void hello_declares_the_sensor_set(void **state)
{
    (void)state;
    void *fw = new_fw();
    hil_msg m, out[4];
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_HELLO;
    m.u.hello.proto_version = HIL_PROTO_VERSION;
    assert_int_equal(exchange(fw, &m, out, 4), 1);
    assert_int_equal(out[0].type, HIL_MSG_HELLO);
    assert_int_equal(out[0].u.hello.role, HIL_ROLE_CONTROLLER);
    assert_int_equal(out[0].u.hello.capabilities, 0x0020u | 0x0010u | 0x0004u);
    hil_msg a;
    param(fw, HIL_MSG_PARAM_GET, 8u, 0.0f, &a);
    assert_int_equal(a.u.param_value.status, HIL_PARAM_OK);
    assert_true(a.u.param_value.value == 47.0f);
    param(fw, HIL_MSG_PARAM_SET, 8u, 3.0f, &a);
    assert_int_equal(a.u.param_value.status, HIL_PARAM_READ_ONLY);
    assert_true(a.u.param_value.value == 47.0f);
    /* every parameter a bench pushes at session start (SPEC.md 8.1) and the board file's are taken */
    static const struct { uint16_t id; float v; } pushed[] = {
        {1, 50e-6f}, {2, 0.01220703125f}, {3, 2048.0f}, {7, 0.0f}, {4, 0.0244140625f}, {5, 0.0f},
        {6, 4096.0f}, {10, 4.0f}, {40, 1.0f}, {11, 0.25f}, {12, 0.3e-3f}, {13, 0.006f}, {23, 0.3f},
        {24, 5.0e-3f}, {25, 0.3f}, {41, 15.0f}, {43, 0.05f}};
    for (size_t i = 0; i < sizeof pushed / sizeof pushed[0]; ++i) {
        param(fw, HIL_MSG_PARAM_SET, pushed[i].id, pushed[i].v, &a);
        assert_int_equal(a.u.param_value.status, HIL_PARAM_OK);
        assert_true(a.u.param_value.value == pushed[i].v);
    }
    param(fw, HIL_MSG_PARAM_SET, HIL_PARAM_POLE_PAIRS, 4.5f, &a); /* refused: the old value */
    assert_int_equal(a.u.param_value.status, HIL_PARAM_OUT_OF_RANGE);
    assert_true(a.u.param_value.value == 4.0f);
    param(fw, HIL_MSG_PARAM_GET, HIL_PARAM_FLUX_BAND_WB, 0.0f, &a); /* a DTC parameter it has not */
    assert_int_equal(a.u.param_value.status, HIL_PARAM_UNKNOWN);
    /* the stall timeout is STALL_TIMEOUT_S (43), > 0; no encoder, so no ENCODER_LOSS_TIMEOUT_S (42) */
    param(fw, HIL_MSG_PARAM_GET, HIL_PARAM_STALL_TIMEOUT_S, 0.0f, &a);
    assert_int_equal(a.u.param_value.status, HIL_PARAM_OK);
    assert_true(a.u.param_value.value == 0.05f);
    param(fw, HIL_MSG_PARAM_SET, HIL_PARAM_STALL_TIMEOUT_S, 0.0f, &a);
    assert_int_equal(a.u.param_value.status, HIL_PARAM_OUT_OF_RANGE);
    assert_true(a.u.param_value.value == 0.05f);
    param(fw, HIL_MSG_PARAM_GET, HIL_PARAM_ENCODER_LOSS_TIMEOUT_S, 0.0f, &a);
    assert_int_equal(a.u.param_value.status, HIL_PARAM_UNKNOWN);
    hil_fw_destroy(fw);
}

/* Hall word 1 (theta_e in (-30, 30) deg): b -> c, B PWM'd, C low, A floated; word 3
 * ((30, 90)): b -> a. Speed wanted from standstill: the torque limit, so the full link. */
static void sample_sensors_commutates_on_the_hall_word(void **state)
{
    (void)state;
    void *fw = new_fw();
    hello_and_enable(fw, 200.0f);
    hil_msg out[8];
    sensors s = at_rest(7u, 1u);
    assert_int_equal(sample(fw, &s, out, 8), 2);
    assert_int_equal(out[0].type, HIL_MSG_DUTY_LEGS);
    assert_int_equal(out[0].u.duty_legs.period, 7u);
    assert_int_equal(out[0].u.duty_legs.leg_enable, HIL_LEG_B | HIL_LEG_C);
    assert_true(out[0].u.duty_legs.duty[1] > 0u);
    assert_int_equal(out[0].u.duty_legs.duty[2], 0u);
    assert_int_equal(out[1].type, HIL_MSG_TELEMETRY);
    assert_int_equal(out[1].u.telemetry.sector, 2);
    assert_int_equal(out[1].u.telemetry.gates, 0x3Cu); /* legs B and C switching */
    assert_true(out[1].u.telemetry.torque_ref_nm > 0.0f);

    s = at_rest(8u, 3u);
    assert_int_equal(sample(fw, &s, out, 8), 2);
    assert_int_equal(out[0].u.duty_legs.leg_enable, HIL_LEG_A | HIL_LEG_B);
    assert_true(out[0].u.duty_legs.duty[1] > 0u);
    assert_int_equal(out[0].u.duty_legs.duty[0], 0u);
    assert_int_equal(out[1].u.telemetry.sector, 3);

    /* the Hall byte's reserved bits 3-7 are ignored */
    s = at_rest(9u, 0xF8u | 3u);
    assert_int_equal(sample(fw, &s, out, 8), 2);
    assert_int_equal(out[0].u.duty_legs.leg_enable, HIL_LEG_A | HIL_LEG_B);

    /* extra sensors in the set (an encoder) are skipped by their layout */
    s = at_rest(10u, 1u);
    s.sensor_set = SET_CURRENTS_VDC_HALL | 0x0010u;
    assert_int_equal(sample(fw, &s, out, 8), 2);
    assert_int_equal(out[0].u.duty_legs.leg_enable, HIL_LEG_B | HIL_LEG_C);

    /* a frame whose length does not match its set is dropped by the codec: no answer */
    uint8_t wire[80];
    s = at_rest(11u, 1u);
    size_t n = sample_sensors_frame(&s, wire);
    uint8_t raw_short[] = {1u, 0x10u, bench_seq++, 8u, 11u, 0u, 0u, 0u, 0x2Fu, 0u, 0u, 0u, 0u, 0u};
    uint16_t crc = crc16(raw_short, 12u);
    raw_short[12] = (uint8_t)crc;
    raw_short[13] = (uint8_t)(crc >> 8);
    n = cobs(raw_short, sizeof raw_short, wire);
    uint8_t tx[64];
    assert_int_equal(hil_fw_exchange(fw, wire, n, tx, sizeof tx), 0u);
    hil_fw_destroy(fw);
}

/* An illegal Hall word floats every leg at once and trips FAULT 2 (position sensor lost)
 * on its second sample, with the seconds it lasted. */
static void illegal_hall_word_trips_encoder_loss(void **state)
{
    (void)state;
    for (uint8_t word = 0u; word <= 7u; word += 7u) {
        void *fw = new_fw();
        hello_and_enable(fw, 200.0f);
        hil_msg out[8];
        sensors s = at_rest(1u, 1u);
        assert_int_equal(sample(fw, &s, out, 8), 2);
        s = at_rest(2u, word);
        assert_int_equal(sample(fw, &s, out, 8), 2);
        assert_int_equal(out[0].type, HIL_MSG_DUTY_LEGS);
        assert_int_equal(out[0].u.duty_legs.leg_enable, 0u);
        assert_int_equal(out[1].u.telemetry.state, HIL_STATE_RUNNING);
        s = at_rest(3u, word);
        assert_int_equal(sample(fw, &s, out, 8), 4);
        assert_int_equal(out[0].type, HIL_MSG_FAULT);
        assert_int_equal(out[0].u.fault.code, HIL_FAULT_ENCODER_LOSS);
        assert_int_equal(out[0].u.fault.period, 3u);
        assert_float_equal(out[0].u.fault.value, 2.0f * 50e-6f, 1e-9f);
        assert_int_equal(out[1].type, HIL_MSG_STATUS);
        assert_int_equal(out[1].u.status.state, HIL_STATE_FAULT);
        assert_int_equal(out[2].type, HIL_MSG_DUTY_LEGS);
        assert_int_equal(out[2].u.duty_legs.leg_enable, 0u);
        /* latched: a legal word again does not restart switching */
        s = at_rest(4u, 1u);
        assert_int_equal(sample(fw, &s, out, 8), 2);
        assert_int_equal(out[0].u.duty_legs.leg_enable, 0u);
        hil_fw_destroy(fw);
    }
}

/* No Hall edge while the speed PI asks for the torque limit: FAULT 7 STALL (not 2: the
 * sensor works, the rotor does not turn) after the timeout (parameter 43), on the
 * (timeout + 1)-th silent period. */
static void locked_rotor_trips_after_the_stall_timeout(void **state)
{
    (void)state;
    void *fw = new_fw();
    hil_msg a, out[8];
    param(fw, HIL_MSG_PARAM_SET, HIL_PARAM_STALL_TIMEOUT_S, 0.001f, &a); /* 20 periods */
    assert_int_equal(a.u.param_value.status, HIL_PARAM_OK);
    hello_and_enable(fw, 200.0f);
    for (uint32_t k = 1u; k <= 20u; ++k) {
        sensors s = at_rest(k, 1u);
        assert_int_equal(sample(fw, &s, out, 8), 2);
        assert_int_equal(out[1].u.telemetry.state, HIL_STATE_RUNNING);
    }
    sensors s = at_rest(21u, 1u);
    assert_int_equal(sample(fw, &s, out, 8), 4);
    assert_int_equal(out[0].type, HIL_MSG_FAULT);
    assert_int_equal(out[0].u.fault.code, HIL_FAULT_STALL);
    assert_float_equal(out[0].u.fault.value, 21.0f * 50e-6f, 1e-7f);
    assert_int_equal(out[2].u.duty_legs.leg_enable, 0u);
    /* disable clears it (SPEC.md 2.5), enable runs again */
    memset(&a, 0, sizeof a);
    a.type = HIL_MSG_COMMAND;
    assert_int_equal(exchange(fw, &a, out, 8), 1);
    assert_int_equal(out[0].u.status.state, HIL_STATE_IDLE);
    a.u.command.flags = HIL_CMD_ENABLE;
    assert_int_equal(exchange(fw, &a, out, 8), 1);
    assert_int_equal(out[0].u.status.state, HIL_STATE_RUNNING);
    hil_fw_destroy(fw);
}

static void overcurrent_and_missing_sensors_trip(void **state)
{
    (void)state;
    void *fw = new_fw();
    hello_and_enable(fw, 200.0f);
    hil_msg out[8];
    sensors s = at_rest(1u, 1u);
    s.ib = (uint16_t)(2048u + 1311u); /* 16.0 A > 15 A */
    s.ic = (uint16_t)(2048u - 1311u);
    assert_int_equal(sample(fw, &s, out, 8), 4);
    assert_int_equal(out[0].u.fault.code, HIL_FAULT_OVERCURRENT);
    assert_float_equal(out[0].u.fault.value, 1311.0f * 25.0f / 2048.0f, 1e-4f);
    hil_fw_destroy(fw);

    fw = new_fw();
    hello_and_enable(fw, 200.0f);
    s = at_rest(1u, 1u);
    s.status = HIL_STATUS_OVERCURRENT; /* the plant's comparator */
    assert_int_equal(sample(fw, &s, out, 8), 4);
    assert_int_equal(out[0].u.fault.code, HIL_FAULT_OVERCURRENT);
    hil_fw_destroy(fw);

    fw = new_fw();
    hello_and_enable(fw, 200.0f);
    s = at_rest(1u, 1u);
    s.sensor_set = 0x000Fu; /* no Hall word */
    assert_int_equal(sample(fw, &s, out, 8), 4);
    assert_int_equal(out[0].u.fault.code, HIL_FAULT_PROTOCOL);
    assert_float_equal(out[0].u.fault.value, 15.0f, 0.0f);
    assert_int_equal(out[2].u.duty_legs.leg_enable, 0u);
    hil_fw_destroy(fw);

    /* a plain SAMPLE has no Halls either */
    fw = new_fw();
    hello_and_enable(fw, 200.0f);
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_SAMPLE;
    m.u.sample.period = 1u;
    m.u.sample.adc_i1 = m.u.sample.adc_i2 = 2048u;
    assert_int_equal(exchange(fw, &m, out, 8), 4);
    assert_int_equal(out[0].u.fault.code, HIL_FAULT_PROTOCOL);
    assert_int_equal(out[2].u.duty_legs.leg_enable, 0u);
    hil_fw_destroy(fw);
}

static void shutdown_stops_switching(void **state)
{
    (void)state;
    void *fw = new_fw();
    hello_and_enable(fw, 200.0f);
    hil_msg m, out[8];
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_SHUTDOWN;
    assert_int_equal(exchange(fw, &m, out, 8), 1);
    assert_int_equal(out[0].u.status.state, HIL_STATE_IDLE);
    assert_int_equal(hil_fw_shutdown_requested(fw), 1);
    sensors s = at_rest(5u, 1u);
    assert_int_equal(sample(fw, &s, out, 8), 2);
    assert_int_equal(out[0].u.duty_legs.leg_enable, 0u);
    hil_fw_destroy(fw);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(abi_version_and_create_refusals),
        cmocka_unit_test(frame_builder_matches_the_handbuilt_vector),
        cmocka_unit_test(hello_declares_the_sensor_set),
        cmocka_unit_test(sample_sensors_commutates_on_the_hall_word),
        cmocka_unit_test(illegal_hall_word_trips_encoder_loss),
        cmocka_unit_test(locked_rotor_trips_after_the_stall_timeout),
        cmocka_unit_test(overcurrent_and_missing_sensors_trip),
        cmocka_unit_test(shutdown_stops_switching),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
