/* circuit.c - the device's circuit stepped exactly, one held output sample at a time (circuit.h). */
#include "circuit.h"

#include <math.h>
#include <string.h>

#define N 5            /* the state (3), the drive u and its slope */
#define M (2 * N)      /* the block matrix whose exponential gives both the step and its integral */
#define TAYLOR_TERMS 20

static void multiply(double out[M][M], double a[M][M], double b[M][M])
{
    double product[M][M];
    for (int i = 0; i < M; i++)
        for (int j = 0; j < M; j++) {
            double sum = 0.0;
            for (int k = 0; k < M; k++)
                sum += a[i][k] * b[k][j];
            product[i][j] = sum;
        }
    memcpy(out, product, sizeof product);
}

/* out = exp(a), by scaling and squaring with a Taylor series (the scaled norm is at most 1/4). */
static void expm(double out[M][M], double a[M][M])
{
    double norm = 0.0;
    for (int j = 0; j < M; j++) {
        double column = 0.0;
        for (int i = 0; i < M; i++)
            column += fabs(a[i][j]);
        norm = fmax(norm, column);
    }
    int squarings = norm > 0.25 ? (int)ceil(log2(norm / 0.25)) : 0;
    double scaled[M][M], term[M][M];
    for (int i = 0; i < M; i++)
        for (int j = 0; j < M; j++) {
            scaled[i][j] = ldexp(a[i][j], -squarings);
            out[i][j] = term[i][j] = (i == j);
        }
    for (int n = 1; n <= TAYLOR_TERMS; n++) {
        multiply(term, term, scaled);
        for (int i = 0; i < M; i++)
            for (int j = 0; j < M; j++) {
                term[i][j] /= n;
                out[i][j] += term[i][j];
            }
    }
    for (int s = 0; s < squarings; s++)
        multiply(out, out, out);
}

void circuit_init(circuit_t *circuit, double c0_f, double shunt_ohm, double l_h, double c_f, double r_ohm,
                  double rate_hz)
{
    /* States (all volts, so that the matrix is balanced): v = node voltage over C0, y = i_L sqrt(L / C),
     * w = voltage on C; u the drive. dv/dt = (u - v) / (R0 C0) - i_L / C0, L di_L/dt = v - R i_L - w,
     * C dw/dt = i_L; du/dt = s, ds/dt = 0 over a sample. */
    double z0 = sqrt(l_h / c_f), omega0 = 1.0 / sqrt(l_h * c_f), h = 1.0 / rate_hz;
    double system[N][N] = {
        {-1.0 / (shunt_ohm * c0_f), -1.0 / (z0 * c0_f), 0.0, 1.0 / (shunt_ohm * c0_f), 0.0},
        {omega0, -r_ohm / l_h, -omega0, 0.0, 0.0},
        {0.0, omega0, 0.0, 0.0, 0.0},
        {0.0, 0.0, 0.0, 0.0, 1.0},
        {0.0, 0.0, 0.0, 0.0, 0.0},
    };
    /* exp([[S h, I h], [0, 0]]) = [[exp(S h), integral over the sample of exp(S t) dt], [0, I]] */
    double block[M][M] = {{0.0}}, exponential[M][M];
    for (int i = 0; i < N; i++) {
        for (int j = 0; j < N; j++)
            block[i][j] = system[i][j] * h;
        block[i][N + i] = h;
    }
    expm(exponential, block);
    /* The slope enters as (u_k - u_(k-1)) / h: its column is taken per sample, not per second. */
    for (int j = 0; j < N; j++) {
        double per = j == N - 1 ? 1.0 / h : 1.0;
        for (int i = 0; i < 3; i++)
            circuit->step[i][j] = exponential[i][j] * per;
        circuit->mean_va[j] = exponential[0][N + j] / h * per;
    }
    circuit->shunt_ohm = shunt_ohm;
    memset(circuit->state, 0, sizeof circuit->state);
    circuit->drive_v = 0.0;
}

double circuit_step(circuit_t *circuit, double drive_v, double *mean_v)
{
    const double in[N] = {circuit->state[0], circuit->state[1], circuit->state[2], circuit->drive_v,
                          drive_v - circuit->drive_v};
    double mean_va = 0.0, next[3] = {0.0, 0.0, 0.0};
    for (int j = 0; j < N; j++) {
        mean_va += circuit->mean_va[j] * in[j];
        for (int i = 0; i < 3; i++)
            next[i] += circuit->step[i][j] * in[j];
    }
    memcpy(circuit->state, next, sizeof next);
    *mean_v = 0.5 * (circuit->drive_v + drive_v);
    circuit->drive_v = drive_v;
    return (*mean_v - mean_va) / circuit->shunt_ohm;
}
