/* Reader for protocol/vectors/vectors.txt. The message fields are set by name
 * through a table of offsets into hil_msg, so the C side builds every message
 * from its fields alone and then must reproduce the recorded bytes. */
#include "vectors.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef enum { F_U8, F_U16, F_U32, F_F32, F_NAME, F_DUTY } field_kind;

typedef struct {
    uint8_t type;
    const char *name;
    field_kind kind;
    size_t offset;
} field_desc;

#define FD(t, n, k, member) {(uint8_t)(t), n, k, offsetof(hil_msg, member)}

static const field_desc FIELDS[] = {
    FD(HIL_MSG_HELLO, "proto_version", F_U8, u.hello.proto_version),
    FD(HIL_MSG_HELLO, "role", F_U8, u.hello.role),
    FD(HIL_MSG_HELLO, "capabilities", F_U16, u.hello.capabilities),
    FD(HIL_MSG_HELLO, "control_period_ns", F_U32, u.hello.control_period_ns),
    FD(HIL_MSG_HELLO, "name_len", F_U8, u.hello.name_len),
    FD(HIL_MSG_HELLO, "name", F_NAME, u.hello.name),
    FD(HIL_MSG_SAMPLE, "period", F_U32, u.sample.period),
    FD(HIL_MSG_SAMPLE, "adc_i1", F_U16, u.sample.adc_i1),
    FD(HIL_MSG_SAMPLE, "adc_i2", F_U16, u.sample.adc_i2),
    FD(HIL_MSG_SAMPLE, "adc_vdc", F_U16, u.sample.adc_vdc),
    FD(HIL_MSG_SAMPLE, "encoder", F_U16, u.sample.encoder),
    FD(HIL_MSG_SAMPLE, "status", F_U8, u.sample.status),
    FD(HIL_MSG_GATES, "period", F_U32, u.gates.period),
    FD(HIL_MSG_GATES, "gates", F_U8, u.gates.gates),
    FD(HIL_MSG_DUTY, "period", F_U32, u.duty.period),
    FD(HIL_MSG_DUTY, "duty", F_DUTY, u.duty.duty),
    FD(HIL_MSG_COMMAND, "flags", F_U8, u.command.flags),
    FD(HIL_MSG_COMMAND, "speed_source", F_U8, u.command.speed_source),
    FD(HIL_MSG_COMMAND, "speed_ref_rad_s", F_F32, u.command.speed_ref_rad_s),
    FD(HIL_MSG_COMMAND, "torque_ref_nm", F_F32, u.command.torque_ref_nm),
    FD(HIL_MSG_COMMAND, "flux_ref_wb", F_F32, u.command.flux_ref_wb),
    FD(HIL_MSG_TELEMETRY, "period", F_U32, u.telemetry.period),
    FD(HIL_MSG_TELEMETRY, "sector", F_U8, u.telemetry.sector),
    FD(HIL_MSG_TELEMETRY, "speed_source", F_U8, u.telemetry.speed_source),
    FD(HIL_MSG_TELEMETRY, "state", F_U8, u.telemetry.state),
    FD(HIL_MSG_TELEMETRY, "gates", F_U8, u.telemetry.gates),
    FD(HIL_MSG_TELEMETRY, "speed_feedback_rad_s", F_F32, u.telemetry.speed_feedback_rad_s),
    FD(HIL_MSG_TELEMETRY, "speed_encoder_rad_s", F_F32, u.telemetry.speed_encoder_rad_s),
    FD(HIL_MSG_TELEMETRY, "speed_raw_rad_s", F_F32, u.telemetry.speed_raw_rad_s),
    FD(HIL_MSG_TELEMETRY, "speed_lpf_rad_s", F_F32, u.telemetry.speed_lpf_rad_s),
    FD(HIL_MSG_TELEMETRY, "speed_ekf_rad_s", F_F32, u.telemetry.speed_ekf_rad_s),
    FD(HIL_MSG_TELEMETRY, "flux_angle_rad", F_F32, u.telemetry.flux_angle_rad),
    FD(HIL_MSG_TELEMETRY, "ekf_angle_rad", F_F32, u.telemetry.ekf_angle_rad),
    FD(HIL_MSG_TELEMETRY, "flux_mag_wb", F_F32, u.telemetry.flux_mag_wb),
    FD(HIL_MSG_TELEMETRY, "torque_est_nm", F_F32, u.telemetry.torque_est_nm),
    FD(HIL_MSG_TELEMETRY, "torque_ref_nm", F_F32, u.telemetry.torque_ref_nm),
    FD(HIL_MSG_TELEMETRY, "rotor_pos_conv_rad", F_F32, u.telemetry.rotor_pos_conv_rad),
    FD(HIL_MSG_TELEMETRY, "rotor_pos_ekf_rad", F_F32, u.telemetry.rotor_pos_ekf_rad),
    FD(HIL_MSG_PARAM_SET, "id", F_U16, u.param_set.id),
    FD(HIL_MSG_PARAM_SET, "value", F_F32, u.param_set.value),
    FD(HIL_MSG_PARAM_GET, "id", F_U16, u.param_get.id),
    FD(HIL_MSG_PARAM_VALUE, "id", F_U16, u.param_value.id),
    FD(HIL_MSG_PARAM_VALUE, "status", F_U8, u.param_value.status),
    FD(HIL_MSG_PARAM_VALUE, "value", F_F32, u.param_value.value),
    FD(HIL_MSG_STATUS, "period", F_U32, u.status.period),
    FD(HIL_MSG_STATUS, "state", F_U8, u.status.state),
    FD(HIL_MSG_STATUS, "fault_code", F_U16, u.status.fault_code),
    FD(HIL_MSG_FAULT, "period", F_U32, u.fault.period),
    FD(HIL_MSG_FAULT, "code", F_U16, u.fault.code),
    FD(HIL_MSG_FAULT, "value", F_F32, u.fault.value),
    FD(HIL_MSG_HEARTBEAT, "counter", F_U32, u.heartbeat.counter),
    FD(HIL_MSG_DUTY_LEGS, "period", F_U32, u.duty_legs.period),
    FD(HIL_MSG_DUTY_LEGS, "duty", F_DUTY, u.duty_legs.duty),
    FD(HIL_MSG_DUTY_LEGS, "leg_enable", F_U8, u.duty_legs.leg_enable),
    FD(HIL_MSG_SAMPLE_SENSORS, "period", F_U32, u.sample_sensors.period),
    FD(HIL_MSG_SAMPLE_SENSORS, "sensor_set", F_U16, u.sample_sensors.sensor_set),
    FD(HIL_MSG_SAMPLE_SENSORS, "status", F_U8, u.sample_sensors.status),
    FD(HIL_MSG_SAMPLE_SENSORS, "adc_ia", F_U16, u.sample_sensors.adc_ia),
    FD(HIL_MSG_SAMPLE_SENSORS, "adc_ib", F_U16, u.sample_sensors.adc_ib),
    FD(HIL_MSG_SAMPLE_SENSORS, "adc_ic", F_U16, u.sample_sensors.adc_ic),
    FD(HIL_MSG_SAMPLE_SENSORS, "adc_vdc", F_U16, u.sample_sensors.adc_vdc),
    FD(HIL_MSG_SAMPLE_SENSORS, "encoder", F_U16, u.sample_sensors.encoder),
    FD(HIL_MSG_SAMPLE_SENSORS, "hall", F_U8, u.sample_sensors.hall),
    FD(HIL_MSG_SAMPLE_SENSORS, "adc_va", F_U16, u.sample_sensors.adc_va),
    FD(HIL_MSG_SAMPLE_SENSORS, "adc_vb", F_U16, u.sample_sensors.adc_vb),
    FD(HIL_MSG_SAMPLE_SENSORS, "adc_vc", F_U16, u.sample_sensors.adc_vc),
    FD(HIL_MSG_SAMPLE_SENSORS, "bemf_comparators", F_U8, u.sample_sensors.bemf_comparators),
    FD(HIL_MSG_SAMPLE_SENSORS, "adc_resolver_sin", F_U16, u.sample_sensors.adc_resolver_sin),
    FD(HIL_MSG_SAMPLE_SENSORS, "adc_resolver_cos", F_U16, u.sample_sensors.adc_resolver_cos),
    FD(HIL_MSG_SAMPLE_SENSORS, "adc_temperature", F_U16, u.sample_sensors.adc_temperature),
};

