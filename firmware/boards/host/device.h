/*
 * device.h - the circuit of a tpad-rt device file (tpad_rt/devices/NAME.yaml), read by the host build.
 *
 * A small, strict reader of the YAML subset those files use: block mappings by indentation
 * (spaces), plain scalars, single- or double-quoted strings, flow lists of numbers, comments.
 * Anything else (tabs, block lists, anchors, multi-line values, duplicate keys) is an error
 * that names the file, the line and what is wrong. Only the fields the simulated circuit
 * needs are taken (the others are only parsed); each is checked against the ranges of
 * tpad_rt/config/device_schema.py.
 */
#ifndef TPAD_HOST_DEVICE_H
#define TPAD_HOST_DEVICE_H

#include <stddef.h>

/* Most rows of the force tables. */
#define DEVICE_MAX_FORCES 64

typedef struct {
    double carrier_hz;      /* the carrier the runtime drives at (Hz) */
    double max_voltage_v;   /* amplifier.max_voltage_v: the drive's limit (V peak) */
    double c0_f;            /* circuit.c0_nf, in F */
    double shunt_ohm;       /* circuit.shunt_ohm: R0 (ohm) */
    size_t forces;          /* rows of the tables below */
    double force_n[DEVICE_MAX_FORCES];      /* strictly increasing (N) */
    double motional_l_h[DEVICE_MAX_FORCES]; /* H */
    double motional_c_f[DEVICE_MAX_FORCES]; /* F (the file's pF x 1e-12) */
    double motional_r_ohm[DEVICE_MAX_FORCES];
} device_t;

/* Read `path` into `device`; 0 on success, else -1 with one line (no newline) in `error`. */
int device_read(const char *path, device_t *device, char *error, size_t error_size);

/* The motional branch (L in H, C in F, R in ohm) at contact force `force_n` (N): linear
 * interpolation in the tables, clamped at their ends (as Device.motional, numpy's interp). */
void device_motional(const device_t *device, double force_n, double *l_h, double *c_f, double *r_ohm);

#endif /* TPAD_HOST_DEVICE_H */
