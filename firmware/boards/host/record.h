/*
 * record.h - tpad-amp --record: the applied envelope and the output over time, as CSV
 * (tpad-amp --help lists the columns), written to a temporary file beside FILE and renamed
 * to FILE at the end (whole or not at all).
 */
#ifndef TPAD_HOST_RECORD_H
#define TPAD_HOST_RECORD_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "amp.h"

/* Most rows kept: 10 minutes at 16 kHz (as amp emulate). */
#define RECORD_MAX_ROWS (10u * 60u * 16000u)
/* Rows waiting for their output samples (an envelope sample's come after it is applied). */
#define RECORD_PENDING 4096u

typedef struct {
    uint8_t event;          /* 0 sample, 1 watchdog trip */
    uint8_t state;
    int64_t index;
    double t_s, envelope_v, carrier_hz, last_frame_s;
    uint32_t outputs_needed, outputs;  /* output samples of this envelope sample: needed, seen */
    double peak_v, sum_a2;
} record_row_t;

typedef struct {
    FILE *file;             /* NULL: not recording */
    char path[4096], temp[4200];
    uint32_t output_rate_hz;
    uint64_t rows;
    int truncated;
    record_row_t pending[RECORD_PENDING];
    uint32_t head, tail;    /* free-running */
} record_t;

/* Start recording to `path` (NULL: no recording). 0, or -1 with one line in `error` when it cannot be
 * written (nothing is left behind). */
int record_open(record_t *record, const char *path, uint32_t output_rate_hz, char *error, size_t error_size);

/* An observer event; `last_frame_s`: when the last valid frame arrived (s; -1: none yet). */
void record_event(record_t *record, const amp_event_t *event, double last_frame_s);

/* One output sample the output stage made: its voltage (V) and the mean series current over it (A). */
void record_output(record_t *record, double output_v, double current_a);

/* Give the recording up: the temporary file is removed. */
void record_abandon(record_t *record);

/* Write what is pending and put the file in place: 0, or -1 with one line in `error`. */
int record_close(record_t *record, char *error, size_t error_size);

#endif /* TPAD_HOST_RECORD_H */
