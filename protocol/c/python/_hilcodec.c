/*
 * _hilcodec: the firmware's serial codec (hil_proto.c, unchanged) as a CPython extension, so the
 * bench frames and decodes in the same C as the boards. protocol/ccodec.py is its front end and
 * gives it the API of protocol/codec.py; the message objects are protocol/messages.py's own
 * classes, built here directly.
 *
 * Why the CPython API and not cffi: the cost that matters is per frame, and most of it is making
 * the Python message object. Here a decoded SAMPLE becomes a Sample by writing six slots of a
 * freshly allocated instance (no __init__ call, no argument tuple); through cffi the C side
 * cannot make Python objects, so every field would be read back from cdata in Python and the
 * message built there (figures: python -m bench protocol, "codec_stream").
 *
 * This file is glue only: every byte is framed, checked and parsed by hil_proto.c. Anything the C
 * encoder cannot take as is (a field of the wrong type or out of range, a subclass, a non-message)
 * goes to the Python codec's encode_frame, which either encodes it the same way or raises the
 * ProtocolError that names the field: one set of error messages.
 *
 * Counters: the C decoder's are uint32; after each feed they are moved into 64-bit totals here,
 * so the Python-visible counters never wrap.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>

#include <errno.h>
#include <float.h>
#include <math.h>
#include <poll.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../hil_proto.h"

#define NTYPES ((int)HIL_MSG_TYPE_MAX + 1)
#define MAX_FIELDS 17

/* One message class of protocol/messages.py: its type object and the offsets of its slots. */
typedef struct {
    PyTypeObject *cls;
    int nfields;
    Py_ssize_t off[MAX_FIELDS];
} msg_class;

static msg_class classes[NTYPES];
static PyObject *fallback_encode; /* protocol.codec.encode_frame */

/* The fields of each message class, in the order protocol/messages.py declares them. */
static const char *const field_names[NTYPES][MAX_FIELDS + 1] = {
    [HIL_MSG_HELLO] = {"proto_version", "role", "capabilities", "control_period_ns", "name_len", "name", NULL},
    [HIL_MSG_SAMPLE] = {"period", "adc_i1", "adc_i2", "adc_vdc", "encoder", "status", NULL},
    [HIL_MSG_GATES] = {"period", "gates", NULL},
    [HIL_MSG_DUTY] = {"period", "duty", NULL},
    [HIL_MSG_COMMAND] = {"flags", "speed_source", "speed_ref_rad_s", "torque_ref_nm", "flux_ref_wb", NULL},
    [HIL_MSG_TELEMETRY] = {"period", "sector", "speed_source", "state", "gates", "speed_feedback_rad_s",
                           "speed_encoder_rad_s", "speed_raw_rad_s", "speed_lpf_rad_s", "speed_ekf_rad_s",
                           "flux_angle_rad", "ekf_angle_rad", "flux_mag_wb", "torque_est_nm", "torque_ref_nm",
                           "rotor_pos_conv_rad", "rotor_pos_ekf_rad", NULL},
    [HIL_MSG_PARAM_SET] = {"id", "value", NULL},
    [HIL_MSG_PARAM_GET] = {"id", NULL},
    [HIL_MSG_PARAM_VALUE] = {"id", "status", "value", NULL},
    [HIL_MSG_STATUS] = {"period", "state", "fault_code", NULL},
    [HIL_MSG_FAULT] = {"period", "code", "value", NULL},
    [HIL_MSG_HEARTBEAT] = {"counter", NULL},
    [HIL_MSG_SHUTDOWN] = {NULL},
    [HIL_MSG_DUTY_LEGS] = {"period", "duty", "leg_enable", NULL},
    [HIL_MSG_SAMPLE_SENSORS] = {"period", "sensor_set", "status", "adc_ia", "adc_ib", "adc_ic", "adc_vdc",
                                "encoder", "hall", "adc_va", "adc_vb", "adc_vc", "bemf_comparators",
                                "adc_resolver_sin", "adc_resolver_cos", "adc_temperature", NULL},
};

/* The type codes this version defines (0x0E is not one: it has no class). */
static int type_defined(int type)
{
    return (type >= HIL_MSG_HELLO && type <= HIL_MSG_SHUTDOWN) || type == HIL_MSG_DUTY_LEGS ||
           type == HIL_MSG_SAMPLE_SENSORS;
}

#define SLOT(obj, off) (*(PyObject **)((char *)(obj) + (off)))

/* ------------------------------------------------------------------ setup */

static int setup_class(int type, PyObject *cls)
{
    if (!PyType_Check(cls)) {
        PyErr_Format(PyExc_TypeError, "message class for type %d is not a class", type);
        return -1;
    }
    msg_class *mc = &classes[type];
    int n = 0;
    for (; field_names[type][n] != NULL; n++) {
        PyObject *d = PyObject_GetAttrString(cls, field_names[type][n]);
        if (d == NULL) {
            return -1;
        }
        int ok = Py_IS_TYPE(d, &PyMemberDescr_Type) &&
                 ((PyMemberDescrObject *)d)->d_member->type == T_OBJECT_EX &&
                 ((PyMemberDescrObject *)d)->d_common.d_type == (PyTypeObject *)cls;
        if (ok) {
            mc->off[n] = ((PyMemberDescrObject *)d)->d_member->offset;
        }
        Py_DECREF(d);
        if (!ok) {
            PyErr_Format(PyExc_TypeError, "%s.%s is not a slot of the class itself",
                         ((PyTypeObject *)cls)->tp_name, field_names[type][n]);
            return -1;
        }
    }
    Py_INCREF(cls);
    Py_XSETREF(mc->cls, (PyTypeObject *)cls);
    mc->nfields = n;
    return 0;
}

PyDoc_STRVAR(setup_doc, "setup(classes, fallback_encode)\n\n"
                        "classes: {type code: message class} (protocol.messages.MESSAGE_CLASSES);\n"
                        "fallback_encode(msg, seq): the Python codec's encode_frame, for what C cannot take.");

static PyObject *mod_setup(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *mapping, *fallback;
    if (!PyArg_ParseTuple(args, "OO:setup", &mapping, &fallback)) {
        return NULL;
    }
    for (int t = HIL_MSG_HELLO; t < NTYPES; t++) {
        if (!type_defined(t)) {
            continue;
        }
        PyObject *key = PyLong_FromLong(t);
        if (key == NULL) {
            return NULL;
        }
        PyObject *cls = PyObject_GetItem(mapping, key);
        Py_DECREF(key);
        if (cls == NULL) {
            return NULL;
        }
        int rc = setup_class(t, cls);
        Py_DECREF(cls);
        if (rc < 0) {
            return NULL;
        }
    }
    Py_INCREF(fallback);
    Py_XSETREF(fallback_encode, fallback);
    Py_RETURN_NONE;
}

static int ready(void)
{
    if (fallback_encode == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "_hilcodec.setup() was not called (import protocol.ccodec)");
        return 0;
    }
    return 1;
}

/* ------------------------------------------------------------------ hil_msg -> message object */

static PyObject *new_message(int type)
{
    PyTypeObject *cls = classes[type].cls;
    return cls->tp_alloc(cls, 0);
}

/* Steals v; on failure obj is released. */
static int put(PyObject *obj, int type, int i, PyObject *v)
{
    if (v == NULL) {
        return -1;
    }
    SLOT(obj, classes[type].off[i]) = v;
    return 0;
}

#define PUT_U(i, x) put(obj, t, (i), PyLong_FromUnsignedLong((unsigned long)(x)))
#define PUT_F(i, x) put(obj, t, (i), PyFloat_FromDouble((double)(x)))

static PyObject *message_object(const hil_msg *m)
{
    int t = m->type;
    PyObject *obj = new_message(t);
    if (obj == NULL) {
        return NULL;
    }
    int rc = 0;
    switch (t) {
    case HIL_MSG_SAMPLE: {
        const hil_sample *s = &m->u.sample;
        rc = PUT_U(0, s->period) | PUT_U(1, s->adc_i1) | PUT_U(2, s->adc_i2) | PUT_U(3, s->adc_vdc) |
             PUT_U(4, s->encoder) | PUT_U(5, s->status);
        break;
    }
    case HIL_MSG_GATES:
        rc = PUT_U(0, m->u.gates.period) | PUT_U(1, m->u.gates.gates);
        break;
    case HIL_MSG_DUTY: {
        const uint16_t *d = m->u.duty.duty;
        rc = PUT_U(0, m->u.duty.period) |
             put(obj, t, 1, Py_BuildValue("(HHH)", d[0], d[1], d[2]));
        break;
    }
    case HIL_MSG_DUTY_LEGS: {
        const uint16_t *d = m->u.duty_legs.duty;
        rc = PUT_U(0, m->u.duty_legs.period) |
             put(obj, t, 1, Py_BuildValue("(HHH)", d[0], d[1], d[2])) | PUT_U(2, m->u.duty_legs.leg_enable);
        break;
    }
    case HIL_MSG_SAMPLE_SENSORS: {
        const hil_sample_sensors *s = &m->u.sample_sensors;
        const unsigned long v[16] = {s->period,           s->sensor_set,       s->status,
                                     s->adc_ia,           s->adc_ib,           s->adc_ic,
                                     s->adc_vdc,          s->encoder,          s->hall,
                                     s->adc_va,           s->adc_vb,           s->adc_vc,
                                     s->bemf_comparators, s->adc_resolver_sin, s->adc_resolver_cos,
                                     s->adc_temperature};
        for (int i = 0; i < 16 && rc == 0; i++) {
            rc = PUT_U(i, v[i]);
        }
        break;
    }
    case HIL_MSG_TELEMETRY: {
        const hil_telemetry *s = &m->u.telemetry;
        const float f[12] = {s->speed_feedback_rad_s, s->speed_encoder_rad_s, s->speed_raw_rad_s,
                             s->speed_lpf_rad_s,      s->speed_ekf_rad_s,     s->flux_angle_rad,
                             s->ekf_angle_rad,        s->flux_mag_wb,         s->torque_est_nm,
                             s->torque_ref_nm,        s->rotor_pos_conv_rad,  s->rotor_pos_ekf_rad};
        rc = PUT_U(0, s->period) | PUT_U(1, s->sector) | PUT_U(2, s->speed_source) | PUT_U(3, s->state) |
             PUT_U(4, s->gates);
        for (int i = 0; i < 12 && rc == 0; i++) {
            rc = PUT_F(5 + i, f[i]);
        }
        break;
    }
    case HIL_MSG_HELLO: {
        const hil_hello *s = &m->u.hello;
        rc = PUT_U(0, s->proto_version) | PUT_U(1, s->role) | PUT_U(2, s->capabilities) |
             PUT_U(3, s->control_period_ns) | PUT_U(4, s->name_len) |
             put(obj, t, 5, PyBytes_FromStringAndSize(s->name, (Py_ssize_t)s->name_len));
        break;
    }
    case HIL_MSG_COMMAND: {
        const hil_command *s = &m->u.command;
        rc = PUT_U(0, s->flags) | PUT_U(1, s->speed_source) | PUT_F(2, s->speed_ref_rad_s) |
             PUT_F(3, s->torque_ref_nm) | PUT_F(4, s->flux_ref_wb);
        break;
    }
    case HIL_MSG_PARAM_SET:
        rc = PUT_U(0, m->u.param_set.id) | PUT_F(1, m->u.param_set.value);
        break;
    case HIL_MSG_PARAM_GET:
        rc = PUT_U(0, m->u.param_get.id);
        break;
    case HIL_MSG_PARAM_VALUE:
        rc = PUT_U(0, m->u.param_value.id) | PUT_U(1, m->u.param_value.status) | PUT_F(2, m->u.param_value.value);
        break;
    case HIL_MSG_STATUS:
        rc = PUT_U(0, m->u.status.period) | PUT_U(1, m->u.status.state) | PUT_U(2, m->u.status.fault_code);
        break;
    case HIL_MSG_FAULT:
        rc = PUT_U(0, m->u.fault.period) | PUT_U(1, m->u.fault.code) | PUT_F(2, m->u.fault.value);
        break;
    case HIL_MSG_HEARTBEAT:
        rc = PUT_U(0, m->u.heartbeat.counter);
        break;
    default: /* SHUTDOWN: no fields */
        break;
    }
    if (rc != 0) {
        Py_DECREF(obj);
        return NULL;
    }
    return obj;
}

/* ------------------------------------------------------------------ message object -> hil_msg */

/* Each returns 0, or -1 when the value is not one the C encoder takes as is (no exception set):
 * the caller then hands the message to the Python codec. */
static int get_uint(PyObject *obj, Py_ssize_t off, unsigned long max, unsigned long *out)
{
    PyObject *v = SLOT(obj, off);
    if (v == NULL || !PyLong_Check(v)) {
        return -1;
    }
    int overflow;
    long long x = PyLong_AsLongLongAndOverflow(v, &overflow);
    if (overflow || x < 0 || (unsigned long long)x > max) {
        return -1;
    }
    *out = (unsigned long)x;
    return 0;
}

