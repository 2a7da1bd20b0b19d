/* core_wire.c - the wire: CRC-16, COBS, the document's worked bytes (section 7), the splitter. */
#include <string.h>

#include "core_check.h"

static void check_bytes(const uint8_t *got, size_t got_n, const uint8_t *want, size_t want_n) {
    CHECK_EQ(got_n, want_n);
    CHECK(got_n == want_n && memcmp(got, want, want_n) == 0);
}

static void test_crc(void) {
    const uint8_t text[] = "123456789";
    CHECK_EQ(amp_crc16(text, 9), 0x29B1);
    const uint8_t keepalive[] = { 0x02, 0x06, 0x05, 0x00 };
    CHECK_EQ(amp_crc16(keepalive, sizeof keepalive), 0x24FD);
}

static void test_cobs(void) {
    uint8_t out[1200], back[1200];
    const uint8_t body[] = { 0x11, 0x22, 0x00, 0x33 }, line[] = { 0x03, 0x11, 0x22, 0x02, 0x33 };
    check_bytes(out, amp_cobs_encode(body, sizeof body, out), line, sizeof line);
    CHECK_EQ(amp_cobs_decode(line, sizeof line, back, sizeof back), 4);
    CHECK(memcmp(back, body, 4) == 0);
    const uint8_t empty_line[] = { 0x01 };
    check_bytes(out, amp_cobs_encode(body, 0, out), empty_line, 1);
    CHECK_EQ(amp_cobs_decode(empty_line, 1, back, sizeof back), 0);
    /* 254 and 255 non-zero bytes, a 0 after 254: the full-block rules (no 0 after code 255) */
    uint8_t run[600];
    for (size_t n = 253; n <= 600; n += (n < 260 ? 1 : 85)) {
        for (size_t i = 0; i < n; i++)
            run[i] = (uint8_t)(i % 255 + 1);
        if (n == 255)
            run[254] = 0;
        size_t length = amp_cobs_encode(run, n, out);
        CHECK_EQ(length, n + 1 + (n - 1) / 254 - (n == 255 ? 0 : 0));
        CHECK(memchr(out, 0, length) == NULL);
        CHECK_EQ(amp_cobs_decode(out, length, back, sizeof back), (long)n);
        CHECK(memcmp(back, run, n) == 0);
    }
    uint8_t full[255];
    for (int i = 0; i < 254; i++)
        full[i] = 7;
    CHECK_EQ(amp_cobs_encode(full, 254, out), 255); /* one full block, nothing after it */
    CHECK_EQ(out[0], 0xFF);
    /* bad encodings: a 0 inside, a block past the end, a body longer than the room */
    const uint8_t zero_inside[] = { 0x03, 0x11, 0x00 }, past_end[] = { 0x05, 0x11, 0x22 };
    CHECK_EQ(amp_cobs_decode(zero_inside, sizeof zero_inside, back, sizeof back), -1);
    CHECK_EQ(amp_cobs_decode(past_end, sizeof past_end, back, sizeof back), -1);
    CHECK_EQ(amp_cobs_decode(line, sizeof line, back, 3), -1);
    CHECK_EQ(amp_cobs_decode(line, sizeof line, back, 4), 4);
    const uint8_t two_blocks[] = { 0x01, 0x01 };
    CHECK_EQ(amp_cobs_decode(two_blocks, 2, back, 0), -1); /* its 0 does not fit */
}

/* Section 7: each body and its line, encoded by the core, and taken by the core as valid. */
static void test_worked_bytes(void) {
    static const uint8_t keepalive_line[] = { 0x04, 0x02, 0x06, 0x05, 0x03, 0xfd, 0x24, 0x00 };
    static const uint8_t hello_line[] = { 0x03, 0x02, 0x01, 0x01, 0x08, 0x74, 0x70, 0x61, 0x64, 0x2d, 0x72,
        0x74, 0x01, 0x01, 0x01, 0x01, 0x07, 0xb9, 0x79, 0x37, 0x9e, 0xc0, 0xc4, 0x00 };
    static const uint8_t envelope_line[] = { 0x04, 0x02, 0x04, 0x03, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01,
        0x02, 0x40, 0x06, 0xc0, 0xff, 0x7f, 0x6a, 0x87, 0x00 };
    static const uint8_t hello_payload[] = { 0x74, 0x70, 0x61, 0x64, 0x2d, 0x72, 0x74, 0, 0, 0, 0, 0,
        0xb9, 0x79, 0x37, 0x9e };
    static const uint8_t envelope_payload[] = { 0, 0, 0, 0, 0x00, 0x00, 0x00, 0x40, 0x00, 0xc0, 0xff, 0x7f };
    uint8_t line[AMP_MAX_ENCODED + 1];
    check_bytes(line, amp_frame_encode(2, MSG_KEEPALIVE, 5, NULL, 0, line), keepalive_line, sizeof keepalive_line);
    check_bytes(line, amp_frame_encode(2, MSG_HELLO, 0, hello_payload, 16, line), hello_line, sizeof hello_line);
    check_bytes(line, amp_frame_encode(2, MSG_ENVELOPE, 3, envelope_payload, 12, line), envelope_line,
                sizeof envelope_line);

    static session_t s;
    session_init(&s, &test_board, 0);
    amp_receive(&s.amp, hello_line, sizeof hello_line, 1000);
    take_sent(&s);
    CHECK_EQ(s.sent_count, 1);
    CHECK_EQ(s.sent[0].type, MSG_INFO);
    CHECK_EQ(get_u32(s.sent[0].payload + 84), 0x9E3779B9u); /* the nonce echoed */
    s.host_seq = 1;
    host_set_carrier(&s, 31360000u, 1000);
    host_start(&s, 16000, 0, 4, 1000);
    CHECK_EQ(s.amp.state, AMP_PRIMING);
    amp_receive(&s.amp, envelope_line, sizeof envelope_line, 1000); /* seq 3 follows START's 2 */
    CHECK_EQ(s.amp.state, AMP_RUNNING);
    amp_receive(&s.amp, keepalive_line, sizeof keepalive_line, 1000);
    amp_counters_t c = counters_of(&s.amp);
    CHECK_EQ(c.frames_ok, 5);
    CHECK_EQ(c.frames_bad, 0);
    CHECK_EQ(c.sequence_gaps, 1); /* KEEPALIVE's seq 5 after 3 */
    /* the samples play as the document says: 0, about half, the same in anti-phase, full scale (clamped) */
    static recorder_t r;
    r.count = 0;
    amp_set_observer(&s.amp, record_event, &r);
    amp_advance(&s.amp, 1000 + 4 * 63);
    CHECK_EQ(r.count, 4);
    CHECK_EQ(r.events[0].index, 0);
    CHECK_EQ(r.events[0].envelope_uv, 0);
    CHECK_EQ(r.events[1].envelope_uv, 6250000); /* slew-limited: 100 V/ms at 16 kHz */
    CHECK_EQ(r.events[3].index, 3);
}

