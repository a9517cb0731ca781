/*
 * UART echo: the smallest firmware that proves the chain (startup, FPU, vector
 * table, interrupt-driven UART with ring buffers, QEMU character device, host
 * socket). Every received byte, 0x00 and 0x01 included, comes back unchanged.
 * Also exercises the FPU so a missing CPACR enable would fault at once.
 */
#include <stddef.h>
#include <stdint.h>

#include "board.h"
#include "cycles.h"
#include "uart.h"

/* volatile so the compiler cannot fold the float arithmetic away */
static volatile float fpu_probe = 1.5f;

int main(void)
{
    fpu_probe = fpu_probe * 2.0f + 0.25f; /* a UsageFault (NOCP) here means the FPU is off */
    cycles_init();
    uart0_init(921600u);
    board_irq_enable();

    static const uint8_t banner[] = "echo ready\n";
    uart0_write(banner, sizeof banner - 1u);
    for (;;) {
        uint8_t chunk[64];
        uint32_t primask = board_irq_save();
        if (uart0_rx_empty()) {
            board_wait_for_interrupt();
        }
        board_irq_restore(primask);
        size_t n = uart0_read(chunk, uart0_tx_space() < sizeof chunk ? uart0_tx_space() : sizeof chunk);
        uart0_write(chunk, n);
    }
}
