/*
 * The stub's shared library seen through the public firmware ABI
 * (protocol/c/hil_fw_abi.h): a thin adapter over the app layer, so the bench's
 * `lib:` link loads libhilstub.so exactly like any user's firmware. The
 * hil_stub_* exports stay as they are (hil/links/stub_library.py uses them).
 */
#include <stddef.h>
#include <stdint.h>

#include "hil_fw_abi.h"
#include "hil_stub.h"

/* The CAN call passes frames straight through: the two frame types must have
 * one layout. */
typedef char can_frame_layouts_match[(sizeof(hil_fw_can_frame) == sizeof(hil_can_frame) &&
                                      offsetof(hil_fw_can_frame, id) == offsetof(hil_can_frame, id) &&
                                      offsetof(hil_fw_can_frame, dlc) == offsetof(hil_can_frame, dlc) &&
                                      offsetof(hil_fw_can_frame, data) == offsetof(hil_can_frame, data))
                                         ? 1
                                         : -1];

uint32_t hil_fw_abi_version(void) { return HIL_FW_ABI_VERSION; }

const char *hil_fw_name(void) { return hil_stub_name(); }

size_t hil_fw_instance_size(void) { return hil_stub_instance_size(); }

void *hil_fw_create(void *mem, size_t mem_size)
{
    /* the app instance holds doubles and pointers: refuse memory that breaks
     * the documented alignment instead of faulting later */
    if (mem == NULL || mem_size < hil_stub_instance_size() || ((uintptr_t)mem % HIL_FW_INSTANCE_ALIGN) != 0u) {
        return NULL;
    }
    hil_stub_init(mem);
    return mem;
}

size_t hil_fw_exchange(void *fw, const uint8_t *rx, size_t rx_len, uint8_t *tx, size_t tx_cap)
{
    return hil_stub_exchange(fw, rx, rx_len, tx, tx_cap);
}

size_t hil_fw_can_exchange(void *fw, const hil_fw_can_frame *rx, size_t rx_count, hil_fw_can_frame *tx,
                           size_t tx_cap)
{
    return hil_stub_can_exchange(fw, (const hil_can_frame *)(const void *)rx, rx_count,
                                 (hil_can_frame *)(void *)tx, tx_cap);
}

int hil_fw_shutdown_requested(const void *fw) { return hil_stub_shutdown_requested(fw); }

/* nothing to release: the memory is the caller's */
void hil_fw_destroy(void *fw) { (void)fw; }