/* The splitter: empty frames, a frame cut across reads, bad frames of every kind, an over-long run. */
static void test_splitter(void) {
    static session_t s;
    session_init(&s, &test_board, 0);
    host_hello(&s, 7, 0);
    uint8_t line[AMP_MAX_ENCODED + 1];
    size_t n = amp_frame_encode(2, MSG_KEEPALIVE, 1, NULL, 0, line);
    const uint8_t zeros[3] = { 0, 0, 0 };
    amp_receive(&s.amp, zeros, 3, 10);            /* empty frames: ignored */
    amp_receive(&s.amp, line, 3, 10);             /* a frame in two reads */
    amp_receive(&s.amp, line + 3, n - 3, 11);
    CHECK_EQ(counters_of(&s.amp).frames_ok, 2);
    CHECK_EQ(counters_of(&s.amp).frames_bad, 0);

    uint8_t bad[AMP_MAX_ENCODED + 10];
    n = amp_frame_encode(2, MSG_KEEPALIVE, 2, NULL, 0, bad);
    bad[4] ^= 0x01; /* the CRC */
    amp_receive(&s.amp, bad, n, 20);
    const uint8_t bad_cobs[] = { 0x05, 0x02, 0x06, 0x00 };         /* a block past the end */
    const uint8_t short_body[] = { 0x04, 0x02, 0x06, 0x05, 0x00 }; /* 3 bytes: under MIN_BODY */
    amp_receive(&s.amp, bad_cobs, sizeof bad_cobs, 21);
    amp_receive(&s.amp, short_body, sizeof short_body, 22);
    CHECK_EQ(counters_of(&s.amp).frames_bad, 3);
    /* a body over MAX_BODY that fits the splitter: bad */
    uint8_t body[AMP_MAX_BODY + 1];
    memset(body, 0x55, sizeof body);
    n = amp_cobs_encode(body, sizeof body, bad);
    bad[n++] = 0;
    amp_receive(&s.amp, bad, n, 23);
    CHECK_EQ(counters_of(&s.amp).frames_bad, 4);
    /* over-long runs: AMP_MAX_ENCODED bytes are still a candidate, one more is one bad frame, however long */
    memset(bad, 0x01, sizeof bad);
    amp_receive(&s.amp, bad, AMP_MAX_ENCODED, 24);
    amp_receive(&s.amp, zeros, 1, 24);
    CHECK_EQ(counters_of(&s.amp).frames_bad, 5); /* decoded: 525 zeros, over MAX_BODY */
    for (int i = 0; i < 4; i++)
        amp_receive(&s.amp, bad, sizeof bad, 25);
    CHECK_EQ(counters_of(&s.amp).frames_bad, 6);
    CHECK_EQ(s.amp.rx_len, 0);
    n = amp_frame_encode(2, MSG_KEEPALIVE, 3, NULL, 0, line);
    amp_receive(&s.amp, line, n, 26); /* discarded up to the 0x00: the KEEPALIVE is lost with the run */
    CHECK_EQ(counters_of(&s.amp).frames_ok, 2);
    amp_receive(&s.amp, line, n, 27); /* and the next one is taken */
    CHECK_EQ(counters_of(&s.amp).frames_ok, 3);
    CHECK_EQ(counters_of(&s.amp).frames_rejected, 0);
    take_sent(&s);
    CHECK_EQ(count_sent(&s, MSG_ACK), 0); /* bad frames are not acknowledged */
}

void test_wire(void) {
    test_crc();
    test_cobs();
    test_worked_bytes();
    test_splitter();
}
