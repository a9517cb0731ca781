/*
 * The controller firmware on mps2-an386: the board layer around the portable
 * app (firmware_stub/app/hil_stub.c), which owns the codec and the control core.
 *
 * Everything time-critical is in interrupts: the UART ISRs move bytes between
 * the peripheral and two ring buffers. The main loop only hands received bytes
 * to hil_stub_exchange, which decodes them and, when a SAMPLE completes, runs
 * one control step and queues GATES (and TELEMETRY, STATUS...); the answer goes
 * into the TX ring. With nothing to do the core sleeps in WFI. On a board with
 * real power stages, the SAMPLE trigger would be the PWM-synchronous ADC
 * interrupt and GATES a write to the timer's compare registers (docs/porting.md).
 */
#include <stddef.h>
#include <stdint.h>

#include "board.h"
#include "cycles.h"
#include "hil_stub.h"
#include "uart.h"

/* Any rate works under QEMU, which moves bytes as fast as its event loop turns;
 * on a real MPS2 this is the highest standard rate the 25 MHz APB clock divides
 * (BAUDDIV 27). */
#define BOARD_UART_BAUD_HZ 921600u

/* Bytes handed to the app per call: one SAMPLE frame is 21, so a call is
 * normally one frame and its answer is sent before the next is decoded. */
#define RX_CHUNK 64u
#define TX_CHUNK 256u

/* The app instance lives in the RAM the linker leaves between the statics and
 * the stack; its size is only known at run time (hil_stub_instance_size). */
static void *board_boot_alloc(size_t size, size_t align)
{
    extern uint8_t __free_ram_start[];
    extern uint8_t __free_ram_end[];
    uintptr_t start = ((uintptr_t)__free_ram_start + (align - 1u)) & ~(uintptr_t)(align - 1u);
    if (start + size > (uintptr_t)__free_ram_end) {
        board_halt(5); /* the instance does not fit: shrink the stack or the rings */
    }
    return (void *)start;
}

int main(void)
{
    cycles_init();
    uart0_init(BOARD_UART_BAUD_HZ);
    void *stub = board_boot_alloc(hil_stub_instance_size(), 8u);
    hil_stub_init(stub);
    hil_stub_set_cycle_counter(stub, cycles_counter);
    board_irq_enable();

    for (;;) {
        uint8_t rx[RX_CHUNK];
        uint8_t tx[TX_CHUNK];

        /* Sleep only when there is neither input nor an answer that could be
         * sent; interrupts are masked across the test so a byte arriving
         * between the test and WFI still wakes the core. */
        uint32_t primask = board_irq_save();
        if (uart0_rx_empty() && (hil_stub_pending(stub) == 0u || uart0_tx_space() == 0u)) {
            board_wait_for_interrupt();
        }
        board_irq_restore(primask);

        size_t n_rx = uart0_read(rx, sizeof rx);
        size_t room = uart0_tx_space();
        size_t n_tx = hil_stub_exchange(stub, rx, n_rx, tx, room < sizeof tx ? room : sizeof tx);
        (void)uart0_write(tx, n_tx); /* fits: at most `room` bytes were taken */
    }
}