static int get_f32(PyObject *obj, Py_ssize_t off, float *out)
{
    PyObject *v = SLOT(obj, off);
    double d;
    if (v != NULL && PyFloat_Check(v)) {
        d = PyFloat_AS_DOUBLE(v);
    } else if (v != NULL && PyLong_Check(v)) {
        d = PyLong_AsDouble(v);
        if (d == -1.0 && PyErr_Occurred()) {
            PyErr_Clear();
            return -1;
        }
    } else {
        return -1;
    }
    /* struct's '<f': the same rounding, the same NaN bits, the same refusal of a finite value
     * too large for a float32. */
    unsigned char b[4];
    if (PyFloat_Pack4(d, (char *)b, 1) < 0) {
        PyErr_Clear();
        return -1;
    }
    uint32_t u = (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
    memcpy(out, &u, sizeof *out);
    return 0;
}

#define U8 0xFFul
#define U16 0xFFFFul
#define U32 0xFFFFFFFFul
#define GET_AS(ctype, i, max, dst)                                                                         \
    do {                                                                                                   \
        unsigned long v_;                                                                                  \
        if (get_uint(obj, off[i], (max), &v_) < 0) {                                                       \
            return -1;                                                                                     \
        }                                                                                                  \
        (dst) = (ctype)v_;                                                                                 \
    } while (0)
#define GET_U(i, max, dst) GET_AS(uint32_t, i, max, dst)
#define GET_F(i, dst)                                                                                      \
    do {                                                                                                   \
        if (get_f32(obj, off[i], &(dst)) < 0) {                                                            \
            return -1;                                                                                     \
        }                                                                                                  \
    } while (0)

/* The three u16 duties of a DUTY or DUTY_LEGS, or -1 when d is not a tuple of three of them. */
static int get_duties(PyObject *d, uint16_t duty[3])
{
    if (d == NULL || !PyTuple_CheckExact(d) || PyTuple_GET_SIZE(d) != 3) {
        return -1;
    }
    for (Py_ssize_t i = 0; i < 3; i++) {
        PyObject *v = PyTuple_GET_ITEM(d, i);
        int overflow;
        long long x = PyLong_Check(v) ? PyLong_AsLongLongAndOverflow(v, &overflow) : -1;
        if (!PyLong_Check(v) || overflow || x < 0 || x > 0xFFFF) {
            return -1;
        }
        duty[i] = (uint16_t)x;
    }
    return 0;
}

/* The hil_msg of obj (an instance of exactly one of the message classes), or -1. */
static int message_struct(PyObject *obj, hil_msg *m)
{
    PyTypeObject *tp = Py_TYPE(obj);
    int t;
    if (tp == classes[HIL_MSG_SAMPLE].cls) { /* the hot ones first */
        t = HIL_MSG_SAMPLE;
    } else if (tp == classes[HIL_MSG_GATES].cls) {
        t = HIL_MSG_GATES;
    } else {
        for (t = HIL_MSG_HELLO; t < NTYPES && classes[t].cls != tp; t++) {
        }
        if (t == NTYPES) {
            return -1;
        }
    }
    const Py_ssize_t *off = classes[t].off;
    m->type = (uint8_t)t;
    switch (t) {
    case HIL_MSG_SAMPLE:
        /* the 12-bit and 4-bit limits are the codec's own (hil_frame_encode answers HIL_ERR_RANGE) */
        GET_U(0, U32, m->u.sample.period);
        GET_AS(uint16_t, 1, U16, m->u.sample.adc_i1);
        GET_AS(uint16_t, 2, U16, m->u.sample.adc_i2);
        GET_AS(uint16_t, 3, U16, m->u.sample.adc_vdc);
        GET_AS(uint16_t, 4, U16, m->u.sample.encoder);
        GET_AS(uint8_t, 5, U8, m->u.sample.status);
        break;
    case HIL_MSG_GATES:
        GET_U(0, U32, m->u.gates.period);
        GET_AS(uint8_t, 1, U8, m->u.gates.gates);
        break;
    case HIL_MSG_DUTY:
        GET_U(0, U32, m->u.duty.period);
        if (get_duties(SLOT(obj, off[1]), m->u.duty.duty) < 0) {
            return -1;
        }
        break;
    case HIL_MSG_DUTY_LEGS:
        GET_U(0, U32, m->u.duty_legs.period);
        if (get_duties(SLOT(obj, off[1]), m->u.duty_legs.duty) < 0) {
            return -1;
        }
        GET_AS(uint8_t, 2, U8, m->u.duty_legs.leg_enable);
        break;
    case HIL_MSG_SAMPLE_SENSORS: {
        /* every field read at its C width; the reserved-bit limits are the codec's own
         * (HIL_ERR_RANGE), and a value that fits no C field goes to the Python codec, which
         * ignores the fields of clear bits as hil_proto.c does */
        hil_sample_sensors *s = &m->u.sample_sensors;
        uint16_t *const u16[11] = {&s->adc_ia, &s->adc_ib, &s->adc_ic, &s->adc_vdc, &s->encoder, &s->adc_va,
                                   &s->adc_vb, &s->adc_vc, &s->adc_resolver_sin, &s->adc_resolver_cos,
                                   &s->adc_temperature};
        static const int u16_slot[11] = {3, 4, 5, 6, 7, 9, 10, 11, 13, 14, 15};
        GET_U(0, U32, s->period);
        GET_AS(uint16_t, 1, U16, s->sensor_set);
        GET_AS(uint8_t, 2, U8, s->status);
        GET_AS(uint8_t, 8, U8, s->hall);
        GET_AS(uint8_t, 12, U8, s->bemf_comparators);
        for (int i = 0; i < 11; i++) {
            GET_AS(uint16_t, u16_slot[i], U16, *u16[i]);
        }
        break;
    }
    case HIL_MSG_TELEMETRY: {
        hil_telemetry *s = &m->u.telemetry;
        float *const f[12] = {&s->speed_feedback_rad_s, &s->speed_encoder_rad_s, &s->speed_raw_rad_s,
                              &s->speed_lpf_rad_s,      &s->speed_ekf_rad_s,     &s->flux_angle_rad,
                              &s->ekf_angle_rad,        &s->flux_mag_wb,         &s->torque_est_nm,
                              &s->torque_ref_nm,        &s->rotor_pos_conv_rad,  &s->rotor_pos_ekf_rad};
        GET_U(0, U32, s->period);
        GET_AS(uint8_t, 1, U8, s->sector);
        GET_AS(uint8_t, 2, U8, s->speed_source);
        GET_AS(uint8_t, 3, U8, s->state);
        GET_AS(uint8_t, 4, U8, s->gates);
        for (int i = 0; i < 12; i++) {
            GET_F(5 + i, *f[i]);
        }
        break;
    }
    case HIL_MSG_HELLO: {
        hil_hello *s = &m->u.hello;
        GET_AS(uint8_t, 0, U8, s->proto_version);
        GET_AS(uint8_t, 1, U8, s->role);
        GET_AS(uint16_t, 2, U16, s->capabilities);
        GET_U(3, U32, s->control_period_ns);
        GET_AS(uint8_t, 4, HIL_NAME_MAX, s->name_len);
        PyObject *name = SLOT(obj, off[5]);
        if (name == NULL || !PyBytes_CheckExact(name) || PyBytes_GET_SIZE(name) != (Py_ssize_t)s->name_len) {
            return -1;
        }
        memcpy(s->name, PyBytes_AS_STRING(name), s->name_len);
        break;
    }
    case HIL_MSG_COMMAND:
        GET_AS(uint8_t, 0, U8, m->u.command.flags);
        GET_AS(uint8_t, 1, U8, m->u.command.speed_source);
        GET_F(2, m->u.command.speed_ref_rad_s);
        GET_F(3, m->u.command.torque_ref_nm);
        GET_F(4, m->u.command.flux_ref_wb);
        break;
    case HIL_MSG_PARAM_SET:
        GET_AS(uint16_t, 0, U16, m->u.param_set.id);
        GET_F(1, m->u.param_set.value);
        break;
    case HIL_MSG_PARAM_GET:
        GET_AS(uint16_t, 0, U16, m->u.param_get.id);
        break;
    case HIL_MSG_PARAM_VALUE:
        GET_AS(uint16_t, 0, U16, m->u.param_value.id);
        GET_AS(uint8_t, 1, U8, m->u.param_value.status);
        GET_F(2, m->u.param_value.value);
        break;
    case HIL_MSG_STATUS:
        GET_U(0, U32, m->u.status.period);
        GET_AS(uint8_t, 1, U8, m->u.status.state);
        GET_AS(uint16_t, 2, U16, m->u.status.fault_code);
        break;
    case HIL_MSG_FAULT:
        GET_U(0, U32, m->u.fault.period);
        GET_AS(uint16_t, 1, U16, m->u.fault.code);
        GET_F(2, m->u.fault.value);
        break;
    case HIL_MSG_HEARTBEAT:
        GET_U(0, U32, m->u.heartbeat.counter);
        break;
    default: /* SHUTDOWN */
        break;
    }
    return 0;
}

/* One frame of msg with sequence number seq; NULL with an exception (from the Python codec) when
 * it cannot be encoded. */
static PyObject *frame_bytes(PyObject *msg, unsigned seq)
{
    hil_msg m;
    if (message_struct(msg, &m) == 0) {
        uint8_t out[HIL_MAX_ENCODED_FRAME];
        m.seq = (uint8_t)seq;
        int n = hil_frame_encode(&m, out, sizeof out);
        if (n > 0) {
            return PyBytes_FromStringAndSize((const char *)out, n);
        }
    }
    /* Not for the C encoder as is: the Python codec encodes it alike or raises the ProtocolError. */
    return PyObject_CallFunction(fallback_encode, "OI", msg, seq);
}

/* seq & 0xFF for any int, as Python computes it. */
static int seq_of(PyObject *v, unsigned *seq)
{
    if (PyLong_Check(v)) {
        int overflow;
        long long x = PyLong_AsLongLongAndOverflow(v, &overflow);
        if (!overflow) {
            *seq = (unsigned)(x & 0xFF);
            return 0;
        }
    }
    PyObject *mask = PyLong_FromLong(0xFF);
    if (mask == NULL) {
        return -1;
    }
    PyObject *r = PyNumber_And(v, mask);
    Py_DECREF(mask);
    if (r == NULL) {
        return -1;
    }
    long x = PyLong_AsLong(r);
    Py_DECREF(r);
    if (x == -1 && PyErr_Occurred()) {
        return -1;
    }
    *seq = (unsigned)x;
    return 0;
}

PyDoc_STRVAR(encode_frame_doc, "encode_frame(msg, seq) -> bytes\n\n"
                               "One serial frame: COBS(header | payload | crc16) followed by 0x00.");

static PyObject *mod_encode_frame(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    unsigned seq;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "encode_frame(msg, seq) takes 2 arguments");
        return NULL;
    }
    if (!ready() || seq_of(args[1], &seq) < 0) {
        return NULL;
    }
    return frame_bytes(args[0], seq);
}

PyDoc_STRVAR(crc16_doc, "crc16(data) -> int\n\nCRC-16/CCITT-FALSE of a bytes-like object (hil_crc16).");

static PyObject *mod_crc16(PyObject *self, PyObject *arg)
{
    (void)self;
    Py_buffer view;
    if (PyObject_GetBuffer(arg, &view, PyBUF_SIMPLE) < 0) {
        return NULL;
    }
    uint16_t crc = hil_crc16((const uint8_t *)view.buf, (size_t)view.len);
    PyBuffer_Release(&view);
    return PyLong_FromLong(crc);
}

/* ------------------------------------------------------------------ FrameEncoder */

typedef struct {
    PyObject_HEAD
    unsigned seq;
} EncoderObject;

static int Encoder_init(EncoderObject *self, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"first_seq", NULL};
    PyObject *first = NULL;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "|O:FrameEncoder", kwlist, &first)) {
        return -1;
    }
    unsigned seq = 0;
    if (first != NULL && seq_of(first, &seq) < 0) {
        return -1;
    }
    self->seq = seq;
    return 0;
}

static PyObject *Encoder_encode(EncoderObject *self, PyObject *msg)
{
    if (!ready()) {
        return NULL;
    }
    PyObject *frame = frame_bytes(msg, self->seq);
    if (frame != NULL) {
        self->seq = (self->seq + 1u) & 0xFFu; /* a message that failed to encode does not use a number */
    }
    return frame;
}

static PyObject *Encoder_get_seq(EncoderObject *self, void *closure)
{
    (void)closure;
    return PyLong_FromUnsignedLong(self->seq);
}

static int Encoder_set_seq(EncoderObject *self, PyObject *v, void *closure)
{
    (void)closure;
    if (v == NULL) {
        PyErr_SetString(PyExc_AttributeError, "seq cannot be deleted");
        return -1;
    }
    unsigned seq;
    if (seq_of(v, &seq) < 0) {
        return -1;
    }
    self->seq = seq;
    return 0;
}

