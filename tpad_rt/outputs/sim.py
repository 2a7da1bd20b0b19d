"""``sim://``: a simulated TPaD driven by the drive samples (no hardware needed).

The plate is the resonator of :mod:`tpad_rt.kernel.sim` at the device's resonance,
with the device's quality factor at the block's contact force (``?q=`` holds it fixed
instead) and the calibration gain ``amplitude_m_per_v(force)``. Per block it records
the plate's mean vibration amplitude ``plate_amplitude_um`` and the relative friction
the finger would feel, ``achieved_mu``: the forward friction model (paper Eqs. 2-3) at
that amplitude and the block's finger speed, raised to the device's speed floor when
slower (or unknown).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from tpad_rt.config.device_schema import MAX_Q, MIN_Q
from tpad_rt.device import Device
from tpad_rt.kernel.sim import COEF_SIZE, SIM_STATE_SIZE, resonate, resonator_coefficients
from tpad_rt.outputs.base import Consumes, Output, OutputKind, Runs
from tpad_rt.physics.friction import relative_friction_core
from tpad_rt.urls import Option, Url, UrlForm, number

_Q_NUMBER = number(MIN_Q, low_closed=False, high=MAX_Q)


def _quality_factor(text: str) -> float | str:
    """``device`` (the device's Q at each block's force) or a number in (MIN_Q, MAX_Q], as device files allow."""
    if text == "device":
        return text
    try:
        return _Q_NUMBER(text)
    except ValueError as error:
        raise ValueError(f"must be device or {str(error).removeprefix('must be ')}") from None


#: The accepted URL.
FORMS = (UrlForm("sim", "", (Option("q", "device", _quality_factor),)),)
#: What it consumes and what runs it.
KIND = OutputKind(Consumes.DAC, Runs.PACED, realtime_only=False)


class SimOutput(Output):
    """A simulated plate for ``device`` at ``fs_hz`` (Hz); ``q``: fixed quality factor, or None."""

    def __init__(self, device: Device, fs_hz: int, q: float | None = None):
        super().__init__(fs_hz)
        self.device = device
        self.q = q
        self._state = np.zeros(SIM_STATE_SIZE)
        self._coef = np.zeros(COEF_SIZE)
        self._coef_force_n = math.nan  # the force self._coef was computed for
        self._envelope_m = np.zeros(0)
        self._amplitude_um: list[float] = []
        self._achieved_mu: list[float] = []

    def write(self, samples: npt.NDArray[np.float32], block: Mapping[str, float]) -> None:
        """Drive the plate with ``samples`` (at least one); ``block`` must carry ``force_n`` (N) and ``speed_mm_s``.

        A force below 0 (or NaN) counts as 0: the device tables are clamped at their ends anyway.
        """
        force_n = float(block["force_n"])
        force_n = force_n if force_n >= 0.0 else 0.0
        device = self.device
        if force_n != self._coef_force_n:
            q = self.q if self.q is not None else float(device.quality_factor(force_n))
            resonator_coefficients(device.resonance_hz, q, float(device.amplitude_m_per_v(force_n)),
                                   float(self.fs_hz), self._coef)
            self._coef_force_n = force_n
        if len(self._envelope_m) < len(samples):
            self._envelope_m = np.zeros(len(samples))
        amplitude_m = resonate(samples, device.volts_per_full_scale, self._coef, self._state, self._envelope_m)
        speed_m_s = float(block["speed_mm_s"]) * 1e-3
        speed_m_s = max(speed_m_s, device.speed_floor_m_s) if math.isfinite(speed_m_s) else device.speed_floor_m_s
        self._amplitude_um.append(amplitude_m * 1e6)
        self._achieved_mu.append(relative_friction_core(
            amplitude_m, device.resonance_hz, speed_m_s, device.mu0, device.poisson, device.psi_star))

    def warm(self) -> None:
        """Run the plate model and the friction model once on scratch arrays (nothing recorded)."""
        coef, state = np.zeros(COEF_SIZE), np.zeros(SIM_STATE_SIZE)
        device = self.device
        resonator_coefficients(device.resonance_hz, 100.0, 1e-8, float(self.fs_hz), coef)
        resonate(np.zeros(1, dtype=np.float32), device.volts_per_full_scale, coef, state, np.zeros(1))
        relative_friction_core(1e-6, device.resonance_hz, 0.1, device.mu0, device.poisson, device.psi_star)

    def latest(self) -> dict[str, float]:
        """``plate_amplitude_um`` and ``achieved_mu`` of the last block written (none before the first)."""
        if not self._achieved_mu:
            return {}
        return {"plate_amplitude_um": self._amplitude_um[-1], "achieved_mu": self._achieved_mu[-1]}

    def measurements(self) -> dict[str, npt.NDArray[np.float64]]:
        """``plate_amplitude_um`` (mean envelope, um) and ``achieved_mu`` per block written."""
        return {
            "plate_amplitude_um": np.array(self._amplitude_um, dtype=np.float64),
            "achieved_mu": np.array(self._achieved_mu, dtype=np.float64),
        }


def open_url(url: Url, *, device: Device, fs_hz: int) -> SimOutput:
    """A SimOutput for ``device``; ConfigError for an unknown option, a bad ``q`` or a target."""
    values = FORMS[0].read(url)
    if url.target:
        raise url.fail(f"unexpected '{url.target}' after sim://", FORMS)
    return SimOutput(device, fs_hz, q=None if values["q"] == "device" else values["q"])
