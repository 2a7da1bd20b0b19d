/*
 * g4_setup.c - hal_init's register writes on the STM32G474RE, in the order RM0440 asks for.
 * Every wait on a ready flag is bounded (G4_WAIT_POLLS) and counted when it runs out, so a
 * board whose clock or converter never comes up reports it (hal_faults) instead of hanging.
 * The host register test runs this file against RAM (g4_regs.h) and checks what it wrote.
 */
#include "g4_setup.h"

#include <stdint.h>

#include "g4_cpu.h"
#include "g4_regs.h"

/* Most polls of a ready flag (well over the longest wait, the PLL's lock, at 170 MHz). */
#define G4_WAIT_POLLS 1000000u

/* PLL (RM0440 §7.2 "PLL", RCC_PLLCFGR's field notes): VCO input = HSI16 / M (2.66..8 MHz),
 * VCO = input * N (96..344 MHz), SYSCLK = VCO / R: 16 MHz / 4 = 4 MHz, * 85 = 340 MHz, / 2 = 170 MHz. */
#define PLL_M 4u
#define PLL_N 85u
#define PLL_R 2u
#define FLASH_WAIT_STATES 4u      /* RM0440 §3.3: range 1 boost, HCLK 136..170 MHz */
/* Cycles of a volatile loop that last >= 1 us at up to 170 MHz (each pass takes >= 2 cycles). */
#define ONE_US_LOOPS 100u

/* The DAC's ramp from its first code up to mid-scale: one code every 25 us (from 0: 51.2 ms),
 * so that the AC-coupled power stage (docs/firmware.md, "Resets") sees no step. */
#define DAC_RAMP_STEP_US 25u
/* ADC (RM0440 §21.4, its voltage regulator and calibration): the regulator's start-up time
 * (t_ADCVREG_STUP, 20 us in the datasheet), and the 4 ADC clocks after calibration before ADEN
 * (1 us covers them at HCLK / 4). */
#define ADC_REGULATOR_US 20u
#define ADC_AFTER_CAL_US 1u
/* IWDG: LSI (32 kHz) / 4 = 8 kHz, 40 counts = 5 ms (4.7..5.4 ms over the LSI's 29.5..34 kHz,
 * datasheet DS12288). */
#define IWDG_PRESCALER_CODE 0u
#define IWDG_RELOAD 39u
/* Interrupt priorities (upper 4 bits count on the G4): the UART first, so no byte is lost. */
#define PRIORITY_USART2 0x00u
#define PRIORITY_DMA1_CH1 0x40u
#define PRIORITY_TIM2 0x80u

/* The pins: their alternate and analog functions from the STM32G474 datasheet (DS12288,
 * pin and alternate-function tables), where they go on the board from its user manual (UM2505). */
#define PIN_VOLTAGE 0u   /* PA0 = ADC12_IN1 (Arduino A0): the voltage divider */
#define PIN_CURRENT 1u   /* PA1 = ADC12_IN2 (Arduino A1): the current-sense amplifier */
#define PIN_TX 2u        /* PA2 = USART2_TX, AF7: the ST-LINK virtual COM port */
#define PIN_RX 3u        /* PA3 = USART2_RX, AF7 */
#define PIN_DAC 4u       /* PA4 = DAC1_OUT1 (Arduino A2): the power stage's input */
#define AF_USART2 7u
#define ADC1_CHANNEL 1u  /* ADC1_IN1 on PA0 */
#define ADC2_CHANNEL 2u  /* ADC2_IN2 on PA1 */

/* The record survives warm resets in .noinit (link.ld); the host test keeps it in plain RAM. */
#ifdef G4_REGISTER_TEST
volatile g4_dac_record_t g4_dac_record;
#else
__attribute__((section(".noinit"))) volatile g4_dac_record_t g4_dac_record;
#endif

static uint32_t timeouts;
static int timer_stuck; /* TIM2 never moved: later delays are not waited for (counted once) */

static void wait_for(uintptr_t base, uint32_t offset, uint32_t mask, uint32_t want)
{
    for (uint32_t poll = 0; poll < G4_WAIT_POLLS; poll++) {
        if ((G4_REG(base, offset) & mask) == want)
            return;
        g4_poll();
    }
    timeouts++;
}

static void delay_loops(uint32_t loops)
{
    for (volatile uint32_t i = 0; i < loops; i++) {
    }
}

