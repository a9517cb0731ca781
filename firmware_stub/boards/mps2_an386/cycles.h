/*
 * Cycle counting with SysTick, free-running from the core clock.
 *
 * On silicon a SysTick tick with CLKSOURCE=1 is one core cycle. Under QEMU it is
 * not: QEMU clocks SysTick at the board's 25 MHz in virtual time, while with
 * -icount shift=S every instruction takes 2^S ns of virtual time, so a tick is
 * 40 / 2^S instructions (40 at shift=0: far too coarse for a ~1000-instruction
 * step). Built with BOARD_QEMU_ICOUNT, cycles_init() measures instructions per
 * tick with a loop of known length, and the counter below counts instructions:
 * exact and repeatable at shift >= 6, where a tick is shorter than an
 * instruction (hil/links/qemu.py runs shift=7).
 */
#ifndef BOARD_CYCLES_H
#define BOARD_CYCLES_H

#include <stdint.h>

void cycles_init(void);

/* A 32-bit cycle counter (instructions under QEMU icount) for
 * hil_stub_set_cycle_counter: the difference of two readings is the cycles
 * spent between them, excluding the cost of taking the readings themselves.
 * Each reading rounds the interval since the previous one, so the difference of
 * two consecutive readings is exact; intervals between consecutive readings
 * must stay under 2^24 ticks (0.67 s at 25 MHz). Main-loop context only. */
uint32_t cycles_counter(void);

/* Core cycles per SysTick tick in Q16 fixed point, as calibrated (1.0 on silicon). */
uint32_t cycles_per_tick_q16(void);

#endif
