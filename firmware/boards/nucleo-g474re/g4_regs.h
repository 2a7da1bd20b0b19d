/*
 * g4_regs.h - the STM32G474RE registers this board uses, written from ST's RM0440 (the STM32G4
 * reference manual), not from a vendor header. Each block cites its RM0440 section (Rev 8
 * numbering) and the manual's own register and field names, which find the same text in any
 * revision.
 *
 * Every block's base address goes through G4_BLOCK(): on the board it is the manual's address;
 * the host register test (tests/g4_registers.c, built with -DG4_REGISTER_TEST) maps each block
 * onto a RAM array instead, runs the same set-up code and reads back what it wrote.
 */
#ifndef TPAD_G4_REGS_H
#define TPAD_G4_REGS_H

#include <stdint.h>

/* The blocks, as indices for the host test's RAM map. */
enum {
    G4_FLASH_IF, G4_PWR, G4_RCC, G4_GPIOA, G4_USART2, G4_TIM2, G4_TIM6, G4_DAC1, G4_DMA1,
    G4_DMAMUX, G4_ADC1, G4_ADC2, G4_ADC12, G4_IWDG, G4_NVIC, G4_UID, G4_BLOCK_COUNT
};
#define G4_BLOCK_BYTES 0x400u /* the largest offset used below is within 1 kB of its base */

#ifdef G4_REGISTER_TEST
extern uint32_t g4_test_blocks[G4_BLOCK_COUNT][G4_BLOCK_BYTES / 4u];
#define G4_BLOCK(index, address) ((uintptr_t)g4_test_blocks[index])
#else
#define G4_BLOCK(index, address) ((uintptr_t)(address))
#endif

/* A 32-bit register (RM0440 accesses peripheral registers by words) and an 8-bit one. */
#define G4_REG(base, offset) (*(volatile uint32_t *)((base) + (offset)))
#define G4_REG8(base, offset) (*(volatile uint8_t *)((base) + (offset)))

/* --- RM0440 §2.2 "Memory map and register boundary addresses" --- */
#define FLASH_IF_BASE G4_BLOCK(G4_FLASH_IF, 0x40022000u) /* AHB1: flash interface registers */
#define PWR_BASE      G4_BLOCK(G4_PWR, 0x40007000u)      /* APB1 */
#define RCC_BASE      G4_BLOCK(G4_RCC, 0x40021000u)      /* AHB1 */
#define GPIOA_BASE    G4_BLOCK(G4_GPIOA, 0x48000000u)    /* AHB2 */
#define USART2_BASE   G4_BLOCK(G4_USART2, 0x40004400u)   /* APB1 */
#define TIM2_BASE     G4_BLOCK(G4_TIM2, 0x40000000u)     /* APB1 */
#define TIM6_BASE     G4_BLOCK(G4_TIM6, 0x40001000u)     /* APB1 */
#define DAC1_BASE     G4_BLOCK(G4_DAC1, 0x50000800u)     /* AHB2 */
#define DMA1_BASE     G4_BLOCK(G4_DMA1, 0x40020000u)     /* AHB1 */
#define DMAMUX_BASE   G4_BLOCK(G4_DMAMUX, 0x40020800u)   /* AHB1 */
#define ADC1_BASE     G4_BLOCK(G4_ADC1, 0x50000000u)     /* AHB2 */
#define ADC2_BASE     G4_BLOCK(G4_ADC2, 0x50000100u)     /* AHB2 */
#define ADC12_BASE    G4_BLOCK(G4_ADC12, 0x50000300u)    /* AHB2: ADC1/ADC2 common registers */
#define IWDG_BASE     G4_BLOCK(G4_IWDG, 0x40003000u)     /* APB1 */
/* Cortex-M4 NVIC (ARM v7-M Architecture Reference Manual B3.4; RM0440 §14): ISER at 0xE000E100. */
#define NVIC_BASE     G4_BLOCK(G4_NVIC, 0xE000E100u)
/* RM0440 §48.1 "Unique device ID register (96 bits)": three words at 0x1FFF7590. */
#define UID_BASE      G4_BLOCK(G4_UID, 0x1FFF7590u)

/* --- RM0440 §3.7 FLASH_ACR; §3.3 "Read access latency", its table of wait states: in range 1
 * boost mode an HCLK up to 170 MHz needs 4 --- */
