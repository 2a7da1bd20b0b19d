"""Fitting the Butterworth-Van Dyke circuit to a measured impedance sweep (``tpad-rt calibrate impedance``).

The model is the actuator's impedance as the paper fits it (Section V, Eqs. 2-3): C0
in parallel with the motional branch L, C, R. It is fitted in four parameters that an
impedance sweep determines independently: C0, the series resonance ``f_s = 1 / (2 pi
sqrt(L C))``, the quality factor ``Q = sqrt(L / C) / R`` and R; then ``L = Q R / (2 pi
f_s)`` and ``C = 1 / (2 pi f_s Q R)``.

1. A robust start, from the admittance ``Y = 1 / Z``: its real part (the conductance)
   is the motional branch's alone, a peak of height ``1 / R`` at ``f_s`` whose
   half-power points lie ``f_s / Q`` apart (the admittance circle's diameter and
   quadrature points). C0 is then the median of what is left of the susceptance.
2. A refinement by nonlinear least squares (scipy's Levenberg-Marquardt) of the
   relative complex error ``(Z_model - Z) / |Z|``, in the logarithms of the four
   parameters.
3. Standard uncertainties from the fit's Jacobian, scaled by the residual variance.

It refuses a sweep the model cannot describe, saying why: no conductance peak, a peak at
the sweep's edge, a peak buried in the noise, fewer than MIN_BAND_POINTS points inside
the half-power band, a second mode in the band, a fit that does not converge. It warns
(``BvdFit.warnings``) when a parameter's uncertainty exceeds UNCERTAIN_FRACTION or the
residuals hold structure the model does not explain.

API map
-------
fit_sweep(sweep) -> BvdFit
    the fitted circuit of one ImpedanceSweep; ConfigError when the model does not fit
model_impedance(freq_hz, fit) -> complex array
    the fitted circuit's impedance (ohm)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from tpad_rt.calibrate.measurements import ImpedanceSweep
from tpad_rt.errors import ConfigError
from tpad_rt.physics import electromech

#: Fewest sweep points inside the half-power band ``f_s +- f_s / (2 Q)``: fewer cannot pin down Q.
MIN_BAND_POINTS = 5
#: A conductance peak other than the resonance's, at least this fraction of its height, SECOND_MODE_NOISE
#: times the conductance's point-to-point noise, and more than SECOND_MODE_BANDWIDTHS half-power bandwidths
#: from it, is a second mode.
SECOND_MODE_FRACTION = 0.2
SECOND_MODE_NOISE = 6.0
SECOND_MODE_BANDWIDTHS = 3.0
#: The conductance peak must stand this many times above the sweep's point-to-point noise.
MIN_PEAK_TO_NOISE = 5.0
#: A fitted parameter whose relative standard uncertainty is above this is reported as poorly determined
#: (three of them then exceed 2 %).
UNCERTAIN_FRACTION = 0.007
#: Residuals whose RMS exceeds their point-to-point noise by this factor, and STRUCTURE_FLOOR (relative), hold
#: structure the model lacks.
STRUCTURE_RATIO = 3.0
STRUCTURE_FLOOR = 1e-4
#: Points in the running median that smooths the conductance before its peak is sought.
_SMOOTHING_POINTS = 5

#: The keys of the fitted quantities, in the order the JSON and the table show them.
QUANTITIES = ("c0_nf", "motional_l_h", "motional_c_pf", "motional_r_ohm", "resonance_hz", "q")

#: The circuit's own parameters, which a device file keeps (f_s and Q follow from them).
_CIRCUIT = QUANTITIES[:4]

_Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class BvdFit:
    """The circuit fitted to one sweep (SI), with relative standard uncertainties by QUANTITIES key."""

    source: str
    force_n: float
    force_given: bool
    c0_f: float
    l_h: float
    c_f: float
    r_ohm: float
    points: int
    band_points: int
    rms_residual: float
    uncertainty: dict[str, float]
    warnings: tuple[str, ...] = field(default=())

    @property
    def resonance_hz(self) -> float:
        """Series resonance of the motional branch, ``1 / (2 pi sqrt(L C))`` (Hz)."""
        return 1.0 / (2.0 * math.pi * math.sqrt(self.l_h * self.c_f))

    @property
    def q(self) -> float:
        """Quality factor of the motional branch, ``sqrt(L / C) / R``."""
        return math.sqrt(self.l_h / self.c_f) / self.r_ohm

    def values(self) -> dict[str, float]:
        """The fitted quantities in the units their QUANTITIES keys name."""
        return {"c0_nf": self.c0_f * 1e9, "motional_l_h": self.l_h, "motional_c_pf": self.c_f * 1e12,
                "motional_r_ohm": self.r_ohm, "resonance_hz": self.resonance_hz, "q": self.q}

    def as_json(self) -> dict[str, Any]:
        """The fit as ``tpad-rt calibrate impedance --json`` prints it."""
        return {
            "force_n": self.force_n,
            **self.values(),
            "uncertainty_percent": {key: 100.0 * value for key, value in self.uncertainty.items()},
            "rms_residual_percent": 100.0 * self.rms_residual,
            "points": self.points,
            "points_in_band": self.band_points,
            "source": self.source,
            "warnings": list(self.warnings),
        }


def model_impedance(freq_hz: npt.ArrayLike, fit: BvdFit) -> npt.NDArray[np.complex128]:
    """The impedance (ohm) of ``fit``'s circuit at ``freq_hz`` (Hz, > 0)."""
    return np.asarray(electromech.impedance(freq_hz, fit.c0_f, fit.l_h, fit.c_f, fit.r_ohm), dtype=np.complex128)


