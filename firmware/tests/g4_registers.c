/*
 * g4_registers.c - the host test of the NUCLEO-G474RE board's register writes (issue 22,
 * item 4). The board's own set-up (boards/nucleo-g474re: g4_setup.c, board.c), built with
 * -DG4_REGISTER_TEST, writes every peripheral block into RAM (g4_test_blocks); a small model of
 * the hardware sets the ready flags it polls for and runs TIM2 one microsecond a poll. The test
 * runs hal_init() and checks each register against numbers worked out here from RM0440 (the
 * STM32G4 reference manual, Rev 8 numbering), with the section named at each check. Offsets and
 * bit positions are written out again here from the manual, not taken from g4_regs.h, so a
 * wrong definition there fails here. Then it drives the board layer's rings through its
 * interrupt handlers (the DMA's count, the UART's flags), as the hardware would.
 */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "g4_irq.h"
#include "g4_regs.h"
#include "g4_setup.h"
#include "hal.h"

uint32_t g4_test_blocks[G4_BLOCK_COUNT][G4_BLOCK_BYTES / 4u];

static int failures, checks;

static uint32_t *reg(int block, uint32_t offset)
{
    return &g4_test_blocks[block][offset / 4u];
}

static uint32_t field(int block, uint32_t offset, unsigned shift, unsigned width)
{
    return (*reg(block, offset) >> shift) & (uint32_t)((1ull << width) - 1u);
}

static void check(const char *what, uint64_t got, uint64_t want, const char *source)
{
    checks++;
    if (got != want) {
        failures++;
        printf("FAIL %s: 0x%llx, expected 0x%llx (%s)\n", what, (unsigned long long)got,
               (unsigned long long)want, source);
    }
}

/* --- the hardware model: what the silicon does to the flags the set-up polls --- */

static int model_on;
static uint64_t polls;
static int switched;              /* SYSCLK went to the PLL */
static uint32_t at_switch_hpre, at_switch_r1mode, at_switch_latency, at_switch_pllrdy;
/* The DAC's output (DOR1) as the model moves it, from when EN1 is first seen set. */
static int dac_on;
static uint32_t dac_first, dac_last, dac_largest_step, dac_writes_seen;

void g4_test_poll(void)
{
    polls++;
    if (!model_on)
        return;
    uint32_t *tim2_cr1 = reg(G4_TIM2, 0x00), *tim2_cnt = reg(G4_TIM2, 0x24);
    if (*tim2_cr1 & 1u)
        *tim2_cnt += 1u; /* one microsecond a poll */
    uint32_t *rcc_cr = reg(G4_RCC, 0x00);
    *rcc_cr = (*rcc_cr & ~(1u << 25)) | ((*rcc_cr >> 24 & 1u) << 25); /* PLLRDY follows PLLON */
    uint32_t *cfgr = reg(G4_RCC, 0x08);
    uint32_t sw = *cfgr & 3u;
    if ((*cfgr >> 2 & 3u) != sw) {
        if (sw == 3u && !switched) {
            switched = 1;
            at_switch_hpre = *cfgr >> 4 & 0xFu;
            at_switch_r1mode = *reg(G4_PWR, 0x80) >> 8 & 1u;
            at_switch_latency = *reg(G4_FLASH_IF, 0x00) & 0xFu;
            at_switch_pllrdy = *rcc_cr >> 25 & 1u;
        }
        *cfgr = (*cfgr & ~(3u << 2)) | sw << 2; /* SWS follows SW */
    }
    int adcs[2] = {G4_ADC1, G4_ADC2};
    for (int i = 0; i < 2; i++) {
        uint32_t *cr = reg(adcs[i], 0x08);
        *cr &= ~(1u << 31); /* calibration done */
        if (*cr & 1u)
            *reg(adcs[i], 0x00) |= 1u; /* ADRDY */
    }
    /* RCC_CSR.RMVF clears the reset flags (bits 31:25) and reads 0 (§7.4 RCC_CSR). */
    uint32_t *csr = reg(G4_RCC, 0x94);
    if (*csr & 1u << 23)
        *csr &= ~(0x7Fu << 25 | 1u << 23);
    /* DAC channel 1 (§22.4): DHR12R1 (0x08) goes to DOR1 (0x2C) one clock after it is written
     * when TEN1 (bit 1) = 0, enabled or not; with TEN1 = 1 at TIM6's events only. */
    uint32_t dac_cr = *reg(G4_DAC1, 0x00), *dor = reg(G4_DAC1, 0x2C);
    if (!(dac_cr & 2u) || (*reg(G4_TIM6, 0x00) & 1u))
        *dor = *reg(G4_DAC1, 0x08) & 0xFFFu;
    if (dac_cr & 1u) {
        *reg(G4_DAC1, 0x34) |= 1u << 11; /* DAC1RDY */
        if (!dac_on) { /* the pin, floating since the reset, is driven from here on */
            dac_on = 1;
            dac_first = dac_last = *dor;
        }
        uint32_t step = *dor > dac_last ? *dor - dac_last : dac_last - *dor;
        if (step > dac_largest_step)
            dac_largest_step = step;
        if (*dor != dac_last)
            dac_writes_seen++;
        dac_last = *dor;
    }
    uint32_t cr1 = *reg(G4_USART2, 0x00);
    if (cr1 & 1u)
        *reg(G4_USART2, 0x1C) |= (cr1 >> 3 & 1u) << 21 | (cr1 >> 2 & 1u) << 22; /* TEACK, REACK */
}

