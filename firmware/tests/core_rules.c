/* core_rules.c - the numbered rules A1-A8 on exact times, the ramps, faults, the transmit queue. */
#include <string.h>

#include "core_check.h"

static session_t s;
static recorder_t r;

#define T0 1000u /* HELLO, START and the first samples (us); the clock's sample n is due at T0 + 62.5 n */

/* Exact due time of clock sample n at 16 kHz, in half microseconds. */
static uint64_t due_half_us(uint64_t n) {
    return 2u * T0 + n * 125u;
}
static uint64_t event_half_us(const amp_event_t *e) {
    return 2u * e->t_us + (e->t_rem != 0);
}

static void running_with(int16_t value, size_t samples) {
    static int16_t buffer[1024];
    session_init(&s, &test_board, 0);
    r.count = 0;
    amp_set_observer(&s.amp, record_event, &r);
    session_running(&s, T0, 0, value);
    for (size_t i = 16; i < samples; i += 256) {
        for (size_t k = 0; k < 256; k++)
            buffer[k] = value;
        host_envelope(&s, (uint32_t)i, buffer, samples - i < 256 ? samples - i : 256, T0);
    }
    take_sent(&s);
}

/* The samples played from the first RUNNING one on (clock sample 1 at T0 + 62.5 us). */
static void test_a1_a2_a3(void) {
    running_with(32767, 64);
    CHECK_EQ(r.count, 1); /* clock sample 0 (PRIMING, at T0) before the ENVELOPE */
    CHECK_EQ(r.events[0].state, AMP_PRIMING);
    CHECK_EQ(r.events[0].index, -1);
    amp_advance(&s.amp, T0 + 70 * 125 / 2);
    CHECK_EQ(r.count, 71);
    int32_t previous = 0;
    for (size_t n = 1; n <= 64; n++) {
        const amp_event_t *e = &r.events[n];
        CHECK_EQ(event_half_us(e), due_half_us(n));
        CHECK_EQ(e->index, (int64_t)n - 1);
        CHECK_EQ(e->state, AMP_RUNNING);
        CHECK_EQ(e->carrier_mhz, 31360000u);
        CHECK(e->envelope_uv <= 100000000); /* A1 */
        CHECK_EQ(e->envelope_uv - previous, n <= 16 ? 6250000 : 0); /* A2: 100 V/ms is 6.25 V a sample */
        previous = e->envelope_uv;
    }
    CHECK_EQ(r.events[16].envelope_uv, 100000000);
    for (size_t n = 65; n <= 70; n++) { /* A3: missing: 0 through A2, one underrun each */
        CHECK_EQ(r.events[n].index, -1);
        CHECK_EQ(r.events[n].envelope_uv, 100000000 - 6250000 * (int32_t)(n - 64));
    }
    amp_counters_t c = counters_of(&s.amp);
    CHECK_EQ(c.underruns, 6);
    CHECK_EQ(c.play_index, 70);
    /* -32768 reads as -32767; negative samples are anti-phase, clamped the same */
    CHECK_EQ(amp_sample_uv(&s.amp, -32768), -125000000);
    CHECK_EQ(amp_sample_uv(&s.amp, 16384), 62501907); /* 16384 / 32767 * 125 V, toward zero */
    CHECK_EQ(amp_sample_uv(&s.amp, -16384), -62501907);
    CHECK_EQ(amp_limit_uv(&s.amp, -200000000), s.amp.output_uv - 6250000);
}

