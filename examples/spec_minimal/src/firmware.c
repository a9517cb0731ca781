/*
 * spec_minimal: a board written from protocol/SPEC.md alone, as a third party
 * would. Sensored field-oriented control on the encoder (speed PI, d/q current
 * PIs), answering DUTY while running. Written against the public headers only:
 * the reference codec (hil_proto.h) and the firmware ABI (hil_fw_abi.h).
 *
 * Deliberately Arduino-style: every piece of state is a static variable at file
 * scope, initialised by the C runtime (.data, zeroed .bss) when the program is
 * loaded, and never re-initialised. hil_fw_create is "power on": it runs once
 * per load and refuses a second call (a board does not boot twice without a
 * reset). The bench's `lib:` link gives each session a freshly loaded copy of
 * the library (protocol/c/hil_fw_abi.h), which is what makes this work for the
 * second session of one process; the host program (host/main.c) is one process
 * per session anyway.
 *
 * Knows only the parameters SPEC.md 8.1 marks as pushed; every other id is
 * answered UNKNOWN. The motor constants and gains are compile-time constants
 * for the paper's Table 1 motor (below).
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "foc.h"
#include "hil_fw_abi.h"
#include "hil_proto.h"

#define SPEC_MINIMAL_VERSION "1.0"
static const char fw_name[] = "spec-minimal " SPEC_MINIMAL_VERSION;
typedef char fw_name_fits_hello[(sizeof fw_name - 1u <= HIL_NAME_MAX) ? 1 : -1];

#define TWO_PI 6.28318530717959f

/* ---- the motor and the design (compile time) ------------------------------
 * The paper's Table 1 motor (plant_rt/profiles/paper.yaml): R = 0.466 ohm,
 * L_s = 4.8 mH (surface magnets: L_d = L_q), psi_m = 0.0928 Wb, J = 8e-4 kg m^2,
 * on a 70 V DC link; p comes from the pushed POLE_PAIRS. */
#define MOTOR_RESISTANCE_OHM 0.466f
#define MOTOR_INDUCTANCE_H 4.8e-3f
#define MOTOR_FLUX_LINKAGE_WB 0.0928f
#define MOTOR_INERTIA_KGM2 8.0e-4f

/* Current loops: PI zero on the winding's pole R/L (97 rad/s), so the closed
 * loop is first order at w_c: kp = L w_c = 15.1 V/A, ki = R w_c = 1464 V/(A s).
 * w_c = 2 pi 500 Hz is 1/40 of the 20 kHz sampling (w_c T = 0.16 rad per
 * period) and 50 x the speed loop below. */
#define CURRENT_BANDWIDTH_RAD_S (TWO_PI * 500.0f)
#define CURRENT_KP_V_PER_A (MOTOR_INDUCTANCE_H * CURRENT_BANDWIDTH_RAD_S)
#define CURRENT_KI_V_PER_AS (MOTOR_RESISTANCE_OHM * CURRENT_BANDWIDTH_RAD_S)

/* Speed loop: with the current loop taken as ideal, the plant is 1/(J s); a PI
 * on torque with a closed-loop double pole at w_s = 2 pi 10 Hz: kp = 2 J w_s =
 * 0.1005 Nm/(rad/s), ki = J w_s^2 = 3.158 Nm/rad. */
#define SPEED_BANDWIDTH_RAD_S (TWO_PI * 10.0f)
#define SPEED_KP_NM_PER_RAD_S (2.0f * MOTOR_INERTIA_KGM2 * SPEED_BANDWIDTH_RAD_S)
#define SPEED_KI_NM_PER_RAD (MOTOR_INERTIA_KGM2 * SPEED_BANDWIDTH_RAD_S * SPEED_BANDWIDTH_RAD_S)

/* q-current limit 12 A: torque limit 1.5 p psi_m 12 A = 1.67 Nm (p = 1), well
 * under the 20 A trip with the current loop's overshoot. */
#define Q_CURRENT_LIMIT_A 12.0f
/* Overcurrent trip (SPEC.md 8.1's default; the board does not know
 * OVERCURRENT_A, `--overcurrent-a` in the arguments changes it). */
#define DEFAULT_OVERCURRENT_A 20.0f
/* Below this DC-link voltage the duties are meaningless: FAULT 3 DC_LINK. */
#define MIN_DC_LINK_V 5.0f

/* Encoder tracking loop: 2 pi 100 Hz, 10 x the speed loop; averages the
 * one-count-per-period quantisation (30.7 rad/s at 4096 counts, 50 us) to under
 * 1 rad/s. */
