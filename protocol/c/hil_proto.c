/*
 * hil-bench wire protocol codec (protocol/SPEC.md), C99.
 *
 * No malloc, no stdio, no floating-point arithmetic (floats are moved as
 * bit patterns), so it links into firmware as is. Every function either
 * completes or returns a negative hil_result without touching the output.
 */
#include "hil_proto.h"

#include <string.h>

/* ------------------------------------------------------------------ CRC */

/* CRC-16/CCITT-FALSE, one table lookup per byte (512 bytes of flash). */
static const uint16_t crc_table[256] = {
    0x0000u, 0x1021u, 0x2042u, 0x3063u, 0x4084u, 0x50A5u, 0x60C6u, 0x70E7u,
    0x8108u, 0x9129u, 0xA14Au, 0xB16Bu, 0xC18Cu, 0xD1ADu, 0xE1CEu, 0xF1EFu,
    0x1231u, 0x0210u, 0x3273u, 0x2252u, 0x52B5u, 0x4294u, 0x72F7u, 0x62D6u,
    0x9339u, 0x8318u, 0xB37Bu, 0xA35Au, 0xD3BDu, 0xC39Cu, 0xF3FFu, 0xE3DEu,
    0x2462u, 0x3443u, 0x0420u, 0x1401u, 0x64E6u, 0x74C7u, 0x44A4u, 0x5485u,
    0xA56Au, 0xB54Bu, 0x8528u, 0x9509u, 0xE5EEu, 0xF5CFu, 0xC5ACu, 0xD58Du,
    0x3653u, 0x2672u, 0x1611u, 0x0630u, 0x76D7u, 0x66F6u, 0x5695u, 0x46B4u,
    0xB75Bu, 0xA77Au, 0x9719u, 0x8738u, 0xF7DFu, 0xE7FEu, 0xD79Du, 0xC7BCu,
    0x48C4u, 0x58E5u, 0x6886u, 0x78A7u, 0x0840u, 0x1861u, 0x2802u, 0x3823u,
    0xC9CCu, 0xD9EDu, 0xE98Eu, 0xF9AFu, 0x8948u, 0x9969u, 0xA90Au, 0xB92Bu,
    0x5AF5u, 0x4AD4u, 0x7AB7u, 0x6A96u, 0x1A71u, 0x0A50u, 0x3A33u, 0x2A12u,
    0xDBFDu, 0xCBDCu, 0xFBBFu, 0xEB9Eu, 0x9B79u, 0x8B58u, 0xBB3Bu, 0xAB1Au,
    0x6CA6u, 0x7C87u, 0x4CE4u, 0x5CC5u, 0x2C22u, 0x3C03u, 0x0C60u, 0x1C41u,
    0xEDAEu, 0xFD8Fu, 0xCDECu, 0xDDCDu, 0xAD2Au, 0xBD0Bu, 0x8D68u, 0x9D49u,
    0x7E97u, 0x6EB6u, 0x5ED5u, 0x4EF4u, 0x3E13u, 0x2E32u, 0x1E51u, 0x0E70u,
    0xFF9Fu, 0xEFBEu, 0xDFDDu, 0xCFFCu, 0xBF1Bu, 0xAF3Au, 0x9F59u, 0x8F78u,
    0x9188u, 0x81A9u, 0xB1CAu, 0xA1EBu, 0xD10Cu, 0xC12Du, 0xF14Eu, 0xE16Fu,
    0x1080u, 0x00A1u, 0x30C2u, 0x20E3u, 0x5004u, 0x4025u, 0x7046u, 0x6067u,
    0x83B9u, 0x9398u, 0xA3FBu, 0xB3DAu, 0xC33Du, 0xD31Cu, 0xE37Fu, 0xF35Eu,
    0x02B1u, 0x1290u, 0x22F3u, 0x32D2u, 0x4235u, 0x5214u, 0x6277u, 0x7256u,
    0xB5EAu, 0xA5CBu, 0x95A8u, 0x8589u, 0xF56Eu, 0xE54Fu, 0xD52Cu, 0xC50Du,
    0x34E2u, 0x24C3u, 0x14A0u, 0x0481u, 0x7466u, 0x6447u, 0x5424u, 0x4405u,
    0xA7DBu, 0xB7FAu, 0x8799u, 0x97B8u, 0xE75Fu, 0xF77Eu, 0xC71Du, 0xD73Cu,
    0x26D3u, 0x36F2u, 0x0691u, 0x16B0u, 0x6657u, 0x7676u, 0x4615u, 0x5634u,
    0xD94Cu, 0xC96Du, 0xF90Eu, 0xE92Fu, 0x99C8u, 0x89E9u, 0xB98Au, 0xA9ABu,
    0x5844u, 0x4865u, 0x7806u, 0x6827u, 0x18C0u, 0x08E1u, 0x3882u, 0x28A3u,
    0xCB7Du, 0xDB5Cu, 0xEB3Fu, 0xFB1Eu, 0x8BF9u, 0x9BD8u, 0xABBBu, 0xBB9Au,
    0x4A75u, 0x5A54u, 0x6A37u, 0x7A16u, 0x0AF1u, 0x1AD0u, 0x2AB3u, 0x3A92u,
    0xFD2Eu, 0xED0Fu, 0xDD6Cu, 0xCD4Du, 0xBDAAu, 0xAD8Bu, 0x9DE8u, 0x8DC9u,
    0x7C26u, 0x6C07u, 0x5C64u, 0x4C45u, 0x3CA2u, 0x2C83u, 0x1CE0u, 0x0CC1u,
    0xEF1Fu, 0xFF3Eu, 0xCF5Du, 0xDF7Cu, 0xAF9Bu, 0xBFBAu, 0x8FD9u, 0x9FF8u,
    0x6E17u, 0x7E36u, 0x4E55u, 0x5E74u, 0x2E93u, 0x3EB2u, 0x0ED1u, 0x1EF0u,
};