static const char *const TYPE_NAMES[] = {"",          "HELLO",     "SAMPLE",      "GATES",
                                         "DUTY",      "COMMAND",   "TELEMETRY",   "PARAM_SET",
                                         "PARAM_GET", "PARAM_VALUE", "STATUS",    "FAULT",
                                         "HEARTBEAT", "SHUTDOWN",  "" /* 0x0E undefined */,
                                         "DUTY_LEGS", "SAMPLE_SENSORS"};

typedef struct {
    const char *path;
    int line;
} where;

static int fail(where w, const char *what, const char *detail)
{
    fprintf(stderr, "%s:%d: %s%s%s\n", w.path, w.line, what, detail ? ": " : "", detail ? detail : "");
    return -1;
}

static int parse_type(const char *s)
{
    for (size_t i = 1; i < sizeof TYPE_NAMES / sizeof TYPE_NAMES[0]; i++) {
        if (strcmp(s, TYPE_NAMES[i]) == 0) {
            return (int)i;
        }
    }
    return -1;
}

static int parse_ulong(const char *s, unsigned long max, unsigned long *out)
{
    char *end;
    errno = 0;
    unsigned long v = strtoul(s, &end, 0);
    if (errno != 0 || *s == '\0' || *end != '\0' || v > max) {
        return -1;
    }
    *out = v;
    return 0;
}