/* A4: the trip at the first sample due 38 ms after the last valid frame; zero 10 ms later. */
static void test_a4_watchdog(void) {
    running_with(8000, 1024); /* 64 ms of samples: the watchdog, not the buffer, ends the stream */
    amp_advance(&s.amp, T0 + 60000);
    size_t trip = 0, zero = 0;
    for (size_t i = 0; i < r.count; i++) {
        if (r.events[i].kind == AMP_EVENT_WATCHDOG_TRIP && !trip)
            trip = i;
        if (trip && !zero && r.events[i].kind == AMP_EVENT_SAMPLE && r.events[i].envelope_uv == 0)
            zero = i;
    }
    CHECK_EQ(event_half_us(&r.events[trip]), 2u * (T0 + 38000u)); /* sample 608 is due exactly then */
    CHECK_EQ(r.events[trip - 1].state, AMP_RUNNING);
    CHECK_EQ(r.events[trip + 1].state, AMP_RAMPING);
    CHECK_EQ(zero, trip + 160); /* R = 10 ms: 160 samples, the last one 0 */
    CHECK_EQ(r.events[zero].state, AMP_IDLE);
    CHECK(event_half_us(&r.events[zero]) <= 2u * (T0 + 50000u)); /* zero within watchdog_ms */
    amp_counters_t c = counters_of(&s.amp);
    CHECK_EQ(c.watchdog_trips, 1);
    CHECK_EQ(c.underruns, 0);
    CHECK_EQ(c.state, AMP_IDLE);
    CHECK_EQ(amp_buffer_fill(&s.amp, c.play_index), 0); /* emptied */
    CHECK(s.amp.rate_hz == 0);                          /* at rest: the clock stopped */
    /* a valid frame (even a rejected one) postpones it; a bad one does not */
    running_with(8000, 1024);
    uint8_t p[2] = { 0 };
    host_send_version(&s, 1, MSG_STOP, p, 2, T0 + 20000);
    uint8_t bad[] = { 0x04, 0x02, 0x06, 0x05, 0x03, 0xfd, 0x25, 0x00 };
    amp_receive(&s.amp, bad, sizeof bad, T0 + 30000);
    CHECK_EQ(counters_of(&s.amp).frames_bad, 1);
    amp_advance(&s.amp, T0 + 57999);
    CHECK_EQ(counters_of(&s.amp).watchdog_trips, 0);
    amp_advance(&s.amp, T0 + 58000);
    CHECK_EQ(counters_of(&s.amp).watchdog_trips, 1);
    /* PRIMING is watched too */
    session_init(&s, &test_board, 0);
    host_hello(&s, 1, 0);
    host_set_carrier(&s, 30000000u, 0);
    host_start(&s, 8000, 0, 10, 100);
    amp_advance(&s.amp, 100 + 37999);
    CHECK_EQ(counters_of(&s.amp).watchdog_trips, 0);
    amp_advance(&s.amp, 100 + 38000);
    CHECK_EQ(counters_of(&s.amp).watchdog_trips, 1);
    /* amp_stop_output: the same ramp, no trip */
    running_with(8000, 1024);
    amp_stop_output(&s.amp, T0 + 1000);
    CHECK_EQ(s.amp.state, AMP_RAMPING);
    amp_advance(&s.amp, T0 + 1000 + 10000);
    CHECK_EQ(counters_of(&s.amp).state, AMP_IDLE);
    CHECK_EQ(counters_of(&s.amp).envelope_uv, 0);
    CHECK_EQ(counters_of(&s.amp).watchdog_trips, 0);
}

