"""A notice while numba compiles the kernels: the first run only, with what it is compiling.

API map
-------
compile_notice(console=None)
    a context manager; inside it, the first compile of a kernel (``tpad_rt.kernel``)
    prints one line to stderr
    (:data:`NOTICE`), then, on a terminal, a spinner naming each function as it compiles,
    and at the end how many it compiled and how long it took. When everything loads from
    numba's cache (every run after the first) it prints nothing. Nested uses show once.
announce_if_uncached(*kernels)
    inside compile_notice: print the notice now if numba's cache holds nothing for one of
    ``kernels`` (numba dispatchers), instead of at their first compile, which numba starts
    only after loading its own lowering registries (about 0.4 s)

numba compiles a kernel the first time it is called in a fresh cache (about 10 s for the
render kernel on a 2-core machine), then loads it from its cache in milliseconds
(docs/kernel.md "Compilation"). The notice listens to numba's own compile events
(``numba.core.event``), so it never guesses from timing.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Iterator
from typing import Any

from numba.core import event
from rich.console import Console
from rich.status import Status

#: The first line a compile prints.
NOTICE = "tpad-rt: compiling the render kernels (first run only; numba caches them for the next runs)"

#: Compiles of functions in this package are the ones the notice is about.
KERNEL_PACKAGE = "tpad_rt.kernel"

_active = threading.Lock()  # held by the outermost compile_notice
_current: list[_Notice] = []  # the outermost compile_notice's listener, while it is active


class _Notice(event.Listener):
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
            self.console.print(NOTICE)
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


@contextlib.contextmanager
def compile_notice(console: Console | None = None) -> Iterator[None]:
    """Show the compile notice for compiles inside the block (module docstring); on stderr by default."""
    if not _active.acquire(blocking=False):  # an outer compile_notice shows them
        yield
        return
    notice = _Notice(console or Console(stderr=True, soft_wrap=True, highlight=False, markup=False, emoji=False))
    _current.append(notice)
    try:
        with event.install_listener("numba:compile", notice):
            yield
    finally:
        _current.clear()
        notice.finish()
        _active.release()


def announce_if_uncached(*kernels: Any) -> None:
    """Inside :func:`compile_notice`, print the notice now when numba's disk cache has no index for one of
    ``kernels`` (numba dispatchers): they will compile. Nothing outside it, or when all are cached."""
    if _current and not all(_cached(kernel) for kernel in kernels):
        _current[0].begin()


def _cached(kernel: Any) -> bool:
    """Whether numba's disk cache has an index file for ``kernel`` (True when that cannot be told).

    numba offers no public way to ask before it compiles: its dispatcher's ``_cache`` and the
    cache file's ``_index_path`` are private, read here only. A stale index (a source changed)
    counts as cached: the compile events announce that compile, a little later.
    """
    try:
        return bool(os.path.exists(kernel._cache._cache_file._index_path))
    except AttributeError:
        return True
