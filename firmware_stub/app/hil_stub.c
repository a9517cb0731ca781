#include "hil_stub.h"

#include <string.h>

#include "control.h"
#include "fastmath.h"

#define STR_(x) #x
#define STR(x) STR_(x)

#if defined(__x86_64__)
#define HIL_STUB_TARGET "x86_64"
#elif defined(__aarch64__)
#define HIL_STUB_TARGET "aarch64"
#elif defined(__ARM_ARCH_7EM__) && defined(__ARM_FP)
#define HIL_STUB_TARGET "cm4f"
#elif defined(__arm__)
#define HIL_STUB_TARGET "arm"
#else
#define HIL_STUB_TARGET "unknown"
#endif

#if defined(__clang__)
#define HIL_STUB_COMPILER "clang" STR(__clang_major__)
#elif defined(__GNUC__)
#define HIL_STUB_COMPILER "gcc" STR(__GNUC__)
#else
#define HIL_STUB_COMPILER "cc"
#endif

#ifndef HIL_STUB_OPT
#define HIL_STUB_OPT ""
#endif

static const char stub_name[] = "hil-stub " HIL_STUB_VERSION " " HIL_STUB_TARGET " " HIL_STUB_COMPILER " " HIL_STUB_OPT;
/* compile-time check that the name fits HELLO */
typedef char stub_name_fits_hello[(sizeof stub_name - 1u <= HIL_NAME_MAX) ? 1 : -1];

#define OUT_BYTES 1024u
#define OUT_FRAMES 64u

enum { TRANSPORT_BYTES = 0, TRANSPORT_CAN = 1 };

typedef struct {
    ctl core;
    hil_decoder dec;
    hil_can_rx can_rx;
    hil_stub_counters counters;
    uint32_t (*read_cycles)(void);
    uint32_t next_period;   /* the period the next SAMPLE is expected to carry */
    hil_msg last_answer;    /* GATES or DUTY of the last SAMPLE, repeated for a resent one */
    uint8_t have_answer;    /* last_answer is valid (a SAMPLE was answered since HELLO) */
    uint32_t heartbeats;    /* HEARTBEATs sent */
    uint32_t version_errors_seen; /* decoder version errors already answered with HELLO */
    uint16_t can_base;
    uint8_t transport;
    uint8_t seq;
    uint8_t shutdown;
    uint8_t reported_state; /* last state sent in STATUS (ctl_reported_state) */
    uint8_t peer_version_bad; /* the bench's HELLO named another version: answer only HELLO */
    size_t out_len;
    uint8_t out[OUT_BYTES];
    size_t can_out_len;
    hil_can_frame can_out[OUT_FRAMES];
} hil_stub;

size_t hil_stub_instance_size(void) { return sizeof(hil_stub); }

const char *hil_stub_name(void) { return stub_name; }

void hil_stub_init(void *inst)
{
    hil_stub *s = (hil_stub *)inst;
    memset(s, 0, sizeof *s);
    ctl_init(&s->core);
    hil_decoder_init(&s->dec);
    s->can_base = HIL_CAN_DEFAULT_BASE_ID;
    hil_can_rx_init(&s->can_rx, s->can_base);
    s->reported_state = HIL_STATE_IDLE;
}

void hil_stub_set_can_base(void *inst, uint16_t base_id)
{
    hil_stub *s = (hil_stub *)inst;
    s->can_base = base_id;
    hil_can_rx_init(&s->can_rx, base_id);
}

void hil_stub_set_cycle_counter(void *inst, uint32_t (*read_cycles)(void))
{
    ((hil_stub *)inst)->read_cycles = read_cycles;
}

int hil_stub_shutdown_requested(const void *inst) { return ((const hil_stub *)inst)->shutdown; }

size_t hil_stub_pending(const void *inst)
{
    const hil_stub *s = (const hil_stub *)inst;
    return s->transport == TRANSPORT_CAN ? s->can_out_len : s->out_len;
}

void hil_stub_get_counters(const void *inst, hil_stub_counters *out)
{
    const hil_stub *s = (const hil_stub *)inst;
    *out = s->counters;
    if (s->transport == TRANSPORT_CAN) {
        out->decode_errors = s->can_rx.sequence_errors + s->can_rx.unknown_types + s->can_rx.length_errors;
    } else {
        out->decode_errors = s->dec.crc_errors + s->dec.framing_errors + s->dec.length_errors +
                             s->dec.version_errors + s->dec.unknown_types;
    }
}

/* Queues one message in the encoding of the current transport. */
static void emit(hil_stub *s, hil_msg *m)
{
    m->seq = s->seq;
    if (s->transport == TRANSPORT_CAN) {
        int n = hil_can_pack(m, HIL_ROLE_CONTROLLER, s->can_base, s->can_out + s->can_out_len,
                             OUT_FRAMES - s->can_out_len);
        if (n < 0) {
            s->counters.tx_overflows++;
            return;
        }
        s->can_out_len += (size_t)n;
    } else {
        int n = hil_frame_encode(m, s->out + s->out_len, OUT_BYTES - s->out_len);
        if (n < 0) {
            s->counters.tx_overflows++;
            return;
        }
        s->out_len += (size_t)n;
    }
    s->seq++;
}

