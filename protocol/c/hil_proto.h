/*
 * hil-bench wire protocol, C99 codec for firmware and host.
 *
 * This header is the contract between the bench and a controller board; the
 * normative description is protocol/SPEC.md. No malloc, no stdio: every buffer
 * is owned by the caller. All multi-byte fields are little-endian on the wire.
 */
#ifndef HIL_PROTO_H
#define HIL_PROTO_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define HIL_PROTO_VERSION 1u

/* Serial frame: COBS( header | payload | crc16 ) 0x00
 * header = version u8, type u8, seq u8, payload_len u8
 * crc16  = CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection,
 *          no final xor) over header and payload, little-endian on the wire. */
#define HIL_HEADER_SIZE 4u
#define HIL_CRC_SIZE 2u
#define HIL_MAX_PAYLOAD 64u
#define HIL_MAX_RAW_FRAME (HIL_HEADER_SIZE + HIL_MAX_PAYLOAD + HIL_CRC_SIZE)
/* COBS adds one byte per 254 (and at least one), plus the 0x00 delimiter. */
#define HIL_MAX_ENCODED_FRAME (HIL_MAX_RAW_FRAME + (HIL_MAX_RAW_FRAME / 254u) + 1u + 1u)
#define HIL_NAME_MAX 40u

typedef enum {
    HIL_MSG_HELLO = 0x01,       /* both ways */
    HIL_MSG_SAMPLE = 0x02,      /* plant -> controller, once per period */
    HIL_MSG_GATES = 0x03,       /* controller -> plant, six switch states */
    HIL_MSG_DUTY = 0x04,        /* controller -> plant, three PWM duty cycles */
    HIL_MSG_COMMAND = 0x05,     /* bench -> controller */
    HIL_MSG_TELEMETRY = 0x06,   /* controller -> bench */
    HIL_MSG_PARAM_SET = 0x07,   /* bench -> controller */
    HIL_MSG_PARAM_GET = 0x08,   /* bench -> controller */
    HIL_MSG_PARAM_VALUE = 0x09, /* controller -> bench, answers SET and GET */
    HIL_MSG_STATUS = 0x0A,      /* controller -> bench */
    HIL_MSG_FAULT = 0x0B,       /* controller -> bench */
    HIL_MSG_HEARTBEAT = 0x0C,   /* both ways */
    HIL_MSG_SHUTDOWN = 0x0D,    /* bench -> controller: stop switching and exit */
    /* 0x0E is not defined (the vector files use it as the unknown type) */
    HIL_MSG_DUTY_LEGS = 0x0F,   /* controller -> plant, DUTY with a per-leg enable */
    HIL_MSG_SAMPLE_SENSORS = 0x10 /* plant -> controller with HIL_CAP_SENSOR_SET, instead of SAMPLE */
} hil_msg_type;
#define HIL_MSG_TYPE_MAX 0x10u /* the highest type code defined in this version */

typedef enum { HIL_ROLE_BENCH = 0, HIL_ROLE_CONTROLLER = 1 } hil_role;

/* HELLO capability bits */
#define HIL_CAP_GATES 0x0001u     /* answers SAMPLE with GATES */
#define HIL_CAP_DUTY 0x0002u      /* answers SAMPLE with DUTY */
#define HIL_CAP_TELEMETRY 0x0004u /* sends TELEMETRY */
#define HIL_CAP_CAN 0x0008u       /* reachable over the CAN mapping */
#define HIL_CAP_DUTY_LEGS 0x0010u /* answers SAMPLE with DUTY_LEGS */
#define HIL_CAP_SENSOR_SET 0x0020u /* reads SAMPLE_SENSORS; its sensor set is parameter SENSOR_SET */

/* SAMPLE_SENSORS sensor-set bits: the fields of each set bit follow the fixed part in bit
 * order (SPEC.md 6.13, 9.8); bits 10-15 reserved (a frame with one is a length error) */
