/*
 * The example ESC's firmware: the sensorless six-step drive (bemf.h) behind
 * the wire protocol (protocol/SPEC.md), exported as the public firmware ABI
 * (protocol/c/hil_fw_abi.h). Written only against those two headers and the
 * reference codec (hil_proto.h); the same file is the shared library, the
 * executable's core (host/main.c) and the Cortex-M4F image's core
 * (board/board_main.c). No I/O, no allocation, no clock: bytes in, bytes out.
 *
 * The board declares a sensor set (HELLO capability SENSOR_SET, parameter
 * SENSOR_SET): three phase currents, the DC link, the three terminal voltages
 * and the three back-EMF comparators; it reads SAMPLE_SENSORS and answers
 * DUTY_LEGS. Serial only: it does not define hil_fw_can_exchange.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "bemf.h"
#include "hil_fw_abi.h"
#include "hil_proto.h"

#define BEMF_FW_VERSION "1.0"

#if defined(__x86_64__)
#define BEMF_TARGET "x86_64"
#elif defined(__aarch64__)
#define BEMF_TARGET "aarch64"
#elif defined(__ARM_ARCH_7EM__) && defined(__ARM_FP)
#define BEMF_TARGET "cm4f"
#else
#define BEMF_TARGET "other"
#endif

static const char fw_name[] = "bemf-sixstep-example " BEMF_FW_VERSION " " BEMF_TARGET;
typedef char fw_name_fits_hello[(sizeof fw_name - 1u <= HIL_NAME_MAX) ? 1 : -1];

/* The sensors this board reads (SENSOR_SET): what an ESC's ADC and comparator pins see. */
#define BEMF_SENSOR_SET                                                                                 \
    (HIL_SENSOR_CURRENT_A | HIL_SENSOR_CURRENT_B | HIL_SENSOR_CURRENT_C | HIL_SENSOR_VDC |            \
     HIL_SENSOR_TERMINAL_VOLTAGES | HIL_SENSOR_BEMF_COMPARATORS)

/* ---- the board's defaults: the shared BLDC (24 V, 4 pole pairs) on a 50 us period ---- */
#define BEMF_DEFAULT_PERIOD_S 50e-6f
#define BEMF_DEFAULT_POLE_PAIRS 4u
#define BEMF_DEFAULT_RESISTANCE_OHM 0.25f
#define BEMF_DEFAULT_INDUCTANCE_H 0.3e-3f
#define BEMF_DEFAULT_MAGNET_FLUX_WB 0.0060f
/* The speed loop's design inertia (rotor and load). Not a protocol parameter:
 * a user sets it for their drive here, or sets the PI gains (24, 25). */
#define BEMF_DESIGN_INERTIA_KGM2 2.0e-5f
#define BEMF_SPEED_BANDWIDTH_HZ 10.0f
#define BEMF_DEFAULT_TORQUE_LIMIT_NM 0.15f
#define BEMF_DEFAULT_OVERCURRENT_A 15.0f
/* longer than the hand-over: handover_zero_crosses + 1 steps at the ramp's end speed (36.7 ms) */
#define BEMF_DEFAULT_ZC_TIMEOUT_S 0.04f

/* Vendor parameters (ids 100-110, examples/bemf_sixstep/board.yaml) */
enum {
    PARAM_ALIGN_TIME_S = 100,
    PARAM_ALIGN_CURRENT_A = 101,
    PARAM_RAMP_START_RAD_S = 102,
    PARAM_RAMP_END_RAD_S = 103,
    PARAM_RAMP_TIME_S = 104,
    PARAM_RAMP_CURRENT_A = 105,
    PARAM_HANDOVER_ZERO_CROSSES = 106,
    PARAM_BLANKING_FRACTION = 107,
    PARAM_CURRENT_BANDWIDTH_HZ = 108,
    PARAM_DEMAG_CURRENT_A = 109,
    PARAM_ZC_LAG_PERIODS = 110
};