uint16_t hil_crc16(const uint8_t *data, size_t len)
{
    uint16_t crc = 0xFFFFu;
    for (size_t i = 0; i < len; i++) {
        crc = (uint16_t)((uint16_t)(crc << 8) ^ crc_table[(uint8_t)((crc >> 8) ^ data[i])]);
    }
    return crc;
}

/* ------------------------------------------------------------------ bytes */

static void put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

static void put_u32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

static void put_f32(uint8_t *p, float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    put_u32(p, u);
}

static uint16_t get_u16(const uint8_t *p)
{
    return (uint16_t)((uint16_t)p[0] | (uint16_t)((uint16_t)p[1] << 8));
}

static uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static float get_f32(const uint8_t *p)
{
    uint32_t u = get_u32(p);
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* ------------------------------------------------------------------ payloads */

#define HELLO_FIXED_SIZE 9u
#define SAMPLE_SIZE 11u
#define GATES_SIZE 5u
#define DUTY_SIZE 10u
#define COMMAND_SIZE 14u
#define TELEMETRY_SIZE 56u
#define PARAM_SET_SIZE 6u
#define PARAM_GET_SIZE 2u
#define PARAM_VALUE_SIZE 7u
#define STATUS_SIZE 7u
#define FAULT_SIZE 10u
#define HEARTBEAT_SIZE 4u
#define SHUTDOWN_SIZE 0u
#define TELEMETRY_FLOATS 12u

static int type_known(uint8_t type)
{
    return type >= (uint8_t)HIL_MSG_HELLO && type <= (uint8_t)HIL_MSG_SHUTDOWN;
}

/* Fixed payload size per type; HELLO's is its fixed part. */
static const uint8_t payload_size[HIL_MSG_SHUTDOWN + 1] = {
    0u, HELLO_FIXED_SIZE, SAMPLE_SIZE, GATES_SIZE, DUTY_SIZE, COMMAND_SIZE, TELEMETRY_SIZE,
    PARAM_SET_SIZE, PARAM_GET_SIZE, PARAM_VALUE_SIZE, STATUS_SIZE, FAULT_SIZE, HEARTBEAT_SIZE,
    SHUTDOWN_SIZE};

/* Three 12-bit ADC counts and 4 status bits as one 40-bit little-endian field. */
static int adc40_check(const hil_sample *s)
{
    if (s->adc_i1 > 0xFFFu || s->adc_i2 > 0xFFFu || s->adc_vdc > 0xFFFu || s->status > 0xFu) {
        return HIL_ERR_RANGE;
    }
    return HIL_OK;
}

static void adc40_put(uint8_t *p, const hil_sample *s)
{
    uint32_t low = (uint32_t)s->adc_i1 | ((uint32_t)s->adc_i2 << 12) | (((uint32_t)s->adc_vdc & 0xFFu) << 24);
    put_u32(p, low);
    p[4] = (uint8_t)((s->adc_vdc >> 8) | (s->status << 4));
}

static void adc40_get(const uint8_t *p, hil_sample *s)
{
    uint32_t low = get_u32(p);
    s->adc_i1 = (uint16_t)(low & 0xFFFu);
    s->adc_i2 = (uint16_t)((low >> 12) & 0xFFFu);
    s->adc_vdc = (uint16_t)((low >> 24) | ((uint32_t)(p[4] & 0x0Fu) << 8));
    s->status = (uint8_t)(p[4] >> 4);
}

/* Payload length of msg, or a negative hil_result when it cannot be encoded. */
static int payload_length(const hil_msg *msg)
{
    if (!type_known(msg->type)) {
        return HIL_ERR_UNKNOWN_TYPE;
    }
    if (msg->type == (uint8_t)HIL_MSG_HELLO) {
        if (msg->u.hello.name_len > HIL_NAME_MAX) {
            return HIL_ERR_RANGE;
        }
        return (int)(HELLO_FIXED_SIZE + msg->u.hello.name_len);
    }
    if (msg->type == (uint8_t)HIL_MSG_SAMPLE && adc40_check(&msg->u.sample) != HIL_OK) {
        return HIL_ERR_RANGE;
    }
    return (int)payload_size[msg->type];
}

static void payload_write(const hil_msg *msg, uint8_t *p)
{
    switch (msg->type) {
    case HIL_MSG_HELLO: {
        const hil_hello *m = &msg->u.hello;
        p[0] = m->proto_version;
        p[1] = m->role;
        put_u16(p + 2, m->capabilities);
        put_u32(p + 4, m->control_period_ns);
        p[8] = m->name_len;
        memcpy(p + HELLO_FIXED_SIZE, m->name, m->name_len);
        break;
    }
    case HIL_MSG_SAMPLE:
        put_u32(p, msg->u.sample.period);
        adc40_put(p + 4, &msg->u.sample);
        put_u16(p + 9, msg->u.sample.encoder);
        break;
    case HIL_MSG_GATES:
        put_u32(p, msg->u.gates.period);
        p[4] = msg->u.gates.gates;
        break;
    case HIL_MSG_DUTY:
        put_u32(p, msg->u.duty.period);
        for (size_t i = 0; i < 3u; i++) {
            put_u16(p + 4 + 2 * i, msg->u.duty.duty[i]);
        }
        break;
    case HIL_MSG_COMMAND:
        p[0] = msg->u.command.flags;
        p[1] = msg->u.command.speed_source;
        put_f32(p + 2, msg->u.command.speed_ref_rad_s);
        put_f32(p + 6, msg->u.command.torque_ref_nm);
        put_f32(p + 10, msg->u.command.flux_ref_wb);
        break;
    case HIL_MSG_TELEMETRY: {
        const hil_telemetry *m = &msg->u.telemetry;
        const float f[TELEMETRY_FLOATS] = {
            m->speed_feedback_rad_s, m->speed_encoder_rad_s, m->speed_raw_rad_s, m->speed_lpf_rad_s,
            m->speed_ekf_rad_s,      m->flux_angle_rad,      m->ekf_angle_rad,   m->flux_mag_wb,
            m->torque_est_nm,        m->torque_ref_nm,       m->rotor_pos_conv_rad,
            m->rotor_pos_ekf_rad};
        put_u32(p, m->period);
        p[4] = m->sector;
        p[5] = m->speed_source;
        p[6] = m->state;
        p[7] = m->gates;
        for (size_t i = 0; i < TELEMETRY_FLOATS; i++) {
            put_f32(p + 8 + 4 * i, f[i]);
        }
        break;
    }
    case HIL_MSG_PARAM_SET:
        put_u16(p, msg->u.param_set.id);
        put_f32(p + 2, msg->u.param_set.value);
        break;
    case HIL_MSG_PARAM_GET:
        put_u16(p, msg->u.param_get.id);
        break;
    case HIL_MSG_PARAM_VALUE:
        put_u16(p, msg->u.param_value.id);
        p[2] = msg->u.param_value.status;
        put_f32(p + 3, msg->u.param_value.value);
        break;
    case HIL_MSG_STATUS:
        put_u32(p, msg->u.status.period);
        p[4] = msg->u.status.state;
        put_u16(p + 5, msg->u.status.fault_code);
        break;
    case HIL_MSG_FAULT:
        put_u32(p, msg->u.fault.period);
        put_u16(p + 4, msg->u.fault.code);
        put_f32(p + 6, msg->u.fault.value);
        break;
    case HIL_MSG_HEARTBEAT:
        put_u32(p, msg->u.heartbeat.counter);
        break;
    default: /* SHUTDOWN: no payload */
        break;
    }
}

int hil_payload_encode(const hil_msg *msg, uint8_t *out, size_t cap)
{
    int n = payload_length(msg);
    if (n < 0) {
        return n;
    }
    if ((size_t)n > cap) {
        return HIL_ERR_BUFFER;
    }
    payload_write(msg, out);
    return n;
}

int hil_payload_decode(uint8_t type, const uint8_t *p, size_t len, hil_msg *msg)
{
    if (!type_known(type)) {
        return HIL_ERR_UNKNOWN_TYPE;
    }
    if (type == (uint8_t)HIL_MSG_HELLO) {
        if (len < HELLO_FIXED_SIZE || p[8] > HIL_NAME_MAX || len != HELLO_FIXED_SIZE + p[8]) {
            return HIL_ERR_LENGTH;
        }
    } else if (len != payload_size[type]) {
        return HIL_ERR_LENGTH;
    }
    /* Length is right: from here on *msg is written. */
    switch (type) {
    case HIL_MSG_HELLO: {
        hil_hello *m = &msg->u.hello;
        m->proto_version = p[0];
        m->role = p[1];
        m->capabilities = get_u16(p + 2);
        m->control_period_ns = get_u32(p + 4);
        m->name_len = p[8];
        memset(m->name, 0, sizeof m->name);
        memcpy(m->name, p + HELLO_FIXED_SIZE, m->name_len);
        break;
    }
    case HIL_MSG_SAMPLE:
        msg->u.sample.period = get_u32(p);
        adc40_get(p + 4, &msg->u.sample);
        msg->u.sample.encoder = get_u16(p + 9);
        break;
    case HIL_MSG_GATES:
        msg->u.gates.period = get_u32(p);
        msg->u.gates.gates = p[4];
        break;
    case HIL_MSG_DUTY:
        msg->u.duty.period = get_u32(p);
        for (size_t i = 0; i < 3u; i++) {
            msg->u.duty.duty[i] = get_u16(p + 4 + 2 * i);
        }
        break;
    case HIL_MSG_COMMAND:
        msg->u.command.flags = p[0];
        msg->u.command.speed_source = p[1];
        msg->u.command.speed_ref_rad_s = get_f32(p + 2);
        msg->u.command.torque_ref_nm = get_f32(p + 6);
        msg->u.command.flux_ref_wb = get_f32(p + 10);
        break;
    case HIL_MSG_TELEMETRY: {
        hil_telemetry *m = &msg->u.telemetry;
        float *const f[TELEMETRY_FLOATS] = {
            &m->speed_feedback_rad_s, &m->speed_encoder_rad_s, &m->speed_raw_rad_s,
            &m->speed_lpf_rad_s,      &m->speed_ekf_rad_s,     &m->flux_angle_rad,
            &m->ekf_angle_rad,        &m->flux_mag_wb,         &m->torque_est_nm,
            &m->torque_ref_nm,        &m->rotor_pos_conv_rad,  &m->rotor_pos_ekf_rad};
        m->period = get_u32(p);
        m->sector = p[4];
        m->speed_source = p[5];
        m->state = p[6];
        m->gates = p[7];
        for (size_t i = 0; i < TELEMETRY_FLOATS; i++) {
            *f[i] = get_f32(p + 8 + 4 * i);
        }
        break;
    }
    case HIL_MSG_PARAM_SET:
        msg->u.param_set.id = get_u16(p);
        msg->u.param_set.value = get_f32(p + 2);
        break;
    case HIL_MSG_PARAM_GET:
        msg->u.param_get.id = get_u16(p);
        break;
    case HIL_MSG_PARAM_VALUE:
        msg->u.param_value.id = get_u16(p);
        msg->u.param_value.status = p[2];
        msg->u.param_value.value = get_f32(p + 3);
        break;
    case HIL_MSG_STATUS:
        msg->u.status.period = get_u32(p);
        msg->u.status.state = p[4];
        msg->u.status.fault_code = get_u16(p + 5);
        break;
    case HIL_MSG_FAULT:
        msg->u.fault.period = get_u32(p);
        msg->u.fault.code = get_u16(p + 4);
        msg->u.fault.value = get_f32(p + 6);
        break;
    case HIL_MSG_HEARTBEAT:
        msg->u.heartbeat.counter = get_u32(p);
        break;
    default: /* SHUTDOWN */
        break;
    }
    msg->type = type;
    return HIL_OK;
}

/* ------------------------------------------------------------------ serial frames */

/* COBS for inputs shorter than 254 bytes (frames are at most HIL_MAX_RAW_FRAME),
 * so no block reaches the 0xFF code. Writes n + 1 bytes and the 0x00 delimiter. */
static size_t cobs_encode(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t code_at = 0;
    size_t o = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < n; i++) {
        if (in[i] == 0u) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
        } else {
            out[o++] = in[i];
            code++;
        }
    }
    out[code_at] = code;
    out[o++] = 0u;
    return o;
}

