/* hal_host.c - hal.h on Linux: CLOCK_MONOTONIC, a pty, the device's circuit simulated (host.h). */
#include "host.h"

#include <complex.h>
#include <math.h>
#include <poll.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "circuit.h"
#include "device.h"
#include "hal.h"
#include "line.h"
#include "pty.h"
#include "record.h"

/* ADC pairs made and not read yet: room for the most output samples one pass writes. */
#define ADC_RING 32768u
/* The longest hal_wait (us): a signal is seen within it even if it came just before poll. */
#define MAX_WAIT_US 50000u
/* The emulator's carrier range (Hz), widened to take in the device's carrier; its step (mHz). */
#define CARRIER_LOW_MHZ 10000000.0
#define CARRIER_HIGH_MHZ 80000000.0
#define CARRIER_STEP_MHZ 10.0
/* The overcurrent trip: this times the rms current at max_mv at the device's carrier (as the emulator). */
#define OVERCURRENT_MARGIN 1.5

static struct {
    hal_board_t board;
    volatile sig_atomic_t *stop;
    int serving;
    struct timespec start;
    pty_t pty;
    line_t line;
    circuit_t circuit;
    record_t record;
    double volts_per_lsb_out;   /* output sample 1 in volts */
    double max_v;               /* the output stage's clamp */
    double adc_lsb_per_v, adc_lsb_per_a;
    int16_t adc_voltage[ADC_RING], adc_current[ADC_RING];
    uint32_t adc_head, adc_tail; /* free-running */
    uint64_t overcurrent_us[OPTIONS_MAX_REPEATS]; /* --fault overcurrent times, ascending */
    size_t overcurrents, overcurrents_done;
    uint64_t end_us;             /* --duration's end; UINT64_MAX: none */
    uint64_t late_us;            /* the latest a wake-up came after its time, since host_take_late_us */
} host;

/* --- set-up --- */

static double impedance_abs(const device_t *device, double force_n, double freq_hz)
{
    double l_h, c_f, r_ohm, omega = 2.0 * M_PI * freq_hz;
    device_motional(device, force_n, &l_h, &c_f, &r_ohm);
    double complex motional = r_ohm + I * (omega * l_h - 1.0 / (omega * c_f));
    return cabs(device->shunt_ohm + 1.0 / (I * omega * device->c0_f + 1.0 / motional));
}

static uint32_t to_u32(double value)
{
    return value >= 4294967295.0 ? 0xFFFFFFFFu : value <= 0.0 ? 0u : (uint32_t)value;
}

static void set_board(const device_t *device, double force_n)
{
    hal_board_t *board = &host.board;
    double carrier_mhz = device->carrier_hz * 1000.0;
    board->name = "host";
    board->output_rate_hz = HOST_OUTPUT_RATE_HZ;
    board->max_mv = to_u32(round(device->max_voltage_v * 1000.0));
    board->full_scale_mv = to_u32(round(device->max_voltage_v * 1250.0));
    board->carrier_min_mhz = to_u32(fmin(CARRIER_LOW_MHZ, floor(carrier_mhz / CARRIER_STEP_MHZ) * CARRIER_STEP_MHZ));
    board->carrier_max_mhz = to_u32(fmax(CARRIER_HIGH_MHZ, ceil(carrier_mhz / CARRIER_STEP_MHZ) * CARRIER_STEP_MHZ));
    double resonance_ma = board->max_mv / sqrt(2.0) / impedance_abs(device, force_n, round(carrier_mhz) / 1000.0);
    board->max_current_ma = to_u32(ceil(OVERCURRENT_MARGIN * resonance_ma));
    board->measures = 7;
    /* The ADC's full scale: the output's full scale, and that voltage across the shunt alone (no current
     * the output stage drives is larger); past them it saturates. */
    double full_scale_v = board->full_scale_mv / 1000.0;
    board->voltage_uv_per_lsb = to_u32(ceil(full_scale_v * 1e6 / 32767.0));
    board->current_na_per_lsb = to_u32(ceil(full_scale_v / device->shunt_ohm * 1e9 / 32767.0));
    if (board->current_na_per_lsb == 0)
        board->current_na_per_lsb = 1;
    host.volts_per_lsb_out = full_scale_v / 32767.0;
    host.max_v = board->max_mv / 1000.0;
    host.adc_lsb_per_v = 1e6 / board->voltage_uv_per_lsb;
    host.adc_lsb_per_a = 1e9 / board->current_na_per_lsb;
}

int host_setup(const options_t *options, volatile sig_atomic_t *stop, char *error, size_t error_size)
{
    static device_t device;
    double l_h, c_f, r_ohm;
    host.pty.master = host.pty.slave = -1;
    host.stop = stop;
    host.serving = 1;
    if (device_read(options->device_path, &device, error, error_size) != 0)
        return -1;
    set_board(&device, options->force_n);
    device_motional(&device, options->force_n, &l_h, &c_f, &r_ohm);
    circuit_init(&host.circuit, device.c0_f, device.shunt_ohm, l_h, c_f, r_ohm, HOST_OUTPUT_RATE_HZ);
    if (record_open(&host.record, options->record_path, HOST_OUTPUT_RATE_HZ, error, error_size) != 0)
        return -1;
    if (pty_open(&host.pty, error, error_size) != 0) {
        record_abandon(&host.record);
        return -1;
    }
    line_init(&host.line, &host.pty, options);
    host.adc_head = host.adc_tail = 0;
    host.overcurrents = options->overcurrents;
    host.overcurrents_done = 0;
    for (size_t i = 0; i < host.overcurrents; i++) { /* insertion sort: at most OPTIONS_MAX_REPEATS */
        uint64_t at = (uint64_t)ceil(options->overcurrent_at_s[i] * 1e6);
        size_t j = i;
        for (; j > 0 && host.overcurrent_us[j - 1] > at; j--)
            host.overcurrent_us[j] = host.overcurrent_us[j - 1];
        host.overcurrent_us[j] = at;
    }
    clock_gettime(CLOCK_MONOTONIC, &host.start);
    host.end_us = options->duration_s > 0.0 ? (uint64_t)ceil(options->duration_s * 1e6) : UINT64_MAX;
    return 0;
}

