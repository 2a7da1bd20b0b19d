"""Figures of the calibration fits: what a user looks at before trusting a device file.

API map
-------
impedance_figure(sweeps, fits) -> Figure
    |Z| and phase with the fit, the motional admittance circle, and the residuals, one colour per force
amplitude_figure(measurements, circuit, fit) -> Figure
    amplitude against volts per force with the one-gamma prediction, and each force's own gamma
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tpad_rt.calibrate.amplitude import Circuit, GammaFit
from tpad_rt.calibrate.impedance import BvdFit, model_impedance
from tpad_rt.calibrate.measurements import AmplitudeMeasurements, ImpedanceSweep
from tpad_rt.errors import printable
from tpad_rt.figures import pyplot

#: Points of a fitted curve across a sweep.
_CURVE_POINTS = 2000


#: More forces than this are told apart by a colour bar, not a legend entry each.
MAX_LEGEND_FORCES = 12


def _colors(count: int) -> list[Any]:
    return [pyplot().get_cmap("viridis")(value) for value in np.linspace(0.0, 0.85, max(count, 1))]


def _force_colorbar(figure: Any, panels: list[Any], forces: list[float]) -> None:
    """A colour bar of contact force for ``panels`` (the forces' colours, in order)."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import ListedColormap, Normalize

    scale = ScalarMappable(Normalize(min(forces), max(forces)), ListedColormap(_colors(256)))
    figure.colorbar(scale, ax=panels, label="contact force (N)", shrink=0.6)


def impedance_figure(sweeps: list[ImpedanceSweep], fits: list[BvdFit]) -> Any:
    """A 2 x 2 Figure: |Z| and phase (measured points, fitted curves), the motional admittance
    ``1/Z - j w C0`` as G against B (a circle for the BVD model), and the relative residuals."""
    plt = pyplot()
    figure, ((magnitude, phase), (circle, residual)) = plt.subplots(2, 2, figsize=(11.0, 8.5), layout="constrained")
    sources = sorted({sweep.source for sweep in sweeps})
    figure.suptitle(printable(f"Impedance fit: {', '.join(sources)}"), fontsize=12, fontweight="bold")
    legend = len(fits) <= MAX_LEGEND_FORCES
    for sweep, fit, color in zip(sweeps, fits, _colors(len(fits))):
        label = f"{fit.force_n:g} N" if fit.force_given else "0 N"
        freq_khz = sweep.freq_hz / 1e3
        curve_hz = np.linspace(sweep.freq_hz[0], sweep.freq_hz[-1], _CURVE_POINTS)
        model = model_impedance(curve_hz, fit)
        magnitude.plot(freq_khz, np.abs(sweep.impedance_ohm), ".", color=color, markersize=2.5, alpha=0.5)
        magnitude.plot(curve_hz / 1e3, np.abs(model), "-", color=color, linewidth=1.2,
                       label=f"{label}: f_s {fit.resonance_hz:.6g} Hz, Q {fit.q:.4g}, R {fit.r_ohm:.4g} ohm" if legend
                       else None)
        phase.plot(freq_khz, np.degrees(np.angle(sweep.impedance_ohm)), ".", color=color, markersize=2.5, alpha=0.5)
        phase.plot(curve_hz / 1e3, np.degrees(np.angle(model)), "-", color=color, linewidth=1.2,
                   label=label if legend else None)
        static = 1j * 2 * np.pi * sweep.freq_hz * fit.c0_f
        measured_y = 1.0 / sweep.impedance_ohm - static
        model_y = 1.0 / model - 1j * 2 * np.pi * curve_hz * fit.c0_f
        circle.plot(measured_y.real * 1e3, measured_y.imag * 1e3, ".", color=color, markersize=2.5, alpha=0.5)
        circle.plot(model_y.real * 1e3, model_y.imag * 1e3, "-", color=color, linewidth=1.2,
                    label=label if legend else None)
        error = (model_impedance(sweep.freq_hz, fit) - sweep.impedance_ohm) / np.abs(sweep.impedance_ohm)
        residual.plot(freq_khz, 100 * error.real, ".", color=color, markersize=2.5)
        residual.plot(freq_khz, 100 * error.imag, "x", color=color, markersize=2.5)
    magnitude.set(xlabel="frequency (kHz)", ylabel="|Z| (ohm)", title="|Z|: points measured, lines fitted")
    magnitude.set_yscale("log")
    phase.set(xlabel="frequency (kHz)", ylabel="phase of Z (degrees)", title="phase")
    circle.set(xlabel="G (mS)", ylabel="B - w C0 (mS)", title="motional admittance 1/Z - j w C0 (a circle)")
    circle.set_aspect("equal", adjustable="datalim")
    residual.set(xlabel="frequency (kHz)", ylabel="(Z fit - Z) / |Z| (%)", title="residuals (dots: real part, crosses: imaginary)")
    residual.axhline(0.0, color="0.5", linewidth=0.8)
    for panel in (magnitude, phase, circle, residual):
        panel.grid(alpha=0.3)
    if legend:
        for panel in (magnitude, phase, circle):
            panel.legend(fontsize=7, loc="upper right")
    else:
        _force_colorbar(figure, [magnitude, phase, circle, residual], [fit.force_n for fit in fits])
    return figure


def amplitude_figure(measurements: AmplitudeMeasurements, circuit: Circuit, fit: GammaFit) -> Any:
    """A 1 x 2 Figure: amplitude against volts per force with the one-gamma line, and each force's own gamma
    against the one gamma (the band is GAMMA_TOLERANCE)."""
    from tpad_rt.calibrate.amplitude import GAMMA_TOLERANCE

    plt = pyplot()
    figure, (amplitude, gammas) = plt.subplots(1, 2, figsize=(11.0, 4.8), layout="constrained")
    figure.suptitle(printable(f"Amplitude fit: {measurements.source}"), fontsize=12, fontweight="bold")
    forces = [force.force_n for force in fit.forces]
    legend = len(forces) <= MAX_LEGEND_FORCES
    for force, color in zip(forces, _colors(len(forces))):
        at = measurements.force_n == force
        volts = measurements.voltage_v[at]
        amplitude.plot(volts, measurements.amplitude_um[at], "o", color=color, markersize=4,
                       label=f"{force:g} N" if legend else None)
        line_v = np.linspace(0.0, float(volts.max()), 50)
        freq_hz = (float(np.median(measurements.freq_hz[at])) if measurements.freq_hz is not None
                   else float(fit.freq_hz or circuit.resonance_hz))
        freq = np.full(line_v.shape, freq_hz)
        branch = np.abs(circuit.branch_impedance(np.full(line_v.shape, force), freq))
        predicted_um = line_v / branch / (fit.gamma_n_per_v * 2 * np.pi * freq) * 1e6
        amplitude.plot(line_v, predicted_um, "-", color=color, linewidth=1.0)
    amplitude.set(xlabel="drive across the actuator (V peak)", ylabel="amplitude (um peak)",
                  title=f"points measured; lines: one gamma = {fit.gamma_n_per_v:.4g} N/V")
    amplitude.grid(alpha=0.3)
    if legend:
        amplitude.legend(fontsize=7, loc="upper left")
    else:
        _force_colorbar(figure, [amplitude], forces)
    own = [force.gamma_n_per_v for force in fit.forces]
    gammas.axhspan(fit.gamma_n_per_v * (1 - GAMMA_TOLERANCE), fit.gamma_n_per_v * (1 + GAMMA_TOLERANCE),
                   color="0.85", label=f"one gamma +-{100 * GAMMA_TOLERANCE:.0f} %")
    gammas.axhline(fit.gamma_n_per_v, color="0.3", linewidth=1.0)
    gammas.plot(forces, own, "o-", color="tab:red", label="each force's own gamma")
    gammas.set(xlabel="contact force (N)", ylabel="gamma (N/V)", title="does one gamma explain every force?")
    gammas.grid(alpha=0.3)
    gammas.legend(fontsize=7)
    return figure