#define FLASH_ACR 0x00u
#define FLASH_ACR_LATENCY_SHIFT 0u   /* LATENCY[3:0]: wait states */
#define FLASH_ACR_LATENCY_MASK 0xFu
#define FLASH_ACR_PRFTEN (1u << 8)   /* prefetch */
#define FLASH_ACR_ICEN (1u << 9)     /* instruction cache */
#define FLASH_ACR_DCEN (1u << 10)    /* data cache */
/* bit 18 DBG_SWEN (1 from reset) lets the debugger in: the set-up keeps it */

/* --- RM0440 §6.4 PWR registers; §6.1 "Dynamic voltage scaling management" (range 1 boost) --- */
#define PWR_CR5 0x80u
#define PWR_CR5_R1MODE (1u << 8)     /* 1: range 1 normal (reset), 0: range 1 boost (170 MHz) */

/* --- RM0440 §7.4 RCC registers --- */
#define RCC_CR 0x00u
#define RCC_CR_HSION (1u << 8)
#define RCC_CR_HSIRDY (1u << 10)
#define RCC_CR_PLLON (1u << 24)
#define RCC_CR_PLLRDY (1u << 25)
#define RCC_CFGR 0x08u
#define RCC_CFGR_SW_SHIFT 0u         /* SW[1:0]: 01 HSI16, 11 PLL */
#define RCC_CFGR_SWS_SHIFT 2u        /* SWS[1:0]: the clock in use (hardware) */
#define RCC_CFGR_SW_PLL 3u
#define RCC_CFGR_HPRE_SHIFT 4u       /* HPRE[3:0]: 0xxx /1, 1000 /2 */
#define RCC_CFGR_HPRE_DIV2 8u
#define RCC_CFGR_PPRE1_SHIFT 8u      /* PPRE1[2:0]: 0xx /1 */
#define RCC_CFGR_PPRE2_SHIFT 11u     /* PPRE2[2:0]: 0xx /1 */
#define RCC_PLLCFGR 0x0Cu
#define RCC_PLLCFGR_PLLSRC_SHIFT 0u  /* PLLSRC[1:0]: 10 HSI16 */
#define RCC_PLLCFGR_PLLSRC_HSI16 2u
#define RCC_PLLCFGR_PLLM_SHIFT 4u    /* PLLM[3:0]: divide by PLLM + 1 */
#define RCC_PLLCFGR_PLLN_SHIFT 8u    /* PLLN[6:0]: multiply by PLLN (8..127) */
#define RCC_PLLCFGR_PLLREN (1u << 24)
#define RCC_PLLCFGR_PLLR_SHIFT 25u   /* PLLR[1:0]: 00 /2, 01 /4, 10 /6, 11 /8 */
#define RCC_AHB1ENR 0x48u
#define RCC_AHB1ENR_DMA1EN (1u << 0)
#define RCC_AHB1ENR_DMAMUX1EN (1u << 2)
#define RCC_AHB2ENR 0x4Cu
#define RCC_AHB2ENR_GPIOAEN (1u << 0)
#define RCC_AHB2ENR_ADC12EN (1u << 13)
#define RCC_AHB2ENR_DAC1EN (1u << 16)
#define RCC_APB1ENR1 0x58u
#define RCC_APB1ENR1_TIM2EN (1u << 0)
#define RCC_APB1ENR1_TIM6EN (1u << 4)
#define RCC_APB1ENR1_USART2EN (1u << 17)
#define RCC_APB1ENR1_PWREN (1u << 28)
#define RCC_CCIPR 0x88u
#define RCC_CCIPR_USART2SEL_SHIFT 2u /* USART2SEL[1:0]: 00 = PCLK1 is USART2's kernel clock */
#define RCC_CSR 0x94u                /* the reset flags, kept across system resets until RMVF: */
#define RCC_CSR_RMVF (1u << 23)      /* write 1: clear every reset flag */
#define RCC_CSR_BORRSTF (1u << 27)   /* brown-out, which power-on is (RCC_CSR's reset value 0x0C000000:
                                      * BORRSTF and PINRSTF); the others are warm resets: OBLRSTF 25,
                                      * PINRSTF 26 (with every reset: the chip drives NRST itself),
                                      * SFTRSTF 28, IWDGRSTF 29, WWDGRSTF 30, LPWRRSTF 31 */

/* --- RM0440 §9.4 GPIO registers --- */
#define GPIO_MODER 0x00u             /* 2 bits a pin: 00 input, 10 alternate, 11 analog */
#define GPIO_PUPDR 0x0Cu             /* 2 bits a pin: 01 pull-up */
#define GPIO_IDR 0x10u               /* */
#define GPIO_AFRL 0x20u              /* 4 bits a pin (pins 0-7): the alternate function */
#define GPIO_MODE_INPUT 0u
#define GPIO_MODE_AF 2u
#define GPIO_MODE_ANALOG 3u
#define GPIO_PULL_UP 1u

