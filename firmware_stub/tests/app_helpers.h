/* Helpers for the application-layer tests: a bench side built on the codec. */
#ifndef APP_HELPERS_H
#define APP_HELPERS_H

#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "hil_proto.h"
#include "hil_stub.h"

#define MAX_REPLIES 64

typedef struct {
    void *stub;
    uint8_t seq;
    hil_decoder dec;
    hil_msg replies[MAX_REPLIES];
    size_t n_replies;
} bench;

static inline void bench_open(bench *b)
{
    b->stub = malloc(hil_stub_instance_size()); /* malloc aligns for any type */
    assert_non_null(b->stub);
    hil_stub_init(b->stub);
    b->seq = 0;
    hil_decoder_init(&b->dec);
    b->n_replies = 0;
}

static inline void bench_close(bench *b) { free(b->stub); }

/* Decodes answer bytes into b->replies (appending). */
static inline void bench_take(bench *b, const uint8_t *tx, size_t n)
{
    hil_msg m;
    for (size_t i = 0; i < n; ++i) {
        if (hil_decoder_feed(&b->dec, tx[i], &m)) {
            assert_true(b->n_replies < MAX_REPLIES);
            b->replies[b->n_replies++] = m;
        }
    }
}

/* Sends raw bytes in one call; collects every answer byte. */
static inline size_t bench_send_bytes(bench *b, const uint8_t *bytes, size_t len)
{
    uint8_t tx[2048];
    size_t total = 0;
    size_t n = hil_stub_exchange(b->stub, bytes, len, tx, sizeof tx);
    while (n > 0) {
        bench_take(b, tx, n);
        total += n;
        n = hil_stub_exchange(b->stub, NULL, 0, tx, sizeof tx);
    }
    return total;
}

static inline size_t bench_encode(bench *b, hil_msg *m, uint8_t *out, size_t cap)
{
    m->seq = b->seq++;
    int n = hil_frame_encode(m, out, cap);
    assert_true(n > 0);
    return (size_t)n;
}

static inline void bench_send(bench *b, hil_msg *m)
{
    uint8_t buf[HIL_MAX_ENCODED_FRAME];
    size_t n = bench_encode(b, m, buf, sizeof buf);
    bench_send_bytes(b, buf, n);
}

/* Index of the first reply of a type at or after `from`, or -1. */
static inline int bench_find(const bench *b, uint8_t type, size_t from)
{
    for (size_t i = from; i < b->n_replies; ++i) {
        if (b->replies[i].type == type) {
            return (int)i;
        }
    }
    return -1;
}

static inline size_t bench_count(const bench *b, uint8_t type)
{
    size_t n = 0;
    for (size_t i = 0; i < b->n_replies; ++i) {
        n += b->replies[i].type == type;
    }
    return n;
}

static inline hil_msg msg_hello(void)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_HELLO;
    m.u.hello.proto_version = HIL_PROTO_VERSION;
    m.u.hello.role = HIL_ROLE_BENCH;
    m.u.hello.control_period_ns = 50000u;
    m.u.hello.name_len = 9;
    memcpy(m.u.hello.name, "hil-bench", 9);
    return m;
}

static inline hil_msg msg_sample(uint32_t period, double ia, double ib, uint16_t encoder)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_SAMPLE;
    m.u.sample.period = period;
    m.u.sample.adc_i1 = (uint16_t)lround(2048.0 + ia / 0.01220703125);
    m.u.sample.adc_i2 = (uint16_t)lround(2048.0 + ib / 0.01220703125);
    m.u.sample.adc_vdc = 2867u;
    m.u.sample.encoder = encoder;
    return m;
}

static inline hil_msg msg_command(uint8_t flags, uint8_t source, float speed)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_COMMAND;
    m.u.command.flags = flags;
    m.u.command.speed_source = source;
    m.u.command.speed_ref_rad_s = speed;
    return m;
}

static inline hil_msg msg_param(uint8_t type, uint16_t id, float value)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = type;
    if (type == HIL_MSG_PARAM_SET) {
        m.u.param_set.id = id;
        m.u.param_set.value = value;
    } else {
        m.u.param_get.id = id;
    }
    return m;
}

#endif
