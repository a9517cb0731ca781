/*
 * C side of the shared vectors: every message is built from its fields and
 * must encode to the recorded serial and CAN bytes and decode back; every
 * stream must yield the recorded messages and counters. Plus the C-only
 * contract: buffer limits, untouched outputs on error, the CRC check value.
 *
 * usage: test_vectors [VECTOR_FILE...]   (default: ../vectors/vectors.txt ../vectors/handbuilt.txt)
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "../hil_proto.h"
#include "vectors.h"

#define MAX_FILES 8
static vec_file g_files[MAX_FILES];

static void assert_msg_equal(const hil_msg *got, const hil_msg *want)
{
    assert_int_equal(got->type, want->type);
    uint8_t a[HIL_MAX_PAYLOAD], b[HIL_MAX_PAYLOAD];
    int na = hil_payload_encode(got, a, sizeof a);
    int nb = hil_payload_encode(want, b, sizeof b);
    assert_true(nb >= 0);
    assert_int_equal(na, nb);
    assert_memory_equal(a, b, (size_t)na);
}

/* ------------------------------------------------------------------ message vectors */

static void test_message(void **state)
{
    const vec_message *v = *state;
    uint8_t out[HIL_MAX_ENCODED_FRAME];

    /* serial: fields -> bytes */
    int n = hil_frame_encode(&v->msg, out, sizeof out);
    assert_int_equal(n, (int)v->serial_len);
    assert_memory_equal(out, v->serial, v->serial_len);

    /* serial: bytes -> fields, completed by the delimiter and not before */
    hil_decoder dec;
    hil_decoder_init(&dec);
    hil_msg got;
    for (size_t i = 0; i + 1 < v->serial_len; i++) {
        assert_int_equal(hil_decoder_feed(&dec, v->serial[i], &got), 0);
    }
    assert_int_equal(hil_decoder_feed(&dec, v->serial[v->serial_len - 1], &got), 1);
    assert_int_equal(got.seq, v->msg.seq);
    assert_msg_equal(&got, &v->msg);
    assert_int_equal(dec.frames_ok, 1);

    /* CAN: fields -> frames */
    hil_can_frame frames[HIL_CAN_MAX_FRAMES];
    int count = hil_can_pack(&v->msg, v->role, v->base_id, frames, HIL_CAN_MAX_FRAMES);
    assert_int_equal(count, (int)v->can_count);
    for (size_t i = 0; i < v->can_count; i++) {
        assert_int_equal(frames[i].id, v->can[i].id);
        assert_int_equal(frames[i].dlc, v->can[i].dlc);
        assert_memory_equal(frames[i].data, v->can[i].data, v->can[i].dlc);
    }

    /* CAN: frames -> fields, completed by the last frame only */
    hil_can_rx rx;
    hil_can_rx_init(&rx, v->base_id);
    uint8_t role = 0xFF;
    for (size_t i = 0; i < v->can_count; i++) {
        int done = hil_can_rx_feed(&rx, &v->can[i], &got, &role);
        assert_int_equal(done, i + 1 == v->can_count);
    }
    assert_int_equal(role, v->role);
    assert_msg_equal(&got, &v->can_msg);
    assert_int_equal(rx.messages_ok, 1);
}

static void test_reject(void **state)
{
    const vec_message *v = *state;
    uint8_t out[HIL_MAX_ENCODED_FRAME];
    hil_can_frame frames[HIL_CAN_MAX_FRAMES];
    assert_int_equal(hil_payload_encode(&v->msg, out, sizeof out), HIL_ERR_RANGE);
    assert_int_equal(hil_frame_encode(&v->msg, out, sizeof out), HIL_ERR_RANGE);
    assert_int_equal(hil_can_pack(&v->msg, 0, HIL_CAN_DEFAULT_BASE_ID, frames, HIL_CAN_MAX_FRAMES), HIL_ERR_RANGE);
}

/* ------------------------------------------------------------------ stream vectors */

typedef struct {
    const char *name;
    size_t offset;
    size_t size;
} counter_desc;

#define SERIAL_COUNTER(n) {#n, offsetof(hil_decoder, n), sizeof(((hil_decoder *)0)->n)}
#define CAN_COUNTER(n) {#n, offsetof(hil_can_rx, n), sizeof(((hil_can_rx *)0)->n)}