int hil_frame_encode(const hil_msg *msg, uint8_t *out, size_t cap)
{
    uint8_t raw[HIL_MAX_RAW_FRAME];
    int n = hil_payload_encode(msg, raw + HIL_HEADER_SIZE, HIL_MAX_PAYLOAD);
    if (n < 0) {
        return n;
    }
    raw[0] = (uint8_t)HIL_PROTO_VERSION;
    raw[1] = msg->type;
    raw[2] = msg->seq;
    raw[3] = (uint8_t)n;
    size_t raw_len = HIL_HEADER_SIZE + (size_t)n;
    put_u16(raw + raw_len, hil_crc16(raw, raw_len));
    raw_len += HIL_CRC_SIZE;
    if (cap < raw_len + 2u) {
        return HIL_ERR_BUFFER;
    }
    return (int)cobs_encode(raw, raw_len, out);
}

static void decoder_restart(hil_decoder *d)
{
    d->len = 0;
    d->encoded_len = 0;
    d->cobs_left = 0;
    d->cobs_zero = 0;
    d->overflow = 0;
}

void hil_decoder_init(hil_decoder *dec)
{
    memset(dec, 0, sizeof *dec);
}

static void decoder_emit(hil_decoder *d, uint8_t byte)
{
    /* COBS never decodes to more bytes than it was given minus one, and at most
     * HIL_MAX_ENCODED_SEGMENT are accepted: this bound cannot trip. */
    if (d->len < sizeof d->buf) {
        d->buf[d->len++] = byte;
    }
}

