"""The paced driver (sim://, wav://, null://) on a virtual clock: blocks per virtual second, catching up,
skip-ahead after a stall with its underflow, an output's error, the thread loop, the stop ramp, and the
memory a long sim:// run holds. No thread sleeps and nothing depends on the host's speed: time is the
VirtualClock's (docs/testing.md "Three tiers").

This module also declares a paced output kind, ``probe://NAME?fail_at=N``, registered per test: it keeps
the blocks it is handed under ``KEPT[NAME]`` with the virtual time of each hand-over, and fails (a
BackendError) when handed block N.
"""

from __future__ import annotations

import sys
import threading
import time
import tracemalloc
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

import tpad_rt.telemetry
from tpad_rt.clock import VirtualClock
from tpad_rt.device import Device
from tpad_rt.drivers.paced import PACED_MAX_BEHIND_S, PacedDriver, PacedRun
from tpad_rt.errors import BackendError
from tpad_rt.kernel import table as tab
from tpad_rt.kernel.layout import STATE_GATE, STATE_RAMP_START
from tpad_rt.outputs import (
    Capability, Consumes, Output, OutputKind, output_kind, register_output, unregister_output,
)
from tpad_rt.outputs.sim import SimOutput
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.realtime import CallbackTable
from tpad_rt.telemetry import TelemetryLog
from tpad_rt.texture import load_compiled
from tpad_rt.urls import Option, Url, UrlForm, count

GRATING = Path(__file__).resolve().parents[1] / "textures" / "grating.yaml"
DEVICE = Device.default()
S = 1_000_000_000  # ns per s

# --- the probe output kind ------------------------------------------------------------------------

#: ``probe://NAME?fail_at=N``: blocks go to ``KEPT[NAME]``; handed block N (0: the first), it fails.
FORMS = (UrlForm("probe", "NAME", (Option("fail_at", 0, count(0, 10**9)),)),)
KIND = OutputKind(Consumes.DAC, "tpad_rt.drivers.paced:PacedDriver", Capability.OFFLINE)
#: NAME -> the blocks handed over (copies), in order.
KEPT: dict[str, list[npt.NDArray[np.float32]]] = {}
#: NAME -> set when the output is about to fail.
FAILING: dict[str, threading.Event] = {}


class ProbeOutput(Output):
    """Keeps every block; ``fail_at`` > 0: raises BackendError when handed block ``fail_at`` (0-based)."""

    def __init__(self, name: str, fail_at: int, fs_hz: int):
        super().__init__(fs_hz)
        self.name = name
        self.blocks = KEPT.setdefault(name, [])
        self.fail_at = fail_at
        self.failing = FAILING.setdefault(name, threading.Event())

    def write(self, samples: npt.NDArray[np.float32], block: Mapping[str, float]) -> None:
        if self.fail_at and len(self.blocks) == self.fail_at:
            self.failing.set()
            raise BackendError(f"probe: {self.name} failed at block {self.fail_at}")
        self.blocks.append(samples.copy())


def open_url(url: Url, *, device: Device, fs_hz: int) -> ProbeOutput:
    values = FORMS[0].read(url)
    return ProbeOutput(url.target, values["fail_at"], fs_hz)


@pytest.fixture
def probe() -> Iterator[None]:
    """probe:// registered for one test."""
    register_output(sys.modules[__name__])
    KEPT.clear()
    FAILING.clear()
    yield
    unregister_output("probe")


# --- helpers --------------------------------------------------------------------------------------


class Recorder(Output):
    """Keeps every block handed to it; ``on_write(k)`` runs before block ``k`` (0-based) is kept."""

    def __init__(self, fs_hz: int, on_write: Callable[[int], None] = lambda k: None):
        super().__init__(fs_hz)
        self.blocks: list[npt.NDArray[np.float32]] = []
        self.rows: list[dict[str, float]] = []
        self.on_write = on_write

    def write(self, samples: npt.NDArray[np.float32], block: Mapping[str, float]) -> None:
        self.on_write(len(self.blocks))
        self.blocks.append(samples.copy())
        self.rows.append(dict(block))


def _pipeline(rate_hz: int, options: RenderOptions = RenderOptions()) -> tuple[Pipeline, CallbackTable]:
    pipeline = Pipeline(DEVICE, load_compiled(GRATING), fs_hz=rate_hz, options=options)
    return pipeline, CallbackTable(pipeline.arrays, load_compiled(GRATING))


def _driver(url: str, rate_hz: int, block_frames: int, clock: VirtualClock,
            options: RenderOptions = RenderOptions()) -> PacedDriver:
    return PacedDriver(output_kind(url)[0], device=DEVICE, rate_hz=rate_hz, block_frames=block_frames,
                       options=options, clock=clock)