/* Hex string ('-' for empty) into buf; returns the byte count or -1. */
static long parse_hex(const char *s, uint8_t *buf, size_t cap)
{
    if (strcmp(s, "-") == 0) {
        return 0;
    }
    size_t n = strlen(s);
    if (n % 2u != 0u || n / 2u > cap) {
        return -1;
    }
    for (size_t i = 0; i < n / 2u; i++) {
        unsigned int byte;
        if (sscanf(s + 2 * i, "%2x", &byte) != 1) {
            return -1;
        }
        buf[i] = (uint8_t)byte;
    }
    return (long)(n / 2u);
}

static int set_field(hil_msg *msg, char **words, int nwords, where w)
{
    for (size_t i = 0; i < sizeof FIELDS / sizeof FIELDS[0]; i++) {
        const field_desc *fd = &FIELDS[i];
        if (fd->type != msg->type || strcmp(fd->name, words[1]) != 0) {
            continue;
        }
        uint8_t *p = (uint8_t *)msg + fd->offset;
        unsigned long v;
        switch (fd->kind) {
        case F_U8:
        case F_U16:
        case F_U32: {
            unsigned long max = fd->kind == F_U8 ? 0xFFul : fd->kind == F_U16 ? 0xFFFFul : 0xFFFFFFFFul;
            if (nwords != 3 || parse_ulong(words[2], max, &v) != 0) {
                return fail(w, "bad integer for field", words[1]);
            }
            if (fd->kind == F_U8) {
                uint8_t x = (uint8_t)v;
                memcpy(p, &x, sizeof x);
            } else if (fd->kind == F_U16) {
                uint16_t x = (uint16_t)v;
                memcpy(p, &x, sizeof x);
            } else {
                uint32_t x = (uint32_t)v;
                memcpy(p, &x, sizeof x);
            }
            return 0;
        }
        case F_F32: {
            char *end;
            float f = strtof(words[2], &end);
            if (nwords != 3 || *end != '\0') {
                return fail(w, "bad float for field", words[1]);
            }
            memcpy(p, &f, sizeof f);
            return 0;
        }
        case F_NAME: {
            /* up to 64 bytes so a reject vector can carry a name longer than the buffer;
             * name_len is what the encoder checks */
            uint8_t tmp[64];
            long len = nwords == 3 ? parse_hex(words[2], tmp, sizeof tmp) : -1;
            if (len < 0) {
                return fail(w, "bad name bytes", words[2]);
            }
            memcpy(p, tmp, (size_t)len < HIL_NAME_MAX ? (size_t)len : HIL_NAME_MAX);
            return 0;
        }
        case F_DUTY:
            if (nwords != 5) {
                return fail(w, "duty needs three values", NULL);
            }
            for (int k = 0; k < 3; k++) {
                if (parse_ulong(words[2 + k], 0xFFFFul, &v) != 0) {
                    return fail(w, "bad duty value", words[2 + k]);
                }
                uint16_t x = (uint16_t)v;
                memcpy(p + 2 * k, &x, sizeof x);
            }
            return 0;
        }
    }
    return fail(w, "no such field for this type", words[1]);
}

uint16_t spec_crc16(const uint8_t *data, size_t n)
{
    uint16_t crc = 0xFFFFu;
    for (size_t i = 0; i < n; i++) {
        crc = (uint16_t)(crc ^ (uint16_t)(data[i] << 8));
        for (int b = 0; b < 8; b++) {
            crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
        }
    }
    return crc;
}

