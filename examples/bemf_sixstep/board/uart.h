/*
 * Interrupt-driven driver for UART0 of mps2-an386 (CMSDK APB UART), with a
 * receive and a transmit ring buffer. One producer and one consumer per ring:
 * the RX interrupt fills rx and the main loop drains it; the main loop fills tx
 * and the TX interrupt drains it. Neither call blocks.
 */
#ifndef BOARD_UART_H
#define BOARD_UART_H

#include <stddef.h>
#include <stdint.h>

#define UART_RX_RING_BYTES 512u /* power of two */
#define UART_TX_RING_BYTES 1024u /* power of two */

typedef struct {
    uint32_t rx_bytes;
    uint32_t tx_bytes;
    uint32_t rx_ring_drops; /* bytes lost because the main loop fell behind */
    uint32_t rx_overruns;   /* bytes lost in the UART itself (interrupt latency) */
} uart_stats;

void uart0_init(uint32_t baud_hz);
/* Moves up to cap received bytes into buf; returns how many. */
size_t uart0_read(uint8_t *buf, size_t cap);
/* Queues up to len bytes for transmission; returns how many fitted. */
size_t uart0_write(const uint8_t *buf, size_t len);
size_t uart0_tx_space(void);
int uart0_rx_empty(void);
int uart0_tx_idle(void);
uart_stats uart0_stats(void);

#endif