void g4_test_wait_for_interrupt(void) {}

/* RCC_CSR's flags for each kind of reset (§7.4 RCC_CSR; the chip drives NRST low on every
 * reset, so PINRSTF comes with each): power-on is a brown-out reset (reset value 0x0C000000). */
#define CSR_PINRSTF (1u << 26)
#define CSR_POWER_ON (1u << 27 | CSR_PINRSTF)
#define CSR_IWDG (1u << 29 | CSR_PINRSTF)
#define CSR_SOFTWARE (1u << 28 | CSR_PINRSTF)
#define CSR_WWDG (1u << 30 | CSR_PINRSTF)
#define CSR_LOW_POWER (1u << 31 | CSR_PINRSTF)
#define CSR_OPTION_BYTES (1u << 25 | CSR_PINRSTF)

/* The reset values the set-up starts from (each register's "Reset value" in RM0440), and the
 * reset flags of the reset being simulated. RAM (g4_dac_record) is left as it is: a warm reset
 * keeps it, and a test of power-on sets it as it likes. */
static void reset(uint32_t rcc_csr)
{
    memset(g4_test_blocks, 0, sizeof g4_test_blocks);
    *reg(G4_RCC, 0x94) = rcc_csr;          /* RCC_CSR (§7.4) */
    *reg(G4_RCC, 0x00) = 0x00000500u;      /* RCC_CR: HSION, HSIRDY (§7.4) */
    *reg(G4_RCC, 0x08) = 0x00000005u;      /* RCC_CFGR: SW = SWS = HSI16 */
    *reg(G4_RCC, 0x0C) = 0x00001000u;      /* RCC_PLLCFGR */
    *reg(G4_RCC, 0x48) = 0x00000100u;      /* RCC_AHB1ENR: FLASHEN */
    *reg(G4_RCC, 0x58) = 0x00000400u;      /* RCC_APB1ENR1: RTCAPBEN */
    *reg(G4_PWR, 0x80) = 0x00000100u;      /* PWR_CR5: R1MODE (range 1 normal) (§6.4) */
    *reg(G4_FLASH_IF, 0x00) = 0x00040600u; /* FLASH_ACR: DBG_SWEN, ICEN, DCEN (§3.7) */
    *reg(G4_GPIOA, 0x00) = 0xABFFFFFFu;    /* GPIOA_MODER: analog, PA13-15 debug (§9.4) */
    *reg(G4_GPIOA, 0x0C) = 0x64000000u;    /* GPIOA_PUPDR */
    *reg(G4_GPIOA, 0x10) = 1u << 9;        /* IDR: the fault line PA9 high (no fault) */
    *reg(G4_ADC1, 0x08) = *reg(G4_ADC2, 0x08) = 0x20000000u; /* ADC_CR: DEEPPWD (§21.7) */
    *reg(G4_ADC1, 0x0C) = *reg(G4_ADC2, 0x0C) = 0x80000000u; /* ADC_CFGR: JQDIS */
    *reg(G4_IWDG, 0x08) = 0x00000FFFu;     /* IWDG_RLR (§34.4) */
    switched = 0;
    dac_on = 0;
    dac_first = dac_last = dac_largest_step = dac_writes_seen = 0u;
    polls = 0;
}

