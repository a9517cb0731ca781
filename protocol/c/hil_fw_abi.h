/*
 * hil-bench firmware ABI, version 1: how the bench loads a controller firmware
 * built as a shared library (link string `lib:PATH.so`) and talks to it
 * in-process, one call per control period.
 *
 * The firmware is the same code that runs on the board: it speaks the wire
 * protocol of protocol/SPEC.md. The ABI only moves those bytes (or CAN frames)
 * in and out, so every protocol byte still crosses the firmware's own codec.
 * docs/porting.md ("The firmware ABI") explains it with an example.
 *
 * Symbols a library exports (C linkage, the platform's C calling convention):
 *
 *   required   hil_fw_abi_version, hil_fw_name, hil_fw_instance_size,
 *              hil_fw_create, hil_fw_exchange, hil_fw_shutdown_requested,
 *              hil_fw_destroy
 *   optional   hil_fw_can_exchange (absent: the firmware speaks serial only)
 *
 * Loading: the bench calls hil_fw_abi_version() first and refuses the library,
 * naming both numbers, unless it returns exactly HIL_FW_ABI_VERSION as the
 * bench knows it. A missing required symbol is refused the same way.
 *
 * Memory: the caller owns the instance memory. It asks hil_fw_instance_size(),
 * provides that many bytes aligned to HIL_FW_INSTANCE_ALIGN, and passes them to
 * hil_fw_create(). The firmware never allocates. A firmware that keeps its
 * state in static variables (common on a microcontroller) returns 0 from
 * hil_fw_instance_size(), ignores the memory, and returns NULL from a second
 * hil_fw_create() until the first instance is destroyed: it supports one
 * instance per process, and the bench says so when asked for two.
 *
 * Threads: calls on one instance must not overlap; distinct instances (when
 * the firmware supports several) are independent.
 *
 * C99, no dependency beyond <stddef.h> and <stdint.h>: a firmware with its own
 * protocol codec needs only this header.
 */
#ifndef HIL_FW_ABI_H
#define HIL_FW_ABI_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Incremented whenever a signature, a struct layout or the meaning of a call
 * changes. Adding a new optional symbol does not change it. */
#define HIL_FW_ABI_VERSION 1u

/* Alignment of the caller's instance memory: malloc's on 64-bit hosts, enough
 * for any C99 object. */
#define HIL_FW_INSTANCE_ALIGN 16u

/* Shared libraries built with -fvisibility=hidden still export the ABI. */
#if defined(__GNUC__) || defined(__clang__)
#define HIL_FW_EXPORT __attribute__((visibility("default")))
#else
#define HIL_FW_EXPORT
#endif

/* One classic CAN data frame with an 11-bit identifier (SPEC.md section 7).
 * Same layout as hil_can_frame in hil_proto.h: id at offset 0, dlc at 2, data
 * at 3, size 12 (with the trailing padding byte), so a firmware using the
 * reference codec can pass its frames through unchanged. */
typedef struct {
    uint16_t id;     /* 11-bit identifier, 0..0x7FF */
    uint8_t dlc;     /* data length, 0..8 */
    uint8_t data[8]; /* bytes beyond dlc are ignored */
} hil_fw_can_frame;

/* HIL_FW_ABI_VERSION as the library was compiled. Call before anything else. */
HIL_FW_EXPORT uint32_t hil_fw_abi_version(void);

/* The firmware's name, NUL-terminated, static: normally its HELLO name (at most
 * 40 bytes, SPEC.md 6.1). The bench puts it in its messages. */
HIL_FW_EXPORT const char *hil_fw_name(void);

/* Bytes of caller memory one instance needs; 0 for a firmware with static
 * state (it ignores the memory given to hil_fw_create). */
HIL_FW_EXPORT size_t hil_fw_instance_size(void);

/* Initialises an instance in `mem` (`mem_size` >= hil_fw_instance_size() bytes,
 * aligned to HIL_FW_INSTANCE_ALIGN; may be NULL when the size is 0) and returns
 * its handle, or NULL when it cannot: memory too small or misaligned, or a
 * static-state firmware whose one instance is in use. The new instance is a
 * board just out of reset: idle, switches open, waiting for HELLO. */
HIL_FW_EXPORT void *hil_fw_create(void *mem, size_t mem_size);

/* Serial transport. Feeds rx_len received bytes (the wire bytes of SPEC.md
 * section 3: COBS frames with their 0x00 delimiters, in any split) and copies up
 * to tx_cap bytes the firmware sends into tx; returns how many. A SAMPLE is
 * answered within the call that completes its frame. Answers that do not fit
 * stay queued in order: call again with rx_len 0 until it returns 0 to drain
 * them. rx may be NULL when rx_len is 0. */
HIL_FW_EXPORT size_t hil_fw_exchange(void *fw, const uint8_t *rx, size_t rx_len, uint8_t *tx, size_t tx_cap);

/* OPTIONAL. CAN transport (SPEC.md section 7, base identifier 0x100 unless the
 * firmware documents otherwise): rx_count received frames in, up to tx_cap
 * frames to send out; returns how many. Queuing as for hil_fw_exchange. A
 * library without this symbol speaks serial only. An instance uses one
 * transport for its life: the first of the two exchange calls picks it. */
HIL_FW_EXPORT size_t hil_fw_can_exchange(void *fw, const hil_fw_can_frame *rx, size_t rx_count,
                                         hil_fw_can_frame *tx, size_t tx_cap);

/* 1 once the firmware has received SHUTDOWN and stopped switching, else 0:
 * the bench's cue that the session is over (a host process would exit). */
HIL_FW_EXPORT int hil_fw_shutdown_requested(const void *fw);

/* Ends the instance. Its memory is the caller's again; the handle is invalid. */
HIL_FW_EXPORT void hil_fw_destroy(void *fw);

#ifdef __cplusplus
}
#endif

#endif /* HIL_FW_ABI_H */
