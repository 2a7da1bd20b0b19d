"""What every input backend implements: finger samples over a span of time.

An input is a source of finger samples ``(t_s, x_mm, y_mm, force_n, down)`` in the
renderer's clock (docs/kernel.md "Time"): seconds, plate millimetres, newtons (NaN:
unknown, the renderer's default force applies) and a touching flag. The offline
renderer asks for the samples of each block's span; the real-time engine will ask from
an input thread, so :meth:`Input.samples_between` must be safe to call from a thread
other than the one that opened the input (scripted inputs are pure functions of time,
file inputs read arrays loaded up front).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from types import TracebackType

import numpy as np

#: One finger sample per row.
FINGER_DTYPE = np.dtype(
    [("t_s", "<f8"), ("x_mm", "<f8"), ("y_mm", "<f8"), ("force_n", "<f8"), ("down", "?")]
)


class Input(ABC):
    """Base class of input backends (pyserial model: state what a backend must implement).

    A backend implements :attr:`duration_s` and :meth:`samples_between`; one that
    holds a resource (a thread, a device) also overrides :meth:`close`. Inputs are
    context managers that close on exit.
    """

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
