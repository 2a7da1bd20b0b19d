/* core_hal.c - a scripted board for the tests of run.c: hal.h on a simulated clock. Bytes arrive at
 * set times, the output takes what room allows, the ADC returns each output sample as the voltage
 * and half of it as the current (a resistive load), faults come at set times, and hal_wait moves
 * the clock (and ends amp_run by longjmp once the script's end is reached). */
#include <setjmp.h>
#include <string.h>

#include "core_hal.h"

hal_script_t hal_script;

const hal_board_t *hal_init(void) {
    hal_script.inits++;
    return hal_script.board;
}

void hal_serial_number(char serial[16]) {
    strcpy(serial, "SCRIPT-1");
}

uint64_t hal_time_us(void) {
    return hal_script.now_us;
}

void hal_wait(uint64_t until_us) {
    hal_script.waits++;
    hal_script.last_wait_us = until_us;
    uint64_t next = until_us;
    if (hal_script.rx_at < hal_script.rx_count && hal_script.rx[hal_script.rx_at].at_us < next)
        next = hal_script.rx[hal_script.rx_at].at_us;
    if (hal_script.fault_bits && hal_script.fault_at_us < next)
        next = hal_script.fault_at_us;
    if (next > hal_script.now_us + hal_script.max_wait_us)
        next = hal_script.now_us + hal_script.max_wait_us;
    if (next > hal_script.now_us)
        hal_script.now_us = next;
    if (hal_script.now_us >= hal_script.end_us && hal_script.jump != NULL)
        longjmp(*hal_script.jump, 1);
}

size_t hal_uart_read(uint8_t *data, size_t cap) {
    size_t n = 0;
    while (n < cap && hal_script.rx_at < hal_script.rx_count
           && hal_script.rx[hal_script.rx_at].at_us <= hal_script.now_us) {
        data[n++] = hal_script.rx[hal_script.rx_at].byte;
        hal_script.rx_at++;
    }
    return n;
}

size_t hal_uart_write(const uint8_t *data, size_t n) {
    size_t room = sizeof hal_script.tx - hal_script.tx_count;
    if (n > hal_script.tx_per_call)
        n = hal_script.tx_per_call;
    if (n > room)
        n = room;
    memcpy(hal_script.tx + hal_script.tx_count, data, n);
    hal_script.tx_count += n;
    return n;
}

size_t hal_output_room(void) {
    return hal_script.output_room;
}

void hal_output_write(const int16_t *samples, size_t n) {
    for (size_t i = 0; i < n; i++) {
        if (hal_script.output_count < HAL_SCRIPT_OUTPUT)
            hal_script.output[hal_script.output_count] = samples[i];
        hal_script.output_count++;
    }
}

void hal_output_off(void) {
    hal_script.output_offs++;
}

size_t hal_adc_read(int16_t *voltage, int16_t *current, size_t cap) {
    size_t n = 0;
    while (n < cap && hal_script.adc_count < hal_script.output_count && hal_script.adc_count < HAL_SCRIPT_OUTPUT) {
        voltage[n] = hal_script.output[hal_script.adc_count];
        current[n] = (int16_t)(hal_script.output[hal_script.adc_count] / 2);
        hal_script.adc_count++;
        n++;
    }
    return n;
}

void hal_watchdog_kick(void) {
    hal_script.kicks++;
}

uint8_t hal_faults(void) {
    if (hal_script.fault_bits && hal_script.now_us >= hal_script.fault_at_us) {
        uint8_t bits = hal_script.fault_bits;
        hal_script.fault_bits = 0;
        return bits;
    }
    return 0;
}