/* Largest burst one SAMPLE causes: DUTY_LEGS 19 + TELEMETRY 64 + FAULT 18 + STATUS 15
 * bytes; the rest is room for PARAM_VALUEs the bench sends in a row. */
#define OUT_BYTES 1024u

typedef struct {
    /* parameters (SPEC.md section 8 and the vendor ones), SI units */
    float control_period_s;
    float current_a_per_count;
    float current_offset_counts;
    float vdc_v_per_count;
    float vdc_offset_counts;
    float terminal_v_per_count;
    uint32_t counts_per_rev;  /* required by SPEC 8.1; this board has no encoder */
    uint32_t current_phases;  /* required by SPEC 8.1; this board reads all three */
    uint32_t pole_pairs;
    float resistance_ohm;
    float inductance_h;
    float magnet_flux_wb;
    float torque_limit_nm;
    float speed_kp;
    float speed_ki;
    uint8_t kp_overridden;    /* PARAM_SET of the gains replaces the bandwidth design */
    uint8_t ki_overridden;
    uint32_t telemetry_divider;
    float overcurrent_a;
    float zc_timeout_s;       /* STALL_TIMEOUT_S: no zero cross this long under drive trips FAULT STALL */
    float align_time_s;
    float align_current_a;
    float ramp_start_rad_s;
    float ramp_end_rad_s;
    float ramp_time_s;
    float ramp_current_a;
    uint32_t handover_zero_crosses;
    float blanking_fraction;
    float current_bandwidth_hz;
    float demag_current_a;
    float zc_lag_periods;
    /* derived (derive()) */
    bemf_config cfg;
    /* command */
    uint8_t enable;
    uint8_t torque_mode;
    uint8_t speed_source;
    float speed_ref_rad_s;
    float torque_cmd_nm;
    /* control state */
    bemf_drive drive;
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
} bemf_fw;

/* ---- parameters -------------------------------------------------------- */

static uint32_t periods_of(float seconds, float period_s)
{
    float n = seconds / period_s + 0.5f;
    return n < 4.0e9f ? (uint32_t)n : 4000000000u;
}

static void derive(bemf_fw *f)
{
    bemf_config *c = &f->cfg;
    bemf_speed_pi_gains design =
        bemf_speed_pi_design(BEMF_DESIGN_INERTIA_KGM2, BEMF_SPEED_BANDWIDTH_HZ, f->torque_limit_nm);
    if (!f->kp_overridden) {
        f->speed_kp = design.kp_nm_per_rad_s;
    }
    if (!f->ki_overridden) {
        f->speed_ki = design.ki_nm_per_rad;
    }
    c->control_period_s = f->control_period_s;
    c->pole_pairs = f->pole_pairs;
    c->resistance_ohm = f->resistance_ohm;
    c->magnet_flux_wb = f->magnet_flux_wb;
    c->overcurrent_a = f->overcurrent_a;
    c->zc_timeout_periods = periods_of(f->zc_timeout_s, f->control_period_s);
    c->align_step = 6u; /* current vector at -30 deg: the rotor's d-axis turns there */
    c->align_current_a = f->align_current_a;
    c->ramp_current_a = f->ramp_current_a;
    c->handover_zero_crosses = f->handover_zero_crosses;
    c->zc_lag_periods = f->zc_lag_periods;
    c->blanking_fraction = f->blanking_fraction;
    c->min_blanking_periods = 2u;
    c->ramp.align_periods = periods_of(f->align_time_s, f->control_period_s);
    c->ramp.ramp_start_rad_s = f->ramp_start_rad_s;
    c->ramp.ramp_end_rad_s = f->ramp_end_rad_s;
    c->ramp.ramp_periods = periods_of(f->ramp_time_s, f->control_period_s);
    c->zc.blanking_periods = c->min_blanking_periods;
    c->zc.demag_current_a = f->demag_current_a;
    c->zc.demag_limit_periods = c->min_blanking_periods + 1u;
    c->zc.confirm_samples = 2u;
    c->speed_gains.kp_nm_per_rad_s = f->speed_kp;
    c->speed_gains.ki_nm_per_rad = f->speed_ki;
    c->speed_gains.torque_limit_nm = f->torque_limit_nm;
    c->current_gains = bemf_current_pi_design(f->resistance_ohm, f->inductance_h, f->current_bandwidth_hz);
    c->torque_constant_nm_per_a = bemf_torque_constant(f->pole_pairs, f->magnet_flux_wb);
}

