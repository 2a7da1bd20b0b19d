"""Butterworth-Van Dyke model of a TPaD's piezo actuator (paper Section V, Eqs. 2-6).

The static capacitance ``C0`` is in parallel with the motional branch ``L``, ``C``,
``R`` (the plate and the finger reflected onto the electrical side); the shunt
resistor ``R0`` is in series with the whole. SI units: Hz, F, H, ohm, V (RMS), W.

The ``*_core`` functions are numba-compiled scalar kernels without input checks;
the public functions validate their inputs and broadcast like NumPy ufuncs.
"""

from __future__ import annotations

import math

import numba
import numpy.typing as npt

from tpad_rt.physics._validate import ComplexOrArray, FloatOrArray, non_negative, positive


@numba.njit(cache=True, nogil=True)
def impedance_core(freq_hz: float, c0_f: float, l_h: float, c_f: float, r_ohm: float) -> complex:
    """Impedance (ohm) of C0 in parallel with L, C, R: paper Eq. 3. No input checks."""
    omega = 2.0 * math.pi * freq_hz
    x0 = -1.0 / (c0_f * omega)
    x1 = l_h * omega - 1.0 / (c_f * omega)
    denominator = r_ohm * r_ohm + (x0 + x1) ** 2
    return complex(x0 * x0 * r_ohm / denominator, x0 * (r_ohm * r_ohm + x0 * x1 + x1 * x1) / denominator)


@numba.njit(cache=True, nogil=True)
def real_power_eq6_core(u_rms: float, freq_hz: float, c0_f: float, r_ohm: float, r0_ohm: float) -> float:
    """Real power (W) at resonance, paper Eq. 6 as written. No input checks."""
    x0 = -1.0 / (c0_f * 2.0 * math.pi * freq_hz)
    return u_rms * u_rms / (r_ohm * (1.0 + r0_ohm * math.sqrt(1.0 / (x0 * x0) + 1.0 / (r_ohm * r_ohm))) ** 2)


@numba.njit(cache=True, nogil=True)
def real_power_exact_core(
    u_rms: float, freq_hz: float, c0_f: float, l_h: float, c_f: float, r_ohm: float, r0_ohm: float
) -> float:
    """Real power (W) into the motional branch, |I_g|^2 R, from the complex circuit. No input checks."""
    omega = 2.0 * math.pi * freq_hz
    z = impedance_core(freq_hz, c0_f, l_h, c_f, r_ohm)
    u_actuator = u_rms * z / (r0_ohm + z)
    i_motional = u_actuator / complex(r_ohm, l_h * omega - 1.0 / (c_f * omega))
    return (i_motional.real**2 + i_motional.imag**2) * r_ohm


@numba.njit(cache=True, nogil=True)
def resonance_hz_core(l_h: float, c_f: float) -> float:
    """Series resonance (Hz) of the motional branch, 1 / (2 pi sqrt(L C)). No input checks."""
    return 1.0 / (2.0 * math.pi * math.sqrt(l_h * c_f))


@numba.njit(cache=True, nogil=True)
def quality_factor_core(l_h: float, c_f: float, r_ohm: float) -> float:
    """Quality factor sqrt(L / C) / R of the motional branch. No input checks."""
    return math.sqrt(l_h / c_f) / r_ohm


@numba.vectorize(cache=True)
def _impedance_ufunc(freq_hz, c0_f, l_h, c_f, r_ohm):  # type: ignore[no-untyped-def]
    return impedance_core(freq_hz, c0_f, l_h, c_f, r_ohm)


@numba.vectorize(cache=True)
def _real_power_eq6_ufunc(u_rms, freq_hz, c0_f, r_ohm, r0_ohm):  # type: ignore[no-untyped-def]
    return real_power_eq6_core(u_rms, freq_hz, c0_f, r_ohm, r0_ohm)


@numba.vectorize(cache=True)
def _real_power_exact_ufunc(u_rms, freq_hz, c0_f, l_h, c_f, r_ohm, r0_ohm):  # type: ignore[no-untyped-def]
    return real_power_exact_core(u_rms, freq_hz, c0_f, l_h, c_f, r_ohm, r0_ohm)


@numba.vectorize(cache=True)
def _resonance_hz_ufunc(l_h, c_f):  # type: ignore[no-untyped-def]
    return resonance_hz_core(l_h, c_f)


@numba.vectorize(cache=True)
def _quality_factor_ufunc(l_h, c_f, r_ohm):  # type: ignore[no-untyped-def]
    return quality_factor_core(l_h, c_f, r_ohm)


def impedance(
    freq_hz: npt.ArrayLike, c0_f: npt.ArrayLike, l_h: npt.ArrayLike, c_f: npt.ArrayLike, r_ohm: npt.ArrayLike
) -> ComplexOrArray:
    """Complex impedance (ohm) of the TPaD (C0 parallel to L, C, R), paper Eqs. 2-3.

    ``Z = X0^2 R / (R^2 + (X0+X1)^2) + j X0 (R^2 + X0 X1 + X1^2) / (R^2 + (X0+X1)^2)``
    with ``X0 = -1/(C0 w)``, ``X1 = L w - 1/(C w)``. Every argument must be finite
    and > 0 (ValueError otherwise).
    """
    return _impedance_ufunc(*positive(freq_hz=freq_hz, c0_f=c0_f, l_h=l_h, c_f=c_f, r_ohm=r_ohm))


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
    return _real_power_eq6_ufunc(u, *positive(freq_hz=freq_hz, c0_f=c0_f, r_ohm=r_ohm), r0)


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
    circuit = positive(freq_hz=freq_hz, c0_f=c0_f, l_h=l_h, c_f=c_f, r_ohm=r_ohm)
    return _real_power_exact_ufunc(u, *circuit, r0)


def resonance_hz(l_h: npt.ArrayLike, c_f: npt.ArrayLike) -> FloatOrArray:
    """Series resonance (Hz) of the motional branch, ``1 / (2 pi sqrt(L C))``; L, C > 0 (ValueError otherwise)."""
    return _resonance_hz_ufunc(*positive(l_h=l_h, c_f=c_f))


def quality_factor(l_h: npt.ArrayLike, c_f: npt.ArrayLike, r_ohm: npt.ArrayLike) -> FloatOrArray:
    """Quality factor ``sqrt(L / C) / R`` of the motional branch; all > 0 (ValueError otherwise)."""
    return _quality_factor_ufunc(*positive(l_h=l_h, c_f=c_f, r_ohm=r_ohm))