#define TRACKER_BANDWIDTH_RAD_S (TWO_PI * 100.0f)

/* Room for the largest burst one SAMPLE causes (DUTY, TELEMETRY, FAULT and
 * STATUS: under 150 wire bytes) and for PARAM_VALUEs the bench asks in a row. */
#define OUT_BYTES 1024u

/* ---- state: globals, as on a microcontroller ------------------------------ */

/* the pushed parameters (SPEC.md 8.1), with their SPEC defaults */
static float control_period_s = 50e-6f;
static float current_a_per_count = 0.01220703125f;
static float current_offset_counts = 2048.0f;
static uint32_t current_phases = 0u; /* 0: a,b  1: a,c  2: b,c */
static float vdc_v_per_count = 0.0244140625f;
static float vdc_offset_counts = 0.0f;
static uint32_t encoder_counts_per_rev = 4096u;
static uint32_t pole_pairs = 1u;
static uint32_t telemetry_divider = 10u;
/* from the arguments (hil_fw_configure) */
static float overcurrent_a = DEFAULT_OVERCURRENT_A;

/* the command */
static uint8_t enabled;
static uint8_t torque_mode;
static float speed_ref_rad_s;
static float torque_cmd_nm;

/* control */
static uint8_t state = HIL_STATE_IDLE; /* hil_state */
static uint16_t fault_code;
static uint8_t encoder_seen;
static uint16_t last_encoder;
static int32_t position_counts; /* 0 .. encoder_counts_per_rev - 1 */
static foc_tracker tracker;
static float speed_integral_nm;
static float d_integral_v;
static float q_integral_v;

/* the answer to the last SAMPLE, sent again for a resent one (SPEC.md 2.4) */
static uint8_t answered_any;
static uint32_t answered_period;
static hil_msg last_answer;

/* protocol */
static uint8_t powered_on;
static hil_decoder decoder;
static uint32_t version_errors_seen;
static uint8_t peer_version_bad;
static uint8_t tx_seq;
static uint32_t next_period;
static uint8_t shutdown_received;
static size_t out_len;
static uint8_t out[OUT_BYTES];

/* ---- output ---------------------------------------------------------------- */

static void emit(hil_msg *m)
{
    m->seq = tx_seq;
    int n = hil_frame_encode(m, out + out_len, OUT_BYTES - out_len);
    if (n < 0) {
        return; /* queue full: the bench's resend or watchdog sees the missing answer */
    }
    out_len += (size_t)n;
    tx_seq++;
}

static void emit_status(uint32_t period)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_STATUS;
    m.u.status.period = period;
    m.u.status.state = state;
    m.u.status.fault_code = fault_code;
    emit(&m);
}

static void emit_hello(void)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_HELLO;
    m.u.hello.proto_version = HIL_PROTO_VERSION;
    m.u.hello.role = HIL_ROLE_CONTROLLER;
    m.u.hello.capabilities = HIL_CAP_DUTY | HIL_CAP_TELEMETRY;
    m.u.hello.control_period_ns = 0u; /* any period: the loops use the pushed CONTROL_PERIOD_S */
    m.u.hello.name_len = (uint8_t)(sizeof fw_name - 1u);
    memcpy(m.u.hello.name, fw_name, sizeof fw_name - 1u);
    emit(&m);
}

/* Latches a fault: the bridge opens at once; FAULT, then STATUS (SPEC.md 2.5). */
static void trip(uint16_t code, float value, uint32_t period)
{
    if (state == HIL_STATE_FAULT) {
        return;
    }
    state = HIL_STATE_FAULT;
    fault_code = code;
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_FAULT;
    m.u.fault.period = period;
    m.u.fault.code = code;
    m.u.fault.value = value;
    emit(&m);
    emit_status(period);
}

/* ---- parameters (SPEC.md 8.1: the pushed ones only) ------------------------ */

static int is_whole(float v, float lo, float hi) { return v >= lo && v <= hi && v == floorf(v); }