#define HIL_SENSOR_CURRENT_A 0x0001u         /* adc_ia u16 */
#define HIL_SENSOR_CURRENT_B 0x0002u         /* adc_ib u16 */
#define HIL_SENSOR_CURRENT_C 0x0004u         /* adc_ic u16 */
#define HIL_SENSOR_VDC 0x0008u               /* adc_vdc u16 */
#define HIL_SENSOR_ENCODER 0x0010u           /* encoder u16 */
#define HIL_SENSOR_HALL 0x0020u              /* hall u8 */
#define HIL_SENSOR_TERMINAL_VOLTAGES 0x0040u /* adc_va, adc_vb, adc_vc u16 */
#define HIL_SENSOR_BEMF_COMPARATORS 0x0080u  /* bemf_comparators u8 */
#define HIL_SENSOR_RESOLVER 0x0100u          /* adc_resolver_sin, adc_resolver_cos u16 */
#define HIL_SENSOR_TEMPERATURE 0x0200u       /* adc_temperature u16 */
#define HIL_SENSOR_SET_ALL 0x03FFu
#define HIL_SAMPLE_SENSORS_FIXED_SIZE 7u /* period u32, sensor_set u16, status u8 */
#define HIL_SAMPLE_SENSORS_MAX_SIZE 31u  /* every bit set */

/* DUTY_LEGS leg_enable bits: 1 = the leg switches (complementary PWM as in DUTY), 0 = floated
 * (both switches off: the phase current free-wheels through the diodes); bits 3-7 reserved (0) */
#define HIL_LEG_A 0x01u
#define HIL_LEG_B 0x02u
#define HIL_LEG_C 0x04u
#define HIL_LEGS_ALL 0x07u

/* GATES bits: 1 = switch on */
#define HIL_GATE_A_HIGH 0x01u
#define HIL_GATE_A_LOW 0x02u
#define HIL_GATE_B_HIGH 0x04u
#define HIL_GATE_B_LOW 0x08u
#define HIL_GATE_C_HIGH 0x10u
#define HIL_GATE_C_LOW 0x20u

/* SAMPLE status bits */
#define HIL_STATUS_INDEX_PULSE 0x01u /* encoder index seen during the last period */
#define HIL_STATUS_OVERCURRENT 0x02u /* plant's hardware overcurrent comparator */
#define HIL_STATUS_OVERVOLTAGE 0x04u /* DC-link overvoltage comparator */
#define HIL_STATUS_GATE_FAULT 0x08u  /* gate driver desaturation/fault line */

/* COMMAND flags and speed sources */
#define HIL_CMD_ENABLE 0x01u
#define HIL_CMD_TORQUE_MODE 0x02u /* speed loop bypassed: torque_ref_nm used directly */
typedef enum {
    HIL_SPEED_ENCODER = 0,
    HIL_SPEED_CONVENTIONAL = 1, /* eq. (10)-(11) with low-pass filter */
    HIL_SPEED_EKF = 2           /* eq. (16)-(23) */
} hil_speed_source;

/* Controller states (STATUS.state, SPEC.md 9.4): STARTING = enabled, start-up phase
 * (alignment, calibration) not done; RUNNING = controlling, ready */
typedef enum { HIL_STATE_IDLE = 0, HIL_STATE_RUNNING = 1, HIL_STATE_FAULT = 2, HIL_STATE_STARTING = 3 } hil_state;

/* FAULT codes */
typedef enum {
    HIL_FAULT_NONE = 0,
    HIL_FAULT_OVERCURRENT = 1,
    HIL_FAULT_ENCODER_LOSS = 2,
    HIL_FAULT_DC_LINK = 3,
    HIL_FAULT_WATCHDOG = 4,
    HIL_FAULT_PROTOCOL = 5,
    HIL_FAULT_NON_FINITE = 6,
    HIL_FAULT_STALL = 7 /* no commutation event under torque demand: locked rotor, lost synchronisation */
} hil_fault_code;
/* FAULT NON_FINITE: the quantity that was NaN or infinite, as the FAULT's value (SPEC.md 9.6) */
typedef enum {
    HIL_NONFINITE_OTHER = 0,
    HIL_NONFINITE_PHASE_CURRENT = 1,
    HIL_NONFINITE_DC_LINK_VOLTAGE = 2,
    HIL_NONFINITE_MEASURED_SPEED = 3,
    HIL_NONFINITE_FLUX_ESTIMATE = 4,
    HIL_NONFINITE_SPEED_ESTIMATE = 5,
    HIL_NONFINITE_TORQUE_REFERENCE = 6,
    HIL_NONFINITE_VOLTAGE_REFERENCE = 7,
    HIL_NONFINITE_COMMAND = 8
} hil_nonfinite_quantity;

