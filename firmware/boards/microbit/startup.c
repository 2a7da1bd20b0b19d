/*
 * startup.c - the nRF51822's vector table and reset handler (ARMv6-M ARM B1.5.2-B1.5.3: word 0
 * the initial stack pointer, word 1 the reset handler, then the exceptions and the nRF51's 32
 * interrupts, numbered by peripheral ID: nRF51 RM "Peripheral interface").
 *
 * The reset handler copies .data from flash, zeroes .bss and calls main(). An unexpected
 * exception (a fault, an interrupt nobody enabled) stops here, asleep: the watchdog, which
 * nothing kicks any more, then resets the chip with its output at 0 (A7). Asleep, not
 * spinning: no interrupt can preempt a fault handler, so WFI does not return (ARMv6-M ARM
 * B1.5.18), and QEMU's CPU thread, which run-qemu runs at real-time priority, stays idle.
 */
#include <stdint.h>
#include <string.h>

#include "board_irq.h"
#include "cortex_m0.h"
#include "nrf51.h"

/* The table below places uart0_irq at entry 2 and timer0_irq at entry 8: their peripheral IDs. */
typedef char uart0_is_interrupt_2[UART0_IRQ == 2u ? 1 : -1];
typedef char timer0_is_interrupt_8[TIMER0_IRQ == 8u ? 1 : -1];

/* The linker script's symbols (microbit.ld). */
extern uint32_t _stack_top, _data_load, _data_start, _data_end, _bss_start, _bss_end;

int main(void);

static void unexpected_exception(void)
{
    for (;;)
        wait_for_interrupt();
}

static void reset_handler(void)
{
    memcpy(&_data_start, &_data_load, (size_t)((uintptr_t)&_data_end - (uintptr_t)&_data_start));
    memset(&_bss_start, 0, (size_t)((uintptr_t)&_bss_end - (uintptr_t)&_bss_start));
    (void)main();  /* amp_run never returns */
    unexpected_exception();
}

#define EXCEPTIONS 15u  /* exception numbers 1..15 */
#define INTERRUPTS 32u  /* nRF51 peripheral IDs 0..31 */

typedef void (*handler_t)(void);

typedef struct {
    void *stack_top;
    handler_t exception[EXCEPTIONS];
    handler_t interrupt[INTERRUPTS];
} vector_table_t;

/* Placed at address 0 by microbit.ld; every entry not named is unexpected_exception. */
__attribute__((section(".vectors"), used))
static const vector_table_t vectors = {
    &_stack_top,
    {
        reset_handler,        unexpected_exception, unexpected_exception, unexpected_exception,
        unexpected_exception, unexpected_exception, unexpected_exception, unexpected_exception,
        unexpected_exception, unexpected_exception, unexpected_exception, unexpected_exception,
        unexpected_exception, unexpected_exception, unexpected_exception,
    },
    {
        unexpected_exception, unexpected_exception, uart0_irq,            unexpected_exception,
        unexpected_exception, unexpected_exception, unexpected_exception, unexpected_exception,
        timer0_irq,           unexpected_exception, unexpected_exception, unexpected_exception,
        unexpected_exception, unexpected_exception, unexpected_exception, unexpected_exception,
        unexpected_exception, unexpected_exception, unexpected_exception, unexpected_exception,
        unexpected_exception, unexpected_exception, unexpected_exception, unexpected_exception,
        unexpected_exception, unexpected_exception, unexpected_exception, unexpected_exception,
        unexpected_exception, unexpected_exception, unexpected_exception, unexpected_exception,
    },
};
