"""Butterworth-Van Dyke model of a TPaD's piezo actuator (paper Section V, Eqs. 2-6).

The static capacitance ``C0`` is in parallel with the motional branch ``L``, ``C``,
``R`` (the plate and the finger reflected onto the electrical side); the shunt
resistor ``R0`` is in series with the whole. SI units: Hz, F, H, ohm, V, A, W. The
paper's functions take RMS volts; the device model's (``motional_current``,
``plate_amplitude_m``, ``loaded_*``) take peak volts, as the runtime's drive does.

The one transduction factor ``gamma`` (N/V, the same as C/m) links the branch to the
plate: the motional current is ``i_g = gamma dX/dt`` (paper Fig. 8), so a sinusoidal
motional current of peak ``I`` at ``omega`` moves the plate ``I / (gamma omega)`` m.

Seen from the motional branch, the source behind its shunt and ``C0`` is a Thevenin
source ``u / (1 + j w R0 C0)`` behind ``Z_th = R0 / (1 + j w R0 C0)``. So the branch's
envelope relaxes with ``tau = 2 L / (R + Re Z_th)`` (the loaded time constant), and it
resonates where ``w L - 1 / (w C) + Im Z_th = 0`` (the loaded resonance).

The functions validate their inputs and broadcast like NumPy ufuncs. They are plain
NumPy: no kernel evaluates the circuit (the kernel reads tables the device builds from
it), and a device check would otherwise compile numba code before any argument is
refused (docs/kernel.md "Compilation").
"""

from __future__ import annotations

from typing import cast

import numpy as np
import numpy.typing as npt

from tpad_rt.physics._validate import ComplexOrArray, FloatOrArray, non_negative, positive


def _impedance(freq_hz: FloatOrArray, c0_f: FloatOrArray, l_h: FloatOrArray, c_f: FloatOrArray,
               r_ohm: FloatOrArray) -> ComplexOrArray:
    """Impedance (ohm) of C0 in parallel with L, C, R: paper Eq. 3. No input checks."""
    omega = 2.0 * np.pi * freq_hz
    x0 = -1.0 / (c0_f * omega)
    x1 = l_h * omega - 1.0 / (c_f * omega)
    denominator = r_ohm * r_ohm + (x0 + x1) ** 2
    z = x0 * x0 * r_ohm / denominator + 1j * (x0 * (r_ohm * r_ohm + x0 * x1 + x1 * x1) / denominator)
    return cast(ComplexOrArray, z)  # numpy's stubs widen a real array plus an imaginary one


def impedance(
    freq_hz: npt.ArrayLike, c0_f: npt.ArrayLike, l_h: npt.ArrayLike, c_f: npt.ArrayLike, r_ohm: npt.ArrayLike
) -> ComplexOrArray:
    """Complex impedance (ohm) of the TPaD (C0 parallel to L, C, R), paper Eqs. 2-3.

    ``Z = X0^2 R / (R^2 + (X0+X1)^2) + j X0 (R^2 + X0 X1 + X1^2) / (R^2 + (X0+X1)^2)``
    with ``X0 = -1/(C0 w)``, ``X1 = L w - 1/(C w)``. Every argument must be finite
    and > 0 (ValueError otherwise).
    """
    return _impedance(*positive(freq_hz=freq_hz, c0_f=c0_f, l_h=l_h, c_f=c_f, r_ohm=r_ohm))


def real_power_eq6(
    u_rms: npt.ArrayLike, freq_hz: npt.ArrayLike, c0_f: npt.ArrayLike, r_ohm: npt.ArrayLike, r0_ohm: npt.ArrayLike
) -> FloatOrArray:
    """Real power (W) at resonance, paper Eq. 6 exactly as written.

    ``P = Ui^2 / (R (1 + R0 sqrt(1/X0^2 + 1/R^2))^2)``, ``X0 = -1/(C0 w)``. Eq. 5
    adds ``|Z|`` and ``R0`` as magnitudes, so this is at most :func:`real_power_exact`
    at resonance, equal as ``R0 -> 0``. ``u_rms`` (V RMS) and ``r0_ohm`` must be
    >= 0, the others > 0 (ValueError otherwise).
    """
    u = non_negative("u_rms", u_rms)
    r0 = non_negative("r0_ohm", r0_ohm)
    freq, c0, r = positive(freq_hz=freq_hz, c0_f=c0_f, r_ohm=r_ohm)
    x0 = -1.0 / (c0 * 2.0 * np.pi * freq)
    power_w: FloatOrArray = u * u / (r * (1.0 + r0 * np.sqrt(1.0 / (x0 * x0) + 1.0 / (r * r))) ** 2)
    return power_w


