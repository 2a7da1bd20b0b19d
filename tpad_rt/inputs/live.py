"""Feeding any input into a renderer in real time: :class:`LiveFeed`.

A feed is a thread and a context manager (the pynput model): ``with LiveFeed(source,
renderer.push_finger, renderer.lift): ...`` starts it and, on exit, stops it, joins it
and re-raises an error raised while feeding. An input with samples over time
(``scripted://``, ``file://``) is replayed: each sample is pushed when it is due,
``t_s`` after the feed started, stamped with that due time on the feed's clock; the
feed sleeps in between (real-time pacing, in the feeder: the output never waits on
it). A live input (``mouse://``) is forwarded: each event is pushed from the input's
listener thread as it happens. A touching sample calls ``push_finger(x_mm, y_mm,
force_n=..., t=...)`` (``force_n=None`` when the sample's force is unknown), a lifted
one ``lift()``; when the feed ends (input over or :meth:`LiveFeed.stop`) with the finger
down, it lifts it. ``push_finger`` and ``lift`` are called from one thread at a time.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import Protocol

from tpad_rt.inputs.base import Input, LiveInput


class PushFinger(Protocol):
    """What a feed pushes to: the Renderer's ``push_finger`` (mm, mm, N or None, s on its clock)."""

    def __call__(self, x_mm: float, y_mm: float, force_n: float | None = None, t: float | None = None) -> None: ...


class LiveFeed(threading.Thread):
    """Feeds ``source`` into ``push_finger`` / ``lift`` in real time (module docstring).

    ``clock()`` (s) is the renderer's clock, the one ``push_finger``'s ``t`` is on
    (default ``time.monotonic``; for a Renderer, ``renderer.now_s``: start the feed once
    the renderer runs, so that its clock moves); live inputs' ``time.monotonic()``
    stamps are shifted onto it by an offset measured once, when listening starts. ``pause(seconds)`` blocks up to ``seconds`` and returns True when the feed
    is stopping (default: a wait on the feed's stop event; inject it with a fake
    clock to replay without sleeping). Replayed inputs are read ``chunk_s`` (s) of
    input time at a time.
    """

    def __init__(self, source: Input, push_finger: PushFinger, lift: Callable[[], None], *,
                 clock: Callable[[], float] = time.monotonic, pause: Callable[[float], bool] | None = None,
                 chunk_s: float = 0.05):
        super().__init__(name="tpad-rt live feed", daemon=True)
        if not chunk_s > 0:
            raise ValueError(f"chunk_s must be > 0, got {chunk_s!r}")
        self.source = source
        self.push_finger = push_finger
        self.lift = lift
        self.clock = clock
        self.chunk_s = chunk_s
        self._stopping = threading.Event()
        self._pause = self._stopping.wait if pause is None else pause
        self._ready = threading.Event()
        self._done = False
        self._touching = False
        self._error: BaseException | None = None
        #: The feed clock's reading (s) when replay started (a replayed sample is due at ``start_s + t_s``).
        self.start_s: float | None = None

    @property
    def done(self) -> bool:
        """True once a finite input has been fed to its end."""
        return self._done

    def stop(self) -> None:
        """Ask the feed to stop (idempotent; returns at once, :meth:`join` waits)."""
        self._stopping.set()

    def wait(self) -> None:
        """Block until the feed is feeding (a live input listening) or has ended."""
        self._ready.wait()

    def join(self, timeout: float | None = None) -> None:
        """Wait for the thread to end; re-raise (once) an error raised while feeding."""
        super().join(timeout)
        if not self.is_alive() and self._error is not None:
            error, self._error = self._error, None
            raise error

    def __enter__(self) -> LiveFeed:
        self.start()
        self.wait()
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.stop()
        self.join()

    def run(self) -> None:
        try:
            if isinstance(self.source, LiveInput):
                self._forward(self.source)
            else:
                self._replay()
            if self._touching:
                self.lift()
        except BaseException as error:  # noqa: BLE001 - handed to join(), as pynput does
            self._error = error
        finally:
            self._ready.set()

    def _replay(self) -> None:
        """Push the samples of ``self.source`` when due, to its end or until stopped."""
        end_s = self.source.duration_s
        self.start_s = self.clock()
        self._ready.set()
        span_start_s, span_end_s = -math.inf, 0.0
        while not self._stopping.is_set():
            span_end_s = span_end_s + self.chunk_s if end_s is None else min(span_end_s + self.chunk_s, end_s)
            for t_s, x_mm, y_mm, force_n, down in self.source.samples_between(span_start_s, span_end_s).tolist():
                due_s = self.start_s + t_s
                while (remaining_s := due_s - self.clock()) > 0:
                    if self._pause(remaining_s):
                        return
                self._deliver(due_s, x_mm, y_mm, force_n, down)
            if end_s is not None and span_end_s >= end_s:
                self._done = True
                return
            span_start_s = span_end_s

    def _forward(self, source: LiveInput) -> None:
        """Push ``source``'s events as they happen, until stopped or an event fails to push."""
        offset_s = 0.0 if self.clock is time.monotonic else self.clock() - time.monotonic()
        failure: list[BaseException] = []

        def on_sample(t_s: float, x_mm: float, y_mm: float, force_n: float, down: bool) -> None:
            if self._stopping.is_set():
                return
            try:
                self._deliver(t_s + offset_s, x_mm, y_mm, force_n, down)
            except BaseException as error:  # noqa: BLE001 - re-raised by the feed thread
                failure.append(error)
                self._stopping.set()

        with source.listen(on_sample):
            self._ready.set()
            self._stopping.wait()
        if failure:
            raise failure[0]

    def _deliver(self, t_s: float, x_mm: float, y_mm: float, force_n: float, down: bool) -> None:
        """Push one sample (``t_s`` on the feed's clock), or lift for a lifted one."""
        if down:
            self.push_finger(x_mm, y_mm, force_n=None if math.isnan(force_n) else force_n, t=t_s)
        else:
            self.lift()
        self._touching = down
