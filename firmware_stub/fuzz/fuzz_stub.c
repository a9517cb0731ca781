/*
 * libFuzzer target: sequences of SAMPLE, COMMAND, PARAM_SET/GET, HELLO and HEARTBEAT against the
 * stub, built with ASan/UBSan and float-cast-overflow, float-divide-by-zero (Makefile, fuzz).
 *
 * The input is a program of operations (format below), so that the fuzzer explores what the
 * drive does with hostile values rather than the framing (protocol/c fuzzes that). Each
 * operation goes two ways, both checked:
 *  - straight into the control core (ctl_set_command, ctl_param_set, ctl_step with telemetry
 *    every period), with the invariants of fail-safe protection asserted after each step:
 *      while RUNNING, every telemetry value is finite;
 *      the gates never switch both devices of a leg (shoot-through) and stay in 0x3F;
 *      DUTY is answered only while RUNNING; in FAULT the gates are all off;
 *      the fault code is one of SPEC.md 9.6, and NON_FINITE's value one of its quantities;
 *      every parameter read back is finite (after each PARAM_SET and at the end);
 *  - as frames through the application layer (hil_stub_exchange), whose answers are decoded:
 *      every GATES is free of shoot-through, every FAULT code is known.
 * A broken invariant traps (__builtin_trap), which libFuzzer reports with the input.
 *
 * Program format, one operation after another until the bytes run out:
 *   op % 6 == 0  SAMPLE: adc_i1 u16, adc_i2 u16, adc_vdc u16 (12 bits kept, as on the wire),
 *                encoder step i8, status u8 (4 bits kept)
 *   op % 6 == 1  n SAMPLEs repeating the last one (the encoder keeps stepping): n u8
 *   op % 6 == 2  COMMAND: flags u8, speed source u8, speed_ref, torque_ref, flux_ref f32 (raw bits)
 *   op % 6 == 3  PARAM_SET: id u8 (+ 10: the parameter ids), mode u8, x u32:
 *                mode % 3 == 0: value = the bits of x; 1: value = x % 70000; 2: value = the
 *                parameter's present value times (x % 64) / 16
 *   op % 6 == 4  PARAM_GET: id u8 (+ 10)
 *   op % 6 == 5  HELLO (x even) or HEARTBEAT (x odd): x u8
 * Little-endian; a SAMPLE's period is one more than the last one's.
 */
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "control.h"
#include "hil_proto.h"
#include "hil_stub.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define REQUIRE(cond)                                                                                  \
    do {                                                                                               \
        if (!(cond)) {                                                                                 \
            __builtin_trap();                                                                          \
        }                                                                                              \
    } while (0)

typedef struct {
    const uint8_t *data;
    size_t size;
    size_t at;
} reader;

static int take(reader *r, void *out, size_t n)
{
    if (r->size - r->at < n) {
        return 0;
    }
    memcpy(out, r->data + r->at, n); /* little-endian host: the fields as they are */
    r->at += n;
    return 1;
}

/* Gates with both devices of a leg on: bit pairs (0x01, 0x02), (0x04, 0x08), (0x10, 0x20). */
static int shoot_through(uint8_t gates) { return (gates & (gates >> 1) & 0x15u) != 0u; }

static void check_telemetry_finite(const hil_telemetry *tm)
{
    const float v[] = {tm->speed_feedback_rad_s, tm->speed_encoder_rad_s, tm->speed_raw_rad_s,
                       tm->speed_lpf_rad_s,      tm->speed_ekf_rad_s,     tm->flux_angle_rad,
                       tm->ekf_angle_rad,        tm->flux_mag_wb,         tm->torque_est_nm,
                       tm->torque_ref_nm,        tm->rotor_pos_conv_rad,  tm->rotor_pos_ekf_rad};
    for (size_t k = 0; k < sizeof v / sizeof v[0]; ++k) {
        REQUIRE(isfinite(v[k]));
    }
}

