/* core_carrier.c - the carrier against a double-precision reference (phase continuous across carrier
 * changes, A2), and the demodulation against a synthesised known amplitude and phase. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "core_check.h"

#define PI 3.14159265358979323846
#define PER_SAMPLE 12 /* 192 kHz / 16 kHz */

static session_t s;
static recorder_t r;
static int16_t out[200000];

static void test_sine(void) {
    double worst = 0.0;
    for (uint32_t i = 0; i <= AMP_SINE_POINTS; i++)
        CHECK(fabs(amp_sine_table[i] - 32767.0 * sin(2 * PI * i / AMP_SINE_POINTS)) <= 0.5);
    for (uint64_t phase = 0; phase < (1ull << 32); phase += 99991) {
        double error = fabs(amp_sine_q15((uint32_t)phase) - 32767.0 * sin(2 * PI * phase / 4294967296.0));
        worst = error > worst ? error : worst;
    }
    CHECK(worst <= 1.05);
    printf("  sine: table and interpolation within %.3f of 32767\n", worst);
}

/* The output of events[first ..] against env / full scale * sin(2 pi phase) * 32767, the reference's
 * phase starting at `phase0` (cycles) and advancing by carrier / 192 kHz per output sample. */
static double worst_error(size_t first, size_t n_out, double phase0) {
    double phase = phase0, worst = 0.0;
    for (size_t k = 0; k < n_out; k++) {
        const amp_event_t *e = &r.events[first + k / PER_SAMPLE];
        double want = e->envelope_uv / 125e6 * sin(2 * PI * phase) * 32767.0;
        double error = fabs(out[k] - want);
        worst = error > worst ? error : worst;
        phase += e->carrier_mhz / 192e6;
        phase -= floor(phase);
    }
    return worst;
}

static void test_synthesis(void) {
    static int16_t ramp[1024];
    session_init(&s, &test_board, 0);
    r.count = 0;
    amp_set_observer(&s.amp, record_event, &r);
    session_running(&s, 1000, 0, 0);
    for (int i = 0; i < 1024; i++)
        ramp[i] = (int16_t)(i % 512 < 256 ? i % 512 * 100 : -(i % 512 - 256) * 100);
    host_envelope(&s, 16, ramp + 16, 256, 1000);
    host_envelope(&s, 272, ramp + 272, 256, 1000);
    size_t n = 0, chunk = 1;
    for (uint64_t t = 1000; t <= 40000; t += 1000) {
        amp_advance(&s.amp, t);
        if (t == 10000) {
            host_set_carrier(&s, 47123450u, t); /* while RUNNING: the phase runs on */
            host_envelope(&s, 528, ramp + 528, 256, t);
        }
        for (;;) { /* taken in pieces of every size */
            size_t got = amp_synthesize(&s.amp, out + n, chunk);
            if (got == 0)
                break;
            n += got;
            chunk = chunk % 37 + 1;
        }
    }
    CHECK_EQ(n, r.count * PER_SAMPLE);
    double worst = worst_error(0, n, 0.0);
    CHECK(worst <= 1.5);
    printf("  synthesis: %zu samples within %.3f of the double-precision reference\n", n, worst);
    CHECK_EQ(amp_synthesize(&s.amp, out, 10), 0);
    /* a board that takes too few: the oldest go, the phase runs on */
    double phase = 0.0;
    for (size_t k = 0; k < n; k++)
        phase += r.events[k / PER_SAMPLE].carrier_mhz / 192e6;
    size_t first = r.count;
    host_envelope(&s, 784, ramp + 784, 240, 40000);
    amp_advance(&s.amp, 40000 + 200 * 125 / 2);
    CHECK_EQ(r.count - first, 200);
    n = amp_synthesize(&s.amp, out, sizeof out / sizeof *out);
    CHECK_EQ(n, AMP_SYNTH_QUEUE * PER_SAMPLE);
    size_t lost = 200 - AMP_SYNTH_QUEUE;
    for (size_t k = 0; k < lost * PER_SAMPLE; k++)
        phase += r.events[first + k / PER_SAMPLE].carrier_mhz / 192e6;
    CHECK(worst_error(first + lost, n, phase - floor(phase)) <= 1.5);
    /* a protocol-only board makes none */
    session_init(&s, &test_board_protocol, 0);
    session_running(&s, 0, 0, 1000);
    amp_advance(&s.amp, 5000);
    CHECK_EQ(amp_synthesize(&s.amp, out, 100), 0);
    amp_measure(&s.amp, out, out, 100);
    CHECK_EQ(s.amp.measured, 0);
}

/* ADC pairs for the samples synthesised: sinusoids of a known amplitude (LSB) and phase (rad) at each
 * output sample's own phase, as a board's ADC would take them. */