/* The value in force of a known id; 0 (UNKNOWN) for any other. */
static uint8_t param_get(uint16_t id, float *value)
{
    switch (id) {
    case HIL_PARAM_CONTROL_PERIOD_S: *value = control_period_s; break;
    case HIL_PARAM_CURRENT_A_PER_COUNT: *value = current_a_per_count; break;
    case HIL_PARAM_CURRENT_OFFSET_COUNTS: *value = current_offset_counts; break;
    case HIL_PARAM_CURRENT_PHASES: *value = (float)current_phases; break;
    case HIL_PARAM_VDC_V_PER_COUNT: *value = vdc_v_per_count; break;
    case HIL_PARAM_VDC_OFFSET_COUNTS: *value = vdc_offset_counts; break;
    case HIL_PARAM_ENCODER_COUNTS_PER_REV: *value = (float)encoder_counts_per_rev; break;
    case HIL_PARAM_POLE_PAIRS: *value = (float)pole_pairs; break;
    case HIL_PARAM_TELEMETRY_DIVIDER: *value = (float)telemetry_divider; break;
    default:
        *value = 0.0f;
        return HIL_PARAM_UNKNOWN;
    }
    return HIL_PARAM_OK;
}

/* Applies a PARAM_SET: OK, UNKNOWN, or OUT_OF_RANGE keeping the old value.
 * Every range test fails for NaN. */
static uint8_t param_set(uint16_t id, float v)
{
    switch (id) {
    case HIL_PARAM_CONTROL_PERIOD_S:
        /* the 500 Hz current loop wants w_c T well under 1: at most 300 us (0.94 rad) */
        if (!(v >= 1e-6f && v <= 300e-6f)) return HIL_PARAM_OUT_OF_RANGE;
        control_period_s = v;
        break;
    case HIL_PARAM_CURRENT_A_PER_COUNT:
        if (!(v > 0.0f && v < 1.0f)) return HIL_PARAM_OUT_OF_RANGE;
        current_a_per_count = v;
        break;
    case HIL_PARAM_CURRENT_OFFSET_COUNTS:
        if (!(v >= 0.0f && v <= 4095.0f)) return HIL_PARAM_OUT_OF_RANGE;
        current_offset_counts = v;
        break;
    case HIL_PARAM_CURRENT_PHASES:
        if (!is_whole(v, 0.0f, 2.0f)) return HIL_PARAM_OUT_OF_RANGE;
        current_phases = (uint32_t)v;
        break;
    case HIL_PARAM_VDC_V_PER_COUNT:
        if (!(v > 0.0f && v < 10.0f)) return HIL_PARAM_OUT_OF_RANGE;
        vdc_v_per_count = v;
        break;
    case HIL_PARAM_VDC_OFFSET_COUNTS:
        if (!(v >= 0.0f && v <= 4095.0f)) return HIL_PARAM_OUT_OF_RANGE;
        vdc_offset_counts = v;
        break;
    case HIL_PARAM_ENCODER_COUNTS_PER_REV:
        /* a 16-bit counter must move less than half its range per period */
        if (!is_whole(v, 4.0f, 65536.0f)) return HIL_PARAM_OUT_OF_RANGE;
        encoder_counts_per_rev = (uint32_t)v;
        encoder_seen = 0u; /* re-read the absolute position */
        break;
    case HIL_PARAM_POLE_PAIRS:
        if (!is_whole(v, 1.0f, 64.0f)) return HIL_PARAM_OUT_OF_RANGE;
        pole_pairs = (uint32_t)v;
        break;
    case HIL_PARAM_TELEMETRY_DIVIDER:
        if (!is_whole(v, 0.0f, 65535.0f)) return HIL_PARAM_OUT_OF_RANGE;
        telemetry_divider = (uint32_t)v;
        break;
    default:
        return HIL_PARAM_UNKNOWN;
    }
    return HIL_PARAM_OK;
}

/* ---- one control period ----------------------------------------------------- */

/* Phase currents a, b from the two measured channels (the third is minus the
 * sum of the others: floating star point). */
static void phase_currents(const hil_sample *s, float *i_a, float *i_b)
{
    float i1 = ((float)s->adc_i1 - current_offset_counts) * current_a_per_count;
    float i2 = ((float)s->adc_i2 - current_offset_counts) * current_a_per_count;
    switch (current_phases) {
    case 1u: *i_a = i1; *i_b = -(i1 + i2); break; /* a, c */
    case 2u: *i_a = -(i1 + i2); *i_b = i1; break; /* b, c */
    default: *i_a = i1; *i_b = i2; break;         /* a, b */
    }
}

/* Mechanical angle from the counter: the absolute count on the first SAMPLE
 * (count 0 at theta_m = 0, SPEC.md 1.1), then signed 16-bit differences. */