static void test_clock(void)
{
    /* HSI16 -> PLL: 16 MHz / M = 4 MHz (VCO input 2.66..8 MHz), x N = 340 MHz (VCO 96..344 MHz),
     * / R = 170 MHz: PLLM = M - 1 = 3, PLLN = 85, PLLR = 00 (/2) (§7.4, RCC_PLLCFGR). */
    check("RCC_PLLCFGR.PLLSRC (HSI16)", field(G4_RCC, 0x0C, 0, 2), 2u, "RM0440 §7.4 RCC_PLLCFGR");
    check("RCC_PLLCFGR.PLLM (/4)", field(G4_RCC, 0x0C, 4, 4), 3u, "RM0440 §7.4 RCC_PLLCFGR");
    check("RCC_PLLCFGR.PLLN (x85)", field(G4_RCC, 0x0C, 8, 7), 85u, "RM0440 §7.4 RCC_PLLCFGR");
    check("RCC_PLLCFGR.PLLR (/2)", field(G4_RCC, 0x0C, 25, 2), 0u, "RM0440 §7.4 RCC_PLLCFGR");
    check("RCC_PLLCFGR.PLLREN", field(G4_RCC, 0x0C, 24, 1), 1u, "RM0440 §7.4 RCC_PLLCFGR");
    check("PLL output (Hz)", 16000000ull / (field(G4_RCC, 0x0C, 4, 4) + 1u) * field(G4_RCC, 0x0C, 8, 7)
          / (2u * (field(G4_RCC, 0x0C, 25, 2) + 1u)), 170000000u, "RM0440 §7.2 PLL");
    check("RCC_CR.PLLON", field(G4_RCC, 0x00, 24, 1), 1u, "RM0440 §7.4 RCC_CR");
    check("RCC_CFGR.SW (PLL)", field(G4_RCC, 0x08, 0, 2), 3u, "RM0440 §7.4 RCC_CFGR");
    check("RCC_CFGR.HPRE (/1 at the end)", field(G4_RCC, 0x08, 4, 4) & 8u, 0u, "RM0440 §7.4 RCC_CFGR");
    check("RCC_CFGR.PPRE1 (/1)", field(G4_RCC, 0x08, 8, 3) & 4u, 0u, "RM0440 §7.4 RCC_CFGR");
    check("RCC_CFGR.PPRE2 (/1)", field(G4_RCC, 0x08, 11, 3) & 4u, 0u, "RM0440 §7.4 RCC_CFGR");
    /* 170 MHz needs range 1 boost: R1MODE = 0; 4 wait states (HCLK 136..170 MHz). */
    check("PWR_CR5.R1MODE (boost)", field(G4_PWR, 0x80, 8, 1), 0u, "RM0440 §6.1 range 1 boost, §6.4 PWR_CR5");
    check("FLASH_ACR.LATENCY (4 WS)", field(G4_FLASH_IF, 0x00, 0, 4), 4u, "RM0440 §3.3 read access latency");
    check("FLASH_ACR.PRFTEN/ICEN/DCEN", field(G4_FLASH_IF, 0x00, 8, 3), 7u, "RM0440 §3.7 FLASH_ACR");
    check("FLASH_ACR.DBG_SWEN (debugger kept)", field(G4_FLASH_IF, 0x00, 18, 1), 1u, "RM0440 §3.7 FLASH_ACR");
    /* The order of §6.1's "range 1 boost mode": AHB /2, R1MODE = 0 and the wait states set
     * before the switch to the higher frequency (seen by the model when SW became PLL). */
    check("switched to the PLL", (uint64_t)switched, 1u, "RM0440 §7.4 RCC_CFGR.SWS");
    check("HPRE at the switch (/2)", at_switch_hpre, 8u, "RM0440 §6.1 range 1 boost, step 1");
    check("R1MODE at the switch", at_switch_r1mode, 0u, "RM0440 §6.1 range 1 boost, step 2");
    check("LATENCY at the switch", at_switch_latency, 4u, "RM0440 §6.1 range 1 boost, step 3");
    check("PLLRDY at the switch", at_switch_pllrdy, 1u, "RM0440 §7.4 RCC_CR");
    /* The clocks of the peripherals used. */
    check("RCC_AHB1ENR DMA1EN, DMAMUX1EN", *reg(G4_RCC, 0x48) & 0x5u, 0x5u, "RM0440 §7.4 RCC_AHB1ENR");
    check("RCC_AHB2ENR GPIOAEN, ADC12EN, DAC1EN", *reg(G4_RCC, 0x4C) & 0x12001u, 0x12001u,
          "RM0440 §7.4 RCC_AHB2ENR");
    check("RCC_APB1ENR1 TIM2EN, TIM6EN, USART2EN, PWREN", *reg(G4_RCC, 0x58) & 0x10020011u, 0x10020011u,
          "RM0440 §7.4 RCC_APB1ENR1");
    check("RCC_CCIPR.USART2SEL (PCLK1)", field(G4_RCC, 0x88, 2, 2), 0u, "RM0440 §7.4 RCC_CCIPR");
}

static void test_pins(void)
{
    /* MODER (2 bits a pin): PA0, PA1, PA4 analog (11), PA2, PA3 alternate (10), PA9 input (00);
     * the rest as at reset: 0xABFFFFFF -> bits 7:4 = 1010, bits 19:18 = 00. */
    check("GPIOA_MODER", *reg(G4_GPIOA, 0x00), 0xABF3FFAFu, "RM0440 §9.4 GPIOx_MODER");
    check("GPIOA_AFRL PA2, PA3 = AF7 (USART2)", field(G4_GPIOA, 0x20, 8, 8), 0x77u, "RM0440 §9.4 GPIOx_AFRL");
    check("GPIOA_AFRL others", *reg(G4_GPIOA, 0x20) & ~0xFF00u, 0u, "RM0440 §9.4 GPIOx_AFRL");
    check("GPIOA_PUPDR PA9 pull-up", field(G4_GPIOA, 0x0C, 18, 2), 1u, "RM0440 §9.4 GPIOx_PUPDR");
}

static void test_usart(void)
{
    /* 170 MHz / 921600 = 184.46: BRR = 184 with OVER8 = 0 (923913 baud, +0.25 %). */
    check("USART2_BRR", *reg(G4_USART2, 0x0C), 184u, "RM0440 §37.5 baud rate generation");
    check("USART2_CR1 UE, RE, TE, RXFNEIE", *reg(G4_USART2, 0x00) & 0x2Du, 0x2Du, "RM0440 §37.8 USART_CR1");
    check("USART2_CR1.FIFOEN", field(G4_USART2, 0x00, 29, 1), 1u, "RM0440 §37.8 USART_CR1");
    check("USART2_CR1 8N1, OVER8 = 0 (M0 12, PCE 10, OVER8 15, M1 28)",
          *reg(G4_USART2, 0x00) & (1u << 12 | 1u << 10 | 1u << 15 | 1u << 28), 0u, "RM0440 §37.8 USART_CR1");
    check("USART2_CR2.STOP (1 bit)", field(G4_USART2, 0x04, 12, 2), 0u, "RM0440 §37.8 USART_CR2");
}

