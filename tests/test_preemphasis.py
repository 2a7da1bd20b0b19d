"""Envelope pre-emphasis speeds up the simulated plate (issue 3, item 2).

The plate's amplitude follows the drive envelope with time constant tau = Q / (pi f0)
(1.55 ms on the default device at 0.5 N). With pre-emphasis the shaper drives a
model of that envelope onto the command's smoothing (0.25 ms by default), as hard as
the volt and power caps allow, braking in anti-phase when the command falls. Measured
on the simulated plate (``sim://``, a resonator driven by the DAC samples), in
simulated time.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tpad_rt.device import Device
from tpad_rt.kernel.layout import FLAG_POWER, FLAG_SHAPER_LIMIT, FLAG_VOLTAGE
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
    # A 1 ms smoothing keeps the step's drive under the cap (at the default 0.25 ms it is clipped:
    # the plate then rises as fast as the cap allows, test_steps_rise_and_fall_at_the_floor...).
    options = RenderOptions(control_interval=ENVELOPE_CONTROL_INTERVAL, default_force_n=FORCE_N, smoothing_ms=1.0)
    pipeline = Pipeline(device, _pulses(tmp_path, 0.85), fs_hz=ENVELOPE_HZ, options=options, envelope_output=True)
    full_scale_v = 50.0
    pipeline.set_drive(pipeline.device_drive.from_hardware(volts_per_full_scale=full_scale_v,
                                                           max_voltage_v=device.max_voltage_v,
                                                           carrier_hz=device.carrier_hz, source="a test"))
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
    assert not flags & (FLAG_VOLTAGE | FLAG_POWER | FLAG_SHAPER_LIMIT)  # the shaper's drive was never clipped
    assert drive_v.max() < device.max_voltage_v
    level_m = commanded[-1]
    first = np.flatnonzero(drive_v > 0)[0]  # the step's first sample (the high half drives nothing)
    assert first == pytest.approx(ENVELOPE_HZ / PULSE_HZ / 2, abs=ENVELOPE_CONTROL_INTERVAL + 1)
    gain = float(device.amplitude_m_per_v(FORCE_N))
    settled = slice(first + round(0.03 * ENVELOPE_HZ), None)
    assert gain * drive_v.max() > 1.4 * level_m  # the drive overshoots: a static mapping would give 1.4x the level
    assert gain * drive_v[settled].mean() == pytest.approx(level_m, rel=1e-3)

    plate_m = device.plate_amplitude_m(drive_v, ENVELOPE_HZ, FORCE_N)
    assert plate_m.max() <= level_m * 1.001  # no overshoot
    assert plate_m[settled] == pytest.approx(np.full(len(drive_v) - settled.start, level_m), rel=1e-3)
    # it follows the command's one-pole smoothing (1 ms here), not the plate's tau (1.55 ms)
    k = np.arange(len(drive_v) - first)
    smoothed_m = level_m * -np.expm1(-(k + 1) / (options.smoothing_ms * 1e-3 * ENVELOPE_HZ))
    assert np.abs(plate_m[first:] - smoothed_m).max() < 0.02 * level_m


def _step_response_bench() -> Any:
    """bench/fidelity/step_response.py, the bench these tests share their measurement with."""
    path = Path(__file__).resolve().parents[1] / "bench" / "fidelity" / "step_response.py"
    spec = importlib.util.spec_from_file_location("step_response", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("k", [0.3, 0.75])
def test_steps_rise_and_fall_at_the_floor_the_volt_limit_allows(tmp_path: Path, k: float) -> None:
    """Issue 10: on sim://, a step to a level needing k x max volts rises and falls (10-90 %) within
    max(1 ms, 1.25 x the floor of a first-order envelope driven at +-Vmax), and no faster than the floor."""
    row = _step_response_bench().measure(k, tmp_path)
    assert row["floor_rise_ms"] * 0.97 <= row["rise_ms"] <= row["bound_rise_ms"]
    assert row["floor_fall_ms"] * 0.97 <= row["fall_ms"] <= row["bound_fall_ms"]
    assert row["peak_drive_v"] <= Device.default().max_voltage_v


def _envelope_of_a_fall(tmp_path: Path, braking: bool) -> tuple[np.ndarray, np.ndarray]:
    """Drive envelope (V, signed) and plate amplitude (um) per sample of a step down, at an amplifier's rate."""
    device = Device.default()
    options = RenderOptions(control_interval=ENVELOPE_CONTROL_INTERVAL, default_force_n=FORCE_N, braking=braking)
    pipeline = Pipeline(device, _pulses(tmp_path, 0.85), fs_hz=ENVELOPE_HZ, options=options, envelope_output=True)
    pipeline.set_drive(pipeline.device_drive.from_hardware(volts_per_full_scale=device.max_voltage_v,
                                                           max_voltage_v=device.max_voltage_v,
                                                           carrier_hz=device.carrier_hz, source="a test"))
    pipeline.start()
    block = np.zeros(ENVELOPE_BLOCK, dtype=np.float32)
    drive = []
    for _ in range(int(0.13 * ENVELOPE_HZ / ENVELOPE_BLOCK)):  # high (off), low (on), and into the next high
        t_s = pipeline.time_s
        pipeline.push_finger(t_s, 10 + SPEED_MM_S * t_s, 30.0, force_n=FORCE_N)
        pipeline.render(block)
        drive.append(block.astype(np.float64) * device.max_voltage_v)
    drive_v = np.concatenate(drive)
    return drive_v, device.plate_amplitude_m(drive_v, ENVELOPE_HZ, FORCE_N) * 1e6


def test_braking_drives_in_antiphase_within_the_cap_and_beats_the_ring_down(tmp_path: Path, tau_s: float) -> None:
    braked_v, braked_um = _envelope_of_a_fall(tmp_path, braking=True)
    passive_v, passive_um = _envelope_of_a_fall(tmp_path, braking=False)
    fall = round(0.1 * ENVELOPE_HZ)  # the second half period's end: the step down
    level_um = braked_um[fall - 1]
    assert level_um == pytest.approx(passive_um[fall - 1], rel=1e-6)  # the same level before the fall

    def fall_ms(plate_um: np.ndarray) -> float:
        after = plate_um[fall:]
        return 1e3 * (np.argmax(after <= 0.1 * level_um) - np.argmax(after <= 0.9 * level_um)) / ENVELOPE_HZ

    assert braked_v.min() < -0.5 * Device.default().max_voltage_v  # anti-phase drive, hard
    assert np.abs(braked_v).max() <= Device.default().max_voltage_v
    assert passive_v.min() >= 0.0  # without braking the drive never reverses
    assert fall_ms(passive_um) == pytest.approx(1e3 * tau_s * math.log(9), rel=0.1)  # passive ring-down
    assert fall_ms(braked_um) < 0.4 * fall_ms(passive_um)
    assert braked_um[fall:].min() >= -1e-3 * level_um  # braking stops at zero: no ring-up in anti-phase
