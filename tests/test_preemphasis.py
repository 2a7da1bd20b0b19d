"""Envelope pre-emphasis speeds up the simulated plate (issue 3, item 2).

The plate's amplitude follows the drive envelope with time constant tau = Q / (pi f0)
(about 3.4 ms on the default device at 0.5 N). With pre-emphasis the drive is shaped
so the plate follows the command's 1 ms smoothing instead. Measured on the simulated
plate (``sim://``, a resonator driven by the DAC samples), in simulated time.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tpad_rt.device import Device
from tpad_rt.kernel.layout import FLAG_POWER, FLAG_VOLTAGE
from tpad_rt.outputs.sim import SimOutput
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.texture import CompiledTexture, load_compiled

FS_HZ = 192000
BLOCK = 16
FORCE_N = 0.5
SPEED_MM_S = 50.0
PULSE_HZ = 10.0  # square pulses: friction steps every 50 ms


def _pulses(folder: Path, low: float) -> CompiledTexture:
    """A temporal texture of square friction steps between ``low`` and 1.0 at PULSE_HZ, compiled."""
    texture_file = folder / "pulses.yaml"
    texture_file.write_text(
        "description: 10 Hz friction steps\nkind: temporal\nwaveform: square\n"
        f"frequency_hz: {PULSE_HZ}\nduty: 0.5\nfriction: {{low: {low}, high: 1.0}}\n"
    )
    return load_compiled(texture_file)


def _plate_after_step(tmp_path: Path, preemphasis: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Block times (s since the first friction step), plate amplitude (um), flags, for a square temporal texture."""
    device = Device.default()
    options = RenderOptions(preemphasis=preemphasis, default_force_n=FORCE_N)
    pipeline = Pipeline(device, _pulses(tmp_path, 0.8), fs_hz=FS_HZ, options=options)
    sim = SimOutput(device, FS_HZ)
    pipeline.start()
    block = np.zeros(BLOCK, dtype=np.float32)
    rows: list[dict[str, float]] = []
    for _ in range(int(0.12 * FS_HZ / BLOCK)):  # through the high (vibration off) half and into the low
        t_s = pipeline.time_s
        pipeline.push_finger(t_s, 10 + SPEED_MM_S * t_s, 30.0, force_n=FORCE_N)
        pipeline.render(block)
        row = {name: float(values[-1]) for name, values in pipeline.drain_telemetry().items()}
        sim.write(block, row)
        rows.append(row)
    t_s = np.array([row["t"] for row in rows])
    flags = np.array([int(row["saturated"]) for row in rows])
    step_s = 1.0 / PULSE_HZ / 2  # square: high for the first half period, then low
    return t_s - step_s, sim.measurements()["plate_amplitude_um"], flags


def _rise_time_s(t_s: np.ndarray, amplitude_um: np.ndarray) -> float:
    """Time from the step to 63 % of the level the plate settles at 30-45 ms later."""
    final_um = amplitude_um[(t_s > 0.030) & (t_s < 0.045)].mean()
    start_um = amplitude_um[(t_s > -0.005) & (t_s < 0.0)].mean()
    assert final_um > 10 * max(start_um, 1e-6)  # a real step, from (almost) still
    after = t_s >= 0
    crossed = np.flatnonzero(amplitude_um[after] >= start_um + 0.632 * (final_um - start_um))
    return float(t_s[after][crossed[0]])


@pytest.fixture(scope="module")
def tau_s() -> float:
    return float(Device.default().envelope_time_constant_s(FORCE_N))