static float mechanical_angle(uint16_t encoder)
{
    int32_t cpr = (int32_t)encoder_counts_per_rev;
    if (!encoder_seen) {
        position_counts = (int32_t)(encoder % encoder_counts_per_rev);
        encoder_seen = 1u;
    } else {
        position_counts += (int16_t)(uint16_t)(encoder - last_encoder);
        position_counts %= cpr;
        if (position_counts < 0) {
            position_counts += cpr;
        }
    }
    last_encoder = encoder;
    /* the middle of the count: the rotor lies somewhere in [count, count + 1) */
    return TWO_PI * ((float)position_counts + 0.5f) / (float)cpr;
}

typedef struct {
    float torque_ref_nm;
    float torque_est_nm;
    uint16_t duty[3];
} control_out;

/* Speed PI -> q-current reference; d/q current PIs with decoupling; voltage
 * limited to the linear range vdc/sqrt3; duties by space-vector PWM. */
static control_out field_oriented_step(float i_a, float i_b, float vdc_v, float theta_e, float dt)
{
    control_out o;
    const float torque_per_amp = 1.5f * (float)pole_pairs * MOTOR_FLUX_LINKAGE_WB;
    const float omega_e = (float)pole_pairs * tracker.speed_rad_s;
    const foc_pi_gains speed_gains = {SPEED_KP_NM_PER_RAD_S, SPEED_KI_NM_PER_RAD, Q_CURRENT_LIMIT_A * torque_per_amp};
    if (torque_mode) {
        float limit = speed_gains.limit;
        o.torque_ref_nm = fminf(fmaxf(torque_cmd_nm, -limit), limit);
    } else {
        o.torque_ref_nm = foc_pi_step(&speed_gains, &speed_integral_nm, speed_ref_rad_s - tracker.speed_rad_s, 0.0f, dt);
    }
    float i_alpha, i_beta, i_d, i_q;
    foc_clarke(i_a, i_b, &i_alpha, &i_beta);
    foc_park(i_alpha, i_beta, sinf(theta_e), cosf(theta_e), &i_d, &i_q);
    o.torque_est_nm = torque_per_amp * i_q;

    const float v_max = vdc_v / 1.73205080756888f;
    const foc_pi_gains current_gains = {CURRENT_KP_V_PER_A, CURRENT_KI_V_PER_AS, v_max};
    float i_q_ref = o.torque_ref_nm / torque_per_amp;
    /* decoupling feedforward: the back-EMF and the cross-coupling of the rotating frame */
    float ff_d = -omega_e * MOTOR_INDUCTANCE_H * i_q;
    float ff_q = omega_e * (MOTOR_INDUCTANCE_H * i_d + MOTOR_FLUX_LINKAGE_WB);
    float v_d = foc_pi_step(&current_gains, &d_integral_v, 0.0f - i_d, ff_d, dt);
    float v_q = foc_pi_step(&current_gains, &q_integral_v, i_q_ref - i_q, ff_q, dt);
    (void)foc_limit_vector(&v_d, &v_q, v_max);

    /* the duties act over the whole next period: rotate by half a period's travel */
    float theta_mid = theta_e + 0.5f * omega_e * dt;
    float v_alpha, v_beta;
    foc_inverse_park(v_d, v_q, sinf(theta_mid), cosf(theta_mid), &v_alpha, &v_beta);
    foc_duties(v_alpha, v_beta, vdc_v, o.duty);
    return o;
}

static void emit_telemetry(uint32_t period, const control_out *o)
{
    const float nan = NAN; /* SPEC.md 2.4: what this board does not compute */
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_TELEMETRY;
    hil_telemetry *t = &m.u.telemetry;
    t->period = period;
    t->sector = 0u;
    t->speed_source = HIL_SPEED_ENCODER;
    t->state = state;
    t->gates = 0u; /* a DUTY board */
    t->speed_feedback_rad_s = tracker.speed_rad_s;
    t->speed_encoder_rad_s = tracker.speed_rad_s;
    t->speed_raw_rad_s = nan;
    t->speed_lpf_rad_s = nan;
    t->speed_ekf_rad_s = nan;
    t->flux_angle_rad = nan;
    t->ekf_angle_rad = nan;
    t->flux_mag_wb = nan;
    t->torque_est_nm = o->torque_est_nm;
    t->torque_ref_nm = o->torque_ref_nm;
    t->rotor_pos_conv_rad = nan;
    t->rotor_pos_ekf_rad = nan;
    emit(&m);
}

