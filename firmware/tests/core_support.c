/* core_support.c - the host's side of a session with the core, for the unit tests. */
#include <string.h>

#include "core_check.h"

const hal_board_t test_board = {
    "test", 192000u, 125000u, 100000u, 10000000u, 80000000u, 2000u, 7u, 5000u, 1000u,
};
const hal_board_t test_board_protocol = {
    "proto", 0u, 125000u, 100000u, 10000000u, 80000000u, 0u, 0u, 0u, 0u,
};

void session_init(session_t *s, const hal_board_t *board, uint64_t now_us) {
    memset(s, 0, sizeof *s);
    amp_init(&s->amp, board, "TEST-0001", now_us);
}

void host_send_version(session_t *s, uint8_t version, uint8_t type, const uint8_t *payload, size_t n,
                       uint64_t now_us) {
    uint8_t line[AMP_MAX_ENCODED + 1];
    size_t length = amp_frame_encode(version, type, s->host_seq++, payload, n, line);
    amp_receive(&s->amp, line, length, now_us);
}

void host_send(session_t *s, uint8_t type, const uint8_t *payload, size_t n, uint64_t now_us) {
    host_send_version(s, AMP_VERSION, type, payload, n, now_us);
}

void host_hello(session_t *s, uint32_t nonce, uint64_t now_us) {
    uint8_t p[16] = { 't', 'e', 's', 't' };
    put_u32(p + 12, nonce);
    s->host_seq = 0;
    host_send(s, MSG_HELLO, p, sizeof p, now_us);
}

void host_set_carrier(session_t *s, uint32_t carrier_mhz, uint64_t now_us) {
    uint8_t p[4];
    put_u32(p, carrier_mhz);
    host_send(s, MSG_SET_CARRIER, p, sizeof p, now_us);
}

void host_start(session_t *s, uint32_t envelope_hz, uint32_t start_index, uint16_t prefill, uint64_t now_us) {
    uint8_t p[10];
    put_u32(p, envelope_hz);
    put_u32(p + 4, start_index);
    put_u16(p + 8, prefill);
    host_send(s, MSG_START, p, sizeof p, now_us);
}

void host_envelope(session_t *s, uint32_t first_index, const int16_t *samples, size_t n, uint64_t now_us) {
    uint8_t p[4 + 2 * 300];
    put_u32(p, first_index);
    for (size_t i = 0; i < n; i++)
        put_u16(p + 4 + 2 * i, (uint16_t)samples[i]);
    host_send(s, MSG_ENVELOPE, p, 4 + 2 * n, now_us);
}

void host_stop(session_t *s, uint16_t ramp_ms, uint64_t now_us) {
    uint8_t p[2];
    put_u16(p, ramp_ms);
    host_send(s, MSG_STOP, p, sizeof p, now_us);
}

void take_sent(session_t *s) {
    uint8_t bytes[4096], frame[AMP_MAX_ENCODED];
    size_t n = amp_transmit(&s->amp, bytes, sizeof bytes), length = 0;
    s->sent_count = 0;
    for (size_t i = 0; i < n; i++) {
        if (bytes[i] != 0) {
            if (length < sizeof frame)
                frame[length++] = bytes[i];
            continue;
        }
        uint8_t body[AMP_MAX_ENCODED];
        amp_frame_t f;
        CHECK_EQ(amp_frame_decode(frame, length, body, &f), 0);
        length = 0;
        if (s->sent_count < MAX_SENT) {
            sent_t *out = &s->sent[s->sent_count++];
            out->version = f.version;
            out->type = f.type;
            out->seq = f.seq;
            out->payload_bytes = f.payload_bytes;
            memcpy(out->payload, f.payload, f.payload_bytes);
        }
    }
    CHECK_EQ(length, 0); /* whole frames only */
}

int last_ack(const session_t *s, uint8_t *acked_type, uint32_t *value) {
    for (size_t i = s->sent_count; i-- > 0;) {
        if (s->sent[i].type == MSG_ACK) {
            if (acked_type)
                *acked_type = s->sent[i].payload[2];
            if (value)
                *value = get_u32(s->sent[i].payload + 4);
            return s->sent[i].payload[3];
        }
    }
    return -1;
}

size_t count_sent(const session_t *s, uint8_t type) {
    size_t n = 0;
    for (size_t i = 0; i < s->sent_count; i++)
        n += s->sent[i].type == type;
    return n;
}

amp_counters_t counters_of(const amp_t *amp) {
    amp_counters_t c;
    amp_counters(amp, &c);
    return c;
}

void session_running(session_t *s, uint64_t t0_us, uint32_t start, int16_t value) {
    int16_t samples[16];
    for (int i = 0; i < 16; i++)
        samples[i] = value;
    host_hello(s, 1, t0_us);
    host_set_carrier(s, 31360000u, t0_us);
    host_start(s, 16000u, start, 16, t0_us);
    host_envelope(s, start, samples, 16, t0_us);
    CHECK_EQ(s->amp.state, AMP_RUNNING);
    take_sent(s);
}

void record_event(void *ctx, const amp_event_t *event) {
    recorder_t *r = ctx;
    if (r->count < MAX_EVENTS)
        r->events[r->count++] = *event;
}
