/*
 * libFuzzer target: the serial stream decoder, byte at a time.
 *
 * Besides ASan/UBSan finding any read past a buffer, it checks the property
 * that makes the decoder trustworthy: a frame is accepted only if it is
 * exactly the canonical encoding of the message it yields (re-encoding the
 * message with its seq reproduces the bytes since the last delimiter; for
 * SAMPLE_SENSORS up to the reserved bits its decoder drops), and
 * the decoder's buffers never exceed their bounds. The buffer-at-a-time entry
 * point, fed the same bytes in chunks the input chooses, must agree exactly.
 */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "../hil_proto.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* COBS-decodes a frame without its delimiter (every code byte's run checked by the decoder
 * already); returns the raw length. */
static size_t uncobs(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t o = 0;
    for (size_t i = 0; i < n;) {
        uint8_t code = in[i++];
        for (uint8_t k = 1; k < code && i < n; k++) {
            out[o++] = in[i++];
        }
        if (code != 0xFFu && i < n) {
            out[o++] = 0u;
        }
    }
    return o;
}

/* SAMPLE_SENSORS is the one type whose decoder drops bits: the reserved bits of status, hall and
 * the comparators (SPEC.md 6.13). A frame with them set re-encodes to other bytes (and another
 * CRC); its payload must then equal the canonical one once those bits are cleared, nothing else. */
static int canonical_but_reserved_bits(const hil_msg *m, const uint8_t *frame, size_t len,
                                       const uint8_t *canonical)
{
    if (m->type != HIL_MSG_SAMPLE_SENSORS || len < 2u) {
        return 0;
    }
    uint8_t raw[HIL_MAX_RAW_FRAME + 2u], want[HIL_MAX_RAW_FRAME + 2u];
    size_t n = uncobs(frame, len - 1u, raw);
    size_t nw = uncobs(canonical, len - 1u, want);
    if (n != nw || n < HIL_HEADER_SIZE + HIL_SAMPLE_SENSORS_FIXED_SIZE + HIL_CRC_SIZE) {
        return 0;
    }
    uint8_t *p = raw + HIL_HEADER_SIZE;
    uint16_t set = (uint16_t)(p[4] | (p[5] << 8));
    p[6] &= 0x0Fu;
    size_t at = HIL_SAMPLE_SENSORS_FIXED_SIZE;
    for (unsigned bit = 0; bit < 5u; bit++) { /* currents a, b, c, vdc, encoder: u16 each */
        at += ((set >> bit) & 1u) * 2u;
    }
    if ((set & HIL_SENSOR_HALL) != 0u) {
        p[at++] &= 0x07u;
    }
    at += (set & HIL_SENSOR_TERMINAL_VOLTAGES) != 0u ? 6u : 0u;
    if ((set & HIL_SENSOR_BEMF_COMPARATORS) != 0u) {
        p[at] &= 0x07u;
    }
    /* header and payload equal; the CRCs differ as the payloads did */
    return memcmp(raw, want, n - HIL_CRC_SIZE) == 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    hil_decoder dec;
    hil_decoder_init(&dec);
    size_t frame_start = 0;
    uint32_t hash_bytewise = 0;
    for (size_t i = 0; i < size; i++) {
        hil_msg m;
        uint32_t ok_before = dec.frames_ok;
        uint32_t before = dec.frames_ok + dec.crc_errors + dec.framing_errors + dec.unknown_types +
                          dec.version_errors + dec.length_errors;
        int got = hil_decoder_feed(&dec, data[i], &m);
        if (dec.len > sizeof dec.buf || dec.encoded_len > HIL_MAX_ENCODED_SEGMENT) {
            __builtin_trap();
        }
        uint32_t events = dec.frames_ok + dec.crc_errors + dec.framing_errors + dec.unknown_types +
                          dec.version_errors + dec.length_errors - before;
        if (data[i] != 0u) {
            if (got || events != 0u) {
                __builtin_trap(); /* only a delimiter completes or rejects a frame */
            }
            continue;
        }
        /* a delimiter: one event per non-empty candidate frame, none for an empty one */
        if (events != (i == frame_start ? 0u : 1u) || got != (dec.frames_ok != ok_before)) {
            __builtin_trap();
        }
        if (got) {
            uint8_t again[HIL_MAX_ENCODED_FRAME];
            int n = hil_frame_encode(&m, again, sizeof again);
            size_t len = i + 1 - frame_start;
            if (n < 0 || (size_t)n != len) {
                __builtin_trap();
            }
            if (memcmp(again, data + frame_start, len) != 0 && !canonical_but_reserved_bits(&m, data + frame_start, len, again)) {
                __builtin_trap();
            }
            hash_bytewise = hash_bytewise * 31u + hil_crc16(again, (size_t)n);
        }
        frame_start = i + 1;
    }

    hil_decoder buf_dec;
    hil_decoder_init(&buf_dec);
    uint32_t hash_buf = 0;
    size_t at = 0;
    while (at < size) {
        size_t chunk = 1u + (size_t)(data[at] % 23u); /* chunk sizes from the input itself */
        size_t end = at + chunk < size ? at + chunk : size;
        while (at < end) {
            hil_msg m;
            int got;
            at += hil_decoder_feed_buf(&buf_dec, data + at, end - at, &m, &got);
            if (got) {
                uint8_t again[HIL_MAX_ENCODED_FRAME];
                int n = hil_frame_encode(&m, again, sizeof again);
                hash_buf = hash_buf * 31u + hil_crc16(again, (size_t)(n < 0 ? 0 : n));
            }
        }
    }
    if (hash_buf != hash_bytewise || buf_dec.frames_ok != dec.frames_ok || buf_dec.crc_errors != dec.crc_errors ||
        buf_dec.framing_errors != dec.framing_errors || buf_dec.seq_gaps != dec.seq_gaps ||
        buf_dec.unknown_types != dec.unknown_types || buf_dec.version_errors != dec.version_errors ||
        buf_dec.length_errors != dec.length_errors || buf_dec.len != dec.len ||
        buf_dec.encoded_len != dec.encoded_len || buf_dec.overflow != dec.overflow) {
        __builtin_trap();
    }
    return 0;
}
