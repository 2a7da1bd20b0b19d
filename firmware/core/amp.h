/*
 * amp.h - the portable amplifier core: docs/amp-protocol.md version 2 on a board's hal.h.
 *
 * The core holds the protocol (COBS, CRC-16, the state machine, rules A1-A8), the envelope
 * buffer, the carrier synthesis and the measurement. It never reads a clock: every call that
 * depends on time takes `now_us`, the board's microseconds (hal_time_us), which must never go
 * back (an earlier time is taken as the latest one seen). It allocates nothing: a board keeps
 * one amp_t in static storage. Nothing here blocks or prints.
 *
 * Choices the document leaves open are those of tpad_rt/amp/emulator.py (its docstring lists
 * them); the conformance suite runs both side by side on a virtual clock:
 * - the envelope sample clock: sample n is due at anchor + n / envelope_hz (exact rational
 *   microseconds, no drift), anchored at the START that found the clock stopped; the clock
 *   stops when the output is at rest (0, IDLE or FAULT, no ramp) at the end of a call and at every
 *   4096th sample one call plays (the emulator's batch: a jump of hours plays at most 4096 samples
 *   at rest). The emulator also runs its clock on while its simulated plate rings: give it a quiet
 *   plate to compare anchors exactly;
 * - due samples and STATUS are made in time order (a sample first on a tie) by every call
 *   taking now_us, before that call's own work (a frame received at t acts after the samples
 *   due up to t);
 * - the watchdog (A4) trips at the first sample due (watchdog_ms - R) ms - 2 ms after the last
 *   valid frame (R = 10 ms ramp, 2 ms the emulator's read allowance);
 * - ramps (HELLO's, STOP's, A4's, A6's) are start * (1 - done / samples) over
 *   max(1, ramp_ms * envelope_hz / 1000) samples, through A1 and A2 like any sample;
 * - the output is held during PRIMING; at rest (IDLE, FAULT) it goes to 0 through A2 (the emulator
 *   does the same: after a STOP ramp shorter than the slew allows, too);
 * - STATUS every status_period_ms on whole microseconds counted from amp_init's now_us,
 *   restarted by HELLO; one more than 100 ms overdue is skipped, not sent late.
 *
 * Units are in every name: _us microseconds, _uv microvolts (the applied envelope, int32),
 * _mv millivolts, _mhz millihertz, _hz hertz. Output and ADC samples: int16, full scale +-32767.
 */
#ifndef TPAD_AMP_AMP_H
#define TPAD_AMP_AMP_H

#include <stddef.h>
#include <stdint.h>

#include "hal.h"

/* --- what this amplifier says in INFO (section 3.2) --- */
#define AMP_VERSION 2                /* protocol version (body byte 0) */
#define AMP_FIRMWARE "tpad-amp 1.0"  /* INFO's firmware string */
#define AMP_BUFFER_SAMPLES 1024u     /* envelope buffer (a power of two: divides 2**32) */
#define AMP_MAX_FRAME_SAMPLES 256u   /* most samples in one ENVELOPE */
#define AMP_WATCHDOG_MS 50u          /* A4: last valid frame to zero output */
#define AMP_RAMP_MS 10u              /* A4's R: the amplifier's own ramp (HELLO's too) */
#define AMP_FAULT_RAMP_MS 1u         /* A6: a fault ramps to 0 within this */
#define AMP_MAX_STOP_RAMP_MS 50u     /* STOP's longest ramp */
#define AMP_READ_ALLOWANCE_US 2000u  /* the watchdog trips this early (the emulator's READ_LATENCY_S) */
#define AMP_STATUS_PERIOD_MS 5u      /* A8 */
#define AMP_MAX_STATUS_LAG_US 100000u /* a periodic STATUS later than this is skipped */
#define AMP_MIN_SLEW_MV_PER_MS 100000u /* A2: slew = max(this, max_mv) mV per ms */
#define AMP_CARRIER_STEP_MHZ 10u     /* the carrier step (INFO's carrier_step_mhz) */
#define AMP_MAX_OUTPUT_RATE_HZ 4000000u /* hal.h's output_rate_hz: at most this (250 outputs per sample) */
#define AMP_MAX_FULL_SCALE_MV 1000000u  /* hal.h's full_scale_mv: 1000 V (microvolt sums stay in int32) */

