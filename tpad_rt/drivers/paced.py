"""The driver of paced outputs (``sim://``, ``wav://``, ``null://``): a Python thread runs the callback.

The thread calls the same native render callback as PortAudio does, no faster than
real time on the driver's clock, and hands each block to the output's
:meth:`tpad_rt.outputs.Output.write` with its telemetry row. It holds the GIL: a
simulator or a recorder, not a real-time path (docs/realtime.md).

The pacing is a step, :meth:`PacedRun.pace_once`: given the time, render the blocks due
by then (skipping ahead past a stall) and say when the next falls due. The thread only
reads the clock, calls the step and sleeps, so tests drive the step on a
:class:`tpad_rt.clock.VirtualClock` with no thread and no sleep. What the output measures
per block (``sim://``: the plate's amplitude and friction) goes to the pipeline's
telemetry log after every step (:attr:`Driver.log`); the output keeps none.
"""

from __future__ import annotations

import threading

import numpy as np

from tpad_rt.clock import Clock
from tpad_rt.device import Device
from tpad_rt.drivers.base import Driver
from tpad_rt.kernel import table_layout as tab
from tpad_rt.outputs import Output, open_paced
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.realtime import CallbackTable
from tpad_rt.telemetry import TelemetryLog
from tpad_rt.urls import Url

#: An output further behind real time than this (s) skips ahead instead of catching up in a burst, and counts
#: an underflow.
PACED_MAX_BEHIND_S = 0.1
#: The thread sleeps at most this long (ns) between two steps: a stop is seen within it.
PACED_POLL_NS = 5_000_000


class PacedRun:
    """One run of a paced output: block ``k`` of ``table``'s callback falls due at ``started_ns + k`` block
    periods (ns on the driver's clock); :meth:`pace_once` renders the blocks due and hands them to ``output``
    with their telemetry rows, and their measurements to ``log`` (None: they are dropped)."""

    def __init__(self, table: CallbackTable, output: Output, pipeline: Pipeline, *, rate_hz: int, block_frames: int,
                 started_ns: int, log: TelemetryLog | None):
        self.table = table
        self.output = output
        self.pipeline = pipeline
        self.rate_hz = rate_hz
        self.block_frames = block_frames
        self.started_ns = started_ns
        #: Block periods accounted for: rendered, or skipped after a stall.
        self.blocks_due = 0
        #: The most blocks one step renders to catch up; more behind is a stall: skip ahead.
        self.most_behind = max(1, round(PACED_MAX_BEHIND_S * rate_hz / block_frames))
        self._block = np.zeros(block_frames, dtype=np.float32)
        self._log = log
        names = tuple(output.take_measurements())  # what it measures (and nothing from before this run)
        self._measuring: Output | None = output if names else None  # the output, when it measures blocks
        if names and log is not None:
            log.begin_measurements(names)

    def due_at_ns(self, block: int) -> int:
        """When block number ``block`` (0: the first) falls due (ns on the driver's clock)."""
        return self.started_ns - (-block * self.block_frames * 1_000_000_000 // self.rate_hz)

    def pace_once(self, now_ns: int) -> int:
        """Render and hand to the output every block due by ``now_ns`` (ns); when more than
        PACED_MAX_BEHIND_S are due (a stall), count an underflow and render only the newest. Returns when the
        next block falls due (ns). Raises what the output's write raises (a full disk...), the blocks written
        before it measured."""
        due = max(0, (now_ns - self.started_ns) * self.rate_hz // (self.block_frames * 1_000_000_000) + 1)
        if due - self.blocks_due > self.most_behind:
            self.table.stats[tab.STAT_UNDERFLOWS] += 1
            self.blocks_due = due - 1
        written_t_s: list[float] = []
        try:
            while self.blocks_due < due:
                self.table.call(self._block)
                row = self.pipeline.last_telemetry_row()
                self.output.write(self._block, row)
                written_t_s.append(row["t"])
                self.blocks_due += 1
        finally:
            self._hand_measurements(written_t_s)
        return self.due_at_ns(self.blocks_due)

    def _hand_measurements(self, t_s: list[float]) -> None:
        """Move what the output measured of the blocks starting at ``t_s`` (s) to the log."""
        if self._measuring is None:
            return
        measured = self._measuring.take_measurements()
        if self._log is not None and t_s:
            self._log.add_measurements(np.array(t_s), measured)

    def finish(self) -> None:
        """The run ended: its rows stop waiting for measurements."""
        if self._measuring is not None and self._log is not None:
            self._log.end_measurements()


class PacedDriver(Driver):
    """A paced output: the URL is opened (and checked) at :meth:`open`."""

    def __init__(self, url: Url, *, device: Device, rate_hz: int, block_frames: int, options: RenderOptions,
                 stall_timeout_s: float = 0.5, clock: Clock | None = None):
        super().__init__(url, device=device, rate_hz=rate_hz, block_frames=block_frames, options=options,
                         stall_timeout_s=stall_timeout_s, clock=clock)
        self._output: Output | None = None
        self._pipeline: Pipeline | None = None
        self._thread: threading.Thread | None = None
        self._halt = threading.Event()
        self._error: BaseException | None = None

    def open(self, pipeline: Pipeline) -> None:
        """Open the output (ConfigError, BackendError as its scheme's open_url says)."""
        self._output = open_paced(self.url, device=self.device, fs_hz=self.rate_hz)
        self._output.warm()  # compiled now, not in the pacing thread while the clock runs
        self._pipeline = pipeline

    def run(self, table: CallbackTable) -> PacedRun:
        """The run's pacing from now on :attr:`clock` (block 0 due now), handing blocks to the opened output."""
        assert self._output is not None and self._pipeline is not None, "open() first"
        return PacedRun(table, self._output, self._pipeline, rate_hz=self.rate_hz, block_frames=self.block_frames,
                        started_ns=self.clock.now_ns(), log=self.log)

    def start(self, table: CallbackTable) -> None:
        """Start the pacing thread."""
        run = self.run(table)
        self._halt.clear()
        self._error = None
        thread = threading.Thread(target=self._loop, args=(run,), name="tpad-rt paced output", daemon=True)
        thread.start()
        self._thread = thread  # only once it runs: close() joins it

    def _loop(self, run: PacedRun) -> None:
        """Until halted: read the clock, step, sleep until the next block is due (at most PACED_POLL_NS)."""
        try:
            with run.output:
                while not self._halt.is_set():
                    now_ns = self.clock.now_ns()
                    self.clock.sleep_until_ns(min(run.pace_once(now_ns), now_ns + PACED_POLL_NS))
        except BaseException as error:  # noqa: BLE001 - reported by poll()
            self._error = error
        finally:
            run.finish()

    def poll(self, table: CallbackTable) -> BaseException | None:
        """The error the output or the thread met (a full disk...), or None."""
        return self._error

    def close(self, ramp_ms: float) -> BaseException | None:
        """Stop the thread (the output closes as it ends); the error it met, if any."""
        thread, self._thread = self._thread, None
        self._halt.set()
        if thread is not None:
            thread.join()  # the thread closed the output
        elif self._output is not None:  # opened, never started
            self._output.close()
        self._output = None
        error, self._error = self._error, None
        return error
