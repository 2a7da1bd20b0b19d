"""numba's compile events, counted: the notice :func:`tpad_rt.compiling.compile_notice` shows for kernels
compiled outside the compile plan (imports numba; :mod:`tpad_rt.compiling` imports this module only when
numba may compile).

API map
-------
Notice(console)
    a ``numba.core.event.Listener``: prints :data:`tpad_rt.compiling.MISSING` at the first compile of a
    tpad-rt kernel (``tpad_rt.kernel``), keeps a spinner on a terminal, and ``finish()`` says how many
    functions it compiled and how long that took
"""

from __future__ import annotations

import time
from typing import Any

from numba.core import event
from rich.console import Console
from rich.status import Status

from tpad_rt.compiling import KERNEL_PACKAGE, MISSING


class Notice(event.Listener):
    """Counts numba's compiles; prints the notice at the first and keeps a spinner up to date."""

    def __init__(self, console: Console):
        self.console = console
        self.started_s: float | None = None
        self.compiled = 0
        self.status: Status | None = None

    def begin(self) -> None:
        """Print the notice and start the spinner, once."""
        if self.started_s is None:
            self.started_s = time.perf_counter()
            self.console.print(MISSING)
            if self.console.is_terminal:
                self.status = self.console.status("compiling")
                self.status.start()

    def on_start(self, compile_event: event.Event) -> None:
        if not _is_kernel(compile_event.data):
            return
        self.begin()
        if self.status is not None:
            self.status.update(f"compiling {_name(compile_event.data)} ({self.compiled} functions done)")

    def on_end(self, compile_event: event.Event) -> None:
        if _is_kernel(compile_event.data):
            self.compiled += 1

    def finish(self) -> None:
        """Stop the spinner; say what was compiled, if anything."""
        if self.status is not None:
            self.status.stop()
        if self.started_s is not None:
            self.console.print(f"tpad-rt: compiled {self.compiled} functions in "
                               f"{time.perf_counter() - self.started_s:.1f} s")


def _function(data: Any) -> Any:
    """The Python function a compile event is about (None if it names none)."""
    dispatcher = data.get("dispatcher") if isinstance(data, dict) else None
    return getattr(dispatcher, "py_func", None)


def _is_kernel(data: Any) -> bool:
    """True for a compile of one of tpad-rt's kernels (``tpad_rt.kernel``), not of other numba code (the
    physics module's ufuncs, the user's own)."""
    return str(getattr(_function(data), "__module__", "")).startswith(KERNEL_PACKAGE)


def _name(data: Any) -> str:
    """The name of the function a compile event is about."""
    return str(getattr(_function(data), "__qualname__", "a kernel"))