static void check_core(const ctl *c, uint8_t gates, const hil_telemetry *tm)
{
    const ctl_state *st = &c->st;
    REQUIRE((gates & ~0x3Fu) == 0u);
    REQUIRE(!shoot_through(gates));
    REQUIRE(st->fault_code <= HIL_FAULT_NON_FINITE);
    if (st->fault_code == HIL_FAULT_NON_FINITE) {
        REQUIRE(st->fault_value >= 1.0f && st->fault_value <= (float)HIL_NONFINITE_COMMAND);
    }
    if (st->state == HIL_STATE_RUNNING) {
        check_telemetry_finite(tm);
    } else {
        REQUIRE(!st->answer_duty);
        REQUIRE(st->state != HIL_STATE_FAULT || gates == 0u);
    }
    if (st->answer_duty) {
        REQUIRE(gates == 0u); /* the duties are the answer */
    }
}

/* After a PARAM_SET and at the end (the resistance identification writes R too). */
static void check_params(const ctl *c)
{
    for (uint16_t id = 0; id < 70u; ++id) {
        float value;
        if (ctl_param_get(c, id, &value) == HIL_PARAM_OK) {
            REQUIRE(isfinite(value));
        }
    }
}

/* The stub's answers: decoded and checked. */
static void drain_app(void *stub, hil_decoder *dec)
{
    uint8_t tx[512];
    size_t n;
    while ((n = hil_stub_exchange(stub, NULL, 0, tx, sizeof tx)) > 0u) {
        for (size_t i = 0; i < n; ++i) {
            hil_msg m;
            if (!hil_decoder_feed(dec, tx[i], &m)) {
                continue;
            }
            if (m.type == HIL_MSG_GATES) {
                REQUIRE((m.u.gates.gates & ~0x3Fu) == 0u && !shoot_through(m.u.gates.gates));
            } else if (m.type == HIL_MSG_FAULT) {
                REQUIRE(m.u.fault.code >= HIL_FAULT_OVERCURRENT && m.u.fault.code <= HIL_FAULT_NON_FINITE);
            } else if (m.type == HIL_MSG_STATUS) {
                REQUIRE(m.u.status.state <= HIL_STATE_FAULT);
            }
        }
    }
}

static void send_app(void *stub, hil_decoder *dec, hil_msg *m, uint8_t *seq)
{
    uint8_t frame[HIL_MAX_ENCODED_FRAME];
    m->seq = (*seq)++;
    int n = hil_frame_encode(m, frame, sizeof frame);
    REQUIRE(n > 0);
    uint8_t tx[512];
    size_t got = hil_stub_exchange(stub, frame, (size_t)n, tx, sizeof tx);
    (void)got; /* read again below, with everything still queued */
    drain_app(stub, dec);
}

