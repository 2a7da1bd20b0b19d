"""Finding a plate's resonance through a serial amplifier that measures current (``tpad-rt calibrate sweep``).

The amplifier (docs/amp-protocol.md) makes the carrier and reports, in every STATUS, the
rms voltage at its output, the rms current through the shunt, and the phase of the
current against the voltage. Holding a small constant envelope (DEFAULT_DRIVE_V, or
1/8 of the device's max volts if less: milliwatts on resonance) at one carrier after
another gives the impedance the amplifier sees, ``Z = V / I`` at ``-phase``; less the
device's shunt, that is the actuator's impedance, the sweep ``calibrate impedance``
fits.

1. A coarse sweep, COARSE_POINTS carriers over ``--from-hz``/``--to-hz`` (default
   +-COARSE_SPAN of the device's carrier), finds the conductance peak, ``Re(1/Z)``: the
   motional branch's resonance.
2. A fine sweep, FINE_POINTS carriers over +-FINE_BANDWIDTHS half-power bandwidths of
   it (the bandwidth from the coarse sweep's half-power points), is fitted with the
   Butterworth-Van Dyke circuit (:func:`tpad_rt.calibrate.impedance.fit_sweep`).

The result is the fitted circuit, its series resonance ``1 / (2 pi sqrt(L C))``, the
loaded resonance (the frequency to drive at, with the shunt and C0: what
``Device.motional_resonance_hz`` gives), and where the phase of Z is nearest zero.
Each carrier is held for ``dwell_s`` (long enough for the plate to settle: a few
envelope time constants, default_dwell_s) before its STATUS is read.

API map
-------
sweep(link, freqs_hz, drive_v, dwell_s, shunt_ohm, progress=None) -> ImpedanceSweep
find_resonance(link, device, drive_v, dwell_s, low_hz=None, high_hz=None, progress=None) -> SweepResult
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from tpad_rt.calibrate.impedance import BvdFit, fit_sweep
from tpad_rt.calibrate.measurements import ImpedanceSweep
from tpad_rt.errors import BackendError
from tpad_rt.physics import electromech

if TYPE_CHECKING:  # annotations only: the device loads pydantic, the amplifier link the kernels
    from tpad_rt.device import Device
    from tpad_rt.outputs.serial_amp import AmpLink

#: The drive held while sweeping (V peak), at most 1/8 of the device's max volts.
DEFAULT_DRIVE_V = 5.0
#: How long each carrier is held before it is measured: at least MIN_DWELL_S (s), and DWELL_TIME_CONSTANTS of the
#: device's slowest envelope, at most MAX_DWELL_S (the longest --dwell-ms; default_dwell_s).
MIN_DWELL_S = 0.02
MAX_DWELL_S = 10.0
DWELL_TIME_CONSTANTS = 5.0
#: The coarse sweep: this many carriers over +-COARSE_SPAN of the device's carrier.
COARSE_POINTS = 81
COARSE_SPAN = 0.04
#: The fine sweep: this many carriers over +-FINE_BANDWIDTHS half-power bandwidths of the coarse peak.
FINE_POINTS = 101
FINE_BANDWIDTHS = 5.0
#: What the amplifier must measure (INFO ``measures`` bits): current and phase.
_CURRENT, _PHASE = 1, 4

Progress = Callable[[int, int], None]


def default_dwell_s(device: Device) -> float:
    """How long (s) to hold each carrier on ``device``: DWELL_TIME_CONSTANTS of its slowest envelope time constant
    (over its calibrated forces: the plate without contact rings longest), within [MIN_DWELL_S, MAX_DWELL_S]."""
    slowest_s = float(np.max(device.envelope_time_constant_s(device.force_table_n)))
    return min(max(MIN_DWELL_S, DWELL_TIME_CONSTANTS * slowest_s), MAX_DWELL_S)


def sweep(link: AmpLink, freqs_hz: np.ndarray, drive_v: float, dwell_s: float, shunt_ohm: float,
          progress: Progress | None = None, source: str = "sweep") -> ImpedanceSweep:
    """The actuator's impedance at each carrier of ``freqs_hz`` (Hz, ascending), holding ``drive_v`` (V peak) for
    ``dwell_s`` at each; ``progress(done, total)`` after each. The carriers are the amplifier's achieved ones.

    BackendError when the amplifier cannot measure current and phase, or the link fails.
    """
    info = link.info
    assert info is not None
    if info.measures & (_CURRENT | _PHASE) != _CURRENT | _PHASE:
        raise BackendError(f"serial: the amplifier on {link.target.port} does not measure both current and phase "
                           f"(INFO measures = {info.measures}): calibrate sweep needs them")
    achieved, impedance = [], []
    for done, freq_hz in enumerate(freqs_hz, start=1):
        link.set_carrier(float(freq_hz))
        status = link.tone(drive_v, dwell_s)
        if status.current_a_rms <= 0.0:
            raise BackendError(f"serial: the amplifier on {link.target.port} measured no current at "
                               f"{status.carrier_hz:g} Hz: is the plate connected?")
        total = status.voltage_v_rms / status.current_a_rms * np.exp(-1j * math.radians(status.phase_deg))
        achieved.append(status.carrier_hz)
        impedance.append(total - shunt_ohm)
        if progress is not None:
            progress(done, len(freqs_hz))
    freq = np.asarray(achieved, dtype=np.float64)
    order = np.argsort(freq, kind="stable")
    return ImpedanceSweep(source, math.nan, False, freq[order], np.asarray(impedance, dtype=np.complex128)[order])


@dataclass(frozen=True)
class SweepResult:
    """A resonance search: the coarse and fine sweeps, the circuit fitted to the fine one, the loaded resonance
    (Hz) with the device's shunt, and the carrier (Hz) where the phase of Z came nearest zero (None if the phase
    never came within ZERO_PHASE_DEG of it: a weakly coupled piezo stays capacitive)."""

    coarse: ImpedanceSweep
    fine: ImpedanceSweep
    fit: BvdFit
    loaded_resonance_hz: float
    zero_phase_hz: float | None

    def as_json(self) -> dict[str, object]:
        """The result as ``tpad-rt calibrate sweep --json`` prints it."""
        return {
            "resonance_hz": self.fit.resonance_hz,
            "loaded_resonance_hz": self.loaded_resonance_hz,
            "zero_phase_hz": self.zero_phase_hz,
            "q": self.fit.q,
            "c0_nf": self.fit.c0_f * 1e9,
            "motional_l_h": self.fit.l_h,
            "motional_c_pf": self.fit.c_f * 1e12,
            "motional_r_ohm": self.fit.r_ohm,
            "uncertainty_percent": {key: 100.0 * value for key, value in self.fit.uncertainty.items()},
            "points": len(self.coarse.freq_hz) + len(self.fine.freq_hz),
            "warnings": list(self.fit.warnings),
        }


#: A phase of Z within this many degrees of zero counts as the zero-phase point.
ZERO_PHASE_DEG = 5.0


def _peak_and_bandwidth(coarse: ImpedanceSweep) -> tuple[float, float]:
    """The coarse sweep's conductance peak (Hz) and its half-power bandwidth (Hz, at least two steps)."""
    conductance = (1.0 / coarse.impedance_ohm).real
    peak = int(np.argmax(conductance))
    base = float(conductance.min())
    half = base + (conductance[peak] - base) / 2
    above = np.flatnonzero(conductance >= half)
    step = float(np.median(np.diff(coarse.freq_hz)))
    width = max(float(coarse.freq_hz[above[-1]] - coarse.freq_hz[above[0]]), 2.0 * step)
    return float(coarse.freq_hz[peak]), width


