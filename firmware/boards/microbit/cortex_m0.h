/*
 * cortex_m0.h - what the board uses of the Cortex-M0 core, from the ARMv6-M Architecture
 * Reference Manual (ARM DDI 0419): the NVIC (B3.4), PRIMASK (B1.4.3, CPSID/CPSIE) and WFI
 * (B1.5.18: a pending interrupt wakes the core even while PRIMASK masks it, so "mask, check,
 * WFI, unmask" never sleeps through the interrupt that the check missed).
 */
#ifndef TPAD_CORTEX_M0_H
#define TPAD_CORTEX_M0_H

#include <stdint.h>

#define NVIC_ISER (*(volatile uint32_t *)(uintptr_t)0xE000E100u)  /* B3.4.3: set-enable, bit n = IRQ n */

static inline void nvic_enable(unsigned irq) { NVIC_ISER = 1u << irq; }

/* Mask interrupts and return the previous PRIMASK (1: they were masked). */
static inline uint32_t irq_save(void)
{
    uint32_t primask;
    __asm__ volatile ("mrs %0, primask\n\tcpsid i" : "=r"(primask) : : "memory");
    return primask;
}

static inline void irq_restore(uint32_t primask)
{
    if (!primask)
        __asm__ volatile ("cpsie i" : : : "memory");
}

static inline void wait_for_interrupt(void) { __asm__ volatile ("wfi" : : : "memory"); }

#endif /* TPAD_CORTEX_M0_H */