static void set_defaults(bemf_fw *f)
{
    f->control_period_s = BEMF_DEFAULT_PERIOD_S;
    f->current_a_per_count = 25.0f / 2048.0f;
    f->current_offset_counts = 2048.0f;
    f->vdc_v_per_count = 100.0f / 4096.0f;
    f->vdc_offset_counts = 0.0f;
    f->terminal_v_per_count = 33.0f / 4096.0f; /* this board's divider: 1:10 into a 3.3 V ADC */
    f->counts_per_rev = 4096u;
    f->current_phases = 0u;
    f->pole_pairs = BEMF_DEFAULT_POLE_PAIRS;
    f->resistance_ohm = BEMF_DEFAULT_RESISTANCE_OHM;
    f->inductance_h = BEMF_DEFAULT_INDUCTANCE_H;
    f->magnet_flux_wb = BEMF_DEFAULT_MAGNET_FLUX_WB;
    f->torque_limit_nm = BEMF_DEFAULT_TORQUE_LIMIT_NM;
    f->telemetry_divider = 1u;
    f->overcurrent_a = BEMF_DEFAULT_OVERCURRENT_A;
    f->zc_timeout_s = BEMF_DEFAULT_ZC_TIMEOUT_S;
    f->align_time_s = 0.05f;
    f->align_current_a = 3.0f;
    f->ramp_start_rad_s = 10.0f;  /* 95 rpm */
    f->ramp_end_rad_s = 50.0f;    /* 477 rpm */
    f->ramp_time_s = 0.1f;
    f->ramp_current_a = 3.0f;
    f->handover_zero_crosses = 6u;
    f->blanking_fraction = 0.25f;
    f->current_bandwidth_hz = 500.0f;
    f->demag_current_a = 0.1f;
    /* the comparators and ADCs see a period's average (half a period late)
     * through this board's 10 us RC filter (0.2 of a 50 us period) */
    f->zc_lag_periods = 0.7f;
    derive(f);
}

static int is_whole(float v, float lo, float hi) { return v >= lo && v <= hi && v == floorf(v); }
static int in_range(float v, float lo, float hi) { return v >= lo && v <= hi; } /* NaN fails */

/* Applies a PARAM_SET; returns the PARAM_VALUE status. A refused value leaves
 * the old one in force (SPEC.md 9.5). NaN fails every range test. */