/* amp_init's answer: the board's constants are within hal.h's ranges, or the first that is not. */
enum { AMP_BOARD_OK = 0, AMP_BOARD_OUTPUT_RATE = 1, AMP_BOARD_FULL_SCALE = 2, AMP_BOARD_MAX_MV = 3,
       AMP_BOARD_MEASURES = 4, AMP_BOARD_CARRIERS = 5 };

/* --- the wire (sections 2.1, 2.2) --- */
#define AMP_MAX_BODY 522u                                       /* an ENVELOPE of 256 samples */
#define AMP_MIN_BODY 6u                                         /* header and CRC */
#define AMP_MAX_ENCODED (AMP_MAX_BODY + AMP_MAX_BODY / 254u + 2u) /* longest run without 0x00 */

/* --- the core's own storage (a board may lower these with -D, each a power of two; a board with
 * no carrier and no ADC, as the microbit, needs only -DAMP_SYNTH_QUEUE=1 -DAMP_MEASURE_RING=1:
 * amp_t is then about 5 KB) --- */
#ifndef AMP_TX_BYTES
#define AMP_TX_BYTES 2048u     /* bytes queued for the host (a STATUS burst after a 100 ms stall
                                * fits); a frame that does not fit is dropped, counted */
#endif
#ifndef AMP_SYNTH_QUEUE
#define AMP_SYNTH_QUEUE 128u   /* envelope samples played, not yet synthesised */
#endif
#ifndef AMP_MEASURE_RING
#define AMP_MEASURE_RING 1024u /* phases of output samples written, not yet measured */
#endif

/* STATUS's states and fault bits (section 3.2); ACK codes. */
enum { AMP_IDLE = 0, AMP_PRIMING = 1, AMP_RUNNING = 2, AMP_RAMPING = 3, AMP_FAULT = 4 };
enum { AMP_FAULT_OVERCURRENT = 1, AMP_FAULT_OVERVOLTAGE = 2, AMP_FAULT_OVERTEMPERATURE = 4,
       AMP_FAULT_SUPPLY = 8 };
enum { AMP_OK = 0, AMP_BAD_VERSION = 1, AMP_UNKNOWN_TYPE = 2, AMP_BAD_LENGTH = 3,
       AMP_OUT_OF_RANGE = 4, AMP_NO_CARRIER = 5, AMP_BAD_RATE = 6, AMP_NOT_STARTED = 7,
       AMP_OUT_OF_WINDOW = 8, AMP_CODE_FAULT = 9 };

/* amp_counters(): STATUS's counters since the last HELLO, and the present output. */
typedef struct {
    uint32_t frames_ok, frames_bad, frames_rejected, sequence_gaps, underruns, watchdog_trips;
    uint8_t faults;       /* latched fault bits */
    uint8_t state;        /* AMP_IDLE .. AMP_FAULT */
    int32_t envelope_uv;  /* the envelope applied now, after A1 and A2 */
    uint32_t carrier_mhz; /* the carrier being made, 0 if none */
    uint32_t play_index;  /* stream index of the next sample to play */
    uint32_t tx_dropped;  /* frames for the host dropped because the queue was full */
} amp_counters_t;

/* What the observer is told. */
enum { AMP_EVENT_SAMPLE = 0, AMP_EVENT_WATCHDOG_TRIP = 1 };
typedef struct {
    uint8_t kind;         /* AMP_EVENT_SAMPLE or AMP_EVENT_WATCHDOG_TRIP */
    uint8_t state;        /* the state after the sample (SAMPLE) */
    /* when: exactly t_us + t_rem / rate_hz microseconds (the sample's due time) */
    uint64_t t_us;
    uint32_t t_rem;
    uint32_t rate_hz;     /* the envelope rate (SAMPLE and WATCHDOG_TRIP) */
    int32_t envelope_uv;  /* applied, after A1 and A2 */
    uint32_t carrier_mhz; /* the carrier it modulates (0: none) */
    int64_t index;        /* the stream index it came from; -1 when none (held, ramp, underrun) */
} amp_event_t;
typedef void (*amp_observer_t)(void *ctx, const amp_event_t *event);