/* `us` microseconds on TIM2's counter (running once time_setup is done). */
static void delay_us(uint32_t us)
{
    if (timer_stuck)
        return;
    uint32_t start = G4_REG(TIM2_BASE, TIM_CNT);
    for (uint32_t poll = 0; poll < G4_WAIT_POLLS; poll++) {
        if (G4_REG(TIM2_BASE, TIM_CNT) - start >= us)
            return;
        g4_poll();
    }
    timeouts++;
    timer_stuck = 1;
}

static void set_field(uintptr_t base, uint32_t offset, uint32_t shift, uint32_t width, uint32_t value)
{
    uint32_t mask = ((1u << width) - 1u) << shift;
    G4_REG(base, offset) = (G4_REG(base, offset) & ~mask) | ((value << shift) & mask);
}

/* HSI16 -> PLL -> 170 MHz in range 1 boost mode: RM0440 §6.1.5's sequence. */
static void clock_setup(void)
{
    G4_REG(RCC_BASE, RCC_APB1ENR1) |= RCC_APB1ENR1_PWREN;
    (void)G4_REG(RCC_BASE, RCC_APB1ENR1); /* the enable takes effect before PWR is written */
    /* 1. AHB prescaler /2 before the system clock goes up; 2. range 1 boost (R1MODE = 0);
     * 3. the wait states of the new frequency, read back before the switch (RM0440 §3.3.3). */
    set_field(RCC_BASE, RCC_CFGR, RCC_CFGR_HPRE_SHIFT, 4u, RCC_CFGR_HPRE_DIV2);
    G4_REG(PWR_BASE, PWR_CR5) &= ~PWR_CR5_R1MODE;
    set_field(FLASH_IF_BASE, FLASH_ACR, FLASH_ACR_LATENCY_SHIFT, 4u, FLASH_WAIT_STATES);
    G4_REG(FLASH_IF_BASE, FLASH_ACR) |= FLASH_ACR_PRFTEN | FLASH_ACR_ICEN | FLASH_ACR_DCEN; /* DBG_SWEN kept */
    wait_for(FLASH_IF_BASE, FLASH_ACR, FLASH_ACR_LATENCY_MASK, FLASH_WAIT_STATES);
    /* HSI16 (on from reset) feeds the PLL, which is set up while off (RM0440 §7.4.4). */
    G4_REG(RCC_BASE, RCC_CR) |= RCC_CR_HSION;
    wait_for(RCC_BASE, RCC_CR, RCC_CR_HSIRDY, RCC_CR_HSIRDY);
    G4_REG(RCC_BASE, RCC_CR) &= ~RCC_CR_PLLON;
    wait_for(RCC_BASE, RCC_CR, RCC_CR_PLLRDY, 0u);
    G4_REG(RCC_BASE, RCC_PLLCFGR) = RCC_PLLCFGR_PLLSRC_HSI16 << RCC_PLLCFGR_PLLSRC_SHIFT
        | (PLL_M - 1u) << RCC_PLLCFGR_PLLM_SHIFT | PLL_N << RCC_PLLCFGR_PLLN_SHIFT
        | (PLL_R / 2u - 1u) << RCC_PLLCFGR_PLLR_SHIFT | RCC_PLLCFGR_PLLREN;
    G4_REG(RCC_BASE, RCC_CR) |= RCC_CR_PLLON;
    wait_for(RCC_BASE, RCC_CR, RCC_CR_PLLRDY, RCC_CR_PLLRDY);
    /* 4. switch to the PLL, APB1 and APB2 undivided; 5. after 1 us, AHB back to /1. */
    set_field(RCC_BASE, RCC_CFGR, RCC_CFGR_PPRE1_SHIFT, 3u, 0u);
    set_field(RCC_BASE, RCC_CFGR, RCC_CFGR_PPRE2_SHIFT, 3u, 0u);
    set_field(RCC_BASE, RCC_CFGR, RCC_CFGR_SW_SHIFT, 2u, RCC_CFGR_SW_PLL);
    wait_for(RCC_BASE, RCC_CFGR, 3u << RCC_CFGR_SWS_SHIFT, RCC_CFGR_SW_PLL << RCC_CFGR_SWS_SHIFT);
    delay_loops(ONE_US_LOOPS);
    set_field(RCC_BASE, RCC_CFGR, RCC_CFGR_HPRE_SHIFT, 4u, 0u);
    /* The peripherals this board uses. */
    G4_REG(RCC_BASE, RCC_AHB1ENR) |= RCC_AHB1ENR_DMA1EN | RCC_AHB1ENR_DMAMUX1EN;
    G4_REG(RCC_BASE, RCC_AHB2ENR) |= RCC_AHB2ENR_GPIOAEN | RCC_AHB2ENR_ADC12EN | RCC_AHB2ENR_DAC1EN;
    G4_REG(RCC_BASE, RCC_APB1ENR1) |= RCC_APB1ENR1_TIM2EN | RCC_APB1ENR1_TIM6EN | RCC_APB1ENR1_USART2EN;
    (void)G4_REG(RCC_BASE, RCC_APB1ENR1);
    set_field(RCC_BASE, RCC_CCIPR, RCC_CCIPR_USART2SEL_SHIFT, 2u, 0u);
}