/* A whole decoded frame in d->buf: checks in the order SPEC.md gives. */
static int decoder_frame(hil_decoder *d, hil_msg *out)
{
    const uint8_t *raw = d->buf;
    size_t n = d->len;
    if (n < HIL_HEADER_SIZE + HIL_CRC_SIZE) {
        d->framing_errors++;
        return 0;
    }
    if (hil_crc16(raw, n - HIL_CRC_SIZE) != get_u16(raw + n - HIL_CRC_SIZE)) {
        d->crc_errors++;
        return 0;
    }
    if (raw[0] != HIL_PROTO_VERSION) {
        d->version_errors++;
        d->last_bad_version = raw[0];
        return 0;
    }
    size_t payload_len = n - HIL_HEADER_SIZE - HIL_CRC_SIZE;
    if (raw[3] != payload_len) {
        d->framing_errors++;
        return 0;
    }
    uint8_t seq = raw[2];
    if (d->have_seq) {
        d->seq_gaps += (uint8_t)(seq - d->last_seq - 1u);
    }
    d->have_seq = 1;
    d->last_seq = seq;
    int rc = hil_payload_decode(raw[1], raw + HIL_HEADER_SIZE, payload_len, out);
    if (rc == HIL_ERR_UNKNOWN_TYPE) {
        d->unknown_types++;
        return 0;
    }
    if (rc != HIL_OK) {
        d->length_errors++;
        return 0;
    }
    out->seq = seq;
    d->frames_ok++;
    return 1;
}

