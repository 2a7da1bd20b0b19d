"""What every input backend implements: finger samples over a span of time.

An input is a source of finger samples ``(t_s, x_mm, y_mm, force_n, down)`` in the
renderer's clock (docs/kernel.md "Time"): seconds, plate millimetres, newtons (NaN:
unknown, the renderer's default force applies) and a touching flag. The offline
renderer asks for the samples of each block's span; the real-time engine will ask from
an input thread, so :meth:`Input.samples_between` must be safe to call from a thread
other than the one that opened the input (scripted inputs are pure functions of time,
file inputs read arrays loaded up front).

A live input (:class:`LiveInput`, ``live = True``: the mouse) has no samples over a
span of time: it exists only as it happens and delivers each event through
:meth:`LiveInput.listen`; its :meth:`~LiveInput.samples_between` raises BackendError.
:class:`tpad_rt.inputs.live.LiveFeed` feeds either kind into a renderer in real time.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from contextlib import AbstractContextManager
from types import TracebackType
from typing import TYPE_CHECKING

import numpy as np

from tpad_rt.errors import BackendError
from tpad_rt.limits import DEFAULT_PLATE_MM, position_range_mm

if TYPE_CHECKING:
    from tpad_rt.device import Device

#: One finger sample per row.
FINGER_DTYPE = np.dtype(
    [("t_s", "<f8"), ("x_mm", "<f8"), ("y_mm", "<f8"), ("force_n", "<f8"), ("down", "?")]
)


def plate_size_mm(device: Device | None) -> tuple[float, float]:
    """``(length, width)`` (mm) of ``device``'s plate, or DEFAULT_PLATE_MM without a device."""
    return DEFAULT_PLATE_MM if device is None else (device.plate.length_m * 1e3, device.plate.width_m * 1e3)


def position_range(device: Device | None) -> tuple[tuple[float, float], tuple[float, float]]:
    """``((x_low, x_high), (y_low, y_high))`` (mm): the finger positions an input may report on
    ``device``'s plate (:func:`tpad_rt.limits.position_range_mm`; the default plate without a device)."""
    return position_range_mm(*plate_size_mm(device))


class Input(ABC):
    """Base class of input backends (pyserial model: state what a backend must implement).

    A backend implements :attr:`duration_s` and :meth:`samples_between`; one that
    holds a resource (a thread, a device) also overrides :meth:`close`. Inputs are
    context managers that close on exit.
    """

    #: False: samples exist for any span (replayable offline); True: a :class:`LiveInput`.
    live: bool = False

    @property
    @abstractmethod
    def duration_s(self) -> float | None:
        """Time (s) of the input's last sample (its natural end), or None when endless."""

    @abstractmethod
    def samples_between(self, t0_s: float, t1_s: float) -> np.ndarray:
        """The samples with ``t0_s < t_s <= t1_s`` in time order, a FINGER_DTYPE array.

        ``t0_s`` may be ``-inf`` (from the start). Consecutive spans ``(a, b]``,
        ``(b, c]`` never repeat or skip a sample.
        """

    def close(self) -> None:
        """Release what the input holds (nothing by default)."""

    def __enter__(self) -> Input:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        self.close()


#: Receives one live finger sample: FINGER_DTYPE's fields in order, ``(t_s, x_mm, y_mm, force_n, down)``.
SampleSink = Callable[[float, float, float, float, bool], None]


class LiveInput(Input):
    """An input that exists only as it happens (a mouse): events, not spans of time.

    A backend sets :attr:`scheme` and implements :meth:`listen`. It is endless
    (``duration_s`` is None) and cannot be rendered offline.
    """

    live = True
    #: The URL scheme, for messages (``"mouse"``).
    scheme: str

    @property
    def duration_s(self) -> None:
        """None: a live input never ends by itself."""
        return None

    def samples_between(self, t0_s: float, t1_s: float) -> np.ndarray:
        """Unsupported: always raises BackendError (a live input has no samples over a span of time)."""
        raise BackendError(
            f"input {self.scheme}://: a live input (events as they happen) cannot be rendered offline; "
            "use it in real time (tpad-rt play, or a Renderer fed by tpad_rt.inputs.live.LiveFeed)"
        )

    @abstractmethod
    def listen(self, on_sample: SampleSink) -> AbstractContextManager[None]:
        """A context manager delivering events to ``on_sample`` while it is open.

        Entering starts the input's own thread and returns once it is ready to
        receive events; each event then calls ``on_sample`` from that thread, with
        ``t_s`` the event's ``time.monotonic()`` (s). Exiting stops and joins the
        thread and re-raises an error raised in it (``on_sample``'s included).
        """