static void measure_known(double v_peak, double v_phase, double i_peak, double i_phase, size_t n) {
    static int16_t voltage[4096], current[4096];
    while (n > 0) {
        size_t chunk = n < 4096 ? n : 4096;
        for (size_t k = 0; k < chunk; k++) {
            uint32_t phase = s.amp.measure_phase[(s.amp.measured + k) & (AMP_MEASURE_RING - 1u)];
            double theta = 2 * PI * phase / 4294967296.0;
            voltage[k] = (int16_t)lround(v_peak * sin(theta + v_phase));
            current[k] = (int16_t)lround(i_peak * sin(theta + i_phase));
        }
        amp_measure(&s.amp, voltage, current, chunk);
        n -= chunk;
    }
}

static void test_demodulation(void) {
    session_init(&s, &test_board, 0);
    session_running(&s, 0, 0, 0);
    int16_t ramp[256];
    memset(ramp, 0, sizeof ramp);
    for (uint32_t i = 16; i < 1024; i += 256)
        host_envelope(&s, i, ramp, 256, 0);
    size_t total = 0;
    for (uint64_t t = 0; t < 20000; t += 1000) { /* 1 ms at a time: synthesise, then measure */
        amp_advance(&s.amp, t);
        size_t n = amp_synthesize(&s.amp, out, sizeof out / sizeof *out);
        measure_known(20000.0, 0.3, 8000.0, 0.3 - 0.5, n);
        total += n;
    }
    CHECK(total > 3000);
    double v_mv = 20000.0 / sqrt(2.0) * 5000 / 1000, i_ua = 8000.0 / sqrt(2.0) * 1000 / 1000;
    CHECK(fabs(s.amp.voltage_mv_rms - v_mv) <= v_mv * 1e-4 + 1);
    CHECK(fabs(s.amp.current_ua_rms - i_ua) <= i_ua * 1e-4 + 1);
    CHECK(abs(s.amp.phase_cdeg - (int)lround(-0.5 * 18000 / PI)) <= 2);
    printf("  demodulation: %u mV rms (want %.1f), %u uA rms (want %.1f), %d cdeg (want %.1f)\n",
           s.amp.voltage_mv_rms, v_mv, s.amp.current_ua_rms, i_ua, s.amp.phase_cdeg, -0.5 * 18000 / PI);
    amp_send_status(&s.amp, 0);
    take_sent(&s);
    CHECK_EQ(get_u32(s.sent[0].payload + 44), s.amp.voltage_mv_rms);
    CHECK_EQ(get_u32(s.sent[0].payload + 48), s.amp.current_ua_rms);
    CHECK_EQ((int16_t)get_u16(s.sent[0].payload + 38), s.amp.phase_cdeg);
    /* current leading by almost half a turn: the phase wraps into +-18000 */
    amp_advance(&s.amp, 21000);
    measure_known(20000.0, -3.0, 8000.0, 3.0, amp_synthesize(&s.amp, out, sizeof out / sizeof *out));
    amp_advance(&s.amp, 22000);
    measure_known(20000.0, -3.0, 8000.0, 3.0, amp_synthesize(&s.amp, out, sizeof out / sizeof *out));
    CHECK(abs(s.amp.phase_cdeg - (int)lround((6.0 - 2 * PI) * 18000 / PI)) <= 2);
    /* a board that fell behind: the pairs whose phases are gone start a new window */
    amp_advance(&s.amp, 30000);
    size_t n = amp_synthesize(&s.amp, out, sizeof out / sizeof *out);
    CHECK(n > AMP_MEASURE_RING);
    static int16_t zeros[20000];
    amp_measure(&s.amp, zeros, zeros, 10); /* these belong to samples whose phases are gone */
    CHECK_EQ(s.amp.written - s.amp.measured, AMP_MEASURE_RING - 10);
    measure_known(0.0, 0.0, 0.0, 0.0, AMP_MEASURE_RING - 10);
    amp_measure(&s.amp, zeros, zeros, 5); /* more pairs than samples: ignored */
    CHECK_EQ(s.amp.measured, s.amp.written);
}