int hil_decoder_feed(hil_decoder *d, uint8_t byte, hil_msg *out)
{
    if (byte != 0u) {
        if (d->overflow) {
            return 0;
        }
        if (d->encoded_len >= HIL_MAX_ENCODED_SEGMENT) {
            d->overflow = 1;
            return 0;
        }
        d->encoded_len++;
        if (d->cobs_left == 0u) { /* a COBS code byte */
            if (d->cobs_zero) {
                decoder_emit(d, 0u);
            }
            d->cobs_left = (uint8_t)(byte - 1u);
            d->cobs_zero = byte != 0xFFu;
        } else {
            decoder_emit(d, byte);
            d->cobs_left--;
        }
        return 0;
    }
    int result = 0;
    if (d->overflow) {
        d->framing_errors++;
    } else if (d->encoded_len == 0u) {
        /* idle line or back-to-back delimiters: nothing to count */
    } else if (d->cobs_left != 0u) {
        d->framing_errors++; /* the last COBS block ran past the delimiter */
    } else {
        result = decoder_frame(d, out);
    }
    decoder_restart(d);
    return result;
}

size_t hil_decoder_feed_buf(hil_decoder *d, const uint8_t *data, size_t len, hil_msg *out, int *got)
{
    /* hil_decoder_feed with the per-byte state in locals: the non-delimiter bytes of a frame
     * are the whole cost, and they touch nothing else. */
    size_t i = 0;
    *got = 0;
    while (i < len) {
        if (data[i] == 0u || d->overflow) {
            int done = hil_decoder_feed(d, data[i++], out);
            if (done) {
                *got = 1;
                return i;
            }
            continue;
        }
        size_t n = d->len;
        size_t enc = d->encoded_len;
        uint8_t left = d->cobs_left;
        uint8_t zero = d->cobs_zero;
        uint8_t *buf = d->buf;
        while (i < len && data[i] != 0u) {
            uint8_t byte = data[i];
            if (enc >= HIL_MAX_ENCODED_SEGMENT) {
                d->overflow = 1;
                break;
            }
            enc++;
            i++;
            if (left == 0u) {
                if (zero && n < sizeof d->buf) {
                    buf[n++] = 0u;
                }
                left = (uint8_t)(byte - 1u);
                zero = byte != 0xFFu;
            } else {
                if (n < sizeof d->buf) {
                    buf[n++] = byte;
                }
                left--;
            }
        }
        d->len = n;
        d->encoded_len = enc;
        d->cobs_left = left;
        d->cobs_zero = zero;
    }
    return i;
}