def real_power_exact(
    u_rms: npt.ArrayLike,
    freq_hz: npt.ArrayLike,
    c0_f: npt.ArrayLike,
    l_h: npt.ArrayLike,
    c_f: npt.ArrayLike,
    r_ohm: npt.ArrayLike,
    r0_ohm: npt.ArrayLike,
) -> FloatOrArray:
    """Real power (W) delivered to the motional branch, ``|I_g|^2 R``, at any drive frequency.

    Solves the complex circuit: ``I = Ui / (R0 + Z)`` (``Z`` from Eq. 3), the
    actuator voltage ``I Z`` drives the branch ``R + j X1``. ``u_rms`` (V RMS) and
    ``r0_ohm`` must be >= 0, the others > 0 (ValueError otherwise).
    """
    u = non_negative("u_rms", u_rms)
    r0 = non_negative("r0_ohm", r0_ohm)
    freq, c0, inductance, c, r = positive(freq_hz=freq_hz, c0_f=c0_f, l_h=l_h, c_f=c_f, r_ohm=r_ohm)
    omega = 2.0 * np.pi * freq
    z = _impedance(freq, c0, inductance, c, r)
    u_actuator = u * z / (r0 + z)
    i_motional = u_actuator / (r + 1j * (inductance * omega - 1.0 / (c * omega)))
    power_w: FloatOrArray = (i_motional.real**2 + i_motional.imag**2) * r
    return power_w


def resonance_hz(l_h: npt.ArrayLike, c_f: npt.ArrayLike) -> FloatOrArray:
    """Series resonance (Hz) of the motional branch, ``1 / (2 pi sqrt(L C))``; L, C > 0 (ValueError otherwise)."""
    inductance, c = positive(l_h=l_h, c_f=c_f)
    resonance: FloatOrArray = 1.0 / (2.0 * np.pi * np.sqrt(inductance * c))
    return resonance


def quality_factor(l_h: npt.ArrayLike, c_f: npt.ArrayLike, r_ohm: npt.ArrayLike) -> FloatOrArray:
    """Quality factor ``sqrt(L / C) / R`` of the motional branch; all > 0 (ValueError otherwise)."""
    inductance, c, r = positive(l_h=l_h, c_f=c_f, r_ohm=r_ohm)
    q: FloatOrArray = np.sqrt(inductance / c) / r
    return q


def _thevenin(omega: FloatOrArray, c0_f: FloatOrArray, r0_ohm: FloatOrArray) -> tuple[ComplexOrArray, ComplexOrArray]:
    """``(voltage ratio, impedance in ohm)`` of the source behind R0 and C0, seen from the motional branch."""
    divider = 1.0 / (1.0 + 1j * omega * r0_ohm * c0_f)
    return cast(ComplexOrArray, divider), cast(ComplexOrArray, r0_ohm * divider)


def motional_current(
    u_peak_v: npt.ArrayLike,
    freq_hz: npt.ArrayLike,
    c0_f: npt.ArrayLike,
    l_h: npt.ArrayLike,
    c_f: npt.ArrayLike,
    r_ohm: npt.ArrayLike,
    r0_ohm: npt.ArrayLike,
) -> ComplexOrArray:
    """Steady complex motional current (A peak) for a source of ``u_peak_v`` (V peak) at ``freq_hz``.

    The source drives R0 in series with C0 parallel to the branch (``|I|^2 R / 2`` is
    :func:`real_power_exact`'s power for ``u_rms = u_peak / sqrt(2)``). ``u_peak_v`` and
    ``r0_ohm`` must be >= 0, the others > 0 (ValueError otherwise).
    """
    u = non_negative("u_peak_v", u_peak_v)
    r0 = non_negative("r0_ohm", r0_ohm)
    freq, c0, inductance, c, r = positive(freq_hz=freq_hz, c0_f=c0_f, l_h=l_h, c_f=c_f, r_ohm=r_ohm)
    omega = 2.0 * np.pi * freq
    ratio, z_th = _thevenin(omega, c0, r0)
    current: ComplexOrArray = u * ratio / (r + z_th + 1j * (inductance * omega - 1.0 / (c * omega)))
    return current


