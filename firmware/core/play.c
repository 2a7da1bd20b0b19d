/* play.c - time: the envelope sample clock and what it plays (A1-A4), and the STATUS schedule (A8).
 *
 * Sample n of the clock is due at anchor + n / rate_hz us, kept exactly as due_us + due_rem / rate_hz
 * (1e6 / rate_hz = period_us + period_rem / rate_hz): no drift, no divide per sample. Samples and
 * STATUS due up to a given time are made in time order, a sample first on a tie (the emulator's). */
#include "amp_core.h"

#define TRIP_US ((AMP_WATCHDOG_MS - AMP_RAMP_MS) * 1000u - AMP_READ_ALLOWANCE_US)
/* The emulator's MAX_BATCH: within one advance it stops a clock at rest at every 4096th sample, and at
 * the end (its flush); the same here bounds the samples a jump of hours plays. */
#define FLUSH_SAMPLES 4096u

/* Start the clock at now_us unless it already runs at rate_hz (START; the anchor stays). */
void amp_clock_start(amp_t *amp, uint64_t now_us, uint32_t rate_hz) {
    if (amp->rate_hz == rate_hz)
        return;
    amp->rate_hz = rate_hz;
    amp->due_us = now_us;
    amp->due_rem = 0;
    amp->period_us = 1000000u / rate_hz;
    amp->period_rem = 1000000u % rate_hz;
    /* A2 per sample: slew_mv_per_ms * 1000 / rate mV, in uV, rounded down (never above the limit). */
    uint64_t step_uv = (uint64_t)amp->slew_mv_per_ms * 1000000u / rate_hz;
    amp->slew_step_uv = step_uv > 0x7FFFFFFFu ? 0x7FFFFFFF : (int32_t)step_uv;
}

uint32_t amp_carrier_made_mhz(const amp_t *amp) {
    if (amp->carrier_mhz)
        return amp->carrier_mhz;
    return amp->ramping ? amp->fading_carrier_mhz : 0; /* HELLO's ramp still makes the old carrier */
}

static int at_rest(const amp_t *amp) {
    return !amp->ramping && amp->output_uv == 0 && (amp->state == AMP_IDLE || amp->state == AMP_FAULT);
}

/* Tell the observer of a sample (or a trip) due now. */
static void notify(amp_t *amp, uint8_t kind, uint32_t carrier_mhz, int64_t index) {
    if (amp->observer == NULL)
        return;
    amp_event_t event = { kind, amp->state, amp->due_us, amp->due_rem, amp->rate_hz, amp->output_uv,
                          carrier_mhz, index };
    amp->observer(amp->observer_ctx, &event);
}

/* Make the sample due now (the emulator's Amplifier._play). */
static void play(amp_t *amp) {
    if ((amp->state == AMP_PRIMING || amp->state == AMP_RUNNING) && amp->due_us >= amp->last_valid_us + TRIP_US) {
        /* A4: no valid frame for watchdog_ms - R: count a trip, ramp to 0 over R, empty the buffer, IDLE. */
        amp->counters.watchdog_trips++;
        notify(amp, AMP_EVENT_WATCHDOG_TRIP, amp_carrier_made_mhz(amp), -1);
        amp_buffer_clear(amp);
        amp_ramp_begin(amp, AMP_RAMP_MS, AMP_RAMPING, AMP_IDLE);
    }
    int64_t index = -1;
    int32_t target_uv;
    if (amp->state == AMP_RUNNING) {
        int16_t sample;
        if (amp_buffer_take(amp, amp->play_index, &sample)) {
            index = amp->play_index;
            target_uv = amp_sample_uv(amp, sample);
        } else {
            amp->counters.underruns++; /* A3: a missing index plays as 0 (through A2), one underrun */
            target_uv = 0;
        }
        amp->play_index++;
    } else if (amp->ramping) {
        target_uv = amp_ramp_next_uv(amp);
    } else {
        target_uv = amp->state == AMP_PRIMING ? amp->output_uv : 0; /* held while PRIMING; 0 at rest */
    }
    uint32_t carrier_mhz = amp_carrier_made_mhz(amp);
    if (amp->ramping && amp->ramp_done >= amp->ramp_samples) {
        amp->state = amp->ramp_then;
        amp->ramping = 0;
    }
    amp->output_uv = amp_limit_uv(amp, target_uv);
    notify(amp, AMP_EVENT_SAMPLE, carrier_mhz, index);
    amp_carrier_played(amp, amp->output_uv, carrier_mhz);
    amp->due_us += amp->period_us;
    amp->due_rem += amp->period_rem;
    if (amp->due_rem >= amp->rate_hz) {
        amp->due_rem -= amp->rate_hz;
        amp->due_us++;
    }
}

/* The sample's due time (exactly due_us + due_rem / rate) is at or before the whole microsecond t_us. */
static int sample_due_by(const amp_t *amp, uint64_t t_us) {
    return amp->rate_hz != 0 && (amp->due_us < t_us || (amp->due_us == t_us && amp->due_rem == 0));
}

void amp_advance(amp_t *amp, uint64_t now_us) {
    if (now_us < amp->now_us)
        now_us = amp->now_us;
    uint32_t period_us = AMP_STATUS_PERIOD_MS * 1000u, played = 0;
    for (;;) {
        if (amp->has_hello) { /* a STATUS overdue by more than 100 ms (the board was stopped) is skipped */
            uint64_t elapsed_us = now_us - amp->origin_us;
            if (elapsed_us > AMP_MAX_STATUS_LAG_US + amp->next_status_us) {
                uint64_t lag_us = elapsed_us - AMP_MAX_STATUS_LAG_US - amp->next_status_us;
                amp->next_status_us += (lag_us + period_us - 1u) / period_us * period_us;
            }
        }
        uint64_t status_at_us = amp->has_hello ? amp->origin_us + amp->next_status_us : UINT64_MAX;
        int sample_first = sample_due_by(amp, status_at_us < now_us ? status_at_us : now_us);
        if (sample_first) {
            play(amp);
            if (++played == FLUSH_SAMPLES) {
                played = 0;
                if (at_rest(amp))
                    amp->rate_hz = 0;
            }
        } else if (status_at_us <= now_us) {
            amp_send_status(amp, amp->next_status_us);
            amp->next_status_us += period_us;
        } else {
            break;
        }
    }
    if (amp->rate_hz != 0 && at_rest(amp))
        amp->rate_hz = 0; /* the clock stops at rest (the next START anchors a new one) */
    amp->now_us = now_us;
}

uint64_t amp_next_due_us(const amp_t *amp) {
    uint64_t due = UINT64_MAX;
    if (amp->rate_hz != 0)
        due = amp->due_us + (amp->due_rem != 0);
    if (amp->has_hello && amp->origin_us + amp->next_status_us < due)
        due = amp->origin_us + amp->next_status_us;
    return due;
}
