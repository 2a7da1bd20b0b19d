/* amp.c - the core's life: power-up (A7), faults (A6), the board going away, what it reports. */
#include <stddef.h>
#include <string.h>

#include "amp_core.h"

/* The board's carriers (multiples of the step within its range, below half the output rate), or
 * AMP_BOARD_CARRIERS when none is left. */
static int set_carriers(amp_t *amp, const hal_board_t *board) {
    uint64_t step = AMP_CARRIER_STEP_MHZ, high_mhz = board->carrier_max_mhz;
    if (board->output_rate_hz != 0 && high_mhz >= (uint64_t)board->output_rate_hz * 500u)
        high_mhz = (uint64_t)board->output_rate_hz * 500u - 1u;
    uint64_t low_mhz = ((uint64_t)board->carrier_min_mhz + step - 1u) / step * step;
    high_mhz = high_mhz / step * step;
    if (low_mhz > high_mhz)
        return AMP_BOARD_CARRIERS;
    amp->carrier_step_mhz = (uint32_t)step;
    amp->carrier_min_mhz = (uint32_t)low_mhz;
    amp->carrier_max_mhz = (uint32_t)high_mhz;
    return AMP_BOARD_OK;
}

/* Which of the board's constants is out of hal.h's ranges (the first), or AMP_BOARD_OK. */
static int board_problem(const hal_board_t *board) {
    uint32_t rate_hz = board->output_rate_hz;
    if (rate_hz % 16000u != 0 || rate_hz > AMP_MAX_OUTPUT_RATE_HZ)
        return AMP_BOARD_OUTPUT_RATE;
    if (board->full_scale_mv < 1u || board->full_scale_mv > AMP_MAX_FULL_SCALE_MV)
        return AMP_BOARD_FULL_SCALE;
    if (board->max_mv < 1u || board->max_mv > board->full_scale_mv)
        return AMP_BOARD_MAX_MV;
    if (board->measures > 7u || ((board->measures & 1u) && board->current_na_per_lsb == 0)
        || ((board->measures & 2u) && board->voltage_uv_per_lsb == 0))
        return AMP_BOARD_MEASURES;
    return AMP_BOARD_OK;
}

/* What a refused board is made: no carrier, no ADC, a clamp of 0 V (every applied envelope 0). */
static const hal_board_t refused_board = { "refused", 0u, 1u, 0u, 0u, 0u, 0u, 0u, 0u, 0u };

int amp_init(amp_t *amp, const hal_board_t *board, const char *serial, uint64_t now_us) {
    memset(amp, 0, sizeof *amp); /* A7: output 0, IDLE, no carrier, no STATUS before HELLO */
    int problem = board_problem(board);
    amp->board_used = *board;
    if (problem == AMP_BOARD_OK)
        problem = set_carriers(amp, board);
    if (problem != AMP_BOARD_OK) {
        amp->board_used = refused_board;
        (void)set_carriers(amp, &refused_board); /* 0 .. 0: never refused */
    }
    board = amp->board = &amp->board_used;
    for (size_t i = 0; i < 15 && serial[i] != 0; i++)
        amp->serial[i] = serial[i];
    amp->origin_us = amp->now_us = now_us;
    amp->full_scale_uv = board->full_scale_mv * 1000u;
    amp->max_mv = board->max_mv;
    amp->max_uv = amp->max_mv * 1000u;
    amp->slew_mv_per_ms = amp->max_mv > AMP_MIN_SLEW_MV_PER_MS ? amp->max_mv : AMP_MIN_SLEW_MV_PER_MS;
    amp_carrier_init(amp);
    amp_measure_reset(amp);
    return problem;
}

const char *amp_board_problem(int problem) {
    switch (problem) {
    case AMP_BOARD_OK: return "within range";
    case AMP_BOARD_OUTPUT_RATE: return "output_rate_hz must be 0 or a multiple of 16000 up to 4000000";
    case AMP_BOARD_FULL_SCALE: return "full_scale_mv must be 1 .. 1000000 (1000 V)";
    case AMP_BOARD_MAX_MV: return "max_mv must be 1 .. full_scale_mv";
    case AMP_BOARD_CARRIERS: return "no carrier between carrier_min_mhz and carrier_max_mhz below half the output rate";
    default: return "measures must be 0 .. 7, with voltage_uv_per_lsb and current_na_per_lsb for what it measures";
    }
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

/* A field's offset and size (bytes). */
#define BOARD_FIELD(f) { offsetof(hal_board_t, f), sizeof(((hal_board_t *)0)->f) }

size_t amp_board_layout(size_t *offsets, size_t *sizes, size_t cap) {
    static const size_t fields[][2] = {
        BOARD_FIELD(name), BOARD_FIELD(output_rate_hz), BOARD_FIELD(full_scale_mv), BOARD_FIELD(max_mv),
        BOARD_FIELD(carrier_min_mhz), BOARD_FIELD(carrier_max_mhz), BOARD_FIELD(max_current_ma),
        BOARD_FIELD(measures), BOARD_FIELD(voltage_uv_per_lsb), BOARD_FIELD(current_na_per_lsb),
    };
    for (size_t i = 0; i < cap && i < sizeof fields / sizeof *fields; i++) {
        offsets[i] = fields[i][0];
        sizes[i] = fields[i][1];
    }
    return sizeof(hal_board_t);
}
