/*
 * host.h - the host board: hal.h on Linux (CLOCK_MONOTONIC, a pty, the simulated circuit),
 * set up from tpad-amp's options before the core starts.
 */
#ifndef TPAD_HOST_HOST_H
#define TPAD_HOST_HOST_H

#include <signal.h>
#include <stddef.h>
#include <stdint.h>

#include "amp.h"
#include "options.h"

/* The output (carrier) rate: 24 x 16 kHz, 4.8 samples a cycle at 80 kHz. */
#define HOST_OUTPUT_RATE_HZ 384000u

/* Read the device, set the board's constants and circuit up, check --record's path, open the
 * pty: 0, or -1 with one line in `error` (nothing is left open). hal_wait returns at once while
 * `*stop` is set and `host_serving` is true. */
int host_setup(const options_t *options, volatile sig_atomic_t *stop, char *error, size_t error_size);

/* The pty a host opens. */
const char *host_port_name(void);

/* Whether hal_wait returns early on a stop request (while serving; not while ramping down). */
void host_set_serving(int serving);

/* The observer the core calls (amp_set_observer): the recording. `ctx` is the amp_t. */
void host_observe(void *ctx, const amp_event_t *event);

/* A HELLO was acted on: drop the bytes the host has not read yet. */
void host_discard_output(void);

/* Whether --duration has passed. */
int host_duration_over(uint64_t now_us);

/* Whether the disconnect fault's time has come; closes the pty when it has. */
int host_disconnected(uint64_t now_us);

/* How late (us) hal_wait's latest wake-ups came after the time they were due, the most since the last call. */
uint64_t host_take_late_us(void);

/* End: close the pty, put the recording in place (0, or -1 with one line in `error`). */
int host_finish(char *error, size_t error_size);

#endif /* TPAD_HOST_HOST_H */
