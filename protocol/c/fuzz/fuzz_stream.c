/*
 * libFuzzer target: the serial stream decoder, byte at a time.
 *
 * Besides ASan/UBSan finding any read past a buffer, it checks the property
 * that makes the decoder trustworthy: a frame is accepted only if it is
 * exactly the canonical encoding of the message it yields (re-encoding the
 * message with its seq reproduces the bytes since the last delimiter), and
 * the decoder's buffers never exceed their bounds.
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
        }
        frame_start = i + 1;
    }
    return 0;
}