/* One played envelope sample waiting for synthesis. */
typedef struct {
    int32_t peak_lsb;       /* the output sample at the sine's peak: envelope / full scale * 32767, rounded */
    uint32_t carrier_mhz;
    uint32_t outputs;       /* output samples it makes: output_rate_hz / envelope_hz */
} amp_played_t;

/* The full state. Boards allocate it statically and touch it only through the functions below. */
typedef struct amp {
    /* the board (amp_init's copy: the refused board's in place of one out of range) and what INFO says */
    const hal_board_t *board;
    hal_board_t board_used;
    char serial[16];
    uint32_t carrier_min_mhz, carrier_max_mhz, carrier_step_mhz;
    uint32_t max_mv, full_scale_uv, max_uv, slew_mv_per_ms;
    /* time */
    uint64_t origin_us;        /* amp_init's now_us: STATUS time_us counts from it */
    uint64_t now_us;           /* latest time seen */
    uint64_t last_valid_us;    /* A4: the last valid frame */
    /* the sample clock (running when rate_hz != 0): sample n due at due_us + due_rem / rate_hz */
    uint32_t rate_hz;
    uint64_t due_us;
    uint32_t due_rem;
    uint32_t period_us, period_rem; /* 1e6 / rate_hz = period_us + period_rem / rate_hz */
    int32_t slew_step_uv;      /* A2, per envelope sample */
    /* protocol state */
    uint8_t state, faults, has_hello, has_last_seq;
    uint16_t last_seq, tx_seq;
    uint32_t carrier_mhz, fading_carrier_mhz;
    uint32_t envelope_hz, play_index;
    uint16_t prefill;
    int32_t output_uv;
    /* the ramp: |start| * done / samples by whole and remainder steps, no per-sample divide */
    uint8_t ramping, ramp_then;
    int32_t ramp_start_uv;
    uint32_t ramp_samples, ramp_done;
    uint32_t ramp_q, ramp_r, ramp_acc_q, ramp_acc_r;
    /* counters */
    amp_counters_t counters;
    /* STATUS schedule (us since origin) */
    uint64_t next_status_us;
    /* the envelope buffer by stream index */
    int16_t buffer[AMP_BUFFER_SAMPLES];
    uint32_t present[AMP_BUFFER_SAMPLES / 32u];
    /* receive splitter */
    uint8_t rx[AMP_MAX_ENCODED];
    uint16_t rx_len;
    uint8_t rx_discarding;
    /* transmit queue (ring) */
    uint8_t tx[AMP_TX_BYTES];
    uint32_t tx_head, tx_tail;   /* bytes written / taken, free-running */
    uint8_t tx_mid_frame;        /* the last byte taken was not a delimiter */
    /* carrier synthesis */
    uint64_t lsb_per_uv_q32;      /* 32767 / full_scale_uv, times 2**32 (rounded down) */
    uint32_t phase;               /* the carrier's phase, cycles * 2**32 */
    uint32_t phase_rem;           /* sub-step remainder, over phase_den */
    uint32_t phase_den;           /* output_rate_hz * 1000 */
    uint32_t inc_carrier_mhz, inc_q, inc_r; /* increment for that carrier: inc_q + inc_r / phase_den */
    amp_played_t played[AMP_SYNTH_QUEUE];
    uint32_t played_head, played_tail, played_done; /* done: output samples made of the tail one */
    uint8_t output_cut;           /* a fault began: the board is to drop its queued output */
    /* measurement */
    uint32_t measure_phase[AMP_MEASURE_RING];
    uint32_t written, measured;   /* output samples synthesised / measured, free-running */
    /* sums over the window: voltage and current times sin and cos (Q15), and the sines' products */
    int64_t sum_vs, sum_vc, sum_is, sum_ic, sum_ss, sum_sc, sum_cc;
    uint32_t window_samples, window_min_samples, window_max_samples, last_measure_phase;
    uint8_t window_open;
    uint32_t voltage_mv_rms, current_ua_rms;
    int16_t phase_cdeg;
    /* the observer */
    amp_observer_t observer;
    void *observer_ctx;
    /* the HELLO hook (amp_set_hello_hook) */
    void (*hello_hook)(void *ctx);
    void *hello_hook_ctx;
} amp_t;