def test_preemphasis_makes_the_plate_reach_a_step_well_under_its_time_constant(tmp_path: Path, tau_s: float) -> None:
    t_on, plate_on, flags_on = _plate_after_step(tmp_path, preemphasis=True)
    t_off, plate_off, _ = _plate_after_step(tmp_path, preemphasis=False)
    assert not np.any(flags_on & (FLAG_VOLTAGE | FLAG_POWER))  # the boost stayed under the limits
    rise_on_s, rise_off_s = _rise_time_s(t_on, plate_on), _rise_time_s(t_off, plate_off)
    assert rise_off_s > 0.8 * tau_s  # without it: the plate's own time constant (and the smoothing)
    assert rise_on_s < 0.5 * tau_s  # with it: about the 1 ms smoothing
    # both settle at the same amplitude: pre-emphasis changes the speed, not the level
    settled = (t_on > 0.030) & (t_on < 0.045)
    assert plate_on[settled].mean() == pytest.approx(plate_off[settled].mean(), rel=0.01)


#: An amplifier's envelope rate (serial://'s default) and the control interval the serial driver scales to there.
ENVELOPE_HZ = 16000
ENVELOPE_CONTROL_INTERVAL = 3
ENVELOPE_BLOCK = 8


def test_the_plate_model_maps_the_preemphasised_envelope_of_a_step_back_to_the_commanded_level(tmp_path: Path) -> None:
    """The kernel's envelope output (as serial:// streams it) through Device.plate_amplitude_m: the overshoot
    pre-emphasis adds is gone, the level is the commanded one, and the rise is the smoothing's."""
    device = Device.default()
    options = RenderOptions(control_interval=ENVELOPE_CONTROL_INTERVAL, default_force_n=FORCE_N)
    pipeline = Pipeline(device, _pulses(tmp_path, 0.85), fs_hz=ENVELOPE_HZ, options=options, envelope_output=True)
    full_scale_v = 50.0
    pipeline.set_drive_scale(full_scale_v, device.max_voltage_v, device.resonance_hz)
    pipeline.start()
    block = np.zeros(ENVELOPE_BLOCK, dtype=np.float32)
    drive, commanded, flags = [], [], 0
    for _ in range(int(0.095 * ENVELOPE_HZ / ENVELOPE_BLOCK)):  # the high half, then the low one up to its end
        t_s = pipeline.time_s
        pipeline.push_finger(t_s, 10 + SPEED_MM_S * t_s, 30.0, force_n=FORCE_N)
        pipeline.render(block)
        drive.append(block.astype(np.float64) * full_scale_v)
        row = pipeline.drain_telemetry()
        commanded.append(row["amplitude_um"][-1] * 1e-6)
        flags |= int(np.bitwise_or.reduce(row["saturated"]))
    drive_v = np.concatenate(drive)
    assert not flags & (FLAG_VOLTAGE | FLAG_POWER)
    assert drive_v.max() < device.max_voltage_v  # pre-emphasis not clipped: the mapping must be exact
    level_m = commanded[-1]
    first = np.flatnonzero(drive_v > 0)[0]  # the step's first sample (the high half drives nothing)
    assert first == pytest.approx(ENVELOPE_HZ / PULSE_HZ / 2, abs=ENVELOPE_CONTROL_INTERVAL + 1)
    gain = float(device.amplitude_m_per_v(FORCE_N))
    settled = slice(first + round(0.03 * ENVELOPE_HZ), None)
    assert gain * drive_v.max() > 2 * level_m  # the drive overshoots: a static mapping would more than double the level
    assert gain * drive_v[settled].mean() == pytest.approx(level_m, rel=1e-3)

    plate_m = device.plate_amplitude_m(drive_v, ENVELOPE_HZ, FORCE_N)
    assert plate_m.max() <= level_m * 1.001  # no overshoot
    assert plate_m[settled] == pytest.approx(np.full(len(drive_v) - settled.start, level_m), rel=1e-3)
    # it follows the command's one-pole smoothing (1 ms), not the plate's tau (~2.8 ms)
    k = np.arange(len(drive_v) - first)
    smoothed_m = level_m * -np.expm1(-(k + 1) / (options.smoothing_ms * 1e-3 * ENVELOPE_HZ))
    assert np.abs(plate_m[first:] - smoothed_m).max() < 0.02 * level_m