static uint64_t stub_storage[(64u * 1024u) / sizeof(uint64_t)];

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static ctl core; /* static: the fuzzer calls this many times; both are re-initialised */
    ctl_init(&core);
    REQUIRE(hil_stub_instance_size() <= sizeof stub_storage);
    void *stub = stub_storage;
    hil_stub_init(stub);
    hil_decoder dec;
    hil_decoder_init(&dec);
    uint8_t seq = 0;
    hil_msg hello;
    memset(&hello, 0, sizeof hello);
    hello.type = HIL_MSG_HELLO;
    hello.u.hello.proto_version = HIL_PROTO_VERSION;
    hello.u.hello.role = HIL_ROLE_BENCH;
    send_app(stub, &dec, &hello, &seq);

    reader r = {data, size, 0u};
    hil_sample sample;
    memset(&sample, 0, sizeof sample);
    sample.adc_i1 = 2048u;
    sample.adc_i2 = 2048u;
    sample.adc_vdc = 2867u;
    int8_t encoder_step = 0;
    uint32_t period = 0u;
    uint8_t op;
    while (take(&r, &op, 1u)) {
        hil_msg m;
        memset(&m, 0, sizeof m);
        unsigned repeat = 0u;
        switch (op % 6u) {
        case 0u:
            if (!take(&r, &sample.adc_i1, 2u) || !take(&r, &sample.adc_i2, 2u) || !take(&r, &sample.adc_vdc, 2u) ||
                !take(&r, &encoder_step, 1u) || !take(&r, &sample.status, 1u)) {
                goto done; /* the program ran out of bytes */
            }
            /* the wire carries 12-bit ADC codes and 4 status bits (SPEC.md 6.2) */
            sample.adc_i1 &= 0xFFFu;
            sample.adc_i2 &= 0xFFFu;
            sample.adc_vdc &= 0xFFFu;
            sample.status &= 0xFu;
            repeat = 1u;
            break;
        case 1u: {
            uint8_t n;
            if (!take(&r, &n, 1u)) {
                goto done; /* the program ran out of bytes */
            }
            repeat = n;
            break;
        }
        case 2u: {
            hil_command cmd;
            if (!take(&r, &cmd.flags, 1u) || !take(&r, &cmd.speed_source, 1u) || !take(&r, &cmd.speed_ref_rad_s, 4u) ||
                !take(&r, &cmd.torque_ref_nm, 4u) || !take(&r, &cmd.flux_ref_wb, 4u)) {
                goto done; /* the program ran out of bytes */
            }
            int refused = ctl_set_command(&core, &cmd);
            if (refused != 0) {
                /* as the application layer does */
                ctl_trip(&core, refused == -2 ? HIL_FAULT_NON_FINITE : HIL_FAULT_PROTOCOL,
                         refused == -2 ? (float)HIL_NONFINITE_COMMAND : 1.0f, period);
            }
            m.type = HIL_MSG_COMMAND;
            m.u.command = cmd;
            send_app(stub, &dec, &m, &seq);
            break;
        }
        case 3u: {
            uint8_t id, mode;
            uint32_t x;
            if (!take(&r, &id, 1u) || !take(&r, &mode, 1u) || !take(&r, &x, 4u)) {
                goto done; /* the program ran out of bytes */
            }
            uint16_t pid = (uint16_t)(id + 10u);
            float value;
            if (mode % 3u == 0u) {
                memcpy(&value, &x, sizeof value);
            } else if (mode % 3u == 1u) {
                value = (float)(x % 70000u);
            } else {
                float now = 0.0f;
                (void)ctl_param_get(&core, pid, &now);
                value = now * (float)(x % 64u) / 16.0f;
            }
            float now;
            uint8_t status = ctl_param_set(&core, pid, value, &now);
            REQUIRE(status != HIL_PARAM_OK || isfinite(now));
            REQUIRE(isfinite(value) || status != HIL_PARAM_OK);
            check_params(&core);
            m.type = HIL_MSG_PARAM_SET;
            m.u.param_set.id = pid;
            m.u.param_set.value = value;
            send_app(stub, &dec, &m, &seq);
            break;
        }
        case 4u: {
            uint8_t id;
            if (!take(&r, &id, 1u)) {
                goto done; /* the program ran out of bytes */
            }
            m.type = HIL_MSG_PARAM_GET;
            m.u.param_get.id = (uint16_t)(id + 10u);
            send_app(stub, &dec, &m, &seq);
            break;
        }
        default: {
            uint8_t x;
            if (!take(&r, &x, 1u)) {
                goto done; /* the program ran out of bytes */
            }
            if (x & 1u) {
                m.type = HIL_MSG_HEARTBEAT;
                m.u.heartbeat.counter = x;
                send_app(stub, &dec, &m, &seq);
            } else {
                send_app(stub, &dec, &hello, &seq);
                period = 0u; /* a new session starts its periods again */
            }
            break;
        }
        }
        for (unsigned k = 0; k < repeat; ++k) {
            sample.period = period++;
            sample.encoder = (uint16_t)(sample.encoder + (uint16_t)(int16_t)encoder_step);
            hil_telemetry tm;
            uint8_t gates = ctl_step(&core, &sample, &tm);
            check_core(&core, gates, &tm);
            m.type = HIL_MSG_SAMPLE;
            m.u.sample = sample;
            send_app(stub, &dec, &m, &seq);
        }
    }
done:
    check_params(&core);
    return 0;
}