def _run_until(clock: VirtualClock, run: PacedRun, end_ns: int) -> list[int]:
    """Step ``run`` at each time it asks to be woken until ``end_ns`` (ns, excluded), as the driver's thread
    does; the number of blocks each step rendered."""
    rendered = []
    while clock.now_ns() < end_ns:
        before = int(run.table.stats[tab.STAT_CALLBACKS])
        wake_ns = run.pace_once(clock.now_ns())
        rendered.append(int(run.table.stats[tab.STAT_CALLBACKS]) - before)
        clock.advance_to(max(wake_ns, clock.now_ns()))
    return rendered


def _paced_by_events(clock: VirtualClock, run: PacedRun, on_step: Callable[[], None] = lambda: None) -> None:
    """Schedule ``run``'s steps as events of ``clock``: whoever advances it (a test, Driver.wait_silent) renders
    the blocks falling due on the way, in this thread."""
    def step() -> None:
        wake_ns = run.pace_once(clock.now_ns())
        on_step()
        clock.at(wake_ns, step)

    clock.at(clock.now_ns(), step)


# --- pacing ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(("rate_hz", "block_frames"), [(96000, 960), (192000, 64)])
def test_it_renders_one_block_per_block_period_of_virtual_time(rate_hz: int, block_frames: int) -> None:
    """Stepped whenever it asks, it renders exactly one block per step, blocks per virtual second as the rate
    says (no drift over 3 s, also where a block period is not a whole number of ns), contiguous."""
    clock = VirtualClock(start_ns=7 * S)
    pipeline, table = _pipeline(rate_hz)
    output = Recorder(rate_hz)
    run = PacedRun(table, output, pipeline, rate_hz=rate_hz, block_frames=block_frames, started_ns=clock.now_ns(),
                   log=None)
    rendered = _run_until(clock, run, 10 * S)
    assert set(rendered) == {1}
    assert len(output.blocks) == 3 * rate_hz // block_frames == table.stats[tab.STAT_CALLBACKS]
    assert table.stats[tab.STAT_UNDERFLOWS] == 0
    t_s = np.array([row["t"] for row in output.rows])
    assert np.allclose(t_s, np.arange(len(t_s)) * block_frames / rate_hz, rtol=0, atol=1e-12)


def test_a_late_wake_catches_up_in_one_burst() -> None:
    """Woken 50 ms late (less than PACED_MAX_BEHIND_S), it renders every block due at once: no underflow."""
    rate_hz, block_frames = 96000, 960  # 10 ms blocks
    pipeline, table = _pipeline(rate_hz)
    output = Recorder(rate_hz)
    run = PacedRun(table, output, pipeline, rate_hz=rate_hz, block_frames=block_frames, started_ns=0, log=None)
    assert run.pace_once(0) == 10_000_000  # block 0 now, block 1 due in 10 ms
    assert run.pace_once(59_999_999) == 60_000_000  # blocks 1-5 due by then
    assert len(output.blocks) == 6 and table.stats[tab.STAT_UNDERFLOWS] == 0
    assert run.pace_once(59_999_999) == 60_000_000 and len(output.blocks) == 6  # nothing new due: nothing


def test_a_stall_skips_ahead_counts_one_underflow_and_paces_on_from_there() -> None:
    """Past PACED_MAX_BEHIND_S behind (a virtual jump of 1 s), it renders only the newest block due, counts one
    underflow, and paces on from the new time without a burst; exactly that many behind still catches up."""
    rate_hz, block_frames = 96000, 960
    period_ns = 10_000_000
    most_behind = round(PACED_MAX_BEHIND_S * rate_hz / block_frames)
    clock = VirtualClock()
    pipeline, table = _pipeline(rate_hz)
    output = Recorder(rate_hz)
    run = PacedRun(table, output, pipeline, rate_hz=rate_hz, block_frames=block_frames, started_ns=0, log=None)
    assert run.most_behind == most_behind == 10
    _run_until(clock, run, 100 * period_ns)  # blocks 0-99
    assert len(output.blocks) == 100
    clock.advance_to(clock.now_ns() + (most_behind - 1) * period_ns)  # block 100 + 9 due: 10 behind
    run.pace_once(clock.now_ns())
    assert len(output.blocks) == 110 and table.stats[tab.STAT_UNDERFLOWS] == 0
    clock.advance_to(clock.now_ns() + S)  # a stall: 100 blocks behind
    wake_ns = run.pace_once(clock.now_ns())
    assert len(output.blocks) == 111 and table.stats[tab.STAT_UNDERFLOWS] == 1
    assert wake_ns == run.due_at_ns(run.blocks_due) == clock.now_ns() + period_ns
    clock.advance_to(wake_ns)
    rendered = _run_until(clock, run, clock.now_ns() + S)
    assert set(rendered) == {1} and len(rendered) == 100 and table.stats[tab.STAT_UNDERFLOWS] == 1
    # The stream stays contiguous: the skipped time is not rendered, the drive goes on where it was.
    t_s = np.array([row["t"] for row in output.rows])
    assert np.allclose(np.diff(t_s), block_frames / rate_hz)


