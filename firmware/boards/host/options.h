/* options.h - tpad-amp's command line (tpad-amp --help), every value checked. */
#ifndef TPAD_HOST_OPTIONS_H
#define TPAD_HOST_OPTIONS_H

#include <stddef.h>
#include <stdint.h>

#define OPTIONS_MAX_REPEATS 64   /* most stall or overcurrent faults */

typedef struct {
    const char *device_path;      /* --device (required) */
    const char *record_path;      /* --record, or NULL */
    double duration_s;            /* --duration; 0: until SIGTERM or SIGINT */
    double force_n;               /* --force-n (default 0.5) */
    uint32_t seed;                /* --seed (default 0) */
    /* --fault: times (s) count from the start */
    double drop_rate, corrupt_rate, delay_s;
    size_t stalls;
    double stall_at_s[OPTIONS_MAX_REPEATS], stall_for_s[OPTIONS_MAX_REPEATS];
    size_t overcurrents;
    double overcurrent_at_s[OPTIONS_MAX_REPEATS];
    double disconnect_at_s;       /* < 0: none */
    int help;                     /* --help given: print the help, nothing else */
} options_t;

/* Parse argv; 0, or -1 with one line (no newline) in `error`. */
int options_parse(int argc, char **argv, options_t *options, char *error, size_t error_size);

/* The text of --help. */
extern const char options_help[];

#endif /* TPAD_HOST_OPTIONS_H */