static const counter_desc SERIAL_COUNTERS[] = {
    SERIAL_COUNTER(frames_ok),     SERIAL_COUNTER(crc_errors),     SERIAL_COUNTER(framing_errors),
    SERIAL_COUNTER(seq_gaps),      SERIAL_COUNTER(unknown_types),  SERIAL_COUNTER(version_errors),
    SERIAL_COUNTER(length_errors), SERIAL_COUNTER(last_bad_version)};
static const counter_desc CAN_COUNTERS[] = {CAN_COUNTER(messages_ok), CAN_COUNTER(sequence_errors),
                                            CAN_COUNTER(unknown_types), CAN_COUNTER(length_errors),
                                            CAN_COUNTER(ignored_frames)};

static uint32_t read_counter(const void *base, const counter_desc *c)
{
    const uint8_t *p = (const uint8_t *)base + c->offset;
    if (c->size == 1u) {
        return *p;
    }
    uint32_t v;
    memcpy(&v, p, sizeof v);
    return v;
}

static void check_counters(const vec_stream *s, const void *state, const counter_desc *table, size_t n)
{
    /* every counter the vector names must exist here ... */
    for (size_t i = 0; i < s->counter_count; i++) {
        int known = 0;
        for (size_t k = 0; k < n; k++) {
            known |= strcmp(table[k].name, s->counters[i].name) == 0;
        }
        if (!known) {
            fail_msg("vector %s names unknown counter %s", s->name, s->counters[i].name);
        }
    }
    /* ... and every counter here must match (0 when the vector does not name it) */
    for (size_t k = 0; k < n; k++) {
        uint32_t got = read_counter(state, &table[k]);
        uint32_t want = vec_counter_value(s, table[k].name);
        if (got != want) {
            fail_msg("%s: counter %s is %u, expected %u", s->name, table[k].name, (unsigned)got, (unsigned)want);
        }
    }
}

static void test_serial_stream(void **state)
{
    const vec_stream *s = *state;
    hil_decoder dec;
    hil_decoder_init(&dec);
    size_t yielded = 0;
    for (size_t i = 0; i < s->len; i++) {
        hil_msg got;
        if (hil_decoder_feed(&dec, s->bytes[i], &got)) {
            assert_true(yielded < s->yield_count);
            assert_msg_equal(&got, &s->messages[s->yields[yielded]].msg);
            yielded++;
        }
        assert_true(dec.len <= sizeof dec.buf);
        assert_true(dec.encoded_len <= HIL_MAX_ENCODED_SEGMENT);
    }
    assert_int_equal(yielded, s->yield_count);
    check_counters(s, &dec, SERIAL_COUNTERS, sizeof SERIAL_COUNTERS / sizeof SERIAL_COUNTERS[0]);

    /* the buffer-at-a-time entry point: same messages, same counters */
    hil_decoder_init(&dec);
    yielded = 0;
    size_t at = 0;
    while (at < s->len) {
        hil_msg got;
        int done;
        at += hil_decoder_feed_buf(&dec, s->bytes + at, s->len - at, &got, &done);
        if (done) {
            assert_true(yielded < s->yield_count);
            assert_msg_equal(&got, &s->messages[s->yields[yielded]].msg);
            yielded++;
        }
    }
    assert_int_equal(yielded, s->yield_count);
    check_counters(s, &dec, SERIAL_COUNTERS, sizeof SERIAL_COUNTERS / sizeof SERIAL_COUNTERS[0]);
}

static void test_can_stream(void **state)
{
    const vec_stream *s = *state;
    hil_can_rx rx;
    hil_can_rx_init(&rx, s->base_id);
    size_t yielded = 0;
    for (size_t i = 0; i < s->frame_count; i++) {
        hil_msg got;
        uint8_t role = 0xFF;
        if (hil_can_rx_feed(&rx, &s->frames[i], &got, &role)) {
            assert_true(yielded < s->yield_count);
            assert_msg_equal(&got, &s->messages[s->yields[yielded]].msg);
            assert_int_equal(role, s->yield_roles[yielded]);
            yielded++;
        }
    }
    assert_int_equal(yielded, s->yield_count);
    check_counters(s, &rx, CAN_COUNTERS, sizeof CAN_COUNTERS / sizeof CAN_COUNTERS[0]);
}