static void gpio_setup(void)
{
    set_field(GPIOA_BASE, GPIO_MODER, 2u * PIN_VOLTAGE, 2u, GPIO_MODE_ANALOG);
    set_field(GPIOA_BASE, GPIO_MODER, 2u * PIN_CURRENT, 2u, GPIO_MODE_ANALOG);
    set_field(GPIOA_BASE, GPIO_MODER, 2u * PIN_DAC, 2u, GPIO_MODE_ANALOG);
    set_field(GPIOA_BASE, GPIO_AFRL, 4u * PIN_TX, 4u, AF_USART2);
    set_field(GPIOA_BASE, GPIO_AFRL, 4u * PIN_RX, 4u, AF_USART2);
    set_field(GPIOA_BASE, GPIO_MODER, 2u * PIN_TX, 2u, GPIO_MODE_AF);
    set_field(GPIOA_BASE, GPIO_MODER, 2u * PIN_RX, 2u, GPIO_MODE_AF);
    set_field(GPIOA_BASE, GPIO_PUPDR, 2u * G4_FAULT_PIN, 2u, GPIO_PULL_UP);
    set_field(GPIOA_BASE, GPIO_MODER, 2u * G4_FAULT_PIN, 2u, GPIO_MODE_INPUT);
}

/* 921600 baud, 8N1, FIFOs on, receive by interrupt (transmit interrupts come and go: board.c). */
static void usart2_setup(void)
{
    G4_REG(USART2_BASE, USART_CR1) = 0u;
    G4_REG(USART2_BASE, USART_BRR) = (G4_SYSCLK_HZ + G4_BAUD / 2u) / G4_BAUD;
    G4_REG(USART2_BASE, USART_CR3) = 0u;
    G4_REG(USART2_BASE, USART_CR1) = USART_CR1_FIFOEN | USART_CR1_TE | USART_CR1_RE | USART_CR1_RXFNEIE;
    G4_REG(USART2_BASE, USART_CR1) |= USART_CR1_UE;
    wait_for(USART2_BASE, USART_ISR, USART_ISR_TEACK | USART_ISR_REACK, USART_ISR_TEACK | USART_ISR_REACK);
}

/* TIM2: a free-running 32-bit microsecond counter (hal_time_us, hal_wait's compare). */
static void time_setup(void)
{
    G4_REG(TIM2_BASE, TIM_PSC) = G4_SYSCLK_HZ / G4_TIME_HZ - 1u;
    G4_REG(TIM2_BASE, TIM_ARR) = 0xFFFFFFFFu;
    G4_REG(TIM2_BASE, TIM_EGR) = TIM_EGR_UG;
    G4_REG(TIM2_BASE, TIM_CR1) = TIM_CR1_CEN;
}

/* The reset's cause (RCC_CSR's flags, RM0440 §7.4), read and cleared for the next reset. */
static uint32_t take_reset_flags(void)
{
    uint32_t flags = G4_REG(RCC_BASE, RCC_CSR);
    G4_REG(RCC_BASE, RCC_CSR) |= RCC_CSR_RMVF;
    return flags;
}

static void record_dac(uint32_t code)
{
    g4_dac_record.code = code;
    g4_dac_record.check = code ^ G4_DAC_RECORD_KEY;
}

/* The code PA4 must start at so that the coupling capacitor (charged to the DAC's last resting
 * level, PA4 floating while the chip is in reset) sees no step: 0 after power-on or a brown-out
 * (the capacitor discharged, as far as the firmware can know); after any warm reset the recorded
 * code, or mid-scale when the record is not valid (RAM changed by a debugger or another program,
 * which this firmware assumes left the output at mid-scale as it does). */
static uint32_t first_dac_code(uint32_t reset_flags)
{
    if (reset_flags & RCC_CSR_BORRSTF)
        return 0u;
    uint32_t code = g4_dac_record.code;
    if ((code ^ G4_DAC_RECORD_KEY) == g4_dac_record.check && code <= G4_DAC_MID)
        return code;
    return G4_DAC_MID;
}

