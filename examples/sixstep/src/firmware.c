/*
 * The example board's firmware: the six-step drive behind the wire protocol
 * (protocol/SPEC.md), exported as the public firmware ABI
 * (protocol/c/hil_fw_abi.h). Written only against those two headers and the
 * reference codec (hil_proto.h); the same file is the shared library, the
 * executable's core (host/main.c) and the Cortex-M4F image's core
 * (board/main.c). No I/O, no allocation, no clock: bytes in, bytes out.
 *
 * Speaks serial only: it does not define hil_fw_can_exchange, and the bench
 * reads that absence as "no CAN".
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "hil_fw_abi.h"
#include "hil_proto.h"
#include "sixstep.h"

#define SIXSTEP_FW_VERSION "1.0"

#if defined(__x86_64__)
#define SIXSTEP_TARGET "x86_64"
#elif defined(__aarch64__)
#define SIXSTEP_TARGET "aarch64"
#elif defined(__ARM_ARCH_7EM__) && defined(__ARM_FP)
#define SIXSTEP_TARGET "cm4f"
#else
#define SIXSTEP_TARGET "other"
#endif

static const char fw_name[] = "sixstep-example " SIXSTEP_FW_VERSION " " SIXSTEP_TARGET;
typedef char fw_name_fits_hello[(sizeof fw_name - 1u <= HIL_NAME_MAX) ? 1 : -1];

/* Largest burst one SAMPLE causes: DUTY_LEGS 19 + TELEMETRY 64 + FAULT 18 + STATUS 15
 * bytes; the rest is room for PARAM_VALUEs the bench sends in a row. */
#define OUT_BYTES 1024u

typedef struct {
    /* parameters (SPEC.md section 8), SI units */
    float control_period_s;
    float current_a_per_count;
    float current_offset_counts;
    float vdc_v_per_count;
    float vdc_offset_counts;
    uint32_t counts_per_rev;
    uint32_t current_phases; /* 0: a,b  1: a,c  2: b,c */
    uint32_t pole_pairs;
    float magnet_flux_wb;
    uint32_t telemetry_divider;
    float overcurrent_a;
    float encoder_loss_timeout_s;
    uint8_t kp_overridden; /* PARAM_SET of the gains replaces the bandwidth design */
    uint8_t ki_overridden;
    /* derived from the parameters (derive()) */
    sixstep_pi_gains pi_gains;
    sixstep_tracker_gains tracker_gains;
    float torque_constant_nm_per_a;
    uint32_t encoder_timeout_periods;
    /* command */
    uint8_t enable;
    uint8_t torque_mode;
    float speed_ref_rad_s;
    float torque_cmd_nm;
    /* control state */
    sixstep_tracker tracker;
    sixstep_pi pi;
    sixstep_encoder_watch watch;
    uint8_t state; /* hil_state */
    uint8_t reported_state;
    uint16_t fault_code;
    uint32_t fault_period;
    float fault_value;
    /* protocol */
    hil_decoder dec;
    uint32_t next_period;
    uint32_t heartbeats;
    uint32_t version_errors_seen;
    uint8_t seq;
    uint8_t shutdown;
    uint8_t peer_version_bad;
    size_t out_len;
    uint8_t out[OUT_BYTES];
} sixstep_fw;

/* ---- parameters -------------------------------------------------------- */

static void derive(sixstep_fw *f)
{
    sixstep_pi_gains design =
        sixstep_speed_pi_design(SIXSTEP_DESIGN_INERTIA_KGM2, SIXSTEP_SPEED_BANDWIDTH_HZ, f->pi_gains.torque_limit_nm);
    if (!f->kp_overridden) {
        f->pi_gains.kp_nm_per_rad_s = design.kp_nm_per_rad_s;
    }
    if (!f->ki_overridden) {
        f->pi_gains.ki_nm_per_rad = design.ki_nm_per_rad;
    }
    f->tracker_gains = sixstep_tracker_design(SIXSTEP_TRACKER_BANDWIDTH_HZ);
    f->torque_constant_nm_per_a = sixstep_torque_constant(f->pole_pairs, f->magnet_flux_wb);
    f->encoder_timeout_periods = (uint32_t)(f->encoder_loss_timeout_s / f->control_period_s + 0.5f);
}

