/* core_check.h - the core's unit tests: a tiny assert helper and what the test files share. */
#ifndef CORE_CHECK_H
#define CORE_CHECK_H

#include <stdint.h>
#include <stdio.h>

#include "amp_core.h"

extern int check_failures;
void check_fail(const char *file, int line, const char *what, long long got, long long want);

#define CHECK(cond) do { if (!(cond)) check_fail(__FILE__, __LINE__, #cond, 0, 0); } while (0)
#define CHECK_EQ(got, want) do { long long g_ = (long long)(got), w_ = (long long)(want); \
    if (g_ != w_) check_fail(__FILE__, __LINE__, #got " == " #want, g_, w_); } while (0)

/* --- a session with the core, as the host (core_support.c) --- */

/* The test board: 192 kHz output, 125 V full scale, 100 V clamp, carriers 10-80 kHz, measures all. */
extern const hal_board_t test_board;
/* The same without synthesis or measurement (the microbit's kind). */
extern const hal_board_t test_board_protocol;

/* One frame the core sent. */
typedef struct {
    uint8_t version, type;
    uint16_t seq;
    uint8_t payload[AMP_MAX_BODY];
    size_t payload_bytes;
} sent_t;

#define MAX_SENT 256
typedef struct {
    amp_t amp;
    uint16_t host_seq;
    sent_t sent[MAX_SENT];  /* frames taken from amp_transmit since the last take_sent */
    size_t sent_count;
} session_t;

void session_init(session_t *s, const hal_board_t *board, uint64_t now_us);
/* Send a frame of this version at now_us with the next host seq. */
void host_send(session_t *s, uint8_t type, const uint8_t *payload, size_t n, uint64_t now_us);
void host_send_version(session_t *s, uint8_t version, uint8_t type, const uint8_t *payload, size_t n,
                       uint64_t now_us);
void host_hello(session_t *s, uint32_t nonce, uint64_t now_us);
void host_set_carrier(session_t *s, uint32_t carrier_mhz, uint64_t now_us);
void host_start(session_t *s, uint32_t envelope_hz, uint32_t start_index, uint16_t prefill, uint64_t now_us);
void host_envelope(session_t *s, uint32_t first_index, const int16_t *samples, size_t n, uint64_t now_us);
void host_stop(session_t *s, uint16_t ramp_ms, uint64_t now_us);
/* Take what the core queued: decoded into s->sent (replacing what was there). */
void take_sent(session_t *s);
/* The last ACK in s->sent: its code and value; -1 when there is none. */
int last_ack(const session_t *s, uint8_t *acked_type, uint32_t *value);
/* Number of frames of `type` in s->sent. */
size_t count_sent(const session_t *s, uint8_t type);
amp_counters_t counters_of(const amp_t *amp);
/* A session up to RUNNING: HELLO at t0, SET_CARRIER, START 16 kHz from index `start`, prefill 16 and
 * 16 samples of value `value` (all at t0); returns nothing, s->sent cleared. */
void session_running(session_t *s, uint64_t t0_us, uint32_t start, int16_t value);

/* An observer that records the samples (up to MAX_EVENTS) and trips. */
#define MAX_EVENTS 20000
typedef struct {
    amp_event_t events[MAX_EVENTS];
    size_t count;
} recorder_t;
void record_event(void *ctx, const amp_event_t *event);

/* The test files' entry points. */
void test_wire(void);
void test_protocol(void);
void test_rules(void);
void test_carrier(void);
void test_run(void);
void test_board_ranges(void);
void test_random(void);

#endif
