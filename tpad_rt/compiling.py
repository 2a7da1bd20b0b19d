"""Compile every kernel once, up front, with progress; and a notice for any compile the plan did not cover.

API map
-------
ensure_compiled(jobs=None, console=None) -> PlanReport | None
    when numba's cache lacks the whole compile plan (:mod:`tpad_rt.kernel_cache`), compile all of it, for
    every command at once, in worker processes (:mod:`tpad_rt.compile_runner`): one line first saying what,
    why and about how long (:data:`NOTICE`), then progress as steps done of the plan's total (a bar on a
    terminal, else a line at each tenth), then what it compiled. Ctrl-C stops it within a second
    (KeyboardInterrupt; the workers are killed, nothing half written is left to trust). Returns the plan's
    report, None when everything was compiled already (or numba's JIT is off). Waits while another process
    compiles it.
compile_notice(console=None)
    a context manager; inside it, a compile of a kernel (``tpad_rt.kernel``) in this process, which the plan
    should have made unnecessary, prints one line to stderr (:data:`MISSING`), then, on a terminal, a spinner
    naming each function as it compiles, and at the end how many it compiled and how long it took. Nested
    uses show once.
default_jobs() -> int
    the worker count ``ensure_compiled`` uses by default: the CPUs, at most :data:`MAX_DEFAULT_JOBS`

numba compiles a kernel the first time it is called in a fresh cache (about 10 s for the render kernel on a
2-core machine), then loads it from its cache in milliseconds (docs/kernel.md "Compilation"). The notice
listens to numba's own compile events (``numba.core.event``), so it never guesses from timing.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from tpad_rt import kernel_cache
from tpad_rt.compile_runner import PlanReport, run_plan

#: How the line that starts a compile of the plan begins.
NOTICE = "tpad-rt: compiling the kernels of every command, once"
#: The first line of a compile in this process (a kernel the plan's compile did not leave in the cache).
MISSING = "tpad-rt: compiling kernels missing from numba's cache"
#: The most workers ensure_compiled starts by default (the plan's steps allow about three at once).
MAX_DEFAULT_JOBS = 2
#: Wall time (s) of a compile of the whole plan with 1 and 2 workers on a quiet 2-core machine (the notice's
#: estimate; measured: 24.0 s and 17.1 s, docs/kernel.md "Compiling once").
PLAN_WALL_S = {1: 25, 2: 20}
#: Progress lines off a terminal: one each time another tenth of the steps is done.
PLAIN_PROGRESS_STEP = 0.1

#: Compiles of functions in this package are the ones the notice is about.
KERNEL_PACKAGE = "tpad_rt.kernel"

_active = threading.Lock()  # held by the outermost compile_notice


@contextlib.contextmanager
def compile_notice(console: Console | None = None) -> Iterator[None]:
    """Show the compile notice for compiles inside the block (module docstring); on stderr by default."""
    if "numba" not in sys.modules and kernel_cache.plan_complete():
        yield  # every path's kernels are cached (the compile plan covers them): nothing to listen for, and a start
        return  # on ahead-of-time code does not import numba for it
    from numba.core import event

    from tpad_rt.compile_events import Notice

    if not _active.acquire(blocking=False):  # an outer compile_notice shows them
        yield
        return
    notice = Notice(console or Console(stderr=True, soft_wrap=True, highlight=False, markup=False, emoji=False))
    try:
        with event.install_listener("numba:compile", notice):
            yield
    finally:
        notice.finish()
        _active.release()


def default_jobs() -> int:
    """The CPUs of this machine, at most MAX_DEFAULT_JOBS."""
    return max(1, min(MAX_DEFAULT_JOBS, os.cpu_count() or 1))


def _stderr_console() -> Console:
    return Console(stderr=True, soft_wrap=True, highlight=False, markup=False, emoji=False)


def ensure_compiled(jobs: int | None = None, console: Console | None = None) -> PlanReport | None:
    """Compile the whole plan unless numba's cache has it (module docstring); raises CompileError (a worker
    failed) and KeyboardInterrupt (Ctrl-C)."""
    if kernel_cache.plan_complete():
        return None
    import numba

    if numba.config.DISABLE_JIT:  # type: ignore[attr-defined]  # not in its stubs
        return None  # with numba's JIT off (the kernel coverage run) nothing compiles
    console = console or _stderr_console()
    waiting = "tpad-rt: waiting for another tpad-rt that is compiling the kernels"
    with kernel_cache.compile_lock(lambda: console.print(waiting)):
        if kernel_cache.plan_complete():
            return None
        return _compile_plan(jobs or default_jobs(), console)


@contextlib.contextmanager
def _interruptible() -> Iterator[None]:
    """Ctrl-C raises KeyboardInterrupt in the block (a caller may have made SIGINT set a flag instead); only
    the main thread can change that, elsewhere nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _compile_plan(jobs: int, console: Console) -> PlanReport:
    """Say why and for how long, compile the plan with progress, say what it did, mark it complete."""
    where = kernel_cache.cache_dir(kernel_cache.COMPILED_PACKAGES[0])
    why = ("the kernels or numba changed since they were last compiled" if kernel_cache.marked_before()
           else f"no complete compile in numba's cache in {where} yet")
    estimate_s = PLAN_WALL_S[min(jobs, max(PLAN_WALL_S))]
    console.print(f"{NOTICE} ({why}); about {estimate_s} s on a quiet 2-core machine with {jobs} "
                  f"job{'s' if jobs > 1 else ''}; Ctrl-C stops")
    started_s = time.perf_counter()
    with _interruptible(), _progress(console, started_s) as on_progress:
        report = run_plan(jobs, on_progress)
    kernel_cache.mark_plan_complete()
    console.print(f"tpad-rt: compiled {report.functions} functions in {time.perf_counter() - started_s:.1f} s "
                  f"with {jobs} job{'s' if jobs > 1 else ''}, cached in {where}")
    return report


@contextlib.contextmanager
def _progress(console: Console, started_s: float) -> Iterator[Any]:
    """A progress callback for run_plan: a rich bar on a terminal, else a line each PLAIN_PROGRESS_STEP."""
    if console.is_terminal:
        columns = (TextColumn("compiling {task.description}"), BarColumn(), MofNCompleteColumn(),
                   TextColumn("steps"), TimeElapsedColumn())
        with Progress(*columns, console=console, transient=True) as bar:
            task = bar.add_task("", total=None)

            def update(done: int, total: int, what: str) -> None:
                bar.update(task, completed=done, total=total, description=what)

            yield update
        return
    shown = [0.0]

    def print_tenths(done: int, total: int, what: str) -> None:
        if total and done / total >= shown[0] + PLAIN_PROGRESS_STEP - 1e-9:
            shown[0] = done / total
            console.print(f"tpad-rt: compiling: {done}/{total} steps done ({what}), "
                          f"{time.perf_counter() - started_s:.0f} s")

    yield print_tenths
