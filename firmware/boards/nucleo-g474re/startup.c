/*
 * startup.c - reset and the vector table of the STM32G474RE (Cortex-M4F): copy .data, zero
 * .bss, enable the FPU, then main(): the portable core's loop (amp_run calls hal_init).
 * The addresses come from link.ld; the vector positions from RM0440 §14.3 ("STM32G4 vector
 * table": 16 Cortex-M4 exceptions, then 102 interrupts).
 */
#include <stdint.h>

#include "amp.h"
#include "hal.h"
#include "g4_irq.h"
#include "g4_regs.h"

extern uint32_t _estack, _sidata, _sdata, _edata, _sbss, _ebss;

void reset_handler(void);
void fault_handler(void);
int main(void);

/* Coprocessor access control (ARM v7-M ARM B3.2.20, CPACR at 0xE000ED88): CP10 and CP11
 * full access, so the core's float code runs on the FPU (-mfloat-abi=hard). */
#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)
#define CPACR_CP10_CP11_FULL (0xFu << 20)

#define EXCEPTIONS 16u
#define INTERRUPTS 102u

/* The table: the initial stack pointer, then the handlers. Interrupts this board never
 * enables are left 0; a fault cuts the output to mid-scale and waits for the IWDG's reset. */
typedef struct {
    uint32_t *initial_sp;
    void (*handlers[EXCEPTIONS - 1u + INTERRUPTS])(void);
} vector_table_t;

__attribute__((section(".isr_vector"), used)) static const vector_table_t vectors = {
    &_estack,
    {
        [1u - 1u] = reset_handler,
        [2u - 1u] = fault_handler,  /* NMI */
        [3u - 1u] = fault_handler,  /* HardFault */
        [4u - 1u] = fault_handler,  /* MemManage */
        [5u - 1u] = fault_handler,  /* BusFault */
        [6u - 1u] = fault_handler,  /* UsageFault */
        [EXCEPTIONS - 1u + IRQ_DMA1_CH1] = g4_dma1_ch1_irq,
        [EXCEPTIONS - 1u + IRQ_TIM2] = g4_tim2_irq,
        [EXCEPTIONS - 1u + IRQ_USART2] = g4_usart2_irq,
    },
};

void reset_handler(void)
{
    uint32_t *from = &_sidata;
    for (uint32_t *to = &_sdata; to < &_edata;)
        *to++ = *from++;
    for (uint32_t *to = &_sbss; to < &_ebss;)
        *to++ = 0u;
    SCB_CPACR |= CPACR_CP10_CP11_FULL;
    __asm__ volatile("dsb\n\tisb" ::: "memory");
    main();
    for (;;) {
    }
}

/* Cut the carrier as a fault does (A6): the whole ring to mid-scale, which TIM6 and the DMA go on
 * playing, so the coupling capacitor stays at mid-scale and the restart after the IWDG's reset
 * (no longer kicked: within 5.4 ms) starts there with no second step (docs/firmware.md, Resets). */
void fault_handler(void)
{
    hal_output_off();
    for (;;) {
    }
}

int main(void)
{
    amp_run();
    return 0;
}
