/* core_random.c - random sessions of valid and hostile input on several boards (seeded: the same every
 * run), with the core's invariants checked after every step:
 * - every applied envelope (observer, counters) within +-max_mv * 1000 uV, every state 0 .. 4;
 * - every output sample within round(max_mv / full_scale_mv * 32767);
 * - no non-zero applied envelope due later than watchdog_ms after the last valid frame;
 * - the counters never go down except at a HELLO (tx_dropped never).
 * The input: HELLO, SET_CARRIER at and past its range's ends, START (rates, indices near 2**32, prefill
 * 0 .. 1100), ENVELOPE (indices around the window and near 2**32, 1 .. 257 samples, -32768 and 0x7FFF),
 * STOP, KEEPALIVE, wrong versions, types and lengths, corrupted frames and bad COBS, faults, ADC pairs
 * (random, all +-32767), time steps of microseconds to hours and backwards, output and line taken in
 * pieces. The test build has ASan and UBSan: undefined behaviour on any of it ends the run. */
#include <string.h>
#include <time.h>

#include "core_check.h"

#define SEED 0x7AD5EEDull
#define STEPS_PER_BOARD 2500u
#define WATCHDOG_US ((uint64_t)AMP_WATCHDOG_MS * 1000u)

static uint64_t rng_state;
static uint32_t rng(void) { /* xorshift64 */
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return (uint32_t)(rng_state >> 16);
}
static uint32_t below(uint32_t n) { return rng() % n; }

static session_t s;
static uint64_t now_us;
static int32_t cap_uv;          /* max_mv * 1000 */
static int16_t cap_sample;      /* round(max / full * 32767) */
static int hello_seen;          /* a HELLO acted on since the last check */
static amp_counters_t previous;
static unsigned long steps, samples_checked, events_checked;

static void on_hello(void *ctx) {
    (void)ctx;
    hello_seen = 1;
}

static void observe(void *ctx, const amp_event_t *e) {
    (void)ctx;
    events_checked++;
    CHECK(e->state <= AMP_FAULT);
    if (e->kind != AMP_EVENT_SAMPLE)
        return;
    CHECK(e->envelope_uv <= cap_uv && e->envelope_uv >= -cap_uv);
    uint64_t last_us = amp_last_valid_us(&s.amp);
    if (last_us != UINT64_MAX && (e->t_us > last_us + WATCHDOG_US || (e->t_us == last_us + WATCHDOG_US && e->t_rem)))
        CHECK_EQ(e->envelope_uv, 0);
}

/* A frame as sent (2.1, 2.2: the body may be longer than the core takes), then maybe corrupted (a byte
 * changed, a 0x00 in it, cut short). */
#define LONGEST_PAYLOAD (AMP_MAX_BODY + 16u)
static void send(uint8_t version, uint8_t type, const uint8_t *payload, size_t n) {
    uint8_t body[LONGEST_PAYLOAD + AMP_MIN_BODY], line[LONGEST_PAYLOAD + AMP_MIN_BODY + 8u];
    body[0] = version;
    body[1] = type;
    put_u16(body + 2, s.host_seq++);
    memcpy(body + 4, payload, n);
    put_u16(body + 4 + n, amp_crc16(body, 4 + n));
    size_t length = amp_cobs_encode(body, n + AMP_MIN_BODY, line);
    line[length++] = 0;
    switch (below(16)) {
    case 0: line[below((uint32_t)length - 1u)] ^= (uint8_t)(1u + below(255)); break;
    case 1: line[below((uint32_t)length - 1u)] = 0; break;
    case 2: length = 1u + below((uint32_t)length); break;
    default: break;
    }
    amp_receive(&s.amp, line, length, now_us);
}

static uint32_t host_next; /* the index after the last ENVELOPE sent in order */

static uint32_t random_index(void) {
    switch (below(8)) {
    case 6: case 7: return host_next;
    case 0: return s.amp.play_index + below(AMP_BUFFER_SAMPLES + 64u) - 32u;
    case 1: return 0xFFFFFFFFu - below(300);
    case 2: return below(300);
    case 3: return rng() ^ (rng() << 16);
    default: return s.amp.play_index + below(600);
    }
}

static int16_t random_sample(uint32_t pattern) {
    switch (pattern) {
    case 0: return -32768;
    case 1: return 0x7FFF;
    case 2: return 0;
    default: return (int16_t)rng();
    }
}

