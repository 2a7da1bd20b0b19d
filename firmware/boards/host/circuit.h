/*
 * circuit.h - the device's circuit in the time domain, at the board's output rate.
 *
 * The amplifier's output voltage u drives the shunt R0 in series with C0 parallel to the
 * motional branch (L, C, R in series). The output stage's reconstruction makes u(t) move
 * linearly from one output sample to the next (a first-order hold: one sample's delay; a
 * DAC's raw steps would put their images, through the shunt, into the measured current),
 * and the circuit is stepped exactly over each sample: the state-space system's matrix
 * exponential, computed once (R0 C0 is about a microsecond: an explicit integrator would be
 * unstable at the output rate). An ADC pair reports the means of u and of the series current
 * over the sample (integrating converters), so that the ratio of the pair's components at
 * the carrier is the circuit's impedance there (within 0.05 % at 768 kHz and 31 kHz).
 */
#ifndef TPAD_HOST_CIRCUIT_H
#define TPAD_HOST_CIRCUIT_H

typedef struct {
    double step[3][5];     /* next state = step . (state, u at the start, u's slope x 1 sample) */
    double mean_va[5];     /* mean node voltage over the sample = mean_va . (the same) */
    double shunt_ohm;
    double state[3];       /* node voltage over C0 (V), motional current x sqrt(L / C) (V), voltage on C (V) */
    double drive_v;        /* the output sample before (V): u(t) starts there */
} circuit_t;

/* Set `circuit` up at rest for output samples at `rate_hz`; every value > 0 (SI units). */
void circuit_init(circuit_t *circuit, double c0_f, double shunt_ohm, double l_h, double c_f, double r_ohm,
                  double rate_hz);

/* One output sample of `drive_v` (V): u(t) moves from the one before to it over 1 / rate_hz. Returns the
 * mean series current over that time (A); `mean_v` gets the mean of u (V). */
double circuit_step(circuit_t *circuit, double drive_v, double *mean_v);

#endif /* TPAD_HOST_CIRCUIT_H */
