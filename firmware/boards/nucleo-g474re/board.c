/*
 * board.c - hal.h on the NUCLEO-G474RE (STM32G474RE, Cortex-M4F at 170 MHz): the serial line,
 * the output ring, the measured pairs, time, the watchdog and the fault line. The register
 * set-up is g4_setup.c; the register names are g4_regs.h (RM0440).
 *
 * The output rate, 400 kHz (G4_OUTPUT_RATE_HZ):
 * - a multiple of both envelope rates (25 x 16000, 50 x 8000 Hz), as hal.h asks;
 * - exactly 170 MHz / 425, so TIM6 steps the DAC on the same crystal-free HSI16 clock as TIM2's
 *   microseconds with no drift between them (512 kHz would need 332.03 clocks a sample);
 * - within the buffered DAC1's 1 MS/s (STM32G474 datasheet, DS12288);
 * - 5 samples a cycle at the highest carrier (80 kHz, as the emulator's range): the images
 *   start at 320 kHz, which the power stage's reconstruction filter removes (docs/firmware.md);
 * - 425 CPU cycles a sample for the core's synthesis and demodulation.
 *
 * The output ring (G4_RING_SAMPLES DAC codes, read by DMA1 channel 1 at every TIM6 event):
 * positions are counted from 0 at start-up (64 bits, never wrap). When the DMA leaves a half,
 * the interrupt refills it with mid-scale (0 V), so whatever the main loop did not write plays
 * 0, and a hung main loop leaves the output at 0 within a ring's time (2.56 ms) while its
 * interrupts run (and the IWDG resets the board 5 ms after its last kick in any case).
 * hal_output_write continues where the last write ended; if the DMA has caught up with it
 * (an underrun), the next write starts OUTPUT_LEAD samples ahead of the DMA instead.
 *
 * The measured pairs: ADC1 (voltage) and ADC2 (current) convert at the same TIM6 event and
 * DMA into rings of the same length that step with the DAC's. The DAC outputs ring position
 * p from the event after its DMA read it; the conversions started at that event land at
 * position p + 1 of the ADC rings. So the pair for the sample written at p is taken at the
 * start of that sample's 2.5 us (after the DAC settles and the ADC samples for 47.5 ADC clocks,
 * 1.1 us; a fixed delay, the same for voltage and current). Each written sample gets one pair,
 * in order; a pair overwritten before hal_adc_read took it comes back as (0, 0).
 */
#include <stddef.h>
#include <stdint.h>

#include "g4_cpu.h"
#include "g4_irq.h"
#include "g4_regs.h"
#include "g4_setup.h"
#include "hal.h"

/* The example power stage of docs/firmware.md (illustrative numbers):
 * - DAC 0..3.3 V, offset-binary around 1.65 V, AC-coupled into a x30 high-voltage amplifier:
 *   sample 32767 = DAC code 2048 + 2047 = 2047 / 4096 * 3300 mV * 30 = 49477 mV peak;
 * - the clamp (A1) at 40 V, the devices' max_voltage_v;
 * - voltage sense: a 320k / 10k divider (1/33) onto a 1.65 V bias: one ADC code (3300 mV /
 *   4096) is 26.59 V / 1000 at the output; hal_adc_read's samples are codes x 16, so one LSB
 *   is 3300 mV / 65536 * 33 = 1661.7 uV (1662);
 * - current sense: a 1 ohm shunt and a x10 amplifier on a 1.65 V reference: one LSB is
 *   3300 mV / 65536 / 10 ohm = 5.035 uA (5035 nA), +-165 mA full scale; the trip at 100 mA rms. */
static const hal_board_t board = {
    .name = "g474",
    .output_rate_hz = G4_OUTPUT_RATE_HZ,
    .full_scale_mv = 49477u,
    .max_mv = 40000u,
    .carrier_min_mhz = 10000000u,
    .carrier_max_mhz = 80000000u,
    .max_current_ma = 100u,
    .measures = 7u,
    .voltage_uv_per_lsb = 1662u,
    .current_na_per_lsb = 5035u,
};