/* A6: a fault ramps to 0 within 1 ms, STATUS at once, FAULT until HELLO. */
static void test_a6_faults(void) {
    running_with(32767, 1024);
    amp_advance(&s.amp, T0 + 2000);
    take_sent(&s);
    size_t before = r.count;
    amp_fault(&s.amp, AMP_FAULT_SUPPLY | 0x70, T0 + 2000); /* unknown bits are ignored */
    take_sent(&s);
    CHECK_EQ(s.sent_count, 1);
    CHECK_EQ(s.sent[0].type, MSG_STATUS);
    CHECK_EQ(get_u32(s.sent[0].payload), T0 + 2000);
    CHECK_EQ(s.sent[0].payload[10], AMP_FAULT);
    CHECK_EQ(s.sent[0].payload[11], AMP_FAULT_SUPPLY);
    CHECK_EQ((int32_t)get_u32(s.sent[0].payload + 40), 100000); /* mV, still applied */
    amp_advance(&s.amp, T0 + 3000);
    CHECK_EQ(r.count - before, 16);
    for (size_t i = before; i < r.count; i++) {
        CHECK_EQ(r.events[i].state, AMP_FAULT);
        CHECK_EQ(r.events[i].envelope_uv, 100000000 - 6250000 * (int32_t)(i - before + 1));
    }
    CHECK_EQ(counters_of(&s.amp).envelope_uv, 0);
    amp_fault(&s.amp, AMP_FAULT_SUPPLY, T0 + 3100); /* not new: no STATUS */
    amp_fault(&s.amp, 0, T0 + 3100);
    take_sent(&s);
    CHECK_EQ(count_sent(&s, MSG_STATUS), 0);
    amp_fault(&s.amp, AMP_FAULT_OVERVOLTAGE, T0 + 3200);
    take_sent(&s);
    CHECK_EQ(count_sent(&s, MSG_STATUS), 1);
    CHECK_EQ(s.sent[0].payload[11], AMP_FAULT_SUPPLY | AMP_FAULT_OVERVOLTAGE);
    host_hello(&s, 3, T0 + 4000);
    CHECK_EQ(counters_of(&s.amp).faults, 0);
    CHECK_EQ(counters_of(&s.amp).state, AMP_IDLE);
    /* at rest a fault goes straight to FAULT */
    session_init(&s, &test_board, 0);
    amp_fault(&s.amp, AMP_FAULT_OVERCURRENT, 10);
    CHECK_EQ(s.amp.state, AMP_FAULT);
}

/* A8: STATUS every 5 ms whatever the host does; one more than 100 ms late is skipped. */
static void test_a8_status(void) {
    session_init(&s, &test_board, 0);
    host_hello(&s, 1, 0);
    take_sent(&s);
    amp_advance(&s.amp, 1000000);
    take_sent(&s);
    CHECK_EQ(count_sent(&s, MSG_STATUS), 21); /* 900 ms .. 1000 ms */
    CHECK_EQ(get_u32(s.sent[0].payload), 900000);
    CHECK_EQ(get_u32(s.sent[20].payload), 1000000);
    CHECK_EQ(amp_next_due_us(&s.amp), 1005000);
    /* the time field wraps with the clock */
    session_init(&s, &test_board, 0);
    host_hello(&s, 1, 0xFFFFF000u);
    amp_advance(&s.amp, (uint64_t)0xFFFFF000u + 5000u);
    take_sent(&s);
    CHECK_EQ(s.sent[1].type, MSG_STATUS);
    CHECK_EQ(get_u32(s.sent[1].payload), 0x388u);
}

/* STATUS's fields while RUNNING. */
static void test_status_fields(void) {
    running_with(3277, 32);
    amp_advance(&s.amp, 6000);
    take_sent(&s);
    CHECK_EQ(s.sent_count, 1);
    const uint8_t *p = s.sent[0].payload;
    CHECK_EQ(get_u32(p), 6000);
    CHECK_EQ(get_u32(p + 4), 80); /* 80 samples due by 6 ms after the PRIMING one; 32 were buffered */
    CHECK_EQ(get_u16(p + 8), 0);
    CHECK_EQ(p[10], AMP_RUNNING);
    CHECK_EQ(get_u32(p + 12), 5);  /* HELLO, SET_CARRIER, START, 2 ENVELOPE */
    CHECK_EQ(get_u32(p + 28), 48); /* underruns */
    CHECK_EQ(get_u16(p + 36), 4);
    CHECK_EQ((int32_t)get_u32(p + 40), 0);
    CHECK_EQ(get_u32(p + 52), 31360000u);
    running_with(3277, 512);
    amp_advance(&s.amp, T0 + 1000); /* 16 samples played */
    amp_send_status(&s.amp, 0);
    take_sent(&s);
    CHECK_EQ(get_u16(s.sent[0].payload + 8), 512 - 16);
    CHECK_EQ((int32_t)get_u32(s.sent[0].payload + 40), 12501); /* 3277 / 32767 * 125 V, in mV */
}