const char *host_port_name(void)
{
    return host.pty.name;
}

void host_set_serving(int serving)
{
    host.serving = serving;
}

void host_discard_output(void)
{
    pty_discard_output(&host.pty);
}

int host_duration_over(uint64_t now_us)
{
    return now_us >= host.end_us;
}

int host_disconnected(uint64_t now_us)
{
    if (!line_disconnected(&host.line, now_us))
        return 0;
    pty_close(&host.pty);
    return 1;
}

void host_observe(void *ctx, const amp_event_t *event)
{
    uint64_t last_us = amp_last_valid_us((const amp_t *)ctx);
    record_event(&host.record, event, last_us == UINT64_MAX ? -1.0 : last_us / 1e6);
}

int host_finish(char *error, size_t error_size)
{
    pty_close(&host.pty);
    return record_close(&host.record, error, error_size);
}

/* --- hal.h --- */

const hal_board_t *hal_init(void)
{
    return &host.board;
}

void hal_serial_number(char serial[16])
{
    snprintf(serial, 16, "HOST-%ld", (long)getpid() % 1000000000L);
}

uint64_t hal_time_us(void)
{
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    int64_t ns = (int64_t)(now.tv_sec - host.start.tv_sec) * 1000000000 + (now.tv_nsec - host.start.tv_nsec);
    return ns > 0 ? (uint64_t)ns / 1000u : 0u;
}

static uint64_t next_overcurrent_us(void)
{
    return host.overcurrents_done < host.overcurrents ? host.overcurrent_us[host.overcurrents_done] : UINT64_MAX;
}

void hal_wait(uint64_t until_us)
{
    if (host.serving && *host.stop)
        return;
    uint64_t now = hal_time_us(), wake = until_us;
    uint64_t events[] = {now + MAX_WAIT_US, line_next_event_us(&host.line, now), next_overcurrent_us(),
                         host.end_us};
    for (size_t i = 0; i < sizeof events / sizeof events[0]; i++)
        wake = events[i] < wake ? events[i] : wake;
    if (wake <= now)
        return;
    int timeout_ms = (int)((wake - now + 999u) / 1000u);
    struct pollfd fd = {host.pty.master, POLLIN, 0};
    poll(&fd, line_reading(&host.line, now) ? 1 : 0, timeout_ms);
    uint64_t woke = hal_time_us();
    if (woke > wake && woke - wake > host.late_us)
        host.late_us = woke - wake;
}

uint64_t host_take_late_us(void)
{
    uint64_t late = host.late_us;
    host.late_us = 0;
    return late;
}

size_t hal_uart_read(uint8_t *data, size_t cap)
{
    return line_read(&host.line, data, cap, hal_time_us());
}

size_t hal_uart_write(const uint8_t *data, size_t n)
{
    if (host.pty.master < 0)
        return n; /* the port is closed: what is sent is lost */
    ssize_t written = write(host.pty.master, data, n);
    return written > 0 ? (size_t)written : 0u;
}

size_t hal_output_room(void)
{
    return ADC_RING - (host.adc_head - host.adc_tail);
}

static int16_t adc(double value)
{
    double lsb = round(value);
    return (int16_t)(lsb > 32767.0 ? 32767 : lsb < -32767.0 ? -32767 : lsb);
}

void hal_output_write(const int16_t *samples, size_t n)
{
    for (size_t k = 0; k < n && hal_output_room() > 0; k++) {
        /* The output stage: the sample at full scale, through its hardware clamp at max_mv. */
        double volts = fmax(-host.max_v, fmin(host.max_v, samples[k] * host.volts_per_lsb_out)), mean_v;
        double current_a = circuit_step(&host.circuit, volts, &mean_v);
        uint32_t slot = host.adc_head++ % ADC_RING;
        host.adc_voltage[slot] = adc(mean_v * host.adc_lsb_per_v);
        host.adc_current[slot] = adc(current_a * host.adc_lsb_per_a);
        record_output(&host.record, volts, current_a);
    }
}

void hal_output_off(void)
{
    host.circuit.drive_v = 0.0; /* the output stage's next sample starts from 0 */
}

size_t hal_adc_read(int16_t *voltage, int16_t *current, size_t cap)
{
    size_t n = 0;
    for (; n < cap && host.adc_tail != host.adc_head; n++, host.adc_tail++) {
        voltage[n] = host.adc_voltage[host.adc_tail % ADC_RING];
        current[n] = host.adc_current[host.adc_tail % ADC_RING];
    }
    return n;
}

void hal_watchdog_kick(void)
{
    /* No hardware watchdog on Linux: a hung process is ended by its user (the pty closes). */
}

uint8_t hal_faults(void)
{
    uint64_t now = hal_time_us();
    uint8_t bits = 0;
    while (next_overcurrent_us() <= now) {
        host.overcurrents_done++;
        bits |= AMP_FAULT_OVERCURRENT;
    }
    return bits;
}