/* The DMA rings (g4_setup.h). */
uint16_t g4_dac_ring[G4_RING_SAMPLES];
volatile uint16_t g4_voltage_ring[G4_RING_SAMPLES];
volatile uint16_t g4_current_ring[G4_RING_SAMPLES];

/* A write that finds the DMA within OUTPUT_MARGIN samples of it starts OUTPUT_LEAD ahead. */
#define OUTPUT_MARGIN 8u
#define OUTPUT_LEAD 256u
/* A pair is ready 2 events after the DMA read its sample (the conversion takes 1.4 us of the
 * 2.5 us between events); it is overwritten once the rings go round, less a guard. */
#define PAIR_READY_LAG 3u
#define PAIR_GUARD 4u

static volatile uint32_t dma_halves; /* halves the ring interrupt has refilled */
static uint64_t write_position;      /* ring position (from start-up) of the next sample */

/* The written runs of positions whose pairs are still to be read, oldest first; pairs of
 * samples written while the queue was full come back as zeros (zero_pairs), in order. */
#define RUNS 8u
typedef struct {
    uint64_t start;
    uint32_t count;
} run_t;
static run_t runs[RUNS];
static uint32_t run_first, run_count, zero_pairs;

/* The serial line's rings (bytes, free-running indices). */
#define RX_BYTES 2048u
#define TX_BYTES 2048u
#define UART_FIFO_BYTES 8u /* USART2's FIFO depth (RM0440 §37.5) */
static uint8_t rx_ring[RX_BYTES];
static uint8_t tx_ring[TX_BYTES];
static volatile uint32_t rx_head, rx_tail, tx_head, tx_tail;

static uint32_t setup_timeouts;
static uint32_t time_low;  /* TIM2's count at the last hal_time_us */
static uint64_t time_high; /* its wraps, x 2**32 */

static void fill_mid(uint32_t first, uint32_t count)
{
    for (uint32_t i = first; i < first + count; i++)
        g4_dac_ring[i] = G4_DAC_MID;
}

const hal_board_t *hal_init(void)
{
    fill_mid(0u, G4_RING_SAMPLES);
    for (uint32_t i = 0; i < G4_RING_SAMPLES; i++)
        g4_voltage_ring[i] = g4_current_ring[i] = G4_DAC_MID;
    dma_halves = 0u;
    write_position = 0u;
    run_first = run_count = zero_pairs = 0u;
    rx_head = rx_tail = tx_head = tx_tail = 0u;
    time_low = 0u;
    time_high = 0u;
    setup_timeouts = g4_setup();
    return &board;
}

/* "g474-" and 10 hex digits of a 64-bit FNV-1a hash of the 96-bit unique ID (RM0440 §48.1). */
void hal_serial_number(char serial[16])
{
    static const char digits[] = "0123456789abcdef";
    uint64_t hash = 0xcbf29ce484222325u;
    for (uint32_t word = 0; word < 3u; word++) {
        uint32_t uid = G4_REG(UID_BASE, 4u * word);
        for (uint32_t byte = 0; byte < 4u; byte++) {
            hash ^= (uid >> (8u * byte)) & 0xFFu;
            hash *= 0x100000001b3u;
        }
    }
    const char prefix[] = "g474-";
    for (uint32_t i = 0; i < 5u; i++)
        serial[i] = prefix[i];
    for (uint32_t i = 0; i < 10u; i++)
        serial[5u + i] = digits[(hash >> (4u * (9u - i))) & 0xFu];
    serial[15] = '\0';
}

/* --- time: TIM2 counts microseconds; called from the main loop only --- */

uint64_t hal_time_us(void)
{
    uint32_t now = G4_REG(TIM2_BASE, TIM_CNT);
    if (now < time_low)
        time_high += (uint64_t)1u << 32;
    time_low = now;
    return time_high | now;
}

