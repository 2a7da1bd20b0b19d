/* device.c - the circuit fields of a tpad-rt device file (device.h). */
#include "device.h"

#include <stdio.h>
#include <string.h>

#include "decimal.h"
#include "yaml_subset.h"

/* Ranges of tpad_rt/config/device_schema.py, and the highest carrier the host build simulates. */
#define MIN_CARRIER_HZ 1000.0
#define HOST_MAX_CARRIER_HZ 100000.0
#define MAX_FORCE_N 50.0

typedef struct {
    const char *file;
    char *error;
    size_t error_size;
} context_t;

static int bad(const context_t *at, const yaml_entry_t *entry, const char *what)
{
    if (entry != NULL)
        snprintf(at->error, at->error_size, "%s, line %d: %s %s", at->file, entry->line, entry->path, what);
    else
        snprintf(at->error, at->error_size, "%s: %s", at->file, what);
    return -1;
}

static const yaml_entry_t *need(const context_t *at, const yaml_doc_t *doc, const char *path, yaml_kind_t kind)
{
    const yaml_entry_t *entry = yaml_find(doc, path);
    char what[160];
    if (entry == NULL) {
        snprintf(what, sizeof what, "%s is missing", path);
        bad(at, NULL, what);
        return NULL;
    }
    if (entry->kind != kind) {
        bad(at, entry, kind == YAML_LIST ? "must be a flow list of numbers ([a, b, ...])" : "must be a number");
        return NULL;
    }
    return entry;
}

/* The number at `path`, within [low, high]. */
static int number(const context_t *at, const yaml_doc_t *doc, const char *path, double low, double high, double *value)
{
    const yaml_entry_t *entry = need(at, doc, path, YAML_PLAIN);
    char what[160];
    if (entry == NULL)
        return -1;
    if (decimal_parse(entry->text, value) != 0)
        return bad(at, entry, "must be a number");
    if (!(*value >= low && *value <= high)) {
        snprintf(what, sizeof what, "must be in [%g, %g], got %g", low, high, *value);
        return bad(at, entry, what);
    }
    return 0;
}

/* The table at `path`: as many numbers as `rows` (0: any number, at least 1), each in [low, high], times `scale`. */
static int table(const context_t *at, const yaml_doc_t *doc, const char *path, size_t rows, double low, double high,
                 double scale, double *out, size_t *count)
{
    const yaml_entry_t *entry = need(at, doc, path, YAML_LIST);
    char what[160];
    if (entry == NULL)
        return -1;
    if (entry->items == 0 || entry->items > DEVICE_MAX_FORCES)
        snprintf(what, sizeof what, "must have 1 to %d items, got %zu", DEVICE_MAX_FORCES, entry->items);
    else if (rows != 0 && entry->items != rows)
        snprintf(what, sizeof what, "must have as many items as force_n (%zu), got %zu", rows, entry->items);
    else
        what[0] = '\0';
    if (what[0] != '\0')
        return bad(at, entry, what);
    for (size_t i = 0; i < entry->items; i++) {
        if (!(entry->values[i] >= low && entry->values[i] <= high)) {
            snprintf(what, sizeof what, "item %zu must be in [%g, %g], got %g", i, low, high, entry->values[i]);
            return bad(at, entry, what);
        }
        out[i] = entry->values[i] * scale;
    }
    *count = entry->items;
    return 0;
}

int device_read(const char *path, device_t *device, char *error, size_t error_size)
{
    static yaml_doc_t doc; /* large: not on the stack */
    context_t at = {path, error, error_size};
    double version = 0.0, c0_nf = 0.0;
    size_t rows = 0, count = 0;
    if (yaml_read(path, &doc, error, error_size) != 0)
        return -1;
    if (number(&at, &doc, "format_version", 2, 2, &version) != 0 ||
        number(&at, &doc, "carrier_hz", MIN_CARRIER_HZ, HOST_MAX_CARRIER_HZ, &device->carrier_hz) != 0 ||
        number(&at, &doc, "amplifier.max_voltage_v", 0.1, 10000.0, &device->max_voltage_v) != 0 ||
        number(&at, &doc, "circuit.c0_nf", 1e-3, 1e5, &c0_nf) != 0 ||
        number(&at, &doc, "circuit.shunt_ohm", 1e-3, 1e6, &device->shunt_ohm) != 0 ||
        table(&at, &doc, "circuit.force_n", 0, 0.0, MAX_FORCE_N, 1.0, device->force_n, &rows) != 0 ||
        table(&at, &doc, "circuit.motional_l_h", rows, 1e-6, 1e4, 1.0, device->motional_l_h, &count) != 0 ||
        table(&at, &doc, "circuit.motional_c_pf", rows, 1e-3, 1e6, 1e-12, device->motional_c_f, &count) != 0 ||
        table(&at, &doc, "circuit.motional_r_ohm", rows, 1e-3, 1e7, 1.0, device->motional_r_ohm, &count) != 0)
        return -1;
    for (size_t i = 1; i < rows; i++)
        if (!(device->force_n[i] > device->force_n[i - 1]))
            return bad(&at, yaml_find(&doc, "circuit.force_n"), "must be strictly increasing");
    device->c0_f = c0_nf * 1e-9;
    device->forces = rows;
    return 0;
}

static double interpolate(const double *x, const double *y, size_t n, double at)
{
    if (at <= x[0])
        return y[0];
    for (size_t i = 1; i < n; i++)
        if (at <= x[i])
            return y[i - 1] + (y[i] - y[i - 1]) * (at - x[i - 1]) / (x[i] - x[i - 1]);
    return y[n - 1];
}

void device_motional(const device_t *device, double force_n, double *l_h, double *c_f, double *r_ohm)
{
    *l_h = interpolate(device->force_n, device->motional_l_h, device->forces, force_n);
    *c_f = interpolate(device->force_n, device->motional_c_f, device->forces, force_n);
    *r_ohm = interpolate(device->force_n, device->motional_r_ohm, device->forces, force_n);
}
