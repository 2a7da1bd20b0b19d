/*
 * line.h - what the firmware receives from the pty, after the fault plan's line faults
 * (--fault drop, corrupt, delay, stall: as amp emulate's FaultPlan) and a disconnect.
 */
#ifndef TPAD_HOST_LINE_H
#define TPAD_HOST_LINE_H

#include <stddef.h>
#include <stdint.h>

#include "options.h"
#include "pty.h"

/* Most received bytes held back by a delay fault (then the newest are dropped, as by a full UART). */
#define LINE_MAX_DELAYED_BYTES (1u << 20)
#define LINE_MAX_DELAYED_CHUNKS 8192u

typedef struct {
    pty_t *pty;
    const options_t *plan;
    uint64_t rng;                          /* splitmix64 state (--seed) */
    uint64_t disconnect_us;                /* UINT64_MAX: none */
    /* the delay fault's queue: chunks of bytes, each released at its time */
    uint8_t bytes[LINE_MAX_DELAYED_BYTES];
    uint32_t bytes_head, bytes_tail;       /* free-running */
    struct { uint64_t release_us; uint32_t length; } chunks[LINE_MAX_DELAYED_CHUNKS];
    uint32_t chunks_head, chunks_tail;     /* free-running */
    uint64_t last_rx_us;                   /* when bytes last came from the host; UINT64_MAX: never */
} line_t;

void line_init(line_t *line, pty_t *pty, const options_t *plan);

/* Up to `cap` bytes the firmware receives at `now_us` (board us since the start). */
size_t line_read(line_t *line, uint8_t *data, size_t cap, uint64_t now_us);

/* Whether the pty is read at `now_us` (open and not in a stall). */
int line_reading(const line_t *line, uint64_t now_us);

/* The next time after `now_us` at which the line changes by itself (delayed bytes due, a stall's
 * edge, the disconnect); UINT64_MAX: none. */
uint64_t line_next_event_us(const line_t *line, uint64_t now_us);

/* Whether the disconnect fault's time has come (the port is then closed). */
int line_disconnected(const line_t *line, uint64_t now_us);

#endif /* TPAD_HOST_LINE_H */