def test_an_output_whose_write_takes_too_long_makes_it_skip_ahead() -> None:
    """A write that holds the thread up for 150 ms (the clock advances in it) leaves the next step behind by
    more than PACED_MAX_BEHIND_S: one underflow, then one block per period again."""
    rate_hz, block_frames = 96000, 960
    clock = VirtualClock()
    pipeline, table = _pipeline(rate_hz)

    def slow_write(k: int) -> None:
        if k == 20:
            clock.advance_by(150_000_000)

    output = Recorder(rate_hz, slow_write)
    run = PacedRun(table, output, pipeline, rate_hz=rate_hz, block_frames=block_frames, started_ns=0, log=None)
    rendered = _run_until(clock, run, S)
    assert table.stats[tab.STAT_UNDERFLOWS] == 1
    assert len(output.blocks) == 100 - 15 + 1  # 15 periods lost to the write, the newest of them rendered
    assert set(rendered) == {1}


def test_an_output_error_ends_the_step_and_the_blocks_before_it_reach_the_log() -> None:
    """The output's error leaves pace_once; what the plate measured of the blocks before it is in the log, the
    failed block's row has NaN there once the run finished, and no row is lost."""
    rate_hz, block_frames = 96000, 960
    pipeline, table = _pipeline(rate_hz)
    log = TelemetryLog(pipeline, rate_hz)

    class FailingPlate(SimOutput):
        def write(self, samples: npt.NDArray[np.float32], block: Mapping[str, float]) -> None:
            if block["t"] >= 0.25:
                raise BackendError("plate: gone")
            super().write(samples, block)

    clock = VirtualClock()
    run = PacedRun(table, FailingPlate(DEVICE, rate_hz), pipeline, rate_hz=rate_hz, block_frames=block_frames,
                   started_ns=0, log=log)
    with pytest.raises(BackendError, match="plate: gone"):
        _run_until(clock, run, S)
    assert clock.now_ns() == 250_000_000 and int(table.stats[tab.STAT_CALLBACKS]) == 26
    log.drain(table)
    measured = log.take()  # the failed block's row waits: the run may still measure it
    assert len(measured["t"]) == 25 and np.all(np.isfinite(measured["achieved_mu"]))
    run.finish()
    log.drain(table)
    failed = log.take()
    assert np.allclose(failed["t"], [0.25]) and np.isnan(failed["achieved_mu"]).all()
    assert np.isnan(failed["plate_amplitude_um"]).all()


def test_the_thread_steps_on_its_clock_and_an_output_error_ends_it(probe: None) -> None:
    """The driver's thread on a virtual clock: it sleeps exactly until each block falls due (the clock reads
    block 30's time when the output fails there), the error is poll()'s and close()'s, the output closed."""
    rate_hz, block_frames = 96000, 96  # 1 ms blocks: shorter than the thread's longest sleep, PACED_POLL_NS
    clock = VirtualClock(start_ns=S)
    pipeline, table = _pipeline(rate_hz)
    driver = _driver("probe://failing?fail_at=30", rate_hz, block_frames, clock)
    driver.open(pipeline)
    driver.start(table)
    assert FAILING["failing"].wait(60)  # the thread runs as fast as the host: the virtual clock waits for it
    error = driver.close(5.0)
    assert isinstance(error, BackendError) and "failed at block 30" in str(error)
    assert len(KEPT["failing"]) == 30 and table.stats[tab.STAT_CALLBACKS] == 31
    assert clock.now_ns() == S + 30 * 1_000_000  # woke at each due time, never between or after
    assert table.stats[tab.STAT_UNDERFLOWS] == 0


# --- the stop -------------------------------------------------------------------------------------