/* ------------------------------------------------------------------ C-only contract */

static hil_msg telemetry_msg(void)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_TELEMETRY;
    m.seq = 9;
    m.u.telemetry.period = 77;
    m.u.telemetry.speed_ekf_rad_s = 314.0f;
    return m;
}

static void test_crc_check_value(void **state)
{
    (void)state;
    assert_int_equal(hil_crc16((const uint8_t *)"123456789", 9), 0x29B1);
    assert_int_equal(hil_crc16((const uint8_t *)"", 0), 0xFFFF);
}

static void test_limits_are_consistent(void **state)
{
    (void)state;
    assert_int_equal(HIL_MAX_RAW_FRAME, 70);
    assert_int_equal(HIL_MAX_ENCODED_FRAME, 72);
    /* the longest message fits with room to spare */
    hil_msg m = telemetry_msg();
    uint8_t out[HIL_MAX_ENCODED_FRAME];
    assert_int_equal(hil_frame_encode(&m, out, sizeof out), 64);
    hil_can_frame frames[HIL_CAN_MAX_FRAMES];
    assert_int_equal(hil_can_pack(&m, 1, HIL_CAN_DEFAULT_BASE_ID, frames, HIL_CAN_MAX_FRAMES), 8);
}

static void test_small_buffers_are_refused_untouched(void **state)
{
    (void)state;
    hil_msg m = telemetry_msg();
    uint8_t out[HIL_MAX_ENCODED_FRAME];
    uint8_t pattern[HIL_MAX_ENCODED_FRAME];
    memset(out, 0xA5, sizeof out);
    memset(pattern, 0xA5, sizeof pattern);
    assert_int_equal(hil_frame_encode(&m, out, 63), HIL_ERR_BUFFER);
    assert_int_equal(hil_payload_encode(&m, out, 55), HIL_ERR_BUFFER);
    assert_memory_equal(out, pattern, sizeof out);
    assert_int_equal(hil_payload_encode(&m, out, 56), 56);

    hil_can_frame frames[HIL_CAN_MAX_FRAMES];
    assert_int_equal(hil_can_pack(&m, 1, HIL_CAN_DEFAULT_BASE_ID, frames, 7), HIL_ERR_BUFFER);
    m.type = HIL_MSG_GATES;
    assert_int_equal(hil_can_pack(&m, 1, HIL_CAN_DEFAULT_BASE_ID, frames, 0), HIL_ERR_BUFFER);
    m.type = HIL_MSG_SAMPLE;
    memset(&m.u, 0, sizeof m.u);
    assert_int_equal(hil_can_pack(&m, 0, HIL_CAN_DEFAULT_BASE_ID, frames, 0), HIL_ERR_BUFFER);
}

static void test_bad_arguments(void **state)
{
    (void)state;
    hil_msg m = telemetry_msg();
    hil_can_frame frames[HIL_CAN_MAX_FRAMES];
    uint8_t out[HIL_MAX_ENCODED_FRAME];
    assert_int_equal(hil_can_pack(&m, 2, HIL_CAN_DEFAULT_BASE_ID, frames, HIL_CAN_MAX_FRAMES), HIL_ERR_RANGE);
    assert_int_equal(hil_can_pack(&m, 1, 0x7C1, frames, HIL_CAN_MAX_FRAMES), HIL_ERR_RANGE);
    assert_int_equal(hil_can_pack(&m, 1, 0x7C0, frames, HIL_CAN_MAX_FRAMES), 8);
    m.type = 0;
    assert_int_equal(hil_frame_encode(&m, out, sizeof out), HIL_ERR_UNKNOWN_TYPE);
    m.type = 0x0E;
    assert_int_equal(hil_payload_encode(&m, out, sizeof out), HIL_ERR_UNKNOWN_TYPE);
    assert_int_equal(hil_can_pack(&m, 0, HIL_CAN_DEFAULT_BASE_ID, frames, HIL_CAN_MAX_FRAMES), HIL_ERR_UNKNOWN_TYPE);
    hil_msg d;
    assert_int_equal(hil_payload_decode(0x0E, out, 0, &d), HIL_ERR_UNKNOWN_TYPE);
    assert_int_equal(hil_payload_decode(HIL_MSG_GATES, out, 4, &d), HIL_ERR_LENGTH);
}

