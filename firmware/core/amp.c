/* amp.c - the core's life: power-up (A7), faults (A6), the board going away, what it reports. */
#include <string.h>

#include "amp_core.h"

#define MAX_FULL_SCALE_MV 1000000u /* 1000 V: keeps every microvolt sum within int32 (limit.c) */

/* INFO's carrier step (mHz): 10, or the smallest multiple of 10 that divides output_rate_hz * 1000
 * into a phase denominator that fits 32 bits (carrier.c). */
static uint32_t carrier_step_mhz(uint32_t output_rate_hz) {
    uint64_t rate_mhz = (uint64_t)output_rate_hz * 1000u;
    uint32_t step = AMP_CARRIER_STEP_MHZ;
    while (rate_mhz % step != 0 || rate_mhz / step > UINT32_MAX)
        step += AMP_CARRIER_STEP_MHZ;
    return step;
}

void amp_init(amp_t *amp, const hal_board_t *board, const char *serial, uint64_t now_us) {
    memset(amp, 0, sizeof *amp); /* A7: output 0, IDLE, no carrier, no STATUS before HELLO */
    amp->board = board;
    for (size_t i = 0; i < 15 && serial[i] != 0; i++)
        amp->serial[i] = serial[i];
    amp->origin_us = amp->now_us = now_us;
    uint32_t full_scale_mv = board->full_scale_mv < MAX_FULL_SCALE_MV ? board->full_scale_mv : MAX_FULL_SCALE_MV;
    amp->full_scale_uv = (full_scale_mv > 0 ? full_scale_mv : 1u) * 1000u;
    amp->max_mv = board->max_mv < amp->full_scale_uv / 1000u ? board->max_mv : amp->full_scale_uv / 1000u;
    amp->max_uv = amp->max_mv * 1000u;
    amp->slew_mv_per_ms = amp->max_mv > AMP_MIN_SLEW_MV_PER_MS ? amp->max_mv : AMP_MIN_SLEW_MV_PER_MS;
    /* the carriers made: multiples of the step within the board's range, below half the output rate */
    uint32_t step = carrier_step_mhz(board->output_rate_hz);
    uint64_t high_mhz = board->carrier_max_mhz;
    if (board->output_rate_hz != 0 && high_mhz >= (uint64_t)board->output_rate_hz * 500u)
        high_mhz = (uint64_t)board->output_rate_hz * 500u - 1u;
    amp->carrier_step_mhz = step;
    amp->carrier_min_mhz = (uint32_t)(((uint64_t)board->carrier_min_mhz + step - 1u) / step * step);
    amp->carrier_max_mhz = (uint32_t)(high_mhz / step * step);
    amp_carrier_init(amp);
    amp_measure_reset(amp);
}

static void raise_fault(amp_t *amp, uint8_t bits) {
    /* A6: ramp to 0 within 1 ms, set the bits, STATUS at once (for a new one), FAULT until HELLO. */
    uint8_t new_bits = (uint8_t)(bits & ~amp->faults);
    amp->faults |= bits;
    if (amp->state != AMP_FAULT) {
        amp_buffer_clear(amp);
        amp_ramp_begin(amp, AMP_FAULT_RAMP_MS, AMP_FAULT, AMP_FAULT);
        amp_carrier_cut(amp);
    }
    if (new_bits)
        amp_send_status(amp, amp->now_us - amp->origin_us);
}

int amp_take_output_cut(amp_t *amp) {
    int cut = amp->output_cut;
    amp->output_cut = 0;
    return cut;
}

void amp_fault(amp_t *amp, uint8_t bits, uint64_t now_us) {
    bits &= AMP_FAULT_OVERCURRENT | AMP_FAULT_OVERVOLTAGE | AMP_FAULT_OVERTEMPERATURE | AMP_FAULT_SUPPLY;
    if (bits == 0)
        return;
    amp_advance(amp, now_us);
    raise_fault(amp, bits);
}

void amp_stop_output(amp_t *amp, uint64_t now_us) {
    amp_advance(amp, now_us);
    if (amp->state == AMP_PRIMING || amp->state == AMP_RUNNING) {
        amp_buffer_clear(amp);
        amp_ramp_begin(amp, AMP_RAMP_MS, AMP_RAMPING, AMP_IDLE);
    }
}

void amp_counters(const amp_t *amp, amp_counters_t *out) {
    *out = amp->counters;
    out->faults = amp->faults;
    out->state = amp->state;
    out->envelope_uv = amp->output_uv;
    out->carrier_mhz = amp_carrier_made_mhz(amp);
    out->play_index = amp->play_index;
}

void amp_set_observer(amp_t *amp, amp_observer_t fn, void *ctx) {
    amp->observer = fn;
    amp->observer_ctx = ctx;
}

void amp_set_hello_hook(amp_t *amp, void (*fn)(void *ctx), void *ctx) {
    amp->hello_hook = fn;
    amp->hello_hook_ctx = ctx;
}

uint64_t amp_last_valid_us(const amp_t *amp) {
    return amp->has_last_seq ? amp->last_valid_us : UINT64_MAX;
}

size_t amp_sizeof(void) {
    return sizeof(amp_t);
}