/* TIM6's update (TRGO) at the output rate steps the DAC and both ADCs; DAC1 channel 1 starts at
 * first_code, is triggered by TIM6 and ramps to mid-scale, then TIM6 stops until the DMA rings
 * are armed. */
static void output_setup(uint32_t first_code)
{
    G4_REG(TIM6_BASE, TIM_CR1) = 0u;
    G4_REG(TIM6_BASE, TIM_PSC) = 0u;
    G4_REG(TIM6_BASE, TIM_ARR) = G4_SYSCLK_HZ / G4_OUTPUT_RATE_HZ - 1u;
    G4_REG(TIM6_BASE, TIM_CR2) = TIM_CR2_MMS_UPDATE << TIM_CR2_MMS_SHIFT;
    G4_REG(TIM6_BASE, TIM_EGR) = TIM_EGR_UG;
    G4_REG(DAC1_BASE, DAC_MCR) = DAC_MCR_HFSEL_ABOVE_160MHZ << DAC_MCR_HFSEL_SHIFT;
    /* The first code into DOR1 before the channel is on: with no trigger (TEN1 = 0) DHR goes to
     * DOR one clock later, the channel's digital side working while EN1 = 0 (RM0440 §22.4, "DAC
     * channel enable" and "DAC conversion"); with TEN1 = 1 DOR would hold its reset 0 until the
     * first TIM6 event, a step to 0 V of up to one sample. */
    G4_REG(DAC1_BASE, DAC_CR) = 0u;
    G4_REG(DAC1_BASE, DAC_DHR12R1) = first_code;
    wait_for(DAC1_BASE, DAC_DOR1, DAC_DOR1_MASK, first_code);
    record_dac(first_code);
    G4_REG(DAC1_BASE, DAC_CR) = DAC_CR_TSEL1_TIM6_TRGO << DAC_CR_TSEL1_SHIFT | DAC_CR_TEN1;
    G4_REG(DAC1_BASE, DAC_CR) |= DAC_CR_EN1;
    wait_for(DAC1_BASE, DAC_SR, DAC_SR_DAC1RDY, DAC_SR_DAC1RDY);
    G4_REG(TIM6_BASE, TIM_CR1) = TIM_CR1_CEN;
    for (uint32_t code = first_code + 1u; code <= G4_DAC_MID; code++) {
        G4_REG(DAC1_BASE, DAC_DHR12R1) = code;
        record_dac(code);
        delay_us(DAC_RAMP_STEP_US);
    }
    G4_REG(TIM6_BASE, TIM_CR1) = 0u;
}

/* ADC1 (voltage, PA0) and ADC2 (current, PA1): clocked by HCLK / 4 synchronously, so each
 * conversion starts a fixed number of cycles after TIM6's event (no jitter between the two). */
static void adc_setup(void)
{
    static const uintptr_t adcs[2] = {ADC1_BASE, ADC2_BASE};
    static const uint32_t channels[2] = {ADC1_CHANNEL, ADC2_CHANNEL};
    set_field(ADC12_BASE, ADC12_CCR, ADC12_CCR_CKMODE_SHIFT, 2u, ADC12_CCR_CKMODE_HCLK_DIV4);
    for (int i = 0; i < 2; i++) {
        G4_REG(adcs[i], ADC_CR) = 0u; /* out of deep power-down */
        G4_REG(adcs[i], ADC_CR) = ADC_CR_ADVREGEN;
    }
    delay_us(ADC_REGULATOR_US);
    for (int i = 0; i < 2; i++) {
        G4_REG(adcs[i], ADC_CR) |= ADC_CR_ADCAL; /* single-ended calibration */
        wait_for(adcs[i], ADC_CR, ADC_CR_ADCAL, 0u);
    }
    delay_us(ADC_AFTER_CAL_US);
    for (int i = 0; i < 2; i++) {
        /* Configured while disabled (every field below may be written with ADEN = 0). */
        G4_REG(adcs[i], ADC_CFGR) = ADC_CFGR_JQDIS | ADC_CFGR_OVRMOD
            | ADC_CFGR_EXTEN_RISING << ADC_CFGR_EXTEN_SHIFT
            | ADC_CFGR_EXTSEL_TIM6_TRGO << ADC_CFGR_EXTSEL_SHIFT | ADC_CFGR_DMACFG | ADC_CFGR_DMAEN;
        G4_REG(adcs[i], ADC_SMPR1) = ADC_SMP_47_5 << (3u * channels[i]);
        G4_REG(adcs[i], ADC_SQR1) = channels[i] << ADC_SQR1_SQ1_SHIFT; /* L = 0: one conversion */
        G4_REG(adcs[i], ADC_CR) |= ADC_CR_ADEN; /* ADRDY is 0 from reset until then */
        wait_for(adcs[i], ADC_ISR, ADC_ISR_ADRDY, ADC_ISR_ADRDY);
    }
}