size_t spec_cobs(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t code_at = 0, o = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < n; i++) {
        if (in[i] == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
        } else {
            out[o++] = in[i];
            code++;
        }
    }
    out[code_at] = code;
    out[o++] = 0;
    return o;
}

/* words[from..n-1] joined into one hex string ("40 e2 01 00" -> "40e20100") */
static const char *join_hex(char **words, int from, int n, char *buf, size_t cap)
{
    size_t len = 0;
    buf[0] = '\0';
    for (int i = from; i < n; i++) {
        size_t add = strlen(words[i]);
        if (len + add + 1u > cap) {
            return "x"; /* too long: parse_hex refuses it */
        }
        memcpy(buf + len, words[i], add + 1u);
        len += add;
    }
    return buf;
}

/* A 'crc' or 'badcrc' line for raw[0..len): checks it with spec_crc16 and writes the two bytes. */
static int crc_line(char **words, int n, const uint8_t *raw, size_t len, uint8_t crc[2], where w)
{
    char hex[64];
    if (len == 0u || parse_hex(join_hex(words, 1, n, hex, sizeof hex), crc, 2) != 2) {
        return fail(w, "needs two CRC bytes after some 'raw' bytes", words[0]);
    }
    uint16_t right = spec_crc16(raw, len);
    int matches = crc[0] == (uint8_t)right && crc[1] == (uint8_t)(right >> 8);
    int want = strcmp(words[0], "crc") == 0;
    if (matches != want) {
        char detail[48];
        snprintf(detail, sizeof detail, "the CRC of the raw bytes is %02x %02x", right & 0xFFu, right >> 8);
        return fail(w, want ? "wrong 'crc' line" : "'badcrc' line is the right CRC", detail);
    }
    return 0;
}

static int split(char *line, char **words, int max)
{
    char *hash = strchr(line, '#');
    if (hash != NULL) {
        *hash = '\0';
    }
    int n = 0;
    for (char *tok = strtok(line, " \t\r\n"); tok != NULL && n < max; tok = strtok(NULL, " \t\r\n")) {
        words[n++] = tok;
    }
    return n;
}

static long find_message(const vec_file *vf, const char *name)
{
    for (size_t i = 0; i < vf->message_count; i++) {
        if (!vf->messages[i].is_reject && strcmp(vf->messages[i].name, name) == 0) {
            return (long)i;
        }
    }
    return -1;
}

static int grow(void **array, size_t count, size_t size)
{
    /* capacity doubles at powers of two */
    if (count != 0u && (count & (count - 1u)) != 0u) {
        return 0;
    }
    void *p = realloc(*array, (count == 0u ? 1u : 2u * count) * size);
    if (p == NULL) {
        return -1;
    }
    *array = p;
    return 0;
}