static void on_sample(const hil_sample *s)
{
    if (answered_any && s->period == answered_period) {
        emit(&last_answer); /* a resent SAMPLE: the same answer, no second control step */
        return;
    }
    const float dt = control_period_s;
    next_period = s->period + 1u;
    float i_a, i_b;
    phase_currents(s, &i_a, &i_b);
    float vdc_v = ((float)s->adc_vdc - vdc_offset_counts) * vdc_v_per_count;
    float theta_m = mechanical_angle(s->encoder);
    foc_tracker_step(&tracker, foc_wrap_pi(theta_m), TRACKER_BANDWIDTH_RAD_S, dt);
    float theta_e = (float)pole_pairs * theta_m;

    if (state == HIL_STATE_RUNNING) {
        float i_c = -(i_a + i_b);
        float i_peak = fmaxf(fabsf(i_a), fmaxf(fabsf(i_b), fabsf(i_c)));
        if ((s->status & HIL_STATUS_OVERCURRENT) != 0u || !(i_peak <= overcurrent_a)) {
            trip(HIL_FAULT_OVERCURRENT, i_peak, s->period); /* NaN trips too */
        } else if (!(vdc_v >= MIN_DC_LINK_V)) {
            trip(HIL_FAULT_DC_LINK, vdc_v, s->period);
        }
    }
    control_out o = {0.0f, 0.0f, {0u, 0u, 0u}};
    hil_msg answer;
    memset(&answer, 0, sizeof answer);
    if (state == HIL_STATE_RUNNING) {
        o = field_oriented_step(i_a, i_b, vdc_v, theta_e, dt);
        answer.type = HIL_MSG_DUTY;
        answer.u.duty.period = s->period;
        memcpy(answer.u.duty.duty, o.duty, sizeof o.duty);
    } else {
        /* DUTY cannot open a leg; GATES 0 lets the motor coast (SPEC.md 2.8.4:
         * the other answer type is accepted and logged once) */
        answer.type = HIL_MSG_GATES;
        answer.u.gates.period = s->period;
        answer.u.gates.gates = 0u;
    }
    last_answer = answer;
    answered_period = s->period;
    answered_any = 1u;
    emit(&answer);
    if (telemetry_divider != 0u && s->period % telemetry_divider == 0u) {
        emit_telemetry(s->period, &o);
    }
}

/* COMMAND applies from the next SAMPLE on. Torque mode is followed (the
 * torque reference, clamped to the q-current limit); a speed source other than
 * the encoder is refused with FAULT 5 PROTOCOL (this board has no estimator);
 * the flux reference is ignored (no field weakening: i_d = 0). */
static void on_command(const hil_command *c)
{
    uint8_t before = state;
    uint8_t enable = (c->flags & HIL_CMD_ENABLE) != 0u;
    torque_mode = (c->flags & HIL_CMD_TORQUE_MODE) != 0u;
    speed_ref_rad_s = c->speed_ref_rad_s;
    torque_cmd_nm = c->torque_ref_nm;
    if (c->speed_source != HIL_SPEED_ENCODER) {
        trip(HIL_FAULT_PROTOCOL, (float)c->speed_source, next_period);
        return;
    }
    if (!(isfinite(speed_ref_rad_s) && isfinite(torque_cmd_nm))) {
        trip(HIL_FAULT_PROTOCOL, speed_ref_rad_s, next_period);
        return;
    }
    if (!enable) {
        state = HIL_STATE_IDLE; /* disabling clears a latched fault (SPEC.md 2.5) */
        fault_code = HIL_FAULT_NONE;
    } else if (state == HIL_STATE_IDLE) {
        state = HIL_STATE_RUNNING;
        speed_integral_nm = 0.0f;
        d_integral_v = 0.0f;
        q_integral_v = 0.0f;
    }
    enabled = enable;
    if (state != before) {
        emit_status(next_period);
    }
}

static void answer_param(uint16_t id, uint8_t status)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_PARAM_VALUE;
    m.u.param_value.id = id;
    float value;
    uint8_t known = param_get(id, &value);
    m.u.param_value.status = status;
    m.u.param_value.value = known == HIL_PARAM_OK ? value : 0.0f;
    emit(&m);
}