static void test_timers(void)
{
    /* TIM6 at 170 MHz: 170e6 / (PSC + 1) / (ARR + 1) = 400 kHz with PSC = 0, ARR = 424. */
    check("TIM6_PSC", *reg(G4_TIM6, 0x28), 0u, "RM0440 §31.4 TIMx_PSC");
    check("TIM6_ARR", *reg(G4_TIM6, 0x2C), 424u, "RM0440 §31.4 TIMx_ARR");
    check("TIM6_CR2.MMS (update -> TRGO)", field(G4_TIM6, 0x04, 4, 3), 2u, "RM0440 §31.4 TIMx_CR2");
    check("TIM6_CR1.CEN", field(G4_TIM6, 0x00, 0, 1), 1u, "RM0440 §31.4 TIMx_CR1");
    /* TIM2 counts microseconds: 170 MHz / (169 + 1); the whole 32 bits. */
    check("TIM2_PSC", *reg(G4_TIM2, 0x28), 169u, "RM0440 §29.4 TIMx_PSC");
    check("TIM2_ARR", *reg(G4_TIM2, 0x2C), 0xFFFFFFFFu, "RM0440 §29.4 TIMx_ARR");
    check("TIM2_EGR.UG (PSC loaded)", field(G4_TIM2, 0x14, 0, 1), 1u, "RM0440 §29.4 TIMx_EGR");
    check("TIM2_CR1.CEN", field(G4_TIM2, 0x00, 0, 1), 1u, "RM0440 §29.4 TIMx_CR1");
}

static void test_dac(void)
{
    check("DAC_CR.EN1", field(G4_DAC1, 0x00, 0, 1), 1u, "RM0440 §22.7 DAC_CR");
    check("DAC_CR.TEN1", field(G4_DAC1, 0x00, 1, 1), 1u, "RM0440 §22.7 DAC_CR");
    check("DAC_CR.TSEL1 (dac_ch1_trg7 = TIM6_TRGO)", field(G4_DAC1, 0x00, 2, 4), 7u, "RM0440 §22.4 DAC trigger table");
    check("DAC_CR.DMAEN1", field(G4_DAC1, 0x00, 12, 1), 1u, "RM0440 §22.7 DAC_CR");
    check("DAC_CR.WAVE1 (none)", field(G4_DAC1, 0x00, 6, 2), 0u, "RM0440 §22.7 DAC_CR");
    check("DAC_MCR.HFSEL (AHB > 160 MHz)", field(G4_DAC1, 0x3C, 14, 2), 2u, "RM0440 §22.7 DAC_MCR");
    check("DAC_MCR.MODE1 (buffered, to the pin)", field(G4_DAC1, 0x3C, 0, 3), 0u, "RM0440 §22.7 DAC_MCR");
    /* After power-on: PA4 driven first at code 0 (the coupling capacitor is discharged), then
     * up to mid-scale (2048) one code at a time, no step; the reset flags cleared. */
    check("power-on: the DAC's first code", dac_first, 0u, "docs/firmware.md Resets; RM0440 §7.4 RCC_CSR.BORRSTF");
    check("DAC_DHR12R1 after the ramp", *reg(G4_DAC1, 0x08), 2048u, "RM0440 §22.7 DAC_DHR12R1");
    check("DAC_DOR1 after the ramp", *reg(G4_DAC1, 0x2C), 2048u, "RM0440 §22.7 DAC_DOR1");
    check("the ramp's largest step (codes)", dac_largest_step, 1u, "docs/firmware.md: no step");
    check("the ramp's codes seen", dac_writes_seen, 2048u, "docs/firmware.md: 0 to 2048");
    check("RCC_CSR reset flags cleared (RMVF)", *reg(G4_RCC, 0x94) >> 25, 0u, "RM0440 §7.4 RCC_CSR");
}