static PyMethodDef Encoder_methods[] = {
    {"encode", (PyCFunction)Encoder_encode, METH_O,
     "encode(msg) -> bytes: the next frame, numbered with this encoder's u8 sequence counter"},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef Encoder_getset[] = {
    {"seq", (getter)Encoder_get_seq, (setter)Encoder_set_seq, "sequence number of the next frame (u8)", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject EncoderType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "protocol.ccodec.FrameEncoder",
    .tp_basicsize = sizeof(EncoderObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = PyDoc_STR("FrameEncoder(first_seq=0): encodes messages into serial frames with hil_frame_encode, "
                        "numbering them with its own u8 sequence counter."),
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Encoder_init,
    .tp_methods = Encoder_methods,
    .tp_getset = Encoder_getset,
};

/* ------------------------------------------------------------------ StreamDecoder */

enum { C_FRAMES_OK, C_CRC, C_FRAMING, C_SEQ_GAPS, C_UNKNOWN, C_VERSION, C_LENGTH, NCOUNTERS };
static const char *const counter_names[NCOUNTERS] = {"frames_ok", "crc_errors", "framing_errors", "seq_gaps",
                                                     "unknown_types", "version_errors", "length_errors"};
static PyObject *counter_keys[NCOUNTERS];

typedef struct {
    PyObject_HEAD
    hil_decoder d;
    unsigned long long total[NCOUNTERS];
} DecoderObject;

static uint32_t *decoder_counter(hil_decoder *d, int i)
{
    switch (i) {
    case C_FRAMES_OK:
        return &d->frames_ok;
    case C_CRC:
        return &d->crc_errors;
    case C_FRAMING:
        return &d->framing_errors;
    case C_SEQ_GAPS:
        return &d->seq_gaps;
    case C_UNKNOWN:
        return &d->unknown_types;
    case C_VERSION:
        return &d->version_errors;
    default:
        return &d->length_errors;
    }
}

static void decoder_collect(DecoderObject *self)
{
    hil_decoder *d = &self->d;
    self->total[C_FRAMES_OK] += d->frames_ok;
    self->total[C_CRC] += d->crc_errors;
    self->total[C_FRAMING] += d->framing_errors;
    self->total[C_SEQ_GAPS] += d->seq_gaps;
    self->total[C_UNKNOWN] += d->unknown_types;
    self->total[C_VERSION] += d->version_errors;
    self->total[C_LENGTH] += d->length_errors;
    d->frames_ok = d->crc_errors = d->framing_errors = d->seq_gaps = 0;
    d->unknown_types = d->version_errors = d->length_errors = 0;
}

static int Decoder_init(DecoderObject *self, PyObject *args, PyObject *kwds)
{
    if (PyTuple_GET_SIZE(args) != 0 || (kwds != NULL && PyDict_GET_SIZE(kwds) != 0)) {
        PyErr_SetString(PyExc_TypeError, "StreamDecoder() takes no arguments");
        return -1;
    }
    hil_decoder_init(&self->d);
    memset(self->total, 0, sizeof self->total);
    return 0;
}

/* Decodes data[0:len] into list out (appends). -1 with an exception on failure (memory only). */
static int decode_into(DecoderObject *self, const uint8_t *p, size_t len, PyObject *out)
{
    int rc = 0;
    while (len > 0u) {
        hil_msg m;
        int got;
        size_t used = hil_decoder_feed_buf(&self->d, p, len, &m, &got);
        p += used;
        len -= used;
        if (got) {
            PyObject *obj = message_object(&m);
            if (obj == NULL || PyList_Append(out, obj) < 0) {
                Py_XDECREF(obj);
                rc = -1; /* keep decoding: the counters stay those of the whole input */
                continue;
            }
            Py_DECREF(obj);
        }
    }
    decoder_collect(self);
    return rc;
}

static PyObject *Decoder_feed(DecoderObject *self, PyObject *data)
{
    if (!ready()) {
        return NULL;
    }
    PyObject *out = PyList_New(0);
    if (out == NULL) {
        return NULL;
    }
    int rc;
    if (PyBytes_CheckExact(data)) {
        rc = decode_into(self, (const uint8_t *)PyBytes_AS_STRING(data), (size_t)PyBytes_GET_SIZE(data), out);
    } else {
        Py_buffer view;
        if (PyObject_GetBuffer(data, &view, PyBUF_SIMPLE) < 0) {
            Py_DECREF(out);
            return NULL;
        }
        rc = decode_into(self, (const uint8_t *)view.buf, (size_t)view.len, out);
        PyBuffer_Release(&view);
    }
    if (rc < 0) {
        Py_DECREF(out);
        return NULL;
    }
    return out;
}

static PyObject *Decoder_reset(DecoderObject *self, PyObject *unused)
{
    (void)unused;
    /* forgets the partial frame and the sequence history; counters, last_seq and
     * last_bad_version are kept, as in protocol/codec.py */
    uint8_t last_seq = self->d.last_seq, last_bad = self->d.last_bad_version;
    hil_decoder_init(&self->d);
    self->d.last_seq = last_seq;
    self->d.last_bad_version = last_bad;
    Py_RETURN_NONE;
}

static PyObject *Decoder_get_counter(DecoderObject *self, void *closure)
{
    return PyLong_FromUnsignedLongLong(self->total[(intptr_t)closure]);
}

static int Decoder_set_counter(DecoderObject *self, PyObject *v, void *closure)
{
    if (v == NULL) {
        PyErr_SetString(PyExc_AttributeError, "counters cannot be deleted");
        return -1;
    }
    unsigned long long x = PyLong_AsUnsignedLongLong(v);
    if (x == (unsigned long long)-1 && PyErr_Occurred()) {
        return -1;
    }
    self->total[(intptr_t)closure] = x;
    *decoder_counter(&self->d, (int)(intptr_t)closure) = 0;
    return 0;
}

static PyObject *Decoder_get_u8(DecoderObject *self, void *closure)
{
    return PyLong_FromLong(closure ? self->d.last_bad_version : self->d.last_seq);
}

static int Decoder_set_u8(DecoderObject *self, PyObject *v, void *closure)
{
    if (v == NULL) {
        PyErr_SetString(PyExc_AttributeError, "cannot be deleted");
        return -1;
    }
    long x = PyLong_AsLong(v);
    if (x == -1 && PyErr_Occurred()) {
        return -1;
    }
    if (x < 0 || x > 0xFF) {
        PyErr_Format(PyExc_ValueError, "%s must be 0..255, got %ld", closure ? "last_bad_version" : "last_seq", x);
        return -1;
    }
    if (closure) {
        self->d.last_bad_version = (uint8_t)x;
    } else {
        self->d.last_seq = (uint8_t)x;
    }
    return 0;
}

static PyObject *Decoder_get_counters(DecoderObject *self, void *closure)
{
    (void)closure;
    PyObject *dict = PyDict_New();
    if (dict == NULL) {
        return NULL;
    }
    for (int i = 0; i < NCOUNTERS; i++) {
        PyObject *v = PyLong_FromUnsignedLongLong(self->total[i]);
        if (v == NULL || PyDict_SetItem(dict, counter_keys[i], v) < 0) {
            Py_XDECREF(v);
            Py_DECREF(dict);
            return NULL;
        }
        Py_DECREF(v);
    }
    return dict;
}

static PyObject *Decoder_get_buffered(DecoderObject *self, void *closure)
{
    (void)closure;
    /* encoded bytes held waiting for a delimiter; none while discarding an overlong frame */
    return PyLong_FromSize_t(self->d.overflow ? 0u : self->d.encoded_len);
}

static PyMethodDef Decoder_methods[] = {
    {"feed", (PyCFunction)Decoder_feed, METH_O,
     "feed(data) -> list: messages completed by the bytes-like data, in order; bad frames are counted, "
     "never raised"},
    {"reset", (PyCFunction)Decoder_reset, METH_NOARGS,
     "reset(): forgets a partial frame and the sequence history (counters are kept)"},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef Decoder_getset[] = {
    {"frames_ok", (getter)Decoder_get_counter, (setter)Decoder_set_counter, NULL, (void *)(intptr_t)C_FRAMES_OK},
    {"crc_errors", (getter)Decoder_get_counter, (setter)Decoder_set_counter, NULL, (void *)(intptr_t)C_CRC},
    {"framing_errors", (getter)Decoder_get_counter, (setter)Decoder_set_counter, NULL, (void *)(intptr_t)C_FRAMING},
    {"seq_gaps", (getter)Decoder_get_counter, (setter)Decoder_set_counter, NULL, (void *)(intptr_t)C_SEQ_GAPS},
    {"unknown_types", (getter)Decoder_get_counter, (setter)Decoder_set_counter, NULL, (void *)(intptr_t)C_UNKNOWN},
    {"version_errors", (getter)Decoder_get_counter, (setter)Decoder_set_counter, NULL, (void *)(intptr_t)C_VERSION},
    {"length_errors", (getter)Decoder_get_counter, (setter)Decoder_set_counter, NULL, (void *)(intptr_t)C_LENGTH},
    {"last_seq", (getter)Decoder_get_u8, (setter)Decoder_set_u8, "sequence number of the last frame accepted",
     NULL},
    {"last_bad_version", (getter)Decoder_get_u8, (setter)Decoder_set_u8,
     "header version of the last frame rejected for its version", (void *)1},
    {"counters", (getter)Decoder_get_counters, NULL, "the seven counters as a dict (COUNTER_NAMES order)", NULL},
    {"buffered", (getter)Decoder_get_buffered, NULL, "bytes held waiting for a delimiter (at most 71)", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject DecoderType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "protocol.ccodec.StreamDecoder",
    .tp_basicsize = sizeof(DecoderObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = PyDoc_STR("StreamDecoder(): turns a byte stream into messages with the firmware's hil_decoder; "
                        "never raises on bad input. Same counters and rules as protocol.codec.StreamDecoder."),
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Decoder_init,
    .tp_methods = Decoder_methods,
    .tp_getset = Decoder_getset,
};


/* ------------------------------------------------------------------ one period, in-process */

typedef size_t (*fw_exchange_fn)(void *fw, const uint8_t *rx, size_t rx_len, uint8_t *tx, size_t tx_cap);

#define EXCHANGE_TX_CAP 4096u

static int append_bytes(PyObject *bytearray, const uint8_t *p, size_t n)
{
    if (bytearray == Py_None || n == 0u) {
        return 0;
    }
    Py_ssize_t old = PyByteArray_GET_SIZE(bytearray);
    if (PyByteArray_Resize(bytearray, old + (Py_ssize_t)n) < 0) {
        return -1;
    }
    memcpy(PyByteArray_AS_STRING(bytearray) + old, p, n);
    return 0;
}

static size_t count_delimiters(const uint8_t *p, size_t n)
{
    size_t count = 0;
    for (size_t i = 0; i < n; i++) {
        count += (p[i] == 0u);
    }
    return count;
}

PyDoc_STRVAR(exchange_sample_doc,
"exchange_sample(exchange, fw, encoder, decoder, capture_out, capture_in, counts, inbox, period,\n"
"                adc_i1, adc_i2, adc_vdc, encoder_count, status) -> None\n\n"
"One lockstep period with firmware in this process (hil_fw_abi.h), in one call: SAMPLE is\n"
"encoded by the bench's C codec with encoder's sequence number, handed to the firmware's\n"
"hil_fw_exchange (address `exchange`, instance `fw`) which decodes it with its own codec and\n"
"answers; the answer bytes are decoded by `decoder`. Every byte still crosses both codecs; what\n"
"is saved is the Python between them. The raw frames are appended to the bytearrays\n"
"capture_out and capture_in (None: not captured), the decoded messages go to inbox.extend(),\n"
"and counts (a writable buffer of 5 native int64: frames out, frames in, bytes out, bytes in,\n"
"closed) gains 1, the frames the firmware sent and both byte counts. A non-zero `closed`\n"
"(set by the link before it destroys the instance) refuses the call with ValueError, so a\n"
"caller holding the arguments can never reach a freed instance.");

static PyObject *str_extend; /* "extend", interned at module init */

static PyObject *exchange_period(void *fn_addr, void *fw, EncoderObject *enc, DecoderObject *dec,
                                 PyObject *capture_out, PyObject *capture_in, PyObject *inbox,
                                 PyObject *const *fields, int64_t counts[5]);

/* The codec arguments of exchange_sample and exchange_periods, a[0..4]: the bench's C encoder and
 * decoder, the two captures (bytearrays or None) and the counts (a writable buffer of 5 int64,
 * taken into *counts: release it). 0, or -1 with TypeError/ValueError naming `who`. */
static int codec_args(const char *who, PyObject *const *a, Py_buffer *counts)
{
    if (!PyObject_TypeCheck(a[0], &EncoderType) || !PyObject_TypeCheck(a[1], &DecoderType)) {
        PyErr_Format(PyExc_TypeError, "%s: needs a protocol.ccodec FrameEncoder and StreamDecoder", who);
        return -1;
    }
    for (int i = 2; i < 4; i++) {
        if (a[i] != Py_None && !PyByteArray_CheckExact(a[i])) {
            PyErr_Format(PyExc_TypeError, "%s: captures are bytearrays or None", who);
            return -1;
        }
    }
    if (PyObject_GetBuffer(a[4], counts, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) {
        return -1;
    }
    if (counts->len < (Py_ssize_t)(5 * sizeof(int64_t))) {
        PyBuffer_Release(counts);
        PyErr_Format(PyExc_ValueError, "%s: counts must hold 5 int64", who);
        return -1;
    }
    return 0;
}

static PyObject *mod_exchange_sample(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 14) {
        PyErr_SetString(PyExc_TypeError, "exchange_sample takes 14 arguments");
        return NULL;
    }
    if (!ready()) {
        return NULL;
    }
    void *fn_addr = PyLong_AsVoidPtr(args[0]);
    void *fw = PyLong_AsVoidPtr(args[1]);
    if (PyErr_Occurred()) {
        return NULL;
    }
    if (fn_addr == NULL || fw == NULL) {
        PyErr_SetString(PyExc_ValueError, "exchange_sample: null exchange function or instance");
        return NULL;
    }
    Py_buffer counts_view;
    if (codec_args("exchange_sample", args + 2, &counts_view) < 0) {
        return NULL;
    }
    EncoderObject *enc = (EncoderObject *)args[2];
    DecoderObject *dec = (DecoderObject *)args[3];
    int64_t counts[5];
    memcpy(counts, counts_view.buf, sizeof counts);
    if (counts[4] != 0) {
        PyBuffer_Release(&counts_view);
        PyErr_SetString(PyExc_ValueError, "exchange_sample: the firmware instance is closed");
        return NULL;
    }
    PyObject *result = exchange_period(fn_addr, fw, enc, dec, args[4], args[5], args[7], args + 8, counts);
    memcpy(counts_view.buf, counts, sizeof counts);
    PyBuffer_Release(&counts_view);
    return result;
}

/* SAMPLE from its six fields (period, adc_i1, adc_i2, adc_vdc, encoder, status) encoded into
 * frame with enc's sequence number (then advanced) and appended to capture_out: the frame's
 * length, or -1 with ValueError naming `who` (a field out of range) or a memory error. */
static int encode_sample_frame(const char *who, PyObject *const *fields, EncoderObject *enc,
                               PyObject *capture_out, uint8_t frame[HIL_MAX_ENCODED_FRAME])
{
    unsigned long v[6];
    static const unsigned long max[6] = {0xFFFFFFFFul, 0xFFFFul, 0xFFFFul, 0xFFFFul, 0xFFFFul, 0x0Ful};
    for (int i = 0; i < 6; i++) {
        v[i] = PyLong_AsUnsignedLong(fields[i]);
        if (PyErr_Occurred() || v[i] > max[i]) {
            PyErr_Clear();
            PyErr_Format(PyExc_ValueError, "%s: SAMPLE field %d out of range", who, i);
            return -1;
        }
    }
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_SAMPLE;
    m.seq = (uint8_t)enc->seq;
    m.u.sample.period = (uint32_t)v[0];
    m.u.sample.adc_i1 = (uint16_t)v[1];
    m.u.sample.adc_i2 = (uint16_t)v[2];
    m.u.sample.adc_vdc = (uint16_t)v[3];
    m.u.sample.encoder = (uint16_t)v[4];
    m.u.sample.status = (uint8_t)v[5];
    int n_frame = hil_frame_encode(&m, frame, HIL_MAX_ENCODED_FRAME);
    if (n_frame <= 0) {
        PyErr_Format(PyExc_ValueError, "%s: SAMPLE did not encode", who);
        return -1;
    }
    enc->seq = (enc->seq + 1u) & 0xFFu;
    if (append_bytes(capture_out, frame, (size_t)n_frame) < 0) {
        return -1;
    }
    return n_frame;
}

#define LOOP_QUEUE 32
enum { LOOP_DONE = 0, LOOP_HANDED = 1, LOOP_PENDING = 2, LOOP_STOPPED = 3, LOOP_LINK_ERROR = 4 };

/* The answers queued between periods: decoded structs, or (at entry) inbox's message objects. */
typedef struct {
    hil_msg m[LOOP_QUEUE];
    PyObject *obj[LOOP_QUEUE]; /* owned when not NULL: an object taken from inbox */
    int head, n;
} answer_queue;

static int append_new(PyObject *list, PyObject *item);

/* Appends the queue's messages from its head to list as message objects and empties the queue;
 * -1 on a failure (memory), the objects released all the same. */
static int queue_to_list(answer_queue *q, PyObject *list)
{
    int rc = 0;
    for (int i = q->head; i < q->n; i++) {
        PyObject *o = q->obj[i];
        q->obj[i] = NULL;
        if (o == NULL && rc == 0) {
            o = message_object(&q->m[i]);
        }
        if (o != NULL && rc == 0 && PyList_Append(list, o) < 0) {
            rc = -1;
        }
        if (o == NULL) {
            rc = -1;
        }
        Py_XDECREF(o);
    }
    q->head = q->n = 0;
    return rc;
}

/* The queue, then spill (when not NULL, released here), onto inbox; -1 with an exception. */
static int queue_to_inbox(answer_queue *q, PyObject *spill, PyObject *inbox)
{
    PyObject *list = PyList_New(0);
    int rc = -1;
    if (list != NULL) {
        rc = queue_to_list(q, list);
    } else {
        for (int i = q->head; i < q->n; i++) {
            Py_CLEAR(q->obj[i]);
        }
        q->head = q->n = 0;
    }
    if (rc == 0 && spill != NULL) {
        rc = PyList_SetSlice(list, PyList_GET_SIZE(list), PyList_GET_SIZE(list), spill);
    }
    Py_XDECREF(spill);
    if (rc == 0 && PyList_GET_SIZE(list) > 0) {
        PyObject *r = PyObject_CallMethodOneArg(inbox, str_extend, list);
        rc = r == NULL ? -1 : 0;
        Py_XDECREF(r);
    }
    Py_XDECREF(list);
    return rc;
}

static int append_new(PyObject *list, PyObject *item)
{
    if (item == NULL) {
        return -1;
    }
    int rc = PyList_Append(list, item);
    Py_DECREF(item);
    return rc;
}

/* Decodes p[0:len] onto q, or as message objects onto the list *spill when q is NULL or once it
 * is full (the list is then made here); then moves the decoder's counters into its totals. 0, or
 * -1 with an exception (decoding goes on: the counters stay those of the whole input). */
static int decode_onto(DecoderObject *dec, const uint8_t *p, size_t len, answer_queue *q, PyObject **spill)
{
    int rc = 0;
    while (len > 0u) {
        hil_msg a;
        int got;
        size_t used = hil_decoder_feed_buf(&dec->d, p, len, &a, &got);
        p += used;
        len -= used;
        if (!got) {
            continue;
        }
        if (*spill == NULL && q->n == LOOP_QUEUE) {   /* (no list yet: q is not NULL) */
            /* more answers than a period ever has: from here on the queue is a list of
             * message objects, and the caller takes the period */
            *spill = PyList_New(0);
            if (*spill == NULL || queue_to_list(q, *spill) < 0) {
                rc = -1;
            }
        }
        if (*spill != NULL) {
            if (rc < 0 || append_new(*spill, message_object(&a)) < 0) {
                rc = -1;
            }
            continue;
        }
        q->m[q->n] = a;
        q->obj[q->n] = NULL;
        q->n++;
    }
    decoder_collect(dec);
    return rc;
}

/* One period's exchange with the firmware: SAMPLE from its six fields (encode_sample_frame),
 * through `exchange`, both directions captured and counted in counts[0..3], the answers decoded
 * by decode_onto. 0, or -1 with an exception. Not inlined: bench/period_instructions.py counts it
 * by name. */
__attribute__((noinline))
/* Whether this interpreter has a Python thread besides the caller's (the Modbus port in thread
 * mode, the live server), asked once a period: a few loads. Read with the GIL held: a thread
 * state is added by the thread that starts it and removed by the thread that ends, each holding
 * the GIL, so the list does not change under the caller. */
static int other_threads(void)
{
    PyThreadState *me = PyThreadState_Get();
    PyThreadState *head = PyInterpreterState_ThreadHead(PyThreadState_GetInterpreter(me));
    return head != me || PyThreadState_Next(head) != NULL;
}

/* One call of the board's exchange, without the GIL when `release_gil` (see exchange_frames). */
static size_t board_call(fw_exchange_fn exchange, void *fw, const uint8_t *rx, size_t rx_len, uint8_t *tx,
                         size_t tx_cap, int release_gil)
{
    size_t n;
    if (!release_gil) {
        return exchange(fw, rx, rx_len, tx, tx_cap);
    }
    Py_BEGIN_ALLOW_THREADS
    n = exchange(fw, rx, rx_len, tx, tx_cap);
    Py_END_ALLOW_THREADS
    return n;
}

static int exchange_frames(const char *who, fw_exchange_fn exchange, void *fw, EncoderObject *enc,
                           DecoderObject *dec, PyObject *capture_out, PyObject *capture_in,
                           PyObject *const *fields, int64_t *counts, answer_queue *q, PyObject **spill,
                           int release_gil)
{
    uint8_t frame[HIL_MAX_ENCODED_FRAME];
    int n_frame = encode_sample_frame(who, fields, enc, capture_out, frame);
    if (n_frame < 0) {
        return -1;
    }
    uint8_t tx[EXCHANGE_TX_CAP];
    size_t frames_in = 0, bytes_in = 0;
    int rc = 0;
    size_t n;
    /* The board runs without the GIL, as a ctypes call would: the bench's other threads (the
     * Modbus port in thread mode, the live server) can take the interpreter here, between
     * periods, when they wake before the loop takes it back, instead of only once per switch
     * interval (5 ms): a Modbus request took 61 ms without this, 9.4 ms with it (bench modbus,
     * docs/modbus.md). The call touches only the frames on this stack and the board's own
     * instance. With no other thread (release_gil 0: other_threads()) the release would only
     * cost its mutex operations, about 400 instructions a period. */
    n = board_call(exchange, fw, frame, (size_t)n_frame, tx, sizeof tx, release_gil);
    while (n > 0u) {
        frames_in += count_delimiters(tx, n);
        bytes_in += n;
        if (append_bytes(capture_in, tx, n) < 0) {
            rc = -1;
        }
        if (decode_onto(dec, tx, n, q, spill) < 0) {
            rc = -1;
        }
        if (n < sizeof tx) {
            break;
        }
        n = board_call(exchange, fw, NULL, 0u, tx, sizeof tx, release_gil);  /* drain what did not fit */
    }
    counts[0] += 1;
    counts[1] += (int64_t)frames_in;
    counts[2] += n_frame;
    counts[3] += (int64_t)bytes_in;
    return rc;
}

/* exchange_sample less its argument checks: counts[0..3] are updated in place. */
static PyObject *exchange_period(void *fn_addr, void *fw, EncoderObject *enc, DecoderObject *dec,
                                 PyObject *capture_out, PyObject *capture_in, PyObject *inbox,
                                 PyObject *const *fields, int64_t counts[5])
{
    PyObject *out = PyList_New(0);
    if (out == NULL) {
        return NULL;
    }
    if (exchange_frames("exchange_sample", (fw_exchange_fn)(uintptr_t)fn_addr, fw, enc, dec, capture_out,
                        capture_in, fields, counts, NULL, &out, other_threads()) < 0) {
        Py_DECREF(out);
        return NULL;
    }
    PyObject *r = PyObject_CallMethodOneArg(inbox, str_extend, out);
    Py_DECREF(out);
    if (r == NULL) {
        return NULL;
    }
    Py_DECREF(r);
    Py_RETURN_NONE;
}

/* ------------------------------------------------------------------ plain periods, in-process */

PyDoc_STRVAR(exchange_periods_doc,
"exchange_periods(target, sample, truth, step, stage, seal, publish_every, count, stop, answer,\n"
"                 live_every) -> (done, state, extra)\n\n"
"The bench's lockstep period loop, in C, for a run of plain periods: no Python frame runs\n"
"between them. target is either exchange_sample's first eight arguments (exchange, fw, encoder,\n"
"decoder, capture_out, capture_in, counts, inbox: a firmware in this process), or ten for a\n"
"serial line's file descriptor (fd, answer_timeout_s, write_timeout_s, encoder, decoder,\n"
"capture_out, capture_in, counts, inbox, partial: the link tap's codec, captures, queue and\n"
"partial-frame bytearray). Each period: s = sample() (a 6-tuple: period k and the SAMPLE\n"
"fields); SAMPLE(k) is encoded and captured; in-process it goes through the firmware's\n"
"exchange and its answers are decoded at once, over a descriptor it is written in full (within\n"
"write_timeout_s) and the answers are read as they come (poll, read, without the GIL) until\n"
"the period is taken or answer_timeout_s after the write has passed; the record: k, the\n"
"sample's fields and truth() written into `stage` (Recorder.batch_stage: sensors, truth and\n"
"telemetry rows, fill counts), seal() when a part of it is full (over a descriptor between the\n"
"write and the wait, while the board computes); the answers are queued behind what inbox\n"
"already held and taken from the front as the bench's period loop takes its inbox: a\n"
"TELEMETRY is written into the stage, and the first GATES (answer 0) or DUTY (answer 1) for\n"
"period k, with no shoot-through, ends the period: step(gates) or step(duty=(d0/65535.0,\n"
"d1/65535.0, d2/65535.0)), what follows it stays queued; then stop(), when given, may end the\n"
"run. counts gains frames out, frames in, bytes out, bytes in. With live_every (not 0) the\n"
"periods and TELEMETRY rows a live view takes (multiples of live_every) are left to the\n"
"caller. state: 0 `count` periods ran; 1 the next period was not begun here (k % publish_every\n"
"== 0, k % live_every == 0, or counts[4] set: the instance closed): the caller runs it; 2\n"
"period k was sampled, recorded and sent, and inbox holds what is left of its answers from the\n"
"first one not taken here (none: no answer in time), for the caller to go on with, extra being\n"
"when the SAMPLE was written (time.monotonic()) over a descriptor; 3 stop() said stop; 4 the\n"
"descriptor failed (period k recorded, not stepped), extra = (errno, what). The queue left\n"
"over always goes back to inbox as message objects, so the caller finds the state its own\n"
"loop would have left; extra is None otherwise.");

static PyObject *str_duty; /* "duty", interned at module init */

/* ---- the descriptor transport: a serial line's file descriptor (a pty, a UART) */

static double monotonic_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);   /* the clock of Python's time.monotonic() */
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* Waits up to timeout_s for fd to be ready for `events`, without the GIL: 1 ready, 0 not, -1 errno. */
static int fd_wait(int fd, short events, double timeout_s)
{
    struct pollfd pfd = {fd, events, 0};
    double ms = ceil(timeout_s * 1e3);
    /* written so that a NaN timeout polls once rather than converting NaN to int (undefined) */
    int timeout_ms = !(ms > 0.0) ? 0 : (ms > 1e9 ? 1000000000 : (int)ms);
    int r;
    Py_BEGIN_ALLOW_THREADS
    r = poll(&pfd, 1, timeout_ms);
    Py_END_ALLOW_THREADS
    if (r < 0) {
        return errno == EINTR ? 0 : -1;
    }
    return r > 0;
}

/* The whole frame into fd within write_timeout_s (a full line buffer is waited on, as
 * SerialLink.send_bytes does): 0, or -1 with errno (ETIMEDOUT: the time ran out). */
static int fd_write_all(int fd, const uint8_t *p, size_t n, double write_timeout_s)
{
    double deadline = -1.0;
    while (n > 0u) {
        ssize_t w;
        Py_BEGIN_ALLOW_THREADS
        w = write(fd, p, n);
        Py_END_ALLOW_THREADS
        if (w > 0) {
            p += w;
            n -= (size_t)w;
            continue;
        }
        if (w < 0 && errno == EINTR) {
            continue;
        }
        if (w < 0 && errno != EAGAIN && errno != EWOULDBLOCK) {
            return -1;
        }
        double now = monotonic_s();
        if (deadline < 0.0) {
            deadline = now + write_timeout_s;
        }
        if (now >= deadline) {
            errno = ETIMEDOUT;
            return -1;
        }
        if (fd_wait(fd, POLLOUT, deadline - now) < 0) {
            return -1;
        }
    }
    return 0;
}

/* What LinkTap._take_in does with a read while no link fault is active: bytes after the last
 * delimiter wait in `partial` (the tap's own buffer) for the rest of their frame; the complete
 * frames are captured, counted by their delimiters and decoded onto q. 0, or -1 with an
 * exception. */
static int fd_take_in(const uint8_t *data, size_t n, PyObject *partial, DecoderObject *dec,
                      PyObject *capture_in, int64_t *counts, answer_queue *q, PyObject **spill)
{
    counts[3] += (int64_t)n;
    if (PyByteArray_GET_SIZE(partial) == 0 && data[n - 1] == 0u) {
        counts[1] += (int64_t)count_delimiters(data, n);
        int rc = append_bytes(capture_in, data, n);
        return decode_onto(dec, data, n, q, spill) < 0 ? -1 : rc;
    }
    if (append_bytes(partial, data, n) < 0) {
        return -1;
    }
    Py_ssize_t size = PyByteArray_GET_SIZE(partial);
    uint8_t *buf = (uint8_t *)PyByteArray_AS_STRING(partial);
    Py_ssize_t end = size - 1;
    while (end >= 0 && buf[end] != 0u) {
        end--;
    }
    if (end < 0) {
        return 0;
    }
    size_t complete = (size_t)end + 1u;
    counts[1] += (int64_t)count_delimiters(buf, complete);
    int rc = append_bytes(capture_in, buf, complete);
    if (decode_onto(dec, buf, complete, q, spill) < 0) {
        rc = -1;
    }
    buf = (uint8_t *)PyByteArray_AS_STRING(partial);
    memmove(buf, buf + complete, (size_t)size - complete);
    if (PyByteArray_Resize(partial, size - (Py_ssize_t)complete) < 0) {
        rc = -1;
    }
    return rc;
}

/* ---- the loop */

/* The recorder's stage (Recorder.batch_stage): sensors (period + 5 fields), truth and telemetry
 * (period + 16 fields) rows of float64, and the int64 fill counts of periods and telemetry rows. */
typedef struct {
    Py_buffer view[4];
    int held;                    /* views taken */
    double *sensors, *truth, *telemetry;
    int64_t *fill;
    Py_ssize_t periods_cap, truth_width, telemetry_cap;
    PyObject *seal;              /* empties the stage in place (fill to 0) */
} stage_t;

#define SENSOR_ROW 6
#define TELEMETRY_ROW 17

static void stage_release(stage_t *st)
{
    for (int i = 0; i < st->held; i++) {
        PyBuffer_Release(&st->view[i]);
    }
    st->held = 0;
}

static int stage_take(stage_t *st, PyObject *stage, PyObject *seal)
{
    st->held = 0;
    st->seal = seal;
    if (!PyTuple_CheckExact(stage) || PyTuple_GET_SIZE(stage) != 4) {
        PyErr_SetString(PyExc_TypeError, "exchange_periods: stage is (sensors, truth, telemetry, fill)");
        return -1;
    }
    for (int i = 0; i < 4; i++) {
        if (PyObject_GetBuffer(PyTuple_GET_ITEM(stage, i), &st->view[i], PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) {
            stage_release(st);
            return -1;
        }
        st->held++;
    }
    st->sensors = (double *)st->view[0].buf;
    st->truth = (double *)st->view[1].buf;
    st->telemetry = (double *)st->view[2].buf;
    st->fill = (int64_t *)st->view[3].buf;
    st->periods_cap = st->view[0].len / (Py_ssize_t)(SENSOR_ROW * sizeof(double));
    st->truth_width = st->periods_cap > 0 ? st->view[1].len / st->periods_cap / (Py_ssize_t)sizeof(double) : 0;
    st->telemetry_cap = st->view[2].len / (Py_ssize_t)(TELEMETRY_ROW * sizeof(double));
    if (st->periods_cap < 1 || st->telemetry_cap < 1 || st->truth_width < 1 ||
        st->view[1].len != st->periods_cap * st->truth_width * (Py_ssize_t)sizeof(double) ||
        st->view[3].len < (Py_ssize_t)(2 * sizeof(int64_t)) || st->fill[0] < 0 || st->fill[1] < 0 ||
        st->fill[0] >= st->periods_cap || st->fill[1] >= st->telemetry_cap) {
        stage_release(st);
        PyErr_SetString(PyExc_ValueError, "exchange_periods: the stage's arrays do not fit together");
        return -1;
    }
    return 0;
}

/* seal() when a part of the stage is full; it must leave the stage empty. */
static int stage_seal_if_full(stage_t *st)
{
    if (st->fill[0] < st->periods_cap && st->fill[1] < st->telemetry_cap) {
        return 0;
    }
    PyObject *r = PyObject_CallNoArgs(st->seal);
    if (r == NULL) {
        return -1;
    }
    Py_DECREF(r);
    if (st->fill[0] != 0 || st->fill[1] != 0) {
        PyErr_SetString(PyExc_RuntimeError, "exchange_periods: seal() left the stage filled");
        return -1;
    }
    return 0;
}

/* value_of for what is not a float: an int or a float subclass, or the TypeError. */
static int value_of_other(PyObject *v, double *d, Py_ssize_t r, const msg_class *mc, const char *field,
                          Py_ssize_t i)
{
    if (v != NULL && PyLong_CheckExact(v)) {
        /* the ADC counts, encoder, status and period: what float(v) gives, without the float
           object PyFloat_AsDouble makes of an int */
        *d = PyLong_AsDouble(v);
        return (*d == -1.0 && PyErr_Occurred()) ? -1 : 0;
    }
    if (v != NULL && (PyFloat_Check(v) || PyLong_Check(v))) {
        *d = PyFloat_AsDouble(v);
        return (*d == -1.0 && PyErr_Occurred()) ? -1 : 0;
    }
    const char *kind = v == NULL ? "unset" : Py_TYPE(v)->tp_name;
    if (mc != NULL) {
        PyErr_Format(PyExc_TypeError, "recorder: row %zd, %s '%s' is %s, not a number", r,
                     mc->cls->tp_name, field, kind);
    } else {
        PyErr_Format(PyExc_TypeError, "recorder: row %zd, value %zd is %s, not a number", r, i, kind);
    }
    return -1;
}

/* v as a double into *d; -1 with TypeError naming row r and the field (a message's class and
 * field name, or the tuple's index i) otherwise. Inline: some forty values a period are floats. */
static inline int value_of(PyObject *v, double *d, Py_ssize_t r, const msg_class *mc, const char *field,
                           Py_ssize_t i)
{
    if (v != NULL && PyFloat_CheckExact(v)) {
        *d = PyFloat_AS_DOUBLE(v);
        return 0;
    }
    return value_of_other(v, d, r, mc, field, i);
}

/* A period's rows, what Recorder.period writes: k and the sample's five fields (sensors), the truth
 * tuple; then seal() if the stage is full. A value that is not an int or a float: TypeError, and
 * the row is not counted. */
static int stage_row(stage_t *st, PyObject *k, PyObject *const *five, PyObject *truth_row)
{
    int64_t n = st->fill[0];
    if (!PyTuple_Check(truth_row) || PyTuple_GET_SIZE(truth_row) != st->truth_width) {
        PyErr_Format(PyExc_TypeError, "recorder: a truth row is a tuple of %zd values", st->truth_width);
        return -1;
    }
    double *row = st->sensors + (size_t)n * SENSOR_ROW;
    if (value_of(k, &row[0], n, NULL, NULL, 0) < 0) {
        return -1;
    }
    for (Py_ssize_t i = 0; i < SENSOR_ROW - 1; i++) {
        if (value_of(five[i], &row[i + 1], n, NULL, NULL, i + 1) < 0) {
            return -1;
        }
    }
    row = st->truth + (size_t)n * (size_t)st->truth_width;
    for (Py_ssize_t i = 0; i < st->truth_width; i++) {
        if (value_of(PyTuple_GET_ITEM(truth_row, i), &row[i], n, NULL, NULL, i) < 0) {
            return -1;
        }
    }
    st->fill[0] = n + 1;
    return stage_seal_if_full(st);
}

/* The loop's record of period k: the 6-tuple sample s and truth(). */
static int record_period(stage_t *st, PyObject *s, PyObject *truth)
{
    PyObject *t = PyObject_CallNoArgs(truth);
    if (t == NULL) {
        return -1;
    }
    int rc = stage_row(st, PyTuple_GET_ITEM(s, 0), &PyTuple_GET_ITEM(s, 1), t);
    Py_DECREF(t);
    return rc;
}

/* A TELEMETRY, decoded (m) or as the message object it was queued as (obj), as Recorder.telemetry
 * writes it: the period, then its fields. */
static int record_telemetry(stage_t *st, const hil_msg *m, PyObject *obj)
{
    int64_t n = st->fill[1];
    double *row = st->telemetry + (size_t)n * TELEMETRY_ROW;
    if (obj != NULL) {
        const msg_class *mc = &classes[HIL_MSG_TELEMETRY];
        for (int i = 0; i < TELEMETRY_ROW; i++) {
            if (value_of(SLOT(obj, mc->off[i]), &row[i], n, mc, field_names[HIL_MSG_TELEMETRY][i], i) < 0) {
                return -1;
            }
        }
    } else {
        const hil_telemetry *t = &m->u.telemetry;
        const double v[TELEMETRY_ROW] = {
            t->period, t->sector, t->speed_source, t->state, t->gates,
            t->speed_feedback_rad_s, t->speed_encoder_rad_s, t->speed_raw_rad_s, t->speed_lpf_rad_s,
            t->speed_ekf_rad_s, t->flux_angle_rad, t->ekf_angle_rad, t->flux_mag_wb, t->torque_est_nm,
            t->torque_ref_nm, t->rotor_pos_conv_rad, t->rotor_pos_ekf_rad};
        memcpy(row, v, sizeof v);
    }
    st->fill[1] = n + 1;
    return stage_seal_if_full(st);
}

/* The answers queued, taken from the front as BenchSession._run_lockstep takes its inbox: a
 * TELEMETRY is written to the recorder's stage (record_telemetry), and the first GATES (answer 0) or DUTY
 * (answer 1) for period k with no shoot-through is taken into *gates or *duty. 1 taken; 0 the
 * queue ran out first; 2 its front is an answer this loop does not take (or a TELEMETRY of a
 * period the live view takes, a multiple of live_every when it is not 0); -1 with an exception. */
static int take_answers(answer_queue *q, unsigned long k, long answer, unsigned long live_every, stage_t *st,
                        long *gates, uint16_t duty[3])
{
    while (q->head < q->n) {
        int i = q->head;
        const hil_msg *a = &q->m[i];
        if (a->type == HIL_MSG_TELEMETRY && live_every > 0u && a->u.telemetry.period % live_every == 0u) {
            return 2;                           /* a row the live view takes: the caller's */
        }
        if (a->type == HIL_MSG_TELEMETRY) {
            PyObject *o = q->obj[i];
            q->obj[i] = NULL;
            int rc = record_telemetry(st, a, o);
            Py_XDECREF(o);
            q->head++;
            if (rc < 0) {
                return -1;
            }
            continue;
        }
        if (a->type == HIL_MSG_GATES && answer == 0 && a->u.gates.period == (uint32_t)k &&
            !(a->u.gates.gates & (a->u.gates.gates >> 1) & 0x15)) {
            *gates = a->u.gates.gates & 0x3F;   /* bits 6-7 reserved: ignored (SPEC 4) */
            q->head++;
            return 1;
        }
        if (a->type == HIL_MSG_DUTY && answer == 1 && a->u.duty.period == (uint32_t)k) {
            memcpy(duty, a->u.duty.duty, 3 * sizeof duty[0]);
            q->head++;
            return 1;
        }
        return 2;
    }
    return 0;
}

static PyObject *loop_result(Py_ssize_t done, int state, PyObject *extra)
{
    if (extra == NULL) {
        return Py_BuildValue("(niO)", done, state, Py_None);
    }
    PyObject *r = Py_BuildValue("(niO)", done, state, extra);
    Py_DECREF(extra);
    return r;
}

/* exchange_periods' state, handed by pointer from step to step. */
typedef struct {
    PyObject *sample, *truth, *step, *stop;  /* the plant's and caller's callables */
    Py_ssize_t publish_every, count;
    long answer;                 /* 0 GATES, 1 DUTY */
    unsigned long live_every;    /* 0: no live view */
    /* the board: in-process (exchange, fw) or a descriptor (fd, the timeouts, partial) */
    int by_fd;
    fw_exchange_fn exchange;
    void *fw;
    int fd;
    double answer_timeout_s, write_timeout_s;
    PyObject *partial;
    PyObject *capture_out, *capture_in, *inbox;
    EncoderObject *enc;
    DecoderObject *dec;
    Py_buffer counts_view;
    int64_t *counts;
    stage_t st;
    answer_queue q;
    PyObject *spill;
    PyObject *extra;             /* the third value returned: when the SAMPLE went, or the I/O error */
    Py_ssize_t done;
    int state;
    int failed;
} period_loop_t;

/* exchange_periods' arguments into L (the counts and the stage's buffers taken). -1 with an
 * exception (nothing held), else 0. */
static int loop_args(period_loop_t *L, PyObject *const *args)
{
    PyObject *target = args[0];
    L->sample = args[1];
    L->truth = args[2];
    L->step = args[3];
    L->stop = args[8];
    Py_ssize_t tlen = PyTuple_CheckExact(target) ? PyTuple_GET_SIZE(target) : -1;
    if (tlen != 8 && tlen != 10) {
        PyErr_SetString(PyExc_TypeError, "exchange_periods: target is 8 (in-process) or 10 (descriptor) values");
        return -1;
    }
    L->publish_every = PyLong_AsSsize_t(args[6]);
    L->count = PyLong_AsSsize_t(args[7]);
    L->answer = PyLong_AsLong(args[9]);
    L->live_every = PyLong_AsUnsignedLong(args[10]);
    if (PyErr_Occurred()) {
        return -1;
    }
    if (L->publish_every < 1 || L->count < 0) {
        PyErr_SetString(PyExc_ValueError, "exchange_periods: publish_every >= 1, count >= 0");
        return -1;
    }
    /* in-process: (exchange, fw, encoder, decoder, capture_out, capture_in, counts, inbox);
     * descriptor: (fd, answer_timeout_s, write_timeout_s, encoder, decoder, capture_out,
     *              capture_in, counts, inbox, partial) */
    L->by_fd = tlen == 10;
    L->exchange = NULL;
    L->fw = NULL;
    L->fd = -1;
    L->answer_timeout_s = 0.0;
    L->write_timeout_s = 0.0;
    L->partial = NULL;
    if (L->by_fd) {
        L->fd = (int)PyLong_AsLong(PyTuple_GET_ITEM(target, 0));
        L->answer_timeout_s = PyFloat_AsDouble(PyTuple_GET_ITEM(target, 1));
        L->write_timeout_s = PyFloat_AsDouble(PyTuple_GET_ITEM(target, 2));
        L->partial = PyTuple_GET_ITEM(target, 9);
        if (PyErr_Occurred()) {
            return -1;
        }
        if (L->fd < 0 || !PyByteArray_CheckExact(L->partial)) {
            PyErr_SetString(PyExc_TypeError, "exchange_periods: a descriptor target needs fd >= 0 and a "
                                             "bytearray for the partial frame");
            return -1;
        }
    } else {
        L->exchange = (fw_exchange_fn)(uintptr_t)PyLong_AsVoidPtr(PyTuple_GET_ITEM(target, 0));
        L->fw = PyLong_AsVoidPtr(PyTuple_GET_ITEM(target, 1));
        if (PyErr_Occurred()) {
            return -1;
        }
    }
    if (!L->by_fd && (L->exchange == NULL || L->fw == NULL)) {
        PyErr_SetString(PyExc_ValueError, "exchange_periods: null exchange function or instance");
        return -1;
    }
    Py_ssize_t base = L->by_fd ? 3 : 2;
    L->capture_out = PyTuple_GET_ITEM(target, base + 2);
    L->capture_in = PyTuple_GET_ITEM(target, base + 3);
    L->inbox = PyTuple_GET_ITEM(target, base + 5);
    if (codec_args("exchange_periods", &PyTuple_GET_ITEM(target, base), &L->counts_view) < 0) {
        return -1;
    }
    L->counts = (int64_t *)L->counts_view.buf;
    if (stage_take(&L->st, args[4], args[5]) < 0) {
        PyBuffer_Release(&L->counts_view);
        return -1;
    }
    L->enc = (EncoderObject *)PyTuple_GET_ITEM(target, base);
    L->dec = (DecoderObject *)PyTuple_GET_ITEM(target, base + 1);
    return 0;
}

/* What inbox already holds comes first, as the loop in Python takes it: TELEMETRY objects
 * only (anything else is the caller's to handle). 0 queued (inbox emptied), 1 the caller's
 * (LOOP_HANDED), -1 with an exception. */
static int inbox_to_queue(period_loop_t *L)
{
    PyTypeObject *telemetry_cls = classes[HIL_MSG_TELEMETRY].cls;
    answer_queue *q = &L->q;
    Py_ssize_t held = PyObject_Length(L->inbox);
    if (held <= 0) {
        return held < 0 ? -1 : 0;
    }
    PyObject *items = held > LOOP_QUEUE / 2 ? NULL : PySequence_List(L->inbox);
    int all_telemetry = items != NULL;
    for (Py_ssize_t i = 0; all_telemetry && i < held; i++) {
        all_telemetry = Py_TYPE(PyList_GET_ITEM(items, i)) == telemetry_cls;
    }
    if (!all_telemetry) {
        Py_XDECREF(items);
        return PyErr_Occurred() ? -1 : 1;
    }
    PyObject *r = PyObject_CallMethod(L->inbox, "clear", NULL);
    if (r == NULL) {
        Py_DECREF(items);
        return -1;
    }
    Py_DECREF(r);
    for (Py_ssize_t i = 0; i < held; i++) {
        PyObject *o = PyList_GET_ITEM(items, i);
        unsigned long period = PyLong_AsUnsignedLong(SLOT(o, classes[HIL_MSG_TELEMETRY].off[0]));
        if (PyErr_Occurred()) {             /* (not a period: its row says so later) */
            PyErr_Clear();
            period = 1u;
        }
        q->obj[q->n] = Py_NewRef(o);
        q->m[q->n].type = HIL_MSG_TELEMETRY;
        q->m[q->n].u.telemetry.period = (uint32_t)period;
        q->n++;
    }
    Py_DECREF(items);
    return 0;
}

/* The loop stops on the link's error: (errno, what) is returned, or the exception if that
 * tuple cannot be made. */
static void loop_link_error(period_loop_t *L, int io_errno, const char *io_what)
{
    L->extra = Py_BuildValue("(is)", io_errno, io_what);
    L->state = L->extra == NULL ? LOOP_DONE : LOOP_LINK_ERROR;
    L->failed = L->extra == NULL;
}

/* The SAMPLE s out: over the descriptor written (a write failure in *io_what, *sent_at when it
 * went), in process through the board's exchange (its answers queued). -1 with an exception. */
static int send_sample(period_loop_t *L, PyObject *s, double *sent_at, int *io_errno,
                       const char **io_what)
{
    if (L->by_fd) {
        uint8_t frame[HIL_MAX_ENCODED_FRAME];
        int n_frame = encode_sample_frame("exchange_periods", &PyTuple_GET_ITEM(s, 0), L->enc,
                                          L->capture_out, frame);
        if (n_frame < 0) {
            return -1;
        }
        if (fd_write_all(L->fd, frame, (size_t)n_frame, L->write_timeout_s) < 0) {
            *io_errno = errno;
            *io_what = *io_errno == ETIMEDOUT ? "write timed out (nobody reading?)" : "write failed";
        } else {
            L->counts[0] += 1;
            L->counts[2] += n_frame;
        }
        *sent_at = monotonic_s();
        return 0;
    }
    return exchange_frames("exchange_periods", L->exchange, L->fw, L->enc, L->dec, L->capture_out,
                           L->capture_in, &PyTuple_GET_ITEM(s, 0), L->counts, &L->q, &L->spill,
                           other_threads());
}

/* Period k's answer from the queue's front (take_answers' values); over a descriptor, read as
 * the answers come within the SAMPLE's one deadline (a read failure in *io_what). */
static int await_answer(period_loop_t *L, unsigned long k, double sent_at, long *gates,
                        uint16_t duty[3], int *io_errno, const char **io_what)
{
    int taken = L->spill != NULL ? 2 : take_answers(&L->q, k, L->answer, L->live_every, &L->st, gates, duty);
    while (L->by_fd && taken == 0) {
        double left = sent_at + L->answer_timeout_s - monotonic_s();
        int ready_now = left > 0.0 ? fd_wait(L->fd, POLLIN, left) : 0;
        if (ready_now <= 0) {
            if (ready_now < 0) {
                *io_errno = errno;
                *io_what = "read failed";
            }
            break;                          /* the deadline: the caller's late handling */
        }
        uint8_t buf[4096];
        ssize_t got;
        Py_BEGIN_ALLOW_THREADS
        got = read(L->fd, buf, sizeof buf);
        Py_END_ALLOW_THREADS
        if (got < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) {
            continue;
        }
        if (got <= 0) {
            *io_errno = got < 0 ? errno : 0;
            *io_what = got == 0 || *io_errno == EIO ? "the other end closed the line" : "read failed";
            break;
        }
        if (fd_take_in(buf, (size_t)got, L->partial, L->dec, L->capture_in, L->counts, &L->q, &L->spill) < 0) {
            return -1;
        }
        taken = L->spill != NULL ? 2 : take_answers(&L->q, k, L->answer, L->live_every, &L->st, gates, duty);
    }
    return taken;
}

/* The plant's step with the board's answer: step(duty=(d0, d1, d2)) in [0, 1], or step(gates).
 * -1 with an exception. */
static int step_plant(period_loop_t *L, long gates, const uint16_t duty[3])
{
    PyObject *r;
    if (L->answer == 1) {
        PyObject *d = Py_BuildValue("(ddd)", duty[0] / 65535.0, duty[1] / 65535.0, duty[2] / 65535.0);
        if (d == NULL) {
            return -1;
        }
        PyObject *kw = PyTuple_Pack(1, str_duty);
        PyObject *call_args[1] = {d};
        r = kw == NULL ? NULL : PyObject_Vectorcall(L->step, call_args, 0, kw);
        Py_XDECREF(kw);
        Py_DECREF(d);
    } else {
        PyObject *g = PyLong_FromLong(gates);
        r = g == NULL ? NULL : PyObject_CallOneArg(L->step, g);
        Py_XDECREF(g);
    }
    if (r == NULL) {
        return -1;
    }
    Py_DECREF(r);
    return 0;
}

/* stop() asked for the loop's end: 1 yes, 0 no (or no stop), -1 with an exception. */
static int stop_asked(PyObject *stop)
{
    if (stop == Py_None) {
        return 0;
    }
    PyObject *r = PyObject_CallNoArgs(stop);
    if (r == NULL) {
        return -1;
    }
    int yes = PyObject_IsTrue(r);
    Py_DECREF(r);
    return yes;
}

/* Keeps the queue's room at its front. */
static void queue_compact(answer_queue *q)
{
    if (q->head > 0) {
        memmove(&q->m[0], &q->m[q->head], (size_t)(q->n - q->head) * sizeof q->m[0]);
        memmove(&q->obj[0], &q->obj[q->head], (size_t)(q->n - q->head) * sizeof q->obj[0]);
        q->n -= q->head;
        q->head = 0;
    }
}

/* One period: sample, SAMPLE out, its record, the answer, the plant's step. 1 to go on; 0 the
 * loop ends (L->state, or L->failed with an exception). */
static int loop_period(period_loop_t *L)
{
    if (L->counts[4] != 0) {                   /* closed: the caller's path raises */
        L->state = LOOP_HANDED;
        return 0;
    }
    PyObject *s = PyObject_CallNoArgs(L->sample);
    if (s == NULL) {
        L->failed = 1;
        return 0;
    }
    if (!PyTuple_Check(s) || PyTuple_GET_SIZE(s) != 6) {
        Py_DECREF(s);
        PyErr_SetString(PyExc_TypeError, "exchange_periods: sample() must return 6 values");
        L->failed = 1;
        return 0;
    }
    unsigned long k = PyLong_AsUnsignedLong(PyTuple_GET_ITEM(s, 0));
    if (PyErr_Occurred()) {
        Py_DECREF(s);
        L->failed = 1;
        return 0;
    }
    if (k % (unsigned long)L->publish_every == 0u || (L->live_every > 0u && k % L->live_every == 0u)) {
        Py_DECREF(s);
        L->state = LOOP_HANDED;
        return 0;
    }
    double sent_at = 0.0;
    int io_errno = 0;
    const char *io_what = NULL;
    /* over a descriptor the record is made while the board computes */
    if (send_sample(L, s, &sent_at, &io_errno, &io_what) < 0) {
        Py_DECREF(s);
        L->failed = 1;
        return 0;
    }
    int rc = record_period(&L->st, s, L->truth);
    Py_DECREF(s);
    if (rc < 0) {
        L->failed = 1;
        return 0;
    }
    if (io_what != NULL) {
        loop_link_error(L, io_errno, io_what);
        return 0;
    }
    long gates = -1;
    uint16_t duty[3] = {0, 0, 0};
    int taken = await_answer(L, k, sent_at, &gates, duty, &io_errno, &io_what);
    if (taken < 0) {
        L->failed = 1;
        return 0;
    }
    if (io_what != NULL) {
        loop_link_error(L, io_errno, io_what);
        return 0;
    }
    if (taken != 1) {
        L->state = LOOP_PENDING;
        if (L->by_fd && (L->extra = PyFloat_FromDouble(sent_at)) == NULL) {
            L->failed = 1;
        }
        return 0;
    }
    if (step_plant(L, gates, duty) < 0) {
        L->failed = 1;
        return 0;
    }
    L->done++;
    int stop = stop_asked(L->stop);
    if (stop != 0) {
        L->failed = stop < 0;
        L->state = stop > 0 ? LOOP_STOPPED : L->state;
        return 0;
    }
    queue_compact(&L->q);
    return 1;
}

/* The loop's end: what is left of the queue goes back to inbox (the state the Python loop
 * leaves); (done, state, extra), or NULL with the loop's exception. */
static PyObject *loop_finish(period_loop_t *L)
{
    if (L->failed) {
        Py_XDECREF(L->extra);
        PyObject *et, *ev, *tb;
        PyErr_Fetch(&et, &ev, &tb);
        if (queue_to_inbox(&L->q, L->spill, L->inbox) < 0) {
            PyErr_Clear();
        }
        PyErr_Restore(et, ev, tb);
        return NULL;
    }
    if (queue_to_inbox(&L->q, L->spill, L->inbox) < 0) {
        Py_XDECREF(L->extra);
        return NULL;
    }
    return loop_result(L->done, L->state, L->extra);
}

static PyObject *mod_exchange_periods(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 11) {
        PyErr_SetString(PyExc_TypeError, "exchange_periods takes 11 arguments");
        return NULL;
    }
    if (!ready()) {
        return NULL;
    }
    period_loop_t L;
    if (loop_args(&L, args) < 0) {
        return NULL;
    }
    L.q.head = L.q.n = 0;
    L.spill = NULL;
    L.extra = NULL;
    L.done = 0;
    L.state = LOOP_DONE;
    L.failed = 0;
    int held = inbox_to_queue(&L);
    if (held != 0) {
        PyBuffer_Release(&L.counts_view);
        stage_release(&L.st);
        return held < 0 ? NULL : loop_result(0, LOOP_HANDED, NULL);
    }
    while (L.done < L.count && loop_period(&L)) {
    }
    PyBuffer_Release(&L.counts_view);
    stage_release(&L.st);
    return loop_finish(&L);
}

PyDoc_STRVAR(stage_period_doc,
"stage_period(stage, seal, k, truth, sample) -> None\n\n"
"Recorder.period in one call: k and the sample's adc_i1, adc_i2, adc_vdc, encoder and status (the\n"
"items after the first of a 6-tuple such as plant_rt's SensorSample, or those attributes) as\n"
"the next sensors row of `stage` (Recorder.batch_stage), the `truth` tuple as the next truth\n"
"row; then seal() if the stage is full. TypeError (nothing counted) for a value that is not an\n"
"int or a float, or a truth that is not a tuple of the stage's width.");

static const char *const sensor_attrs[5] = {"adc_i1", "adc_i2", "adc_vdc", "encoder", "status"};

static PyObject *mod_stage_period(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "stage_period takes 5 arguments");
        return NULL;
    }
    stage_t st;
    if (stage_take(&st, args[0], args[1]) < 0) {
        return NULL;
    }
    PyObject *sample = args[4];
    int rc;
    if (PyTuple_Check(sample) && PyTuple_GET_SIZE(sample) == 6) {
        rc = stage_row(&st, args[2], &PyTuple_GET_ITEM(sample, 1), args[3]);
    } else {
        PyObject *five[5] = {NULL, NULL, NULL, NULL, NULL};
        rc = 0;
        for (int i = 0; i < 5 && rc == 0; i++) {
            five[i] = PyObject_GetAttrString(sample, sensor_attrs[i]);
            rc = five[i] == NULL ? -1 : 0;
        }
        if (rc == 0) {
            rc = stage_row(&st, args[2], five, args[3]);
        }
        for (int i = 0; i < 5; i++) {
            Py_XDECREF(five[i]);
        }
    }
    stage_release(&st);
    if (rc < 0) {
        return NULL;
    }
    Py_RETURN_NONE;
}

PyDoc_STRVAR(stage_telemetry_doc,
"stage_telemetry(stage, seal, msg) -> None\n\n"
"Recorder.telemetry in one call: the TELEMETRY message msg (protocol.messages.Telemetry) as the\n"
"next telemetry row of `stage` (its period, then its fields), then seal() if the stage is full.\n"
"TypeError for another kind of object or a field that is not a number.");

static PyObject *mod_stage_telemetry(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "stage_telemetry takes 3 arguments");
        return NULL;
    }
    if (!ready()) {
        return NULL;
    }
    if (!Py_IS_TYPE(args[2], classes[HIL_MSG_TELEMETRY].cls)) {
        PyErr_SetString(PyExc_TypeError, "stage_telemetry: not a Telemetry message");
        return NULL;
    }
    stage_t st;
    if (stage_take(&st, args[0], args[1]) < 0) {
        return NULL;
    }
    int rc = record_telemetry(&st, NULL, args[2]);
    stage_release(&st);
    if (rc < 0) {
        return NULL;
    }
    Py_RETURN_NONE;
}

PyDoc_STRVAR(records_into_doc,
"records_into(out, offset, template, codes, offsets, times, values) -> count\n\n"
"The recorder's float64 rows as fixed-layout log records (hil/logs/mcap_writer.py\n"
"FixedChannel.write_many): for each of the n rows, `template` (one record's bytes, with its\n"
"constant header and field tags) is copied into the writable buffer `out` from byte `offset`\n"
"on, the row's time (the uint64 buffer `times`) written as its log and publish time (bytes 15\n"
"and 23, little-endian), and value i of the row (the float64 buffer `values`, n rows of\n"
"len(codes)) written at offsets[i] as codes[i]: 'd' double, 'f' float, 'I' uint32, 'i' int32,\n"
"'Q' uint64, 'q' int64, little-endian. The values are all checked before anything is written:\n"
"an integer field takes a whole number in its range, a float field a value a float holds (NaN\n"
"and infinities included); otherwise ValueError (the caller's numpy path names the value and\n"
"the field), and `out` is untouched.");

static void put_le(uint8_t *p, uint64_t v, int bytes)
{
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    /* the host's own order is the record's: one move instead of a loop of shifts */
    if (bytes == 8) {
        memcpy(p, &v, 8);
        return;
    }
    if (bytes == 4) {
        uint32_t w = (uint32_t)v;
        memcpy(p, &w, 4);
        return;
    }
#endif
    for (int i = 0; i < bytes; i++) {
        p[i] = (uint8_t)(v >> (8 * i));
    }
}

/* v is a whole number in [lo, hi] (NaN fails every comparison). The conversion to int64_t is
   defined only inside that type's range, so a whole-number test through it comes after the
   range test; 'Q' above 2^63 goes through uint64_t. floor() would be a libm call a value. */
static int whole_in(double v, double lo, double hi, int unsigned64)
{
    if (!(v >= lo && v <= hi)) {
        return 0;
    }
    if (unsigned64) {
        return (double)(uint64_t)v == v;
    }
    return (double)(int64_t)v == v;
}

static int fits(double v, char code)
{
    switch (code) {
    case 'd':
        return 1;
    case 'f':
        return !isfinite(v) || fabs(v) <= (double)FLT_MAX;
    case 'I':
        return whole_in(v, 0.0, 4294967295.0, 0);
    case 'i':
        return whole_in(v, -2147483648.0, 2147483647.0, 0);
    case 'Q':
        /* the largest double below 2^64 */
        return whole_in(v, 0.0, 18446744073709549568.0, 1);
    case 'q':
        /* -2^63 to the largest double below 2^63 */
        return whole_in(v, -9223372036854775808.0, 9223372036854774784.0, 0);
    default:
        return 0;
    }
}

static PyObject *mod_records_into(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 7) {
        PyErr_SetString(PyExc_TypeError, "records_into takes 7 arguments");
        return NULL;
    }
    Py_ssize_t offset = PyLong_AsSsize_t(args[1]);
    if (offset == -1 && PyErr_Occurred()) {
        return NULL;
    }
    PyObject *template = args[2], *codes = args[3], *offsets = args[4];
    if (!PyBytes_CheckExact(template) || !PyBytes_CheckExact(codes) || !PyTuple_CheckExact(offsets) ||
        PyTuple_GET_SIZE(offsets) != PyBytes_GET_SIZE(codes) || PyBytes_GET_SIZE(template) < 31) {
        PyErr_SetString(PyExc_TypeError, "records_into: template and codes are bytes, offsets a tuple of one "
                                         "int per code, the template at least a message record's 31-byte head");
        return NULL;
    }
    Py_ssize_t size = PyBytes_GET_SIZE(template), width = PyBytes_GET_SIZE(codes);
    const char *code = PyBytes_AS_STRING(codes);
    Py_ssize_t off[64];
    int nbytes[64];
    if (width > 64) {
        PyErr_SetString(PyExc_ValueError, "records_into: at most 64 fields");
        return NULL;
    }
    for (Py_ssize_t i = 0; i < width; i++) {
        off[i] = PyLong_AsSsize_t(PyTuple_GET_ITEM(offsets, i));
        nbytes[i] = code[i] == 'd' || code[i] == 'Q' || code[i] == 'q' ? 8 : 4;
        if (off[i] == -1 && PyErr_Occurred()) {
            return NULL;
        }
        if (strchr("dfIiQq", code[i]) == NULL || code[i] == '\0' || off[i] < 31 || off[i] + nbytes[i] > size) {
            PyErr_Format(PyExc_ValueError, "records_into: field %zd: code %c at offset %zd does not fit a "
                         "%zd-byte record", i, code[i], off[i], size);
            return NULL;
        }
    }
    Py_buffer out, times, values;
    if (PyObject_GetBuffer(args[0], &out, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) {
        return NULL;
    }
    if (PyObject_GetBuffer(args[5], &times, PyBUF_C_CONTIGUOUS) < 0) {
        PyBuffer_Release(&out);
        return NULL;
    }
    if (PyObject_GetBuffer(args[6], &values, PyBUF_C_CONTIGUOUS) < 0) {
        PyBuffer_Release(&out);
        PyBuffer_Release(&times);
        return NULL;
    }
    Py_ssize_t n = times.len / (Py_ssize_t)sizeof(uint64_t);
    PyObject *result = NULL;
    if (times.len != n * (Py_ssize_t)sizeof(uint64_t) || values.len != n * width * (Py_ssize_t)sizeof(double) ||
        offset < 0 || offset > out.len || (out.len - offset) / size < n) {
        PyErr_Format(PyExc_ValueError, "records_into: %zd times, %zd bytes of values for %zd fields and %zd bytes "
                     "from offset %zd do not go together", n, values.len, width, out.len, offset);
        goto done;
    }
    const double *v = (const double *)values.buf;
    /* The fields grouped by code once, so that each row is a few tight loops (a 'd' or 'f'
     * field is one conversion and one store) instead of a switch a value; every double fits
     * a 'd' field, so only the other codes are checked. 'I' and 'i' share a group: a checked
     * value of either is a whole number within int64_t, whose low 32 bits are the field. */
    Py_ssize_t by_code[5][64], n_by_code[5] = {0, 0, 0, 0, 0};
    static const char order[] = "dfIQq";
    for (Py_ssize_t i = 0; i < width; i++) {
        Py_ssize_t c = strchr(order, code[i] == 'i' ? 'I' : code[i]) - order;
        by_code[c][n_by_code[c]++] = i;
    }
    Py_ssize_t checked[64], n_checked = 0;
    for (Py_ssize_t i = 0; i < width; i++) {
        if (code[i] != 'd') {
            checked[n_checked++] = i;
        }
    }
    for (Py_ssize_t r = 0; r < n && n_checked; r++) {
        for (Py_ssize_t j = 0; j < n_checked; j++) {
            Py_ssize_t i = checked[j];
            if (!fits(v[r * width + i], code[i])) {
                PyErr_Format(PyExc_ValueError, "records_into: row %zd, field %zd does not fit its type", r, i);
                goto done;
            }
        }
    }
    const uint64_t *t = (const uint64_t *)times.buf;
    const uint8_t *tpl = (const uint8_t *)PyBytes_AS_STRING(template);
    uint8_t *p = (uint8_t *)out.buf + offset;
    for (Py_ssize_t r = 0; r < n; r++, p += size) {
        const double *row = v + r * width;
        memcpy(p, tpl, (size_t)size);
        put_le(p + 15, t[r], 8);
        put_le(p + 23, t[r], 8);
        for (Py_ssize_t j = 0; j < n_by_code[0]; j++) {         /* 'd' */
            Py_ssize_t i = by_code[0][j];
            memcpy(p + off[i], &row[i], 8);
        }
        for (Py_ssize_t j = 0; j < n_by_code[1]; j++) {         /* 'f' */
            Py_ssize_t i = by_code[1][j];
            float f = (float)row[i];
            memcpy(p + off[i], &f, 4);
        }
        for (Py_ssize_t j = 0; j < n_by_code[2]; j++) {         /* 'I' and 'i' */
            Py_ssize_t i = by_code[2][j];
            put_le(p + off[i], (uint32_t)(int64_t)row[i], 4);
        }
        for (Py_ssize_t j = 0; j < n_by_code[3]; j++) {         /* 'Q' */
            Py_ssize_t i = by_code[3][j];
            put_le(p + off[i], (uint64_t)row[i], 8);
        }
        for (Py_ssize_t j = 0; j < n_by_code[4]; j++) {         /* 'q' */
            Py_ssize_t i = by_code[4][j];
            put_le(p + off[i], (uint64_t)(int64_t)row[i], 8);
        }
    }
    result = PyLong_FromSsize_t(n);
done:
    PyBuffer_Release(&out);
    PyBuffer_Release(&times);
    PyBuffer_Release(&values);
    return result;
}

PyDoc_STRVAR(index_span_doc,
"index_span(indexes) -> (earliest, latest)\n\n"
"The earliest and latest log time in a chunk's message indexes, the chunk record's message\n"
"start and end time (hil/logs/mcap_writer.py McapLog._finish_chunk): `indexes` is a list of\n"
"buffers of native uint64, each one channel's (log time, offset) pairs interleaved, the times\n"
"the even entries, in any order. ValueError when a buffer is not whole pairs or no buffer\n"
"holds one.");

static PyObject *mod_index_span(PyObject *self, PyObject *arg)
{
    (void)self;
    PyObject *seq = PySequence_Fast(arg, "index_span: a list of buffers");
    if (seq == NULL) {
        return NULL;
    }
    uint64_t earliest = UINT64_MAX, latest = 0;
    int any = 0;
    for (Py_ssize_t i = 0; i < PySequence_Fast_GET_SIZE(seq); i++) {
        Py_buffer b;
        if (PyObject_GetBuffer(PySequence_Fast_GET_ITEM(seq, i), &b, PyBUF_C_CONTIGUOUS) < 0) {
            Py_DECREF(seq);
            return NULL;
        }
        if (b.len % 16 != 0) {
            PyErr_Format(PyExc_ValueError, "index_span: buffer %zd holds %zd bytes, not whole (time, offset) "
                         "pairs of uint64", i, b.len);
            PyBuffer_Release(&b);
            Py_DECREF(seq);
            return NULL;
        }
        const uint8_t *p = (const uint8_t *)b.buf;
        for (Py_ssize_t k = 0; k < b.len; k += 16) {
            uint64_t t;
            memcpy(&t, p + k, sizeof t);
            earliest = t < earliest ? t : earliest;
            latest = t > latest ? t : latest;
            any = 1;
        }
        PyBuffer_Release(&b);
    }
    Py_DECREF(seq);
    if (!any) {
        PyErr_SetString(PyExc_ValueError, "index_span: no (time, offset) pair");
        return NULL;
    }
    return Py_BuildValue("(KK)", (unsigned long long)earliest, (unsigned long long)latest);
}

PyDoc_STRVAR(chunk_tail_doc,
"chunk_tail(channel_ids, indexes, chunk_start, chunk_length, start, end, compression,\n"
"           compressed_size, uncompressed_size) -> (message_indexes, chunk_index)\n\n"
"The records that follow a finished chunk (hil/logs/mcap_writer.py McapLog._finish_chunk),\n"
"byte for byte what hil.logs.mcap_records writes: `message_indexes`, one MessageIndex record\n"
"(opcode 0x07) a channel, in the order given, written right after the chunk, and\n"
"`chunk_index`, its ChunkIndex record (0x08) for the summary, with each MessageIndex's file\n"
"offset. `indexes` are buffers of native uint64, each one channel's (log time, offset in the\n"
"chunk) pairs interleaved; `channel_ids` their channel ids (uint16). ValueError when the two\n"
"differ in length, a buffer is not whole pairs, an id is not a uint16 or a size is negative.");

static PyObject *mod_chunk_tail(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 9) {
        PyErr_SetString(PyExc_TypeError, "chunk_tail: 9 arguments");
        return NULL;
    }
    unsigned long long num[6];         /* chunk_start, chunk_length, start, end, compressed, uncompressed */
    const int num_arg[6] = {2, 3, 4, 5, 7, 8};
    for (int i = 0; i < 6; i++) {
        num[i] = PyLong_AsUnsignedLongLong(args[num_arg[i]]);
        if (num[i] == (unsigned long long)-1 && PyErr_Occurred()) {
            PyErr_Clear();
            PyErr_Format(PyExc_ValueError, "chunk_tail: argument %d is not a uint64", num_arg[i] + 1);
            return NULL;
        }
    }
    Py_ssize_t comp_len;
    const char *comp = PyUnicode_AsUTF8AndSize(args[6], &comp_len);
    if (comp == NULL) {
        return NULL;
    }
    PyObject *ids = PySequence_Fast(args[0], "chunk_tail: channel_ids is a sequence");
    if (ids == NULL) {
        return NULL;
    }
    PyObject *idx = PySequence_Fast(args[1], "chunk_tail: indexes is a sequence");
    if (idx == NULL) {
        Py_DECREF(ids);
        return NULL;
    }
    PyObject *result = NULL, *records = NULL, *chunk_index = NULL;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(ids);
    Py_buffer *bufs = NULL;
    Py_ssize_t got = 0;
    uint16_t *id16 = NULL;
    if (PySequence_Fast_GET_SIZE(idx) != n) {
        PyErr_Format(PyExc_ValueError, "chunk_tail: %zd channel ids for %zd indexes", n,
                     PySequence_Fast_GET_SIZE(idx));
        goto done;
    }
    bufs = PyMem_New(Py_buffer, (size_t)(n ? n : 1));
    id16 = PyMem_New(uint16_t, (size_t)(n ? n : 1));
    if (bufs == NULL || id16 == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    Py_ssize_t total = 0;
    for (; got < n; got++) {
        long id = PyLong_AsLong(PySequence_Fast_GET_ITEM(ids, got));
        if (id < 0 || id > 0xFFFF) {
            if (!PyErr_Occurred() || PyErr_ExceptionMatches(PyExc_OverflowError) ||
                PyErr_ExceptionMatches(PyExc_TypeError)) {
                PyErr_Clear();
                PyErr_Format(PyExc_ValueError, "chunk_tail: channel id %zd is not a uint16", got);
            }
            goto done;
        }
        id16[got] = (uint16_t)id;
        if (PyObject_GetBuffer(PySequence_Fast_GET_ITEM(idx, got), &bufs[got], PyBUF_C_CONTIGUOUS) < 0) {
            goto done;
        }
        if (bufs[got].len % 16 != 0) {
            PyErr_Format(PyExc_ValueError, "chunk_tail: index %zd holds %zd bytes, not whole (time, offset) "
                         "pairs of uint64", got, bufs[got].len);
            got++;
            goto done;
        }
        total += 9 + 6 + bufs[got].len;
    }
    /* MessageIndex records: opcode, u64 length, u16 channel, u32 pairs' bytes, the pairs (LE) */
    records = PyBytes_FromStringAndSize(NULL, total);
    /* ChunkIndex: opcode, u64 length, 4 x u64, u32 map bytes + n x (u16, u64), u64,
       u32 + compression, 2 x u64 */
    Py_ssize_t ci_body = 32 + 4 + 10 * n + 8 + 4 + comp_len + 16;
    chunk_index = PyBytes_FromStringAndSize(NULL, 9 + ci_body);
    if (records == NULL || chunk_index == NULL) {
        goto done;
    }
    uint8_t *r = (uint8_t *)PyBytes_AS_STRING(records);
    uint8_t *c = (uint8_t *)PyBytes_AS_STRING(chunk_index);
    c[0] = 0x08;
    put_le(c + 1, (uint64_t)ci_body, 8);
    put_le(c + 9, num[2], 8);
    put_le(c + 17, num[3], 8);
    put_le(c + 25, num[0], 8);
    put_le(c + 33, num[1], 8);
    put_le(c + 41, (uint64_t)(10 * n), 4);
    uint8_t *map = c + 45;
    uint64_t offset = (uint64_t)num[0] + (uint64_t)num[1];
    for (Py_ssize_t i = 0; i < n; i++) {
        Py_ssize_t len = bufs[i].len;
        put_le(map + 10 * i, id16[i], 2);
        put_le(map + 10 * i + 2, offset, 8);
        r[0] = 0x07;
        put_le(r + 1, (uint64_t)(6 + len), 8);
        put_le(r + 9, id16[i], 2);
        put_le(r + 11, (uint64_t)len, 4);
        const uint8_t *src = (const uint8_t *)bufs[i].buf;
        uint8_t *dst = r + 15;
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
        memcpy(dst, src, (size_t)len);      /* the host's order is the record's */
#else
        for (Py_ssize_t k = 0; k < len; k += 8) {
            uint64_t v;
            memcpy(&v, src + k, sizeof v);
            put_le(dst + k, v, 8);
        }
#endif
        r += 15 + len;
        offset += (uint64_t)(15 + len);
    }
    uint8_t *t = map + 10 * n;
    put_le(t, (uint64_t)total, 8);
    put_le(t + 8, (uint64_t)comp_len, 4);
    memcpy(t + 12, comp, (size_t)comp_len);
    put_le(t + 12 + comp_len, num[4], 8);
    put_le(t + 20 + comp_len, num[5], 8);
    result = PyTuple_Pack(2, records, chunk_index);
done:
    for (Py_ssize_t i = 0; i < got; i++) {
        PyBuffer_Release(&bufs[i]);
    }
    PyMem_Free(bufs);
    PyMem_Free(id16);
    Py_XDECREF(records);
    Py_XDECREF(chunk_index);
    Py_DECREF(ids);
    Py_DECREF(idx);
    return result;
}

/* ------------------------------------------------------------------ module */

static PyMethodDef module_methods[] = {
    {"setup", mod_setup, METH_VARARGS, setup_doc},
    {"encode_frame", (PyCFunction)(void (*)(void))mod_encode_frame, METH_FASTCALL, encode_frame_doc},
    {"crc16", mod_crc16, METH_O, crc16_doc},
    {"exchange_sample", (PyCFunction)(void (*)(void))mod_exchange_sample, METH_FASTCALL, exchange_sample_doc},
    {"exchange_periods", (PyCFunction)(void (*)(void))mod_exchange_periods, METH_FASTCALL, exchange_periods_doc},
    {"records_into", (PyCFunction)(void (*)(void))mod_records_into, METH_FASTCALL, records_into_doc},
    {"index_span", (PyCFunction)mod_index_span, METH_O, index_span_doc},
    {"chunk_tail", (PyCFunction)(void (*)(void))mod_chunk_tail, METH_FASTCALL, chunk_tail_doc},
    {"stage_period", (PyCFunction)(void (*)(void))mod_stage_period, METH_FASTCALL, stage_period_doc},
    {"stage_telemetry", (PyCFunction)(void (*)(void))mod_stage_telemetry, METH_FASTCALL, stage_telemetry_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT,
    .m_name = "_hilcodec",
    .m_doc = "The firmware's C codec (protocol/c/hil_proto.c) for the bench; use it through protocol.ccodec.",
    .m_size = -1,
    .m_methods = module_methods,
};

PyMODINIT_FUNC PyInit__hilcodec(void);

PyMODINIT_FUNC PyInit__hilcodec(void)
{
    if (PyType_Ready(&EncoderType) < 0 || PyType_Ready(&DecoderType) < 0) {
        return NULL;
    }
    for (int i = 0; i < NCOUNTERS; i++) {
        if (counter_keys[i] == NULL && (counter_keys[i] = PyUnicode_InternFromString(counter_names[i])) == NULL) {
            return NULL;
        }
    }
    if (str_extend == NULL && (str_extend = PyUnicode_InternFromString("extend")) == NULL) {
        return NULL;
    }
    if (str_duty == NULL && (str_duty = PyUnicode_InternFromString("duty")) == NULL) {
        return NULL;
    }
    PyObject *m = PyModule_Create(&module_def);
    if (m == NULL) {
        return NULL;
    }
    Py_INCREF(&EncoderType);
    Py_INCREF(&DecoderType);
    if (PyModule_AddObject(m, "FrameEncoder", (PyObject *)&EncoderType) < 0 ||
        PyModule_AddObject(m, "StreamDecoder", (PyObject *)&DecoderType) < 0 ||
        PyModule_AddIntConstant(m, "MAX_ENCODED_SEGMENT", (long)HIL_MAX_ENCODED_SEGMENT) < 0 ||
        PyModule_AddIntConstant(m, "MAX_ENCODED_FRAME", (long)HIL_MAX_ENCODED_FRAME) < 0 ||
        PyModule_AddIntConstant(m, "PROTOCOL_VERSION", (long)HIL_PROTO_VERSION) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
