/*
 * A sensor-set board as a firmware library (link lib:, protocol/c/hil_fw_abi.h) for
 * tests/test_session_sensor_set.py: it advertises GATES and SENSOR_SET, answers PARAM_GET of
 * SENSOR_SET with the mask given by `--sensor-set N`, and writes every SAMPLE and
 * SAMPLE_SENSORS it decodes with the reference C codec (hil_proto.c) as one line of numbers
 * to the file given by `--record PATH`; each is answered GATES 0. A test fixture, not a
 * controller: it uses stdio to report what it got.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "hil_fw_abi.h"
#include "hil_proto.h"

#define OUT_BYTES 1024u
#define PARAMS 256u

static hil_decoder decoder;
static uint8_t out[OUT_BYTES];
static size_t out_len;
static uint8_t tx_seq;
static uint8_t shutdown_received;
static float params[PARAMS];
static float sensor_set;
static FILE *record;

static void emit(hil_msg *m)
{
    m->seq = tx_seq++;
    int n = hil_frame_encode(m, out + out_len, OUT_BYTES - out_len);
    if (n > 0) {
        out_len += (size_t)n;
    }
}

static void answer_param(uint16_t id, uint8_t status, float value)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_PARAM_VALUE;
    m.u.param_value.id = id;
    m.u.param_value.status = status;
    m.u.param_value.value = value;
    emit(&m);
}

static void answer_gates(uint32_t period)
{
    hil_msg m;
    memset(&m, 0, sizeof m);
    m.type = HIL_MSG_GATES;
    m.u.gates.period = period;
    emit(&m);
}

static void dispatch(const hil_msg *in)
{
    hil_msg m;
    if (in->type == HIL_MSG_HELLO) {
        memset(&m, 0, sizeof m);
        m.type = HIL_MSG_HELLO;
        m.u.hello.proto_version = HIL_PROTO_VERSION;
        m.u.hello.role = HIL_ROLE_CONTROLLER;
        m.u.hello.capabilities = HIL_CAP_GATES | HIL_CAP_SENSOR_SET;
        m.u.hello.control_period_ns = in->u.hello.control_period_ns;
        m.u.hello.name_len = 9u;
        memcpy(m.u.hello.name, "lib-board", 9u);
        emit(&m);
    } else if (in->type == HIL_MSG_PARAM_GET) {
        uint16_t id = in->u.param_get.id;
        answer_param(id, 0u, id == HIL_PARAM_SENSOR_SET ? sensor_set
                                                         : (id < PARAMS ? params[id] : 0.0f));
    } else if (in->type == HIL_MSG_PARAM_SET) {
        uint16_t id = in->u.param_set.id;
        if (id == HIL_PARAM_SENSOR_SET) {
            answer_param(id, 3u, sensor_set); /* READ_ONLY */
        } else {
            if (id < PARAMS) {
                params[id] = in->u.param_set.value;
            }
            answer_param(id, 0u, in->u.param_set.value);
        }
    } else if (in->type == HIL_MSG_SAMPLE_SENSORS) {
        const hil_sample_sensors *s = &in->u.sample_sensors;
        if (record != NULL) {
            fprintf(record, "SampleSensors %lu %u %u %u %u %u %u %u %u %u %u %u %u %u %u %u\n",
                    (unsigned long)s->period, s->sensor_set, s->status, s->adc_ia, s->adc_ib,
                    s->adc_ic, s->adc_vdc, s->encoder, s->hall, s->adc_va, s->adc_vb, s->adc_vc,
                    s->bemf_comparators, s->adc_resolver_sin, s->adc_resolver_cos,
                    s->adc_temperature);
        }
        answer_gates(s->period);
    } else if (in->type == HIL_MSG_SAMPLE) {
        if (record != NULL) {
            fprintf(record, "Sample %lu\n", (unsigned long)in->u.sample.period);
        }
        answer_gates(in->u.sample.period);
    } else if (in->type == HIL_MSG_SHUTDOWN) {
        shutdown_received = 1u;
    }
}

uint32_t hil_fw_abi_version(void) { return HIL_FW_ABI_VERSION; }

const char *hil_fw_name(void) { return "sensor-board-lib"; }

size_t hil_fw_instance_size(void) { return 0u; }

void *hil_fw_create(void *mem, size_t mem_size)
{
    (void)mem;
    (void)mem_size;
    hil_decoder_init(&decoder);
    return &decoder;
}

int hil_fw_configure(void *fw, int argc, const char *const *argv, char *why, size_t why_cap)
{
    (void)fw;
    for (int k = 0; k + 1 < argc; k += 2) {
        if (strcmp(argv[k], "--sensor-set") == 0) {
            sensor_set = strtof(argv[k + 1], NULL);
        } else if (strcmp(argv[k], "--record") == 0) {
            record = fopen(argv[k + 1], "w");
            if (record == NULL) {
                snprintf(why, why_cap, "cannot open %s", argv[k + 1]);
                return 2;
            }
        } else {
            snprintf(why, why_cap, "unknown option %s", argv[k]);
            return 1;
        }
    }
    return 0;
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
    }
    size_t n = out_len < tx_cap ? out_len : tx_cap;
    memcpy(tx, out, n);
    memmove(out, out + n, out_len - n);
    out_len -= n;
    return n;
}

int hil_fw_shutdown_requested(const void *fw)
{
    (void)fw;
    return shutdown_received;
}

void hil_fw_destroy(void *fw)
{
    (void)fw;
    if (record != NULL) {
        fclose(record);
        record = NULL;
    }
}