/* STATUS for a state that changed at `period` */
static void emit_status(hil_stub *s, uint32_t period)
{
    hil_msg m;
    m.type = HIL_MSG_STATUS;
    m.u.status.period = period;
    m.u.status.state = ctl_reported_state(&s->core);
    m.u.status.fault_code = s->core.st.fault_code;
    s->reported_state = m.u.status.state;
    emit(s, &m);
}

/* A trip the bench has not heard of: FAULT once, then STATUS (SPEC.md 2.5). */
static void report_fault(hil_stub *s)
{
    if (s->core.st.state != HIL_STATE_FAULT || s->reported_state == HIL_STATE_FAULT) {
        return;
    }
    hil_msg m;
    m.type = HIL_MSG_FAULT;
    m.u.fault.period = s->core.st.fault_period;
    m.u.fault.code = s->core.st.fault_code;
    m.u.fault.value = s->core.st.fault_value;
    emit(s, &m);
    emit_status(s, s->core.st.fault_period);
}

static void on_sample(hil_stub *s, const hil_sample *sample)
{
    hil_msg m;
    if (s->have_answer && sample->period + 1u == s->next_period) {
        /* SPEC.md 2.8.1: a resent SAMPLE (same period) gets the same answer again, without a
         * second control step: the bench lost the first answer, the simulation must not change */
        emit(s, &s->last_answer);
        return;
    }
    s->next_period = sample->period + 1u;
    uint32_t div = s->core.params.telemetry_divider;
    int want_telemetry = div != 0u && sample->period % div == 0u;
    uint32_t c0 = s->read_cycles ? s->read_cycles() : 0u;
    uint8_t gates = ctl_step(&s->core, sample, want_telemetry ? &m.u.telemetry : NULL);
    if (s->read_cycles) {
        s->core.st.step_cycles = s->read_cycles() - c0;
    }
    hil_msg g;
    if (s->core.st.answer_duty) {
        /* FOC while running: centre-aligned PWM duties (SPEC.md 6.4) */
        g.type = HIL_MSG_DUTY;
        g.u.duty.period = sample->period;
        g.u.duty.duty[0] = s->core.st.duty[0];
        g.u.duty.duty[1] = s->core.st.duty[1];
        g.u.duty.duty[2] = s->core.st.duty[2];
    } else {
        g.type = HIL_MSG_GATES;
        g.u.gates.period = sample->period;
        g.u.gates.gates = gates;
    }
    emit(s, &g);
    s->last_answer = g;
    s->have_answer = 1u;
    if (want_telemetry) {
        m.type = HIL_MSG_TELEMETRY;
        emit(s, &m);
    }
    report_fault(s);
    if (ctl_reported_state(&s->core) != s->reported_state) {
        /* the start-up ended in this step: this SAMPLE's answer is the first that controls,
         * so the board is ready from this period on (SPEC.md 6.8) */
        emit_status(s, sample->period);
    }
}

static void on_command(hil_stub *s, const hil_command *cmd)
{
    int refused = ctl_set_command(&s->core, cmd);
    if (refused == -2) {
        /* a NaN or infinite reference: stop switching and say which (SPEC.md 9.6) */
        ctl_trip(&s->core, HIL_FAULT_NON_FINITE, (float)HIL_NONFINITE_COMMAND, s->next_period);
        report_fault(s);
        return;
    }
    if (refused != 0) {
        /* an unknown speed source is a bench bug: stop switching and say why */
        ctl_trip(&s->core, HIL_FAULT_PROTOCOL, (float)cmd->speed_source, s->next_period);
        report_fault(s);
        return;
    }
    if (ctl_reported_state(&s->core) != s->reported_state) {
        emit_status(s, s->next_period); /* applies from the next SAMPLE on */
    }
}

static void on_param(hil_stub *s, const hil_msg *in)
{
    hil_msg m;
    m.type = HIL_MSG_PARAM_VALUE;
    if (in->type == HIL_MSG_PARAM_SET) {
        m.u.param_value.id = in->u.param_set.id;
        m.u.param_value.status = ctl_param_set(&s->core, in->u.param_set.id, in->u.param_set.value,
                                               &m.u.param_value.value);
    } else {
        m.u.param_value.id = in->u.param_get.id;
        m.u.param_value.status = ctl_param_get(&s->core, in->u.param_get.id, &m.u.param_value.value);
    }
    emit(s, &m);
}

