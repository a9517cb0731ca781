/*
 * Byte-in, byte-out entry points for build/libhilproto.so, so the Python tests
 * can hold the C codec against the Python one on inputs hypothesis makes up
 * (tests/test_protocol_c_parity.py). Messages cross as payload bytes or as
 * serial frames, never as structs, so Python needs no struct layouts.
 */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "../hil_proto.h"

int hil_shim_frame_from_payload(uint8_t type, uint8_t seq, const uint8_t *payload, size_t len, uint8_t *out,
                                size_t cap);
int hil_shim_can_from_payload(uint8_t type, uint8_t seq, uint8_t role, uint16_t base_id, const uint8_t *payload,
                              size_t len, uint8_t *out, size_t cap);
long hil_shim_decode_stream(const uint8_t *data, size_t len, uint8_t *out, size_t cap, uint32_t counters[8]);
long hil_shim_can_stream(uint16_t base_id, const uint8_t *frames, size_t count, uint8_t *out, size_t cap,
                         uint32_t counters[5]);

/* Payload -> C message -> serial frame with the given seq. */
int hil_shim_frame_from_payload(uint8_t type, uint8_t seq, const uint8_t *payload, size_t len, uint8_t *out,
                                size_t cap)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    int rc = hil_payload_decode(type, payload, len, &m);
    if (rc != HIL_OK) {
        return rc;
    }
    m.seq = seq;
    return hil_frame_encode(&m, out, cap);
}

/* Payload -> C message -> CAN frames, written as 11-byte records: id u16 LE, dlc u8, data[8].
 * Returns the number of frames or a negative hil_result. */
int hil_shim_can_from_payload(uint8_t type, uint8_t seq, uint8_t role, uint16_t base_id, const uint8_t *payload,
                              size_t len, uint8_t *out, size_t cap)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    int rc = hil_payload_decode(type, payload, len, &m);
    if (rc != HIL_OK) {
        return rc;
    }
    m.seq = seq;
    hil_can_frame frames[HIL_CAN_MAX_FRAMES];
    int n = hil_can_pack(&m, role, base_id, frames, HIL_CAN_MAX_FRAMES);
    if (n < 0) {
        return n;
    }
    if ((size_t)n * 11u > cap) {
        return HIL_ERR_BUFFER;
    }
    for (int i = 0; i < n; i++) {
        uint8_t *r = out + 11 * i;
        r[0] = (uint8_t)frames[i].id;
        r[1] = (uint8_t)(frames[i].id >> 8);
        r[2] = frames[i].dlc;
        memcpy(r + 3, frames[i].data, 8);
    }
    return n;
}

/* Feeds a byte stream to a fresh decoder (hil_decoder_feed_buf, so the Python parity tests
 * cover that entry point; the C vector tests cover both); each decoded message is written re-encoded as a
 * serial frame with its received seq. counters: frames_ok, crc_errors, framing_errors,
 * seq_gaps, unknown_types, version_errors, length_errors, last_bad_version.
 * Returns the bytes written, or -1 when out is too small. */
long hil_shim_decode_stream(const uint8_t *data, size_t len, uint8_t *out, size_t cap, uint32_t counters[8])
{
    hil_decoder dec;
    hil_decoder_init(&dec);
    size_t used = 0;
    size_t at = 0;
    while (at < len) {
        hil_msg m;
        int got;
        at += hil_decoder_feed_buf(&dec, data + at, len - at, &m, &got);
        if (got) {
            int n = hil_frame_encode(&m, out + used, cap - used);
            if (n < 0) {
                return -1;
            }
            used += (size_t)n;
        }
    }
    counters[0] = dec.frames_ok;
    counters[1] = dec.crc_errors;
    counters[2] = dec.framing_errors;
    counters[3] = dec.seq_gaps;
    counters[4] = dec.unknown_types;
    counters[5] = dec.version_errors;
    counters[6] = dec.length_errors;
    counters[7] = dec.last_bad_version;
    return (long)used;
}

/* Feeds 11-byte frame records (as above; dlc may exceed 8) to a fresh reassembler; each
 * message is written as a role byte followed by its serial frame (seq = the CAN counter).
 * counters: messages_ok, sequence_errors, unknown_types, length_errors, ignored_frames. */
long hil_shim_can_stream(uint16_t base_id, const uint8_t *frames, size_t count, uint8_t *out, size_t cap,
                         uint32_t counters[5])
{
    hil_can_rx rx;
    hil_can_rx_init(&rx, base_id);
    size_t used = 0;
    for (size_t i = 0; i < count; i++) {
        const uint8_t *r = frames + 11 * i;
        hil_can_frame f;
        f.id = (uint16_t)(r[0] | (r[1] << 8));
        f.dlc = r[2];
        memcpy(f.data, r + 3, 8);
        hil_msg m;
        uint8_t role;
        if (hil_can_rx_feed(&rx, &f, &m, &role)) {
            if (used + 1u > cap) {
                return -1;
            }
            out[used++] = role;
            int n = hil_frame_encode(&m, out + used, cap - used);
            if (n < 0) {
                return -1;
            }
            used += (size_t)n;
        }
    }
    counters[0] = rx.messages_ok;
    counters[1] = rx.sequence_errors;
    counters[2] = rx.unknown_types;
    counters[3] = rx.length_errors;
    counters[4] = rx.ignored_frames;
    return (long)used;
}
