"""Tracking (RenderOptions.track, play/render --track): each control step drives at the device circuit's loaded
resonance at its force, the carrier's phase continuous; checked on the drive samples themselves and on the
simulated plate, which resonates where the circuit does."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import hilbert

from cli_run import REPO, tpad_rt
from tpad_rt.device import Device
from tpad_rt.errors import ConfigError
from tpad_rt.kernel import layout
from tpad_rt.outputs.sim import SimOutput
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.shipped import DEVICES_DIR
from tpad_rt.texture import load_compiled

FS_HZ = 192_000
BLOCK = 256
SLG04 = Device.from_file(DEVICES_DIR / "SLG_0.4.yaml")


def _even(tmp_path: Path, mu: float) -> Path:
    """A texture asking the same friction everywhere."""
    path = tmp_path / "even.yaml"
    path.write_text(f"description: even\nkind: grating\nperiod_mm: 5\nfriction: {{low: {mu!r}, high: {mu!r}}}\n")
    return path


def _render(device: Device, texture: Path, seconds: float, track: bool, force_n) -> tuple[np.ndarray, SimOutput]:  # type: ignore[no-untyped-def]
    """Drive samples (V) and the simulated plate they drove, the finger at 100 mm/s with force ``force_n(t)``."""
    pipeline = Pipeline(device, load_compiled(texture), FS_HZ, options=RenderOptions(track=track))
    sim = SimOutput(device, FS_HZ)
    pipeline.start()
    block = np.empty(BLOCK, dtype=np.float32)
    drive = []
    for _ in range(int(seconds * FS_HZ / BLOCK)):
        t_s = pipeline.time_s
        pipeline.push_finger(t_s, 5.0 + 100.0 * t_s, 30.0, force_n(t_s))
        pipeline.render(block)
        row = {name: float(values[-1]) for name, values in pipeline.drain_telemetry().items()}
        sim.write(block, row)
        drive.append(block.astype(np.float64) * device.volts_per_full_scale)
    assert pipeline.faults()["faults"] == 0
    return np.concatenate(drive), sim


def _instantaneous_hz(drive_v: np.ndarray) -> np.ndarray:
    """The drive's frequency at each sample (Hz), from its analytic signal's phase."""
    phase = np.unwrap(np.angle(hilbert(drive_v)))
    return np.diff(phase) * FS_HZ / (2 * math.pi)


def test_tracking_drives_a_detuned_plate_on_its_resonance_with_fewer_volts(tmp_path: Path) -> None:
    texture = _even(tmp_path, 0.9)  # 1.24 um at 100 mm/s: 29 V off resonance, 18 V on it (both unsaturated)
    force_n = 2.0
    resonance_hz = float(SLG04.motional_resonance_hz(force_n))
    assert resonance_hz - SLG04.carrier_hz > 25.0  # 2 N pulls the plate 28 Hz above its carrier
    results = {}
    for track in (False, True):
        drive_v, sim = _render(SLG04, texture, 0.3, track, lambda t: force_n)
        settled = slice(len(drive_v) // 2, None)
        frequency_hz = float(np.median(_instantaneous_hz(drive_v[settled])))
        amplitude_um = sim.measurements()["plate_amplitude_um"]
        results[track] = (frequency_hz, float(np.abs(drive_v[settled]).max()), float(amplitude_um[-100:].mean()))
    (fixed_hz, fixed_v, fixed_um), (tracked_hz, tracked_v, tracked_um) = results[False], results[True]
    assert fixed_hz == pytest.approx(SLG04.carrier_hz, abs=0.5)
    assert tracked_hz == pytest.approx(resonance_hz, abs=0.5)
    # The same friction, so the same plate amplitude: on resonance it takes 1 / sqrt(detuning factor) the volts
    assert tracked_um == pytest.approx(fixed_um, rel=0.01)
    detuning = float(SLG04.detuning_factor(force_n))
    assert tracked_v / fixed_v == pytest.approx(1 / math.sqrt(detuning), rel=0.02)
    assert tracked_v / fixed_v < 0.7


def test_the_tracked_carrier_follows_the_force_without_a_phase_jump(tmp_path: Path) -> None:
    texture = _even(tmp_path, 0.8)
    seconds = 0.6

    def force_n(t_s: float) -> float:
        return 2.0 * min(t_s / seconds, 1.0)

    drive_v, _ = _render(SLG04, texture, seconds, True, force_n)
    frequency_hz = _instantaneous_hz(drive_v)
    t_s = np.arange(len(frequency_hz)) / FS_HZ
    inside = (t_s > 0.05) & (t_s < seconds - 0.01)
    expected_hz = np.asarray(SLG04.motional_resonance_hz(2.0 * t_s[inside] / seconds))
    # Over each 5 ms the carrier is the resonance at the force then (the force is read per control step; the
    # analytic signal's frequency wobbles where the envelope moves)
    window = int(0.005 * FS_HZ)
    got = np.convolve(frequency_hz[inside], np.ones(window) / window, "valid")
    want = np.convolve(expected_hz, np.ones(window) / window, "valid")
    assert want[-1] - want[0] > 25.0
    assert np.median(np.abs(got - want)) < 0.1 and np.percentile(np.abs(got - want), 95) < 0.5
    # No phase jump: a sinusoid obeys x[n+1] = 2 cos(w) x[n] - x[n-1]; the drive departs from that only as much
    # as its envelope moves from one sample to the next (a jump of the phase would depart by its whole envelope)
    omega = 2 * math.pi * np.asarray(SLG04.motional_resonance_hz(np.array([force_n(t) for t in t_s]))) / FS_HZ
    residual = drive_v[2:] - 2 * np.cos(omega[1:]) * drive_v[1:-1] + drive_v[:-2]
    envelope = np.abs(hilbert(drive_v))[1:-1]
    steady = (t_s[1:] > 0.05) & (envelope > 0.5 * envelope.max())
    assert np.max(np.abs(residual[steady]) / envelope[steady]) < 0.05


def test_a_corrupt_phase_record_is_a_counted_fault_and_the_output_stays_in_bounds(tmp_path: Path) -> None:
    pipeline = Pipeline(SLG04, load_compiled(_even(tmp_path, 0.5)), FS_HZ, options=RenderOptions(track=True))
    pipeline.start()
    block = np.empty(BLOCK, dtype=np.float32)
    for index in range(60):
        t_s = pipeline.time_s
        pipeline.push_finger(t_s, 5.0 + 100.0 * t_s, 30.0, 1.0)
        if index == 30:
            pipeline.arrays.state[layout.STATE_PHASE_HI] = math.nan
            pipeline.arrays.state[layout.STATE_PHASE_INDEX] = 1e300
        pipeline.render(block)
        assert np.all(np.isfinite(block))
        assert np.abs(block).max() * SLG04.volts_per_full_scale <= SLG04.max_voltage_v * (1 + 1e-6)
    faults = pipeline.faults()
    assert faults["faults"] == 1 and "state" in faults["fault_causes"]


def test_track_must_be_a_bool() -> None:
    with pytest.raises(ConfigError, match="RenderOptions.track: must be true or false, got 1"):
        RenderOptions(track=1)  # type: ignore[arg-type]


def test_render_track_on_the_command_line(tmp_path: Path) -> None:
    out = tmp_path / "t.npz"
    run = tpad_rt("render", str(REPO / "textures" / "grating.yaml"), "--device", "SLG_0.4", "--force", "2",
                  "--track", "--input", "scripted://swipe?speed_mm_s=100", "--out", str(out))
    assert run.returncode == 0, run.stderr
    with np.load(out) as recording:
        assert json.loads(str(recording["metadata_json"]))["render_options"]["track"] is True
        drive, fs_hz = recording["drive"].astype(np.float64), float(recording["fs"])
    # The drive's carrier is the plate's loaded resonance at 2 N, 28 Hz above the device's carrier
    spectrum = np.abs(np.fft.rfft(drive * np.hanning(drive.size), 8 * drive.size))
    peak_hz = float(np.argmax(spectrum)) * fs_hz / (8 * drive.size)
    resolution_hz = fs_hz / drive.size
    assert peak_hz == pytest.approx(float(SLG04.motional_resonance_hz(2.0)), abs=resolution_hz)
    assert abs(peak_hz - SLG04.carrier_hz) > 10 * resolution_hz
