/*
 * g4_cpu.h - the few Cortex-M4 instructions the board needs (ARM v7-M ARM: CPSID/CPSIE, WFI),
 * and the host register test's stand-ins for them (tests/g4_registers.c defines those).
 */
#ifndef TPAD_G4_CPU_H
#define TPAD_G4_CPU_H

/* A compiler barrier: the ring's bytes are stored before its index says so (the M4 itself
 * keeps the order of its own stores, as seen by its interrupts). */
static inline void g4_barrier(void) { __asm__ volatile("" ::: "memory"); }

#ifdef G4_REGISTER_TEST
/* The test's model of the hardware: it sets the ready flags a polled register waits for. */
void g4_test_poll(void);
void g4_test_wait_for_interrupt(void);
static inline void g4_irq_off(void) {}
static inline void g4_irq_on(void) {}
static inline void g4_wait_for_interrupt(void) { g4_test_wait_for_interrupt(); }
static inline void g4_poll(void) { g4_test_poll(); }
#else
/* Mask interrupts (PRIMASK); a pending interrupt still ends WFI, and runs on g4_irq_on. */
static inline void g4_irq_off(void) { __asm__ volatile("cpsid i" ::: "memory"); }
static inline void g4_irq_on(void) { __asm__ volatile("cpsie i" ::: "memory"); }
static inline void g4_wait_for_interrupt(void) { __asm__ volatile("dsb\n\twfi" ::: "memory"); }
static inline void g4_poll(void) {}
#endif

#endif /* TPAD_G4_CPU_H */