def _impedance(freq_hz: _Array, log_params: _Array) -> npt.NDArray[np.complex128]:
    """Impedance (ohm) of C0 || (L, C, R) for ``log(C0, f_s, Q, R)``, without input checks."""
    c0_f, fs_hz, q, r_ohm = np.exp(log_params)
    motional_y = 1.0 / (r_ohm * (1.0 + 1j * q * (freq_hz / fs_hz - fs_hz / freq_hz)))
    return 1.0 / (1j * 2.0 * np.pi * freq_hz * c0_f + motional_y)


def _smoothed(values: _Array) -> _Array:
    """A running median over _SMOOTHING_POINTS points (the ends use what they have)."""
    from scipy.ndimage import median_filter  # type: ignore[import-untyped]

    return np.asarray(median_filter(values, size=_SMOOTHING_POINTS, mode="nearest"), dtype=np.float64)


def _noise(values: _Array) -> float:
    """Point-to-point noise of ``values``: a robust standard deviation of their differences over sqrt(2)."""
    differences = np.diff(values)
    return float(1.4826 * np.median(np.abs(differences - np.median(differences))) / math.sqrt(2.0))


def _half_power_crossing(freq_hz: _Array, excess: _Array, peak: int, half: float, step: int) -> float | None:
    """Frequency (Hz) where ``excess`` first falls below ``half`` walking from ``peak`` by ``step``; None if never."""
    index = peak
    while 0 <= index + step < len(excess):
        if excess[index + step] < half:
            inside, outside = excess[index], excess[index + step]
            fraction = (inside - half) / (inside - outside)
            return float(freq_hz[index] + fraction * (freq_hz[index + step] - freq_hz[index]))
        index += step
    return None


@dataclass(frozen=True)
class _Start:
    log_params: _Array
    bandwidth_hz: float
    peak_s: float


