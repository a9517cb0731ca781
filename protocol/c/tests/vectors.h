/* Reader for the files in protocol/vectors/ (format described at the top of each file; handbuilt.txt's
 * raw/crc/wire items included). Test code only. */
#ifndef HIL_TEST_VECTORS_H
#define HIL_TEST_VECTORS_H

#include <stddef.h>
#include <stdint.h>

#include "../hil_proto.h"

#define VEC_NAME_MAX 64
#define VEC_MAX_CAN 16
#define VEC_MAX_YIELDS 64
#define VEC_MAX_COUNTERS 16

typedef struct {
    char name[VEC_NAME_MAX];
    uint32_t value;
} vec_counter;

typedef struct {
    char name[VEC_NAME_MAX];
    int is_reject;
    hil_msg msg; /* type, seq and fields as written */
    uint8_t role;
    uint16_t base_id;
    uint8_t serial[HIL_MAX_ENCODED_FRAME];
    size_t serial_len;
    hil_can_frame can[VEC_MAX_CAN];
    size_t can_count;
    hil_msg can_msg; /* what a fresh CAN receiver reports (canfield lines applied) */
    uint8_t raw[HIL_MAX_RAW_FRAME]; /* handbuilt.txt: header and payload as written */
    size_t raw_len;
    int line;
} vec_message;

typedef struct {
    char name[VEC_NAME_MAX];
    int is_can;
    uint16_t base_id;
    uint8_t *bytes; /* serial streams */
    size_t len;
    hil_can_frame *frames; /* CAN streams */
    size_t frame_count;
    size_t yields[VEC_MAX_YIELDS]; /* indices into vec_file.messages */
    uint8_t yield_roles[VEC_MAX_YIELDS];
    size_t yield_count;
    vec_counter counters[VEC_MAX_COUNTERS];
    size_t counter_count;
    const vec_message *messages; /* the messages of the stream's own file (yields index them) */
    int line;
} vec_stream;

typedef struct {
    vec_message *messages;
    size_t message_count;
    vec_stream *streams;
    size_t stream_count;
} vec_file;

/* Parses the file; on error prints "path:line: reason" to stderr and returns -1. Every 'crc'
 * line is checked against spec_crc16 of the raw bytes above it, every 'badcrc' must differ. */
int vec_load(const char *path, vec_file *out);
void vec_free(vec_file *vf);
/* CRC-16/CCITT-FALSE bit by bit, as SPEC 3.1 defines it: independent of hil_crc16. */
uint16_t spec_crc16(const uint8_t *data, size_t n);
/* COBS as SPEC 3.2 describes it, then the 0x00; returns the frame length (out: n + 2 bytes). */
size_t spec_cobs(const uint8_t *in, size_t n, uint8_t *out);
/* Expected counter value (0 when the stream does not list it). */
uint32_t vec_counter_value(const vec_stream *s, const char *name);

#endif