/*
 * The functions. All run to completion in the caller's context (no interrupts, no locks: call them
 * from one thread or the main loop only; an interrupt handler only fills the board's buffers).
 * "What is due" is every envelope sample and periodic STATUS whose time is at or before now_us,
 * made in time order; every call taking now_us makes it first. A typical board: amp_run().
 */

/* Power-up (A7): output 0, IDLE, no carrier, no STATUS before the first HELLO; STATUS time_us
 * counts from `now_us`. Call once, before any other function. `board` (hal_init's) is copied (its
 * name must outlive amp). Returns AMP_BOARD_OK when its constants are within hal.h's ranges; else
 * the first out of range (AMP_BOARD_*; amp_board_problem says it in words), and the core runs a
 * refused board: the protocol answers (INFO: full scale 1 mV, max_mv 0, carriers 0 .. 0, measures 0), but no
 * carrier is made, no ADC pair is taken and every applied envelope is 0 (a clamp of 0 V).
 * `serial` is INFO's serial: up to 15 characters, up to a NUL (a char[16] from
 * hal_serial_number, or a shorter string). */
int amp_init(amp_t *amp, const hal_board_t *board, const char *serial, uint64_t now_us);

/* What amp_init's answer `problem` means: the range the board's constant broke ("within range" for
 * AMP_BOARD_OK). */
const char *amp_board_problem(int problem);

/* `n` bytes from the line (any bytes: every one is validated) arrived at `now_us`. Each frame they
 * complete acts at now_us after what is due up to then, in order; answers are queued for
 * amp_transmit. At most AMP_MAX_ENCODED bytes of an unfinished frame are held. */
void amp_receive(amp_t *amp, const uint8_t *data, size_t n, uint64_t now_us);

/* Make what is due up to `now_us`: envelope samples (A1-A4 applied, queued for amp_synthesize,
 * told to the observer) and periodic STATUS (A8). Call it at least at amp_next_due_us(). */
void amp_advance(amp_t *amp, uint64_t now_us);

/* Hardware fault `bits` (AMP_FAULT_*; others ignored) at `now_us`, after what is due (A6): the
 * applied envelope ramps to 0 within 1 ms, the bits latch until HELLO, a STATUS goes out at once
 * for a new bit, the state is FAULT (START refused) until HELLO; see amp_take_output_cut. */
void amp_fault(amp_t *amp, uint8_t bits, uint64_t now_us);

/* The board is going away (e.g. the host build's SIGTERM): while PRIMING or RUNNING, ramp to 0 over
 * R (10 ms) and go IDLE as the watchdog would, without counting a trip. Keep calling amp_advance
 * until amp_counters' state is IDLE and envelope_uv 0 (amp_next_due_us then only names STATUS). */
void amp_stop_output(amp_t *amp, uint64_t now_us);

/* Take up to `cap` of the bytes queued for the host, in order (whole frames, each ending in 0x00,
 * are queued; they may be taken in any pieces). The queue holds AMP_TX_BYTES: a frame that does
 * not fit is dropped whole and counted (tx_dropped); HELLO drops what was not taken. */
size_t amp_transmit(amp_t *amp, uint8_t *out, size_t cap);

/* Take up to `cap` carrier samples (at output_rate_hz, output_rate_hz / envelope_hz per envelope
 * sample played, the envelope held over them): applied envelope / full scale * sin(2 pi phase) *
 * 32767, rounded. The phase starts at 0 at power-up, advances only while samples are made, and is
 * continuous across samples and carrier changes (A2); it is exact (carrier.c: no drift). Against
 * that double-precision reference the samples are within 1.5 (of 32767; tests/core_carrier.c).
 * A board that takes fewer than are made loses the oldest beyond AMP_SYNTH_QUEUE envelope samples
 * (the phase runs on). Returns 0 when output_rate_hz is 0. */
