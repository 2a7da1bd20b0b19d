/*
 * g4_setup.h - the register writes hal_init makes on the STM32G474RE (g4_setup.c), and the
 * board's clock and converter numbers the rest of the board layer (board.c) shares.
 */
#ifndef TPAD_G4_SETUP_H
#define TPAD_G4_SETUP_H

#include <stdint.h>

/* Clocks (g4_setup.c derives each register value from these). */
#define G4_SYSCLK_HZ 170000000u   /* HSI16 / 4 * 85 / 2: SYSCLK = HCLK = PCLK1 = PCLK2 */
#define G4_OUTPUT_RATE_HZ 400000u /* DAC and ADC samples per second (board.c says why) */
#define G4_BAUD 921600u           /* the serial line (docs/amp-protocol.md section 1) */
#define G4_TIME_HZ 1000000u       /* TIM2 counts microseconds */

/* The DMA rings: G4_RING_SAMPLES DAC codes (played in a circle, in two halves) and as many
 * ADC1 (voltage) and ADC2 (current) conversions, all three stepped by the same TIM6 event. */
#define G4_RING_SAMPLES 1024u
#define G4_HALF_SAMPLES (G4_RING_SAMPLES / 2u)
/* The rings themselves (board.c): DAC codes, and ADC1's and ADC2's conversions (12 bits). */
extern uint16_t g4_dac_ring[G4_RING_SAMPLES];
extern volatile uint16_t g4_voltage_ring[G4_RING_SAMPLES];
extern volatile uint16_t g4_current_ring[G4_RING_SAMPLES];
#define G4_DAC_MID 2048u          /* the 12-bit DAC's mid-scale: output sample 0 */
#define G4_FAULT_PIN 9u           /* PA9 (Arduino D8): the power stage's fault line, active low */

/* The code the DAC last rested at (the start-up ramp's progress, then mid-scale for good: the
 * carrier plays around it), kept in RAM that a warm reset leaves alone and startup.c does not
 * clear (.noinit): the level the AC coupling capacitor holds. Valid when check == code ^
 * G4_DAC_RECORD_KEY. */
typedef struct {
    uint32_t code;
    uint32_t check;
} g4_dac_record_t;
extern volatile g4_dac_record_t g4_dac_record;
#define G4_DAC_RECORD_KEY 0x7a0d5c3bu

/* Set the board up with the output at mid-scale (A7): the reset's cause (RCC_CSR, then cleared),
 * clocks, pins, USART2, TIM2, the DAC from the first code the reset calls for (0 after power-on,
 * the recorded code after a warm reset) up to mid-scale, the ADCs, the three DMA rings,
 * interrupts, and last the IWDG. Returns how many ready flags never came within their bounded
 * wait (0 when all did). */
uint32_t g4_setup(void);

#endif /* TPAD_G4_SETUP_H */