void hal_wait(uint64_t until_us)
{
    g4_irq_off();
    uint64_t now_us = hal_time_us();
    if (rx_head == rx_tail && until_us > now_us) {
        /* TIM2's compare wakes the core at until_us (the ring's interrupt, every 1.28 ms, in
         * any case); armed with interrupts masked, a match before WFI still ends it. */
        if (until_us - now_us < 0x80000000u) {
            G4_REG(TIM2_BASE, TIM_CCR1) = (uint32_t)until_us;
            G4_REG(TIM2_BASE, TIM_SR) = ~TIM_SR_CC1IF;
            G4_REG(TIM2_BASE, TIM_DIER) |= TIM_DIER_CC1IE;
        }
        if (hal_time_us() < until_us)
            g4_wait_for_interrupt();
    }
    g4_irq_on();
}

void g4_tim2_irq(void)
{
    G4_REG(TIM2_BASE, TIM_DIER) &= ~TIM_DIER_CC1IE;
    G4_REG(TIM2_BASE, TIM_SR) = ~TIM_SR_CC1IF;
}

/* --- the serial line: USART2 through the FIFOs, by interrupt --- */

size_t hal_uart_read(uint8_t *data, size_t cap)
{
    size_t n = 0;
    uint32_t head = rx_head;
    while (n < cap && rx_tail != head) {
        g4_barrier();
        data[n++] = rx_ring[rx_tail % RX_BYTES];
        rx_tail++;
    }
    return n;
}

size_t hal_uart_write(const uint8_t *data, size_t n)
{
    size_t taken = 0;
    while (taken < n && tx_head - tx_tail < TX_BYTES) {
        tx_ring[tx_head % TX_BYTES] = data[taken++];
        g4_barrier();
        tx_head++;
    }
    if (taken > 0u) {
        g4_irq_off();
        G4_REG(USART2_BASE, USART_CR1) |= USART_CR1_TXFNFIE;
        g4_irq_on();
    }
    return taken;
}

void g4_usart2_irq(void)
{
    const uint32_t errors = USART_ISR_PE | USART_ISR_FE | USART_ISR_NE | USART_ISR_ORE;
    if (G4_REG(USART2_BASE, USART_ISR) & errors)
        G4_REG(USART2_BASE, USART_ICR) = errors; /* the frame they hit fails its CRC */
    for (uint32_t i = 0; i < UART_FIFO_BYTES && (G4_REG(USART2_BASE, USART_ISR) & USART_ISR_RXFNE); i++) {
        uint8_t byte = (uint8_t)G4_REG(USART2_BASE, USART_RDR);
        if (rx_head - rx_tail < RX_BYTES) { /* full: the newest bytes are dropped (hal.h) */
            rx_ring[rx_head % RX_BYTES] = byte;
            g4_barrier();
            rx_head++;
        }
    }
    if (G4_REG(USART2_BASE, USART_CR1) & USART_CR1_TXFNFIE) {
        for (uint32_t i = 0; i < UART_FIFO_BYTES && tx_tail != tx_head
                             && (G4_REG(USART2_BASE, USART_ISR) & USART_ISR_TXFNF); i++) {
            G4_REG(USART2_BASE, USART_TDR) = tx_ring[tx_tail % TX_BYTES];
            tx_tail++;
        }
        if (tx_tail == tx_head)
            G4_REG(USART2_BASE, USART_CR1) &= ~USART_CR1_TXFNFIE;
    }
}

/* --- the output ring --- */

/* The ring position the DAC's DMA reads next (from its count left, and the halves the
 * interrupt has seen: one half event may be pending while interrupts are masked). */
static uint64_t read_position(void)
{
    for (;;) {
        uint32_t halves = dma_halves;
        uint32_t left = G4_REG(DMA1_BASE, DMA_CNDTR(1u));
        if (halves != dma_halves)
            continue;
        uint32_t position = (G4_RING_SAMPLES - left) % G4_RING_SAMPLES;
        uint64_t lap = halves / 2u + ((halves & 1u) && position < G4_HALF_SAMPLES ? 1u : 0u);
        return lap * G4_RING_SAMPLES + position;
    }
}

void g4_dma1_ch1_irq(void)
{
    uint32_t flags = G4_REG(DMA1_BASE, DMA_ISR);
    if (flags & DMA_FLAG_HT(1u)) { /* the first half played: the DMA reads the second */
        G4_REG(DMA1_BASE, DMA_IFCR) = DMA_FLAG_HT(1u);
        fill_mid(0u, G4_HALF_SAMPLES);
        dma_halves++;
    }
    if (flags & DMA_FLAG_TC(1u)) {
        G4_REG(DMA1_BASE, DMA_IFCR) = DMA_FLAG_TC(1u);
        fill_mid(G4_HALF_SAMPLES, G4_HALF_SAMPLES);
        dma_halves++;
    }
}

