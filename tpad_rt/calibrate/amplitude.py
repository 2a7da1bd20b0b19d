"""Fitting the one transduction factor gamma to amplitude measurements (``tpad-rt calibrate amplitude``).

The motional current is ``i_g = gamma dX/dt`` (paper Fig. 8): at a drive of ``V`` volts
peak across the actuator at angular frequency ``w``, the branch ``R + j (w L - 1/(w C))``
carries ``|I_g| = V / |Z_m|`` and moves the plate ``X = |I_g| / (gamma w)``. So each
measured row gives ``gamma = V / (|Z_m| w X)``, with the branch interpolated at the
row's force from the circuit (impedance fits or a device file).

``gamma`` is the geometric mean over every row; its uncertainty the standard error of
``log gamma``. Per force the fit reports how linear the amplitude is in volts (the
largest departure from the line through the origin) and how far that force's own gamma
lies from the one gamma: the test of the model, where the paper's files needed a gamma
1.66-2.24x larger at 2 N than at 0 N.

API map
-------
fit_gamma(measurements, circuit, freq_hz=None) -> GammaFit
Circuit
    the motional branch against force that the rows are interpreted with
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from tpad_rt.calibrate.measurements import AmplitudeMeasurements
from tpad_rt.device import Device
from tpad_rt.errors import ConfigError

#: A force whose amplitude departs from proportional to volts by more than this fraction is flagged.
LINEARITY_TOLERANCE = 0.05
#: A force whose own gamma lies further than this fraction from the one gamma is flagged.
GAMMA_TOLERANCE = 0.10
#: A drive frequency more than this factor from the circuit's resonance is a mistake (kHz for Hz, rad/s for Hz):
#: a plate's amplitude is measured near its resonance.
FREQUENCY_FACTOR = 2.0

_Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Circuit:
    """The motional branch (SI) at ascending ``force_n`` knots, interpolated linearly and clamped at the ends;
    ``resonance_hz`` is the default drive frequency (the branch's series resonance at the lowest force)."""

    force_n: _Array
    l_h: _Array
    c_f: _Array
    r_ohm: _Array

    @classmethod
    def of_device(cls, device: Device) -> Circuit:
        """The motional branch of ``device``'s circuit."""
        return cls(device.force_table_n, device.motional_l_h_table, device.motional_c_f_table,
                   device.motional_r_ohm_table)

    @property
    def resonance_hz(self) -> float:
        return float(1.0 / (2.0 * math.pi * math.sqrt(self.l_h[0] * self.c_f[0])))

    def branch_impedance(self, force_n: _Array, freq_hz: _Array) -> npt.NDArray[np.complex128]:
        """``R + j (w L - 1 / (w C))`` (ohm) at each force (N) and frequency (Hz)."""
        l_h, c_f, r_ohm = (np.interp(force_n, self.force_n, table) for table in (self.l_h, self.c_f, self.r_ohm))
        omega = 2.0 * np.pi * freq_hz
        return np.asarray(r_ohm + 1j * (omega * l_h - 1.0 / (omega * c_f)), dtype=np.complex128)


@dataclass(frozen=True)
class ForceGamma:
    """One force's rows: their count, their own gamma (N/V), its departure from the one gamma, and the
    largest departure of amplitude from proportional to volts (fractions; None with one voltage)."""

    force_n: float
    points: int
    gamma_n_per_v: float
    deviation: float
    linearity: float | None


@dataclass(frozen=True)
class GammaFit:
    """The one gamma (N/V) with its relative standard uncertainty, per-force results, and warnings."""

    source: str
    gamma_n_per_v: float
    uncertainty: float
    freq_hz: float | None
    forces: tuple[ForceGamma, ...]
    warnings: tuple[str, ...] = field(default=())

    @property
    def worst_deviation(self) -> float:
        """The largest departure of a force's gamma from the one gamma (fraction)."""
        return max(abs(force.deviation) for force in self.forces)

    def as_json(self) -> dict[str, Any]:
        """The fit as ``tpad-rt calibrate amplitude --json`` prints it."""
        return {
            "gamma_n_per_v": self.gamma_n_per_v,
            "uncertainty_percent": 100.0 * self.uncertainty,
            "freq_hz": self.freq_hz,
            "worst_deviation_percent": 100.0 * self.worst_deviation,
            "forces": [
                {"force_n": force.force_n, "points": force.points, "gamma_n_per_v": force.gamma_n_per_v,
                 "deviation_percent": 100.0 * force.deviation,
                 "linearity_percent": None if force.linearity is None else 100.0 * force.linearity}
                for force in self.forces
            ],
            "source": self.source,
            "warnings": list(self.warnings),
        }


def _linearity(voltage_v: _Array, amplitude: _Array) -> float | None:
    """Largest relative departure of ``amplitude`` from the least-squares line through the origin; None when
    every row has the same voltage (nothing to judge linearity by)."""
    if np.ptp(voltage_v) <= 1e-9 * float(voltage_v.max()):
        return None
    slope = float(voltage_v @ amplitude / (voltage_v @ voltage_v))
    return float(np.max(np.abs(amplitude - slope * voltage_v) / amplitude))


def fit_gamma(measurements: AmplitudeMeasurements, circuit: Circuit, freq_hz: float | None = None) -> GammaFit:
    """The one gamma that explains ``measurements`` through ``circuit`` (module docstring).

    Each row's drive frequency is its ``freq_hz`` column, else ``freq_hz`` (Hz), else the
    circuit's resonance at its lowest force. Raises ConfigError when a drive frequency
    lies more than FREQUENCY_FACTOR from that resonance or a row's gamma is not finite.
    """
    rows = len(measurements.force_n)
    if measurements.freq_hz is not None:
        freq = measurements.freq_hz
        used_hz = None
    else:
        used_hz = circuit.resonance_hz if freq_hz is None else freq_hz
        freq = np.full(rows, used_hz)
    far = np.flatnonzero((freq > FREQUENCY_FACTOR * circuit.resonance_hz) | (freq < circuit.resonance_hz / FREQUENCY_FACTOR))
    if far.size:
        given = "the drive frequency" if measurements.freq_hz is None else f"row {far[0] + 1}'s freq_hz"
        raise ConfigError(f"{measurements.source}: {given}, {freq[far[0]]:g} Hz, is far from the circuit's resonance "
                          f"({circuit.resonance_hz:.6g} Hz): amplitudes are measured near it (in Hz, not kHz)")
    warnings = []
    low, high = float(circuit.force_n[0]), float(circuit.force_n[-1])
    outside = np.flatnonzero((measurements.force_n < low - 1e-9) | (measurements.force_n > high + 1e-9))
    if outside.size:
        warnings.append(f"forces outside the circuit's {low:g}-{high:g} N (e.g. {measurements.force_n[outside[0]]:g} "
                        "N) use the circuit at its nearest end")
    current_a = measurements.voltage_v / np.abs(circuit.branch_impedance(measurements.force_n, freq))
    amplitude_m = measurements.amplitude_um * 1e-6
    gammas = current_a / (2.0 * np.pi * freq * amplitude_m)
    if not np.all(np.isfinite(gammas) & (gammas > 0.0)):
        raise ConfigError(f"{measurements.source}: a row gives no finite gamma (check its values)")
    logs = np.log(gammas)
    gamma = float(np.exp(logs.mean()))
    uncertainty = float(logs.std(ddof=1) / math.sqrt(rows)) if rows > 1 else math.inf
    forces = []
    for force in np.unique(measurements.force_n):
        at = measurements.force_n == force
        own = float(np.exp(logs[at].mean()))
        linearity = _linearity(measurements.voltage_v[at], measurements.amplitude_um[at])
        forces.append(ForceGamma(float(force), int(at.sum()), own, own / gamma - 1.0, linearity))
        if linearity is not None and linearity > LINEARITY_TOLERANCE:
            warnings.append(f"at {force:g} N the amplitude departs from proportional to volts by up to "
                            f"{100 * linearity:.1f} %: the plate is not linear there (drive lower?)")
    spread = [force for force in forces if abs(force.deviation) > GAMMA_TOLERANCE]
    if spread:
        worst = max(spread, key=lambda force: abs(force.deviation))
        warnings.append(f"one gamma does not explain every force: at {worst.force_n:g} N the rows need "
                        f"{worst.gamma_n_per_v:.4g} N/V, {100 * worst.deviation:+.0f} % from {gamma:.4g} N/V (is the "
                        "circuit measured at the same forces and points as the amplitudes?)")
    if rows == 1:
        warnings.append("one row: gamma's uncertainty is unknown; measure at several volts and forces")
    return GammaFit(measurements.source, gamma, uncertainty, used_hz, tuple(forces), tuple(warnings))