/* ------------------------------------------------------------------ CAN */

#define CAN_ID_MAX 0x7FFu
#define CAN_ROLE_STRIDE 0x20u
#define CAN_SEGMENT_DATA 7u

/* Types whose payload does not fit one classic frame: sent with a segmentation header. */
static int can_segmented(uint8_t type)
{
    return type == (uint8_t)HIL_MSG_HELLO || type == (uint8_t)HIL_MSG_COMMAND ||
           type == (uint8_t)HIL_MSG_TELEMETRY || type == (uint8_t)HIL_MSG_FAULT;
}

int hil_can_pack(const hil_msg *msg, uint8_t sender_role, uint16_t base_id, hil_can_frame *frames,
                 size_t max_frames)
{
    if (sender_role >= HIL_CAN_ROLES || base_id > CAN_ID_MAX - (HIL_CAN_ID_SPAN - 1u)) {
        return HIL_ERR_RANGE;
    }
    if (!type_known(msg->type)) {
        return HIL_ERR_UNKNOWN_TYPE;
    }
    uint16_t id = (uint16_t)(base_id + CAN_ROLE_STRIDE * sender_role + msg->type);
    if (msg->type == (uint8_t)HIL_MSG_SAMPLE) {
        if (adc40_check(&msg->u.sample) != HIL_OK) {
            return HIL_ERR_RANGE;
        }
        if (max_frames < 1u) {
            return HIL_ERR_BUFFER;
        }
        frames[0].id = id;
        frames[0].dlc = 8;
        frames[0].data[0] = (uint8_t)msg->u.sample.period; /* low 8 bits, see SPEC.md */
        adc40_put(frames[0].data + 1, &msg->u.sample);
        put_u16(frames[0].data + 6, msg->u.sample.encoder);
        return 1;
    }
    if (msg->type == (uint8_t)HIL_MSG_DUTY) {
        if (max_frames < 1u) {
            return HIL_ERR_BUFFER;
        }
        frames[0].id = id;
        frames[0].dlc = 8;
        put_u16(frames[0].data, (uint16_t)msg->u.duty.period); /* low 16 bits */
        for (size_t i = 0; i < 3u; i++) {
            put_u16(frames[0].data + 2 + 2 * i, msg->u.duty.duty[i]);
        }
        return 1;
    }
    uint8_t payload[HIL_MAX_PAYLOAD];
    int n = hil_payload_encode(msg, payload, sizeof payload);
    if (n < 0) {
        return n;
    }
    size_t len = (size_t)n;
    if (!can_segmented(msg->type)) {
        if (max_frames < 1u) {
            return HIL_ERR_BUFFER;
        }
        frames[0].id = id;
        frames[0].dlc = (uint8_t)len;
        memcpy(frames[0].data, payload, len);
        return 1;
    }
    size_t count = (len + CAN_SEGMENT_DATA - 1u) / CAN_SEGMENT_DATA;
    if (count > max_frames) {
        return HIL_ERR_BUFFER;
    }
    for (size_t i = 0; i < count; i++) {
        size_t start = i * CAN_SEGMENT_DATA;
        size_t chunk = len - start < CAN_SEGMENT_DATA ? len - start : CAN_SEGMENT_DATA;
        frames[i].id = id;
        frames[i].dlc = (uint8_t)(1u + chunk);
        frames[i].data[0] = (uint8_t)(((msg->seq & 0x0Fu) << 4) | i);
        memcpy(frames[i].data + 1, payload + start, chunk);
    }
    return (int)count;
}

