"""Reference render pipeline: a slow, sample-by-sample Python loop written from docs/kernel.md.

``render_reference(device, textures, fs_hz, options, fingers, n_samples, run=...)``
renders a stream from sample 0 and returns its drive samples and, per control step,
what the kernel's telemetry reports. It uses the Device's own methods (np.interp of
its tables, the exact circuit) and the physics' public functions, the texture
reference (``reference_friction`` on the texture models), and none of the kernel's
arrays, tables or layout. It is written in the doc's recurrent form (one-pole
update per sample, carrier phase from an exact fraction, ring sums recomputed), not
in the kernel's closed forms.

What it shares with the kernel is the contract: control steps at ``n % C == 0``; the
finger read at control steps only (so is RUN); limits with the relative margin
``SAFETY_MARGIN``; until a finger is first active the step's finger values (and force
for the power estimate) are 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Any, Sequence

import numpy as np
from reference.texture_ref import reference_friction

from tpad_rt.device import Device
from tpad_rt.physics.friction import amplitude_for
from tpad_rt.pipeline import RenderOptions

#: docs/kernel.md: every limit is kept with this relative margin against rounding.
SAFETY_MARGIN = 1e-6
#: docs/kernel.md "Per sample": a plate over the power cap by more than this at a new force is braked.
MODEL_GUARD_FRACTION = 0.02
VOLTAGE, POWER, SPEED_FLOOR, WATCHDOG, SHAPER_LIMIT = 1, 2, 4, 8, 32
STEP_FIELDS = (
    "t", "x_mm", "y_mm", "speed_mm_s", "force_n", "target_mu", "amplitude_um", "command_v", "cap_v",
    "gate", "flags", "power_w", "peak_v", "shaper_margin_v", "plate_w",
)


@dataclass
class Reference:
    """A rendered stream: ``samples`` (float32), ``envelope`` (V per sample), ``steps`` (per control step)."""

    samples: np.ndarray
    envelope: np.ndarray
    steps: dict[str, np.ndarray]


@dataclass
class _Finger:
    """The finger as the control step sees it."""

    active: bool
    x_mm: float = 0.0
    y_mm: float = 0.0
    vx_mm_s: float = 0.0
    vy_mm_s: float = 0.0
    force_n: float = 0.0


def _finger_at(fingers: np.ndarray, t_s: float, options: RenderOptions) -> _Finger:
    """The newest sample at or before ``t_s``, its velocity over the touch, position extrapolated."""
    earlier = np.flatnonzero(fingers[:, 0] <= t_s)
    if earlier.size == 0:
        return _Finger(False)
    i = earlier[-1]
    t_i, x_i, y_i, force_n, down = fingers[i]
    watchdog_s = options.watchdog_ms / 1000
    if down == 0 or t_s - t_i > watchdog_s:
        return _Finger(False)
    j = i
    heading = np.zeros(2)  # the newest step that moved; a step against it is a reversal and ends the stroke
    while j > 0 and fingers[j - 1, 4] != 0 and t_i - fingers[j - 1, 0] <= options.velocity_window_ms / 1000:
        step = fingers[j, 1:3] - fingers[j - 1, 1:3]
        if float(step @ heading) < 0:
            break
        if not heading.any():
            heading = step
        j -= 1
    vx = vy = 0.0
    if t_i > fingers[j, 0]:
        vx = (x_i - fingers[j, 1]) / (t_i - fingers[j, 0])
        vy = (y_i - fingers[j, 2]) / (t_i - fingers[j, 0])
    lead_s = min(t_s - t_i + options.horizon_ms / 1000, watchdog_s)
    force_n = options.default_force_n if math.isnan(force_n) else force_n
    return _Finger(True, x_i + vx * lead_s, y_i + vy * lead_s, vx, vy, force_n)


class _Stream:
    """The carried state of the reference renderer (what the kernel keeps in ``state``)."""

    def __init__(self, device: Device, fs_hz: float, options: RenderOptions):
        self.device, self.fs_hz, self.options = device, fs_hz, options
        self.cap_w = device.power_budget_w if options.power_budget_w is None else options.power_budget_w
        self.avg_w = self.cap_w if options.power_avg_w is None else options.power_avg_w
        self.window_steps = max(1, round(options.power_window_s * fs_hz / options.control_interval))
        self.ramp_samples = max(1, round(options.ramp_ms / 1000 * fs_hz))
        self.k_smooth = 1 - math.exp(-1 / (options.smoothing_ms / 1000 * fs_hz))
        self.preemphasis = device.preemphasis if options.preemphasis is None else options.preemphasis
        self.carrier = Fraction(device.carrier_hz) / Fraction(fs_hz)
        self.step_powers: list[float] = []
        self.finger = _Finger(False)
        self.target_mu = 0.0
        self.command_v = 0.0
        self.smoothed_v = 0.0
        self.model_v = 0.0  # the shaper's first-order model of the plate envelope (volts of drive)
        self.model_gain_m_per_v = 0.0  # the plate amplitude per volt those volts were worth (0: none yet)
        self.slip_v = 0.0  # the volts the plate holds beyond the model (force changes the guard let pass)
        self.press_braking = False  # braking a pressed plate until the model is back down on the command
        # the most volts a press can make the plate model hold: the volts limit times the gain's span over the forces
        gains = device.amplitude_m_per_v(np.linspace(device.force_table_n[0], device.force_table_n[-1], 4097))
        self.model_bound_v = device.max_voltage_v * min(float(gains.max() / gains.min()), 1e6)
        self.ramp = 0

    def control_step(self, n: int, fingers: np.ndarray, texture: Any, t0_s: float, run: bool) -> dict[str, float]:
        """Finger, texture, inverse model and limits at sample ``n``; the step's record."""
        device, options = self.device, self.options
        t_s = n / self.fs_hz
        finger = _finger_at(fingers, t_s, options)
        flags = 0
        if finger.active:
            self.finger = finger
            speed_mm_s = math.hypot(finger.vx_mm_s, finger.vy_mm_s)
            ux, uy = (finger.vx_mm_s / speed_mm_s, finger.vy_mm_s / speed_mm_s) if speed_mm_s > 0 else (0.0, 0.0)
            mu = float(reference_friction(texture, finger.x_mm, finger.y_mm, ux, uy, t_s - t0_s))
            self.target_mu = min(max(mu, options.mu_floor), 1.0)
            speed_m_s = speed_mm_s / 1000
            if speed_m_s < device.speed_floor_m_s:
                speed_m_s, flags = device.speed_floor_m_s, SPEED_FLOOR
            alpha_m = amplitude_for(self.target_mu, device.carrier_hz, speed_m_s, device.mu0, device.poisson,
                                    device.psi_star)
            self.command_v = float(alpha_m / device.amplitude_m_per_v(max(finger.force_n, 0.0)))
        else:
            flags = WATCHDOG
        force_n = max(self.finger.force_n, 0.0)
        self.p1_w = float(device.power_w_per_v2(force_n))
        keep = 1 - SAFETY_MARGIN
        previous_w = sum(self.step_powers[-(self.window_steps - 1):]) if self.window_steps > 1 else 0.0
        allowance_w = max(self.window_steps * self.avg_w * keep - previous_w, 0.0)
        power_v = math.sqrt(min(self.cap_w * keep, allowance_w) / self.p1_w)
        voltage_v = device.max_voltage_v * keep
        self.cap_v, bound = (voltage_v, VOLTAGE) if voltage_v <= power_v else (power_v, POWER)
        if self.command_v > self.cap_v:
            self.command_v, flags = self.cap_v, flags | bound
        # A plate holding more than the power cap (plus MODEL_GUARD_FRACTION) allows at its now lower gain is braked:
        # the model takes the volts that amplitude is worth now
        gain_m_per_v = float(device.amplitude_m_per_v(force_n))
        if self.model_gain_m_per_v > 0:
            held_v = (self.model_v + self.slip_v) * (self.model_gain_m_per_v / gain_m_per_v)
            held_v = min(max(held_v, -self.model_bound_v), self.model_bound_v)
            if held_v > 0 and held_v**2 * self.p1_w > self.cap_w * (1 + MODEL_GUARD_FRACTION):
                self.model_v, self.slip_v = held_v, 0.0
            else:
                self.slip_v = held_v - self.model_v
        self.model_gain_m_per_v = gain_m_per_v
        self.plate_w = self.p1_w * (self.model_v + self.slip_v) ** 2  # the plate's power, as modelled
        tau_s = float(device.envelope_time_constant_s(force_n))
        self.model_step = 1 - math.exp(-1 / (tau_s * self.fs_hz))
        # braking: to -cap, or to the full volts from a step whose plate holds more than the cap until the model is
        # back down on the command (then with the shaper, pre-emphasis or not)
        landing = self.press_braking and self.model_v + self.slip_v > self.smoothed_v
        pressed = (self.plate_w > self.cap_w * (1 + MODEL_GUARD_FRACTION) or landing) and options.braking
        self.press_braking = pressed
        self.follow_gain = 1 / self.model_step if self.preemphasis or pressed else 0.0
        brake_v = device.max_voltage_v * keep if pressed else self.cap_v
        self.low_v = -brake_v if options.braking and self.follow_gain else 0.0
        self.gate = finger.active and run
        self.energy_v2: list[float] = []
        self.step_flags = flags
        self.shaper_margin_v = math.inf  # how near a shaper drive came to a limit, either side, in this step (V)
        f = self.finger
        return dict(
            t=t_s, x_mm=f.x_mm, y_mm=f.y_mm, speed_mm_s=math.hypot(f.vx_mm_s, f.vy_mm_s), force_n=f.force_n,
            target_mu=self.target_mu,
            amplitude_um=self.command_v * float(device.amplitude_m_per_v(force_n)) * 1e6,
            command_v=self.command_v, cap_v=self.cap_v, gate=float(self.gate), flags=flags, plate_w=self.plate_w,
        )

    def sample(self, n: int) -> tuple[float, float]:
        """Drive envelope (V) and DAC sample of sample ``n`` (the doc's per-sample recurrences)."""
        self.smoothed_v += self.k_smooth * (self.command_v - self.smoothed_v)
        self.ramp = min(max(self.ramp + (1 if self.gate else -1), 0), self.ramp_samples)
        if self.ramp < self.ramp_samples or not self.follow_gain:
            envelope_v = self.ramp / self.ramp_samples * min(max(self.smoothed_v, 0.0), self.cap_v)
        else:
            drive_v = self.model_v + self.follow_gain * (self.smoothed_v - self.model_v)
            envelope_v = min(max(drive_v, self.low_v), self.cap_v)
            if envelope_v != drive_v:
                self.step_flags |= SHAPER_LIMIT
            self.shaper_margin_v = min(self.shaper_margin_v, abs(min(self.cap_v - drive_v, drive_v - self.low_v)))
        self.model_v += self.model_step * (envelope_v - self.model_v)
        self.slip_v *= 1 - self.model_step  # the plate follows the same drive: what it holds beyond decays
        phase = n * self.carrier
        sine = math.sin(2 * math.pi * float(phase - math.floor(phase)))
        self.energy_v2.append(envelope_v * envelope_v)
        return envelope_v, envelope_v / self.device.volts_per_full_scale * sine

    def close_step(self) -> tuple[float, float]:
        """The finished step's power ``p1 * mean(e^2)`` (W), at most ``p1 * cap^2`` (braking a pressed plate at the
        full volts counts as braking at the cap), remembered for the window, and its peak (V)."""
        drive_w = min(self.p1_w * sum(self.energy_v2) / len(self.energy_v2), self.p1_w * self.cap_v**2)
        self.step_powers.append(drive_w)
        return drive_w, math.sqrt(max(self.energy_v2))


