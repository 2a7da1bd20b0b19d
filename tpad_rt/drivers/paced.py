"""The driver of paced outputs (``sim://``, ``wav://``, ``null://``): a Python thread runs the callback.

The thread calls the same native render callback as PortAudio does, no faster than
real time, and hands each block to the output's :meth:`tpad_rt.outputs.Output.write`
with its telemetry row. It holds the GIL: a simulator or a recorder, not a real-time
path (docs/realtime.md).
"""

from __future__ import annotations

import threading
import time

import numpy as np

from tpad_rt.clock import Clock
from tpad_rt.device import Device
from tpad_rt.drivers.base import Driver
from tpad_rt.kernel import table as tab
from tpad_rt.outputs import Output, open_output
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.realtime import CallbackTable
from tpad_rt.urls import Url

#: An output further behind real time than this (s) skips ahead instead of catching up in a burst, and counts
#: an underflow.
PACED_MAX_BEHIND_S = 0.1


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
        """Open the output (ConfigError, BackendError as :func:`tpad_rt.outputs.open_output`)."""
        self._output = open_output(self.url.text, device=self.device, fs_hz=self.rate_hz)
        self._output.warm()  # compiled now, not in the pacing thread while the clock runs
        self._pipeline = pipeline

    def start(self, table: CallbackTable) -> None:
        """Start the pacing thread."""
        assert self._output is not None, "open() first"
        self._halt.clear()
        self._error = None
        thread = threading.Thread(target=self._run, args=(table, self._output), name="tpad-rt paced output",
                                  daemon=True)
        thread.start()
        self._thread = thread  # only once it runs: close() joins it

    def _run(self, table: CallbackTable, output: Output) -> None:
        try:
            with output:
                self._pace(table, output)
        except BaseException as error:  # noqa: BLE001 - reported by poll()
            self._error = error

    def _pace(self, table: CallbackTable, output: Output) -> None:
        """Call the render callback one block at a time, no faster than real time; hand blocks to ``output``."""
        pipeline = self._pipeline
        assert pipeline is not None
        block = np.zeros(self.block_frames, dtype=np.float32)
        most_behind = max(1, round(PACED_MAX_BEHIND_S * self.rate_hz / self.block_frames))
        started = time.monotonic()
        rendered = 0
        while not self._halt.is_set():
            due = int((time.monotonic() - started) * self.rate_hz / self.block_frames) + 1
            if due - rendered > most_behind:  # stalled (e.g. compiling): skip ahead, count an underflow
                table.stats[tab.STAT_UNDERFLOWS] += 1
                rendered = due - 1
            for _ in range(due - rendered):
                table.call(block)
                output.write(block, pipeline.last_telemetry_row())
            rendered = max(rendered, due)
            time.sleep(min(0.005, self.block_frames / self.rate_hz))

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