static void random_frame(void) {
    uint8_t p[LONGEST_PAYLOAD];
    uint32_t low = s.amp.carrier_min_mhz, high = s.amp.carrier_max_mhz;
    switch (below(12)) {
    case 0: /* HELLO */
        memset(p, 'h', 12);
        put_u32(p + 12, rng());
        s.host_seq = 0;
        send(AMP_VERSION, MSG_HELLO, p, HELLO_BYTES);
        break;
    case 1: { /* SET_CARRIER at and past the range's ends, or anywhere */
        static const int32_t off[] = { -1, 0, 1 };
        uint32_t mhz = below(3) ? (below(2) ? low : high) + (uint32_t)off[below(3)] : rng();
        if (below(2))
            mhz = low + below(high - low + 1u);
        put_u32(p, mhz);
        send(AMP_VERSION, MSG_SET_CARRIER, p, SET_CARRIER_BYTES);
        break;
    }
    case 2: /* START */
        put_u32(p, below(8) ? (below(2) ? 8000u : 16000u) : rng());
        host_next = random_index();
        put_u32(p + 4, host_next);
        put_u16(p + 8, (uint16_t)below(1101));
        send(AMP_VERSION, MSG_START, p, START_BYTES);
        break;
    case 3: case 4: case 5: case 6: { /* ENVELOPE */
        uint32_t count = below(10) ? 1u + below(AMP_MAX_FRAME_SAMPLES) : AMP_MAX_FRAME_SAMPLES + 1u;
        uint32_t pattern = below(6);
        uint32_t first = random_index();
        put_u32(p, first);
        host_next = first + count;
        for (uint32_t k = 0; k < count; k++)
            put_u16(p + 4 + 2 * k, (uint16_t)random_sample(pattern));
        send(AMP_VERSION, MSG_ENVELOPE, p, 4u + 2u * count);
        break;
    }
    case 7: /* STOP */
        put_u16(p, (uint16_t)(below(2) ? below(60) : rng()));
        send(AMP_VERSION, MSG_STOP, p, STOP_BYTES);
        break;
    case 8:
        send(AMP_VERSION, MSG_KEEPALIVE, p, 0);
        break;
    case 9: { /* a wrong version, an unknown type, a wrong length */
        size_t n = below(40);
        for (size_t i = 0; i < n; i++)
            p[i] = (uint8_t)rng();
        send(below(3) ? AMP_VERSION : (uint8_t)rng(), (uint8_t)(below(2) ? rng() : 1u + below(6)), p, n);
        break;
    }
    default: { /* raw bytes: bad COBS, runs without a 0x00 */
        uint8_t raw[AMP_MAX_ENCODED + 64];
        size_t n = below(sizeof raw);
        for (size_t i = 0; i < n; i++)
            raw[i] = below(8) ? (uint8_t)rng() : 0;
        amp_receive(&s.amp, raw, n, now_us);
        break;
    }
    }
}

/* Time: mostly small steps, sometimes past the watchdog, rarely hours, sometimes backwards. */
static void random_time(void) {
    uint32_t kind = below(100);
    if (kind < 70)
        now_us += below(3000);
    else if (kind < 90)
        now_us += below(120000);
    else if (kind < 92)
        now_us += (uint64_t)(1u + below(3)) * 3600u * 1000000u;
    else
        amp_advance(&s.amp, now_us - (now_us < 100000u ? now_us : below(100000))); /* backwards: ignored */
}

/* The board takes its output in pieces (checked) and gives ADC pairs for it. */
static void take_output(void) {
    static int16_t out[4096], voltage[4096], current[4096];
    size_t n;
    while ((n = amp_synthesize(&s.amp, out, 1u + below(4096))) > 0) {
        for (size_t k = 0; k < n; k++) {
            CHECK(out[k] <= cap_sample && out[k] >= -cap_sample);
            uint32_t kind = below(4);
            voltage[k] = kind == 0 ? 32767 : kind == 1 ? -32767 : kind == 2 ? out[k] : (int16_t)rng();
            current[k] = kind == 0 ? 32767 : kind == 1 ? -32767 : (int16_t)rng();
        }
        samples_checked += n;
        amp_measure(&s.amp, voltage, current, below(4) ? n : below((uint32_t)n + 1u));
    }
}