/* PARAM_VALUE status */
typedef enum { HIL_PARAM_OK = 0, HIL_PARAM_UNKNOWN = 1, HIL_PARAM_OUT_OF_RANGE = 2, HIL_PARAM_READ_ONLY = 3 } hil_param_status;

/* Parameter identifiers (PARAM_SET / PARAM_GET / PARAM_VALUE). Values are float32 in SI units. */
typedef enum {
    HIL_PARAM_CONTROL_PERIOD_S = 1,
    HIL_PARAM_CURRENT_A_PER_COUNT = 2,
    HIL_PARAM_CURRENT_OFFSET_COUNTS = 3,
    HIL_PARAM_VDC_V_PER_COUNT = 4,
    HIL_PARAM_VDC_OFFSET_COUNTS = 5,
    HIL_PARAM_ENCODER_COUNTS_PER_REV = 6,
    HIL_PARAM_CURRENT_PHASES = 7, /* 0: a,b  1: a,c  2: b,c */
    HIL_PARAM_SENSOR_SET = 8,     /* read-only: the board's SAMPLE_SENSORS set (HIL_SENSOR_* bits) */
    HIL_PARAM_POLE_PAIRS = 10,
    HIL_PARAM_STATOR_RESISTANCE_OHM = 11,
    HIL_PARAM_STATOR_INDUCTANCE_H = 12,
    HIL_PARAM_MAGNET_FLUX_WB = 13,
    HIL_PARAM_TERMINAL_V_PER_COUNT = 14,       /* phase terminal volts per count, divider included */
    HIL_PARAM_RESOLVER_POLE_PAIRS = 15,        /* resolver electrical turns per mechanical turn */
    HIL_PARAM_RESOLVER_OFFSET_COUNTS = 16,     /* resolver sin/cos count at zero signal */
    HIL_PARAM_TEMPERATURE_DEGC_PER_COUNT = 17,
    HIL_PARAM_TEMPERATURE_OFFSET_COUNTS = 18,  /* temperature count at 0 degC */
    HIL_PARAM_FLUX_REF_WB = 20,
    HIL_PARAM_FLUX_BAND_WB = 21,
    HIL_PARAM_TORQUE_BAND_NM = 22,
    HIL_PARAM_TORQUE_LIMIT_NM = 23,
    HIL_PARAM_SPEED_KP_NM_PER_RAD_S = 24,
    HIL_PARAM_SPEED_KI_NM_PER_RAD = 25,
    HIL_PARAM_SPEED_LPF_CUTOFF_HZ = 26,
    HIL_PARAM_EKF_K1 = 30,
    HIL_PARAM_EKF_K2 = 31,
    HIL_PARAM_EKF_K3 = 32,
    HIL_PARAM_FLUX_DRIFT_CUTOFF_HZ = 33,
    HIL_PARAM_TELEMETRY_DIVIDER = 40,
    HIL_PARAM_OVERCURRENT_A = 41,
    HIL_PARAM_ENCODER_LOSS_TIMEOUT_S = 42,
    HIL_PARAM_STALL_TIMEOUT_S = 43,     /* no commutation event under torque demand for this long trips FAULT STALL */
    HIL_PARAM_CONTROL_STEP_CYCLES = 50, /* read-only: cycles of the last control step on target (SysTick) */
    HIL_PARAM_CONTROL_LAW = 60,         /* 0: DTC (the paper's, answers GATES), 1: FOC (answers DUTY) */
    HIL_PARAM_CURRENT_BANDWIDTH_HZ = 61, /* FOC d-q current loop bandwidth */
    HIL_PARAM_FOC_ANGLE_SOURCE = 62,    /* FOC rotor angle: 0 encoder, 1 EKF (eq. (21) minus eq. (25)) */
    HIL_PARAM_DEAD_TIME_COMP_S = 63,    /* dead-time compensation by current sign (FOC duties, DTC observer voltage), 0 = off */
    HIL_PARAM_DEVICE_DROP_COMP_V = 64,  /* DTC: device drop compensated in the observer voltage, 0 = off */
    HIL_PARAM_DELAY_COMP_PERIODS = 65,  /* DTC: 1 = answers act one period late; integrate what acted, predict one period */
    HIL_PARAM_CURRENT_ZERO_CAL_PERIODS = 66, /* at each enable, periods with the bridge off to measure the current ADCs' zero, 0 = off */
    HIL_PARAM_RS_ID_PERIODS = 67 /* start-up stator-resistance identification at standstill, periods per current level, 0 = off */
} hil_param_id;

