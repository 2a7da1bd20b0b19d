"""What every driver does: run the render callback of one :class:`tpad_rt.realtime.CallbackTable` for an output.

The Renderer (tpad_rt.engine) calls, in order: :meth:`Driver.prepare` (find the
hardware), :meth:`Driver.warm` (compile what the driver runs, on a copy of the
table), :meth:`Driver.open` (open the hardware; it may tell the pipeline its drive
scale), :meth:`Driver.start`; then its watcher thread calls :meth:`Driver.poll` every
20 ms (``tpad_rt.engine.WATCH_PERIOD_S``) until :meth:`Driver.close`. A driver may be started again after a close.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from tpad_rt.device import Device
from tpad_rt.outputs.base import Consumes
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.realtime import CallbackTable
from tpad_rt.urls import Url


class Driver(ABC):
    """Runs the render callback for the output ``url`` names (drivers set ``consumes``).

    ``rate_hz`` (Hz) and ``block_frames`` are the renderer's; a driver replaces them by
    what its URL or its hardware asks for, and may adjust ``options`` (e.g. keep the
    control period at another rate). ``channels`` interleaved channels, the drive in
    ``channel`` (0-based), are known after :meth:`prepare`.
    """

    consumes = Consumes.DAC

    def __init__(self, url: Url, *, device: Device, rate_hz: int, block_frames: int, options: RenderOptions):
        self.url = url
        self.device = device
        self.rate_hz = rate_hz
        self.block_frames = block_frames
        self.options = options
        self.channels = 1
        self.channel = 0

    def prepare(self) -> None:
        """Find the hardware and learn its channels (BackendError when it is not there); nothing by default."""

    def warm(self, table: CallbackTable) -> None:
        """Compile (or load) what the driver runs, calling it on ``table``, a copy of the real one."""
        table.call(np.zeros(self.block_frames * self.channels, dtype=np.float32))

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

    def stats(self) -> dict[str, Any]:
        """The driver's own figures for Renderer.stats(), if it has any (none by default)."""
        return {}

    def stall_limit_s(self) -> float:
        """How long (s) the output may go without a callback before :meth:`poll` reports it stalled (0: it
        reports failures as they come)."""
        return 0.0

    def stream_time_s(self) -> float:
        """The output's own clock (s), NaN where it has none."""
        return math.nan