static void check_step(void) {
    amp_counters_t c = counters_of(&s.amp);
    CHECK(c.state <= AMP_FAULT);
    CHECK(c.envelope_uv <= cap_uv && c.envelope_uv >= -cap_uv);
    uint64_t last_us = amp_last_valid_us(&s.amp);
    if (last_us != UINT64_MAX && s.amp.now_us > last_us + WATCHDOG_US + 125u) /* a sample every 125 us at most */
        CHECK_EQ(c.envelope_uv, 0);
    CHECK(c.tx_dropped >= previous.tx_dropped);
    if (!hello_seen) {
        CHECK(c.frames_ok >= previous.frames_ok && c.frames_bad >= previous.frames_bad);
        CHECK(c.frames_rejected >= previous.frames_rejected && c.sequence_gaps >= previous.sequence_gaps);
        CHECK(c.underruns >= previous.underruns && c.watchdog_trips >= previous.watchdog_trips);
    }
    hello_seen = 0;
    previous = c;
    steps++;
}

/* A valid stream: a carrier in range, START, then frames in order paced at the rate, the board's
 * output taken as it goes. */
static void stream(void) {
    uint8_t p[4 + 2 * 64];
    uint32_t rate_hz = below(2) ? 8000u : 16000u, frames = 1u + below(40), pattern = below(6);
    put_u32(p, s.amp.carrier_min_mhz + below(s.amp.carrier_max_mhz - s.amp.carrier_min_mhz + 1u));
    send(AMP_VERSION, MSG_SET_CARRIER, p, SET_CARRIER_BYTES);
    host_next = random_index();
    put_u32(p, rate_hz);
    put_u32(p + 4, host_next);
    put_u16(p + 8, (uint16_t)(1u + below(200)));
    send(AMP_VERSION, MSG_START, p, START_BYTES);
    for (uint32_t f = 0; f < frames; f++) {
        put_u32(p, host_next);
        for (uint32_t k = 0; k < 64; k++)
            put_u16(p + 4 + 2 * k, (uint16_t)random_sample(pattern));
        host_next += 64;
        send(AMP_VERSION, MSG_ENVELOPE, p, sizeof p);
        now_us += 64u * 1000000u / rate_hz - 500u + below(1000);
        amp_advance(&s.amp, now_us);
        take_output();
        check_step();
    }
}

static void run_board(const hal_board_t *board) {
    session_init(&s, board, now_us);
    CHECK_EQ(amp_init(&s.amp, board, "RANDOM", now_us), AMP_BOARD_OK);
    amp_set_observer(&s.amp, observe, NULL);
    amp_set_hello_hook(&s.amp, on_hello, NULL);
    cap_uv = (int32_t)(board->max_mv * 1000u);
    cap_sample = (int16_t)(((uint64_t)board->max_mv * 32767u * 2u + board->full_scale_mv) / (2u * board->full_scale_mv));
    previous = counters_of(&s.amp);
    for (uint32_t step = 0; step < STEPS_PER_BOARD; step++) {
        uint32_t kind = below(11);
        if (kind < 6)
            random_frame();
        else if (kind == 10)
            stream();
        else if (kind == 6)
            amp_fault(&s.amp, (uint8_t)(below(4) ? 0 : rng()), now_us);
        else if (kind == 7)
            random_time();
        else
            now_us += below(2000);
        amp_advance(&s.amp, now_us);
        if (amp_take_output_cut(&s.amp) || below(2))
            take_output();
        if (below(3) == 0)
            take_sent(&s);
        check_step();
    }
}

void test_random(void) {
    /* output rates 0 / 192 / 384 / 400 kHz, measures 0 / 7, full scales and clamps at their ends */
    static const hal_board_t boards[] = {
        { "r0", 0u, 125000u, 100000u, 10000000u, 80000000u, 0u, 0u, 0u, 0u },
        { "r192", 192000u, 125000u, 100000u, 10000000u, 80000000u, 2000u, 7u, 5000u, 1000u },
        { "r192-0", 192000u, 49477u, 24738u, 10000000u, 80000000u, 0u, 0u, 0u, 0u },
        { "r384", 384000u, 1000000u, 1000000u, 10000000u, 80000000u, 1u, 7u, 0xFFFFFFFFu, 0xFFFFFFFFu },
        { "r400", 400000u, 49477u, 40000u, 10000000u, 80000000u, 100u, 7u, 1662u, 5035u },
        { "r400-1", 400000u, 1u, 1u, 1u, 0xFFFFFFFFu, 0u, 0u, 0u, 0u },
    };
    clock_t start = clock();
    rng_state = SEED;
    now_us = 1000;
    steps = samples_checked = events_checked = 0;
    for (size_t b = 0; b < sizeof boards / sizeof *boards; b++)
        run_board(&boards[b]);
    printf("  random: %lu steps on %zu boards, %lu envelope events and %lu output samples checked (%.2f s)\n", steps,
           sizeof boards / sizeof *boards, events_checked, samples_checked,
           (double)(clock() - start) / CLOCKS_PER_SEC);
}
