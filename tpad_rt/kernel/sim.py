"""The simulated plate: a second-order resonator driven by the DAC samples.

The plate's vibrating mode is ``x'' + (w0 / Q) x' + w0**2 x = b u(t)`` with ``x`` the
vibration amplitude (m), ``u`` the drive (V), ``w0 = 2 pi f0`` the resonance of the
device's motional branch as the source loads it, and ``Q`` the loaded quality factor,
both at the current contact force. Its envelope ``sqrt(x**2 + (x' / w0)**2)`` rises and
falls with time constant ``Q / (pi f0)``. A carrier off ``f0`` (a finger detunes the
plate) beats against it in every transient, as the real circuit does.

Discretisation: exact for a drive held constant over each sample (zero-order hold,
``Phi = expm(A T)``, ``Gamma = A^-1 (Phi - I) B``), with ``b`` set so that a sampled
sine at the carrier of peak ``V`` gives the steady amplitude ``gain * V`` exactly. That
normalisation removes the hold's sinc droop at the carrier (4 % at 31 kHz / 192 kHz),
as a DAC's reconstruction filter does: near the carrier the plate sees the samples'
band-limited waveform, whose peak is the samples' peak.

Kernels obey docs/kernel.md's rules (njit, cache, nogil, no allocation, state in arrays).
"""

from __future__ import annotations

import math

import numpy as np

from tpad_rt.kernel.cache_stamp import stamp_cache
from tpad_rt.kernel.jit import njit
from tpad_rt.physics import friction
from tpad_rt.physics.friction import relative_friction_core

# felt_friction compiles friction's core in: this module's cache is stamped with that file too.
stamp_cache(__file__, friction.__file__)

# --- state: float64[SIM_STATE_SIZE], carried across blocks --------------------
SIM_X_M = 0                   # displacement (m)
SIM_V_M_S = 1                 # velocity (m/s)
SIM_STATE_SIZE = 2

# --- coef: float64[COEF_SIZE], from resonator_coefficients ------------------
COEF_PHI_XX = 0               # state transition Phi = expm(A T)
COEF_PHI_XV = 1
COEF_PHI_VX = 2
COEF_PHI_VV = 3
COEF_GAMMA_X = 4              # input gain per drive volt (m/V, m/s/V)
COEF_GAMMA_V = 5
COEF_INV_OMEGA_S = 6          # 1 / w0, to put velocity in metres for the envelope
COEF_SIZE = 7

#: Vibration amplitude (m) below which the plate is at rest (its state is set to 0 at the end of a call of
#: :func:`resonate`): a silent plate's ring-down otherwise ends in subnormal floats, each operation on which costs
#: up to a hundred times more (an 11 s render that touched for 3 s spent most of its time there).
NEGLIGIBLE_M = 1e-30


@njit(cache=True, nogil=True)
def resonator_coefficients(
    f0_hz: float, q: float, gain_m_per_v: float, carrier_hz: float, fs_hz: float, coef: np.ndarray
) -> None:
    """Fill ``coef`` for resonance ``f0_hz``, quality factor ``q`` (> 0.5), steady gain ``gain_m_per_v``.

    ``gain_m_per_v`` is the steady vibration amplitude (m) per peak volt of a sine at
    ``carrier_hz`` sampled at ``fs_hz``. No input checks.
    """
    omega = 2.0 * math.pi * f0_hz
    step_s = 1.0 / fs_hz
    sigma = omega / (2.0 * q)
    omega_d = omega * math.sqrt(1.0 - 1.0 / (4.0 * q * q))
    decay = math.exp(-sigma * step_s)
    cos_d = math.cos(omega_d * step_s)
    sin_d = math.sin(omega_d * step_s)
    phi_xx = decay * (cos_d + sigma / omega_d * sin_d)
    phi_xv = decay * sin_d / omega_d
    phi_vx = -decay * omega * omega / omega_d * sin_d
    phi_vv = decay * (cos_d - sigma / omega_d * sin_d)
    # Gamma = A^-1 (Phi - I) B for B = (0, 1), A = ((0, 1), (-w0^2, -2 sigma)).
    gamma_x = (1.0 - phi_vv - 2.0 * sigma * phi_xv) / (omega * omega)
    gamma_v = phi_xv
    # Steady displacement per unit input at z = exp(j w_carrier T): x-row of (zI - Phi)^-1 Gamma.
    carrier_rad = 2.0 * math.pi * carrier_hz * step_s
    z = complex(math.cos(carrier_rad), math.sin(carrier_rad))
    determinant = z * z - (phi_xx + phi_vv) * z + (phi_xx * phi_vv - phi_xv * phi_vx)
    response = ((z - phi_vv) * gamma_x + phi_xv * gamma_v) / determinant
    scale = gain_m_per_v / abs(response)
    coef[COEF_PHI_XX] = phi_xx
    coef[COEF_PHI_XV] = phi_xv
    coef[COEF_PHI_VX] = phi_vx
    coef[COEF_PHI_VV] = phi_vv
    coef[COEF_GAMMA_X] = gamma_x * scale
    coef[COEF_GAMMA_V] = gamma_v * scale
    coef[COEF_INV_OMEGA_S] = 1.0 / omega


