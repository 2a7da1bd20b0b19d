/*
 * uart.c - hal_uart_read and hal_uart_write on the nRF51's UART0 (nRF51 RM chapter 29), at
 * 921600 baud 8N1 on the micro:bit's USB serial pins. Neither ever blocks:
 * - receive: the RXDRDY interrupt moves each byte from RXD into rx_ring; when the ring is full
 *   the newest bytes are dropped (their frame then fails its CRC: a bad frame, never applied);
 * - transmit: hal_uart_write copies into tx_ring and the TXDRDY interrupt sends it byte by byte.
 * Each ring has one writer and one reader; its indices run free (mod 2**32, the sizes are powers
 * of two) and a 32-bit store is atomic on the Cortex-M0, so no lock is needed but the one that
 * starts a transmission.
 */
#include <stddef.h>
#include <stdint.h>

#include "board_irq.h"
#include "cortex_m0.h"
#include "hal.h"
#include "nrf51.h"

#define RX_BYTES 1024u  /* 11 ms at 921600 baud between two reads by the main loop */
#define TX_BYTES 512u   /* more than one STATUS and one ACK (64 + 16 bytes on the line) */

static volatile uint8_t rx_ring[RX_BYTES];
static volatile uint32_t rx_head, rx_tail;  /* written by the interrupt / by hal_uart_read */
static volatile uint8_t tx_ring[TX_BYTES];
static volatile uint32_t tx_head, tx_tail;  /* written by hal_uart_write / by uart_tx_pump */
static volatile uint8_t tx_busy;            /* a byte is in TXD and its TXDRDY not yet taken */

void uart_init(void)
{
    /* The UART chapter: TXD an output driven high, RXD an input, set in the GPIO. */
    GPIO_OUTSET = 1u << MICROBIT_UART_TX_PIN;
    GPIO_DIRSET = 1u << MICROBIT_UART_TX_PIN;
    GPIO_PIN_CNF(MICROBIT_UART_RX_PIN) = GPIO_PIN_CNF_INPUT_CONNECTED;
    UART0_PSELTXD = MICROBIT_UART_TX_PIN;
    UART0_PSELRXD = MICROBIT_UART_RX_PIN;
    UART0_CONFIG = 0u;
    UART0_BAUDRATE = UART0_BAUDRATE_921600;
    UART0_ENABLE = UART0_ENABLE_ENABLED;
    UART0_EVENTS_RXDRDY = 0u;
    UART0_EVENTS_TXDRDY = 0u;
    UART0_INTENSET = UART0_INTEN_RXDRDY | UART0_INTEN_TXDRDY;
    UART0_TASKS_STARTRX = 1u;
    UART0_TASKS_STARTTX = 1u;
    nvic_enable(UART0_IRQ);
}

/* Send from tx_ring while the UART takes bytes. Runs in the interrupt, or with interrupts
 * masked: QEMU's UART (7.2) sets TXDRDY without raising the interrupt when a byte waited for a
 * full pty, so hal_uart_write and hal_wait call this too; on the chip it then finds nothing. */
void uart_tx_pump(void)
{
    for (;;) {
        if (UART0_EVENTS_TXDRDY) {
            UART0_EVENTS_TXDRDY = 0u;
            tx_busy = 0u;
        }
        if (tx_busy || tx_head == tx_tail)
            return;
        tx_busy = 1u;
        UART0_TXD = tx_ring[tx_tail % TX_BYTES];
        tx_tail = tx_tail + 1u;
    }
}

void uart0_irq(void)
{
    /* RM: clear RXDRDY before reading RXD; the FIFO behind it sets RXDRDY again while it holds
     * more. */
    while (UART0_EVENTS_RXDRDY) {
        UART0_EVENTS_RXDRDY = 0u;
        uint8_t byte = (uint8_t)UART0_RXD;
        if (rx_head - rx_tail < RX_BYTES) {
            rx_ring[rx_head % RX_BYTES] = byte;
            rx_head = rx_head + 1u;
        }
    }
    uart_tx_pump();
}

int uart_rx_pending(void) { return rx_head != rx_tail; }

size_t hal_uart_read(uint8_t *data, size_t cap)
{
    size_t count = 0;
    uint32_t tail = rx_tail;
    uint32_t head = rx_head;
    while (count < cap && tail != head) {
        data[count++] = rx_ring[tail % RX_BYTES];
        tail++;
    }
    rx_tail = tail;
    return count;
}

size_t hal_uart_write(const uint8_t *data, size_t n)
{
    uint32_t head = tx_head;
    size_t room = TX_BYTES - (size_t)(head - tx_tail);
    size_t taken = n < room ? n : room;
    for (size_t i = 0; i < taken; i++)
        tx_ring[(head + i) % TX_BYTES] = data[i];
    tx_head = head + (uint32_t)taken;
    uint32_t primask = irq_save();
    uart_tx_pump();
    irq_restore(primask);
    return taken;
}
