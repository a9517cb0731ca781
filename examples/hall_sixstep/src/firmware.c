/*
 * The hall_sixstep example board's firmware: a BLDC six-step drive on three
 * Hall sensors behind the wire protocol (protocol/SPEC.md), exported as the
 * public firmware ABI (protocol/c/hil_fw_abi.h). Written only against those two
 * headers and the reference codec (hil_proto.h); the same file is the shared
 * library, the executable's core (host/main.c) and the Cortex-M4F image's core
 * (board/board_main.c). No I/O, no allocation, no clock: bytes in, bytes out.
 *
 * It declares a sensor set (HELLO capability SENSOR_SET, read-only parameter
 * SENSOR_SET): three phase currents, the DC link and the Hall word, read from
 * SAMPLE_SENSORS every period; it answers DUTY_LEGS (the conducting pair
 * switched, the third leg floated). Speaks serial only: it does not define
 * hil_fw_can_exchange, and the bench reads that absence as "no CAN".
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "hall_sixstep.h"
#include "hil_fw_abi.h"
#include "hil_proto.h"

#define HS_FW_VERSION "1.0"

#if defined(__x86_64__)
#define HS_TARGET "x86_64"
#elif defined(__aarch64__)
#define HS_TARGET "aarch64"
#elif defined(__ARM_ARCH_7EM__) && defined(__ARM_FP)
#define HS_TARGET "cm4f"
#else
#define HS_TARGET "other"
#endif

static const char fw_name[] = "hall_sixstep-example " HS_FW_VERSION " " HS_TARGET;
typedef char fw_name_fits_hello[(sizeof fw_name - 1u <= HIL_NAME_MAX) ? 1 : -1];

/* The sensors this board reads (SPEC.md 6.13): the value of its read-only
 * parameter SENSOR_SET, and what every SAMPLE_SENSORS must carry. */
#define HS_SENSOR_SET \
    (HIL_SENSOR_CURRENT_A | HIL_SENSOR_CURRENT_B | HIL_SENSOR_CURRENT_C | HIL_SENSOR_VDC | HIL_SENSOR_HALL)

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
    uint32_t counts_per_rev; /* pushed by every bench; this drive has no encoder */
    uint32_t current_phases; /* pushed by every bench; this drive reads all three */
    uint32_t pole_pairs;
    float resistance_ohm;
    float inductance_h;
    float magnet_flux_wb;
    uint32_t telemetry_divider;
    float overcurrent_a;
    float stall_timeout_s; /* parameter STALL_TIMEOUT_S: Hall silence under torque demand */
    uint8_t kp_overridden; /* PARAM_SET of the gains replaces the bandwidth design */
    uint8_t ki_overridden;
    /* derived from the parameters (derive()) */
    hs_speed_gains speed_gains;
    hs_current_gains current_gains;
    float torque_constant_nm_per_a;
    uint32_t stall_timeout_periods;
    /* command */
    uint8_t torque_mode;
    float speed_ref_rad_s;
    float torque_cmd_nm;
    /* control state */
    hs_hall_speed hall_speed;
    hs_speed_pi speed_pi;
    hs_current_pi current_pi;
    hs_hall_watch hall_watch;
    hs_stall_watch stall_watch;
    uint8_t state; /* hil_state */
    uint8_t reported_state;
    uint16_t fault_code;
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
} hs_fw;

/* ---- parameters -------------------------------------------------------- */

static void derive(hs_fw *f)
{
    hs_speed_gains design = hs_speed_pi_design(HS_DESIGN_INERTIA_KGM2, HS_SPEED_BANDWIDTH_HZ,
                                               f->speed_gains.torque_limit_nm);
    if (!f->kp_overridden) {
        f->speed_gains.kp_nm_per_rad_s = design.kp_nm_per_rad_s;
    }
    if (!f->ki_overridden) {
        f->speed_gains.ki_nm_per_rad = design.ki_nm_per_rad;
    }
    f->current_gains = hs_current_design(f->resistance_ohm, f->inductance_h, f->pole_pairs, f->magnet_flux_wb,
                                         HS_CURRENT_BANDWIDTH_HZ);
    f->torque_constant_nm_per_a = hs_torque_constant(f->pole_pairs, f->magnet_flux_wb);
    f->stall_timeout_periods = (uint32_t)(f->stall_timeout_s / f->control_period_s + 0.5f);
}