@njit(cache=True, nogil=True)
def resonate(
    drive: np.ndarray, volts_per_full_scale: float, coef: np.ndarray, state: np.ndarray, envelope_m: np.ndarray
) -> float:
    """Advance the plate over the DAC samples ``drive`` (float32, full scale 1); the mean envelope (m).

    Sample ``i`` drives with ``drive[i] * volts_per_full_scale`` volts for one sample
    period; ``envelope_m[i]`` (m, at least ``len(drive)`` long) receives the envelope
    ``sqrt(x**2 + (v / w0)**2)`` at the end of that period. ``state`` carries ``(x, v)``, set to 0 at the end
    when the envelope is below NEGLIGIBLE_M. Returns 0.0 for an empty ``drive``.
    """
    phi_xx = coef[COEF_PHI_XX]
    phi_xv = coef[COEF_PHI_XV]
    phi_vx = coef[COEF_PHI_VX]
    phi_vv = coef[COEF_PHI_VV]
    gamma_x = coef[COEF_GAMMA_X]
    gamma_v = coef[COEF_GAMMA_V]
    inv_omega_s = coef[COEF_INV_OMEGA_S]
    x_m = state[SIM_X_M]
    v_m_s = state[SIM_V_M_S]
    total_m = 0.0
    for i in range(drive.shape[0]):
        volts = float(drive[i]) * volts_per_full_scale  # float64 (NumPy 2 keeps float32 * float in float32)
        x_next = phi_xx * x_m + phi_xv * v_m_s + gamma_x * volts
        v_m_s = phi_vx * x_m + phi_vv * v_m_s + gamma_v * volts
        x_m = x_next
        v_scaled_m = v_m_s * inv_omega_s
        envelope_m[i] = math.sqrt(x_m * x_m + v_scaled_m * v_scaled_m)
        total_m += envelope_m[i]
    if x_m * x_m + (v_m_s * inv_omega_s) ** 2 < NEGLIGIBLE_M * NEGLIGIBLE_M:  # (NaN is kept)
        x_m = v_m_s = 0.0  # a plate rung down: 0, not subnormal floats that slow every later sample down
    state[SIM_X_M] = x_m
    state[SIM_V_M_S] = v_m_s
    return total_m / max(drive.shape[0], 1)


@njit(cache=True, nogil=True)
def resonate_blocks(
    drive: np.ndarray,
    block_frames: int,
    volts_per_full_scale: float,
    coefs: np.ndarray,
    coef_rows: np.ndarray,
    state: np.ndarray,
    envelope_m: np.ndarray,
    amplitude_m: np.ndarray,
) -> None:
    """:func:`resonate` over consecutive blocks of ``block_frames`` samples of ``drive``, block ``k`` with the
    coefficients ``coefs[coef_rows[k]]``; its mean envelope (m) into ``amplitude_m[k]``.

    ``coefs``: float64 ``[M, COEF_SIZE]``; ``coef_rows``: int64, one per block, each in
    ``[0, M)``; ``envelope_m`` at least ``block_frames`` long. No input checks.
    """
    for k in range(coef_rows.shape[0]):
        begin = k * block_frames
        amplitude_m[k] = resonate(drive[begin:begin + block_frames], volts_per_full_scale, coefs[coef_rows[k]],
                                  state, envelope_m)


@njit(cache=True, nogil=True)
def felt_friction(
    amplitude_m: np.ndarray, speed_m_s: np.ndarray, freq_hz: float, mu0: float, poisson: float, psi_star: float,
    mu_rel: np.ndarray,
) -> None:
    """``mu_rel[k]``: the relative friction at vibration amplitude ``amplitude_m[k]`` (m) and finger speed
    ``speed_m_s[k]`` (m/s), by :func:`tpad_rt.physics.friction.relative_friction_core` (paper Eqs. 2-3)."""
    for k in range(amplitude_m.shape[0]):
        mu_rel[k] = relative_friction_core(amplitude_m[k], freq_hz, speed_m_s[k], mu0, poisson, psi_star)
