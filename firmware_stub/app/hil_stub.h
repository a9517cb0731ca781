/*
 * Application layer of the controller stub: owns the protocol codec and the
 * control core, and turns received bytes (or CAN frames) into bytes (or CAN
 * frames) to send. No I/O, no allocation, no clock: the host executable, the
 * shared library (ctypes) and the Cortex-M4F board port all call these
 * functions, typically once per control period with one SAMPLE frame in and
 * GATES, or DUTY when HIL_PARAM_CONTROL_LAW selects FOC and the drive runs
 * (+ TELEMETRY every HIL_PARAM_TELEMETRY_DIVIDER periods) out.
 *
 * The instance is an opaque block of hil_stub_instance_size() bytes, aligned
 * to 8 bytes, owned by the caller.
 */
#ifndef HIL_STUB_H
#define HIL_STUB_H

#include <stddef.h>
#include <stdint.h>

#include "hil_proto.h"

#define HIL_STUB_VERSION "0.1"

size_t hil_stub_instance_size(void);
void hil_stub_init(void *inst);

/* Feeds rx_len received bytes of the serial protocol and copies up to tx_cap
 * bytes to send into tx; returns how many. Answers that do not fit stay queued
 * for the next call (call with rx_len = 0 to drain). */
size_t hil_stub_exchange(void *inst, const uint8_t *rx, size_t rx_len, uint8_t *tx, size_t tx_cap);

/* The same over the CAN mapping: rx_count frames in, up to tx_cap frames out. */
size_t hil_stub_can_exchange(void *inst, const hil_can_frame *rx, size_t rx_count, hil_can_frame *tx,
                             size_t tx_cap);
/* CAN identifiers start at base_id (default HIL_CAN_DEFAULT_BASE_ID); resets CAN reassembly. */
void hil_stub_set_can_base(void *inst, uint16_t base_id);

/* 1 once a SHUTDOWN message has been received (switching has stopped). */
int hil_stub_shutdown_requested(const void *inst);

/* Bytes (or CAN frames) answered but not yet handed out. */
size_t hil_stub_pending(const void *inst);

/* Optional cycle counter (e.g. DWT->CYCCNT or SysTick): when set, each
 * control step is timed and HIL_PARAM_CONTROL_STEP_CYCLES reads the last one. */
void hil_stub_set_cycle_counter(void *inst, uint32_t (*read_cycles)(void));

/* The HELLO name: "hil-stub <version> <target> <compiler> <flags>", at most HIL_NAME_MAX chars. */
const char *hil_stub_name(void);

/* Counters for diagnostics. */
typedef struct {
    uint32_t frames_in;       /* valid messages received */
    uint32_t ignored;         /* valid messages a controller does not act on (GATES, TELEMETRY...) */
    uint32_t tx_overflows;    /* answers dropped because the output queue was full */
    uint32_t decode_errors;   /* serial: CRC + framing + length + version + unknown type; CAN: all */
} hil_stub_counters;
void hil_stub_get_counters(const void *inst, hil_stub_counters *out);

#endif