def _in_effect(schedule: Sequence[tuple[Any, ...]], n: int) -> tuple[Any, ...]:
    """The last entry of ``schedule`` (sorted by first sample) starting at or before sample ``n``."""
    return [entry for entry in schedule if entry[0] <= n][-1]


def render_reference(
    device: Device,
    textures: Sequence[tuple[int, Any, float]],
    fs_hz: float,
    options: RenderOptions,
    fingers: np.ndarray,
    n_samples: int,
    run: Sequence[tuple[int, bool]] = ((0, True),),
) -> Reference:
    """Samples ``0 .. n_samples - 1`` of a stream.

    ``textures``: ``(first_sample, texture_model, t0_s)``, the texture in effect from that
    sample on (the first at sample 0); ``run``: ``(first_sample, running)``, the RUN
    flag from that sample on (the first at sample 0); ``fingers``: rows ``(t_s, x_mm, y_mm, force_n, down)``,
    all known from the start. ``steps`` holds one entry per control step of
    :data:`STEP_FIELDS` (``power_w`` and ``peak_v`` over the step's samples).
    """
    stream = _Stream(device, fs_hz, options)
    interval = options.control_interval
    samples = np.zeros(n_samples, dtype=np.float32)
    envelope = np.zeros(n_samples)
    steps: list[dict[str, float]] = []
    for n in range(n_samples):
        if n % interval == 0:
            if steps:
                steps[-1]["power_w"], steps[-1]["peak_v"] = stream.close_step()
            _, texture, t0_s = _in_effect(textures, n)
            _, running = _in_effect(run, n)
            steps.append(stream.control_step(n, fingers, texture, t0_s, running))
        envelope[n], value = stream.sample(n)
        samples[n] = np.float32(value)
        steps[-1]["flags"] = stream.step_flags
        steps[-1]["shaper_margin_v"] = stream.shaper_margin_v
    steps[-1]["power_w"], steps[-1]["peak_v"] = stream.close_step()
    return Reference(samples, envelope, {name: np.array([step[name] for step in steps]) for name in STEP_FIELDS})