def plate_amplitude_m(
    u_peak_v: npt.ArrayLike,
    freq_hz: npt.ArrayLike,
    c0_f: npt.ArrayLike,
    l_h: npt.ArrayLike,
    c_f: npt.ArrayLike,
    r_ohm: npt.ArrayLike,
    r0_ohm: npt.ArrayLike,
    gamma_n_per_v: npt.ArrayLike,
) -> FloatOrArray:
    """Steady plate vibration amplitude (m peak), ``|I_g| / (gamma omega)``, for ``u_peak_v`` at ``freq_hz``.

    ``gamma_n_per_v`` (N/V) must be > 0; the rest as :func:`motional_current` (ValueError otherwise).
    """
    (gamma,) = positive(gamma_n_per_v=gamma_n_per_v)
    current = motional_current(u_peak_v, freq_hz, c0_f, l_h, c_f, r_ohm, r0_ohm)
    amplitude: FloatOrArray = np.abs(current) / (gamma * 2.0 * np.pi * np.asarray(freq_hz, dtype=np.float64))
    return amplitude


def loaded_time_constant_s(
    freq_hz: npt.ArrayLike, c0_f: npt.ArrayLike, l_h: npt.ArrayLike, r_ohm: npt.ArrayLike, r0_ohm: npt.ArrayLike
) -> FloatOrArray:
    """Time constant (s) of the motional current's envelope near ``freq_hz``: ``2 L / (R + Re Z_th)``.

    The unloaded ``Q / (pi f0)`` is ``2 L / R``; the shunt, seen through C0, adds
    ``Re Z_th`` of damping. ``r0_ohm`` must be >= 0, the others > 0 (ValueError otherwise).
    """
    r0 = non_negative("r0_ohm", r0_ohm)
    freq, c0, inductance, r = positive(freq_hz=freq_hz, c0_f=c0_f, l_h=l_h, r_ohm=r_ohm)
    _, z_th = _thevenin(2.0 * np.pi * freq, c0, r0)
    tau_s: FloatOrArray = 2.0 * inductance / (r + z_th.real)
    return tau_s


def loaded_resonance_hz(
    c0_f: npt.ArrayLike, l_h: npt.ArrayLike, c_f: npt.ArrayLike, r0_ohm: npt.ArrayLike
) -> FloatOrArray:
    """Resonance (Hz) of the motional branch as the source loads it: ``w L - 1 / (w C) + Im Z_th(w) = 0``.

    Above ``1 / (2 pi sqrt(L C))`` by a few parts in 10^5 for a TPaD (``Im Z_th`` is
    capacitive). Solved by fixed-point iteration from the unloaded resonance, to within
    1e-12 relative. ``r0_ohm`` must be >= 0, the others > 0 (ValueError otherwise).
    """
    r0 = non_negative("r0_ohm", r0_ohm)
    c0, inductance, c = positive(c0_f=c0_f, l_h=l_h, c_f=c_f)
    omega = 1.0 / np.sqrt(inductance * c)
    for _ in range(60):
        # For a fixed Im Z_th = x, w L - 1 / (w C) + x = 0 is a quadratic in w; its positive root.
        x = _thevenin(omega, c0, r0)[1].imag
        updated = (-x + np.sqrt(x * x + 4.0 * inductance / c)) / (2.0 * inductance)
        converged = bool(np.all(np.abs(updated - omega) <= 1e-13 * updated))
        omega = updated
        if converged:
            break
    resonance: FloatOrArray = omega / (2.0 * np.pi)
    return resonance


def detuning_factor(
    freq_hz: npt.ArrayLike, c0_f: npt.ArrayLike, l_h: npt.ArrayLike, c_f: npt.ArrayLike, r_ohm: npt.ArrayLike,
    r0_ohm: npt.ArrayLike,
) -> FloatOrArray:
    """``1 + (X / R_loop)^2`` at ``freq_hz``: how far a transient's power can exceed the steady power.

    ``X = w L - 1 / (w C) + Im Z_th`` and ``R_loop = R + Re Z_th`` are the branch loop's
    reactance and resistance at the drive frequency. The branch's complex envelope obeys
    ``2 L dI/dt = V_th - (R_loop + j X) I``; for any drive whose envelope stays within
    ``|V|``, ``|I|`` stays within ``|V_th| / R_loop`` (the impulse response's L1 norm),
    while the steady current is ``|V_th| / |R_loop + j X|``. So a power cap that uses the
    steady power per V^2 times this factor holds through every transient, detuned or not.
    1 at the loaded resonance. Ranges as :func:`motional_current` (ValueError otherwise).
    """
    r0 = non_negative("r0_ohm", r0_ohm)
    freq, c0, inductance, c, r = positive(freq_hz=freq_hz, c0_f=c0_f, l_h=l_h, c_f=c_f, r_ohm=r_ohm)
    omega = 2.0 * np.pi * freq
    _, z_th = _thevenin(omega, c0, r0)
    ratio = (inductance * omega - 1.0 / (c * omega) + z_th.imag) / (r + z_th.real)
    factor: FloatOrArray = 1.0 + ratio * ratio
    return factor