/* STOP: ACK at once, a ramp of min(ramp_ms, 50) ms, start * (1 - k / samples), IDLE. */
static void test_stop(void) {
    running_with(13107, 1024); /* 50 V */
    amp_advance(&s.amp, T0 + 2000);
    int32_t start = counters_of(&s.amp).envelope_uv;
    CHECK_EQ(start, amp_sample_uv(&s.amp, 13107));
    size_t before = r.count;
    host_stop(&s, 5, T0 + 2000);
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_OK);
    CHECK_EQ(s.amp.state, AMP_RAMPING);
    amp_advance(&s.amp, T0 + 8000);
    for (size_t k = 1; k <= 80; k++) {
        double want = start * (1.0 - (double)k / 80.0);
        int32_t got = r.events[before + k - 1].envelope_uv;
        CHECK(got - want < 1.0 && want - got < 1.0);
        CHECK_EQ(r.events[before + k - 1].state, k < 80 ? AMP_RAMPING : AMP_IDLE);
    }
    CHECK(s.amp.rate_hz == 0);
    CHECK_EQ(amp_buffer_fill(&s.amp, counters_of(&s.amp).play_index), 0);
    /* over 50 ms asked: 50 ms */
    running_with(13107, 1024);
    amp_advance(&s.amp, T0 + 2000);
    before = r.count;
    host_stop(&s, 60000, T0 + 2000);
    amp_advance(&s.amp, T0 + 2000 + 49999);
    CHECK_EQ(s.amp.state, AMP_RAMPING);
    amp_advance(&s.amp, T0 + 2000 + 50000);
    CHECK_EQ(s.amp.state, AMP_IDLE);
    CHECK_EQ(r.count - before, 800);
    /* 0 ms: one sample, then the rest through A2 (0 at rest) */
    running_with(32767, 1024);
    amp_advance(&s.amp, T0 + 2000);
    before = r.count;
    host_stop(&s, 0, T0 + 2000);
    amp_advance(&s.amp, T0 + 4000);
    CHECK_EQ(r.events[before].state, AMP_IDLE);
    CHECK_EQ(r.events[before].envelope_uv, 100000000 - 6250000);
    CHECK_EQ(r.events[before + 15].envelope_uv, 0);
    CHECK_EQ(counters_of(&s.amp).envelope_uv, 0);
}

/* HELLO: the ramp on the old carrier, then IDLE; counters, seq and the queue start again. */
static void test_hello_ramp(void) {
    running_with(13107, 1024);
    amp_advance(&s.amp, T0 + 3000);
    size_t before = r.count;
    host_hello(&s, 9, T0 + 3000);
    take_sent(&s);
    CHECK_EQ(s.sent_count, 1);
    CHECK_EQ(s.sent[0].type, MSG_INFO);
    CHECK_EQ(counters_of(&s.amp).carrier_mhz, 31360000u); /* still made during the ramp */
    amp_advance(&s.amp, T0 + 3000 + 20000); /* the ramp, then 0 until this advance (the clock then stops) */
    CHECK_EQ(r.count - before, 320);
    CHECK_EQ(r.events[before + 158].state, AMP_RAMPING);
    CHECK_EQ(r.events[before + 159].state, AMP_IDLE);
    CHECK_EQ(r.events[before + 159].carrier_mhz, 31360000u);
    CHECK_EQ(r.events[before + 159].envelope_uv, 0);
    CHECK_EQ(r.events[before + 160].carrier_mhz, 0);
    CHECK_EQ(amp_next_due_us(&s.amp), 29000); /* only STATUS: the clock stopped */
    CHECK_EQ(counters_of(&s.amp).carrier_mhz, 0);
    CHECK_EQ(counters_of(&s.amp).frames_ok, 1);
    /* START needs a new carrier */
    host_start(&s, 16000, 0, 1, T0 + 30000);
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_NO_CARRIER);
}

