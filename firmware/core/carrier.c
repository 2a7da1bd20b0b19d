/* carrier.c - the carrier: a phase accumulator, the sine, the output samples (A2: phase continuous).
 *
 * The phase is cycles * 2**32 (uint32, wrapping once a cycle). Per output sample it advances by
 * carrier_mhz / (output_rate_hz * 1000) cycles, which is kept exactly: with m = carrier_mhz / step and
 * den = output_rate_hz * 1000 / step, the increment is (m * 2**32) / den = inc_q + inc_r / den, and
 * the remainder accumulates in phase_rem (over den): the phase never drifts from the ideal one, so
 * every carrier that is a multiple of the step is made exactly. The step (INFO's carrier_step_mhz)
 * is 10 mHz: den fits 32 bits for every output rate amp_init takes (at most 4 MHz).
 * The phase starts at 0 at power-up and advances only while samples are made (the emulator's Plate). */
#include "amp_core.h"

/* 32767 * sin(2 pi phase / 2**32): the table's two neighbours, interpolated linearly on the next 16
 * bits (within 1.05: the table's rounding, the interpolation's; >> of a negative number is gcc's
 * arithmetic shift). */
int32_t amp_sine_q15(uint32_t phase) {
    uint32_t i = phase >> (32 - AMP_SINE_BITS);
    int32_t frac = (int32_t)((phase >> (16 - AMP_SINE_BITS)) & 0xFFFFu);
    int32_t low = amp_sine_table[i], high = amp_sine_table[i + 1u];
    return low + (((high - low) * frac + 32768) >> 16);
}

static void set_increment(amp_t *amp, uint32_t carrier_mhz) {
    uint64_t m = (uint64_t)(carrier_mhz / amp->carrier_step_mhz) << 32;
    amp->inc_carrier_mhz = carrier_mhz;
    amp->inc_q = (uint32_t)(m / amp->phase_den);
    amp->inc_r = (uint32_t)(m % amp->phase_den);
}

/* The phase of the next output sample, then one step on. */
static uint32_t next_phase(amp_t *amp) {
    uint32_t phase = amp->phase;
    amp->phase += amp->inc_q;
    if (amp->phase_rem >= amp->phase_den - amp->inc_r) {
        amp->phase_rem -= amp->phase_den - amp->inc_r;
        amp->phase++;
    } else {
        amp->phase_rem += amp->inc_r;
    }
    return phase;
}

void amp_carrier_init(amp_t *amp) {
    const hal_board_t *board = amp->board;
    if (board->output_rate_hz == 0)
        return;
    amp->phase_den = (uint32_t)((uint64_t)board->output_rate_hz * 1000u / amp->carrier_step_mhz);
    amp->lsb_per_uv_q32 = ((uint64_t)32767u << 32) / amp->full_scale_uv; /* rounded down: never above */
    set_increment(amp, 0);
}

/* peak_lsb * sine_q15 / 32767, rounded half away from zero (C99 division truncates toward zero): its
 * magnitude never exceeds |peak_lsb| (|sine_q15| <= 32767), and equals it at the sine's peak. */
static int16_t output_sample(int32_t peak_lsb, int32_t sine_q15) {
    int32_t product = peak_lsb * sine_q15;
    return (int16_t)((product + (product < 0 ? -16383 : 16383)) / 32767);
}

/* Drop the oldest played sample: its phase runs on (the board took too few samples). */
static void drop_oldest(amp_t *amp) {
    amp_played_t *played = &amp->played[amp->played_tail & (AMP_SYNTH_QUEUE - 1u)];
    if (played->carrier_mhz != amp->inc_carrier_mhz)
        set_increment(amp, played->carrier_mhz);
    for (; amp->played_done < played->outputs; amp->played_done++)
        next_phase(amp);
    amp->played_done = 0;
    amp->played_tail++;
}

/* A fault (A6): what is queued, and what plays in FAULT, is made at 0; the board cuts its own queue. */
void amp_carrier_cut(amp_t *amp) {
    for (uint32_t k = amp->played_tail; k != amp->played_head; k++)
        amp->played[k & (AMP_SYNTH_QUEUE - 1u)].peak_lsb = 0;
    amp->output_cut = 1;
}

/* A sample was played (play.c): queue it for synthesis (at 0 in FAULT). */
void amp_carrier_played(amp_t *amp, int32_t envelope_uv, uint32_t carrier_mhz) {
    if (amp->board->output_rate_hz == 0)
        return;
    if (amp->state == AMP_FAULT)
        envelope_uv = 0;
    if (amp->played_head - amp->played_tail == AMP_SYNTH_QUEUE)
        drop_oldest(amp);
    amp_played_t *played = &amp->played[amp->played_head & (AMP_SYNTH_QUEUE - 1u)];
    uint32_t magnitude_uv = (uint32_t)(envelope_uv < 0 ? -envelope_uv : envelope_uv);
    /* round(|envelope| / full scale * 32767): 32767 at full scale, at most round(max / full * 32767) */
    int32_t peak_lsb = (int32_t)((magnitude_uv * amp->lsb_per_uv_q32 + 0x80000000u) >> 32);
    played->peak_lsb = envelope_uv < 0 ? -peak_lsb : peak_lsb;
    played->carrier_mhz = carrier_mhz;
    played->outputs = amp->board->output_rate_hz / amp->rate_hz;
    amp->played_head++;
}

size_t amp_synthesize(amp_t *amp, int16_t *out, size_t cap) {
    size_t n = 0;
    while (n < cap && amp->played_tail != amp->played_head) {
        const amp_played_t *played = &amp->played[amp->played_tail & (AMP_SYNTH_QUEUE - 1u)];
        if (played->carrier_mhz != amp->inc_carrier_mhz)
            set_increment(amp, played->carrier_mhz);
        for (; amp->played_done < played->outputs && n < cap; amp->played_done++) {
            uint32_t phase = next_phase(amp);
            if (amp->board->measures) {
                amp->measure_phase[amp->written & (AMP_MEASURE_RING - 1u)] = phase;
                amp->written++;
            }
            out[n++] = output_sample(played->peak_lsb, amp_sine_q15(phase));
        }
        if (amp->played_done == played->outputs) {
            amp->played_done = 0;
            amp->played_tail++;
        }
    }
    return n;
}