void hil_can_rx_init(hil_can_rx *rx, uint16_t base_id)
{
    memset(rx, 0, sizeof *rx);
    rx->base_id = base_id;
}

/* Full period from its low `bits` bits: the value nearest the last period seen. */
static uint32_t can_extend_period(hil_can_rx *rx, uint32_t low, unsigned bits)
{
    uint32_t period;
    if (!rx->have_period) {
        period = low;
    } else {
        uint32_t mask = (1u << bits) - 1u;
        uint32_t half = 1u << (bits - 1u);
        uint32_t ahead = (low - rx->last_period) & mask;
        period = ahead < half ? rx->last_period + ahead : rx->last_period - ((mask + 1u) - ahead);
    }
    rx->last_period = period;
    rx->have_period = 1;
    return period;
}

static void can_note_period(hil_can_rx *rx, const hil_msg *msg)
{
    uint32_t period;
    switch (msg->type) {
    case HIL_MSG_GATES:
        period = msg->u.gates.period;
        break;
    case HIL_MSG_TELEMETRY:
        period = msg->u.telemetry.period;
        break;
    case HIL_MSG_STATUS:
        period = msg->u.status.period;
        break;
    case HIL_MSG_FAULT:
        period = msg->u.fault.period;
        break;
    default:
        return;
    }
    rx->last_period = period;
    rx->have_period = 1;
}

static int can_single(hil_can_rx *rx, uint8_t type, const hil_can_frame *f, hil_msg *out)
{
    if (type == (uint8_t)HIL_MSG_SAMPLE || type == (uint8_t)HIL_MSG_DUTY) {
        if (f->dlc != 8u) {
            rx->length_errors++;
            return 0;
        }
        if (type == (uint8_t)HIL_MSG_SAMPLE) {
            out->u.sample.period = can_extend_period(rx, f->data[0], 8u);
            adc40_get(f->data + 1, &out->u.sample);
            out->u.sample.encoder = get_u16(f->data + 6);
        } else {
            out->u.duty.period = can_extend_period(rx, get_u16(f->data), 16u);
            for (size_t i = 0; i < 3u; i++) {
                out->u.duty.duty[i] = get_u16(f->data + 2 + 2 * i);
            }
        }
        out->type = type;
    } else {
        if (hil_payload_decode(type, f->data, f->dlc, out) != HIL_OK) {
            rx->length_errors++;
            return 0;
        }
        can_note_period(rx, out);
    }
    return 1;
}

