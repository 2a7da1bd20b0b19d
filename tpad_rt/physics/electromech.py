"""Butterworth-Van Dyke model of a TPaD's piezo actuator (paper Section V, Eqs. 2-6).

The static capacitance ``C0`` is in parallel with the motional branch ``L``, ``C``,
``R`` (the plate and the finger reflected onto the electrical side); the shunt
resistor ``R0`` is in series with the whole. SI units: Hz, F, H, ohm, V (RMS), W.

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
