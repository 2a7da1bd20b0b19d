/* protocol.c - acting on a valid frame (docs/amp-protocol.md 2.2-2.3, 3.1; the emulator's receive
 * and its handlers): watchdog, sequence gaps, version, type, length, then each message's rules. */
#include "amp_core.h"

/* Count a refused valid frame; ACK it, unless it is an ENVELOPE of this version (3.1). */
static void reject(amp_t *amp, const amp_frame_t *frame, uint8_t code, uint32_t value) {
    amp->counters.frames_rejected++;
    if (frame->version != AMP_VERSION || frame->type != MSG_ENVELOPE)
        amp_send_ack(amp, frame, code, value);
}

static void accept(amp_t *amp) {
    amp->counters.frames_ok++;
}

static void on_hello(amp_t *amp, const amp_frame_t *frame) {
    amp->fading_carrier_mhz = amp_carrier_made_mhz(amp);
    amp->carrier_mhz = 0;
    amp_buffer_clear(amp);
    amp_ramp_begin(amp, AMP_RAMP_MS, AMP_RAMPING, AMP_IDLE); /* A4's ramp, on the old carrier, then IDLE */
    amp->faults = 0;
    amp_counters_t zero = { 0 };
    zero.tx_dropped = amp->counters.tx_dropped;
    amp->counters = zero;
    amp->tx_seq = 0;
    amp_tx_discard(amp); /* stale: the new session starts with INFO */
    if (amp->hello_hook != NULL)
        amp->hello_hook(amp->hello_hook_ctx); /* and what the board's line still holds */
    amp_send_info(amp, get_u32(frame->payload + 12)); /* the nonce: the answer to this HELLO */
    accept(amp);
    amp->has_hello = 1;
    amp->next_status_us = amp->now_us - amp->origin_us + AMP_STATUS_PERIOD_MS * 1000u;
}

static void on_set_carrier(amp_t *amp, const amp_frame_t *frame) {
    uint32_t asked_mhz = get_u32(frame->payload), step = amp->carrier_step_mhz;
    if (asked_mhz < amp->carrier_min_mhz || asked_mhz > amp->carrier_max_mhz) {
        reject(amp, frame, AMP_OUT_OF_RANGE, 0);
        return;
    }
    /* the nearest carrier made (ties up); the limits are multiples of the step, so it stays in range */
    amp->carrier_mhz = (uint32_t)(((uint64_t)asked_mhz + step / 2u) / step * step);
    accept(amp);
    amp_send_ack(amp, frame, AMP_OK, amp->carrier_mhz);
}

static void on_start(amp_t *amp, const amp_frame_t *frame) {
    uint32_t envelope_hz = get_u32(frame->payload), start_index = get_u32(frame->payload + 4);
    uint16_t prefill = get_u16(frame->payload + 8);
    if (amp->state == AMP_FAULT) {
        reject(amp, frame, AMP_CODE_FAULT, 0); /* A6 */
    } else if (envelope_hz != 8000u && envelope_hz != 16000u) {
        reject(amp, frame, AMP_BAD_RATE, 0);
    } else if (amp->carrier_mhz == 0) {
        reject(amp, frame, AMP_NO_CARRIER, 0);
    } else if (prefill < 1u || prefill > AMP_BUFFER_SAMPLES) {
        reject(amp, frame, AMP_OUT_OF_RANGE, 0);
    } else {
        amp_buffer_clear(amp);
        amp->play_index = start_index;
        amp->prefill = prefill;
        amp->envelope_hz = envelope_hz;
        amp->ramping = 0; /* the output continues from its present value, slew-limited */
        amp_clock_start(amp, amp->now_us, envelope_hz);
        amp->state = AMP_PRIMING;
        accept(amp);
        amp_send_ack(amp, frame, AMP_OK, start_index);
    }
}

static void on_envelope(amp_t *amp, const amp_frame_t *frame) {
    uint32_t first = get_u32(frame->payload);
    uint32_t count = (uint32_t)(frame->payload_bytes - ENVELOPE_HEADER_BYTES) / 2u;
    if (amp->state != AMP_PRIMING && amp->state != AMP_RUNNING) {
        reject(amp, frame, AMP_NOT_STARTED, 0);
    } else if (!amp_buffer_fits(first, count, amp->play_index)) {
        reject(amp, frame, AMP_OUT_OF_WINDOW, 0);
    } else {
        amp_buffer_put(amp, first, frame->payload + ENVELOPE_HEADER_BYTES, count);
        accept(amp);
        if (amp->state == AMP_PRIMING && amp_buffer_fill(amp, amp->play_index) >= amp->prefill)
            amp->state = AMP_RUNNING; /* its first sample plays at the clock's next due time */
    }
}

static void on_stop(amp_t *amp, const amp_frame_t *frame) {
    accept(amp);
    amp_send_ack(amp, frame, AMP_OK, 0); /* at once, before the ramp ends */
    if (amp->state == AMP_PRIMING || amp->state == AMP_RUNNING || amp->state == AMP_RAMPING) {
        uint16_t ramp_ms = get_u16(frame->payload);
        amp_buffer_clear(amp);
        amp_ramp_begin(amp, ramp_ms < AMP_MAX_STOP_RAMP_MS ? ramp_ms : AMP_MAX_STOP_RAMP_MS, AMP_RAMPING, AMP_IDLE);
    }
}

/* The payload length `type` has (2.3 step 4); 0 when it is fine. */
static int length_ok(const amp_frame_t *frame) {
    size_t n = frame->payload_bytes;
    switch (frame->type) {
    case MSG_HELLO: return n == HELLO_BYTES;
    case MSG_SET_CARRIER: return n == SET_CARRIER_BYTES;
    case MSG_START: return n == START_BYTES;
    case MSG_STOP: return n == STOP_BYTES;
    case MSG_KEEPALIVE: return n == KEEPALIVE_BYTES;
    default: /* ENVELOPE */
        return n >= ENVELOPE_HEADER_BYTES + 2u && (n - ENVELOPE_HEADER_BYTES) % 2u == 0
            && (n - ENVELOPE_HEADER_BYTES) / 2u <= AMP_MAX_FRAME_SAMPLES;
    }
}

void amp_on_frame(amp_t *amp, const amp_frame_t *frame) {
    amp->last_valid_us = amp->now_us; /* A4: every valid frame, even one rejected, resets the watchdog */
    if (frame->type != MSG_HELLO && amp->has_last_seq && frame->seq != (uint16_t)(amp->last_seq + 1u))
        amp->counters.sequence_gaps++; /* 2.2; HELLO sets the count's start */
    amp->last_seq = frame->seq;
    amp->has_last_seq = 1;
    if (frame->version != AMP_VERSION) {
        reject(amp, frame, AMP_BAD_VERSION, AMP_VERSION); /* 2.3 step 3, A5 */
    } else if (frame->type < MSG_HELLO || frame->type > MSG_KEEPALIVE) {
        reject(amp, frame, AMP_UNKNOWN_TYPE, 0);
    } else if (!length_ok(frame)) {
        reject(amp, frame, AMP_BAD_LENGTH, 0);
    } else {
        switch (frame->type) {
        case MSG_HELLO: on_hello(amp, frame); break;
        case MSG_SET_CARRIER: on_set_carrier(amp, frame); break;
        case MSG_START: on_start(amp, frame); break;
        case MSG_ENVELOPE: on_envelope(amp, frame); break;
        case MSG_STOP: on_stop(amp, frame); break;
        default: accept(amp); break; /* KEEPALIVE: nothing but the watchdog */
        }
    }
}