static void test_dma(void)
{
    /* DMAMUX channel 0..2 serve DMA1 channel 1..3; request ids from the table "DMAMUX:
     * assignment of multiplexer inputs to resources": ADC1 5, DAC1_CH1 6, ADC2 36. */
    check("DMAMUX_C0CR (DAC1_CH1)", field(G4_DMAMUX, 0x00, 0, 7), 6u, "RM0440 §13.3 DMAMUX request table");
    check("DMAMUX_C1CR (ADC1)", field(G4_DMAMUX, 0x04, 0, 7), 5u, "RM0440 §13.3 DMAMUX request table");
    check("DMAMUX_C2CR (ADC2)", field(G4_DMAMUX, 0x08, 0, 7), 36u, "RM0440 §13.3 DMAMUX request table");
    /* CCR: EN 0, TCIE 1, HTIE 2, DIR 4, CIRC 5, MINC 7, PSIZE 9:8, MSIZE 11:10, PL 13:12.
     * DAC: memory (16 bits) -> DHR12R1 (32 bits), circular, very high priority, both halves. */
    check("DMA1_CCR1", *reg(G4_DMA1, 0x08), 0x1u | 0x2u | 0x4u | 0x10u | 0x20u | 0x80u | 2u << 8 | 1u << 10 | 3u << 12,
          "RM0440 §12.6 DMA_CCRx");
    check("DMA1_CNDTR1", *reg(G4_DMA1, 0x0C), 1024u, "RM0440 §12.6 DMA_CNDTRx");
    check("DMA1_CPAR1 (DAC_DHR12R1)", *reg(G4_DMA1, 0x10), (uint32_t)((uintptr_t)g4_test_blocks[G4_DAC1] + 0x08u),
          "RM0440 §22.7 DAC_DHR12R1");
    check("DMA1_CMAR1", *reg(G4_DMA1, 0x14), (uint32_t)(uintptr_t)g4_dac_ring, "RM0440 §12.6 DMA_CMARx");
    /* ADCs: DR (32 bits) -> memory (16 bits), circular, high priority, no interrupt. */
    uint32_t adc_ccr = 0x1u | 0x20u | 0x80u | 2u << 8 | 1u << 10 | 2u << 12;
    check("DMA1_CCR2", *reg(G4_DMA1, 0x1C), adc_ccr, "RM0440 §12.6 DMA_CCRx");
    check("DMA1_CCR3", *reg(G4_DMA1, 0x30), adc_ccr, "RM0440 §12.6 DMA_CCRx");
    check("DMA1_CNDTR2", *reg(G4_DMA1, 0x20), 1024u, "RM0440 §12.6 DMA_CNDTRx");
    check("DMA1_CNDTR3", *reg(G4_DMA1, 0x34), 1024u, "RM0440 §12.6 DMA_CNDTRx");
    check("DMA1_CPAR2 (ADC1_DR)", *reg(G4_DMA1, 0x24), (uint32_t)((uintptr_t)g4_test_blocks[G4_ADC1] + 0x40u),
          "RM0440 §21.7 ADC_DR");
    check("DMA1_CPAR3 (ADC2_DR)", *reg(G4_DMA1, 0x38), (uint32_t)((uintptr_t)g4_test_blocks[G4_ADC2] + 0x40u),
          "RM0440 §21.7 ADC_DR");
    check("DMA1_CMAR2", *reg(G4_DMA1, 0x28), (uint32_t)(uintptr_t)g4_voltage_ring, "RM0440 §12.6 DMA_CMARx");
    check("DMA1_CMAR3", *reg(G4_DMA1, 0x3C), (uint32_t)(uintptr_t)g4_current_ring, "RM0440 §12.6 DMA_CMARx");
}

static void test_adc(void)
{
    /* Synchronous clock HCLK / 4 = 42.5 MHz (<= 60 MHz); 47.5 + 12.5 cycles = 1.41 us a
     * conversion, inside the 2.5 us between TIM6 events. */
    check("ADC12_CCR.CKMODE (HCLK/4)", field(G4_ADC12, 0x08, 16, 2), 3u, "RM0440 §21.8 ADCx_CCR");
    check("ADC12_CCR.DUAL (independent)", field(G4_ADC12, 0x08, 0, 5), 0u, "RM0440 §21.8 ADCx_CCR");
    int adcs[2] = {G4_ADC1, G4_ADC2};
    const char *names[2] = {"ADC1", "ADC2"};
    for (int i = 0; i < 2; i++) {
        char what[80];
        unsigned channel = (unsigned)i + 1u; /* ADC1_IN1 = PA0, ADC2_IN2 = PA1 */
#define ADC_CHECK(label, got, want, source) \
        (snprintf(what, sizeof what, "%s %s", names[i], label), check(what, got, want, source))
        ADC_CHECK("CFGR.EXTSEL (adc_ext_trg13 = TIM6_TRGO)", field(adcs[i], 0x0C, 5, 5), 13u, "RM0440 §21.4 ADC1/2 trigger table");
        ADC_CHECK("CFGR.EXTEN (rising)", field(adcs[i], 0x0C, 10, 2), 1u, "RM0440 §21.7 ADC_CFGR");
        ADC_CHECK("CFGR.DMAEN, DMACFG (circular)", field(adcs[i], 0x0C, 0, 2), 3u, "RM0440 §21.7 ADC_CFGR");
        ADC_CHECK("CFGR.RES (12 bits)", field(adcs[i], 0x0C, 3, 2), 0u, "RM0440 §21.7 ADC_CFGR");
        ADC_CHECK("CFGR.CONT, ALIGN (single, right)", *reg(adcs[i], 0x0C) & (1u << 13 | 1u << 15), 0u,
                  "RM0440 §21.7 ADC_CFGR");
        ADC_CHECK("SQR1.L (one conversion)", field(adcs[i], 0x30, 0, 4), 0u, "RM0440 §21.7 ADC_SQR1");
        ADC_CHECK("SQR1.SQ1 (channel)", field(adcs[i], 0x30, 6, 5), channel, "RM0440 §21.7 ADC_SQR1");
        ADC_CHECK("SMPR1.SMPx (47.5 cycles)", field(adcs[i], 0x14, 3u * channel, 3), 4u, "RM0440 §21.7 ADC_SMPR1");
        ADC_CHECK("CR ADEN, ADSTART", *reg(adcs[i], 0x08) & 0x5u, 0x5u, "RM0440 §21.7 ADC_CR");
        ADC_CHECK("CR.ADVREGEN", field(adcs[i], 0x08, 28, 1), 1u, "RM0440 §21.7 ADC_CR");
        ADC_CHECK("CR.DEEPPWD", field(adcs[i], 0x08, 29, 1), 0u, "RM0440 §21.7 ADC_CR");
        ADC_CHECK("CR.ADCAL (done)", field(adcs[i], 0x08, 31, 1), 0u, "RM0440 §21.7 ADC_CR");
#undef ADC_CHECK
    }
}