def test_after_a_stop_the_output_receives_the_ramp_to_zero_within_the_ramp_and_a_block(probe: None) -> None:
    """A finger slides, the drive runs; the pipeline stops at a virtual time, and Driver.wait_silent, waiting on
    the virtual clock, has the paced steps render the ramp down: the output's blocks are silent from
    control step + ramp_ms + one block after the stop (by virtual time) on, and were not before it."""
    rate_hz, block_frames = 96000, 96  # 1 ms blocks
    options = RenderOptions(ramp_ms=5.0)
    clock = VirtualClock()
    pipeline, table = _pipeline(rate_hz, options)
    driver = _driver("probe://stop", rate_hz, block_frames, clock, options)
    driver.open(pipeline)
    run = driver.run(table)
    handed_ns: list[int] = []  # the virtual time each block was handed over at
    _paced_by_events(clock, run, lambda: handed_ns.extend([clock.now_ns()] * (len(KEPT["stop"]) - len(handed_ns))))
    pipeline.start()
    for k in range(400):  # 100 mm/s along the plate, a sample every 1 ms of stream time
        pipeline.push_finger(0.001 * k, 10.0 + 0.1 * k, 20.0)
    clock.advance_to(300_000_000)
    stop_ns = clock.now_ns()
    assert np.abs(KEPT["stop"][-1]).max() > 0.05  # driving when it stops
    pipeline.stop()
    silent_by = driver.wait_silent(table, threading.Event())
    state = table.arrays.state
    assert not (state[STATE_GATE] or state[STATE_RAMP_START]) and table.next_sample >= silent_by
    blocks = KEPT["stop"]
    after = [k for k, t_ns in enumerate(handed_ns) if t_ns > stop_ns]
    loud = [k for k in after if np.abs(blocks[k]).max() > 0]
    bound_ns = (options.control_interval / rate_hz + options.ramp_ms * 1e-3 + block_frames / rate_hz) * S
    assert loud and handed_ns[loud[-1]] - stop_ns <= bound_ns  # it ramped (not cut) and was done in time
    assert all(np.abs(blocks[k]).max() == 0 for k in after if k > loud[-1])
    assert np.abs(blocks[loud[-1]]).max() < 0.2 * np.abs(blocks[after[0] - 1]).max()  # down a ramp, not a cut
    assert driver.close(options.ramp_ms) is None


# --- memory ---------------------------------------------------------------------------------------


def test_a_long_sim_run_keeps_bounded_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    """Three virtual minutes of sim:// with a telemetry log that no one takes from (the watcher drains every
    20 ms): the output keeps no measurement past a step, the log at most MAX_PENDING_ROWS rows, each measured,
    and the memory Python holds (tracemalloc) does not grow after the first minute."""
    monkeypatch.setattr(tpad_rt.telemetry, "MAX_PENDING_ROWS", 500)
    rate_hz, block_frames = 72000, 3600  # 20 blocks a second (the plate's model costs per sample)
    clock = VirtualClock()
    pipeline, table = _pipeline(rate_hz)
    log = TelemetryLog(pipeline, rate_hz)
    driver = _driver("sim://", rate_hz, block_frames, clock)
    driver.log = log
    driver.open(pipeline)
    run = driver.run(table)
    assert isinstance(run.output, SimOutput)
    output = run.output
    most_kept = [0]  # the most measurements the output held after a step

    def note_kept() -> None:
        most_kept[0] = max(most_kept[0], len(output.measurements()["achieved_mu"]))

    _paced_by_events(clock, run, note_kept)

    def watch() -> None:
        log.drain(table)
        clock.at(clock.now_ns() + 20_000_000, watch)

    clock.at(0, watch)
    pipeline.start()
    pipeline.push_finger(0.0, 30.0, 20.0)
    tracemalloc.start()
    try:
        clock.advance_to(60 * S)
        first_minute = tracemalloc.get_traced_memory()[0]
        clock.advance_to(180 * S - 1)
        three_minutes = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    assert table.stats[tab.STAT_CALLBACKS] == 180 * 20 and most_kept == [0]
    log.drain(table)
    rows = log.take()
    assert len(rows["t"]) == 500 and rows["t"][-1] == (180 * 20 - 1) * block_frames / rate_hz
    assert np.all(np.isfinite(rows["achieved_mu"]))
    # The leak this replaces kept two Python floats per block: 2,400 blocks after the first minute, >150 kB.
    assert three_minutes - first_minute < 50_000


# --- the real clock (the real-time tier) ----------------------------------------------------------


@pytest.mark.realtime
def test_on_the_host_clock_it_keeps_real_time_and_never_runs_ahead() -> None:
    """The thread on CLOCK_MONOTONIC for a second: never more blocks than the time passed allows (that holds on
    any host), and a fifth of them at least (a margin a loaded host meets: with a busy loop and a load average
    of 10 on 2 cores it rendered 40 %, skipping ahead past its stalls; the pacing itself is checked above, on the
    virtual clock)."""
    rate_hz, block_frames = 96000, 960
    pipeline, table = _pipeline(rate_hz)
    driver = PacedDriver(output_kind("null://")[0], device=DEVICE, rate_hz=rate_hz, block_frames=block_frames,
                         options=RenderOptions())
    driver.open(pipeline)
    started_ns = time.monotonic_ns()
    driver.start(table)
    threading.Event().wait(1.0)
    assert driver.close(5.0) is None
    periods = (time.monotonic_ns() - started_ns) / 10_000_000
    blocks = int(table.stats[tab.STAT_CALLBACKS])
    assert 0.2 * periods <= blocks <= periods + 1
