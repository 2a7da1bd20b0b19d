"""``sim://``: a simulated TPaD driven by the drive samples (no hardware needed).

The plate is the resonator of :mod:`tpad_rt.kernel.sim` (:func:`plate_resonator`): at
the block's contact force, the device's motional branch as the shunt and C0 load it,
its resonance and loaded quality factor (``?q=`` holds the quality factor fixed
instead), with the steady gain ``amplitude_m_per_v(force)`` at the carrier. A carrier
off that resonance (contact detunes the plate) beats in every transient, as on the real
circuit. Per block it records
the plate's mean vibration amplitude ``plate_amplitude_um`` (at an antinode) and the
relative friction the finger would feel, ``achieved_mu``: the forward friction model
(paper Eqs. 2-3) at the amplitude under the finger and the block's finger speed, raised
to the device's speed floor when slower (or unknown). The amplitude under the finger is
the antinode's times :meth:`Device.mode_gain` at the block's ``x_mm`` on a device with a
mode shape (the standing wave averaged over the contact patch), the antinode's without.

It keeps the measurements until taken (:meth:`SimOutput.take_measurements`): an offline
render reads them all at its end, the paced driver moves them into the run's telemetry
log after every step (:mod:`tpad_rt.drivers.paced`), where ``tpad-rt play`` reads them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from tpad_rt.config.device_schema import MAX_Q, MIN_Q
from tpad_rt.device import Device
from tpad_rt.kernel.sim import (
    COEF_SIZE,
    SIM_STATE_SIZE,
    felt_friction,
    resonate,
    resonate_blocks,
    resonator_coefficients,
)
from tpad_rt.physics.friction import relative_friction_core
from tpad_rt.outputs.base import Capability, Consumes, Output, OutputKind
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
KIND = OutputKind(Consumes.DAC, "tpad_rt.drivers.paced:PacedDriver", Capability.OFFLINE)


def plate_resonator(device: Device, force_n: float, fs_hz: float, coef: np.ndarray, q: float | None = None) -> None:
    """Fill ``coef`` (COEF_SIZE) with the simulated plate at contact force ``force_n`` (N, >= 0), sampled at
    ``fs_hz``: the loaded motional resonance, the loaded quality factor (or ``q``), and the device's steady
    amplitude per volt at its carrier."""
    resonator_coefficients(
        float(device.motional_resonance_hz(force_n)),
        float(device.loaded_quality_factor(force_n)) if q is None else q,
        float(device.amplitude_m_per_v(force_n)),
        device.carrier_hz,
        float(fs_hz),
        coef,
    )


class SimOutput(Output):
    """A simulated plate for ``device`` at ``fs_hz`` (Hz); ``q``: fixed quality factor, or None."""

    def __init__(self, device: Device, fs_hz: int, q: float | None = None):
        super().__init__(fs_hz)
        self.device = device
        self.q = q
        self._state = np.zeros(SIM_STATE_SIZE)
        self._coef_force_n = math.nan  # the contact force (N) self._coef_now is for
        self._coef_now = np.zeros(COEF_SIZE)
        self._envelope_m = np.zeros(0)
        self._amplitude_um: list[float] = []
        self._achieved_mu: list[float] = []
        self._latest: dict[str, float] = {}  # the last block's, taken or not

    def _coef(self, force_n: float) -> np.ndarray:
        """The resonator coefficients at contact force ``force_n`` (N, >= 0): recomputed when the force changes
        (only the last force's are kept: an input whose force varies does not grow memory)."""
        if force_n != self._coef_force_n:
            device = self.device
            self._coef_now = np.zeros(COEF_SIZE)
            plate_resonator(device, force_n, self.fs_hz, self._coef_now, self.q)
            self._coef_force_n = force_n
        return self._coef_now

    def _speeds_m_s(self, speed_mm_s: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Finger speeds (m/s) for the friction model: raised to the device's floor, the floor where unknown
        (what :meth:`write` does for one block)."""
        speed_m_s = speed_mm_s * 1e-3
        floor_m_s = self.device.speed_floor_m_s
        return np.where(np.isfinite(speed_m_s), np.maximum(speed_m_s, floor_m_s), floor_m_s)

    def _mode_gains(self, blocks: Mapping[str, Any]) -> npt.NDArray[np.float64]:
        """The amplitude under the finger over the antinode's at ``blocks["x_mm"]`` (read only on a device with a
        mode shape: 1 without); a position that is not finite counts as the plate's end at x = 0."""
        force_n = np.asarray(blocks["force_n"])
        if self.device.contact_width_m is None:
            return np.ones(force_n.shape)
        return self.device.mode_gain(np.nan_to_num(np.asarray(blocks["x_mm"], dtype=np.float64), nan=0.0))

    def write(self, samples: npt.NDArray[np.float32], block: Mapping[str, float]) -> None:
        """Drive the plate with ``samples`` (at least one); ``block`` must carry ``force_n`` (N) and ``speed_mm_s``,
        and on a device with a mode shape ``x_mm``.

        A force below 0 (or NaN) counts as 0: the device tables are clamped at their ends anyway.
        """
        force_n = float(block["force_n"])
        force_n = force_n if force_n >= 0.0 else 0.0
        if len(self._envelope_m) < len(samples):
            self._envelope_m = np.zeros(len(samples))
        device = self.device
        amplitude_m = resonate(samples, device.volts_per_full_scale, self._coef(force_n), self._state, self._envelope_m)
        speed_m_s = float(block["speed_mm_s"]) * 1e-3
        speed_m_s = max(speed_m_s, device.speed_floor_m_s) if math.isfinite(speed_m_s) else device.speed_floor_m_s
        under_finger_m = amplitude_m * float(self._mode_gains(block))
        achieved_mu = relative_friction_core(under_finger_m, device.carrier_hz, speed_m_s, device.mu0,
                                             device.poisson, device.psi_star)
        self._amplitude_um.append(amplitude_m * 1e6)  # both or neither: a block is measured whole
        self._achieved_mu.append(achieved_mu)
        self._latest = {"plate_amplitude_um": amplitude_m * 1e6, "achieved_mu": achieved_mu}

    def write_blocks(self, samples: npt.NDArray[np.float32], block_frames: int,
                     blocks: Mapping[str, npt.NDArray[Any]]) -> None:
        """Drive the plate with consecutive blocks of ``block_frames`` samples, block ``k`` at contact force
        ``blocks["force_n"][k]`` (N; below 0 or NaN counts as 0), finger speed ``blocks["speed_mm_s"][k]`` and
        (with a mode shape) position ``blocks["x_mm"][k]``; natively, with the rules of :meth:`write` (the offline render's path; tests compare the two)."""
        force_n = np.asarray(blocks["force_n"], dtype=np.float64)
        count = len(force_n)
        force_n = np.where(force_n >= 0.0, force_n, 0.0)
        forces, coef_rows = np.unique(force_n, return_inverse=True)
        coefs = np.array([self._coef(float(force)) for force in forces]).reshape(len(forces), COEF_SIZE)
        if len(self._envelope_m) < block_frames:
            self._envelope_m = np.zeros(block_frames)
        device = self.device
        amplitude_m = np.zeros(count)
        resonate_blocks(samples, block_frames, device.volts_per_full_scale, coefs, coef_rows.astype(np.int64),
                        self._state, self._envelope_m, amplitude_m)
        speed_m_s = self._speeds_m_s(np.asarray(blocks["speed_mm_s"], dtype=np.float64))
        achieved_mu = np.zeros(count)
        felt_friction(amplitude_m * self._mode_gains(blocks), speed_m_s, device.carrier_hz, device.mu0, device.poisson, device.psi_star,
                      achieved_mu)
        self._amplitude_um.extend((amplitude_m * 1e6).tolist())
        self._achieved_mu.extend(achieved_mu.tolist())
        if count:
            self._latest = {"plate_amplitude_um": self._amplitude_um[-1], "achieved_mu": self._achieved_mu[-1]}

    def warm(self, batch: bool = False) -> None:
        """Run the plate model and the friction model of :meth:`write` (with ``batch``, of :meth:`write_blocks`)
        once on scratch arrays (nothing recorded)."""
        coef, state = np.zeros((1, COEF_SIZE)), np.zeros(SIM_STATE_SIZE)
        device = self.device
        resonator_coefficients(device.carrier_hz, 100.0, 1e-8, device.carrier_hz, float(self.fs_hz), coef[0])
        silence = np.zeros(1, dtype=np.float32)
        if batch:
            amplitude_m, mu_rel = np.zeros(1), np.zeros(1)
            resonate_blocks(silence, 1, device.volts_per_full_scale, coef, np.zeros(1, np.int64), state, np.zeros(1),
                            amplitude_m)
            felt_friction(amplitude_m, np.full(1, 0.1), device.carrier_hz, device.mu0, device.poisson,
                          device.psi_star, mu_rel)
        else:
            resonate(silence, device.volts_per_full_scale, coef[0], state, np.zeros(1))
            relative_friction_core(1e-6, device.carrier_hz, 0.1, device.mu0, device.poisson, device.psi_star)

    def latest(self) -> dict[str, float]:
        """``plate_amplitude_um`` and ``achieved_mu`` of the last block written (none before the first)."""
        return dict(self._latest)

    def take_measurements(self) -> dict[str, npt.NDArray[np.float64]]:
        """:meth:`measurements`, then forget them: the paced driver takes them after every step (into the
        telemetry log), so a real-time run keeps none here."""
        taken = self.measurements()
        self._amplitude_um, self._achieved_mu = [], []
        return taken

    def measurements(self) -> dict[str, npt.NDArray[np.float64]]:
        """``plate_amplitude_um`` (mean envelope, um) and ``achieved_mu`` per block written since the last
        :meth:`take_measurements` (both names, empty before a block)."""
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
