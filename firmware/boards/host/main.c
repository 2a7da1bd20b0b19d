/*
 * main.c - tpad-amp on Linux (tpad-amp --help): the portable core on a pty, its hardware
 * simulated (hal_host.c), until SIGTERM, SIGINT, --duration or a disconnect fault; then the
 * output ramps to 0 and the counters are printed on one line, as amp emulate prints them.
 */
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>

#include "amp.h"
#include "host.h"
#include "options.h"

/* The SCHED_FIFO priority asked for, as amp emulate: a microcontroller that nothing else delays. */
#define REALTIME_PRIORITY 10
/* A pass this late (us) while the output plays is said on stderr, at most once a second (as amp emulate):
 * the firmware's timing was not a microcontroller's. */
#define LATE_PASS_US 20000u
/* After the output is told to stop: the ramp (R) and this much more (ms) at most. */
#define STOP_GRACE_MS 50u

static volatile sig_atomic_t stop_requested;

static void on_signal(int signum)
{
    (void)signum;
    stop_requested = 1;
}

static void stop_signals(void)
{
    struct sigaction action;
    memset(&action, 0, sizeof action);
    action.sa_handler = on_signal; /* no SA_RESTART: poll returns at once */
    sigemptyset(&action.sa_mask);
    sigaction(SIGTERM, &action, NULL);
    sigaction(SIGINT, &action, NULL);
}

static void realtime_priority(void)
{
    struct sched_param param;
    memset(&param, 0, sizeof param);
    param.sched_priority = REALTIME_PRIORITY;
    if (sched_setscheduler(0, SCHED_FIFO, &param) != 0)
        fprintf(stderr, "tpad-amp: no real-time priority here (SCHED_FIFO refused): a busy machine can delay the "
                        "firmware, and frames it reads late count as underruns\n");
}

static amp_t amp;
static amp_pending_t pending;

/* A HELLO (amp_set_hello_hook): what the pty and the loop's pending bytes hold for the host is stale; a
 * 0x00 then ends any frame the host had begun to read, so that INFO arrives whole. */
static void on_hello(void *ctx)
{
    (void)ctx;
    host_discard_output();
    pending.bytes[0] = 0x00;
    pending.count = 1;
}

/* Say on stderr (at most once a second) that the loop woke `late_us` late while the output played. */
static void note_late(uint64_t now_us, uint64_t late_us, uint64_t *noted_us)
{
    amp_counters_t counters;
    amp_counters(&amp, &counters);
    if (late_us <= LATE_PASS_US || counters.state == AMP_IDLE ||
        (*noted_us != UINT64_MAX && now_us < *noted_us + 1000000u))
        return;
    *noted_us = now_us;
    fprintf(stderr, "tpad-amp: the firmware ran %lu ms late (a busy machine?): frames waiting meanwhile were read "
                    "late, and may have let the watchdog trip\n", (unsigned long)(late_us / 1000u));
}

/* Serve until asked to stop; why it ended. */
static const char *serve(void)
{
    uint64_t noted_us = UINT64_MAX; /* when the last note was said: never */
    for (;;) {
        uint64_t now = hal_time_us();
        if (stop_requested)
            return "stopped by a signal";
        if (host_duration_over(now))
            return "ran for --duration";
        if (host_disconnected(now))
            return "disconnected";
        note_late(now, host_take_late_us(), &noted_us);
        amp_run_once(&amp, &pending);
    }
}

/* Ramp to 0 (A4's ramp, no trip counted) and play it out, at most R + STOP_GRACE_MS. */
static void ramp_down(void)
{
    uint64_t now = hal_time_us(), deadline = now + (AMP_RAMP_MS + STOP_GRACE_MS) * 1000u;
    amp_counters_t counters;
    host_set_serving(0);
    amp_stop_output(&amp, now);
    do {
        amp_run_once(&amp, &pending);
        amp_counters(&amp, &counters);
    } while (!((counters.state == AMP_IDLE || counters.state == AMP_FAULT) && counters.envelope_uv == 0) &&
             hal_time_us() < deadline);
}

int main(int argc, char **argv)
{
    static options_t options;
    char error[512], serial[16];
    if (options_parse(argc, argv, &options, error, sizeof error) != 0) {
        fprintf(stderr, "tpad-amp: %s\n", error);
        return 1;
    }
    if (options.help) {
        fputs(options_help, stdout);
        return 0;
    }
    stop_signals();
    if (host_setup(&options, &stop_requested, error, sizeof error) != 0) {
        fprintf(stderr, "tpad-amp: %s\n", error);
        return 1;
    }
    realtime_priority();
    const hal_board_t *board = hal_init();
    hal_serial_number(serial);
    int problem = amp_init(&amp, board, serial, hal_time_us());
    if (problem != AMP_BOARD_OK) { /* the device file's figures make a board the core refuses */
        fprintf(stderr, "tpad-amp: %s: the amplifier it makes is out of range: %s\n", options.device_path,
                amp_board_problem(problem));
        host_finish(error, sizeof error);
        return 1;
    }
    amp_set_observer(&amp, host_observe, &amp);
    amp_set_hello_hook(&amp, on_hello, NULL);
    printf("amplifier on %s\n", host_port_name());
    fflush(stdout);
    const char *ending = serve();
    ramp_down();
    amp_counters_t counters;
    amp_counters(&amp, &counters);
    int status = host_finish(error, sizeof error);
    printf("tpad-amp %s: frames_ok=%lu frames_bad=%lu frames_rejected=%lu sequence_gaps=%lu underruns=%lu "
           "watchdog_trips=%lu faults=%u\n",
           ending, (unsigned long)counters.frames_ok, (unsigned long)counters.frames_bad,
           (unsigned long)counters.frames_rejected, (unsigned long)counters.sequence_gaps,
           (unsigned long)counters.underruns, (unsigned long)counters.watchdog_trips, (unsigned)counters.faults);
    fflush(stdout);
    if (status != 0) {
        fprintf(stderr, "tpad-amp: %s\n", error);
        return 1;
    }
    return 0;
}
