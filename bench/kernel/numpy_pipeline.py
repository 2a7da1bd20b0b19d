"""The render pipeline in vectorised NumPy: the benchmark's baseline (what one writes without numba).

``NumpyPipeline(device, texture_model, fs_hz, options)`` has the offline surface the
bench needs (``push_fingers``, ``start``, ``render(out)``; the texture set at time 0)
and the semantics of docs/kernel.md: everything per control step (finger search, velocity, texture,
inverse model, device tables) is vectorised over the block's control steps; what
depends on the previous step (the power window, the hold of the command, the
smoothing and ramp state) is a Python loop over the block's steps, each step's
samples vectorised. The texture is evaluated by the NumPy texture reference of the
test suite (``tests/reference/texture_ref.py``), so the tests directory must be on
``sys.path``. The bench checks its samples against the kernel's.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from reference.texture_ref import reference_friction

from tpad_rt.device import Device
from tpad_rt.kernel import layout
from tpad_rt.kernel.layout import FLAG_POWER, FLAG_SPEED_FLOOR, FLAG_VOLTAGE, FLAG_WATCHDOG
from tpad_rt.kernel.render import SAFETY_MARGIN
from tpad_rt.pipeline import RenderOptions, device_tables


class NumpyPipeline:
    """One stream, from sample 0, rendered block by block (any block size)."""

    def __init__(self, device: Device, texture: Any, fs_hz: float, options: RenderOptions):
        self.device, self.texture, self.fs_hz, self.options = device, texture, fs_hz, options
        self.interval = options.control_interval
        tables, self.grid_start_n, self.grid_step_n = device_tables(device)
        # The rows this pipeline models (the kernel's tables hold more: carrier, mode gain, reactance).
        self.tables = tables[[layout.DEV_AMP_M_PER_V, layout.DEV_POWER_W_PER_V2, layout.DEV_TAU_S]]
        self.cap_w = device.power_budget_w if options.power_budget_w is None else options.power_budget_w
        self.avg_w = self.cap_w if options.power_avg_w is None else options.power_avg_w
        self.ring = np.zeros(max(1, round(options.power_window_s * fs_hz / self.interval)))
        self.window_w = 0.0
        self.slot = -1
        self.decay = math.exp(-1.0 / (options.smoothing_ms / 1000 * fs_hz))
        self.ramp_samples = max(1, round(options.ramp_ms / 1000 * fs_hz))
        self.preemphasis = device.preemphasis if options.preemphasis is None else options.preemphasis
        self.fingers = np.zeros((0, 5))
        self.running = False
        self.sample_index = 0
        self.held = dict(x_mm=0.0, y_mm=0.0, speed_mm_s=0.0, force_n=0.0, target_mu=0.0, command_v=0.0)
        self.smoothed_v = 0.0
        self.ramp = 0.0
        self.step: dict[str, Any] | None = None
        self.telemetry: list[tuple[float, float, int]] = []

    def push_fingers(self, rows: np.ndarray) -> None:
        """Append finger rows ``(t_s, x_mm, y_mm, force_n, down)`` (times non-decreasing)."""
        self.fingers = np.vstack([self.fingers, rows])

    def start(self) -> None:
        """Let the drive ramp up while a finger slides."""
        self.running = True

    # --- per control step, vectorised over the block's steps ----------------------------

    def _device(self, force_n: np.ndarray) -> np.ndarray:
        """``[amplitude per volt, p1, tau]`` at each force: linear on the pipeline's force grid."""
        last = self.tables.shape[1] - 1
        position = np.clip((force_n - self.grid_start_n) / self.grid_step_n, 0.0, last)
        i = np.minimum(position.astype(np.int64), max(last - 1, 0))
        i_next = np.minimum(i + 1, last)
        return self.tables[:, i] + (position - i) * (self.tables[:, i_next] - self.tables[:, i])

    def _fingers_at(self, t_s: np.ndarray) -> dict[str, np.ndarray]:
        """The finger at each control-step time: active, extrapolated position, velocity, force."""
        options, rows = self.options, self.fingers
        times = rows[:, 0]
        newest = np.searchsorted(times, t_s, side="right") - 1
        valid = newest >= 0
        i = np.maximum(newest, 0)
        watchdog_s = options.watchdog_ms * 1e-3
        age_s = t_s - times[i] if len(rows) else np.zeros_like(t_s)
        active = valid & (rows[i, 4] != 0.0) & (age_s <= watchdog_s) if len(rows) else valid
        if not len(rows):
            return {"active": active}
        lifts = np.where(rows[:, 4] == 0.0, np.arange(len(rows)), -1)
        touch_start = np.maximum.accumulate(lifts) + 1
        window_s = options.velocity_window_ms * 1e-3
        j = np.maximum(np.searchsorted(times, times[i] - window_s, side="left"), touch_start[i])
        j = np.where((j > touch_start[i]) & (times[i] - times[np.maximum(j - 1, 0)] <= window_s), j - 1, j)
        j = np.where((j < i) & (times[i] - times[j] > window_s), j + 1, j)
        dt_s = times[i] - times[j]
        moving = dt_s > 0.0
        safe_dt = np.where(moving, dt_s, 1.0)
        vx = np.where(moving, (rows[i, 1] - rows[j, 1]) / safe_dt, 0.0)
        vy = np.where(moving, (rows[i, 2] - rows[j, 2]) / safe_dt, 0.0)
        lead_s = np.minimum(age_s + options.horizon_ms * 1e-3, watchdog_s)
        force = rows[i, 3]
        return {
            "active": active, "x_mm": rows[i, 1] + vx * lead_s, "y_mm": rows[i, 2] + vy * lead_s,
            "vx": vx, "vy": vy, "speed_mm_s": np.sqrt(vx * vx + vy * vy),
            "force_n": np.where(np.isnan(force), options.default_force_n, force),
        }

    def _commands(self, n: np.ndarray) -> dict[str, np.ndarray]:
        """Finger, target friction and (unlimited) command volts at control steps ``n``."""
        device, options = self.device, self.options
        t_s = n / self.fs_hz
        finger = self._fingers_at(t_s)
        active = finger["active"]
        if not active.any():
            return finger
        speed = np.where(active, finger["speed_mm_s"], 0.0)
        moving = speed > 0.0
        ux = np.where(moving, finger["vx"] / np.where(moving, speed, 1.0), 0.0)
        uy = np.where(moving, finger["vy"] / np.where(moving, speed, 1.0), 0.0)
        mu = reference_friction(self.texture, finger["x_mm"], finger["y_mm"], ux, uy, t_s)
        mu = np.clip(mu, options.mu_floor, 1.0)
        speed_m_s = speed * 1e-3
        floored = speed_m_s < device.speed_floor_m_s
        speed_m_s = np.maximum(speed_m_s, device.speed_floor_m_s)
        with np.errstate(divide="ignore"):  # mu' = 1: -log1p(-1) = inf, amplitude 0
            alpha_m = speed_m_s / (device.carrier_hz * device.mu0 * (1.0 + device.poisson) * device.psi_star
                                   * -np.log1p(-mu))
        amplitude_per_v = self._device(finger["force_n"])[0]
        return {**finger, "target_mu": mu, "floored": floored, "command_v": alpha_m / amplitude_per_v}

    # --- the sequential part: one step at a time, its samples vectorised ----------------

    def _close_step(self) -> None:
        step = self.step
        if step is None or not step["envelope"]:
            return
        envelope = np.concatenate(step["envelope"])
        power_w = step["p1"] * float(np.dot(envelope, envelope)) / envelope.size
        self.window_w += power_w - self.ring[self.slot]
        self.ring[self.slot] = power_w
        self.smoothed_v = step["command_v"] + (self.smoothed_v - step["command_v"]) * self.decay**envelope.size
        direction = 1.0 if step["gate"] else -1.0
        self.ramp = min(max(self.ramp + direction * envelope.size, 0.0), self.ramp_samples)

    def _open_step(self, n: int, commands: dict[str, np.ndarray], k: int) -> None:
        self._close_step()
        self.slot = (self.slot + 1) % self.ring.size
        options, held = self.options, self.held
        flags = FLAG_WATCHDOG
        if commands["active"][k]:
            flags = FLAG_SPEED_FLOOR if commands["floored"][k] else 0
            for name in ("x_mm", "y_mm", "speed_mm_s", "force_n", "target_mu", "command_v"):
                held[name] = float(commands[name][k])
        amplitude_per_v, p1_w, tau_s = self._device(np.array([held["force_n"]]))[:, 0]
        keep = 1.0 - SAFETY_MARGIN
        previous_w = self.window_w - self.ring[self.slot]
        allowance_w = max(self.ring.size * self.avg_w * keep - previous_w, 0.0)
        power_v = math.sqrt(min(self.cap_w * keep, allowance_w) / p1_w)
        voltage_v = self.device.max_voltage_v * keep
        cap_v, bound = (voltage_v, FLAG_VOLTAGE) if voltage_v <= power_v else (power_v, FLAG_POWER)
        if held["command_v"] > cap_v:
            held["command_v"] = cap_v
            flags |= bound
        gain = tau_s / (options.smoothing_ms * 1e-3) if self.preemphasis else 0.0
        phase = n * self.device.carrier_hz / self.fs_hz
        self.step = dict(command_v=held["command_v"], cap_v=cap_v, gain=gain, p1=p1_w, flags=flags,
                         gate=bool(commands["active"][k]) and self.running, theta0=2 * math.pi * (phase % 1.0),
                         envelope=[])

    def _render_segment(self, out: np.ndarray) -> tuple[float, float]:
        """Samples of the open step into ``out``; returns the segment's peak volts and sum of p1 e^2."""
        step = self.step
        j = sum(part.size for part in step["envelope"]) + np.arange(1, out.size + 1)
        v = step["command_v"]
        drive_v = np.clip(v + (1.0 - step["gain"]) * (self.smoothed_v - v) * self.decay**j, 0.0, step["cap_v"])
        direction = 1.0 if step["gate"] else -1.0
        envelope = np.clip(self.ramp + direction * j, 0.0, self.ramp_samples) / self.ramp_samples * drive_v
        carrier = np.sin(step["theta0"] + (j - 1) * (2 * math.pi * self.device.carrier_hz / self.fs_hz))
        out[:] = envelope / self.device.volts_per_full_scale * carrier
        step["envelope"].append(envelope)
        return float(envelope.max()), step["p1"] * float(np.dot(envelope, envelope))

    def render(self, out: np.ndarray) -> None:
        """The next ``len(out)`` samples (float32); one telemetry tuple (peak V, mean W, flags) per block."""
        start, total = self.sample_index, out.size
        offsets = np.arange((-start) % self.interval, total, self.interval)
        commands = self._commands(start + offsets)
        boundaries = [*offsets.tolist(), total]
        if not boundaries or boundaries[0] != 0:
            boundaries.insert(0, 0)
        peak_v, energy_w, flags = 0.0, 0.0, 0
        for first, stop in zip(boundaries[:-1], boundaries[1:]):
            if self.step is None or (start + first) % self.interval == 0:
                self._open_step(start + first, commands, int(np.searchsorted(offsets, first)))
            segment_peak_v, segment_w = self._render_segment(out[first:stop])
            peak_v, energy_w, flags = max(peak_v, segment_peak_v), energy_w + segment_w, flags | self.step["flags"]
        self.telemetry.append((peak_v, energy_w / total, flags))
        self.sample_index += total