def _start(sweep: ImpedanceSweep) -> _Start:
    """The robust first estimate (module docstring, step 1); ConfigError when there is no usable resonance."""
    freq, admittance = sweep.freq_hz, 1.0 / sweep.impedance_ohm
    conductance = _smoothed(admittance.real)
    base = max(float(conductance.min()), 0.0)
    excess = conductance - base
    peak = int(np.argmax(excess))
    height = float(excess[peak])
    noise = _noise(admittance.real)
    where = f"{sweep.label}: the model does not fit"
    if height <= 0.0:
        raise ConfigError(f"{where}: the conductance Re(1/Z) has no peak: no resonance in the sweep")
    if height < MIN_PEAK_TO_NOISE * noise:
        raise ConfigError(f"{where}: the conductance peak at {freq[peak]:.6g} Hz is only {height / noise:.1f} times "
                          f"the point-to-point noise (at least {MIN_PEAK_TO_NOISE:g} needed): the resonance is "
                          "buried in noise; average more, or drive the analyser harder")
    if peak < 2 or peak > len(freq) - 3:
        raise ConfigError(f"{where}: the conductance peaks at the sweep's edge ({freq[peak]:.6g} Hz): the resonance "
                          "is outside the sweep; widen it")
    below = _half_power_crossing(freq, excess, peak, height / 2, -1)
    above = _half_power_crossing(freq, excess, peak, height / 2, +1)
    if below is None and above is None:
        raise ConfigError(f"{where}: the sweep does not reach the half-power points of the resonance near "
                          f"{freq[peak]:.6g} Hz on either side: widen it")
    half_widths = [abs(crossing - freq[peak]) for crossing in (below, above) if crossing is not None]
    bandwidth = 2.0 * float(np.mean(half_widths))
    fs, r_ohm = float(freq[peak]), 1.0 / height
    q = fs / bandwidth
    omega = 2.0 * np.pi * freq
    reactance = r_ohm * q * (freq / fs - fs / freq)
    motional_b = -reactance / (r_ohm * r_ohm + reactance * reactance)
    c0_f = float(np.median((admittance.imag - motional_b) / omega))
    if not c0_f > 0.0:
        edges = np.concatenate([admittance.imag[:max(2, len(freq) // 20)], admittance.imag[-max(2, len(freq) // 20):]])
        if np.all(edges < 0.0):
            raise ConfigError(f"{where}: the susceptance Im(1/Z) is not a capacitor's (C0 would be {c0_f:.3g} F): is "
                              "the phase's sign as the format says (about -90 degrees for a piezo)?")
        raise ConfigError(f"{where}: the motional branch outweighs C0 across the whole sweep (its conductance peak "
                          f"1/R = {height:.3g} S, C0's susceptance too small to start from): widen the sweep to take "
                          "in the antiresonance above the resonance")
    return _Start(np.log([c0_f, fs, q, r_ohm]), bandwidth, height)


def _second_mode(freq_hz: _Array, conductance: _Array, resonance_hz: float, bandwidth_hz: float,
                 height: float) -> tuple[float, float] | None:
    """``(frequency Hz, height fraction)`` of the tallest conductance peak away from the resonance; None if none."""
    from scipy.signal import find_peaks  # type: ignore[import-untyped]

    prominence = max(SECOND_MODE_FRACTION * height, SECOND_MODE_NOISE * _noise(conductance))
    peaks, properties = find_peaks(_smoothed(conductance), prominence=prominence)
    far = [(properties["prominences"][i], freq_hz[p]) for i, p in enumerate(peaks)
           if abs(freq_hz[p] - resonance_hz) > SECOND_MODE_BANDWIDTHS * bandwidth_hz]
    if not far:
        return None
    prominence, frequency = max(far)
    return float(frequency), float(prominence / height)


def _uncertainty(jacobian: _Array, residuals: _Array) -> dict[str, float]:
    """Relative standard uncertainties by QUANTITIES key, from the Jacobian in log parameters.

    The covariance is ``V diag(1 / s^2) V^T`` times the residual variance, from the
    Jacobian's singular values ``s`` with no cutoff (a pseudo-inverse's would drop a
    direction the sweep barely determines and report its parameter as certain); a
    singular value below the Jacobian's rounding counts as that rounding.
    """
    dof = max(len(residuals) - jacobian.shape[1], 1)
    variance = float(residuals @ residuals) / dof
    _, singular, vt = np.linalg.svd(jacobian, full_matrices=False)
    floor = max(float(singular.max(initial=0.0)) * np.finfo(np.float64).eps, np.finfo(np.float64).tiny)
    covariance = (vt.T / np.maximum(singular, floor) ** 2) @ vt * variance
    # Rows: d log(quantity) / d log(C0, f_s, Q, R).
    transform = np.array([
        [1.0, 0.0, 0.0, 0.0],    # C0
        [0.0, -1.0, 1.0, 1.0],   # L = Q R / (2 pi f_s)
        [0.0, -1.0, -1.0, -1.0],  # C = 1 / (2 pi f_s Q R)
        [0.0, 0.0, 0.0, 1.0],    # R
        [0.0, 1.0, 0.0, 0.0],    # f_s
        [0.0, 0.0, 1.0, 0.0],    # Q
    ])
    variances = np.einsum("ij,jk,ik->i", transform, covariance, transform)
    # A direction no point determines (an overflowed or NaN variance) is an infinite uncertainty
    return {key: math.sqrt(max(float(value), 0.0)) if math.isfinite(value) else math.inf
            for key, value in zip(QUANTITIES, variances)}


def fit_sweep(sweep: ImpedanceSweep) -> BvdFit:
    """The BVD circuit fitted to ``sweep`` (module docstring).

    Raises ConfigError ``file, force: the model does not fit: why`` when the sweep has no
    usable resonance, too few points near it, a second mode in the band, or the fit
    does not converge.
    """
    from scipy.optimize import least_squares  # type: ignore[import-untyped]

    freq, measured = sweep.freq_hz, sweep.impedance_ohm
    scale = np.abs(measured)
    where = f"{sweep.label}: the model does not fit"
    start = _start(sweep)
    fs_start = math.exp(start.log_params[1])
    band = np.abs(freq - fs_start) <= start.bandwidth_hz / 2
    band_points = int(np.count_nonzero(band))
    if band_points < MIN_BAND_POINTS:
        step_hz = start.bandwidth_hz / MIN_BAND_POINTS
        raise ConfigError(f"{where}: too few points near the resonance: {band_points} inside the half-power band "
                          f"{fs_start - start.bandwidth_hz / 2:.6g}-{fs_start + start.bandwidth_hz / 2:.6g} Hz, at "
                          f"least {MIN_BAND_POINTS} needed: sweep in steps of {step_hz:.3g} Hz or finer there")
    second = _second_mode(freq, (1.0 / measured).real, fs_start, start.bandwidth_hz, start.peak_s)
    if second is not None:
        raise ConfigError(f"{where}: a second mode in the band at {second[0]:.6g} Hz (its conductance peak is "
                          f"{100 * second[1]:.0f} % of the resonance's at {fs_start:.6g} Hz): trim the sweep to one "
                          "mode")

    def residuals(log_params: _Array) -> _Array:
        error = (_impedance(freq, log_params) - measured) / scale
        return np.concatenate([error.real, error.imag])

    with np.errstate(all="ignore"):  # trial steps may overflow; a fit that ends there is refused below
        result = least_squares(residuals, start.log_params, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12,
                               max_nfev=2000)
    if not result.success or not np.all(np.isfinite(result.x)):
        raise ConfigError(f"{where}: the least-squares fit did not converge ({result.message})")
    c0_f, fs_hz, q, r_ohm = (float(value) for value in np.exp(result.x))
    if not freq[0] <= fs_hz <= freq[-1]:
        raise ConfigError(f"{where}: the fitted resonance {fs_hz:.6g} Hz lies outside the sweep "
                          f"({freq[0]:.6g}-{freq[-1]:.6g} Hz): widen it")
    fitted = np.asarray(result.fun, dtype=np.float64)
    uncertainty = _uncertainty(np.asarray(result.jac, dtype=np.float64), fitted)
    l_h = q * r_ohm / (2.0 * math.pi * fs_hz)
    c_f = 1.0 / (2.0 * math.pi * fs_hz * q * r_ohm)
    rms = float(np.sqrt(np.mean(fitted * fitted)))
    warnings = [
        f"{key} is poorly determined: +-{100 * value:.2g} % (more points near the resonance, or averaging, help)"
        for key, value in uncertainty.items() if key in _CIRCUIT and value > UNCERTAIN_FRACTION
    ]
    half = len(freq)
    noise = max(_noise(fitted[:half]), _noise(fitted[half:]))
    if rms > max(STRUCTURE_RATIO * noise, STRUCTURE_FLOOR):
        warnings.append(f"the residuals (RMS {100 * rms:.2g} %) are {rms / noise:.1f} times the point-to-point noise: "
                        "the circuit does not explain the sweep fully (dielectric loss, a nearby mode, a drifting "
                        "temperature?)")
    return BvdFit(sweep.source, sweep.force_n, sweep.force_given, c0_f, l_h, c_f, r_ohm, len(freq), band_points, rms,
                  uncertainty, tuple(warnings))