static void test_watchdog_and_interrupts(void)
{
    /* LSI 32 kHz / 4 (PR = 0) = 8 kHz; (RL + 1) = 40 counts = 5 ms. Its last key: a reload. */
    check("IWDG_PR (/4)", *reg(G4_IWDG, 0x04), 0u, "RM0440 §34.4 IWDG_PR");
    check("IWDG_RLR (40 counts, 5 ms)", *reg(G4_IWDG, 0x08), 39u, "RM0440 §34.4 IWDG_RLR");
    check("IWDG timeout (us at 32 kHz)", (*reg(G4_IWDG, 0x08) + 1u) * (4u << *reg(G4_IWDG, 0x04)) * 1000000ull / 32000u,
          5000u, "RM0440 §34.3");
    check("IWDG_KR (last key: reload)", *reg(G4_IWDG, 0x00), 0xAAAAu, "RM0440 §34.4 IWDG_KR");
    /* Positions in the vector table: DMA1 channel 1 = 11, TIM2 = 28, USART2 = 38. */
    check("NVIC_ISER0 (DMA1_CH1, TIM2)", *reg(G4_NVIC, 0x000), 1u << 11 | 1u << 28, "RM0440 §14.3 vector table");
    check("NVIC_ISER1 (USART2)", *reg(G4_NVIC, 0x004), 1u << (38 - 32), "RM0440 §14.3 vector table");
    uint8_t *ipr = (uint8_t *)reg(G4_NVIC, 0x300);
    check("USART2 before DMA1_CH1", ipr[38] < ipr[11], 1u, "ARM v7-M B3.4 NVIC_IPR");
    check("DMA1_CH1 before TIM2", ipr[11] < ipr[28], 1u, "ARM v7-M B3.4 NVIC_IPR");
}

static void test_faults(void)
{
    check("hal_faults, fault line high", hal_faults(), 0u, "board.c");
    *reg(G4_GPIOA, 0x10) &= ~(1u << 9);
    check("hal_faults, fault line low (overcurrent)", hal_faults(), 1u, "board.c");
    *reg(G4_GPIOA, 0x10) |= 1u << 9;
    hal_watchdog_kick();
    check("hal_watchdog_kick: IWDG_KR", *reg(G4_IWDG, 0x00), 0xAAAAu, "RM0440 §34.4 IWDG_KR");
}

/* --- the board layer at run time, driven as the hardware would --- */

/* The DAC's DMA has read `done` samples since start-up (its CNDTR), with each half event. */
static uint32_t dma_done;
static void dma_advance(uint32_t samples)
{
    for (uint32_t i = 0; i < samples; i++) {
        dma_done++;
        *reg(G4_DMA1, 0x0C) = 1024u - dma_done % 1024u;
        if (dma_done % 512u == 0u) {
            *reg(G4_DMA1, 0x00) |= (dma_done % 1024u == 0u) ? 1u << 1 : 1u << 2; /* TCIF1 : HTIF1 */
            g4_dma1_ch1_irq();
        }
    }
}