int vec_load(const char *path, vec_file *vf)
{
    memset(vf, 0, sizeof *vf);
    FILE *f = fopen(path, "r");
    if (f == NULL) {
        fprintf(stderr, "%s: cannot open: %s\n", path, strerror(errno));
        return -1;
    }
    char line[4096];
    char hex[4096];
    char *words[96];
    uint8_t pending[HIL_MAX_RAW_FRAME + 2]; /* a stream's raw frame being built */
    size_t pending_len = 0;
    vec_message *m = NULL;
    vec_stream *s = NULL;
    where w = {path, 0};
    int rc = 0;
    while (rc == 0 && fgets(line, sizeof line, f) != NULL) {
        w.line++;
        int n = split(line, words, 96);
        if (n == 0) {
            continue;
        }
        if (m == NULL && s == NULL) {
            if ((strcmp(words[0], "message") == 0 && n == 6) || (strcmp(words[0], "reject") == 0 && n == 4)) {
                if (grow((void **)&vf->messages, vf->message_count, sizeof *m) != 0) {
                    rc = fail(w, "out of memory", NULL);
                    break;
                }
                m = &vf->messages[vf->message_count++];
                memset(m, 0, sizeof *m);
                m->line = w.line;
                m->is_reject = words[0][0] == 'r';
                snprintf(m->name, sizeof m->name, "%s", words[1]);
                int type = parse_type(words[2]);
                if (type < 0) {
                    rc = fail(w, "unknown message type", words[2]);
                    break;
                }
                m->msg.type = (uint8_t)type;
                if (!m->is_reject) {
                    unsigned long seq, role, base;
                    if (parse_ulong(words[3], 0xFF, &seq) || parse_ulong(words[4], 1, &role) ||
                        parse_ulong(words[5], 0x7FF, &base)) {
                        rc = fail(w, "bad seq, role or base id", NULL);
                        break;
                    }
                    m->msg.seq = (uint8_t)seq;
                    m->role = (uint8_t)role;
                    m->base_id = (uint16_t)base;
                }
            } else if ((strcmp(words[0], "serial_stream") == 0 && n == 2) ||
                       (strcmp(words[0], "can_stream") == 0 && n == 3)) {
                if (grow((void **)&vf->streams, vf->stream_count, sizeof *s) != 0) {
                    rc = fail(w, "out of memory", NULL);
                    break;
                }
                s = &vf->streams[vf->stream_count++];
                memset(s, 0, sizeof *s);
                s->line = w.line;
                s->is_can = words[0][0] == 'c';
                snprintf(s->name, sizeof s->name, "%s", words[1]);
                unsigned long base;
                if (s->is_can) {
                    if (parse_ulong(words[2], 0x7FF, &base) != 0) {
                        rc = fail(w, "bad base id", words[2]);
                        break;
                    }
                    s->base_id = (uint16_t)base;
                }
            } else {
                rc = fail(w, "expected a record", words[0]);
            }
            continue;
        }
        if (strcmp(words[0], "end") == 0) {
            if (pending_len != 0u) {
                rc = fail(w, "'raw' bytes without a 'crc' or 'badcrc' line", NULL);
                break;
            }
            if (m != NULL && !m->is_reject) {
                m->can_msg = m->can_msg.type ? m->can_msg : m->msg;
            }
            m = NULL;
            s = NULL;
            continue;
        }
        if (m != NULL) {
            if (strcmp(words[0], "field") == 0 && n >= 3) {
                rc = set_field(&m->msg, words, n, w);
            } else if (strcmp(words[0], "raw") == 0 && n >= 2) {
                long len = parse_hex(join_hex(words, 1, n, hex, sizeof hex), m->raw + m->raw_len,
                                     sizeof m->raw - m->raw_len);
                rc = len < 0 ? fail(w, "bad raw bytes", NULL) : 0;
                m->raw_len += (size_t)(len < 0 ? 0 : len);
            } else if (strcmp(words[0], "crc") == 0) {
                uint8_t frame[HIL_MAX_RAW_FRAME + 2];
                memcpy(frame, m->raw, m->raw_len);
                rc = crc_line(words, n, m->raw, m->raw_len, frame + m->raw_len, w);
                m->serial_len = rc == 0 ? spec_cobs(frame, m->raw_len + 2u, m->serial) : 0u;
            } else if (strcmp(words[0], "serial") == 0 && n == 2) {
                long len = parse_hex(words[1], m->serial, sizeof m->serial);
                rc = len < 0 ? fail(w, "bad serial bytes", NULL) : 0;
                m->serial_len = (size_t)(len < 0 ? 0 : len);
            } else if (strcmp(words[0], "can") == 0 && n >= 3 && m->can_count < VEC_MAX_CAN) {
                hil_can_frame *cf = &m->can[m->can_count++];
                unsigned long id;
                long len = parse_hex(join_hex(words, 2, n, hex, sizeof hex), cf->data, 8);
                if (parse_ulong(words[1], 0x7FF, &id) != 0 || len < 0) {
                    rc = fail(w, "bad CAN frame", NULL);
                }
                cf->id = (uint16_t)id;
                cf->dlc = (uint8_t)(len < 0 ? 0 : len);
            } else if (strcmp(words[0], "canfield") == 0 && n == 3) {
                if (m->can_msg.type == 0u) {
                    m->can_msg = m->msg;
                }
                char *fw[3] = {words[0], words[1], words[2]};
                rc = set_field(&m->can_msg, fw, 3, w);
            } else {
                rc = fail(w, "unexpected line in message", words[0]);
            }
        } else {
            const uint8_t *add_bytes = NULL; /* bytes to append to a serial stream */
            size_t add_len = 0;
            uint8_t frame[HIL_MAX_ENCODED_FRAME + 2];
            uint8_t parsed[2048];
            if (strcmp(words[0], "bytes") == 0 && n >= 2 && !s->is_can) {
                long len = parse_hex(join_hex(words, 1, n, hex, sizeof hex), parsed, sizeof parsed);
                rc = len < 0 ? fail(w, "bad bytes", NULL) : 0;
                add_bytes = parsed;
                add_len = (size_t)(len < 0 ? 0 : len);
            } else if (strcmp(words[0], "wire") == 0 && n == 2 && !s->is_can) {
                long k = find_message(vf, words[1]);
                if (k < 0) {
                    rc = fail(w, "wire: no such message above", words[1]);
                } else {
                    add_bytes = vf->messages[k].serial;
                    add_len = vf->messages[k].serial_len;
                }
            } else if (strcmp(words[0], "raw") == 0 && n >= 2 && !s->is_can) {
                long len = parse_hex(join_hex(words, 1, n, hex, sizeof hex), pending + pending_len,
                                     HIL_MAX_RAW_FRAME - pending_len);
                rc = len < 0 ? fail(w, "bad raw bytes", NULL) : 0;
                pending_len += (size_t)(len < 0 ? 0 : len);
            } else if ((strcmp(words[0], "crc") == 0 || strcmp(words[0], "badcrc") == 0) && !s->is_can) {
                rc = crc_line(words, n, pending, pending_len, pending + pending_len, w);
                add_bytes = frame;
                add_len = rc == 0 ? spec_cobs(pending, pending_len + 2u, frame) : 0u;
                pending_len = 0;
            } else if (strcmp(words[0], "frame") == 0 && n >= 3 && s->is_can) {
                if (grow((void **)&s->frames, s->frame_count, sizeof *s->frames) != 0) {
                    rc = fail(w, "out of memory", NULL);
                    break;
                }
                hil_can_frame *cf = &s->frames[s->frame_count++];
                memset(cf, 0, sizeof *cf);
                unsigned long id;
                long len = parse_hex(join_hex(words, 2, n, hex, sizeof hex), cf->data, 8);
                if (parse_ulong(words[1], 0x7FF, &id) != 0 || len < 0) {
                    rc = fail(w, "bad CAN frame", NULL);
                }
                cf->id = (uint16_t)id;
                cf->dlc = (uint8_t)(len < 0 ? 0 : len);
            } else if (strcmp(words[0], "yield") == 0 && n == (s->is_can ? 3 : 2) &&
                       s->yield_count < VEC_MAX_YIELDS) {
                long y = find_message(vf, words[1]);
                unsigned long role = 0;
                if (y < 0 || (s->is_can && parse_ulong(words[2], 1, &role) != 0)) {
                    rc = fail(w, "yield of an unknown message", words[1]);
                }
                s->yield_roles[s->yield_count] = (uint8_t)role;
                s->yields[s->yield_count++] = (size_t)(y < 0 ? 0 : y);
            } else if (strcmp(words[0], "counter") == 0 && n == 3 && s->counter_count < VEC_MAX_COUNTERS) {
                vec_counter *c = &s->counters[s->counter_count++];
                unsigned long v;
                snprintf(c->name, sizeof c->name, "%s", words[1]);
                rc = parse_ulong(words[2], 0xFFFFFFFFul, &v) != 0 ? fail(w, "bad counter", words[2]) : 0;
                c->value = (uint32_t)v;
            } else {
                rc = fail(w, "unexpected line in stream", words[0]);
            }
            if (rc == 0 && add_len > 0u) {
                uint8_t *p = realloc(s->bytes, s->len + add_len);
                if (p == NULL) {
                    rc = fail(w, "out of memory", NULL);
                    break;
                }
                memcpy(p + s->len, add_bytes, add_len);
                s->bytes = p;
                s->len += add_len;
            }
        }
    }
    for (size_t i = 0; i < vf->stream_count; i++) {
        vf->streams[i].messages = vf->messages;
    }
    if (rc == 0 && (m != NULL || s != NULL)) {
        rc = fail(w, "record without 'end'", NULL);
    }
    fclose(f);
    if (rc != 0) {
        vec_free(vf);
    }
    return rc;
}

void vec_free(vec_file *vf)
{
    for (size_t i = 0; i < vf->stream_count; i++) {
        free(vf->streams[i].bytes);
        free(vf->streams[i].frames);
    }
    free(vf->streams);
    free(vf->messages);
    memset(vf, 0, sizeof *vf);
}

uint32_t vec_counter_value(const vec_stream *s, const char *name)
{
    for (size_t i = 0; i < s->counter_count; i++) {
        if (strcmp(s->counters[i].name, name) == 0) {
            return s->counters[i].value;
        }
    }
    return 0;
}