static void set_defaults(hs_fw *f)
{
    f->control_period_s = HS_DEFAULT_PERIOD_S;
    f->current_a_per_count = 25.0f / 2048.0f; /* SPEC 8.1's defaults */
    f->current_offset_counts = 2048.0f;
    f->vdc_v_per_count = 100.0f / 4096.0f;
    f->vdc_offset_counts = 0.0f;
    f->counts_per_rev = 4096u;
    f->current_phases = 0u;
    f->pole_pairs = HS_DEFAULT_POLE_PAIRS;
    f->resistance_ohm = HS_DEFAULT_RESISTANCE_OHM;
    f->inductance_h = HS_DEFAULT_INDUCTANCE_H;
    f->magnet_flux_wb = HS_DEFAULT_MAGNET_FLUX_WB;
    f->telemetry_divider = 1u;
    f->overcurrent_a = HS_DEFAULT_OVERCURRENT_A;
    f->stall_timeout_s = HS_DEFAULT_STALL_TIMEOUT_S;
    f->speed_gains.torque_limit_nm = HS_DEFAULT_TORQUE_LIMIT_NM;
    derive(f);
}

static int is_whole(float v, float lo, float hi) { return v >= lo && v <= hi && v == floorf(v); }

/* Applies a PARAM_SET; returns the PARAM_VALUE status. A refused value leaves
 * the old one in force (SPEC.md 9.5). NaN fails every range test. */
