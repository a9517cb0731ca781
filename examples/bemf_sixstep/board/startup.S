/*
 * Reset handler for the Cortex-M4F. In assembly so that nothing the compiler
 * generates (with -mfloat-abi=hard it may use s0-s31 anywhere) can run before
 * the FPU is switched on: an FPU instruction with CPACR.CP10/CP11 = 0 raises a
 * UsageFault (NOCP), which looks like a crash at the first float.
 */
    .syntax unified
    .cpu cortex-m4
    .fpu fpv4-sp-d16
    .thumb

    .section .text.Reset_Handler, "ax", %progbits
    .global Reset_Handler
    .type Reset_Handler, %function
    .thumb_func
Reset_Handler:
#ifndef BOARD_TEST_FPU_LEFT_OFF /* only for the test that proves a missing enable is caught */
    /* CPACR (0xE000ED88): full access to CP10 and CP11, the single-precision FPU. */
    ldr   r0, =0xE000ED88
    ldr   r1, [r0]
    orr   r1, r1, #(0xF << 20)
    str   r1, [r0]
    dsb
    isb                              /* the write must take effect before the next FPU instruction */
#endif

    /* Copy .data initialisers from flash to RAM. */
    ldr   r0, =__data_start
    ldr   r1, =__data_end
    ldr   r2, =__data_load
1:  cmp   r0, r1
    bhs   2f
    ldr   r3, [r2], #4
    str   r3, [r0], #4
    b     1b

    /* Zero .bss. */
2:  ldr   r0, =__bss_start
    ldr   r1, =__bss_end
    movs  r3, #0
3:  cmp   r0, r1
    bhs   4f
    str   r3, [r0], #4
    b     3b

4:  bl    main
    /* main does not return on a board; if it does, stop here (a debugger sees where). */
5:  wfi
    b     5b

    .size Reset_Handler, . - Reset_Handler
    .pool