/* --- RM0440 §37.8 USART registers (FIFO mode) --- */
#define USART_CR1 0x00u              /* (FIFO enabled) */
#define USART_CR1_UE (1u << 0)
#define USART_CR1_RE (1u << 2)
#define USART_CR1_TE (1u << 3)
#define USART_CR1_RXFNEIE (1u << 5)  /* RX FIFO not empty interrupt */
#define USART_CR1_TXFNFIE (1u << 7)  /* TX FIFO not full interrupt */
#define USART_CR1_FIFOEN (1u << 29)
#define USART_CR3 0x08u              /* */
#define USART_BRR 0x0Cu              /* USARTDIV = f_ck / baud with OVER8 = 0 */
#define USART_ISR 0x1Cu              /* (FIFO enabled) */
#define USART_ISR_PE (1u << 0)
#define USART_ISR_FE (1u << 1)
#define USART_ISR_NE (1u << 2)
#define USART_ISR_ORE (1u << 3)
#define USART_ISR_RXFNE (1u << 5)
#define USART_ISR_TXFNF (1u << 7)
#define USART_ISR_TEACK (1u << 21)
#define USART_ISR_REACK (1u << 22)
#define USART_ICR 0x20u              /* write 1 to clear PE, FE, NE, ORE (bits 0-3) */
#define USART_RDR 0x24u
#define USART_TDR 0x28u

/* --- RM0440 §29.4 TIM2..TIM5 and §31.4 TIM6/TIM7 registers (same offsets) --- */
#define TIM_CR1 0x00u
#define TIM_CR1_CEN (1u << 0)
#define TIM_CR2 0x04u
#define TIM_CR2_MMS_SHIFT 4u         /* §31.4 MMS[2:0]: 010 = the update event is TRGO */
#define TIM_CR2_MMS_UPDATE 2u
#define TIM_DIER 0x0Cu
#define TIM_DIER_CC1IE (1u << 1)     /* §29.4 TIMx_DIER: capture/compare 1 interrupt */
#define TIM_SR 0x10u
#define TIM_SR_CC1IF (1u << 1)
#define TIM_EGR 0x14u
#define TIM_EGR_UG (1u << 0)         /* re-initialise the counter, load PSC (a preloaded register) */
#define TIM_CNT 0x24u
#define TIM_PSC 0x28u                /* counter clock = f_CK_PSC / (PSC + 1) */
#define TIM_ARR 0x2Cu                /* update every ARR + 1 counts */
#define TIM_CCR1 0x34u

/* --- RM0440 §22.7 DAC registers --- */
#define DAC_CR 0x00u                 /* */
#define DAC_CR_EN1 (1u << 0)
#define DAC_CR_TEN1 (1u << 1)
#define DAC_CR_TSEL1_SHIFT 2u        /* TSEL1[3:0]: §22.4 trigger table: dac_ch1_trg7 = TIM6_TRGO */
#define DAC_CR_TSEL1_TIM6_TRGO 7u
#define DAC_CR_DMAEN1 (1u << 12)
#define DAC_DHR12R1 0x08u            /* 12-bit right-aligned data, channel 1 */
#define DAC_DOR1 0x2Cu               /* the code channel 1 outputs (read-only, 12 bits) */
#define DAC_DOR1_MASK 0xFFFu
#define DAC_SR 0x34u                 /* */
#define DAC_SR_DAC1RDY (1u << 11)
#define DAC_MCR 0x3Cu                /* */
#define DAC_MCR_HFSEL_SHIFT 14u      /* HFSEL[1:0]: 10 = AHB clock above 160 MHz */
#define DAC_MCR_HFSEL_ABOVE_160MHZ 2u

