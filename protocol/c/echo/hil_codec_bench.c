/*
 * hil_codec_bench: nanoseconds per frame of the C codec on this host
 * (read by bench/protocol.py). Each figure is the median of BATCHES batches
 * of ITERATIONS operations, timed with clock_gettime(CLOCK_MONOTONIC).
 * Prints one JSON object.
 *
 *   hil_codec_bench [ITERATIONS [BATCHES]]
 *   hil_codec_bench --only OP ITERATIONS    runs one operation untimed, for instruction
 *                                           counting under valgrind --tool=callgrind
 *                                           (OP: sample_encode, sample_decode,
 *                                           sample_decode_bytewise, gates_...)
 */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../hil_proto.h"

#define MAX_BATCHES 64

static volatile uint32_t sink;

static double now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e9 + (double)ts.tv_nsec;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

typedef void (*op_fn)(const hil_msg *m, long iterations);

static void op_encode(const hil_msg *m, long iterations)
{
    uint8_t out[HIL_MAX_ENCODED_FRAME];
    hil_msg local = *m;
    for (long i = 0; i < iterations; i++) {
        local.seq = (uint8_t)i;
        sink += (uint32_t)hil_frame_encode(&local, out, sizeof out);
        sink += out[3];
    }
}

static void op_decode(const hil_msg *m, long iterations)
{
    uint8_t frame[HIL_MAX_ENCODED_FRAME];
    hil_msg local = *m;
    local.seq = 0;
    int n = hil_frame_encode(&local, frame, sizeof frame);
    hil_decoder dec;
    hil_decoder_init(&dec);
    hil_msg out;
    for (long i = 0; i < iterations; i++) {
        int got;
        sink += (uint32_t)hil_decoder_feed_buf(&dec, frame, (size_t)n, &out, &got);
        sink += (uint32_t)got;
    }
    sink += dec.frames_ok;
}

static void op_decode_bytewise(const hil_msg *m, long iterations)
{
    uint8_t frame[HIL_MAX_ENCODED_FRAME];
    hil_msg local = *m;
    local.seq = 0;
    int n = hil_frame_encode(&local, frame, sizeof frame);
    hil_decoder dec;
    hil_decoder_init(&dec);
    hil_msg out;
    for (long i = 0; i < iterations; i++) {
        for (int k = 0; k < n; k++) {
            sink += (uint32_t)hil_decoder_feed(&dec, frame[k], &out);
        }
    }
    sink += dec.frames_ok;
}

static void op_can_roundtrip(const hil_msg *m, long iterations)
{
    hil_can_frame frames[HIL_CAN_MAX_FRAMES];
    hil_can_rx rx;
    hil_can_rx_init(&rx, HIL_CAN_DEFAULT_BASE_ID);
    hil_msg out;
    for (long i = 0; i < iterations; i++) {
        int n = hil_can_pack(m, 0, HIL_CAN_DEFAULT_BASE_ID, frames, HIL_CAN_MAX_FRAMES);
        for (int k = 0; k < n; k++) {
            sink += (uint32_t)hil_can_rx_feed(&rx, &frames[k], &out, NULL);
        }
    }
}

static double median_ns(op_fn op, const hil_msg *m, long iterations, int batches)
{
    double per[MAX_BATCHES] = {0};
    op(m, iterations / 10 + 1); /* warm-up */
    for (int b = 0; b < batches; b++) {
        double t0 = now_ns();
        op(m, iterations);
        per[b] = (now_ns() - t0) / (double)iterations;
    }
    qsort(per, (size_t)batches, sizeof per[0], cmp_double);
    return per[batches / 2];
}

int main(int argc, char **argv)
{
    if (argc == 4 && strcmp(argv[1], "--only") == 0) {
        hil_msg m;
        memset(&m, 0, sizeof m);
        long n = atol(argv[3]);
        int is_sample = strncmp(argv[2], "sample_", 7) == 0;
        if (is_sample) {
            m.type = HIL_MSG_SAMPLE;
            m.u.sample = (hil_sample){123456u, 2048u, 1000u, 3000u, 65000u, 5u};
        } else {
            m.type = HIL_MSG_GATES;
            m.u.gates = (hil_gates){123456u, 0x21u};
        }
        const char *op = argv[2] + (is_sample ? 7 : 6);
        if (strcmp(op, "encode") == 0) {
            op_encode(&m, n);
        } else if (strcmp(op, "decode") == 0) {
            op_decode(&m, n);
        } else if (strcmp(op, "decode_bytewise") == 0) {
            op_decode_bytewise(&m, n);
        } else {
            fprintf(stderr, "unknown operation %s\n", argv[2]);
            return 2;
        }
        return 0;
    }
    long iterations = argc > 1 ? atol(argv[1]) : 200000;
    int batches = argc > 2 ? atoi(argv[2]) : 7;
    if (iterations < 1 || batches < 1 || batches > MAX_BATCHES) {
        fprintf(stderr, "usage: hil_codec_bench [ITERATIONS [BATCHES<=%d]]\n", MAX_BATCHES);
        return 2;
    }
    hil_msg sample, gates, telemetry;
    memset(&sample, 0, sizeof sample);
    sample.type = HIL_MSG_SAMPLE;
    sample.u.sample = (hil_sample){123456u, 2048u, 1000u, 3000u, 65000u, 5u};
    memset(&gates, 0, sizeof gates);
    gates.type = HIL_MSG_GATES;
    gates.u.gates = (hil_gates){123456u, 0x21u};
    memset(&telemetry, 0, sizeof telemetry);
    telemetry.type = HIL_MSG_TELEMETRY;
    telemetry.u.telemetry.period = 123456u;
    telemetry.u.telemetry.speed_ekf_rad_s = 314.159f;
    telemetry.u.telemetry.flux_mag_wb = 0.3f;

    double se = median_ns(op_encode, &sample, iterations, batches);
    double sd = median_ns(op_decode, &sample, iterations, batches);
    double sb = median_ns(op_decode_bytewise, &sample, iterations, batches);
    double ge = median_ns(op_encode, &gates, iterations, batches);
    double gd = median_ns(op_decode, &gates, iterations, batches);
    double gb = median_ns(op_decode_bytewise, &gates, iterations, batches);
    double te = median_ns(op_encode, &telemetry, iterations, batches);
    double td = median_ns(op_decode, &telemetry, iterations, batches);
    double sc = median_ns(op_can_roundtrip, &sample, iterations, batches);
    double tc = median_ns(op_can_roundtrip, &telemetry, iterations, batches);
    printf("{\"iterations\": %ld, \"batches\": %d, "
           "\"sample_encode_ns\": %.1f, \"sample_decode_ns\": %.1f, \"sample_decode_bytewise_ns\": %.1f, "
           "\"gates_encode_ns\": %.1f, \"gates_decode_ns\": %.1f, \"gates_decode_bytewise_ns\": %.1f, "
           "\"telemetry_encode_ns\": %.1f, \"telemetry_decode_ns\": %.1f, "
           "\"can_sample_pack_unpack_ns\": %.1f, \"can_telemetry_pack_unpack_ns\": %.1f}\n",
           iterations, batches, se, sd, sb, ge, gd, gb, te, td, sc, tc);
    return (int)(sink & 0u);
}
