/* core_protocol.c - the messages (section 3): HELLO and INFO, SET_CARRIER, START's checks in the
 * emulator's order, ENVELOPE's window and lengths, STOP, KEEPALIVE, versions, types, sequence gaps. */
#include <string.h>

#include "core_check.h"

static session_t s;

static void test_power_up(void) {
    session_init(&s, &test_board, 500);
    amp_counters_t c = counters_of(&s.amp);
    CHECK_EQ(c.state, AMP_IDLE); /* A7 */
    CHECK_EQ(c.envelope_uv, 0);
    CHECK_EQ(c.carrier_mhz, 0);
    CHECK_EQ(amp_next_due_us(&s.amp), UINT64_MAX); /* no STATUS before HELLO */
    amp_advance(&s.amp, 1000000);
    take_sent(&s);
    CHECK_EQ(s.sent_count, 0);
    CHECK_EQ(amp_sizeof(), sizeof(amp_t));
}

static void test_hello_info(void) {
    session_init(&s, &test_board, 500);
    host_hello(&s, 0xDEADBEEFu, 1500);
    take_sent(&s);
    CHECK_EQ(s.sent_count, 1);
    const sent_t *info = &s.sent[0];
    CHECK_EQ(info->type, MSG_INFO);
    CHECK_EQ(info->version, 2);
    CHECK_EQ(info->seq, 0);
    CHECK_EQ(info->payload_bytes, 92);
    CHECK(memcmp(info->payload, "tpad-amp 1.0\0\0\0\0", 16) == 0);
    CHECK(memcmp(info->payload + 16, "TEST-0001\0\0\0\0\0\0\0", 16) == 0);
    CHECK_EQ(get_u32(info->payload + 32), 8000);
    CHECK_EQ(get_u32(info->payload + 36), 16000);
    CHECK_EQ(get_u32(info->payload + 40), 0);
    CHECK_EQ(get_u32(info->payload + 48), 10000000);
    CHECK_EQ(get_u32(info->payload + 52), 80000000);
    CHECK_EQ(get_u32(info->payload + 56), 10);
    CHECK_EQ(get_u32(info->payload + 60), 125000);
    CHECK_EQ(get_u32(info->payload + 64), 100000);
    CHECK_EQ(get_u32(info->payload + 68), 100000);
    CHECK_EQ(get_u16(info->payload + 72), 1024);
    CHECK_EQ(get_u16(info->payload + 74), 256);
    CHECK_EQ(get_u16(info->payload + 76), 50);
    CHECK_EQ(get_u16(info->payload + 78), 5);
    CHECK_EQ(info->payload[80], 7);
    CHECK_EQ(info->payload[81] | info->payload[82] | info->payload[83], 0);
    CHECK_EQ(get_u32(info->payload + 84), 0xDEADBEEFu);
    CHECK_EQ(get_u32(info->payload + 88), 2000);
    CHECK_EQ(counters_of(&s.amp).frames_ok, 1);
    /* STATUS every 5 ms from HELLO on: the first at 5 ms after it, time_us counted from amp_init */
    CHECK_EQ(amp_next_due_us(&s.amp), 6500);
    amp_advance(&s.amp, 6499);
    take_sent(&s);
    CHECK_EQ(s.sent_count, 0);
    amp_advance(&s.amp, 11500);
    take_sent(&s);
    CHECK_EQ(count_sent(&s, MSG_STATUS), 2);
    CHECK_EQ(get_u32(s.sent[0].payload), 6000);
    CHECK_EQ(get_u32(s.sent[1].payload), 11000);
    CHECK_EQ(s.sent[1].seq, 2);
    CHECK_EQ(get_u32(s.sent[1].payload + 12), 1); /* frames_ok: the HELLO */
    /* a second HELLO restarts the schedule, the counters and seq; a new nonce is echoed */
    host_hello(&s, 5, 12000);
    take_sent(&s);
    CHECK_EQ(s.sent[0].seq, 0);
    CHECK_EQ(get_u32(s.sent[0].payload + 84), 5);
    CHECK_EQ(amp_next_due_us(&s.amp), 17000);
    /* a protocol-only board says so */
    session_init(&s, &test_board_protocol, 0);
    host_hello(&s, 1, 0);
    take_sent(&s);
    CHECK_EQ(s.sent[0].payload[80], 0);
    CHECK_EQ(get_u32(s.sent[0].payload + 88), 0);
}

