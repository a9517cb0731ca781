/*
 * libFuzzer target: the CAN reassembler.
 *
 * Input: records of id (2 bytes, 11 bits used), dlc (1 byte, 0..15: a value
 * above 8 must be refused, never read), then min(dlc, 8) data bytes. Ids are
 * folded near the protocol's range so most frames are ours. Every message
 * that comes out must pack again and reassemble, in a fresh receiver, into
 * the same payload (the period of SAMPLE/DUTY/DUTY_LEGS compared in its transmitted bits).
 */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "../hil_proto.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static void same_message(const hil_msg *a, const hil_msg *b)
{
    uint8_t pa[HIL_MAX_PAYLOAD], pb[HIL_MAX_PAYLOAD];
    hil_msg x = *a, y = *b;
    if (x.type == HIL_MSG_SAMPLE) {
        x.u.sample.period &= 0xFFu;
        y.u.sample.period &= 0xFFu;
    } else if (x.type == HIL_MSG_DUTY) {
        x.u.duty.period &= 0xFFFFu;
        y.u.duty.period &= 0xFFFFu;
    } else if (x.type == HIL_MSG_DUTY_LEGS) {
        x.u.duty_legs.period &= 0x1FFFu; /* 13 bits: the leg enables share the word */
        y.u.duty_legs.period &= 0x1FFFu;
    }
    int na = hil_payload_encode(&x, pa, sizeof pa);
    int nb = hil_payload_encode(&y, pb, sizeof pb);
    if (na < 0 || na != nb || memcmp(pa, pb, (size_t)na) != 0 || x.type != y.type) {
        __builtin_trap();
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const uint16_t base = HIL_CAN_DEFAULT_BASE_ID;
    hil_can_rx rx;
    hil_can_rx_init(&rx, base);
    size_t i = 0;
    while (i + 3u <= size) {
        hil_can_frame f;
        memset(&f, 0, sizeof f);
        uint16_t raw_id = (uint16_t)((data[i] | (data[i + 1] << 8)) & 0x7FF);
        f.id = (uint16_t)(raw_id < 0x80u ? base - 0x10u + raw_id : raw_id); /* mostly ours */
        f.dlc = (uint8_t)(data[i + 2] & 0x0Fu);
        i += 3;
        size_t n = f.dlc > 8u ? 8u : f.dlc;
        if (i + n > size) {
            n = size - i;
        }
        memcpy(f.data, data + i, n);
        i += n;
        hil_msg m;
        uint8_t role = 0xFF;
        if (!hil_can_rx_feed(&rx, &f, &m, &role)) {
            continue;
        }
        if (role >= HIL_CAN_ROLES) {
            __builtin_trap();
        }
        hil_can_frame frames[HIL_CAN_MAX_FRAMES];
        int count = hil_can_pack(&m, role, base, frames, HIL_CAN_MAX_FRAMES);
        if (count <= 0) {
            __builtin_trap();
        }
        hil_can_rx fresh;
        hil_can_rx_init(&fresh, base);
        hil_msg again;
        for (int k = 0; k < count; k++) {
            int done = hil_can_rx_feed(&fresh, &frames[k], &again, NULL);
            if (done != (k + 1 == count)) {
                __builtin_trap();
            }
        }
        same_message(&m, &again);
    }
    return 0;
}
