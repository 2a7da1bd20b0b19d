/* options.c - tpad-amp's command line (options.h). */
#include "options.h"

#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "decimal.h"

#define MAX_S 86400.0         /* longest time (s) an option names: tpad_rt.limits.MAX_INPUT_S */
#define MAX_FORCE_N 50.0      /* tpad_rt.limits.MAX_FORCE_N */
#define MAX_DELAY_MS 10000.0  /* the emulator's longest delay:MS */
#define DEFAULT_FORCE_N 0.5   /* the runtime's default finger force, as amp emulate */

const char options_help[] =
    "usage: tpad-amp --device FILE [--record FILE.csv] [--duration S] [--fault SPEC]...\n"
    "                [--force-n N] [--seed N]\n"
    "\n"
    "The tpad-amp firmware (docs/firmware.md) built for Linux: the amplifier of\n"
    "docs/amp-protocol.md (version 2) on a new pty, with the device's circuit simulated\n"
    "in place of the hardware. It prints 'amplifier on /dev/pts/N' first (a host opens\n"
    "serial:///dev/pts/N; the firmware keeps its own end open, so a host may reopen it),\n"
    "serves until SIGTERM, SIGINT, --duration or a disconnect fault, ramps the output to\n"
    "0, writes --record, and prints its counters on one line: frames_ok, frames_bad,\n"
    "frames_rejected, sequence_gaps, underruns, watchdog_trips, faults (name=value).\n"
    "\n"
    "The output (carrier samples at 384 kHz, clamped at the device's max_voltage_v by\n"
    "the output stage) drives the device's shunt in series with C0 parallel to its\n"
    "motional branch at --force-n, stepped exactly; the ADC reads the output voltage and\n"
    "the series current, so STATUS reports what the device's impedance gives.\n"
    "\n"
    "options:\n"
    "  --device FILE     the tpad-rt device file whose circuit is simulated (required:\n"
    "                    a firmware cannot find tpad-rt's shipped devices; the default\n"
    "                    device is tpad_rt/devices/default.yaml in a checkout)\n"
    "  --record FILE     write the applied envelope and the output over time here at\n"
    "                    the end, as CSV (below); refused at the start when it cannot be\n"
    "                    written\n"
    "  --duration S      end after S seconds, at most 86400 (default: until a signal)\n"
    "  --fault SPEC      inject a fault (below); times count from the start\n"
    "  --force-n N       contact force on the simulated plate, 0 to 50 N (default 0.5)\n"
    "  --seed N          seed of the random faults, 0 to 4294967295 (default 0)\n"
    "  --help            this text\n"
    "\n"
    "faults (--fault SPEC, repeatable where said):\n"
    "  drop:RATE            drop each received byte with probability RATE (0 to 1)\n"
    "  corrupt:RATE         flip one random bit of each received byte with probability RATE\n"
    "  delay:MS             hand every received byte on MS ms late (0 to 10000)\n"
    "  stall:AT_S:FOR_S     read nothing from AT_S s on, for FOR_S s (repeatable)\n"
    "  overcurrent:AT_S     an overcurrent fault at AT_S s (A6; repeatable)\n"
    "  disconnect:AT_S      close the port at AT_S s, then end as on SIGTERM\n"
    "\n"
    "the recording (--record FILE: CSV, a header line, then one row per applied envelope\n"
    "sample and one per watchdog trip; numpy.genfromtxt(FILE, delimiter=',', names=True)):\n"
    "  t_s            when, on the firmware's clock (s since it started)\n"
    "  event          0 an envelope sample applied, 1 a watchdog trip (A4)\n"
    "  envelope_v     the applied envelope (signed V peak, after clamp and slew)\n"
    "  carrier_hz     the carrier it modulated (0: none)\n"
    "  index          the stream index it came from; -1 for none (held, ramp, underrun)\n"
    "  state          STATUS's state after it (0 IDLE 1 PRIMING 2 RUNNING 3 RAMPING 4 FAULT)\n"
    "  output_peak_v  the largest |output| (V) the output stage made over the sample\n"
    "  current_a_rms  the rms series current (A) over the sample\n"
    "  last_frame_s   when the last valid frame from the host arrived (s, firmware clock;\n"
    "                 -1 before the first)\n"
    "At most 10 minutes at 16 kHz of rows are kept (a note on stderr says when it stops).\n"
    "\n"
    "A bad option, fault, device file or recording path ends in one line on stderr and\n"
    "exit status 1.\n";

static int fail(char *error, size_t size, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    vsnprintf(error, size, format, args);
    va_end(args);
    return -1;
}

/* A number in [low, high] (low excluded when `open_low`), of `unit`; `what` names it in errors. */
static int number(const char *what, const char *text, double low, int open_low, double high, const char *unit,
                  double *value, char *error, size_t size)
{
    if (decimal_parse(text, value) != 0 || *value < low || (open_low && *value == low) || *value > high)
        return fail(error, size, "%s: must be a number in %c%g, %g] (%s), got '%s'", what, open_low ? '(' : '[', low,
                    high, unit, text);
    return 0;
}

static const char *const FAULT_SYNTAX = "drop:RATE, corrupt:RATE, delay:MS, stall:AT_S:FOR_S, overcurrent:AT_S, "
                                        "disconnect:AT_S";

