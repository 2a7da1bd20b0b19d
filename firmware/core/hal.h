/*
 * hal.h - the hardware interface: what a board gives the portable core.
 *
 * The core (firmware/core) holds no hardware: the protocol, the envelope buffer, the
 * limits (A1 clamp, A2 slew, A4 watchdog, A6 faults), STATUS, the carrier synthesis and
 * the measurement all run on what these functions give. A board (firmware/boards/NAME)
 * implements every function below, in C99, against its reference manual's registers.
 * docs/firmware.md "Porting to a new board" says what each must guarantee.
 *
 * Units: times in microseconds of the board's own monotonic clock (hal_time_us), which
 * starts near 0 at power-up and never wraps in practice (64 bits); output and ADC samples
 * are signed 16-bit values, full scale +-32767.
 */
#ifndef TPAD_AMP_HAL_H
#define TPAD_AMP_HAL_H

#include <stddef.h>
#include <stdint.h>

/* What the board is: its constants, read once by the core at start-up. */
typedef struct {
    /* INFO's firmware string is "tpad-amp <version>"; the board's name goes into its serial. */
    const char *name;
    /* Output (carrier) samples per second: a multiple of every envelope rate the board offers
     * (8000 and 16000 Hz), so a multiple of 16000, at most 4000000 (AMP_MAX_OUTPUT_RATE_HZ);
     * 0 when the board makes no carrier (a protocol-only board). */
    uint32_t output_rate_hz;
    /* Peak output (mV, at the amplifier's output: the drive the device's circuit model takes)
     * of output sample 32767, 1 .. 1000000 (1000 V), and the clamp (A1, mV peak,
     * 1 .. full_scale_mv). */
    uint32_t full_scale_mv;
    uint32_t max_mv;
    /* The carriers the board can make (mHz; the range must hold a multiple of 10 mHz below half
     * the output rate), and the overcurrent trip (mA rms; 0 = none; any value). */
    uint32_t carrier_min_mhz;
    uint32_t carrier_max_mhz;
    uint32_t max_current_ma;
    /* INFO's measures bits (1 current, 2 voltage, 4 phase; 0 .. 7): 0 when the board has no ADC. */
    uint8_t measures;
    /* What one ADC step is: microvolts (at the amplifier's output) and nanoamperes (through
     * the plate) per least significant bit of hal_adc_read's samples; any value, not 0 for what
     * measures names (STATUS's rms values saturate at 2**32 - 1). amp_init refuses a board with a
     * constant out of these ranges (amp.h: AMP_BOARD_*). */
    uint32_t voltage_uv_per_lsb;
    uint32_t current_na_per_lsb;
} hal_board_t;

/* Set the board up (clocks, pins, UART, timer, output, ADC, watchdog) with the output at 0
 * (A7); returns its constants. Called once, first. */
const hal_board_t *hal_init(void);

/* The board's serial number, as up to 15 ASCII characters and a NUL. */
void hal_serial_number(char serial[16]);

/* --- time --- */

/* Microseconds since power-up on the board's monotonic clock. */
uint64_t hal_time_us(void);

/* Sleep until a byte arrives, the output wants samples, or hal_time_us() reaches until_us,
 * whichever comes first (it may return early; never much later). */
void hal_wait(uint64_t until_us);

/* --- the serial line (UART or USB CDC): never blocks --- */

/* Bytes received since the last call, up to cap; returns how many were copied. A board keeps
 * a receive buffer filled by interrupt or DMA; on overflow it drops the newest bytes (the
 * frames they belonged to then fail their CRC: counted as bad, never applied). */
size_t hal_uart_read(uint8_t *data, size_t cap);

/* Queue up to n bytes for sending; returns how many were taken (0 when the queue is full). */
size_t hal_uart_write(const uint8_t *data, size_t n);

/* --- the output: the carrier, sample by sample --- */

/* Output samples the board can take now without overwriting samples not yet played. */
size_t hal_output_room(void);

/* Queue n output samples (the carrier times the envelope), played at output_rate_hz in order. */
void hal_output_write(const int16_t *samples, size_t n);

/* Set the output to 0 at once, dropping what is queued (a fault: A6). */
void hal_output_off(void);

/* --- the ADC: voltage and current at the plate, one pair per output sample --- */

/* Measured pairs since the last call, up to cap, in the order of the output samples they
 * were taken with (the k-th pair is the one taken while the k-th output sample played,
 * after the board's fixed delay). Returns how many were copied; 0 on a board with no ADC. */
size_t hal_adc_read(int16_t *voltage, int16_t *current, size_t cap);

/* --- protection --- */

/* Restart the board's hardware watchdog: the core calls it from its main loop; a hung
 * core stops calling it, and the board resets with its output at 0 (A7). */
void hal_watchdog_kick(void);

/* Hardware fault bits latched since the last call (STATUS's: 1 overcurrent, 2 overvoltage,
 * 4 overtemperature, 8 supply): a comparator or supervisor that the board reads. */
uint8_t hal_faults(void);

#endif /* TPAD_AMP_HAL_H */