static void test_output_ring(void)
{
    dma_done = 0;
    /* At start the DMA reads position 0: the first write goes 256 ahead, up to the ring's end. */
    check("room at start", hal_output_room(), 1024u - 256u, "board.c OUTPUT_LEAD");
    int16_t samples[4] = {32767, -32767, 0, -32768};
    hal_output_write(samples, 4);
    check("sample 32767 -> code", g4_dac_ring[256], 4095u, "offset binary, 12 bits");
    check("sample -32767 -> code", g4_dac_ring[257], 1u, "offset binary, 12 bits");
    check("sample 0 -> code", g4_dac_ring[258], 2048u, "offset binary, 12 bits");
    check("sample -32768 -> code (read as -32767)", g4_dac_ring[259], 1u, "board.c: symmetric, no code 0");
    check("room after 4", hal_output_room(), 1024u - 260u, "board.c");
    /* The DMA plays half 0: the interrupt refills it with mid-scale (0 V). */
    dma_advance(512);
    check("half 0 refilled", g4_dac_ring[256], 2048u, "board.c: unwritten plays 0");
    /* Pairs: the sample written at p is measured at p + 1 of the ADC rings. */
    g4_voltage_ring[257] = 2048u + 100u;
    g4_current_ring[257] = 2048u - 7u;
    g4_voltage_ring[260] = 4095u;
    int16_t v[8], c[8];
    size_t n = hal_adc_read(v, c, 8);
    check("pairs for the 4 samples", n, 4u, "hal.h hal_adc_read");
    check("pair 0 voltage", (uint64_t)(int64_t)v[0], (uint64_t)(int64_t)(100 * 16), "ADC code - 2048, x 16");
    check("pair 0 current", (uint64_t)(int64_t)c[0], (uint64_t)(int64_t)(-7 * 16), "ADC code - 2048, x 16");
    check("pair 3 voltage", (uint64_t)(int64_t)v[3], (uint64_t)(int64_t)(2047 * 16), "ADC code - 2048, x 16");
    check("no more pairs", hal_adc_read(v, c, 8), 0u, "hal.h hal_adc_read");
    /* The DMA (at 512) has passed the writer (at 260): an underrun; writing resumes 256 ahead
     * of the DMA, up to the end of the half after the one it is in (1536). */
    check("room after an underrun", hal_output_room(), 1536u - (512u + 256u), "board.c OUTPUT_LEAD");
    hal_output_write(samples, 2);
    check("written 256 ahead of the DMA", g4_dac_ring[768], 4095u, "board.c OUTPUT_LEAD");
    dma_advance(100);
    hal_output_write(samples, 2);
    check("the next write follows on", g4_dac_ring[770], 4095u, "board.c");
    check("room, no underrun", hal_output_room(), 1536u - 772u, "board.c");
    /* Those pairs are not converted until the DMA is 2 past them; pairs left for a ring's
     * time come back as zeros, in their place. */
    check("not converted yet", hal_adc_read(v, c, 8), 0u, "board.c PAIR_READY_LAG");
    dma_advance(256u + 1024u);
    check("overwritten pairs", hal_adc_read(v, c, 8), 4u, "board.c PAIR_GUARD");
    check("overwritten pairs are 0", (uint64_t)(v[0] | c[0] | v[3] | c[3]), 0u, "board.c PAIR_GUARD");
    hal_output_off();
    int mid = 1;
    for (int i = 0; i < 1024; i++)
        mid &= g4_dac_ring[i] == 2048u;
    check("hal_output_off: all mid-scale", (uint64_t)mid, 1u, "hal.h hal_output_off");
}

static void test_uart(void)
{
    /* Received: RXFNE stays set in RAM, so one interrupt takes the FIFO's depth, 8 bytes. */
    *reg(G4_USART2, 0x24) = 'A';
    *reg(G4_USART2, 0x1C) |= 1u << 5 | 1u << 3; /* RXFNE, ORE */
    g4_usart2_irq();
    check("USART2_ICR clears ORE", *reg(G4_USART2, 0x20) & 0xFu, 0xFu, "RM0440 §37.8 USART_ICR");
    uint8_t got[16];
    check("bytes read", hal_uart_read(got, sizeof got), 8u, "USART FIFO depth 8");
    check("byte", got[7], 'A', "USART_RDR");
    *reg(G4_USART2, 0x1C) &= ~(1u << 5);
    /* Sent: the write turns TXFNFIE on; the interrupt fills TDR and turns it off when done. */
    check("hal_uart_write takes", hal_uart_write((const uint8_t *)"hi", 2), 2u, "hal.h");
    check("USART2_CR1.TXFNFIE on", field(G4_USART2, 0x00, 7, 1), 1u, "RM0440 §37.8 USART_CR1");
    *reg(G4_USART2, 0x1C) |= 1u << 7; /* TXFNF */
    g4_usart2_irq();
    check("USART2_TDR last byte", *reg(G4_USART2, 0x28), 'i', "RM0440 §37.8 USART_TDR");
    check("USART2_CR1.TXFNFIE off", field(G4_USART2, 0x00, 7, 1), 0u, "RM0440 §37.8 USART_CR1");
}

static void test_time_and_serial(void)
{
    *reg(G4_TIM2, 0x24) = 0xFFFFFFF0u;
    check("hal_time_us before the wrap", hal_time_us(), 0xFFFFFFF0u, "TIM2 32 bits");
    *reg(G4_TIM2, 0x24) = 5u;
    check("hal_time_us after the wrap", hal_time_us(), 0x100000005ull, "64-bit extension");
    *reg(G4_UID, 0) = 0x00450031u;
    *reg(G4_UID, 4) = 0x484E5011u;
    *reg(G4_UID, 8) = 0x20383330u;
    char a[16], b[16];
    hal_serial_number(a);
    check("serial length", strlen(a), 15u, "hal.h: 15 characters and a NUL");
    check("serial prefix", (uint64_t)memcmp(a, "g474-", 5), 0u, "board.c");
    *reg(G4_UID, 0) ^= 1u;
    hal_serial_number(b);
    check("serials of two UIDs differ", (uint64_t)(strcmp(a, b) != 0), 1u, "RM0440 §48.1 UID");
}