static void set_defaults(sixstep_fw *f)
{
    f->control_period_s = SIXSTEP_DEFAULT_PERIOD_S;
    f->current_a_per_count = 25.0f / 2048.0f; /* the bench profile's sensors */
    f->current_offset_counts = 2048.0f;
    f->vdc_v_per_count = 100.0f / 4096.0f;
    f->vdc_offset_counts = 0.0f;
    f->counts_per_rev = SIXSTEP_DEFAULT_COUNTS_PER_REV;
    f->current_phases = 0u;
    f->pole_pairs = SIXSTEP_DEFAULT_POLE_PAIRS;
    f->magnet_flux_wb = SIXSTEP_DEFAULT_MAGNET_FLUX_WB;
    f->telemetry_divider = 1u;
    f->overcurrent_a = SIXSTEP_DEFAULT_OVERCURRENT_A;
    f->encoder_loss_timeout_s = SIXSTEP_DEFAULT_ENCODER_LOSS_TIMEOUT_S;
    f->pi_gains.torque_limit_nm = SIXSTEP_DEFAULT_TORQUE_LIMIT_NM;
    derive(f);
}

static int is_whole(float v, float lo, float hi) { return v >= lo && v <= hi && v == floorf(v); }

/* Applies a PARAM_SET; returns the PARAM_VALUE status. A refused value leaves
 * the old one in force (SPEC.md 9.5). NaN fails every range test. */