static uint8_t param_set(bemf_fw *f, uint16_t id, float v)
{
    switch (id) {
    case HIL_PARAM_CONTROL_PERIOD_S:
        if (!in_range(v, 1e-6f, 0.01f)) return HIL_PARAM_OUT_OF_RANGE;
        f->control_period_s = v;
        break;
    case HIL_PARAM_CURRENT_A_PER_COUNT:
        if (!(v > 0.0f && v < 1.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->current_a_per_count = v;
        break;
    case HIL_PARAM_CURRENT_OFFSET_COUNTS:
        if (!in_range(v, 0.0f, 65535.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->current_offset_counts = v;
        break;
    case HIL_PARAM_VDC_V_PER_COUNT:
        if (!(v > 0.0f && v < 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->vdc_v_per_count = v;
        break;
    case HIL_PARAM_VDC_OFFSET_COUNTS:
        if (!in_range(v, 0.0f, 65535.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->vdc_offset_counts = v;
        break;
    case HIL_PARAM_TERMINAL_V_PER_COUNT:
        if (!(v > 0.0f && v < 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->terminal_v_per_count = v;
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
        f->torque_limit_nm = v;
        break;
    case HIL_PARAM_SPEED_KP_NM_PER_RAD_S:
        if (!(v >= 0.0f && v < 1000.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->speed_kp = v;
        f->kp_overridden = 1u;
        break;
    case HIL_PARAM_SPEED_KI_NM_PER_RAD:
        if (!(v >= 0.0f && v < 1e6f)) return HIL_PARAM_OUT_OF_RANGE;
        f->speed_ki = v;
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
        if (!(v > 0.0f && v <= 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->zc_timeout_s = v;
        break;
    case PARAM_ALIGN_TIME_S:
        if (!in_range(v, 0.0f, 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->align_time_s = v;
        break;
    case PARAM_ALIGN_CURRENT_A:
        if (!in_range(v, 0.0f, 100.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->align_current_a = v;
        break;
    case PARAM_RAMP_START_RAD_S:
        if (!(v > 0.0f && v <= 10000.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->ramp_start_rad_s = v;
        break;
    case PARAM_RAMP_END_RAD_S:
        if (!(v > 0.0f && v <= 10000.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->ramp_end_rad_s = v;
        break;
    case PARAM_RAMP_TIME_S:
        if (!in_range(v, 0.0f, 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->ramp_time_s = v;
        break;
    case PARAM_RAMP_CURRENT_A:
        if (!in_range(v, 0.0f, 100.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->ramp_current_a = v;
        break;
    case PARAM_HANDOVER_ZERO_CROSSES:
        if (!is_whole(v, 1.0f, 1000.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->handover_zero_crosses = (uint32_t)v;
        break;
    case PARAM_BLANKING_FRACTION:
        if (!in_range(v, 0.0f, 0.45f)) return HIL_PARAM_OUT_OF_RANGE;
        f->blanking_fraction = v;
        break;
    case PARAM_CURRENT_BANDWIDTH_HZ:
        if (!in_range(v, 1.0f, 5000.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->current_bandwidth_hz = v;
        break;
    case PARAM_DEMAG_CURRENT_A:
        if (!(v > 0.0f && v <= 100.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->demag_current_a = v;
        break;
    case PARAM_ZC_LAG_PERIODS:
        if (!in_range(v, 0.0f, 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        f->zc_lag_periods = v;
        break;
    default:
        return HIL_PARAM_UNKNOWN;
    }
    derive(f);
    return HIL_PARAM_OK;
}

static uint8_t param_get(const bemf_fw *f, uint16_t id, float *v)
{
    switch (id) {
    case HIL_PARAM_CONTROL_PERIOD_S: *v = f->control_period_s; break;
    case HIL_PARAM_CURRENT_A_PER_COUNT: *v = f->current_a_per_count; break;
    case HIL_PARAM_CURRENT_OFFSET_COUNTS: *v = f->current_offset_counts; break;
    case HIL_PARAM_VDC_V_PER_COUNT: *v = f->vdc_v_per_count; break;
    case HIL_PARAM_VDC_OFFSET_COUNTS: *v = f->vdc_offset_counts; break;
    case HIL_PARAM_TERMINAL_V_PER_COUNT: *v = f->terminal_v_per_count; break;
    case HIL_PARAM_ENCODER_COUNTS_PER_REV: *v = (float)f->counts_per_rev; break;
    case HIL_PARAM_CURRENT_PHASES: *v = (float)f->current_phases; break;
    case HIL_PARAM_SENSOR_SET: *v = (float)BEMF_SENSOR_SET; break;
    case HIL_PARAM_POLE_PAIRS: *v = (float)f->pole_pairs; break;
    case HIL_PARAM_STATOR_RESISTANCE_OHM: *v = f->resistance_ohm; break;
    case HIL_PARAM_STATOR_INDUCTANCE_H: *v = f->inductance_h; break;
    case HIL_PARAM_MAGNET_FLUX_WB: *v = f->magnet_flux_wb; break;
    case HIL_PARAM_TORQUE_LIMIT_NM: *v = f->torque_limit_nm; break;
    case HIL_PARAM_SPEED_KP_NM_PER_RAD_S: *v = f->speed_kp; break;
    case HIL_PARAM_SPEED_KI_NM_PER_RAD: *v = f->speed_ki; break;
    case HIL_PARAM_TELEMETRY_DIVIDER: *v = (float)f->telemetry_divider; break;
    case HIL_PARAM_OVERCURRENT_A: *v = f->overcurrent_a; break;
    case HIL_PARAM_STALL_TIMEOUT_S: *v = f->zc_timeout_s; break;
    case PARAM_ALIGN_TIME_S: *v = f->align_time_s; break;
    case PARAM_ALIGN_CURRENT_A: *v = f->align_current_a; break;
    case PARAM_RAMP_START_RAD_S: *v = f->ramp_start_rad_s; break;
    case PARAM_RAMP_END_RAD_S: *v = f->ramp_end_rad_s; break;
    case PARAM_RAMP_TIME_S: *v = f->ramp_time_s; break;
    case PARAM_RAMP_CURRENT_A: *v = f->ramp_current_a; break;
    case PARAM_HANDOVER_ZERO_CROSSES: *v = (float)f->handover_zero_crosses; break;
    case PARAM_BLANKING_FRACTION: *v = f->blanking_fraction; break;
    case PARAM_CURRENT_BANDWIDTH_HZ: *v = f->current_bandwidth_hz; break;
    case PARAM_DEMAG_CURRENT_A: *v = f->demag_current_a; break;
    case PARAM_ZC_LAG_PERIODS: *v = f->zc_lag_periods; break;
    default:
        *v = 0.0f;
        return HIL_PARAM_UNKNOWN;
    }
    return HIL_PARAM_OK;
}

/* ---- output ------------------------------------------------------------ */

static void emit(bemf_fw *f, hil_msg *m)
{
    m->seq = f->seq;
    int n = hil_frame_encode(m, f->out + f->out_len, OUT_BYTES - f->out_len);
    if (n < 0) {
        return; /* queue full: the bench's watchdog sees the missing answer */
    }
    f->out_len += (size_t)n;
    f->seq++;
}

static void emit_status(bemf_fw *f, uint32_t period)
{
    hil_msg m;
    m.type = HIL_MSG_STATUS;
    m.u.status.period = period;
    m.u.status.state = f->state;
    m.u.status.fault_code = f->fault_code;
    f->reported_state = f->state;
    emit(f, &m);
}

static void emit_hello(bemf_fw *f)
{
    hil_msg m;
    m.type = HIL_MSG_HELLO;
    m.u.hello.proto_version = HIL_PROTO_VERSION;
    m.u.hello.role = HIL_ROLE_CONTROLLER;
    m.u.hello.capabilities = HIL_CAP_DUTY_LEGS | HIL_CAP_TELEMETRY | HIL_CAP_SENSOR_SET;
    m.u.hello.control_period_ns = (uint32_t)(f->control_period_s * 1e9f + 0.5f);
    m.u.hello.name_len = (uint8_t)(sizeof fw_name - 1u);
    memcpy(m.u.hello.name, fw_name, sizeof fw_name - 1u);
    emit(f, &m);
}

/* Latches a fault: switching stops at once; FAULT then STATUS (SPEC.md 2.5). */
static void trip(bemf_fw *f, uint16_t code, float value, uint32_t period)
{
    if (f->state == HIL_STATE_FAULT) {
        return;
    }
    bemf_drive_disable(&f->drive);
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

/* The DUTY_LEGS answer of a bridge command (SPEC.md 6.12): the step's high leg
 * switches at the duty, its low leg is at duty 0 (low switch on all period),
 * the third leg floats so that its terminal shows star point + back-EMF. */
static void duty_legs_of(bemf_output out, hil_duty_legs *answer)
{
    answer->duty[0] = answer->duty[1] = answer->duty[2] = 0u;
    answer->leg_enable = 0u;
    if (out.step == 0u) {
        return;
    }
    bemf_step s = bemf_commutation(out.step);
    float d = out.duty > 1.0f ? 1.0f : (out.duty > 0.0f ? out.duty : 0.0f);
    answer->duty[s.high] = (uint16_t)(d * 65535.0f + 0.5f);
    answer->leg_enable = (uint8_t)((1u << s.high) | (1u << s.low));
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

static void send_answer(bemf_fw *f, uint32_t period, bemf_output out)
{
    hil_msg m;
    m.type = HIL_MSG_DUTY_LEGS;
    m.u.duty_legs.period = period;
    duty_legs_of(out, &m.u.duty_legs);
    uint8_t conducting = telemetry_gates(&m.u.duty_legs);
    emit(f, &m);
    if (f->telemetry_divider != 0u && period % f->telemetry_divider == 0u) {
        const bemf_drive *d = &f->drive;
        memset(&m, 0, sizeof m);
        m.type = HIL_MSG_TELEMETRY;
        hil_telemetry *t = &m.u.telemetry;
        t->period = period;
        t->sector = out.step;
        t->speed_source = f->speed_source;
        t->state = f->state;
        t->gates = conducting;
        /* the speed from the zero crosses (the open-loop ramp's while starting) */
        t->speed_feedback_rad_s = d->speed_rad_s;
        t->speed_raw_rad_s = d->speed_rad_s;
        t->torque_ref_nm = d->torque_ref_nm;
        t->torque_est_nm = d->pair_current_a * f->cfg.torque_constant_nm_per_a;
        /* fields of estimators this drive does not have stay 0 */
        emit(f, &m);
    }
}

static void on_sample_sensors(bemf_fw *f, const hil_sample_sensors *s)
{
    f->next_period = s->period + 1u;
    bemf_output out = {0u, 0.0f};
    if ((s->sensor_set & BEMF_SENSOR_SET) != BEMF_SENSOR_SET) {
        /* a sample without our sensors: nothing to commutate on */
        if (f->state == HIL_STATE_RUNNING || f->state == HIL_STATE_STARTING) {
            trip(f, HIL_FAULT_PROTOCOL, (float)s->sensor_set, s->period);
        }
        send_answer(f, s->period, out);
        return;
    }
    bemf_inputs in;
    const uint16_t counts[3] = {s->adc_ia, s->adc_ib, s->adc_ic};
    for (unsigned x = 0u; x < 3u; ++x) {
        in.phase_current_a[x] = ((float)counts[x] - f->current_offset_counts) * f->current_a_per_count;
    }
    in.vdc_v = ((float)s->adc_vdc - f->vdc_offset_counts) * f->vdc_v_per_count;
    in.comparators = s->bemf_comparators;
    const uint16_t terminal[3] = {s->adc_va, s->adc_vb, s->adc_vc};
    for (unsigned x = 0u; x < 3u; ++x) {
        in.terminal_v[x] = (float)terminal[x] * f->terminal_v_per_count;
    }
    in.overcurrent_flag = (s->status & HIL_STATUS_OVERCURRENT) != 0u;
    in.torque_mode = f->torque_mode;
    in.speed_ref_rad_s = f->speed_ref_rad_s;
    in.torque_ref_nm = f->torque_cmd_nm;
    if (f->state == HIL_STATE_RUNNING || f->state == HIL_STATE_STARTING) {
        out = bemf_drive_step(&f->cfg, &f->drive, &in);
        if (f->drive.mode == BEMF_TRIPPED) {
            /* no zero cross in time (desync, locked rotor, failed start): the rotor does not
             * follow the drive, SPEC.md 9.6 STALL */
            uint16_t code = f->drive.trip == BEMF_TRIP_OVERCURRENT ? HIL_FAULT_OVERCURRENT : HIL_FAULT_STALL;
            trip(f, code, f->drive.trip_value, s->period);
            out.step = 0u;
        } else if (f->drive.mode == BEMF_CLOSED && f->state == HIL_STATE_STARTING) {
            /* ready: this period's answer is the first that commutates on the zero crosses */
            f->state = HIL_STATE_RUNNING;
            emit_status(f, s->period);
        }
    }
    send_answer(f, s->period, out);
}

static void on_command(bemf_fw *f, const hil_command *c)
{
    if (!(fabsf(c->speed_ref_rad_s) <= 1e6f) || !(fabsf(c->torque_ref_nm) <= 1e6f)) {
        /* SPEC.md 9.6: a NaN or infinite reference is refused, not applied */
        trip(f, HIL_FAULT_NON_FINITE, 8.0f, f->next_period);
        return;
    }
    uint8_t enable = (c->flags & HIL_CMD_ENABLE) != 0u;
    f->torque_mode = (c->flags & HIL_CMD_TORQUE_MODE) != 0u;
    f->speed_source = c->speed_source; /* the zero crosses are this drive's only speed source */
    f->speed_ref_rad_s = c->speed_ref_rad_s;
    f->torque_cmd_nm = c->torque_ref_nm;
    if (!enable) {
        /* disabling clears a latched fault (SPEC.md 2.5) */
        f->state = HIL_STATE_IDLE;
        f->fault_code = HIL_FAULT_NONE;
        bemf_drive_disable(&f->drive);
    } else if (f->state == HIL_STATE_IDLE) {
        /* align and ramp first: STARTING until the zero crosses take over */
        f->state = HIL_STATE_STARTING;
        bemf_drive_enable(&f->drive, &f->cfg);
    }
    f->enable = enable;
    if (f->state != f->reported_state) {
        emit_status(f, f->next_period); /* applies from the next SAMPLE on */
    }
}

static void dispatch(bemf_fw *f, const hil_msg *in)
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
    case HIL_MSG_SAMPLE: {
        /* the plain SAMPLE has no comparators: answer with the bridge open */
        hil_sample_sensors none;
        memset(&none, 0, sizeof none);
        none.period = in->u.sample.period;
        on_sample_sensors(f, &none);
        break;
    }
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
        bemf_drive_disable(&f->drive);
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
    bemf_fw *f = (bemf_fw *)fw;
    for (int k = 0; k < argc; ++k) {
        float v;
        if (strcmp(argv[k], "--overcurrent-a") == 0 && k + 1 < argc) {
            if (!parse_decimal(argv[k + 1], &v) || !(v > 0.0f && v <= 50.0f)) {
                copy_reason(why, why_cap, "--overcurrent-a wants a current in A, 0 < A <= 50; got ", argv[k + 1]);
                return 2;
            }
            f->overcurrent_a = v;
            derive(f);
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

size_t hil_fw_instance_size(void) { return sizeof(bemf_fw); }

void *hil_fw_create(void *mem, size_t mem_size)
{
    if (mem == NULL || mem_size < sizeof(bemf_fw) || ((uintptr_t)mem % HIL_FW_INSTANCE_ALIGN) != 0u) {
        return NULL;
    }
    bemf_fw *f = (bemf_fw *)mem;
    memset(f, 0, sizeof *f);
    set_defaults(f);
    hil_decoder_init(&f->dec);
    f->state = HIL_STATE_IDLE;
    f->reported_state = HIL_STATE_IDLE;
    return f;
}

size_t hil_fw_exchange(void *fw, const uint8_t *rx, size_t rx_len, uint8_t *tx, size_t tx_cap)
{
    bemf_fw *f = (bemf_fw *)fw;
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

int hil_fw_shutdown_requested(const void *fw) { return ((const bemf_fw *)fw)->shutdown; }

void hil_fw_destroy(void *fw) { (void)fw; /* the memory is the caller's; nothing else is held */ }