/* Test-side COBS, for frames with a chosen defect. */
static size_t cobs(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t code_at = 0, o = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < n; i++) {
        if (in[i] == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
        } else {
            out[o++] = in[i];
            code++;
        }
    }
    out[code_at] = code;
    out[o++] = 0;
    return o;
}

static void feed_defective(const uint8_t *payload, size_t len, uint8_t type, uint16_t crc_xor,
                           uint32_t expected_event, size_t counter_offset)
{
    uint8_t raw[HIL_MAX_RAW_FRAME], enc[HIL_MAX_ENCODED_FRAME];
    raw[0] = HIL_PROTO_VERSION;
    raw[1] = type;
    raw[2] = 0;
    raw[3] = (uint8_t)len;
    memcpy(raw + 4, payload, len);
    uint16_t crc = (uint16_t)(hil_crc16(raw, 4 + len) ^ crc_xor);
    raw[4 + len] = (uint8_t)crc;
    raw[5 + len] = (uint8_t)(crc >> 8);
    size_t n = cobs(raw, 6 + len, enc);
    hil_decoder dec;
    hil_decoder_init(&dec);
    hil_msg out, pattern;
    memset(&out, 0x5A, sizeof out);
    memset(&pattern, 0x5A, sizeof pattern);
    for (size_t i = 0; i < n; i++) {
        assert_int_equal(hil_decoder_feed(&dec, enc[i], &out), 0);
    }
    uint32_t counter;
    memcpy(&counter, (const uint8_t *)&dec + counter_offset, sizeof counter);
    assert_int_equal(counter, expected_event);
    assert_memory_equal(&out, &pattern, sizeof out);
    /* control: the same bytes without the defect do decode */
    if (type == HIL_MSG_TELEMETRY && len == 56 && crc_xor != 0) {
        raw[4 + len] = (uint8_t)(crc ^ crc_xor);
        raw[5 + len] = (uint8_t)((crc ^ crc_xor) >> 8);
        n = cobs(raw, 6 + len, enc);
        int got = 0;
        for (size_t i = 0; i < n; i++) {
            got += hil_decoder_feed(&dec, enc[i], &out);
        }
        assert_int_equal(got, 1);
        assert_int_equal(out.u.telemetry.period, 0x04030201u);
    }
}

static void test_decoder_output_untouched_on_error(void **state)
{
    (void)state;
    uint8_t hello[20] = {1, 0, 0, 0, 0x50, 0xC3, 0, 0, 12 /* name_len, but 11 name bytes follow */};
    feed_defective(hello, sizeof hello, HIL_MSG_HELLO, 0, 1, offsetof(hil_decoder, length_errors));
    uint8_t telemetry[56] = {1, 2, 3, 4};
    feed_defective(telemetry, sizeof telemetry, HIL_MSG_TELEMETRY, 0x0100, 1, offsetof(hil_decoder, crc_errors));
    feed_defective(telemetry, 55, HIL_MSG_TELEMETRY, 0, 1, offsetof(hil_decoder, length_errors));
    feed_defective(telemetry, 8, 0x0E, 0, 1, offsetof(hil_decoder, unknown_types));
}

static void test_can_extension_wraps_32_bits(void **state)
{
    (void)state;
    hil_can_rx rx;
    hil_can_rx_init(&rx, HIL_CAN_DEFAULT_BASE_ID);
    hil_msg m, got;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_STATUS;
    m.u.status.period = 0xFFFFFFFFu;
    hil_can_frame f[1];
    assert_int_equal(hil_can_pack(&m, 1, HIL_CAN_DEFAULT_BASE_ID, f, 1), 1);
    assert_int_equal(hil_can_rx_feed(&rx, &f[0], &got, NULL), 1);
    m.type = HIL_MSG_SAMPLE;
    memset(&m.u, 0, sizeof m.u);
    m.u.sample.period = 0; /* one period later, modulo 2^32 */
    assert_int_equal(hil_can_pack(&m, 0, HIL_CAN_DEFAULT_BASE_ID, f, 1), 1);
    assert_int_equal(hil_can_rx_feed(&rx, &f[0], &got, NULL), 1);
    assert_int_equal(got.u.sample.period, 0);
    m.u.sample.period = 0xFFFFFFFEu; /* and two back again */
    assert_int_equal(hil_can_pack(&m, 0, HIL_CAN_DEFAULT_BASE_ID, f, 1), 1);
    assert_int_equal(hil_can_rx_feed(&rx, &f[0], &got, NULL), 1);
    assert_int_equal(got.u.sample.period, 0xFFFFFFFEu);
}