static uint8_t param_set(sixstep_fw *f, uint16_t id, float v)
{
    switch (id) {
    case HIL_PARAM_CONTROL_PERIOD_S:
        if (!(v >= 1e-6f && v <= 0.01f)) return HIL_PARAM_OUT_OF_RANGE;
        f->control_period_s = v;
        break;
    case HIL_PARAM_CURRENT_A_PER_COUNT:
        if (!(v > 0.0f && v < 1.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->current_a_per_count = v;
        break;
    case HIL_PARAM_CURRENT_OFFSET_COUNTS:
        if (!(v >= 0.0f && v <= 4095.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->current_offset_counts = v;
        break;
    case HIL_PARAM_VDC_V_PER_COUNT:
        if (!(v > 0.0f && v < 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->vdc_v_per_count = v;
        break;
    case HIL_PARAM_VDC_OFFSET_COUNTS:
        if (!(v >= 0.0f && v <= 4095.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->vdc_offset_counts = v;
        break;
    case HIL_PARAM_ENCODER_COUNTS_PER_REV:
        /* a 16-bit counter must move less than half its range per period */
        if (!is_whole(v, 4.0f, 65536.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->counts_per_rev = (uint32_t)v;
        sixstep_tracker_reset(&f->tracker);
        break;
    case HIL_PARAM_CURRENT_PHASES:
        if (!is_whole(v, 0.0f, 2.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->current_phases = (uint32_t)v;
        break;
    case HIL_PARAM_POLE_PAIRS:
        if (!is_whole(v, 1.0f, 64.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->pole_pairs = (uint32_t)v;
        break;
    case HIL_PARAM_MAGNET_FLUX_WB:
        if (!(v > 0.0f && v < 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->magnet_flux_wb = v;
        break;
    case HIL_PARAM_TORQUE_LIMIT_NM:
        if (!(v > 0.0f && v < 1000.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->pi_gains.torque_limit_nm = v;
        break;
    case HIL_PARAM_SPEED_KP_NM_PER_RAD_S:
        if (!(v >= 0.0f && v < 1000.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->pi_gains.kp_nm_per_rad_s = v;
        f->kp_overridden = 1u;
        break;
    case HIL_PARAM_SPEED_KI_NM_PER_RAD:
        if (!(v >= 0.0f && v < 1e6f)) return HIL_PARAM_OUT_OF_RANGE;
        f->pi_gains.ki_nm_per_rad = v;
        f->ki_overridden = 1u;
        break;
    case HIL_PARAM_TELEMETRY_DIVIDER:
        if (!is_whole(v, 0.0f, 65535.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->telemetry_divider = (uint32_t)v;
        break;
    case HIL_PARAM_OVERCURRENT_A:
        if (!(v > 0.0f && v < 1000.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->overcurrent_a = v;
        break;
    case HIL_PARAM_ENCODER_LOSS_TIMEOUT_S:
        if (!(v >= 0.0f && v <= 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->encoder_loss_timeout_s = v;
        break;
    default:
        return HIL_PARAM_UNKNOWN;
    }
    derive(f);
    return HIL_PARAM_OK;
}

static uint8_t param_get(const sixstep_fw *f, uint16_t id, float *v)
{
    switch (id) {
    case HIL_PARAM_CONTROL_PERIOD_S: *v = f->control_period_s; break;
    case HIL_PARAM_CURRENT_A_PER_COUNT: *v = f->current_a_per_count; break;
    case HIL_PARAM_CURRENT_OFFSET_COUNTS: *v = f->current_offset_counts; break;
    case HIL_PARAM_VDC_V_PER_COUNT: *v = f->vdc_v_per_count; break;
    case HIL_PARAM_VDC_OFFSET_COUNTS: *v = f->vdc_offset_counts; break;
    case HIL_PARAM_ENCODER_COUNTS_PER_REV: *v = (float)f->counts_per_rev; break;
    case HIL_PARAM_CURRENT_PHASES: *v = (float)f->current_phases; break;
    case HIL_PARAM_POLE_PAIRS: *v = (float)f->pole_pairs; break;
    case HIL_PARAM_MAGNET_FLUX_WB: *v = f->magnet_flux_wb; break;
    case HIL_PARAM_TORQUE_LIMIT_NM: *v = f->pi_gains.torque_limit_nm; break;
    case HIL_PARAM_SPEED_KP_NM_PER_RAD_S: *v = f->pi_gains.kp_nm_per_rad_s; break;
    case HIL_PARAM_SPEED_KI_NM_PER_RAD: *v = f->pi_gains.ki_nm_per_rad; break;
    case HIL_PARAM_TELEMETRY_DIVIDER: *v = (float)f->telemetry_divider; break;
    case HIL_PARAM_OVERCURRENT_A: *v = f->overcurrent_a; break;
    case HIL_PARAM_ENCODER_LOSS_TIMEOUT_S: *v = f->encoder_loss_timeout_s; break;
    default:
        *v = 0.0f;
        return HIL_PARAM_UNKNOWN;
    }
    return HIL_PARAM_OK;
}

/* ---- output ------------------------------------------------------------ */

static void emit(sixstep_fw *f, hil_msg *m)
{
    m->seq = f->seq;
    int n = hil_frame_encode(m, f->out + f->out_len, OUT_BYTES - f->out_len);
    if (n < 0) {
        return; /* queue full: the bench's watchdog sees the missing answer */
    }
    f->out_len += (size_t)n;
    f->seq++;
}

static void emit_status(sixstep_fw *f, uint32_t period)
{
    hil_msg m;
    m.type = HIL_MSG_STATUS;
    m.u.status.period = period;
    m.u.status.state = f->state;
    m.u.status.fault_code = f->fault_code;
    f->reported_state = f->state;
    emit(f, &m);
}

static void emit_hello(sixstep_fw *f)
{
    hil_msg m;
    m.type = HIL_MSG_HELLO;
    m.u.hello.proto_version = HIL_PROTO_VERSION;
    m.u.hello.role = HIL_ROLE_CONTROLLER;
    m.u.hello.capabilities = HIL_CAP_DUTY_LEGS | HIL_CAP_TELEMETRY;
    m.u.hello.control_period_ns = (uint32_t)(f->control_period_s * 1e9f + 0.5f);
    m.u.hello.name_len = (uint8_t)(sizeof fw_name - 1u);
    memcpy(m.u.hello.name, fw_name, sizeof fw_name - 1u);
    emit(f, &m);
}

/* Latches a fault: switching stops at once; FAULT then STATUS (SPEC.md 2.5). */
static void trip(sixstep_fw *f, uint16_t code, float value, uint32_t period)
{
    if (f->state == HIL_STATE_FAULT) {
        return;
    }
    f->state = HIL_STATE_FAULT;
    f->fault_code = code;
    f->fault_value = value;
    f->fault_period = period;
    hil_msg m;
    m.type = HIL_MSG_FAULT;
    m.u.fault.period = period;
    m.u.fault.code = code;
    m.u.fault.value = value;
    emit(f, &m);
    emit_status(f, period);
}

/* ---- one control period ------------------------------------------------ */

/* The chopper's switch word as the DUTY_LEGS answer (SPEC.md 6.12): a leg with its high switch
 * on is at duty 1 all period, with its low switch on at duty 0, with neither it is floated (the
 * open phase of block commutation). The same switching as that GATES word; a PWM chopper would
 * put its duty in place of the 1. */
static void duty_legs_of_gates(uint8_t gates, hil_duty_legs *answer)
{
    answer->leg_enable = 0u;
    for (unsigned x = 0u; x < 3u; x++) {
        unsigned high = (gates >> (2u * x)) & 1u;
        unsigned low = (gates >> (2u * x + 1u)) & 1u;
        answer->duty[x] = high != 0u ? 0xFFFFu : 0u;
        if ((high | low) != 0u) {
            answer->leg_enable = (uint8_t)(answer->leg_enable | (1u << x));
        }
    }
}

/* TELEMETRY gates for a DUTY_LEGS answer (SPEC.md 6.6): both switches of every enabled leg. */
static uint8_t telemetry_gates(const hil_duty_legs *answer)
{
    uint8_t mask = 0u;
    for (unsigned x = 0u; x < 3u; x++) {
        if ((answer->leg_enable >> x) & 1u) {
            mask = (uint8_t)(mask | (0x03u << (2u * x)));
        }
    }
    return mask;
}

static void phase_currents(const sixstep_fw *f, const hil_sample *s, float i_abc[3])
{
    float i1 = ((float)s->adc_i1 - f->current_offset_counts) * f->current_a_per_count;
    float i2 = ((float)s->adc_i2 - f->current_offset_counts) * f->current_a_per_count;
    /* three-wire star: the unmeasured phase is minus the sum of the others */
    static const uint8_t first[3] = {0u, 0u, 1u};
    static const uint8_t second[3] = {1u, 2u, 2u};
    static const uint8_t third[3] = {2u, 1u, 0u};
    uint32_t k = f->current_phases;
    i_abc[first[k]] = i1;
    i_abc[second[k]] = i2;
    i_abc[third[k]] = -(i1 + i2);
}

static void on_sample(sixstep_fw *f, const hil_sample *s)
{
    const float dt = f->control_period_s;
    f->next_period = s->period + 1u;
    float i_abc[3];
    phase_currents(f, s, i_abc);
    /* the position is tracked in every state, so enabling a coasting rotor commutes right */
    int32_t moved = sixstep_tracker_step(&f->tracker_gains, &f->tracker, s->encoder, f->counts_per_rev, dt);
    float speed = f->tracker.speed_rad_s;

    uint8_t gates = 0u;
    uint8_t sector = 0u;
    float torque_ref = 0.0f;
    float torque_est = 0.0f;
    if (f->state == HIL_STATE_RUNNING) {
        float i_peak = fmaxf(fabsf(i_abc[0]), fmaxf(fabsf(i_abc[1]), fabsf(i_abc[2])));
        if ((s->status & HIL_STATUS_OVERCURRENT) != 0u || i_peak > f->overcurrent_a) {
            trip(f, HIL_FAULT_OVERCURRENT, i_peak, s->period);
        }
    }
    if (f->state == HIL_STATE_RUNNING) {
        if (f->torque_mode) {
            float lim = f->pi_gains.torque_limit_nm;
            torque_ref = fminf(fmaxf(f->torque_cmd_nm, -lim), lim);
        } else {
            torque_ref = sixstep_pi_step(&f->pi_gains, &f->pi, f->speed_ref_rad_s - speed, dt);
        }
        if (sixstep_encoder_watch_step(&f->watch, moved, speed, torque_ref, f->pi_gains.torque_limit_nm,
                                       f->counts_per_rev, f->encoder_timeout_periods, dt)) {
            trip(f, HIL_FAULT_ENCODER_LOSS, (float)f->watch.silent_periods * dt, s->period);
        }
    }
    if (f->state == HIL_STATE_RUNNING) {
        float theta_e = sixstep_electrical_angle(f->tracker.position_counts, f->counts_per_rev, f->pole_pairs);
        sector = sixstep_sector(theta_e);
        sixstep_pair pair = sixstep_commutation(sector, torque_ref < 0.0f);
        float current_ref = torque_ref / f->torque_constant_nm_per_a;
        float pair_current = sixstep_pair_current(i_abc, pair);
        int motoring = torque_ref * speed >= 0.0f;
        gates = sixstep_gates(pair, sixstep_chopper(pair_current, current_ref, motoring));
        torque_est = (torque_ref < 0.0f ? -pair_current : pair_current) * f->torque_constant_nm_per_a;
    }

    hil_msg m;
    m.type = HIL_MSG_DUTY_LEGS;
    m.u.duty_legs.period = s->period;
    duty_legs_of_gates(gates, &m.u.duty_legs);
    uint8_t conducting = telemetry_gates(&m.u.duty_legs);
    emit(f, &m);
    if (f->telemetry_divider != 0u && s->period % f->telemetry_divider == 0u) {
        memset(&m, 0, sizeof m);
        m.type = HIL_MSG_TELEMETRY;
        hil_telemetry *t = &m.u.telemetry;
        t->period = s->period;
        t->sector = sector;
        t->speed_source = HIL_SPEED_ENCODER;
        t->state = f->state;
        t->gates = conducting;
        t->speed_feedback_rad_s = speed;
        t->speed_encoder_rad_s = speed;
        t->torque_est_nm = torque_est;
        t->torque_ref_nm = torque_ref;
        /* fields of estimators this drive does not have stay 0 */
        emit(f, &m);
    }
}

static void on_command(sixstep_fw *f, const hil_command *c)
{
    if (c->speed_source != HIL_SPEED_ENCODER) {
        /* this drive has no speed estimators: refuse to run blind, say why */
        trip(f, HIL_FAULT_PROTOCOL, (float)c->speed_source, f->next_period);
        return;
    }
    uint8_t enable = (c->flags & HIL_CMD_ENABLE) != 0u;
    f->torque_mode = (c->flags & HIL_CMD_TORQUE_MODE) != 0u;
    f->speed_ref_rad_s = c->speed_ref_rad_s;
    f->torque_cmd_nm = c->torque_ref_nm;
    if (!enable) {
        /* disabling clears a latched fault (SPEC.md 2.5) */
        f->state = HIL_STATE_IDLE;
        f->fault_code = HIL_FAULT_NONE;
    } else if (f->state == HIL_STATE_IDLE) {
        f->state = HIL_STATE_RUNNING;
        f->pi.integral_nm = 0.0f;
        memset(&f->watch, 0, sizeof f->watch);
        f->watch.speed_at_edge_rad_s = f->tracker.speed_rad_s;
    }
    f->enable = enable;
    if (f->state != f->reported_state) {
        emit_status(f, f->next_period); /* applies from the next SAMPLE on */
    }
}

static void dispatch(sixstep_fw *f, const hil_msg *in)
{
    hil_msg m;
    if (in->type == HIL_MSG_HELLO) {
        /* SPEC.md 2.1: answer every HELLO; after one of another version answer only HELLO */
        f->peer_version_bad = in->u.hello.proto_version != HIL_PROTO_VERSION;
        emit_hello(f);
        return;
    }
    if (f->peer_version_bad) {
        return;
    }
    switch (in->type) {
    case HIL_MSG_SAMPLE:
        on_sample(f, &in->u.sample);
        break;
    case HIL_MSG_COMMAND:
        on_command(f, &in->u.command);
        break;
    case HIL_MSG_PARAM_SET:
        m.type = HIL_MSG_PARAM_VALUE;
        m.u.param_value.id = in->u.param_set.id;
        m.u.param_value.status = param_set(f, in->u.param_set.id, in->u.param_set.value);
        if (param_get(f, in->u.param_set.id, &m.u.param_value.value) != HIL_PARAM_OK) {
            m.u.param_value.value = 0.0f;
        }
        emit(f, &m);
        break;
    case HIL_MSG_PARAM_GET:
        m.type = HIL_MSG_PARAM_VALUE;
        m.u.param_value.id = in->u.param_get.id;
        m.u.param_value.status = param_get(f, in->u.param_get.id, &m.u.param_value.value);
        emit(f, &m);
        break;
    case HIL_MSG_HEARTBEAT:
        m.type = HIL_MSG_HEARTBEAT;
        m.u.heartbeat.counter = f->heartbeats++;
        emit(f, &m);
        break;
    case HIL_MSG_SHUTDOWN:
        f->enable = 0u;
        f->state = HIL_STATE_IDLE;
        f->fault_code = HIL_FAULT_NONE;
        f->shutdown = 1u;
        emit_status(f, f->next_period);
        break;
    default:
        break; /* controller-to-bench types: nothing to do */
    }
}

/* ---- the firmware's arguments (hil_fw_configure) ------------------------ */

/* A decimal number without exponent ("5", "12.5"); 0 when `text` is not one. No strtof:
 * the Cortex-M4F image links no locale-aware C library parsing. */
static int parse_decimal(const char *text, float *value)
{
    float v = 0.0f, scale = 1.0f;
    int digits = 0, fraction = 0;
    for (; *text != '\0'; ++text) {
        if (*text == '.' && !fraction) {
            fraction = 1;
        } else if (*text >= '0' && *text <= '9' && digits < 9) {
            v = 10.0f * v + (float)(*text - '0');
            scale *= fraction ? 10.0f : 1.0f;
            ++digits;
        } else {
            return 0;
        }
    }
    *value = v / scale;
    return digits > 0;
}

static void copy_reason(char *why, size_t why_cap, const char *reason, const char *arg)
{
    size_t n = 0;
    for (const char *p = reason; *p != '\0' && n + 1u < why_cap; ++p) why[n++] = *p;
    for (const char *p = arg; *p != '\0' && n + 1u < why_cap; ++p) why[n++] = *p;
    why[n] = '\0';
}

/* The board's start-up settings, from `exec:PATH?args=...` (host/main.c hands its argv
 * here) or `lib:PATH.so?args=...` alike. Copying this template, add your options here:
 * host/main.c stays as it is. --overcurrent-a A: the phase-current trip level until the
 * bench sets parameter 41, 0 < A <= 50. */
int hil_fw_configure(void *fw, int argc, const char *const *argv, char *why, size_t why_cap)
{
    sixstep_fw *f = (sixstep_fw *)fw;
    for (int k = 0; k < argc; ++k) {
        float v;
        if (strcmp(argv[k], "--overcurrent-a") == 0 && k + 1 < argc) {
            if (!parse_decimal(argv[k + 1], &v) || !(v > 0.0f && v <= 50.0f)) {
                copy_reason(why, why_cap, "--overcurrent-a wants a current in A, 0 < A <= 50; got ", argv[k + 1]);
                return 2;
            }
            f->overcurrent_a = v;
            ++k;
        } else {
            copy_reason(why, why_cap, "unknown argument (known: --overcurrent-a A): ", argv[k]);
            return 1;
        }
    }
    return 0;
}

/* ---- the ABI (hil_fw_abi.h) -------------------------------------------- */

uint32_t hil_fw_abi_version(void) { return HIL_FW_ABI_VERSION; }

const char *hil_fw_name(void) { return fw_name; }

size_t hil_fw_instance_size(void) { return sizeof(sixstep_fw); }

void *hil_fw_create(void *mem, size_t mem_size)
{
    if (mem == NULL || mem_size < sizeof(sixstep_fw) || ((uintptr_t)mem % HIL_FW_INSTANCE_ALIGN) != 0u) {
        return NULL;
    }
    sixstep_fw *f = (sixstep_fw *)mem;
    memset(f, 0, sizeof *f);
    set_defaults(f);
    sixstep_tracker_reset(&f->tracker);
    hil_decoder_init(&f->dec);
    f->state = HIL_STATE_IDLE;
    f->reported_state = HIL_STATE_IDLE;
    return f;
}

size_t hil_fw_exchange(void *fw, const uint8_t *rx, size_t rx_len, uint8_t *tx, size_t tx_cap)
{
    sixstep_fw *f = (sixstep_fw *)fw;
    hil_msg in;
    size_t i = 0;
    while (i < rx_len) {
        int got = 0;
        i += hil_decoder_feed_buf(&f->dec, rx + i, rx_len - i, &in, &got);
        if (got) {
            dispatch(f, &in);
        }
        if (f->dec.version_errors != f->version_errors_seen) {
            /* a frame of another version: say which one we speak (SPEC.md 2.1) */
            f->version_errors_seen = f->dec.version_errors;
            emit_hello(f);
        }
    }
    size_t n = f->out_len < tx_cap ? f->out_len : tx_cap;
    if (n > 0u) {
        memcpy(tx, f->out, n);
        memmove(f->out, f->out + n, f->out_len - n);
        f->out_len -= n;
    }
    return n;
}

int hil_fw_shutdown_requested(const void *fw) { return ((const sixstep_fw *)fw)->shutdown; }

void hil_fw_destroy(void *fw) { (void)fw; /* the memory is the caller's; nothing else is held */ }