static uint8_t param_set(hs_fw *f, uint16_t id, float v)
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
        if (!(v >= 0.0f && v <= 65535.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->current_offset_counts = v;
        break;
    case HIL_PARAM_VDC_V_PER_COUNT:
        if (!(v > 0.0f && v < 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->vdc_v_per_count = v;
        break;
    case HIL_PARAM_VDC_OFFSET_COUNTS:
        if (!(v >= 0.0f && v <= 65535.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->vdc_offset_counts = v;
        break;
    case HIL_PARAM_ENCODER_COUNTS_PER_REV:
        if (!is_whole(v, 4.0f, 65536.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->counts_per_rev = (uint32_t)v;
        break;
    case HIL_PARAM_CURRENT_PHASES:
        if (!is_whole(v, 0.0f, 2.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->current_phases = (uint32_t)v;
        break;
    case HIL_PARAM_SENSOR_SET:
        return HIL_PARAM_READ_ONLY;
    case HIL_PARAM_POLE_PAIRS:
        if (!is_whole(v, 1.0f, 64.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->pole_pairs = (uint32_t)v;
        break;
    case HIL_PARAM_STATOR_RESISTANCE_OHM:
        if (!(v > 0.0f && v < 100.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->resistance_ohm = v;
        break;
    case HIL_PARAM_STATOR_INDUCTANCE_H:
        if (!(v > 0.0f && v < 1.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->inductance_h = v;
        break;
    case HIL_PARAM_MAGNET_FLUX_WB:
        if (!(v > 0.0f && v < 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->magnet_flux_wb = v;
        break;
    case HIL_PARAM_TORQUE_LIMIT_NM:
        if (!(v > 0.0f && v < 1000.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->speed_gains.torque_limit_nm = v;
        break;
    case HIL_PARAM_SPEED_KP_NM_PER_RAD_S:
        if (!(v >= 0.0f && v < 1000.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->speed_gains.kp_nm_per_rad_s = v;
        f->kp_overridden = 1u;
        break;
    case HIL_PARAM_SPEED_KI_NM_PER_RAD:
        if (!(v >= 0.0f && v < 1e6f)) return HIL_PARAM_OUT_OF_RANGE;
        f->speed_gains.ki_nm_per_rad = v;
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
    case HIL_PARAM_STALL_TIMEOUT_S:
        /* > 0 (SPEC.md 8): a zero timeout would trip on the first sample without an edge */
        if (!(v > 0.0f && v <= 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->stall_timeout_s = v;
        break;
    default:
        return HIL_PARAM_UNKNOWN;
    }
    derive(f);
    return HIL_PARAM_OK;
}

static uint8_t param_get(const hs_fw *f, uint16_t id, float *v)
{
    switch (id) {
    case HIL_PARAM_CONTROL_PERIOD_S: *v = f->control_period_s; break;
    case HIL_PARAM_CURRENT_A_PER_COUNT: *v = f->current_a_per_count; break;
    case HIL_PARAM_CURRENT_OFFSET_COUNTS: *v = f->current_offset_counts; break;
    case HIL_PARAM_VDC_V_PER_COUNT: *v = f->vdc_v_per_count; break;
    case HIL_PARAM_VDC_OFFSET_COUNTS: *v = f->vdc_offset_counts; break;
    case HIL_PARAM_ENCODER_COUNTS_PER_REV: *v = (float)f->counts_per_rev; break;
    case HIL_PARAM_CURRENT_PHASES: *v = (float)f->current_phases; break;
    case HIL_PARAM_SENSOR_SET: *v = (float)HS_SENSOR_SET; break;
    case HIL_PARAM_POLE_PAIRS: *v = (float)f->pole_pairs; break;
    case HIL_PARAM_STATOR_RESISTANCE_OHM: *v = f->resistance_ohm; break;
    case HIL_PARAM_STATOR_INDUCTANCE_H: *v = f->inductance_h; break;
    case HIL_PARAM_MAGNET_FLUX_WB: *v = f->magnet_flux_wb; break;
    case HIL_PARAM_TORQUE_LIMIT_NM: *v = f->speed_gains.torque_limit_nm; break;
    case HIL_PARAM_SPEED_KP_NM_PER_RAD_S: *v = f->speed_gains.kp_nm_per_rad_s; break;
    case HIL_PARAM_SPEED_KI_NM_PER_RAD: *v = f->speed_gains.ki_nm_per_rad; break;
    case HIL_PARAM_TELEMETRY_DIVIDER: *v = (float)f->telemetry_divider; break;
    case HIL_PARAM_OVERCURRENT_A: *v = f->overcurrent_a; break;
    case HIL_PARAM_STALL_TIMEOUT_S: *v = f->stall_timeout_s; break;
    default:
        *v = 0.0f;
        return HIL_PARAM_UNKNOWN;
    }
    return HIL_PARAM_OK;
}

/* ---- output ------------------------------------------------------------ */

static void emit(hs_fw *f, hil_msg *m)
{
    m->seq = f->seq;
    int n = hil_frame_encode(m, f->out + f->out_len, OUT_BYTES - f->out_len);
    if (n < 0) {
        return; /* queue full: the bench's watchdog sees the missing answer */
    }
    f->out_len += (size_t)n;
    f->seq++;
}

static void emit_status(hs_fw *f, uint32_t period)
{
    hil_msg m;
    m.type = HIL_MSG_STATUS;
    m.u.status.period = period;
    m.u.status.state = f->state;
    m.u.status.fault_code = f->fault_code;
    f->reported_state = f->state;
    emit(f, &m);
}

static void emit_hello(hs_fw *f)
{
    hil_msg m;
    m.type = HIL_MSG_HELLO;
    m.u.hello.proto_version = HIL_PROTO_VERSION;
    m.u.hello.role = HIL_ROLE_CONTROLLER;
    m.u.hello.capabilities = HIL_CAP_SENSOR_SET | HIL_CAP_DUTY_LEGS | HIL_CAP_TELEMETRY;
    m.u.hello.control_period_ns = (uint32_t)(f->control_period_s * 1e9f + 0.5f);
    m.u.hello.name_len = (uint8_t)(sizeof fw_name - 1u);
    memcpy(m.u.hello.name, fw_name, sizeof fw_name - 1u);
    emit(f, &m);
}

/* Latches a fault: switching stops at once; FAULT then STATUS (SPEC.md 2.5). */
static void trip(hs_fw *f, uint16_t code, float value, uint32_t period)
{
    if (f->state == HIL_STATE_FAULT) {
        return;
    }
    f->state = HIL_STATE_FAULT;
    f->fault_code = code;
    hil_msg m;
    m.type = HIL_MSG_FAULT;
    m.u.fault.period = period;
    m.u.fault.code = code;
    m.u.fault.value = value;
    emit(f, &m);
    emit_status(f, period);
}

/* ---- one control period ------------------------------------------------ */

/* TELEMETRY gates for a DUTY_LEGS answer (SPEC.md 6.6): both switches of every enabled leg. */
static uint8_t telemetry_gates(uint8_t leg_enable)
{
    uint8_t mask = 0u;
    for (unsigned x = 0u; x < 3u; x++) {
        if ((leg_enable >> x) & 1u) {
            mask = (uint8_t)(mask | (0x03u << (2u * x)));
        }
    }
    return mask;
}

static uint16_t duty_counts(float duty)
{
    /* hs_legs duties are in [0, 1] (hs_legs_for_pair_voltage) */
    return (uint16_t)(duty * 65535.0f + 0.5f);
}

/* What one period decided, for the answer and TELEMETRY. */
typedef struct {
    hs_legs legs;
    uint8_t sector;
    float speed_rad_s;
    float torque_ref_nm;
    float torque_est_nm;
} hs_period;

static void answer(hs_fw *f, uint32_t period, const hs_period *p)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_DUTY_LEGS;
    m.u.duty_legs.period = period;
    m.u.duty_legs.leg_enable = p->legs.leg_enable;
    for (unsigned x = 0u; x < 3u; x++) {
        m.u.duty_legs.duty[x] = (p->legs.leg_enable >> x) & 1u ? duty_counts(p->legs.duty[x]) : 0u;
    }
    emit(f, &m);
    if (f->telemetry_divider != 0u && period % f->telemetry_divider == 0u) {
        memset(&m, 0, sizeof m);
        m.type = HIL_MSG_TELEMETRY;
        hil_telemetry *t = &m.u.telemetry;
        t->period = period;
        t->sector = p->legs.leg_enable != 0u ? p->sector : 0u;
        t->speed_source = HIL_SPEED_ENCODER; /* the position sensor: the Halls */
        t->state = f->state;
        t->gates = telemetry_gates(p->legs.leg_enable);
        t->speed_feedback_rad_s = p->speed_rad_s;
        t->speed_encoder_rad_s = p->speed_rad_s;
        t->torque_est_nm = p->torque_est_nm;
        t->torque_ref_nm = p->torque_ref_nm;
        /* fields of estimators this drive does not have stay 0 */
        emit(f, &m);
    }
}

static void phase_currents(const hs_fw *f, const hil_sample_sensors *s, float i_abc[3])
{
    i_abc[0] = ((float)s->adc_ia - f->current_offset_counts) * f->current_a_per_count;
    i_abc[1] = ((float)s->adc_ib - f->current_offset_counts) * f->current_a_per_count;
    i_abc[2] = ((float)s->adc_ic - f->current_offset_counts) * f->current_a_per_count;
}

/* Protections ahead of the control law, in order of urgency; each latches FAULT. */
static void protect(hs_fw *f, const hil_sample_sensors *s, const float i_abc[3], uint8_t sector)
{
    float i_peak = fmaxf(fabsf(i_abc[0]), fmaxf(fabsf(i_abc[1]), fabsf(i_abc[2])));
    if ((s->status & HIL_STATUS_OVERCURRENT) != 0u || i_peak > f->overcurrent_a) {
        trip(f, HIL_FAULT_OVERCURRENT, i_peak, s->period);
    }
    /* Hall word 0 or 7: the position sensor is lost (SPEC.md 9.6 ENCODER_LOSS; value: the
     * seconds the word has been illegal) */
    if (hs_hall_watch_step(&f->hall_watch, sector)) {
        trip(f, HIL_FAULT_ENCODER_LOSS, (float)f->hall_watch.illegal_periods * f->control_period_s, s->period);
    }
}

static void on_sample_sensors(hs_fw *f, const hil_sample_sensors *s)
{
    const float dt = f->control_period_s;
    f->next_period = s->period + 1u;
    hs_period p;
    memset(&p, 0, sizeof p);
    p.legs = hs_legs_off();
    if ((s->sensor_set & HS_SENSOR_SET) != HS_SENSOR_SET) {
        /* a sensor this drive commutates or regulates on is missing: never switch blind */
        if (f->state == HIL_STATE_RUNNING) {
            trip(f, HIL_FAULT_PROTOCOL, (float)s->sensor_set, s->period);
        }
        answer(f, s->period, &p);
        return;
    }
    float i_abc[3];
    phase_currents(f, s, i_abc);
    float vdc = ((float)s->adc_vdc - f->vdc_offset_counts) * f->vdc_v_per_count;
    p.sector = hs_sector_of_hall(s->hall);
    /* the speed is tracked in every state, so enabling a coasting rotor starts right */
    int edge = hs_hall_speed_step(&f->hall_speed, p.sector, f->pole_pairs, dt);
    p.speed_rad_s = f->hall_speed.speed_rad_s;

    if (f->state == HIL_STATE_RUNNING) {
        protect(f, s, i_abc, p.sector);
    }
    if (f->state == HIL_STATE_RUNNING) {
        if (f->torque_mode) {
            float lim = f->speed_gains.torque_limit_nm;
            p.torque_ref_nm = fminf(fmaxf(f->torque_cmd_nm, -lim), lim);
        } else {
            p.torque_ref_nm = hs_speed_pi_step(&f->speed_gains, &f->speed_pi, f->speed_ref_rad_s - p.speed_rad_s, dt);
        }
        if (hs_stall_watch_step(&f->stall_watch, edge, p.torque_ref_nm, f->speed_gains.torque_limit_nm,
                                f->stall_timeout_periods)) {
            /* no Hall edge under torque: the rotor does not follow the drive (SPEC.md 9.6
             * STALL, value: the seconds since the last Hall edge); the sensor itself works */
            trip(f, HIL_FAULT_STALL, (float)f->stall_watch.silent_periods * dt, s->period);
        }
    }
    if (f->state == HIL_STATE_RUNNING && p.sector != 0u) {
        hs_pair pair = hs_commutation(p.sector);
        float pair_current = hs_pair_current(i_abc, pair);
        float current_ref = p.torque_ref_nm / f->torque_constant_nm_per_a;
        float v = hs_current_step(&f->current_gains, &f->current_pi, current_ref, pair_current, p.speed_rad_s,
                                  vdc, dt);
        p.legs = hs_legs_for_pair_voltage(pair, v, vdc);
        p.torque_est_nm = pair_current * f->torque_constant_nm_per_a;
    }
    /* an illegal Hall word not yet confirmed (sector 0) floats every leg: no commutation is right */
    answer(f, s->period, &p);
}

/* A plain SAMPLE carries no Hall word: the bench did not take this board's sensor set. */
static void on_plain_sample(hs_fw *f, const hil_sample *s)
{
    f->next_period = s->period + 1u;
    if (f->state == HIL_STATE_RUNNING) {
        trip(f, HIL_FAULT_PROTOCOL, 0.0f, s->period);
    }
    hs_period p;
    memset(&p, 0, sizeof p);
    p.legs = hs_legs_off();
    answer(f, s->period, &p);
}

static void on_command(hs_fw *f, const hil_command *c)
{
    if (c->speed_source != HIL_SPEED_ENCODER) {
        /* this drive's only speed is the Halls' (the position sensor, "encoder" in SPEC
         * terms): refuse to run on an estimator it does not have, say why */
        trip(f, HIL_FAULT_PROTOCOL, (float)c->speed_source, f->next_period);
        return;
    }
    if (!isfinite(c->speed_ref_rad_s) || !isfinite(c->torque_ref_nm)) {
        trip(f, HIL_FAULT_NON_FINITE, (float)HIL_NONFINITE_COMMAND, f->next_period);
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
        f->speed_pi.integral_nm = 0.0f;
        f->current_pi.integral_v = 0.0f;
        memset(&f->hall_watch, 0, sizeof f->hall_watch);
        memset(&f->stall_watch, 0, sizeof f->stall_watch);
    }
    if (f->state != f->reported_state) {
        emit_status(f, f->next_period); /* applies from the next SAMPLE on */
    }
}

static void dispatch(hs_fw *f, const hil_msg *in)
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
    case HIL_MSG_SAMPLE_SENSORS:
        on_sample_sensors(f, &in->u.sample_sensors);
        break;
    case HIL_MSG_SAMPLE:
        on_plain_sample(f, &in->u.sample);
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
    hs_fw *f = (hs_fw *)fw;
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

size_t hil_fw_instance_size(void) { return sizeof(hs_fw); }

void *hil_fw_create(void *mem, size_t mem_size)
{
    if (mem == NULL || mem_size < sizeof(hs_fw) || ((uintptr_t)mem % HIL_FW_INSTANCE_ALIGN) != 0u) {
        return NULL;
    }
    hs_fw *f = (hs_fw *)mem;
    memset(f, 0, sizeof *f);
    set_defaults(f);
    hs_hall_speed_reset(&f->hall_speed);
    hil_decoder_init(&f->dec);
    f->state = HIL_STATE_IDLE;
    f->reported_state = HIL_STATE_IDLE;
    return f;
}

size_t hil_fw_exchange(void *fw, const uint8_t *rx, size_t rx_len, uint8_t *tx, size_t tx_cap)
{
    hs_fw *f = (hs_fw *)fw;
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

int hil_fw_shutdown_requested(const void *fw) { return ((const hs_fw *)fw)->shutdown; }

void hil_fw_destroy(void *fw) { (void)fw; /* the memory is the caller's; nothing else is held */ }