/* --- RM0440 §12.6 DMA registers (channel n = 1..8 at 0x14 * (n - 1)) --- */
#define DMA_ISR 0x00u                /* 4 flags a channel: GIF, TCIF, HTIF, TEIF */
#define DMA_IFCR 0x04u               /* the same bits, write 1 to clear */
#define DMA_FLAG_TC(n) (1u << (4u * ((n) - 1u) + 1u))
#define DMA_FLAG_HT(n) (1u << (4u * ((n) - 1u) + 2u))
#define DMA_CCR(n) (0x08u + 0x14u * ((n) - 1u))   /* */
#define DMA_CNDTR(n) (0x0Cu + 0x14u * ((n) - 1u)) /* transfers left (reloads in circular) */
#define DMA_CPAR(n) (0x10u + 0x14u * ((n) - 1u))  /* */
#define DMA_CMAR(n) (0x14u + 0x14u * ((n) - 1u))  /* */
#define DMA_CCR_EN (1u << 0)
#define DMA_CCR_TCIE (1u << 1)
#define DMA_CCR_HTIE (1u << 2)
#define DMA_CCR_DIR (1u << 4)        /* 1: read from memory */
#define DMA_CCR_CIRC (1u << 5)
#define DMA_CCR_MINC (1u << 7)
#define DMA_CCR_PSIZE_SHIFT 8u       /* PSIZE/MSIZE: 01 16 bits, 10 32 bits */
#define DMA_CCR_MSIZE_SHIFT 10u
#define DMA_CCR_PL_SHIFT 12u         /* PL: 10 high, 11 very high */
#define DMA_SIZE_16 1u
#define DMA_SIZE_32 2u

/* --- RM0440 §13.6 DMAMUX_CxCR (channel x = 0..7 serves DMA1 channel x + 1, §13.3);
 * §13.3, the table "DMAMUX: assignment of multiplexer inputs to resources" --- */
#define DMAMUX_CCR(x) (0x04u * (x))
#define DMAMUX_REQ_ADC1 5u
#define DMAMUX_REQ_DAC1_CH1 6u
#define DMAMUX_REQ_ADC2 36u

/* --- RM0440 §21.7 ADC registers (each ADC), §21.8 common registers --- */
#define ADC_ISR 0x00u                /* */
#define ADC_ISR_ADRDY (1u << 0)
#define ADC_CR 0x08u                 /* (reset value 0x2000 0000: deep power-down) */
#define ADC_CR_ADEN (1u << 0)
#define ADC_CR_ADSTART (1u << 2)
#define ADC_CR_ADVREGEN (1u << 28)
#define ADC_CR_DEEPPWD (1u << 29)
#define ADC_CR_ADCAL (1u << 31)
#define ADC_CFGR 0x0Cu               /* (reset value 0x8000 0000: JQDIS) */
#define ADC_CFGR_DMAEN (1u << 0)
#define ADC_CFGR_DMACFG (1u << 1)    /* 1: DMA circular mode */
/* EXTSEL[4:0]: §21.4, the ADC1/ADC2 regular-trigger table: adc_ext_trg13 = TIM6_TRGO */
#define ADC_CFGR_EXTSEL_SHIFT 5u
#define ADC_CFGR_EXTSEL_TIM6_TRGO 13u
#define ADC_CFGR_EXTEN_SHIFT 10u     /* EXTEN[1:0]: 01 rising edge */
#define ADC_CFGR_EXTEN_RISING 1u
#define ADC_CFGR_OVRMOD (1u << 12)
#define ADC_CFGR_JQDIS (1u << 31)
#define ADC_SMPR1 0x14u              /* SMPx[2:0] at bit 3x; 100 = 47.5 ADC clock cycles */
#define ADC_SMP_47_5 4u
#define ADC_SQR1 0x30u               /* L[3:0] conversions - 1; SQ1[4:0] at bit 6 */
#define ADC_SQR1_SQ1_SHIFT 6u
#define ADC_DR 0x40u                 /* */
#define ADC12_CCR 0x08u              /* §21.8 ADCx_CCR */
#define ADC12_CCR_CKMODE_SHIFT 16u   /* CKMODE[1:0]: 11 = HCLK / 4, synchronous */
#define ADC12_CCR_CKMODE_HCLK_DIV4 3u

/* --- RM0440 §34.4 IWDG registers --- */
#define IWDG_KR 0x00u
#define IWDG_KR_START 0xCCCCu
#define IWDG_KR_RELOAD 0xAAAAu
#define IWDG_KR_UNLOCK 0x5555u
#define IWDG_PR 0x04u                /* PR[2:0]: LSI divided by 4 << PR */
#define IWDG_RLR 0x08u               /* RL[11:0]: timeout = (RL + 1) * divider / f_LSI */
#define IWDG_SR 0x0Cu                /* PVU, RVU, WVU: an update still in progress */

/* --- NVIC (ARM v7-M ARM B3.4.4, B3.4.9): ISERn at 0x000, IPRn bytes at 0x300 from ISER0;
 * RM0440 §14.3, the "STM32G4 vector table": the interrupt positions --- */
#define NVIC_ISER(n) (0x004u * (n))
#define NVIC_IPR(irq) (0x300u + (irq))
#define IRQ_DMA1_CH1 11u
#define IRQ_TIM2 28u
#define IRQ_USART2 38u

#endif /* TPAD_G4_REGS_H */