typedef struct {
    uint8_t proto_version;
    uint8_t role;          /* hil_role */
    uint16_t capabilities; /* HIL_CAP_* */
    uint32_t control_period_ns;
    uint8_t name_len; /* <= HIL_NAME_MAX */
    char name[HIL_NAME_MAX]; /* not NUL-terminated on the wire */
} hil_hello;

typedef struct {
    uint32_t period;   /* period index k: sensors sampled at t = k * T */
    uint16_t adc_i1;   /* first measured phase current, 12-bit ADC counts */
    uint16_t adc_i2;   /* second measured phase current, 12-bit ADC counts */
    uint16_t adc_vdc;  /* DC-link voltage, 12-bit ADC counts */
    uint16_t encoder;  /* quadrature counter, wraps at 65536 */
    uint8_t status;    /* HIL_STATUS_* (4 bits used) */
} hil_sample;

/* SAMPLE_SENSORS: only the fields of set sensor_set bits travel; the decoder sets the others
 * to 0, the encoder ignores them. Counts are u16 (ADCs up to 16 bits). */
typedef struct {
    uint32_t period;     /* period index k: sensors sampled at t = k * T */
    uint16_t sensor_set; /* HIL_SENSOR_* bits */
    uint8_t status;      /* HIL_STATUS_* (bits 0-3; 4-7 reserved) */
    uint16_t adc_ia;     /* phase-a current, ADC counts */
    uint16_t adc_ib;
    uint16_t adc_ic;
    uint16_t adc_vdc;    /* DC-link voltage, ADC counts */
    uint16_t encoder;    /* quadrature counter, wraps at 65536 */
    uint8_t hall;        /* bit 0 Hall A, bit 1 B, bit 2 C; 3-7 reserved */
    uint16_t adc_va;     /* phase-a terminal voltage to DC-, ADC counts */
    uint16_t adc_vb;
    uint16_t adc_vc;
    uint8_t bemf_comparators; /* bit x: phase x terminal above the virtual neutral; 3-7 reserved */
    uint16_t adc_resolver_sin;
    uint16_t adc_resolver_cos;
    uint16_t adc_temperature; /* winding temperature, ADC counts */
} hil_sample_sensors;

typedef struct {
    uint32_t period; /* the SAMPLE period this answers */
    uint8_t gates;   /* HIL_GATE_* */
} hil_gates;

typedef struct {
    uint32_t period;
    uint16_t duty[3]; /* high-side on-time per centre-aligned PWM period, 0..65535 = 0..1 */
} hil_duty;

typedef struct {
    uint32_t period;
    uint16_t duty[3];   /* as hil_duty, for the enabled legs */
    uint8_t leg_enable; /* HIL_LEG_*: a leg whose bit is 0 is floated */
} hil_duty_legs;

typedef struct {
    uint8_t flags;        /* HIL_CMD_* */
    uint8_t speed_source; /* hil_speed_source */
    float speed_ref_rad_s; /* mechanical */
    float torque_ref_nm;   /* used in torque mode */
    float flux_ref_wb;     /* stator flux magnitude reference */
} hil_command;

