/*
 * clock.c - hal_time_us and hal_wait on TIMER0 (nRF51 RM chapter "Timer/counter (TIMER)"),
 * clocked from the 16 MHz crystal (RM "Clock management (CLOCK)": the RC oscillator's
 * tolerance would break STATUS's play_index against time_us, within 1 %, rule H10).
 *
 * TIMER0 counts microseconds in 32 bits (PRESCALER 4, BITMODE 32): CC[0] takes the count on
 * TASKS_CAPTURE[0] (hal_time_us), CC[1] is hal_wait's wake-up. The count wraps every 2**32 us
 * (71.6 minutes); hal_time_us extends it to 64 bits by counting the wraps it sees, which is
 * exact while it is called more often than that: hal_wait never sleeps longer than
 * MAX_SLEEP_US, and the core's loop reads the time after every wait.
 */
#include <stdint.h>

#include "board_irq.h"
#include "cortex_m0.h"
#include "hal.h"
#include "nrf51.h"

#define CAPTURE_CC 0u
#define WAKE_CC 1u
/* The longest sleep (us): well within the watchdog's timeout (board.c) and the wrap. */
#define MAX_SLEEP_US 50000u

static uint32_t last_count_us;  /* the count at the last hal_time_us */
static uint32_t wraps;          /* times the 32-bit count wrapped since power-up */

void clock_init(void)
{
    CLOCK_XTALFREQ = CLOCK_XTALFREQ_16MHZ;
    CLOCK_EVENTS_HFCLKSTARTED = 0u;
    CLOCK_TASKS_HFCLKSTART = 1u;
    while (!CLOCK_EVENTS_HFCLKSTARTED) {
    }
    TIMER0_MODE = 0u;
    TIMER0_BITMODE = TIMER0_BITMODE_32BIT;
    TIMER0_PRESCALER = TIMER0_PRESCALER_1MHZ;
    TIMER0_TASKS_CLEAR = 1u;
    TIMER0_TASKS_START = 1u;
    nvic_enable(TIMER0_IRQ);
}

uint64_t hal_time_us(void)
{
    uint32_t primask = irq_save();
    TIMER0_TASKS_CAPTURE(CAPTURE_CC) = 1u;
    uint32_t count_us = TIMER0_CC(CAPTURE_CC);
    if (count_us < last_count_us)
        wraps++;
    last_count_us = count_us;
    uint64_t now_us = ((uint64_t)wraps << 32) | count_us;
    irq_restore(primask);
    return now_us;
}

/* The wake-up compare: it has done its job (woken the core); hal_wait arms it again. */
void timer0_irq(void)
{
    TIMER0_INTENCLR = TIMER0_INTEN_COMPARE(WAKE_CC);
    TIMER0_EVENTS_COMPARE(WAKE_CC) = 0u;
}

void hal_wait(uint64_t until_us)
{
    uint64_t now_us = hal_time_us();
    if (until_us > now_us + MAX_SLEEP_US)
        until_us = now_us + MAX_SLEEP_US;
    uint32_t primask = irq_save();
    uart_tx_pump();
    if (!uart_rx_pending() && until_us > now_us) {
        TIMER0_CC(WAKE_CC) = (uint32_t)until_us;  /* first: an old CC matching now cannot fire after */
        TIMER0_EVENTS_COMPARE(WAKE_CC) = 0u;
        TIMER0_INTENSET = TIMER0_INTEN_COMPARE(WAKE_CC);
        /* A compare set at a count already passed fires only after the wrap: check again. */
        if (hal_time_us() < until_us)
            wait_for_interrupt();  /* wakes on a byte, the compare, or the transmit interrupt */
    }
    irq_restore(primask);
}
