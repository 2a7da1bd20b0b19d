/*
 * nrf51.h - the nRF51822 registers the micro:bit board uses, written from the nRF51 Series
 * Reference Manual v3.0 ("RM" below; each block cites its chapter and register table).
 * Only what this board touches; no vendor SDK. Every register is a 32-bit word; a task is
 * triggered by writing 1, an event is cleared by writing 0 (RM "Peripheral interface":
 * tasks, events, shortcuts and interrupts).
 */
#ifndef TPAD_NRF51_H
#define TPAD_NRF51_H

#include <stdint.h>

#define NRF51_REG(address) (*(volatile uint32_t *)(uintptr_t)(address))

/* RM "Peripheral interface": a peripheral's ID (its interrupt number) is bits 12-16 of its
 * base address. */
#define NRF51_IRQ_OF(base) ((unsigned)(((base) >> 12) & 0x1Fu))

/* --- CLOCK: clock management (RM chapter "Clock management (CLOCK)", register table) --- */
#define CLOCK_BASE 0x40000000u
#define CLOCK_TASKS_HFCLKSTART NRF51_REG(CLOCK_BASE + 0x000u)  /* start the crystal oscillator */
#define CLOCK_EVENTS_HFCLKSTARTED NRF51_REG(CLOCK_BASE + 0x100u)
#define CLOCK_XTALFREQ NRF51_REG(CLOCK_BASE + 0x550u)          /* crystal frequency */
#define CLOCK_XTALFREQ_16MHZ 0xFFu                             /* the micro:bit's crystal */

/* --- UART0 (RM chapter 29 "Universal Asynchronous Receiver/Transmitter (UART)",
 *     register table and the BAUDRATE register's values) --- */
#define UART0_BASE 0x40002000u
#define UART0_IRQ NRF51_IRQ_OF(UART0_BASE)                     /* 2 */
#define UART0_TASKS_STARTRX NRF51_REG(UART0_BASE + 0x000u)
#define UART0_TASKS_STARTTX NRF51_REG(UART0_BASE + 0x008u)
#define UART0_EVENTS_RXDRDY NRF51_REG(UART0_BASE + 0x108u)     /* a byte is in RXD */
#define UART0_EVENTS_TXDRDY NRF51_REG(UART0_BASE + 0x11Cu)     /* TXD's byte has gone */
#define UART0_INTENSET NRF51_REG(UART0_BASE + 0x304u)
#define UART0_INTEN_RXDRDY (1u << 2)
#define UART0_INTEN_TXDRDY (1u << 7)
#define UART0_ENABLE NRF51_REG(UART0_BASE + 0x500u)
#define UART0_ENABLE_ENABLED 4u
#define UART0_PSELTXD NRF51_REG(UART0_BASE + 0x50Cu)           /* pin number */
#define UART0_PSELRXD NRF51_REG(UART0_BASE + 0x514u)
#define UART0_RXD NRF51_REG(UART0_BASE + 0x518u)               /* read after clearing RXDRDY */
#define UART0_TXD NRF51_REG(UART0_BASE + 0x51Cu)
#define UART0_BAUDRATE NRF51_REG(UART0_BASE + 0x524u)
#define UART0_BAUDRATE_921600 0x0EBEDFA4u                      /* RM's value for the nRF51 */
#define UART0_CONFIG NRF51_REG(UART0_BASE + 0x56Cu)            /* 0: no flow control, no parity */

/* --- TIMER0 (RM chapter "Timer/counter (TIMER)", register table): f = 16 MHz / 2**PRESCALER --- */
#define TIMER0_BASE 0x40008000u
#define TIMER0_IRQ NRF51_IRQ_OF(TIMER0_BASE)                   /* 8 */
#define TIMER0_TASKS_START NRF51_REG(TIMER0_BASE + 0x000u)
#define TIMER0_TASKS_CLEAR NRF51_REG(TIMER0_BASE + 0x00Cu)
#define TIMER0_TASKS_CAPTURE(n) NRF51_REG(TIMER0_BASE + 0x040u + 4u * (n)) /* counter -> CC[n] */
#define TIMER0_EVENTS_COMPARE(n) NRF51_REG(TIMER0_BASE + 0x140u + 4u * (n))
#define TIMER0_INTENSET NRF51_REG(TIMER0_BASE + 0x304u)
#define TIMER0_INTENCLR NRF51_REG(TIMER0_BASE + 0x308u)
#define TIMER0_INTEN_COMPARE(n) (1u << (16u + (n)))
#define TIMER0_MODE NRF51_REG(TIMER0_BASE + 0x504u)            /* 0: timer */
#define TIMER0_BITMODE NRF51_REG(TIMER0_BASE + 0x508u)
#define TIMER0_BITMODE_32BIT 3u
#define TIMER0_PRESCALER NRF51_REG(TIMER0_BASE + 0x510u)
#define TIMER0_PRESCALER_1MHZ 4u                               /* 16 MHz / 2**4 */
#define TIMER0_CC(n) NRF51_REG(TIMER0_BASE + 0x540u + 4u * (n))

/* --- WDT (RM chapter "Watchdog timer (WDT)", register table): runs on the 32.768 kHz clock,
 *     timeout = (CRV + 1) / 32768 s; a reload writes RR_RELOAD to every enabled RR --- */
#define WDT_BASE 0x40010000u
#define WDT_TASKS_START NRF51_REG(WDT_BASE + 0x000u)
#define WDT_CRV NRF51_REG(WDT_BASE + 0x504u)
#define WDT_RREN NRF51_REG(WDT_BASE + 0x508u)
#define WDT_CONFIG NRF51_REG(WDT_BASE + 0x50Cu)
#define WDT_CONFIG_RUN_WHILE_SLEEPING 1u                       /* bit 0 SLEEP; bit 3 HALT left 0 */
#define WDT_RR(n) NRF51_REG(WDT_BASE + 0x600u + 4u * (n))
#define WDT_RR_RELOAD 0x6E524635u
#define WDT_LFCLK_HZ 32768u

/* --- FICR (RM chapter "Factory information configuration registers (FICR)"): a 64-bit
 *     random device identifier --- */
#define FICR_BASE 0x10000000u
#define FICR_DEVICEID(n) NRF51_REG(FICR_BASE + 0x060u + 4u * (n))

/* --- GPIO (RM chapter "General purpose input/output (GPIO)", register table): the UART's pins
 *     are set in the GPIO as the UART chapter asks: TXD an output driven high, RXD an input --- */
#define GPIO_BASE 0x50000000u
#define GPIO_OUTSET NRF51_REG(GPIO_BASE + 0x508u)
#define GPIO_DIRSET NRF51_REG(GPIO_BASE + 0x518u)
#define GPIO_PIN_CNF(n) NRF51_REG(GPIO_BASE + 0x700u + 4u * (n))
#define GPIO_PIN_CNF_INPUT_CONNECTED 0u                        /* DIR input, input buffer on */

/* The micro:bit (v1.x) wires UART0 to its interface chip's USB serial port: TX P0.24, RX P0.25
 * (the micro:bit's schematic; micro:bit v2 is an nRF52833 and needs another board). */
#define MICROBIT_UART_TX_PIN 24u
#define MICROBIT_UART_RX_PIN 25u

#endif /* TPAD_NRF51_H */