static void test_set_carrier(void) {
    session_init(&s, &test_board, 0);
    host_hello(&s, 1, 0);
    host_set_carrier(&s, 31360004u, 0); /* nearest multiple of 10 mHz */
    take_sent(&s);
    uint32_t value;
    uint8_t type;
    CHECK_EQ(last_ack(&s, &type, &value), AMP_OK);
    CHECK_EQ(type, MSG_SET_CARRIER);
    CHECK_EQ(value, 31360000u);
    host_set_carrier(&s, 31360005u, 0); /* a tie rounds up */
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, &value), AMP_OK);
    CHECK_EQ(value, 31360010u);
    host_set_carrier(&s, 80000001u, 0);
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, &value), AMP_OUT_OF_RANGE);
    CHECK_EQ(value, 0);
    CHECK_EQ(counters_of(&s.amp).carrier_mhz, 31360010u); /* unchanged */
    host_set_carrier(&s, 9999999u, 0);
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_OUT_OF_RANGE);
    host_set_carrier(&s, 80000000u, 0);
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, &value), AMP_OK);
    CHECK_EQ(value, 80000000u);
    CHECK_EQ(counters_of(&s.amp).frames_rejected, 2);
}

/* A board's range is made to multiples of the step, inside it and below half the output rate. */
static void test_carrier_range(void) {
    static const hal_board_t odd = { "odd", 48000u, 1000u, 900u, 10005u, 30000000u, 0u, 0u, 0u, 0u };
    session_init(&s, &odd, 0);
    CHECK_EQ(s.amp.carrier_min_mhz, 10010);
    CHECK_EQ(s.amp.carrier_max_mhz, 23999990);
    CHECK_EQ(s.amp.max_mv, 900);
    CHECK_EQ(s.amp.slew_mv_per_ms, 100000);
}

static void test_start_checks(void) {
    session_init(&s, &test_board, 0);
    host_hello(&s, 1, 0);
    host_start(&s, 12000, 0, 16, 0); /* no carrier either: BAD_RATE comes first */
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_BAD_RATE);
    host_start(&s, 16000, 0, 0, 0); /* prefill 0 too: NO_CARRIER comes first */
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_NO_CARRIER);
    host_set_carrier(&s, 30000000u, 0);
    host_start(&s, 16000, 0, 0, 0);
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_OUT_OF_RANGE);
    host_start(&s, 16000, 0, 1025, 0);
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_OUT_OF_RANGE);
    CHECK_EQ(s.amp.state, AMP_IDLE);
    uint32_t value;
    host_start(&s, 8000, 77, 1024, 0);
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, &value), AMP_OK);
    CHECK_EQ(value, 77);
    CHECK_EQ(s.amp.state, AMP_PRIMING);
    amp_fault(&s.amp, AMP_FAULT_OVERTEMPERATURE, 10);
    host_start(&s, 12000, 0, 0, 20); /* FAULT comes before everything */
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_CODE_FAULT);
    CHECK_EQ(counters_of(&s.amp).frames_rejected, 5);
    host_hello(&s, 2, 30); /* until HELLO */
    host_set_carrier(&s, 30000000u, 30);
    host_start(&s, 16000, 0, 1, 30);
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_OK);
}

static void test_envelope_checks(void) {
    int16_t samples[300] = { 0 };
    session_init(&s, &test_board, 0);
    host_hello(&s, 1, 0);
    host_set_carrier(&s, 30000000u, 0);
    host_envelope(&s, 0, samples, 4, 0); /* NOT_STARTED: counted, never acknowledged */
    take_sent(&s);
    CHECK_EQ(count_sent(&s, MSG_ACK), 1); /* SET_CARRIER's */
    CHECK_EQ(counters_of(&s.amp).frames_rejected, 1);
    host_start(&s, 16000, 0xFFFFFF00u, 1024, 0);
    take_sent(&s);
    host_envelope(&s, 0xFFFFFF00u + 1024u - 256u, samples, 256, 0); /* the window's last 256 (across 2**32) */
    host_envelope(&s, 0xFFFFFF00u + 1024u - 255u, samples, 256, 0); /* one past the window */
    host_envelope(&s, 0xFFFFFEFFu, samples, 1, 0);                  /* one before play_index */
    host_envelope(&s, 0x7FFFFFFFu, samples, 1, 0);                  /* absurd */
    take_sent(&s);
    CHECK_EQ(count_sent(&s, MSG_ACK), 0);
    amp_counters_t c = counters_of(&s.amp);
    CHECK_EQ(c.frames_rejected, 4);
    CHECK_EQ(amp_buffer_fill(&s.amp, 0xFFFFFF00u), 0);
    CHECK_EQ(amp_buffer_fill(&s.amp, 0xFFFFFF00u + 768u), 256);
    /* lengths: no samples, an odd byte, shorter than first_index: BAD_LENGTH, counted, not acknowledged */
    uint8_t p[16] = { 0 };
    host_send(&s, MSG_ENVELOPE, p, 4, 0);
    host_send(&s, MSG_ENVELOPE, p, 7, 0);
    host_send(&s, MSG_ENVELOPE, p, 3, 0);
    take_sent(&s);
    CHECK_EQ(s.sent_count, 0);
    CHECK_EQ(counters_of(&s.amp).frames_rejected, 7);
    /* 257 samples: a body over MAX_BODY, a bad frame (however good its CRC) */
    uint8_t body[6 + 4 + 2 * 257] = { 2, MSG_ENVELOPE, 0, 0 }, line[AMP_MAX_ENCODED + 8];
    put_u16(body + sizeof body - 2, amp_crc16(body, sizeof body - 2));
    size_t n = amp_cobs_encode(body, sizeof body, line);
    line[n++] = 0;
    amp_receive(&s.amp, line, n, 0);
    take_sent(&s);
    CHECK_EQ(s.sent_count, 0);
    CHECK_EQ(counters_of(&s.amp).frames_bad, 1);
    /* samples arriving again replace those buffered */
    int16_t one = 1000, two = 2000;
    host_envelope(&s, 0xFFFFFF00u, &one, 1, 0);
    host_envelope(&s, 0xFFFFFF00u, &two, 1, 0);
    int16_t got = 0;
    CHECK(amp_buffer_take(&s.amp, 0xFFFFFF00u, &got));
    CHECK_EQ(got, 2000);
    CHECK(!amp_buffer_take(&s.amp, 0xFFFFFF00u, &got));
}

