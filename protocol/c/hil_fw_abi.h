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
 *   optional   hil_fw_can_exchange (absent: the firmware speaks serial only),
 *              hil_fw_configure (absent: the firmware takes no arguments)
 *
 * Loading: the bench calls hil_fw_abi_version() first and refuses the library,
 * naming both numbers, unless it returns exactly HIL_FW_ABI_VERSION as the
 * bench knows it. A missing required symbol is refused the same way.
 *
 * Memory: the caller owns the instance memory. It asks hil_fw_instance_size(),
 * provides that many bytes aligned to HIL_FW_INSTANCE_ALIGN, and passes them to
 * hil_fw_create(). The firmware never allocates. A firmware that keeps its
 * state in static variables (common on a microcontroller, an Arduino-style
 * sketch) returns 0 from hil_fw_instance_size() and ignores the memory.
 *
 * What a firmware may assume from the bench (link `lib:`):
 *  - Fresh globals per session. Each session loads its own private copy of the
 *    library (hil/links/firmware_library.py), so a firmware's static variables
 *    start as in a freshly loaded program: .data initialised, .bss zeroed,
 *    constructors run once per copy. Nothing carries over from an earlier
 *    session, and two sessions in one process (the profiles of one `hil run`,
 *    a sweep's runs) never share a variable: a static-state firmware needs no
 *    reset code of its own and never sees a second hil_fw_create.
 *  - Order of calls on a copy: hil_fw_abi_version, hil_fw_name and
 *    hil_fw_instance_size (any number of times), then hil_fw_create once, then
 *    hil_fw_configure once (only if exported), then hil_fw_exchange (or
 *    hil_fw_can_exchange) and hil_fw_shutdown_requested calls, then hil_fw_destroy once. No call of any
 *    kind follows hil_fw_destroy: the copy is unloaded after it.
 *  - Threads: calls on one instance never overlap (one thread at a time,
 *    normally the one running the session); nothing is called from a signal
 *    handler. The bench may run other copies of the same library on
 *    other threads at the same time: only what lies outside the library (its
 *    dependencies, files, the process's environment) is shared.
 *  - The in-process stub (link `stub`) is the exception: its state is all in
 *    the instance memory, so the bench loads it once per process.
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
 * its handle, or NULL when it cannot: memory too small or misaligned. A
 * static-state firmware returns any non-NULL handle (e.g. the address of its
 * state). The new instance is a board just out of reset: idle, switches open,
 * waiting for HELLO. */
HIL_FW_EXPORT void *hil_fw_create(void *mem, size_t mem_size);

/* OPTIONAL. The firmware's arguments: the link string's `args=` option
 * (`lib:fw.so?args=--kp%200.5` or `args=--kp+0.5`), split into words like a
 * shell's, exactly as `exec:PATH?args=...` splits it into the argv of a host
 * program, so one parser serves both builds. Called once, after hil_fw_create
 * and before any exchange, also with argc 0 when no args are given.
 * argv[0..argc-1] are NUL-terminated UTF-8 words (no program name; at most 64
 * words, 4096 bytes in all) and argv[argc] is NULL; they live only during the
 * call: copy what you keep. Returns 0 to accept; anything else refuses the
 * arguments, and the session ends with an error naming the library, the
 * arguments, the status and the reason the firmware wrote into `why` (a
 * NUL-terminated text of at most why_cap bytes, why_cap >= 1, zero-filled by
 * the bench). A library without this symbol takes no arguments: the bench
 * refuses `args=` for it, naming the file. */
HIL_FW_EXPORT int hil_fw_configure(void *fw, int argc, const char *const *argv, char *why, size_t why_cap);

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

/* Ends the instance. Its memory is the caller's again; the handle is invalid.
 * The last call the bench makes into this copy of the library. */
HIL_FW_EXPORT void hil_fw_destroy(void *fw);

#ifdef __cplusplus
}
#endif

#endif /* HIL_FW_ABI_H */