def find_resonance(link: AmpLink, device: Device, drive_v: float, dwell_s: float, low_hz: float | None = None,
                   high_hz: float | None = None, progress: Progress | None = None) -> SweepResult:
    """The coarse sweep, the fine sweep and the fit (module docstring), within the amplifier's carrier range.

    ConfigError when the fine sweep does not fit the model (its message says why); BackendError for the link.
    """
    info = link.info
    assert info is not None
    low = device.carrier_hz * (1 - COARSE_SPAN) if low_hz is None else low_hz
    high = device.carrier_hz * (1 + COARSE_SPAN) if high_hz is None else high_hz
    low, high = max(low, info.carrier_min_hz), min(high, info.carrier_max_hz)
    total = COARSE_POINTS + FINE_POINTS

    def coarse_progress(done: int, _: int) -> None:
        if progress is not None:
            progress(done, total)

    def fine_progress(done: int, _: int) -> None:
        if progress is not None:
            progress(COARSE_POINTS + done, total)

    coarse = sweep(link, np.linspace(low, high, COARSE_POINTS), drive_v, dwell_s, device.shunt_ohm, coarse_progress,
                   "coarse sweep")
    peak_hz, width_hz = _peak_and_bandwidth(coarse)
    fine_low = max(peak_hz - FINE_BANDWIDTHS * width_hz, info.carrier_min_hz)
    fine_high = min(peak_hz + FINE_BANDWIDTHS * width_hz, info.carrier_max_hz)
    fine = sweep(link, np.linspace(fine_low, fine_high, FINE_POINTS), drive_v, dwell_s, device.shunt_ohm,
                 fine_progress, "fine sweep")
    fine = ImpedanceSweep(f"the fine sweep around {peak_hz:.6g} Hz", fine.force_n, False, fine.freq_hz,
                          fine.impedance_ohm)
    fit = fit_sweep(fine)
    loaded_hz = float(electromech.loaded_resonance_hz(fit.c0_f, fit.l_h, fit.c_f, device.shunt_ohm))
    phase = np.degrees(np.angle(fine.impedance_ohm))
    nearest = int(np.argmin(np.abs(phase)))
    zero_hz = float(fine.freq_hz[nearest]) if abs(phase[nearest]) <= ZERO_PHASE_DEG else None
    return SweepResult(coarse, fine, fit, loaded_hz, zero_hz)
