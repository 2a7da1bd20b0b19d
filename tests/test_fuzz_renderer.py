"""A fuzz harness for the Renderer API (issue 8): hypothesis-driven sequences of calls with good and
bad values, on null://, sim:// and a real JACK dummy server.

For every sequence: each call with valid arguments succeeds, each with a bad one raises a clear
error (SampleError or ConfigError: one line naming what is wrong) and the run goes on; the drive
that reached the output is finite and within max_voltage_v, the telemetry within the limits; no
thread is left behind. A last test checks that memory stays bounded over many runs. The JACK
part also pushes NaN through the real server: the captured output stays finite and the drive
comes back on the next valid swipe (docs/realtime.md "Safety").
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from jack_server import jack_server
from test_audio_engine import DRIVE_PORT, RATE_HZ, Capture, carrier_baseband, swipe, wait_for_stream

from tpad_rt.device import Device
from tpad_rt.engine import Renderer
from tpad_rt.errors import ConfigError, SampleError
from tpad_rt.kernel.atomics import publish
from tpad_rt.kernel.layout import FLAG_FAULT
from tpad_rt.recording import read_recording

TEXTURES = Path(__file__).resolve().parents[1] / "textures"
DEVICE = Device.default()
LIMIT_FS = DEVICE.max_voltage_v / DEVICE.volts_per_full_scale

GOOD_X = st.floats(-130.0, 260.0)
GOOD_Y = st.floats(-60.0, 120.0)
GOOD_FORCE = st.one_of(st.none(), st.floats(0.0, 50.0))
BAD_NUMBERS = st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 10**400, -(10**400), "1", None, True])
#: A finite value out of range for each push argument (x, y, force, time).
OUT_OF_RANGE = (260.5, -60.5, 50.5, 1e9)


@dataclass(frozen=True)
class Call:
    """One API call and whether its arguments are valid."""

    name: str
    args: tuple[Any, ...]
    valid: bool


def _push() -> st.SearchStrategy[Call]:
    good = st.tuples(GOOD_X, GOOD_Y, GOOD_FORCE, st.one_of(st.none(), st.floats(-0.05, 0.05)))

    def spoil(values: tuple[Any, ...], which: int, bad: Any) -> Call:
        """``values`` with argument ``which`` (x, y, force, time) replaced by ``bad``; None, valid for the
        force (the default) and the time (now), becomes a force of -1 N or a time of 1e9 s."""
        spoiled = list(values)
        spoiled[which] = bad if bad is not None or which < 2 else (-1.0, 1e9)[which - 2]
        return Call("push", tuple(spoiled), False)

    return st.one_of(
        good.map(lambda values: Call("push", values, True)),
        st.builds(spoil, good, st.integers(0, 3), BAD_NUMBERS),
        st.builds(lambda values, which: spoil(values, which, OUT_OF_RANGE[which]), good, st.integers(0, 3)),
    )


CALLS = st.one_of(
    _push(),
    _push(),
    st.one_of(st.none(), st.floats(-0.05, 0.05)).map(lambda t: Call("lift", (t,), True)),
    BAD_NUMBERS.filter(lambda v: v is not None).map(lambda t: Call("lift", (t,), False)),
    st.sampled_from(["grating.yaml", "square_grating.yaml", "bumps_grid.yaml", "temporal_pulse.yaml"]).map(
        lambda name: Call("texture", (TEXTURES / name,), True)),
    st.sampled_from(["missing.yaml", "../README.md", "/dev/null"]).map(
        lambda name: Call("texture", (TEXTURES / name,), False)),
    st.floats(0.0, 0.02).map(lambda s: Call("wait", (s,), True)),
    st.just(Call("stats", (), True)),
)


def _time(renderer: Renderer, t: Any) -> Any:
    """The ``t`` argument for a call: None (now), now + ``t`` for a small offset (s), else ``t`` itself."""
    return renderer.now_s() + t if isinstance(t, float) and abs(t) < 1 else t


def _apply(renderer: Renderer, call: Call) -> None:
    """Make ``call``; a valid one must succeed, a bad one raise a clear, one-line error."""
    try:
        if call.name == "push":
            x_mm, y_mm, force_n, t = call.args
            renderer.push_finger(x_mm, y_mm, force_n, t=_time(renderer, t))
        elif call.name == "lift":
            renderer.lift(t=_time(renderer, call.args[0]))
        elif call.name == "texture":
            renderer.set_texture(call.args[0])
        elif call.name == "wait":
            time.sleep(call.args[0])
        else:
            stats = renderer.stats()
            assert stats["power_peak_w"] <= stats["power_budget_w"]
    except (SampleError, ConfigError) as error:
        assert not call.valid, f"{call} refused: {error}"
        assert str(error) and "Traceback" not in str(error)
        assert isinstance(error, ValueError) or call.name == "texture"
        if call.name != "texture":
            assert "\n" not in str(error)
    else:
        assert call.valid, f"{call} was accepted"


def _run(output: str, calls: list[Call]) -> None:
    """One renderer run making ``calls``; checks the drive, the telemetry and the threads afterwards."""
    threads_before = threading.active_count()
    renderer = Renderer(DEVICE, output, texture=TEXTURES / "grating.yaml")
    with renderer:
        table = renderer.callback_table
        assert table is not None
        for call in calls:
            _apply(renderer, call)
    stats = renderer.stats()
    frames = min(int(table.stats[0] * renderer.block_frames), len(table.drive))
    drive = table.drive[:frames]
    assert np.all(np.isfinite(drive)) and np.max(np.abs(drive), initial=0.0) <= LIMIT_FS
    assert stats["power_peak_w"] <= stats["power_budget_w"]
    telemetry = renderer.telemetry()
    assert np.all(np.isfinite(telemetry["voltage_v"])) and np.all(telemetry["voltage_v"] <= DEVICE.max_voltage_v)
    assert threading.active_count() == threads_before


FUZZ = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.mark.parametrize("output", ["null://", "sim://"])
@FUZZ
@given(calls=st.lists(CALLS, min_size=1, max_size=30))
def test_renderer_api_sequences_on_paced_outputs(output: str, calls: list[Call]) -> None:
    _run(output, calls)


@pytest.fixture(scope="module")
def jack() -> Any:
    with jack_server(RATE_HZ, 64) as name:
        yield name


@pytest.mark.system
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(calls=st.lists(CALLS, min_size=1, max_size=30))
def test_renderer_api_sequences_on_a_jack_server(jack: str, calls: list[Call]) -> None:
    _run("audio://", calls)


def _unchecked_row(renderer: Renderer, row: tuple[float, float, float, float, float]) -> None:
    """Append a finger row past every check (a producer that skipped them, or memory overwritten)."""
    arrays = renderer._pipeline.arrays
    arrays.finger[arrays.finger_count[0] % len(arrays.finger)] = row
    publish(arrays.finger_count, 0, int(arrays.finger_count[0]) + 1)


@pytest.mark.system
@pytest.mark.realtime  # a busy host's late samples can cut a swipe's drive short (a CI run: 187 ms of 400)
def test_nan_through_a_jack_server_leaves_the_output_finite_and_the_next_swipe_drives(
    jack: str, tmp_path: Path
) -> None:
    """What JACK received (a capture client) is finite and within the limits; the drive's course is read from the
    recording of the samples the callback made (lossless: an xrun of the shared machine slips a capture client)."""
    window = 192  # 1 ms
    renderer = Renderer(DEVICE, "audio://", texture=TEXTURES / "grating.yaml")
    renderer.record(tmp_path / "nan.npz")
    with renderer:
        capture = Capture(DRIVE_PORT, tmp_path / "capture.npy", 1.6)
        start_s, end_s = swipe(renderer, 10.0, 50.0, 0.4, hold_s=0.0)
        with pytest.raises(SampleError, match="x_mm: must be a finite number"):
            renderer.push_finger(math.nan, 20.0, 0.5, t=end_s)  # the boundary refuses it...
        for bad in ((end_s + 0.004, math.nan, 20.0, 0.5, 1.0), (end_s + 0.006, 1e308, 20.0, 0.5, 1.0),
                    (end_s + 0.008, 30.0, math.inf, -1.0, 1.0)):
            _unchecked_row(renderer, bad)  # ...and the kernel survives it when it gets past
        wait_for_stream(renderer, end_s + 0.05)
        second_s, _ = swipe(renderer, 10.0, 50.0, 0.4, hold_s=0.0, lead_s=0.25)
        wait_for_stream(renderer, second_s + 0.45)
        stats = renderer.stats()
        telemetry = renderer.telemetry()
    samples = capture.result()
    assert np.all(np.isfinite(samples)) and np.max(np.abs(samples)) <= LIMIT_FS
    assert stats["faults"] >= 1 and "finger" in stats["fault_causes"] and stats["fault_blocks"] >= 1
    assert np.any(telemetry["saturated"] & FLAG_FAULT)
    envelope = np.abs(carrier_baseband(read_recording(tmp_path / "nan.npz").drive, DEVICE.carrier_hz, window))
    # The grating ripples the envelope within a swipe: a swipe is a run of 40 ms windows with drive.
    reach = np.array([envelope[k:k + 40].max() for k in range(len(envelope) - 40)])
    on = reach > 0.3 * envelope.max()
    edges = np.flatnonzero(np.diff(np.r_[0, on.astype(int), 0]))
    # A swipe: at least 100 ms of drive (a fault's ramp lasts ramp_ms; a busy host's late samples can cut a
    # 0.4 s swipe's drive short: a CI run's second swipe drove for 187 ms).
    swipes = [(start, stop) for start, stop in zip(edges[::2], edges[1::2]) if stop - start >= 100]
    assert len(swipes) == 2, f"the drive did not come back after the bad samples: {edges}"
    (first, first_end), (second, second_end) = swipes
    assert envelope[second:second_end].max() >= 0.5 * envelope[first:first_end].max()
    assert envelope[first_end + 40:second].max() < 0.3 * envelope.max()  # faulted and quiet in between


def _rss_mb() -> float:
    with open("/proc/self/statm") as stats:
        return int(stats.read().split()[1]) * 4096 / 2**20


def test_memory_stays_bounded_over_many_runs() -> None:
    calls = [Call("push", (50.0, 30.0, None, None), True), Call("push", (math.nan, 30.0, None, None), False),
             Call("wait", (0.002,), True), Call("lift", (None,), True)]
    for _ in range(5):
        _run("null://", calls)  # warm: caches, first allocations
    before = _rss_mb()
    for _ in range(60):
        _run("null://", calls)
    assert _rss_mb() - before < 64  # a leaked 4 MiB drive ring per run would add 240 MB