/* START while RUNNING restarts the stream: held output during PRIMING, same clock anchor. */
static void test_restart(void) {
    running_with(13107, 1024);
    amp_advance(&s.amp, T0 + 1000);
    host_start(&s, 16000, 5000, 2, T0 + 1000);
    size_t before = r.count;
    amp_advance(&s.amp, T0 + 1250);
    CHECK_EQ(r.count - before, 4);
    CHECK_EQ(r.events[before].state, AMP_PRIMING);
    CHECK_EQ(r.events[before].envelope_uv, amp_sample_uv(&s.amp, 13107));
    CHECK_EQ(event_half_us(&r.events[before]), due_half_us(17));
    int16_t two[2] = { 0, 0 };
    host_envelope(&s, 5000, two, 2, T0 + 1250);
    amp_advance(&s.amp, T0 + 1250 + 63);
    CHECK_EQ(r.events[r.count - 1].index, 5000);
    CHECK_EQ(r.events[r.count - 1].envelope_uv, amp_sample_uv(&s.amp, 13107) - 6250000);
    /* another rate: a new anchor at the START */
    host_start(&s, 8000, 0, 2, 5001);
    CHECK_EQ(amp_next_due_us(&s.amp), 5001);
    CHECK_EQ(s.amp.slew_step_uv, 12500000);
}

/* The ramp's integer steps against start * (1 - done / samples). */
static void test_ramp_exact(void) {
    static const int32_t starts[] = { 100000000, -99999999, 7, -1, 123456789, 0 };
    static const uint32_t ms[] = { 1, 5, 10, 50 };
    session_init(&s, &test_board, 0);
    amp_clock_start(&s.amp, 0, 16000);
    for (size_t i = 0; i < sizeof starts / sizeof *starts; i++)
        for (size_t j = 0; j < 4; j++) {
            s.amp.output_uv = starts[i];
            amp_ramp_begin(&s.amp, ms[j], AMP_RAMPING, AMP_IDLE);
            for (uint32_t done = 1; done <= s.amp.ramp_samples; done++) {
                double want = starts[i] * (1.0 - (double)done / s.amp.ramp_samples);
                int32_t got = amp_ramp_next_uv(&s.amp);
                CHECK(got - want < 1.0 && want - got < 1.0);
            }
        }
}

static unsigned hello_hooks;
static size_t queued_at_hook;
static void on_hello_hook(void *ctx) {
    hello_hooks++;
    queued_at_hook = ((amp_t *)ctx)->tx_head - ((amp_t *)ctx)->tx_tail;
}

/* The board's HELLO hook runs after the core dropped its queue, before INFO; the watchdog's reference. */
static void test_hello_hook(void) {
    session_init(&s, &test_board, 0);
    CHECK_EQ(amp_last_valid_us(&s.amp), UINT64_MAX);
    amp_set_hello_hook(&s.amp, on_hello_hook, &s.amp);
    hello_hooks = 0;
    host_hello(&s, 1, 700);
    CHECK_EQ(hello_hooks, 1);
    CHECK_EQ(queued_at_hook, 0);
    CHECK_EQ(amp_last_valid_us(&s.amp), 700);
    host_send(&s, MSG_KEEPALIVE, NULL, 0, 900);
    CHECK_EQ(amp_last_valid_us(&s.amp), 900);
    const uint8_t bad[] = { 0x02, 0x55, 0x00 };
    amp_receive(&s.amp, bad, sizeof bad, 1000); /* a bad frame is not a valid one */
    CHECK_EQ(amp_last_valid_us(&s.amp), 900);
    take_sent(&s);
    CHECK_EQ(count_sent(&s, MSG_INFO), 1);
}