static void dma_channel(uint32_t n, uint32_t request, uintptr_t peripheral, volatile uint16_t *ring, uint32_t ccr)
{
    G4_REG(DMA1_BASE, DMA_CCR(n)) = 0u;
    G4_REG(DMAMUX_BASE, DMAMUX_CCR(n - 1u)) = request;
    G4_REG(DMA1_BASE, DMA_CPAR(n)) = (uint32_t)peripheral;
    G4_REG(DMA1_BASE, DMA_CMAR(n)) = (uint32_t)(uintptr_t)ring;
    G4_REG(DMA1_BASE, DMA_CNDTR(n)) = G4_RING_SAMPLES;
    G4_REG(DMA1_BASE, DMA_CCR(n)) = ccr | DMA_CCR_CIRC | DMA_CCR_MINC
        | DMA_SIZE_16 << DMA_CCR_MSIZE_SHIFT | DMA_SIZE_32 << DMA_CCR_PSIZE_SHIFT;
    G4_REG(DMA1_BASE, DMA_CCR(n)) |= DMA_CCR_EN;
}

/* Channel 1: the DAC ring (memory to DHR12R1, very high priority, an interrupt at each half);
 * channels 2 and 3: ADC1 and ADC2 into theirs. Then the ADCs wait for triggers, the DAC asks
 * for DMA, and TIM6 starts from 0: all three rings step together from their first entry. */
static void rings_setup(void)
{
    dma_channel(1u, DMAMUX_REQ_DAC1_CH1, DAC1_BASE + DAC_DHR12R1, g4_dac_ring,
                DMA_CCR_DIR | DMA_CCR_TCIE | DMA_CCR_HTIE | 3u << DMA_CCR_PL_SHIFT);
    dma_channel(2u, DMAMUX_REQ_ADC1, ADC1_BASE + ADC_DR, g4_voltage_ring, 2u << DMA_CCR_PL_SHIFT);
    dma_channel(3u, DMAMUX_REQ_ADC2, ADC2_BASE + ADC_DR, g4_current_ring, 2u << DMA_CCR_PL_SHIFT);
    G4_REG(ADC1_BASE, ADC_CR) |= ADC_CR_ADSTART;
    G4_REG(ADC2_BASE, ADC_CR) |= ADC_CR_ADSTART;
    G4_REG(DAC1_BASE, DAC_CR) |= DAC_CR_DMAEN1;
    G4_REG(TIM6_BASE, TIM_CNT) = 0u;
    G4_REG(TIM6_BASE, TIM_CR1) = TIM_CR1_CEN;
}

static void nvic_enable(uint32_t irq, uint8_t priority)
{
    G4_REG8(NVIC_BASE, NVIC_IPR(irq)) = priority;
    /* ISER reads the enabled set and writing 0 changes nothing: |= is a plain set on the M4,
     * and keeps the earlier bits in the host test's RAM. */
    G4_REG(NVIC_BASE, NVIC_ISER(irq / 32u)) |= 1u << (irq % 32u);
}

/* The IWDG last (it cannot be stopped once started, RM0440 §34.3): 5 ms without a kick resets. */
static void iwdg_setup(void)
{
    G4_REG(IWDG_BASE, IWDG_KR) = IWDG_KR_START;
    G4_REG(IWDG_BASE, IWDG_KR) = IWDG_KR_UNLOCK;
    G4_REG(IWDG_BASE, IWDG_PR) = IWDG_PRESCALER_CODE;
    G4_REG(IWDG_BASE, IWDG_RLR) = IWDG_RELOAD;
    wait_for(IWDG_BASE, IWDG_SR, 0x7u, 0u);
    G4_REG(IWDG_BASE, IWDG_KR) = IWDG_KR_RELOAD;
}

uint32_t g4_setup(void)
{
    timeouts = 0;
    timer_stuck = 0;
    uint32_t first_code = first_dac_code(take_reset_flags());
    clock_setup();
    gpio_setup();
    usart2_setup();
    time_setup();
    output_setup(first_code);
    adc_setup();
    rings_setup();
    nvic_enable(IRQ_USART2, PRIORITY_USART2);
    nvic_enable(IRQ_DMA1_CH1, PRIORITY_DMA1_CH1);
    nvic_enable(IRQ_TIM2, PRIORITY_TIM2);
    iwdg_setup();
    return timeouts;
}