static int fault(const char *spec, options_t *options, unsigned *given, char *error, size_t size)
{
    static const struct {
        const char *name, *syntax;
        int fields;
        int repeatable;
    } kinds[] = {{"drop", "drop:RATE", 1, 0},       {"corrupt", "corrupt:RATE", 1, 0},
                 {"delay", "delay:MS", 1, 0},       {"stall", "stall:AT_S:FOR_S", 2, 1},
                 {"overcurrent", "overcurrent:AT_S", 1, 1}, {"disconnect", "disconnect:AT_S", 1, 0}};
    char copy[128], *fields[3];
    int count = 0, kind = -1;
    if (strlen(spec) >= sizeof copy)
        return fail(error, size, "--fault: '%.40s...' is too long", spec);
    strcpy(copy, spec);
    for (char *p = copy; count < 3;) {
        fields[count++] = p;
        p = strchr(p, ':');
        if (p == NULL)
            break;
        *p++ = '\0';
    }
    for (int k = 0; k < (int)(sizeof kinds / sizeof kinds[0]); k++)
        if (strcmp(fields[0], kinds[k].name) == 0)
            kind = k;
    if (kind < 0)
        return fail(error, size, "--fault: unknown fault '%s' in '%s'; one of %s", fields[0], spec, FAULT_SYNTAX);
    if (count - 1 != kinds[kind].fields || strchr(fields[count - 1], ':') != NULL)
        return fail(error, size, "--fault: %s is written %s, got '%s'", fields[0], kinds[kind].syntax, spec);
    if (given[kind]++ && !kinds[kind].repeatable)
        return fail(error, size, "--fault %s given twice; it may be given once", fields[0]);
    char what[64];
    snprintf(what, sizeof what, "--fault %s", fields[0]);
    double at = 0.0;
    switch (kind) {
    case 0:
        return number(what, fields[1], 0.0, 0, 1.0, "a probability", &options->drop_rate, error, size);
    case 1:
        return number(what, fields[1], 0.0, 0, 1.0, "a probability", &options->corrupt_rate, error, size);
    case 2:
        if (number(what, fields[1], 0.0, 0, MAX_DELAY_MS, "ms", &options->delay_s, error, size) != 0)
            return -1;
        options->delay_s /= 1000.0;
        return 0;
    case 3:
        if (options->stalls == OPTIONS_MAX_REPEATS)
            return fail(error, size, "--fault stall: at most %d of them", OPTIONS_MAX_REPEATS);
        if (number("--fault stall AT_S", fields[1], 0.0, 0, MAX_S, "s", &options->stall_at_s[options->stalls], error,
                   size) != 0 ||
            number("--fault stall FOR_S", fields[2], 0.0, 0, MAX_S, "s", &options->stall_for_s[options->stalls], error,
                   size) != 0)
            return -1;
        options->stalls++;
        return 0;
    case 4:
        if (options->overcurrents == OPTIONS_MAX_REPEATS)
            return fail(error, size, "--fault overcurrent: at most %d of them", OPTIONS_MAX_REPEATS);
        return number(what, fields[1], 0.0, 0, MAX_S, "s", &options->overcurrent_at_s[options->overcurrents++],
                      error, size);
    default:
        if (number(what, fields[1], 0.0, 0, MAX_S, "s", &at, error, size) != 0)
            return -1;
        options->disconnect_at_s = at;
        return 0;
    }
}

static int seed(const char *text, uint32_t *value, char *error, size_t size)
{
    char *end;
    errno = 0;
    unsigned long long parsed = strtoull(text, &end, 10);
    if (text[0] < '0' || text[0] > '9' || *end != '\0' || errno == ERANGE || parsed > 0xFFFFFFFFull)
        return fail(error, size, "--seed: must be a whole number from 0 to 4294967295, got '%s'", text);
    *value = (uint32_t)parsed;
    return 0;
}

int options_parse(int argc, char **argv, options_t *options, char *error, size_t size)
{
    static const char *const valued[] = {"--device", "--record", "--duration", "--fault", "--force-n", "--seed"};
    unsigned faults_given[6] = {0};
    int once[6] = {0};
    memset(options, 0, sizeof *options);
    options->force_n = DEFAULT_FORCE_N;
    options->disconnect_at_s = -1.0;
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i], *value = NULL;
        if (strcmp(arg, "--help") == 0 || strcmp(arg, "-h") == 0) {
            options->help = 1;
            return 0;
        }
        int which = -1;
        size_t name_length = strcspn(arg, "=");
        for (int k = 0; k < 6; k++)
            if (strlen(valued[k]) == name_length && strncmp(arg, valued[k], name_length) == 0)
                which = k;
        if (which < 0)
            return fail(error, size, arg[0] == '-' ? "unknown option '%s' (tpad-amp --help lists them)"
                                                   : "unexpected argument '%s' (tpad-amp --help lists the options)",
                        arg);
        if (arg[name_length] == '=')
            value = arg + name_length + 1;
        else if (i + 1 < argc)
            value = argv[++i];
        else
            return fail(error, size, "%s needs a value", valued[which]);
        if (which != 3 && once[which]++)
            return fail(error, size, "%s given twice", valued[which]);
        int status = 0;
        switch (which) {
        case 0:
        case 1:
            if (value[0] == '\0')
                return fail(error, size, "%s: an empty path", valued[which]);
            if (which == 0)
                options->device_path = value;
            else
                options->record_path = value;
            break;
        case 2:
            status = number("--duration", value, 0.0, 1, MAX_S, "s", &options->duration_s, error, size);
            break;
        case 3:
            status = fault(value, options, faults_given, error, size);
            break;
        case 4:
            status = number("--force-n", value, 0.0, 0, MAX_FORCE_N, "N", &options->force_n, error, size);
            break;
        default:
            status = seed(value, &options->seed, error, size);
            break;
        }
        if (status != 0)
            return -1;
    }
    if (options->device_path == NULL)
        return fail(error, size, "--device FILE is required: the tpad-rt device file whose circuit to simulate "
                                 "(e.g. tpad_rt/devices/default.yaml)");
    return 0;
}