static void dispatch(const hil_msg *in)
{
    if (in->type == HIL_MSG_HELLO) {
        /* answer every HELLO; after one of another version, only HELLO (SPEC.md 2.1) */
        peer_version_bad = in->u.hello.proto_version != HIL_PROTO_VERSION;
        emit_hello();
        return;
    }
    if (peer_version_bad) {
        return;
    }
    float unused;
    switch (in->type) {
    case HIL_MSG_SAMPLE: on_sample(&in->u.sample); break;
    case HIL_MSG_COMMAND: on_command(&in->u.command); break;
    case HIL_MSG_PARAM_SET: answer_param(in->u.param_set.id, param_set(in->u.param_set.id, in->u.param_set.value)); break;
    case HIL_MSG_PARAM_GET: answer_param(in->u.param_get.id, param_get(in->u.param_get.id, &unused)); break;
    case HIL_MSG_SHUTDOWN:
        shutdown_received = 1u;
        enabled = 0u;
        if (state != HIL_STATE_IDLE) {
            state = HIL_STATE_IDLE;
            fault_code = HIL_FAULT_NONE;
            emit_status(next_period);
        }
        break;
    default:
        break; /* HEARTBEAT (this board has no clock to send its own) and controller-to-bench types */
    }
}

/* ---- arguments ---------------------------------------------------------------- */

/* A decimal number ("20", "7.5", "-0.25"); 0 when the text is not one. No
 * strtof: no locale, nothing of the C library's I/O in the firmware. */
static int parse_decimal(const char *text, float *value)
{
    float sign = 1.0f, v = 0.0f, scale = 1.0f;
    int digits = 0, fraction = 0;
    if (*text == '-' || *text == '+') {
        sign = *text == '-' ? -1.0f : 1.0f;
        ++text;
    }
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
    *value = sign * v / scale;
    return digits > 0;
}

static void copy_reason(char *why, size_t why_cap, const char *reason, const char *arg)
{
    size_t n = 0;
    for (const char *p = reason; *p != '\0' && n + 1u < why_cap; ++p) why[n++] = *p;
    for (const char *p = arg; arg != NULL && *p != '\0' && n + 1u < why_cap; ++p) why[n++] = *p;
    why[n] = '\0';
}

/* --overcurrent-a A: the phase-current trip level, 0 < A <= 50. */
static int configure(int argc, const char *const *argv, char *why, size_t why_cap)
{
    for (int k = 0; k < argc; ++k) {
        if (strcmp(argv[k], "--overcurrent-a") == 0 && k + 1 < argc) {
            float v;
            if (!parse_decimal(argv[k + 1], &v) || !(v > 0.0f && v <= 50.0f)) {
                copy_reason(why, why_cap, "--overcurrent-a wants a current in A, 0 < A <= 50; got ", argv[k + 1]);
                return 2;
            }
            overcurrent_a = v;
            ++k;
        } else {
            copy_reason(why, why_cap, "unknown argument (known: --overcurrent-a A): ", argv[k]);
            return 1;
        }
    }
    return 0;
}

/* ---- the ABI (hil_fw_abi.h) ----------------------------------------------------- */

uint32_t hil_fw_abi_version(void) { return HIL_FW_ABI_VERSION; }

const char *hil_fw_name(void) { return fw_name; }

size_t hil_fw_instance_size(void) { return 0u; /* all state is static */ }

void *hil_fw_create(void *mem, size_t mem_size)
{
    (void)mem;
    (void)mem_size;
    if (powered_on) {
        return NULL; /* one boot per load: the globals are not re-initialised */
    }
    powered_on = 1u;
    hil_decoder_init(&decoder);
    return &powered_on;
}

int hil_fw_configure(void *fw, int argc, const char *const *argv, char *why, size_t why_cap)
{
    (void)fw;
    return configure(argc, argv, why, why_cap);
}

size_t hil_fw_exchange(void *fw, const uint8_t *rx, size_t rx_len, uint8_t *tx, size_t tx_cap)
{
    (void)fw;
    hil_msg in;
    size_t i = 0;
    while (i < rx_len) {
        int got = 0;
        i += hil_decoder_feed_buf(&decoder, rx + i, rx_len - i, &in, &got);
        if (got) {
            dispatch(&in);
        }
        if (decoder.version_errors != version_errors_seen) {
            version_errors_seen = decoder.version_errors; /* say which version we speak */
            emit_hello();
        }
    }
    size_t n = out_len < tx_cap ? out_len : tx_cap;
    if (n > 0u) {
        memcpy(tx, out, n);
        memmove(out, out + n, out_len - n);
        out_len -= n;
    }
    return n;
}

int hil_fw_shutdown_requested(const void *fw)
{
    (void)fw;
    return shutdown_received;
}

void hil_fw_destroy(void *fw) { (void)fw; /* power off: nothing to release */ }