typedef struct {
    uint32_t period;
    uint8_t sector;       /* 1..6, 0 when not switching */
    uint8_t speed_source; /* the one the speed loop uses */
    uint8_t state;        /* hil_state */
    uint8_t gates;        /* gates chosen this period */
    float speed_feedback_rad_s; /* mechanical, the value the speed loop used */
    float speed_encoder_rad_s;
    float speed_raw_rad_s;      /* eq. (11), unfiltered */
    float speed_lpf_rad_s;      /* eq. (11) through the low-pass filter */
    float speed_ekf_rad_s;      /* eq. (22) */
    float flux_angle_rad;       /* eq. (10) */
    float ekf_angle_rad;        /* eq. (21) */
    float flux_mag_wb;          /* eq. (5) */
    float torque_est_nm;        /* eq. (6) */
    float torque_ref_nm;        /* speed regulator output */
    float rotor_pos_conv_rad;   /* eq. (26) with the eq. (10) angle */
    float rotor_pos_ekf_rad;    /* eq. (26) with the eq. (21) angle */
} hil_telemetry;

typedef struct {
    uint16_t id;
    float value;
} hil_param_set;

typedef struct {
    uint16_t id;
} hil_param_get;

typedef struct {
    uint16_t id;
    uint8_t status; /* hil_param_status */
    float value;
} hil_param_value;

typedef struct {
    uint32_t period;
    uint8_t state;        /* hil_state */
    uint16_t fault_code;  /* hil_fault_code latched, 0 when none */
} hil_status;

typedef struct {
    uint32_t period;
    uint16_t code; /* hil_fault_code */
    float value;   /* the measured value that tripped, in SI units */
} hil_fault;

typedef struct {
    uint32_t counter;
} hil_heartbeat;

typedef struct {
    uint8_t type; /* hil_msg_type */
    uint8_t seq;  /* sender's frame counter; set by the caller, checked by the decoder */
    union {
        hil_hello hello;
        hil_sample sample;
        hil_gates gates;
        hil_duty duty;
        hil_command command;
        hil_telemetry telemetry;
        hil_param_set param_set;
        hil_param_get param_get;
        hil_param_value param_value;
        hil_status status;
        hil_fault fault;
        hil_heartbeat heartbeat;
        hil_duty_legs duty_legs;
        hil_sample_sensors sample_sensors;
    } u;
} hil_msg;

typedef enum {
    HIL_OK = 0,
    HIL_ERR_LENGTH = -1,       /* payload length wrong for the type */
    HIL_ERR_UNKNOWN_TYPE = -2, /* type code not in this version */
    HIL_ERR_VERSION = -3,      /* frame from another protocol version */
    HIL_ERR_RANGE = -4,        /* field out of range (name_len > 40, SAMPLE count > 4095, bad CAN role/base,
                                * DUTY_LEGS reserved leg bits on CAN, SAMPLE_SENSORS reserved set, status,
                                * hall or comparator bits) */
    HIL_ERR_BUFFER = -5        /* caller's buffer too small */
} hil_result;

/* CRC-16/CCITT-FALSE */
uint16_t hil_crc16(const uint8_t *data, size_t len);

/* Payload only (no header, no CRC). Returns the payload length, or a negative hil_result. */
int hil_payload_encode(const hil_msg *msg, uint8_t *out, size_t cap);
/* Decodes a payload of a given type into *msg (msg->type is set, msg->seq untouched). */
int hil_payload_decode(uint8_t type, const uint8_t *payload, size_t len, hil_msg *msg);

/* Whole serial frame, COBS-encoded with its trailing 0x00 delimiter.
 * Returns the number of bytes written, or a negative hil_result. */
int hil_frame_encode(const hil_msg *msg, uint8_t *out, size_t cap);

/* Byte-at-a-time stream decoder. Resynchronises at the next 0x00 after garbage;
 * counts errors instead of failing. COBS is undone as the bytes arrive, so the
 * buffer holds the decoded frame only. */