size_t amp_synthesize(amp_t *amp, int16_t *out, size_t cap);

/* 1 once after a fault began (A6): the board drops the output it has queued (hal_output_off);
 * amp_run does so. From the fault on, amp_synthesize makes the carrier at 0 (the applied envelope,
 * what STATUS and the observer report, still ramps as A6 says). */
int amp_take_output_cut(amp_t *amp);

/* `n` ADC pairs (hal_adc_read's), the k-th taken while the k-th sample amp_synthesize gave
 * played. Synchronous demodulation against each sample's own phase, over windows of whole
 * carrier periods (at least 1 ms): STATUS's voltage_mv_rms, current_ua_rms (through the board's
 * uv/na per lsb), phase_cdeg (current against voltage, +-18000), and the overcurrent trip (A6,
 * rms current above max_current_ma, at the last now_us seen). Pairs whose sample's phase is older
 * than AMP_MEASURE_RING output samples start a new window; pairs for samples never made are
 * ignored. Does nothing when the board's measures is 0. */
void amp_measure(amp_t *amp, const int16_t *voltage, const int16_t *current, size_t n);

/* When the next envelope sample or STATUS is due (board us, rounded up); UINT64_MAX when neither
 * (at rest before the first HELLO). A board sleeps until then or until bytes arrive. */
uint64_t amp_next_due_us(const amp_t *amp);

/* STATUS's counters since the last HELLO, the fault bits, the state, the applied envelope (uV),
 * the carrier made (mHz, 0: none) and play_index; tx_dropped counts from power-up. */
void amp_counters(const amp_t *amp, amp_counters_t *out);

/* `fn(ctx, event)` is called for every applied envelope sample and every watchdog trip, from inside
 * the call that made it (it must not call the core); NULL: none. The host build records with it. */
void amp_set_observer(amp_t *amp, amp_observer_t fn, void *ctx);

/* Called when a HELLO is acted on, after the core dropped what it held for the host and before INFO
 * is queued (NULL: none): a board drops the bytes its line still holds for the host, stale in the
 * new session (the emulator's Port.discard_output). */
void amp_set_hello_hook(amp_t *amp, void (*fn)(void *ctx), void *ctx);

/* When the last valid frame arrived (board us, the now_us it was received at; the watchdog's A4
 * reference); UINT64_MAX before the first. */
uint64_t amp_last_valid_us(const amp_t *amp);

/* sizeof(amp_t), for callers that allocate it without this header (ctypes). */
size_t amp_sizeof(void);

/* hal_board_t's layout, for callers that build one without hal.h (ctypes): the offset and size (bytes)
 * of each of its fields in hal.h's order, up to `cap` of them, into `offsets` and `sizes`; returns
 * sizeof(hal_board_t). */
size_t amp_board_layout(size_t *offsets, size_t *sizes, size_t cap);

/* The main loop on hal.h: hal_init, hal_serial_number, amp_init(hal_time_us()), then forever
 * amp_run_once on a static amp_t (a refused board too: its output stays 0, its INFO says max_mv 0).
 * Never returns. */
void amp_run(void);

/* One pass of amp_run's loop on `amp`: hal_uart_read -> amp_receive (at most 16 reads of 64 bytes,
 * each stamped hal_time_us()), hal_faults -> amp_fault, amp_advance, hal_adc_read -> amp_measure,
 * amp_take_output_cut -> hal_output_off, amp_synthesize -> hal_output_write (up to
 * hal_output_room), amp_transmit -> hal_uart_write (what it does not take stays in `pending`, at
 * most AMP_PENDING_BYTES; the loop never waits for the host), hal_watchdog_kick, then
 * hal_wait(amp_next_due_us). For a board that runs its own loop on the same functions. */
#define AMP_PENDING_BYTES 256u
typedef struct {
    uint8_t bytes[AMP_PENDING_BYTES];
    size_t count;
} amp_pending_t;
void amp_run_once(amp_t *amp, amp_pending_t *pending);

#endif /* TPAD_AMP_AMP_H */
