/*
 * The example firmware on QEMU's mps2-an386 (Cortex-M4F): the board layer around
 * the portable firmware (../src), which it reaches only through the public
 * firmware ABI (protocol/c/hil_fw_abi.h), exactly as the shared library's
 * caller does.
 *
 * The UART interrupts move bytes between the peripheral and two rings; the
 * main loop hands received bytes to hil_fw_exchange, which runs one control
 * period when a SAMPLE frame completes and returns DUTY_LEGS (+ TELEMETRY...); the
 * answer goes into the TX ring. With nothing to do the core sleeps in WFI. On a
 * power stage the trigger would be the PWM-synchronous ADC interrupt and DUTY_LEGS
 * a write to the timer's compare registers and output enables (docs/porting.md).
 */
#include <stddef.h>
#include <stdint.h>

#include "board.h"
#include "hil_fw_abi.h"
#include "uart.h"

/* QEMU moves UART bytes at its own pace; on a real MPS2 this is the fastest
 * standard rate the 25 MHz APB clock divides. */
#define BOARD_UART_BAUD_HZ 921600u
#define RX_CHUNK 64u
#define TX_CHUNK 256u

/* The firmware instance lives in the RAM the linker leaves between the statics
 * and the stack (mps2_an386.ld); its size is the library's business. */
static void *board_boot_alloc(size_t size, size_t align)
{
    extern uint8_t __free_ram_start[];
    extern uint8_t __free_ram_end[];
    uintptr_t start = ((uintptr_t)__free_ram_start + (align - 1u)) & ~(uintptr_t)(align - 1u);
    if (start + size > (uintptr_t)__free_ram_end) {
        board_halt(5); /* does not fit: shrink the stack or the rings */
    }
    return (void *)start;
}

int main(void)
{
    uart0_init(BOARD_UART_BAUD_HZ);
    if (hil_fw_abi_version() != HIL_FW_ABI_VERSION) {
        board_halt(6); /* firmware and board built from different headers */
    }
    size_t size = hil_fw_instance_size();
    void *fw = hil_fw_create(board_boot_alloc(size, HIL_FW_INSTANCE_ALIGN), size);
    if (fw == NULL) {
        board_halt(5);
    }
    board_irq_enable();

    int more = 0; /* the last exchange filled its buffer: answers may still be queued */
    for (;;) {
        uint8_t rx[RX_CHUNK];
        uint8_t tx[TX_CHUNK];

        /* Sleep only with no input and nothing left to send; interrupts are
         * masked across the test so a byte arriving before WFI still wakes it. */
        uint32_t primask = board_irq_save();
        if (uart0_rx_empty() && (!more || uart0_tx_space() == 0u)) {
            board_wait_for_interrupt();
        }
        board_irq_restore(primask);

        size_t n_rx = uart0_read(rx, sizeof rx);
        size_t room = uart0_tx_space();
        size_t cap = room < sizeof tx ? room : sizeof tx;
        size_t n_tx = hil_fw_exchange(fw, rx, n_rx, tx, cap);
        more = cap > 0u && n_tx == cap;
        (void)uart0_write(tx, n_tx); /* fits: at most `room` bytes were taken */
    }
}