static void test_other_frames(void) {
    session_init(&s, &test_board, 0);
    host_hello(&s, 1, 0);
    uint8_t p[20] = { 0 };
    uint32_t value;
    uint8_t type;
    host_send_version(&s, 1, MSG_ENVELOPE, p, 6, 0); /* another version: BAD_VERSION, even an ENVELOPE */
    take_sent(&s);
    CHECK_EQ(last_ack(&s, &type, &value), AMP_BAD_VERSION);
    CHECK_EQ(type, MSG_ENVELOPE);
    CHECK_EQ(value, 2);
    host_send_version(&s, 3, MSG_HELLO, p, 16, 0); /* A5: a HELLO of another version is not acted on */
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_BAD_VERSION);
    CHECK_EQ(count_sent(&s, MSG_INFO), 0);
    host_send(&s, 0x07, p, 0, 0);
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_UNKNOWN_TYPE);
    host_send(&s, MSG_STATUS, p, 0, 0);
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_UNKNOWN_TYPE);
    static const uint8_t types[] = { MSG_HELLO, MSG_SET_CARRIER, MSG_START, MSG_STOP, MSG_KEEPALIVE };
    for (size_t i = 0; i < sizeof types; i++) {
        host_send(&s, types[i], p, 1, 0);
        take_sent(&s);
        CHECK_EQ(last_ack(&s, &type, NULL), AMP_BAD_LENGTH);
        CHECK_EQ(type, types[i]);
    }
    CHECK_EQ(counters_of(&s.amp).frames_rejected, 9);
    CHECK_EQ(counters_of(&s.amp).frames_ok, 1);
    host_send(&s, MSG_KEEPALIVE, p, 0, 0); /* answered by nothing */
    host_stop(&s, 5, 0);                   /* STOP outside a stream: OK */
    take_sent(&s);
    CHECK_EQ(s.sent_count, 1);
    CHECK_EQ(last_ack(&s, NULL, &value), AMP_OK);
    CHECK_EQ(value, 0);
    CHECK_EQ(counters_of(&s.amp).frames_ok, 3);
}

static void test_sequence(void) {
    session_init(&s, &test_board, 0);
    host_send(&s, MSG_KEEPALIVE, NULL, 0, 0); /* the first frame ever: no gap */
    s.host_seq = 40;
    host_send(&s, MSG_KEEPALIVE, NULL, 0, 0);
    CHECK_EQ(counters_of(&s.amp).sequence_gaps, 1);
    host_hello(&s, 1, 0); /* sets the count's start, and counters to 0 */
    CHECK_EQ(counters_of(&s.amp).sequence_gaps, 0);
    s.host_seq = 0xFFFF;
    host_send(&s, MSG_KEEPALIVE, NULL, 0, 0); /* 0 -> 0xFFFF: a gap */
    host_send(&s, MSG_KEEPALIVE, NULL, 0, 0); /* 0xFFFF -> 0: none (mod 65536) */
    uint8_t p[2] = { 0 };
    s.host_seq = 7;
    host_send_version(&s, 9, MSG_STOP, p, 2, 0); /* a rejected valid frame counts too */
    CHECK_EQ(counters_of(&s.amp).sequence_gaps, 2);
    CHECK_EQ(s.amp.last_seq, 7);
    host_send(&s, MSG_KEEPALIVE, NULL, 0, 0);
    CHECK_EQ(counters_of(&s.amp).sequence_gaps, 2);
}

void test_protocol(void) {
    test_power_up();
    test_hello_info();
    test_set_carrier();
    test_carrier_range();
    test_start_checks();
    test_envelope_checks();
    test_other_frames();
    test_sequence();
}
