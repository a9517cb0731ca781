#include "uart.h"

#include "board.h"

typedef struct {
    volatile uint32_t head; /* written by the producer only */
    volatile uint32_t tail; /* written by the consumer only */
} ring_idx;

static uint8_t rx_buf[UART_RX_RING_BYTES];
static uint8_t tx_buf[UART_TX_RING_BYTES];
static ring_idx rx_ring;
static ring_idx tx_ring;
static volatile uint8_t tx_active; /* a byte is in the UART and its TX interrupt will follow */
static volatile uart_stats stats;

/* Indices run free and wrap at 2^32; the ring sizes are powers of two so
 * head - tail is the fill level even across the wrap. */
static uint32_t ring_used(const ring_idx *r) { return r->head - r->tail; }

void uart0_init(uint32_t baud_hz)
{
    UART_CTRL(UART0_BASE) = 0u;
    UART_BAUDDIV(UART0_BASE) = BOARD_SYSCLK_HZ / baud_hz;
    UART_INTSTATUS(UART0_BASE) = 0x0Fu;
    UART_STATE(UART0_BASE) = UART_STATE_TXOVR | UART_STATE_RXOVR;
    rx_ring.head = rx_ring.tail = 0u;
    tx_ring.head = tx_ring.tail = 0u;
    tx_active = 0u;
    UART_CTRL(UART0_BASE) = UART_CTRL_TXEN | UART_CTRL_RXEN | UART_CTRL_TXIE | UART_CTRL_RXIE | UART_CTRL_RXOIE;
    NVIC_IPR8(UART0_RX_IRQn) = 0x40u; /* RX above TX: a lost input byte is a lost frame */
    NVIC_IPR8(UART0_TX_IRQn) = 0x80u;
    NVIC_IPR8(UART_OVERFLOW_IRQn) = 0x80u;
    NVIC_ISER(0) = (1u << UART0_RX_IRQn) | (1u << UART0_TX_IRQn) | (1u << UART_OVERFLOW_IRQn);
}

void uart0_rx_isr(void)
{
    /* Clear the RX flag BEFORE reading DATA: reading DATA frees the holding
     * register, the next byte may land at once and set the flag again; clearing
     * afterwards would wipe that new request and the byte would sit unread. */
    UART_INTSTATUS(UART0_BASE) = UART_INT_RX;
    while (UART_STATE(UART0_BASE) & UART_STATE_RXFULL) {
        uint8_t byte = (uint8_t)UART_DATA(UART0_BASE);
        uint32_t head = rx_ring.head;
        if (head - rx_ring.tail < UART_RX_RING_BYTES) {
            rx_buf[head & (UART_RX_RING_BYTES - 1u)] = byte;
            compiler_barrier();
            rx_ring.head = head + 1u;
            stats.rx_bytes++;
        } else {
            stats.rx_ring_drops++;
        }
    }
}

/* Starts or continues transmission; caller has interrupts masked or is the TX ISR. */
static void tx_next(void)
{
    uint32_t tail = tx_ring.tail;
    if (tail != tx_ring.head && !(UART_STATE(UART0_BASE) & UART_STATE_TXFULL)) {
        uint8_t byte = tx_buf[tail & (UART_TX_RING_BYTES - 1u)];
        compiler_barrier();
        tx_ring.tail = tail + 1u;
        tx_active = 1u;
        stats.tx_bytes++;
        UART_DATA(UART0_BASE) = byte;
    } else {
        tx_active = 0u;
    }
}

void uart0_tx_isr(void)
{
    UART_INTSTATUS(UART0_BASE) = UART_INT_TX;
    tx_next();
}

void uart_overflow_isr(void)
{
    UART_INTSTATUS(UART0_BASE) = UART_INT_RXO; /* also clears STATE.RXOVR */
    stats.rx_overruns++;
}

size_t uart0_read(uint8_t *buf, size_t cap)
{
    size_t n = 0;
    uint32_t tail = rx_ring.tail;
    uint32_t head = rx_ring.head;
    while (n < cap && tail != head) {
        buf[n++] = rx_buf[tail & (UART_RX_RING_BYTES - 1u)];
        tail++;
    }
    compiler_barrier();
    rx_ring.tail = tail;
    return n;
}

size_t uart0_tx_space(void) { return UART_TX_RING_BYTES - ring_used(&tx_ring); }

size_t uart0_write(const uint8_t *buf, size_t len)
{
    size_t n = 0;
    uint32_t head = tx_ring.head;
    while (n < len && head - tx_ring.tail < UART_TX_RING_BYTES) {
        tx_buf[head & (UART_TX_RING_BYTES - 1u)] = buf[n++];
        head++;
    }
    compiler_barrier();
    tx_ring.head = head;
    if (n > 0u) {
        uint32_t primask = board_irq_save();
        if (!tx_active) {
            tx_next(); /* the UART is idle, so no TX interrupt would ever come to start it */
        }
        board_irq_restore(primask);
    }
    return n;
}

int uart0_rx_empty(void) { return rx_ring.head == rx_ring.tail; }

int uart0_tx_idle(void) { return !tx_active && ring_used(&tx_ring) == 0u; }

uart_stats uart0_stats(void)
{
    uart_stats s;
    uint32_t primask = board_irq_save();
    s.rx_bytes = stats.rx_bytes;
    s.tx_bytes = stats.tx_bytes;
    s.rx_ring_drops = stats.rx_ring_drops;
    s.rx_overruns = stats.rx_overruns;
    board_irq_restore(primask);
    return s;
}
