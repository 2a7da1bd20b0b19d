/* limit.c - the applied envelope in integer microvolts: a sample's value (3.1 ENVELOPE), the clamp
 * (A1), the slew limit (A2) and the linear ramps (HELLO, STOP, A4, A6), with no per-sample 64-bit
 * arithmetic and no divide (a Cortex-M0 plays these at 16 kHz). */
#include "amp_core.h"

/* s / 32767 * full_scale, toward zero: full_scale_uv = uv_q * 32767 + uv_r, so s * uv_q is exact and
 * s * uv_r < 2**30 (amp_init refuses full scale above 1000 V: s * uv_q < 2**31). -32768 reads as -32767. */
int32_t amp_sample_uv(const amp_t *amp, int16_t sample) {
    int32_t s = sample < -32767 ? -32767 : sample;
    int32_t q = (int32_t)(amp->full_scale_uv / 32767u), r = (int32_t)(amp->full_scale_uv % 32767u);
    return s * q + s * r / 32767;
}

/* A1 then A2: clamp to +-max_uv, then move from the present output by at most one slew step. */
int32_t amp_limit_uv(const amp_t *amp, int32_t target_uv) {
    int32_t max_uv = (int32_t)amp->max_uv;
    if (target_uv > max_uv)
        target_uv = max_uv;
    if (target_uv < -max_uv)
        target_uv = -max_uv;
    int32_t change = target_uv - amp->output_uv; /* both within +-1e9: no overflow */
    if (change > amp->slew_step_uv)
        return amp->output_uv + amp->slew_step_uv;
    if (change < -amp->slew_step_uv)
        return amp->output_uv - amp->slew_step_uv;
    return target_uv;
}

/* A ramp from the present output to 0 over max(1, ramp_ms * rate / 1000) samples in state `during`,
 * then `then` (the emulator's Ramp); at rest (the clock stopped) straight to `then`. */
void amp_ramp_begin(amp_t *amp, uint32_t ramp_ms, uint8_t during, uint8_t then) {
    if (amp->rate_hz == 0) {
        amp->state = then;
        return;
    }
    uint32_t samples = ramp_ms * amp->rate_hz / 1000u;
    uint32_t start = (uint32_t)(amp->output_uv < 0 ? -amp->output_uv : amp->output_uv);
    amp->ramp_samples = samples > 0 ? samples : 1u;
    amp->ramp_start_uv = amp->output_uv;
    amp->ramp_done = 0;
    amp->ramp_q = start / amp->ramp_samples;
    amp->ramp_r = start % amp->ramp_samples;
    amp->ramp_acc_q = amp->ramp_acc_r = 0;
    amp->ramp_then = then;
    amp->ramping = 1;
    amp->state = during;
}

/* The next ramp value: start * (1 - done / samples), done counted from 1; |start| * done / samples
 * is kept as a whole part and a remainder over `samples`, stepped by |start| / samples each sample. */
int32_t amp_ramp_next_uv(amp_t *amp) {
    amp->ramp_done++;
    amp->ramp_acc_q += amp->ramp_q;
    amp->ramp_acc_r += amp->ramp_r;
    if (amp->ramp_acc_r >= amp->ramp_samples) {
        amp->ramp_acc_r -= amp->ramp_samples;
        amp->ramp_acc_q++;
    }
    int32_t left = (int32_t)((uint32_t)(amp->ramp_start_uv < 0 ? -amp->ramp_start_uv : amp->ramp_start_uv)
                             - amp->ramp_acc_q);
    return amp->ramp_start_uv < 0 ? -left : left;
}
