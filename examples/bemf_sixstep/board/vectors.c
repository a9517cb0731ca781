/*
 * Vector table for the Cortex-M4 of AN386 (16 system exceptions + 32 IRQs) and
 * the fault handlers. Placed in .vectors, which the linker script puts at 0x0,
 * where the core fetches the initial stack pointer and reset vector.
 */
#include <stdint.h>

#include "board.h"

extern uint32_t __stack_top;
void Reset_Handler(void);
void uart0_rx_isr(void);
void uart0_tx_isr(void);
void uart_overflow_isr(void);

/* A fault means a bug in the firmware: stop with a status the host can see
 * (QEMU exit status 3 under semihosting) rather than run on with broken state. */
static void fault_handler(void) { board_halt(3); }

static void unexpected_irq(void) { board_halt(4); }

#define AN386_NUM_IRQ 32

typedef void (*vector_fn)(void);

/* Entry 0 is the initial stack pointer, not a function: the cast is how every
 * Cortex-M vector table in C is written. Every IRQ slot has a handler so a stray
 * interrupt halts visibly instead of jumping to address 0. */
__attribute__((section(".vectors"), used)) static const vector_fn vector_table[16 + AN386_NUM_IRQ] = {
    (vector_fn)(uintptr_t)&__stack_top,
    Reset_Handler,
    fault_handler,  /* NMI */
    fault_handler,  /* HardFault */
    fault_handler,  /* MemManage */
    fault_handler,  /* BusFault */
    fault_handler,  /* UsageFault (NOCP here means the FPU was not enabled) */
    0, 0, 0, 0,     /* reserved */
    unexpected_irq, /* SVCall */
    unexpected_irq, /* DebugMonitor */
    0,              /* reserved */
    unexpected_irq, /* PendSV */
    unexpected_irq, /* SysTick: free-running, its interrupt stays disabled */
    uart0_rx_isr, /* IRQ 0 */
    uart0_tx_isr, /* IRQ 1 */
    unexpected_irq, /* IRQ 2 */
    unexpected_irq, /* IRQ 3 */
    unexpected_irq, /* IRQ 4 */
    unexpected_irq, /* IRQ 5 */
    unexpected_irq, /* IRQ 6 */
    unexpected_irq, /* IRQ 7 */
    unexpected_irq, /* IRQ 8 */
    unexpected_irq, /* IRQ 9 */
    unexpected_irq, /* IRQ 10 */
    unexpected_irq, /* IRQ 11 */
    uart_overflow_isr, /* IRQ 12 */
    unexpected_irq, /* IRQ 13 */
    unexpected_irq, /* IRQ 14 */
    unexpected_irq, /* IRQ 15 */
    unexpected_irq, /* IRQ 16 */
    unexpected_irq, /* IRQ 17 */
    unexpected_irq, /* IRQ 18 */
    unexpected_irq, /* IRQ 19 */
    unexpected_irq, /* IRQ 20 */
    unexpected_irq, /* IRQ 21 */
    unexpected_irq, /* IRQ 22 */
    unexpected_irq, /* IRQ 23 */
    unexpected_irq, /* IRQ 24 */
    unexpected_irq, /* IRQ 25 */
    unexpected_irq, /* IRQ 26 */
    unexpected_irq, /* IRQ 27 */
    unexpected_irq, /* IRQ 28 */
    unexpected_irq, /* IRQ 29 */
    unexpected_irq, /* IRQ 30 */
    unexpected_irq, /* IRQ 31 */
};

void board_halt(int status)
{
#ifdef BOARD_SEMIHOSTING
    /* SYS_EXIT_EXTENDED (0x20) with ADP_Stopped_ApplicationExit: QEMU exits with `status`. */
    volatile uint32_t block[2] = {0x20026u, (uint32_t)status};
    register uint32_t r0 __asm("r0") = 0x20u;
    register volatile uint32_t *r1 __asm("r1") = block;
    __asm volatile("bkpt 0xab" : "+r"(r0) : "r"(r1) : "memory");
#else
    (void)status;
#endif
    board_irq_disable();
    for (;;) {
        board_wait_for_interrupt();
    }
}
