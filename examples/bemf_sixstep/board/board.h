/*
 * Registers of the mps2-an386 peripherals this port uses, and the board API the
 * main loop sees. Addresses and IRQ numbers are those of ARM AN386 as modelled by
 * QEMU (hw/arm/mps2.c): UARTn RX interrupt on IRQ 2n, TX on IRQ 2n+1.
 */
#ifndef BOARD_H
#define BOARD_H

#include <stdint.h>

#define REG32(addr) (*(volatile uint32_t *)(addr))

/* Main system clock of the MPS2 FPGA images: drives the core, SysTick (CLKSOURCE=1) and the APB UARTs. */
#define BOARD_SYSCLK_HZ 25000000u

/* CMSDK APB UART (ARM DDI0479C, section 4.3) */
#define UART0_BASE 0x40004000u
#define UART_DATA(b) REG32((b) + 0x00u)
#define UART_STATE(b) REG32((b) + 0x04u)
#define UART_CTRL(b) REG32((b) + 0x08u)
#define UART_INTSTATUS(b) REG32((b) + 0x0Cu) /* write 1 to clear */
#define UART_BAUDDIV(b) REG32((b) + 0x10u)   /* >= 16 */
#define UART_STATE_TXFULL 0x01u
#define UART_STATE_RXFULL 0x02u
#define UART_STATE_TXOVR 0x04u
#define UART_STATE_RXOVR 0x08u
#define UART_CTRL_TXEN 0x01u
#define UART_CTRL_RXEN 0x02u
#define UART_CTRL_TXIE 0x04u
#define UART_CTRL_RXIE 0x08u
#define UART_CTRL_RXOIE 0x20u
#define UART_INT_TX 0x01u
#define UART_INT_RX 0x02u
#define UART_INT_RXO 0x08u
#define UART0_RX_IRQn 0
#define UART0_TX_IRQn 1
#define UART_OVERFLOW_IRQn 12 /* UART0..2 overrun interrupts ORed together */

/* NVIC */
#define NVIC_ISER(n) REG32(0xE000E100u + 4u * (n))
#define NVIC_ICER(n) REG32(0xE000E180u + 4u * (n))
#define NVIC_IPR8(irq) (*(volatile uint8_t *)(0xE000E400u + (irq)))

/* SysTick (ARMv7-M ARM, B3.3) */
#define SYST_CSR REG32(0xE000E010u)
#define SYST_RVR REG32(0xE000E014u)
#define SYST_CVR REG32(0xE000E018u)
#define SYST_CSR_ENABLE 0x1u
#define SYST_CSR_CLKSOURCE_CORE 0x4u
#define SYST_RELOAD_MAX 0x00FFFFFFu

/* SCB */
#define SCB_CPACR REG32(0xE000ED88u)
#define SCB_SHCSR REG32(0xE000ED24u)
#define SCB_CFSR REG32(0xE000ED28u)

/* Keeps the compiler from moving ring-buffer data accesses across the index update that publishes them. */
static inline void compiler_barrier(void) { __asm volatile("" ::: "memory"); }
static inline void board_irq_disable(void) { __asm volatile("cpsid i" ::: "memory"); }
static inline void board_irq_enable(void) { __asm volatile("cpsie i" ::: "memory"); }
/* Saves PRIMASK and masks interrupts; pair with board_irq_restore. */
static inline uint32_t board_irq_save(void)
{
    uint32_t primask;
    __asm volatile("mrs %0, primask\n cpsid i" : "=r"(primask)::"memory");
    return primask;
}
static inline void board_irq_restore(uint32_t primask) { __asm volatile("msr primask, %0" ::"r"(primask) : "memory"); }
/* Sleeps until an interrupt; called with interrupts masked so a wake-up between
 * the caller's "nothing to do" check and the WFI cannot be lost (WFI wakes on a
 * pending interrupt even while PRIMASK masks it). */
static inline void board_wait_for_interrupt(void) { __asm volatile("dsb\n wfi" ::: "memory"); }

/* Stops the board. Under QEMU with -semihosting this exits the emulator with the
 * given status; on a real board (or QEMU without semihosting) it parks the core. */
void board_halt(int status) __attribute__((noreturn));

#endif