static void test_overcurrent(void) {
    static const hal_board_t weak = { "weak", 192000u, 125000u, 100000u, 10000000u, 80000000u, 10u, 7u, 5000u, 1000u };
    session_init(&s, &weak, 0);
    session_running(&s, 0, 0, 1000);
    int16_t level[256];
    for (int i = 0; i < 256; i++)
        level[i] = 1000;
    host_envelope(&s, 16, level, 256, 0);
    for (uint64_t t = 1000; t <= 3000; t += 1000) {
        amp_advance(&s.amp, t);
        measure_known(1000.0, 0.0, 14000.0, 0.0, amp_synthesize(&s.amp, out, sizeof out / sizeof *out));
    }
    CHECK(s.amp.current_ua_rms > 9800);
    CHECK_EQ(s.amp.state, AMP_RUNNING); /* 9.9 mA: under the 10 mA trip */
    for (uint64_t t = 4000; t <= 6000 && s.amp.state != AMP_FAULT; t += 1000) {
        amp_advance(&s.amp, t);
        measure_known(1000.0, 0.0, 14500.0, 0.0, amp_synthesize(&s.amp, out, sizeof out / sizeof *out));
    }
    CHECK_EQ(s.amp.state, AMP_FAULT); /* A6 from the measured current */
    CHECK_EQ(s.amp.faults, AMP_FAULT_OVERCURRENT);
    CHECK_EQ(amp_take_output_cut(&s.amp), 1); /* once */
    CHECK_EQ(amp_take_output_cut(&s.amp), 0);
    CHECK(s.amp.output_uv != 0); /* the applied envelope still ramps (A6), ... */
    amp_advance(&s.amp, s.amp.now_us + 2000);
    size_t made = amp_synthesize(&s.amp, out, sizeof out / sizeof *out);
    CHECK(made > 100);
    for (size_t k = 0; k < made; k++) /* ... the carrier is cut at once */
        CHECK_EQ(out[k], 0);
    take_sent(&s);
    size_t fault_status = 0;
    for (size_t i = 0; i < s.sent_count; i++)
        fault_status += s.sent[i].type == MSG_STATUS && s.sent[i].payload[11] == AMP_FAULT_OVERCURRENT
                        && s.sent[i].payload[10] == AMP_FAULT;
    CHECK(fault_status >= 1); /* at once, and periodic ones after it */
    /* no carrier in a window (none made): nothing to fit, reported as 0 */
    session_init(&s, &weak, 0);
    amp_clock_start(&s.amp, 0, 16000);
    for (int i = 0; i < 1200; i++) {
        amp_carrier_played(&s.amp, 0, 0);
        measure_known(1000.0, 0.0, 1000.0, 0.0, amp_synthesize(&s.amp, out, sizeof out / sizeof *out));
    }
    CHECK_EQ(s.amp.voltage_mv_rms, 0);
    CHECK_EQ(s.amp.phase_cdeg, 0);
}

/* The output's peak at the clamp: a 48 kHz carrier at 192 kHz puts a sample on the sine's peak
 * (phase 1/4); the envelope at max_mv makes exactly round(max / full * 32767) there and nowhere more
 * (49477 / 24738: the G4's full scale at half, where scaling by 32768 made one LSB more). */
static void test_peak_at_the_clamp(void) {
    static const uint32_t max_mvs[] = { 24738u, 40000u, 49477u, 1u };
    for (size_t b = 0; b < sizeof max_mvs / sizeof *max_mvs; b++) {
        hal_board_t board = test_board;
        board.full_scale_mv = 49477u;
        board.max_mv = max_mvs[b];
        session_init(&s, &board, 0);
        int16_t top[256];
        for (int i = 0; i < 256; i++)
            top[i] = 32767;
        host_hello(&s, 1, 0);
        host_set_carrier(&s, 48000000u, 0);
        host_start(&s, 16000u, 0, 256, 0);
        host_envelope(&s, 0, top, 256, 0);
        int peak = 0;
        for (uint64_t t = 1000; t <= 15000; t += 1000) {
            amp_advance(&s.amp, t);
            size_t n = amp_synthesize(&s.amp, out, sizeof out / sizeof *out);
            CHECK(n >= 16 * PER_SAMPLE);
            for (size_t k = 0; k < n; k++)
                peak = abs(out[k]) > peak ? abs(out[k]) : peak;
        }
        CHECK_EQ(peak, (int)lround(max_mvs[b] / 49477.0 * 32767));
    }
}

/* Huge per-LSB constants: STATUS's rms values saturate at 2**32 - 1 (a double past uint32 was cast
 * before: undefined), and the saturated current trips the overcurrent (A6). */
static void test_rms_saturates(void) {
    hal_board_t huge = test_board;
    huge.voltage_uv_per_lsb = huge.current_na_per_lsb = 0xFFFFFFFFu;
    session_init(&s, &huge, 0);
    session_running(&s, 0, 0, 1000);
    for (uint64_t t = 1000; t <= 3000 && s.amp.state != AMP_FAULT; t += 1000) {
        amp_advance(&s.amp, t);
        measure_known(30000.0, 0.0, 30000.0, 0.0, amp_synthesize(&s.amp, out, sizeof out / sizeof *out));
    }
    CHECK_EQ(s.amp.voltage_mv_rms, UINT32_MAX);
    CHECK_EQ(s.amp.current_ua_rms, UINT32_MAX);
    CHECK_EQ(s.amp.faults, AMP_FAULT_OVERCURRENT);
}

void test_carrier(void) {
    test_sine();
    test_peak_at_the_clamp();
    test_synthesis();
    test_demodulation();
    test_overcurrent();
    test_rms_saturates();
}