size_t hal_output_room(void)
{
    uint64_t read = read_position();
    if (write_position < read + OUTPUT_MARGIN)
        write_position = read + OUTPUT_LEAD;
    /* Writable: up to the end of the half after the one the interrupt last saw the DMA enter
     * (the interrupt has refilled everything before that end since it was last played). */
    uint64_t end = ((uint64_t)dma_halves + 2u) * G4_HALF_SAMPLES;
    return end > write_position ? (size_t)(end - write_position) : 0u;
}

static void note_pairs(uint64_t start, uint32_t count)
{
    if (zero_pairs == 0u && run_count > 0u) {
        run_t *last = &runs[(run_first + run_count - 1u) % RUNS];
        if (last->start + last->count == start) {
            last->count += count;
            return;
        }
    }
    if (zero_pairs == 0u && run_count < RUNS) {
        runs[(run_first + run_count) % RUNS] = (run_t){start, count};
        run_count++;
        return;
    }
    zero_pairs += count;
}

void hal_output_write(const int16_t *samples, size_t n)
{
    size_t room = hal_output_room();
    size_t fits = n < room ? n : room;
    for (size_t i = 0; i < fits; i++) {
        /* Offset binary: -32767..32767 -> codes 1..4095, symmetric about mid-scale; -32768 is
         * read as -32767 (code 1), so no sample reaches code 0. */
        int32_t sample = samples[i] < -32767 ? -32767 : samples[i];
        g4_dac_ring[(write_position + i) % G4_RING_SAMPLES] = (uint16_t)((int32_t)G4_DAC_MID + sample / 16);
    }
    if (fits > 0u)
        note_pairs(write_position, (uint32_t)fits);
    write_position += fits;
    zero_pairs += (uint32_t)(n - fits); /* not played (hal.h's caller asks for room first) */
}

void hal_output_off(void)
{
    fill_mid(0u, G4_RING_SAMPLES);
}

/* --- the measured pairs --- */

static int16_t centred(uint16_t code)
{
    return (int16_t)(((int32_t)(code & 0xFFFu) - (int32_t)G4_DAC_MID) * 16);
}

size_t hal_adc_read(int16_t *voltage, int16_t *current, size_t cap)
{
    uint64_t read = read_position();
    size_t n = 0;
    while (n < cap && run_count > 0u) {
        run_t *run = &runs[run_first];
        if (run->start + PAIR_READY_LAG > read)
            return n;
        uint64_t taken_at = run->start + 1u;
        if (read - taken_at > G4_RING_SAMPLES - PAIR_GUARD) {
            voltage[n] = current[n] = 0;
        } else {
            voltage[n] = centred(g4_voltage_ring[taken_at % G4_RING_SAMPLES]);
            current[n] = centred(g4_current_ring[taken_at % G4_RING_SAMPLES]);
        }
        n++;
        run->start++;
        if (--run->count == 0u) {
            run_first = (run_first + 1u) % RUNS;
            run_count--;
        }
    }
    while (n < cap && run_count == 0u && zero_pairs > 0u) {
        voltage[n] = current[n] = 0;
        n++;
        zero_pairs--;
    }
    return n;
}

/* --- protection --- */

void hal_watchdog_kick(void)
{
    G4_REG(IWDG_BASE, IWDG_KR) = IWDG_KR_RELOAD;
}

/* 1 (overcurrent) while the power stage holds its fault line low; 8 (supply) when the board's
 * own set-up found a clock or converter that never became ready (the output is not to be
 * trusted: START is refused, A6). */
uint8_t hal_faults(void)
{
    uint8_t bits = setup_timeouts > 0u ? 8u : 0u;
    if ((G4_REG(GPIOA_BASE, GPIO_IDR) & (1u << G4_FAULT_PIN)) == 0u)
        bits |= 1u;
    return bits;
}