static void emit_hello(hil_stub *s)
{
    hil_msg m;
    const size_t name_len = sizeof stub_name - 1u < HIL_NAME_MAX ? sizeof stub_name - 1u : HIL_NAME_MAX;
    m.type = HIL_MSG_HELLO;
    m.u.hello.proto_version = HIL_PROTO_VERSION;
    m.u.hello.role = HIL_ROLE_CONTROLLER;
    m.u.hello.capabilities = HIL_CAP_GATES | HIL_CAP_DUTY | HIL_CAP_TELEMETRY | HIL_CAP_CAN;
    m.u.hello.control_period_ns = fm_trunc_sat_u32(s->core.params.control_period_s * 1e9f + 0.5f);
    m.u.hello.name_len = (uint8_t)name_len;
    memcpy(m.u.hello.name, stub_name, name_len);
    emit(s, &m);
}

static void dispatch(hil_stub *s, const hil_msg *in)
{
    hil_msg m;
    if (in->type == HIL_MSG_HELLO) {
        /* SPEC.md 2.1: answer every HELLO; after one naming another version,
         * ignore everything but HELLO */
        s->peer_version_bad = in->u.hello.proto_version != HIL_PROTO_VERSION;
        s->have_answer = 0u; /* a new session: period 0 is a new SAMPLE, not a resend */
        if (!s->peer_version_bad && in->u.hello.control_period_ns != 0u) {
            /* The period is a parameter here, not built in: take the bench's if it is in
             * CONTROL_PERIOD_S's range (the answer then announces it); else keep ours, and
             * the bench refuses the mismatch (SPEC.md 2.1). */
            float now;
            (void)ctl_param_set(&s->core, HIL_PARAM_CONTROL_PERIOD_S,
                                (float)in->u.hello.control_period_ns * 1e-9f, &now);
        }
        emit_hello(s);
        s->counters.frames_in++;
        return;
    }
    if (s->peer_version_bad) {
        s->counters.ignored++;
        return;
    }
    switch (in->type) {
    case HIL_MSG_SAMPLE:
        on_sample(s, &in->u.sample);
        break;
    case HIL_MSG_COMMAND:
        on_command(s, &in->u.command);
        break;
    case HIL_MSG_PARAM_SET:
    case HIL_MSG_PARAM_GET:
        on_param(s, in);
        break;
    case HIL_MSG_HEARTBEAT:
        /* the bench only sends one after 100 ms of silence, so answering keeps
         * to SPEC.md 2.6; the counter is our own */
        m.type = HIL_MSG_HEARTBEAT;
        m.u.heartbeat.counter = s->heartbeats++;
        emit(s, &m);
        break;
    case HIL_MSG_SHUTDOWN: {
        hil_command off = {0u, s->core.cmd.speed_source, 0.0f, 0.0f, 0.0f};
        (void)ctl_set_command(&s->core, &off);
        s->shutdown = 1u;
        emit_status(s, s->next_period);
        break;
    }
    default:
        s->counters.ignored++; /* controller-to-bench types: nothing to do */
        return;
    }
    s->counters.frames_in++;
}

size_t hil_stub_exchange(void *inst, const uint8_t *rx, size_t rx_len, uint8_t *tx, size_t tx_cap)
{
    hil_stub *s = (hil_stub *)inst;
    s->transport = TRANSPORT_BYTES;
    hil_msg in;
    size_t i = 0;
    while (i < rx_len) {
        /* up to and with the next delimiter: a frame at a time, so a HELLO answering a frame of
         * another version goes out where that frame ended, as fed byte by byte */
        const uint8_t *delimiter = memchr(rx + i, 0, rx_len - i);
        size_t end = delimiter != NULL ? (size_t)(delimiter - rx) + 1u : rx_len;
        int got;
        i += hil_decoder_feed_buf(&s->dec, rx + i, end - i, &in, &got);
        if (got) {
            dispatch(s, &in);
        }
        if (s->dec.version_errors != s->version_errors_seen) {
            /* a frame of another version: say which one we speak (SPEC.md 2.1) */
            s->version_errors_seen = s->dec.version_errors;
            emit_hello(s);
        }
    }
    size_t n = s->out_len < tx_cap ? s->out_len : tx_cap;
    if (n > 0u) {
        memcpy(tx, s->out, n);
        memmove(s->out, s->out + n, s->out_len - n);
        s->out_len -= n;
    }
    return n;
}

size_t hil_stub_can_exchange(void *inst, const hil_can_frame *rx, size_t rx_count, hil_can_frame *tx,
                             size_t tx_cap)
{
    hil_stub *s = (hil_stub *)inst;
    s->transport = TRANSPORT_CAN;
    hil_msg in;
    for (size_t i = 0; i < rx_count; ++i) {
        uint8_t role = HIL_ROLE_CONTROLLER;
        if (hil_can_rx_feed(&s->can_rx, &rx[i], &in, &role)) {
            if (role == HIL_ROLE_BENCH) {
                dispatch(s, &in);
            } else {
                s->counters.ignored++; /* our own frames echoed back */
            }
        }
    }
    size_t n = s->can_out_len < tx_cap ? s->can_out_len : tx_cap;
    if (n > 0u) {
        memcpy(tx, s->can_out, n * sizeof tx[0]);
        memmove(s->can_out, s->can_out + n, (s->can_out_len - n) * sizeof tx[0]);
        s->can_out_len -= n;
    }
    return n;
}
