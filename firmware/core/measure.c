/* measure.c - voltage, current and phase from the ADC (synchronous demodulation; A6's overcurrent).
 *
 * Each ADC pair belongs to one output sample (hal_adc_read), whose phase the carrier recorded. Over
 * a window of whole carrier periods (from one phase wrap to the first wrap with at least 1 ms of
 * samples in) the voltage and the current are each fitted, by least squares, as a * sin + b * cos of
 * that phase: amplitude sqrt(a^2 + b^2), phase atan2(b, a). That is exact for a sinusoid at the
 * carrier whatever the sampling, so a window need not hold a whole number of samples per period. */
#include <math.h>

#include "amp_core.h"

#define PI 3.14159265358979323846
/* Longest window (in minimum windows): a carrier too slow to wrap in it (or none) ends it anyway. */
#define MAX_WINDOWS 64u

void amp_measure_reset(amp_t *amp) {
    amp->sum_vs = amp->sum_vc = amp->sum_is = amp->sum_ic = 0;
    amp->sum_ss = amp->sum_sc = amp->sum_cc = 0;
    amp->window_samples = 0;
    amp->window_open = 0;
    uint32_t rate_hz = amp->board->output_rate_hz;
    amp->window_min_samples = rate_hz / 1000u > 0 ? rate_hz / 1000u : 1u;
    amp->window_max_samples = amp->window_min_samples * MAX_WINDOWS;
}

/* A sinusoid's peak (in the samples' units) and phase (rad) from its sums against sin and cos. */
static double fit(double det, double ss, double sc, double cc, int64_t xs, int64_t xc, double *phase) {
    double a = ((double)xs * cc - (double)xc * sc) / det, b = ((double)xc * ss - (double)xs * sc) / det;
    *phase = atan2(b, a);
    return sqrt(a * a + b * b) * 32767.0;
}

/* A peak (LSB) as rms in the unit 1000 times that of `per_lsb`, rounded, saturating at 2**32 - 1 (a
 * huge per-LSB constant, or a fit of few samples; NaN too). */
static uint32_t rms_u32(double peak_lsb, uint32_t per_lsb) {
    double rms = peak_lsb / sqrt(2.0) * per_lsb / 1000.0 + 0.5;
    return rms < 4294967295.0 ? (uint32_t)rms : UINT32_MAX;
}

static void end_window(amp_t *amp) {
    const hal_board_t *board = amp->board;
    double ss = (double)amp->sum_ss, sc = (double)amp->sum_sc, cc = (double)amp->sum_cc;
    double det = ss * cc - sc * sc;
    if (det > 0.0) {
        double v_phase, i_phase;
        double v_peak = fit(det, ss, sc, cc, amp->sum_vs, amp->sum_vc, &v_phase);
        double i_peak = fit(det, ss, sc, cc, amp->sum_is, amp->sum_ic, &i_phase);
        double cdeg = (i_phase - v_phase) * 18000.0 / PI; /* current against voltage */
        if (cdeg > 18000.0)
            cdeg -= 36000.0;
        if (cdeg < -18000.0)
            cdeg += 36000.0;
        amp->voltage_mv_rms = rms_u32(v_peak, board->voltage_uv_per_lsb);
        amp->current_ua_rms = rms_u32(i_peak, board->current_na_per_lsb);
        amp->phase_cdeg = (int16_t)(v_peak > 0.0 && i_peak > 0.0 ? floor(cdeg + 0.5) : 0.0);
    } else { /* no carrier in the window: nothing to fit */
        amp->voltage_mv_rms = amp->current_ua_rms = 0;
        amp->phase_cdeg = 0;
    }
    amp->sum_vs = amp->sum_vc = amp->sum_is = amp->sum_ic = 0;
    amp->sum_ss = amp->sum_sc = amp->sum_cc = 0;
    amp->window_samples = 0;
    if ((board->measures & AMP_FAULT_OVERCURRENT) && board->max_current_ma != 0
        && amp->current_ua_rms > (uint64_t)board->max_current_ma * 1000u)
        amp_fault(amp, AMP_FAULT_OVERCURRENT, amp->now_us); /* A6 */
}

void amp_measure(amp_t *amp, const int16_t *voltage, const int16_t *current, size_t n) {
    if (amp->board->measures == 0)
        return;
    for (size_t k = 0; k < n; k++) {
        if (amp->measured == amp->written)
            return; /* pairs for samples never made: the board's error, ignored */
        if (amp->written - amp->measured > AMP_MEASURE_RING) { /* their phases are gone */
            amp->measured = amp->written - AMP_MEASURE_RING;
            amp_measure_reset(amp);
        }
        uint32_t phase = amp->measure_phase[amp->measured & (AMP_MEASURE_RING - 1u)];
        amp->measured++;
        int wrapped = phase < amp->last_measure_phase;
        amp->last_measure_phase = phase;
        if (wrapped && amp->window_open && amp->window_samples >= amp->window_min_samples)
            end_window(amp);
        if (wrapped)
            amp->window_open = 1;
        if (!amp->window_open)
            continue;
        int64_t s = amp_sine_q15(phase), c = amp_sine_q15(phase + 0x40000000u);
        amp->sum_vs += voltage[k] * s;
        amp->sum_vc += voltage[k] * c;
        amp->sum_is += current[k] * s;
        amp->sum_ic += current[k] * c;
        amp->sum_ss += s * s;
        amp->sum_sc += s * c;
        amp->sum_cc += c * c;
        if (++amp->window_samples >= amp->window_max_samples)
            end_window(amp);
    }
}
