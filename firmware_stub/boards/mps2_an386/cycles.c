#include "cycles.h"

#include "board.h"

static uint32_t per_tick_q16 = 1u << 16;
static uint32_t last_tick;       /* SysTick value at the previous reading */
static uint32_t count;           /* cycles so far, readings excluded */
static uint32_t reading_cycles;  /* what one reading adds to an interval it ends and starts */

/* SysTick counts down from its 24-bit reload value. */
static uint32_t ticks_between(uint32_t earlier, uint32_t later) { return (earlier - later) & SYST_RELOAD_MAX; }

static uint32_t ticks_to_cycles(uint32_t ticks)
{
    return (uint32_t)(((uint64_t)ticks * per_tick_q16 + 0x8000u) >> 16);
}

#ifdef BOARD_QEMU_ICOUNT
/* Ticks taken by `iterations` turns of a two-instruction loop (subs, bne). */
static uint32_t ticks_of_loop(uint32_t iterations)
{
    uint32_t start = SYST_CVR;
    __asm volatile("1: subs %0, %0, #1\n\tbne 1b" : "+r"(iterations)::"cc");
    return ticks_between(start, SYST_CVR);
}

/* Instructions per tick from the difference of two loop lengths, which cancels
 * the fixed cost around the loops. Over 2 * 2^16 instructions the ratio is good
 * to one tick in 3277 at shift=0 and one in 419430 at shift=7. */
static void calibrate(void)
{
    const uint32_t short_loop = 1024u;
    const uint32_t long_loop = short_loop + 65536u;
    uint32_t primask = board_irq_save();
    uint32_t ticks_short = ticks_of_loop(short_loop);
    uint32_t ticks_long = ticks_of_loop(long_loop);
    board_irq_restore(primask);
    uint32_t ticks = ticks_long - ticks_short;
    uint64_t instructions = 2ull * (long_loop - short_loop);
    per_tick_q16 = (uint32_t)(((instructions << 16) + ticks / 2u) / ticks);
}
#endif

void cycles_init(void)
{
    SYST_CSR = 0u;
    SYST_RVR = SYST_RELOAD_MAX;
    SYST_CVR = 0u; /* any write clears the counter; it reloads on the next tick */
    SYST_CSR = SYST_CSR_ENABLE | SYST_CSR_CLKSOURCE_CORE;
#ifdef BOARD_QEMU_ICOUNT
    calibrate();
#endif
    /* Two readings back to back: the interval between them is the reading itself. */
    uint32_t primask = board_irq_save();
    reading_cycles = 0u;
    (void)cycles_counter();
    uint32_t before = count;
    (void)cycles_counter();
    reading_cycles = count - before;
    count = 0u;
    board_irq_restore(primask);
}

__attribute__((noinline)) uint32_t cycles_counter(void)
{
    uint32_t now = SYST_CVR;
    uint32_t cycles = ticks_to_cycles(ticks_between(last_tick, now));
    last_tick = now;
    count += cycles > reading_cycles ? cycles - reading_cycles : 0u;
    return count;
}

uint32_t cycles_per_tick_q16(void) { return per_tick_q16; }
