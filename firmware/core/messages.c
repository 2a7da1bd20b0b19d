/* messages.c - what the amplifier sends (docs/amp-protocol.md 3.2): INFO, STATUS, ACK. */
#include "amp_core.h"

static void put_text(uint8_t *p, const char *text, size_t size) {
    size_t i = 0;
    for (; i < size && text[i] != 0; i++)
        p[i] = (uint8_t)text[i];
    for (; i < size; i++)
        p[i] = 0;
}

void amp_send_info(amp_t *amp, uint32_t hello_nonce) {
    const hal_board_t *board = amp->board;
    uint8_t p[INFO_BYTES] = { 0 };
    put_text(p, AMP_FIRMWARE, 16);
    put_text(p + 16, amp->serial, 16);
    put_u32(p + 32, 8000u); /* envelope_rates_hz: 8000, 16000, 0, 0 */
    put_u32(p + 36, 16000u);
    put_u32(p + 48, amp->carrier_min_mhz);
    put_u32(p + 52, amp->carrier_max_mhz);
    put_u32(p + 56, amp->carrier_step_mhz);
    put_u32(p + 60, amp->full_scale_uv / 1000u);
    put_u32(p + 64, amp->max_mv);
    put_u32(p + 68, amp->slew_mv_per_ms);
    put_u16(p + 72, AMP_BUFFER_SAMPLES);
    put_u16(p + 74, AMP_MAX_FRAME_SAMPLES);
    put_u16(p + 76, AMP_WATCHDOG_MS);
    put_u16(p + 78, AMP_STATUS_PERIOD_MS);
    p[80] = board->measures & 7u;
    put_u32(p + 84, hello_nonce);
    put_u32(p + 88, board->max_current_ma);
    amp_send(amp, MSG_INFO, p, sizeof p);
}

/* time_us goes out as its low 32 bits (the field wraps). */
void amp_send_status(amp_t *amp, uint64_t time_us) {
    uint8_t measures = amp->board->measures;
    const amp_counters_t *c = &amp->counters;
    int32_t uv = amp->output_uv;
    uint8_t p[STATUS_BYTES];
    put_u32(p, (uint32_t)time_us);
    put_u32(p + 4, amp->play_index);
    put_u16(p + 8, (uint16_t)amp_buffer_fill(amp, amp->play_index));
    p[10] = amp->state;
    p[11] = amp->faults;
    put_u32(p + 12, c->frames_ok);
    put_u32(p + 16, c->frames_bad);
    put_u32(p + 20, c->frames_rejected);
    put_u32(p + 24, c->sequence_gaps);
    put_u32(p + 28, c->underruns);
    put_u32(p + 32, c->watchdog_trips);
    put_u16(p + 36, amp->last_seq);
    put_u16(p + 38, (uint16_t)(measures & 4u ? amp->phase_cdeg : 0));
    put_u32(p + 40, (uint32_t)(uv >= 0 ? (uv + 500) / 1000 : -((-uv + 500) / 1000))); /* mV, rounded */
    put_u32(p + 44, measures & 2u ? amp->voltage_mv_rms : 0u);
    put_u32(p + 48, measures & 1u ? amp->current_ua_rms : 0u);
    put_u32(p + 52, amp_carrier_made_mhz(amp));
    amp_send(amp, MSG_STATUS, p, sizeof p);
}

void amp_send_ack(amp_t *amp, const amp_frame_t *frame, uint8_t code, uint32_t value) {
    uint8_t p[ACK_BYTES];
    put_u16(p, frame->seq);
    p[2] = frame->type;
    p[3] = code;
    put_u32(p + 4, value);
    amp_send(amp, MSG_ACK, p, sizeof p);
}
