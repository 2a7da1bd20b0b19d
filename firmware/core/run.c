/* run.c - the main loop on hal.h (a board's main() sets itself up, then calls amp_run). */
#include <string.h>

#include "amp_core.h"

#define CHUNK 64u          /* bytes or samples moved per hal call */
#define MAX_READS 16u      /* reads per pass: a flood of bytes cannot starve the output */

static amp_t amp_state;    /* the core's whole state: static, no allocation */

void amp_run(void) {
    static amp_pending_t pending;
    char serial[16] = { 0 };
    const hal_board_t *board = hal_init();
    hal_serial_number(serial);
    serial[15] = 0;
    /* a board out of hal.h's ranges runs refused: its output stays 0 (no console to say more on) */
    (void)amp_init(&amp_state, board, serial, hal_time_us());
    for (;;)
        amp_run_once(&amp_state, &pending);
}

static void move_output(amp_t *amp) {
    int16_t samples[CHUNK];
    size_t room = hal_output_room();
    while (room > 0) {
        size_t n = amp_synthesize(amp, samples, room < CHUNK ? room : CHUNK);
        if (n == 0)
            break;
        hal_output_write(samples, n);
        room -= n;
    }
}

static void move_adc(amp_t *amp) {
    int16_t voltage[CHUNK], current[CHUNK];
    size_t n;
    while ((n = hal_adc_read(voltage, current, CHUNK)) > 0)
        amp_measure(amp, voltage, current, n);
}

/* Bytes for the host: what hal_uart_write did not take stays in `pending` for the next pass. */
static void move_tx(amp_t *amp, amp_pending_t *pending) {
    for (;;) {
        if (pending->count == 0)
            pending->count = amp_transmit(amp, pending->bytes, sizeof pending->bytes);
        if (pending->count == 0)
            return;
        size_t taken = hal_uart_write(pending->bytes, pending->count);
        memmove(pending->bytes, pending->bytes + taken, pending->count - taken);
        pending->count -= taken;
        if (pending->count > 0)
            return;
    }
}

void amp_run_once(amp_t *amp, amp_pending_t *pending) {
    uint8_t bytes[CHUNK];
    size_t n;
    for (unsigned reads = 0; reads < MAX_READS && (n = hal_uart_read(bytes, sizeof bytes)) > 0; reads++)
        amp_receive(amp, bytes, n, hal_time_us());
    uint8_t faults = hal_faults();
    if (faults)
        amp_fault(amp, faults, hal_time_us());
    amp_advance(amp, hal_time_us());
    if (amp->board->measures)
        move_adc(amp); /* an overcurrent it finds cuts the output below */
    if (amp_take_output_cut(amp))
        hal_output_off();
    if (amp->board->output_rate_hz != 0)
        move_output(amp);
    move_tx(amp, pending);
    hal_watchdog_kick();
    hal_wait(amp_next_due_us(amp));
}
