/*
 * board_irq.h - the micro:bit board's interrupt handlers, which startup.c's vector table names,
 * and the set-up of the peripherals they serve (called by hal_init, board.c).
 */
#ifndef TPAD_MICROBIT_BOARD_IRQ_H
#define TPAD_MICROBIT_BOARD_IRQ_H

void uart_init(void);   /* uart.c: UART0 at 921600 baud, 8N1, receive and transmit interrupts */
void uart0_irq(void);
int uart_rx_pending(void); /* bytes wait in the receive ring (hal_wait does not sleep then) */
void uart_tx_pump(void);   /* with interrupts masked: send what the transmit interrupt missed */

void clock_init(void);  /* clock.c: the crystal, TIMER0 at 1 MHz */
void timer0_irq(void);

#endif /* TPAD_MICROBIT_BOARD_IRQ_H */