static void test_dlc_above_8_is_a_length_error(void **state)
{
    (void)state;
    hil_can_rx rx;
    hil_can_rx_init(&rx, HIL_CAN_DEFAULT_BASE_ID);
    hil_can_frame f;
    memset(&f, 0, sizeof f);
    f.id = HIL_CAN_DEFAULT_BASE_ID + HIL_MSG_TELEMETRY + 0x20;
    f.dlc = 15; /* a corrupt driver value must not make the reassembler read past data[8] */
    hil_msg got;
    assert_int_equal(hil_can_rx_feed(&rx, &f, &got, NULL), 0);
    assert_int_equal(rx.length_errors, 1);
}

/* ------------------------------------------------------------------ main */

int main(int argc, char **argv)
{
    static const char *const defaults[] = {"../vectors/vectors.txt", "../vectors/handbuilt.txt"};
    const char *const *paths = argc > 1 ? (const char *const *)(argv + 1) : defaults;
    size_t nfiles = argc > 1 ? (size_t)(argc - 1) : 2u;
    if (nfiles > MAX_FILES) {
        fprintf(stderr, "at most %d vector files\n", MAX_FILES);
        return 2;
    }
    for (size_t f = 0; f < nfiles; f++) {
        if (vec_load(paths[f], &g_files[f]) != 0) {
            return 2;
        }
    }
    const struct CMUnitTest unit[] = {
        cmocka_unit_test(test_crc_check_value),
        cmocka_unit_test(test_limits_are_consistent),
        cmocka_unit_test(test_small_buffers_are_refused_untouched),
        cmocka_unit_test(test_bad_arguments),
        cmocka_unit_test(test_decoder_output_untouched_on_error),
        cmocka_unit_test(test_can_extension_wraps_32_bits),
        cmocka_unit_test(test_dlc_above_8_is_a_length_error),
    };
    int failed = cmocka_run_group_tests_name("codec", unit, NULL, NULL);

    size_t n = 0;
    for (size_t f = 0; f < nfiles; f++) {
        n += g_files[f].message_count + g_files[f].stream_count;
    }
    struct CMUnitTest *tests = calloc(n, sizeof *tests);
    char(*names)[VEC_NAME_MAX + 16] = calloc(n, sizeof *names);
    if (tests == NULL || names == NULL) {
        return 2;
    }
    size_t k = 0;
    for (size_t f = 0; f < nfiles; f++) {
        const vec_file *vf = &g_files[f];
        for (size_t i = 0; i < vf->message_count; i++, k++) {
            vec_message *v = &vf->messages[i];
            snprintf(names[k], sizeof names[k], "%s %s", v->is_reject ? "reject" : "message", v->name);
            tests[k].name = names[k];
            tests[k].test_func = v->is_reject ? test_reject : test_message;
            tests[k].initial_state = v;
        }
        for (size_t i = 0; i < vf->stream_count; i++, k++) {
            vec_stream *s = &vf->streams[i];
            snprintf(names[k], sizeof names[k], "%s %s", s->is_can ? "can_stream" : "serial_stream", s->name);
            tests[k].name = names[k];
            tests[k].test_func = s->is_can ? test_can_stream : test_serial_stream;
            tests[k].initial_state = s;
        }
    }
    failed += _cmocka_run_group_tests("vectors", tests, n, NULL, NULL);
    free(names);
    free(tests);
    for (size_t f = 0; f < nfiles; f++) {
        vec_free(&g_files[f]);
    }
    return failed == 0 ? 0 : 1;
}