/* Indices play on across 2**32 (the buffer's slots run on: the size divides 2**32). */
static void test_index_wrap(void) {
    session_init(&s, &test_board, 0);
    r.count = 0;
    amp_set_observer(&s.amp, record_event, &r);
    session_running(&s, T0, 0xFFFFFFF8u, 1000);
    int16_t more[16];
    for (int i = 0; i < 16; i++)
        more[i] = (int16_t)(2000 + i);
    host_envelope(&s, 8, more, 16, T0); /* 0xFFFFFFF8 + 16 is 8 */
    amp_advance(&s.amp, T0 + 32 * 125 / 2);
    CHECK_EQ(r.count, 33);
    for (uint32_t n = 1; n <= 32; n++)
        CHECK_EQ(r.events[n].index, (int64_t)(uint32_t)(0xFFFFFFF8u + n - 1u));
    CHECK_EQ(r.events[32].envelope_uv, amp_sample_uv(&s.amp, 2015));
    CHECK_EQ(counters_of(&s.amp).underruns, 0);
    CHECK_EQ(counters_of(&s.amp).play_index, 24);
}

/* The queue for the host is bounded: a host that never reads loses whole frames, counted. */
static void test_tx_queue(void) {
    session_init(&s, &test_board, 0);
    host_hello(&s, 1, 0);
    uint8_t part[3];
    CHECK_EQ(amp_transmit(&s.amp, part, 3), 3); /* the host has part of INFO */
    for (uint64_t t = 0; t <= 300000; t += 50000)
        amp_advance(&s.amp, t); /* 60 STATUS of 65 bytes: 2 KB holds 29 after INFO */
    amp_counters_t c = counters_of(&s.amp);
    CHECK(c.tx_dropped > 20);
    CHECK(s.amp.tx_head - s.amp.tx_tail <= AMP_TX_BYTES);
    host_hello(&s, 2, 300000); /* the cut INFO is ended by a 0x00, then the new INFO */
    uint8_t first;
    CHECK_EQ(amp_transmit(&s.amp, &first, 1), 1);
    CHECK_EQ(first, 0);
    take_sent(&s);
    CHECK_EQ(s.sent_count, 1);
    CHECK_EQ(get_u32(s.sent[0].payload + 84), 2);
    CHECK_EQ(counters_of(&s.amp).tx_dropped, c.tx_dropped);
}

/* A jump of an hour (a board stopped, then resumed): the watchdog's ramp, then the clock stops at the
 * first 4096th sample at rest (the emulator's batch), not after an hour of samples at rest. */
static void test_hour_jump(void) {
    running_with(8000, 1024);
    size_t before = r.count;
    uint64_t hour_us = 3600ull * 1000000u;
    amp_advance(&s.amp, T0 + hour_us);
    CHECK_EQ(r.count - before, 4096 + 1); /* and the trip */
    CHECK_EQ(counters_of(&s.amp).watchdog_trips, 1);
    CHECK_EQ(counters_of(&s.amp).state, AMP_IDLE);
    CHECK_EQ(r.events[r.count - 1].envelope_uv, 0);
    CHECK_EQ(amp_next_due_us(&s.amp) > T0 + hour_us, 1); /* only STATUS: the clock stopped */
    size_t after = r.count;
    amp_advance(&s.amp, T0 + 2 * hour_us);
    CHECK_EQ(r.count, after);
}

void test_rules(void) {
    test_a1_a2_a3();
    test_a4_watchdog();
    test_a6_faults();
    test_a8_status();
    test_status_fields();
    test_stop();
    test_hello_ramp();
    test_restart();
    test_ramp_exact();
    test_tx_queue();
    test_hello_hook();
    test_index_wrap();
    test_hour_jump();
}