/* Payload length of a segmented message: 0 while not yet known, -1 when invalid. */
static int can_expected_len(const hil_can_slot *s)
{
    if (s->type != (uint8_t)HIL_MSG_HELLO) {
        return (int)payload_size[s->type];
    }
    if (s->len < HELLO_FIXED_SIZE) {
        return 0;
    }
    if (s->buf[8] > HIL_NAME_MAX) {
        return -1;
    }
    return (int)(HELLO_FIXED_SIZE + s->buf[8]);
}

/* Drops the message in progress; its remaining frames are then dropped without being
 * counted again, so one broken message costs one error. */
static void can_abandon(hil_can_slot *s, uint8_t type, uint8_t counter)
{
    s->type = 0;
    s->skip_type = type;
    s->skip_counter = counter;
}

static int can_segment(hil_can_rx *rx, hil_can_slot *s, uint8_t type, const hil_can_frame *f,
                       hil_msg *out)
{
    if (f->dlc < 1u) {
        rx->length_errors++;
        if (s->type != 0u) {
            can_abandon(s, s->type, s->counter);
        }
        return 0;
    }
    uint8_t index = (uint8_t)(f->data[0] & 0x0Fu);
    uint8_t counter = (uint8_t)(f->data[0] >> 4);
    if (index == 0u) {
        if (s->type != 0u) {
            rx->sequence_errors++; /* the previous message never completed */
        }
        s->type = type;
        s->counter = counter;
        s->next_index = 0;
        s->len = 0;
        s->skip_type = 0;
    } else if (s->type != type || s->counter != counter || s->next_index != index) {
        if (s->type == 0u && s->skip_type == type && s->skip_counter == counter) {
            return 0; /* the rest of a message already counted */
        }
        rx->sequence_errors++;
        can_abandon(s, type, counter);
        return 0;
    }
    size_t chunk = (size_t)f->dlc - 1u;
    if (chunk == 0u || s->len + chunk > sizeof s->buf) {
        rx->length_errors++;
        can_abandon(s, type, counter);
        return 0;
    }
    memcpy(s->buf + s->len, f->data + 1, chunk);
    s->len = (uint8_t)(s->len + chunk);
    s->next_index++;
    int expected = can_expected_len(s);
    if (expected < 0 || (expected > 0 && s->len > (size_t)expected)) {
        rx->length_errors++;
        can_abandon(s, type, counter);
        return 0;
    }
    if (expected > 0 && s->len == (size_t)expected) {
        s->type = 0;
        if (hil_payload_decode(type, s->buf, s->len, out) != HIL_OK) {
            rx->length_errors++; /* unreachable: the length was checked above */
            return 0;
        }
        out->seq = counter;
        can_note_period(rx, out);
        return 1;
    }
    if (chunk < CAN_SEGMENT_DATA) {
        rx->length_errors++; /* a short frame that does not end the message */
        can_abandon(s, type, counter);
    }
    return 0;
}

int hil_can_rx_feed(hil_can_rx *rx, const hil_can_frame *frame, hil_msg *out, uint8_t *sender_role)
{
    if (frame->id < rx->base_id || frame->id >= rx->base_id + HIL_CAN_ID_SPAN) {
        rx->ignored_frames++;
        return 0;
    }
    uint8_t offset = (uint8_t)(frame->id - rx->base_id);
    uint8_t role = (uint8_t)(offset / CAN_ROLE_STRIDE);
    uint8_t type = (uint8_t)(offset % CAN_ROLE_STRIDE);
    if (!type_known(type)) {
        rx->unknown_types++;
        return 0;
    }
    if (frame->dlc > 8u) {
        rx->length_errors++;
        return 0;
    }
    int done;
    if (can_segmented(type)) {
        done = can_segment(rx, &rx->slot[role], type, frame, out);
    } else {
        done = can_single(rx, type, frame, out);
        if (done) {
            out->seq = 0;
        }
    }
    if (done) {
        rx->messages_ok++;
        if (sender_role != NULL) {
            *sender_role = role;
        }
    }
    return done;
}
