/*
 * board.c - the BBC micro:bit (v1.x: nRF51822, Cortex-M0 at 16 MHz, 256 kB flash, 16 kB RAM)
 * as a PROTOCOL-ONLY amplifier: it speaks docs/amp-protocol.md on its USB serial port (the
 * interface chip's UART bridge) and drives nothing. It has no DAC and measures nothing:
 * output_rate_hz and measures are 0, the hal_output_* functions do nothing and hal_adc_read
 * gives no samples. It exists to run the portable core on a real Cortex-M build, under QEMU's
 * `microbit` machine (firmware/run-qemu) or on the board itself; what a user drives a plate
 * with is boards/nucleo-g474re.
 *
 * INFO's volts are therefore nominal, not a promise about any pin: full_scale_mv and max_mv
 * are those the Python emulator gives the shipped devices (max 40 V, full scale 1.25 times
 * that), so that a host streams the same samples to this board as to the emulator, and A1/A2
 * run on the same numbers; the carrier range is the emulator's 10-80 kHz; no current trip.
 */
#include <stdint.h>

#include "board_irq.h"
#include "hal.h"
#include "nrf51.h"

/* The hardware watchdog: a core that stops kicking it for this long resets the chip (A7).
 * Above hal_wait's longest sleep (clock.c: 50 ms) with room to spare. */
#define WATCHDOG_TIMEOUT_MS 250u

static const hal_board_t microbit = {
    .name = "microbit",
    .output_rate_hz = 0u,           /* no carrier: protocol only */
    .full_scale_mv = 50000u,        /* nominal (see above) */
    .max_mv = 40000u,
    .carrier_min_mhz = 10000000u,   /* 10 kHz */
    .carrier_max_mhz = 80000000u,   /* 80 kHz */
    .max_current_ma = 0u,           /* no trip: nothing is measured */
    .measures = 0u,
    .voltage_uv_per_lsb = 0u,
    .current_na_per_lsb = 0u,
};

static void watchdog_init(void)
{
    WDT_CRV = WATCHDOG_TIMEOUT_MS * WDT_LFCLK_HZ / 1000u - 1u;
    WDT_RREN = 1u;  /* RR[0] only */
    WDT_CONFIG = WDT_CONFIG_RUN_WHILE_SLEEPING;
    WDT_TASKS_START = 1u;
}

const hal_board_t *hal_init(void)
{
    clock_init();
    uart_init();
    watchdog_init();
    return &microbit;
}

/* "MB-" and the low 48 bits of FICR's DEVICEID in hex: 15 characters. */
void hal_serial_number(char serial[16])
{
    static const char hex[] = "0123456789ABCDEF";
    uint64_t id = ((uint64_t)(FICR_DEVICEID(1) & 0xFFFFu) << 32) | FICR_DEVICEID(0);
    serial[0] = 'M';
    serial[1] = 'B';
    serial[2] = '-';
    for (int digit = 0; digit < 12; digit++)
        serial[3 + digit] = hex[(id >> (4 * (11 - digit))) & 0xFu];
    serial[15] = '\0';
}

void hal_watchdog_kick(void) { WDT_RR(0) = WDT_RR_RELOAD; }

/* No output stage: nothing to take, nothing to play, nothing to switch off. */
size_t hal_output_room(void) { return 0; }

void hal_output_write(const int16_t *samples, size_t n)
{
    (void)samples;
    (void)n;
}

void hal_output_off(void) {}

/* No ADC. */
size_t hal_adc_read(int16_t *voltage, int16_t *current, size_t cap)
{
    (void)voltage;
    (void)current;
    (void)cap;
    return 0;
}

/* No comparator or supervisor is wired: no hardware fault is ever seen. */
uint8_t hal_faults(void) { return 0u; }
