/*
 * amp_core.h - what the core's files share among themselves (not for boards: amp.h is their API).
 */
#ifndef TPAD_AMP_CORE_H
#define TPAD_AMP_CORE_H

#include <stddef.h>
#include <stdint.h>

#include "amp.h"

/* Message types (section 3). */
enum { MSG_HELLO = 0x01, MSG_SET_CARRIER = 0x02, MSG_START = 0x03, MSG_ENVELOPE = 0x04,
       MSG_STOP = 0x05, MSG_KEEPALIVE = 0x06, MSG_INFO = 0x81, MSG_STATUS = 0x82, MSG_ACK = 0x83 };

/* Payload lengths (bytes) of the fixed-length messages; ENVELOPE's header before its samples. */
#define HELLO_BYTES 16u
#define SET_CARRIER_BYTES 4u
#define START_BYTES 10u
#define STOP_BYTES 2u
#define KEEPALIVE_BYTES 0u
#define ENVELOPE_HEADER_BYTES 4u
#define INFO_BYTES 92u
#define STATUS_BYTES 56u
#define ACK_BYTES 8u

/* Little-endian fields (section 2.2). */
static inline void put_u16(uint8_t *p, uint16_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }
static inline void put_u32(uint8_t *p, uint32_t v) {
    put_u16(p, (uint16_t)v);
    put_u16(p + 2, (uint16_t)(v >> 16));
}
static inline uint16_t get_u16(const uint8_t *p) { return (uint16_t)(p[0] | (p[1] << 8)); }
static inline uint32_t get_u32(const uint8_t *p) {
    return (uint32_t)get_u16(p) | ((uint32_t)get_u16(p + 2) << 16);
}

/* crc16.c: CRC-16/IBM-3740 (2.2). */
uint16_t amp_crc16(const uint8_t *data, size_t n);

/* cobs.c (2.1): encode `n` bytes into `out` (room for n + n / 254 + 1), returning its length;
 * decode into `out` (room for `cap`), returning the body's length, or -1 when the encoding is
 * bad (a 0x00, a block past the end) or the body longer than `cap`. */
size_t amp_cobs_encode(const uint8_t *in, size_t n, uint8_t *out);
long amp_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap);

/* frame.c: a candidate frame (the bytes between two 0x00) checked by 2.3 steps 1-2. */
typedef struct {
    uint8_t version, type;
    uint16_t seq;
    const uint8_t *payload; /* into the caller's body buffer */
    size_t payload_bytes;
} amp_frame_t;
/* 0 and `frame` filled (pointing into `body`, AMP_MAX_ENCODED bytes) when valid; -1 when bad. */
int amp_frame_decode(const uint8_t *encoded, size_t n, uint8_t *body, amp_frame_t *frame);
/* The frame for `type` and `payload` (at most AMP_MAX_BODY - 6 bytes) as sent (COBS, 0x00) into `out`
 * (room for AMP_MAX_ENCODED + 1);
 * returns its length. */
size_t amp_frame_encode(uint8_t version, uint8_t type, uint16_t seq, const uint8_t *payload,
                        size_t payload_bytes, uint8_t *out);

/* tx.c: queue a frame for the host with the next seq (dropped whole, and counted, when it does not
 * fit); drop what the host has not taken (ending a frame cut short with a 0x00). */
void amp_send(amp_t *amp, uint8_t type, const uint8_t *payload, size_t payload_bytes);
void amp_tx_discard(amp_t *amp);

/* rx.c: the receive splitter (2.1) feeding amp_on_candidate; NULL encoded: an over-long run. */
void amp_on_candidate(amp_t *amp, const uint8_t *encoded, size_t n);

/* buffer.c: the envelope buffer by stream index (slot index % AMP_BUFFER_SAMPLES). */
void amp_buffer_clear(amp_t *amp);
int amp_buffer_fits(uint32_t first, uint32_t count, uint32_t play_index);
void amp_buffer_put(amp_t *amp, uint32_t first, const uint8_t *samples_le, uint32_t count);
int amp_buffer_take(amp_t *amp, uint32_t index, int16_t *sample);
uint32_t amp_buffer_fill(const amp_t *amp, uint32_t play_index);

/* limit.c: sample value to microvolts, A1 and A2, and the linear ramps. */
int32_t amp_sample_uv(const amp_t *amp, int16_t sample);
int32_t amp_limit_uv(const amp_t *amp, int32_t target_uv);
void amp_ramp_begin(amp_t *amp, uint32_t ramp_ms, uint8_t during, uint8_t then);
int32_t amp_ramp_next_uv(amp_t *amp);

/* play.c: the sample clock, the samples, the STATUS schedule. */
void amp_clock_start(amp_t *amp, uint64_t now_us, uint32_t rate_hz);
uint32_t amp_carrier_made_mhz(const amp_t *amp);

/* messages.c: INFO (echoing `hello_nonce`), STATUS at `time_us` (us since amp_init), ACK of `frame`. */
void amp_send_info(amp_t *amp, uint32_t hello_nonce);
void amp_send_status(amp_t *amp, uint64_t time_us);
void amp_send_ack(amp_t *amp, const amp_frame_t *frame, uint8_t code, uint32_t value);

/* protocol.c: act on a valid frame at amp->now_us. */
void amp_on_frame(amp_t *amp, const amp_frame_t *frame);

/* carrier.c: the phase accumulator and the sine. */
void amp_carrier_init(amp_t *amp);
void amp_carrier_played(amp_t *amp, int32_t envelope_uv, uint32_t carrier_mhz);
void amp_carrier_cut(amp_t *amp); /* a fault: the samples not yet made are made at 0 */
int32_t amp_sine_q15(uint32_t phase);

/* measure.c: the demodulator. */
void amp_measure_reset(amp_t *amp);

/* The sine table (sine_table.c): round(32767 * sin(2 pi i / AMP_SINE_POINTS)), i = 0 .. POINTS. */
#define AMP_SINE_BITS 10
#define AMP_SINE_POINTS (1u << AMP_SINE_BITS)
extern const int16_t amp_sine_table[AMP_SINE_POINTS + 1u];

#endif /* TPAD_AMP_CORE_H */
