"""What every driver does: run the render callback of one :class:`tpad_rt.realtime.CallbackTable` for an output.

The Renderer (tpad_rt.engine) calls, in order: :meth:`Driver.prepare` (find the
hardware), :meth:`Driver.warm` (compile what the driver runs, on a copy of the
table), :meth:`Driver.open` (open the hardware; it may replace the pipeline's drive with
what the hardware reported: :meth:`tpad_rt.pipeline.Pipeline.set_drive`), :meth:`Driver.start`;
then its watcher thread calls :meth:`Driver.poll` every 20 ms (``tpad_rt.engine.WATCH_PERIOD_S``);
to stop, the pipeline stops, :meth:`Driver.wait_silent` waits out the ramp down on the
driver's clock, and :meth:`Driver.close` ends the output. A driver may be started again after a close.
"""

from __future__ import annotations

import math
import threading
from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from tpad_rt.clock import Clock, MonotonicClock
from tpad_rt.device import Device
from tpad_rt.kernel.layout import STATE_GATE, STATE_RAMP_START
from tpad_rt.outputs.base import Consumes
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.realtime import CallbackTable
from tpad_rt.telemetry import TelemetryLog
from tpad_rt.urls import Url


#: The stop waits at most this many times the ramp's duration (plus a second) for the drive to reach 0.
STOP_TIMEOUT_FACTOR = 20
#: How often (ns) :meth:`Driver.wait_silent` reads the kernel's gain.
SILENCE_POLL_NS = 1_000_000


class Driver(ABC):
    """Runs the render callback for the output ``url`` names (drivers set ``consumes``).

    ``rate_hz`` (Hz) and ``block_frames`` are the renderer's; a driver replaces them by
    what its URL or its hardware asks for, and may adjust ``options`` (e.g. keep the
    control period at another rate). ``channels`` interleaved channels, the drive in
    ``channel`` (0-based), are known after :meth:`prepare`. ``stall_timeout_s`` (s) is how long
    an output with a clock of its own may go without a callback before it counts as stalled.
    ``clock`` is what the driver waits on (a :class:`tpad_rt.clock.VirtualClock` in tests).
    """

    consumes = Consumes.DAC

    def __init__(self, url: Url, *, device: Device, rate_hz: int, block_frames: int, options: RenderOptions,
                 stall_timeout_s: float = 0.5, clock: Clock | None = None):
        self.url = url
        self.device = device
        self.rate_hz = rate_hz
        self.block_frames = block_frames
        self.options = options
        self.stall_timeout_s = stall_timeout_s
        self.clock: Clock = MonotonicClock() if clock is None else clock
        #: The run's telemetry log (the Renderer sets it): a driver whose output measures blocks hands it
        #: their measurements (:meth:`tpad_rt.telemetry.TelemetryLog.add_measurements`).
        self.log: TelemetryLog | None = None
        self.channels = 1
        self.channel = 0

    def prepare(self) -> None:
        """Find the hardware and learn its channels (BackendError when it is not there); nothing by default."""

    def warm(self, table: CallbackTable) -> None:
        """Compile (or load) what the driver runs, calling it on ``table``, a copy of the real one."""
        table.call(np.zeros(self.block_frames * self.channels, dtype=np.float32))

    def warm_compiles(self) -> bool:
        """Whether :meth:`warm` and :meth:`open` may compile numba code (then under the compile notice): yes
        unless a driver knows better."""
        return True

    def open(self, pipeline: Pipeline) -> None:
        """Open the hardware before the drive starts (BackendError when it cannot); nothing by default."""

    @abstractmethod
    def start(self, table: CallbackTable) -> None:
        """Start calling the render callback on ``table``; BackendError when the output cannot start."""

    @abstractmethod
    def poll(self, table: CallbackTable) -> BaseException | None:
        """The error that ended the output (lost, stalled, failed), or None while it runs; once there is one,
        the same object at every call and from :meth:`close` (so it is reported once). Cheap: the watcher
        calls it every 20 ms."""

    @abstractmethod
    def close(self, ramp_ms: float) -> BaseException | None:
        """Stop calling the callback (after the drive ramped down over ``ramp_ms``) and release the output; the
        error met doing so, or that ended the output, if any. Safe to call twice."""

    def wait_silent(self, table: CallbackTable, ended: threading.Event) -> int:
        """After the pipeline stopped: wait until the kernel's gain has reached 0 (the ramp rendered, from the
        control step after the stop) and one block more has been rendered past that (the block holding the
        ramp's end handed to the output). Returns the stream index by which the drive is silent: a stream
        past it whose gain is not 0 did not ramp down (the Renderer reports that).

        The gain is read, not inferred from the stream's index: a serial stream held up skips its index
        ahead, past samples it never rendered. Waits on :attr:`clock`, at most STOP_TIMEOUT_FACTOR times the
        ramp's duration plus a second plus :meth:`stall_limit_s` (a stall that begins now is reported first),
        and no longer once ``ended`` is set (the run failed).
        """
        state = table.arrays.state
        ramp_samples = max(1, round(self.options.ramp_ms * 1e-3 * self.rate_hz))
        target = table.next_sample + self.options.control_interval + ramp_samples + self.block_frames
        limit_s = STOP_TIMEOUT_FACTOR * (target - table.next_sample) / self.rate_hz + 1.0 + self.stall_limit_s()
        deadline_ns = self.clock.now_ns() + round(limit_s * 1e9)
        silent_from: int | None = None  # the index at which the gain was first seen at 0
        while not ended.is_set():
            index = table.next_sample
            if silent_from is None and not (state[STATE_GATE] or state[STATE_RAMP_START]):
                silent_from = index
            if silent_from is not None and index >= max(silent_from + self.block_frames, target):
                break
            now_ns = self.clock.now_ns()
            if now_ns >= deadline_ns:
                break
            self.clock.sleep_until_ns(now_ns + SILENCE_POLL_NS)
        return target

    def stats(self) -> dict[str, Any]:
        """The driver's own figures for Renderer.stats(), if it has any (none by default)."""
        return {}

    def summary_lines(self, stats: dict[str, Any]) -> list[str]:
        """Lines about this output for the end of ``tpad-rt play``, from Renderer.stats() (none by default)."""
        return []

    def stall_limit_s(self) -> float:
        """How long (s) the output may go without a callback before :meth:`poll` reports it stalled (0: it
        reports failures as they come)."""
        return 0.0

    def stream_time_s(self) -> float:
        """The output's own clock (s), NaN where it has none."""
        return math.nan