/* One hal_init after a reset with these flags and this record in RAM; its DAC's first code. */
static uint32_t first_code_after(const char *what, uint32_t rcc_csr, uint32_t record_code, uint32_t record_check)
{
    char label[96];
    reset(rcc_csr);
    g4_dac_record.code = record_code;
    g4_dac_record.check = record_check;
    hal_init();
    snprintf(label, sizeof label, "%s: set-up complete", what);
    check(label, hal_faults() & 8u, 0u, "board.c");
    snprintf(label, sizeof label, "%s: mid-scale at the end", what);
    check(label, *reg(G4_DAC1, 0x2C), 2048u, "RM0440 §22.7 DAC_DOR1");
    snprintf(label, sizeof label, "%s: no step of more than 1 code once driven", what);
    check(label, dac_largest_step <= 1u, 1u, "docs/firmware.md Resets: no step");
    snprintf(label, sizeof label, "%s: reset flags cleared", what);
    check(label, *reg(G4_RCC, 0x94) >> 25, 0u, "RM0440 §7.4 RCC_CSR.RMVF");
    return dac_first;
}

/* Each kind of reset: the first code PA4 is driven at is the level the coupling capacitor holds
 * (docs/firmware.md, "Resets"). The record a finished start-up leaves: mid-scale. */
static void test_resets(void)
{
    const uint32_t key = 0x7a0d5c3bu, mid = 2048u;
    check("the record after start-up", g4_dac_record.code, mid, "g4_setup.h g4_dac_record");
    check("the record's check", g4_dac_record.check, mid ^ key, "g4_setup.h g4_dac_record");
    static const struct {
        const char *what;
        uint32_t csr;
    } warm[] = {
        {"IWDG reset", CSR_IWDG}, {"software reset", CSR_SOFTWARE}, {"NRST pin reset", CSR_PINRSTF},
        {"WWDG reset", CSR_WWDG}, {"low-power reset", CSR_LOW_POWER}, {"option-byte reset", CSR_OPTION_BYTES},
    };
    for (size_t i = 0; i < sizeof warm / sizeof warm[0]; i++) {
        char label[96];
        snprintf(label, sizeof label, "%s after start-up: the DAC's first code", warm[i].what);
        check(label, first_code_after(warm[i].what, warm[i].csr, mid, mid ^ key), mid,
              "RM0440 §7.4 RCC_CSR; docs/firmware.md Resets");
        snprintf(label, sizeof label, "%s after start-up: codes stepped", warm[i].what);
        check(label, dac_writes_seen, 0u, "docs/firmware.md Resets: no ramp");
    }
    /* An IWDG reset 25 ms into the start-up ramp (code 1000): on from 1000. */
    check("IWDG reset during the ramp: the DAC's first code", first_code_after("IWDG mid-ramp", CSR_IWDG, 1000u, 1000u ^ key),
          1000u, "docs/firmware.md Resets");
    check("IWDG reset during the ramp: codes stepped", dac_writes_seen, 1048u, "1000 to 2048");
    /* A warm reset with no valid record (a debugger or another program changed RAM): mid-scale. */
    check("IWDG reset, record not valid: first code", first_code_after("IWDG no record", CSR_IWDG, 1000u, 1000u),
          mid, "docs/firmware.md Resets");
    check("software reset, record out of range: first code",
          first_code_after("software no record", CSR_SOFTWARE, 4000u, 4000u ^ key), mid, "docs/firmware.md Resets");
    /* Power-on (and brown-out), whatever RAM holds: from 0. */
    check("power-on, RAM holding a record: first code", first_code_after("power-on", CSR_POWER_ON, mid, mid ^ key), 0u,
          "RM0440 §7.4 RCC_CSR.BORRSTF; docs/firmware.md Resets");
    check("power-on: codes stepped", dac_writes_seen, 2048u, "0 to 2048");
}

int main(void)
{
    reset(CSR_POWER_ON);
    model_on = 1;
    const hal_board_t *board = hal_init();
    check("board output rate = TIM6 event rate", board->output_rate_hz,
          170000000u / (*reg(G4_TIM6, 0x28) + 1u) / (*reg(G4_TIM6, 0x2C) + 1u), "board.c");
    check("output rate a multiple of 16000", board->output_rate_hz % 16000u, 0u, "hal.h");
    check("set-up complete (no wait ran out)", hal_faults() & 8u, 0u, "board.c");
    test_clock();
    test_pins();
    test_usart();
    test_timers();
    test_dac();
    test_dma();
    test_adc();
    test_watchdog_and_interrupts();
    test_faults();
    test_output_ring();
    test_uart();
    test_time_and_serial();
    test_resets();
    /* A board whose flags never come: every wait is bounded, and the fault is reported. */
    reset(CSR_POWER_ON);
    model_on = 0;
    hal_init();
    check("hal_init returns, supply fault reported", hal_faults() & 8u, 8u, "board.c: bounded waits");
    if (failures) {
        printf("g4 registers: %d of %d checks failed\n", failures, checks);
        return 1;
    }
    printf("g4 registers: %d checks passed\n", checks);
    return 0;
}
