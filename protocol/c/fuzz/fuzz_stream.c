/*
 * libFuzzer target: the serial stream decoder, byte at a time.
 *
 * Besides ASan/UBSan finding any read past a buffer, it checks the property
 * that makes the decoder trustworthy: a frame is accepted only if it is
 * exactly the canonical encoding of the message it yields (re-encoding the
 * message with its seq reproduces the bytes since the last delimiter), and
 * the decoder's buffers never exceed their bounds. The buffer-at-a-time entry
 * point, fed the same bytes in chunks the input chooses, must agree exactly.
 */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "../hil_proto.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

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
            if (n < 0 || (size_t)n != len || memcmp(again, data + frame_start, len) != 0) {
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