#define HIL_MAX_ENCODED_SEGMENT (HIL_MAX_ENCODED_FRAME - 1u) /* bytes between two delimiters */
typedef struct {
    uint8_t buf[HIL_MAX_RAW_FRAME]; /* decoded bytes of the current frame */
    size_t len;                     /* decoded bytes in buf */
    size_t encoded_len;             /* encoded bytes since the last delimiter */
    uint8_t cobs_left;              /* data bytes left in the current COBS block */
    uint8_t cobs_zero;              /* the current block ends in an implied zero */
    uint8_t overflow; /* the current frame outgrew the limit: discard up to the next delimiter */
    uint8_t have_seq;
    uint8_t last_seq;
    uint8_t last_bad_version; /* header version of the last frame rejected for its version */
    uint32_t frames_ok;
    uint32_t crc_errors;
    uint32_t framing_errors;  /* bad COBS, too long, too short, length field mismatch */
    uint32_t seq_gaps;        /* frames missing according to seq, summed */
    uint32_t unknown_types;
    uint32_t version_errors;
    uint32_t length_errors;   /* known type, payload length wrong */
} hil_decoder;

void hil_decoder_init(hil_decoder *dec);
/* Feeds one byte. Returns 1 and fills *out when the byte completes a valid frame, else 0. */
int hil_decoder_feed(hil_decoder *dec, uint8_t byte, hil_msg *out);
/* Same decoder, a buffer at a time (fewer instructions per byte, e.g. from a UART DMA buffer).
 * Consumes bytes up to and including the first one that completes a valid frame, or all of
 * them. Returns the number of bytes consumed; *got is 1 when *out was filled, else 0. Call
 * again with the rest of the buffer until it is consumed. */
size_t hil_decoder_feed_buf(hil_decoder *dec, const uint8_t *data, size_t len, hil_msg *out, int *got);

/* CAN mapping (classic CAN, 11-bit identifiers):
 * id = base_id + 0x20 * sender_role + type. SAMPLE, GATES, DUTY and DUTY_LEGS fit one
 * 8-byte frame; longer messages (HELLO, COMMAND, TELEMETRY, FAULT, SAMPLE_SENSORS) are split
 * over numbered frames (SPEC.md). */
#define HIL_CAN_DEFAULT_BASE_ID 0x100u
#define HIL_CAN_MAX_FRAMES 16u
typedef struct {
    uint16_t id;
    uint8_t dlc;
    uint8_t data[8];
} hil_can_frame;

/* Returns the number of frames written, or a negative hil_result. msg->seq & 0x0F
 * numbers multi-frame messages (the segmentation header). */
int hil_can_pack(const hil_msg *msg, uint8_t sender_role, uint16_t base_id, hil_can_frame *frames,
                 size_t max_frames);

/* Reassembly state of one sender role's multi-frame message. */
typedef struct {
    uint8_t type;       /* message being reassembled, 0 when none */
    uint8_t counter;    /* message counter from the segmentation header */
    uint8_t next_index; /* index the next frame must carry */
    uint8_t len;        /* payload bytes received so far */
    uint8_t skip_type;  /* the rest of this abandoned message is dropped uncounted, 0 when none */
    uint8_t skip_counter;
    uint8_t buf[HIL_MAX_PAYLOAD];
} hil_can_slot;

#define HIL_CAN_ROLES 2u
#define HIL_CAN_ID_SPAN 0x40u /* ids base_id .. base_id + 0x3F belong to the protocol */

typedef struct {
    uint16_t base_id;
    hil_can_slot slot[HIL_CAN_ROLES]; /* one per sender role: their frames may interleave */
    uint32_t last_period;  /* reference for extending truncated period fields, see SPEC.md */
    uint8_t have_period;
    uint32_t messages_ok;
    uint32_t sequence_errors; /* multi-frame messages lost to a missing or out-of-order frame */
    uint32_t unknown_types;
    uint32_t length_errors;   /* frames or messages of the wrong length */
    uint32_t ignored_frames;  /* identifiers outside base_id .. base_id + 0x3F */
} hil_can_rx;

void hil_can_rx_init(hil_can_rx *rx, uint16_t base_id);
/* Standard data frames only: the caller drops extended, remote and error frames (and, if it
 * wishes, frames of its own role) before feeding.
 * Returns 1 and fills *out (and *sender_role if not NULL) when a frame completes a message, else 0.
 * out->seq is the segmentation counter of a multi-frame message, 0 for a single frame. */
int hil_can_rx_feed(hil_can_rx *rx, const hil_can_frame *frame, hil_msg *out, uint8_t *sender_role);

#ifdef __cplusplus
}
#endif

#endif /* HIL_PROTO_H */
