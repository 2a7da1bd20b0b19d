"""Run the compile plan (``tpad_rt.compile_plan``) in worker processes, report progress, stop them at once.

API map
-------
run_plan(jobs, on_progress=None) -> PlanReport
    start ``jobs`` workers (``python -m tpad_rt.compile_plan``; fewer when the plan has fewer steps), give
    each step to an idle worker once the steps it runs ``after`` are done, and return what each step
    compiled. ``on_progress(done, total, what)`` is called as steps finish and functions start compiling
    (``what``: the function or the step). CompileError when a worker fails or dies; on any exception
    (Ctrl-C's KeyboardInterrupt too) the workers are killed at once and the cache is cleaned of what they
    left half written (:func:`tpad_rt.kernel_cache.discard_unfinished`) before it propagates
PlanReport
    ``.compiled`` (step -> the tpad-rt functions numba compiled in it, in order), ``.concurrent`` (pairs of
    steps that ran at the same time), ``.functions`` (how many compiles in all), ``.shared()`` (functions two
    steps that ran at the same time both compiled: a plan whose ``after`` lacks a step; run_plan then removes
    their cache entries and raises CompileError)

Workers run in their own session, so a terminal's Ctrl-C reaches only this process: the main thread waits
on the workers' pipes, never inside numba, and kills them (SIGKILL: a worker inside LLVM would not run a
signal handler for seconds).
"""

from __future__ import annotations

import json
import os
import selectors
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import IO, Any

from tpad_rt.errors import TpadError
from tpad_rt.kernel_cache import PACKAGE_DIR, discard_functions, discard_unfinished

#: How much of a failed worker's stderr its error quotes (characters, the end).
STDERR_TAIL_CHARS = 2000


class CompileError(TpadError):
    """A compile worker failed or died."""


@dataclass
class PlanReport:
    """What a run of the plan compiled (module docstring)."""

    compiled: dict[str, list[str]] = field(default_factory=dict)
    concurrent: set[frozenset[str]] = field(default_factory=set)

    @property
    def functions(self) -> int:
        return sum(len(functions) for functions in self.compiled.values())

    def shared(self) -> set[str]:
        """Functions compiled by two steps that ran at the same time."""
        return {function for pair in self.concurrent if len(pair) == 2
                for function in set.intersection(*(set(self.compiled.get(step, ())) for step in pair))}


class _Worker:
    """One ``python -m tpad_rt.compile_plan`` process, its unread output and the step it runs."""

    def __init__(self) -> None:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, (str(PACKAGE_DIR.parent),
                                                                         os.environ.get("PYTHONPATH")))))
        self.stderr: IO[bytes] = tempfile.TemporaryFile()
        self.process = subprocess.Popen([sys.executable, "-m", "tpad_rt.compile_plan"], stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, stderr=self.stderr, env=env, start_new_session=True)
        self.pending = b""
        self.step: str | None = None

    def give(self, step: str) -> None:
        assert self.process.stdin is not None
        self.step = step
        self.process.stdin.write(step.encode() + b"\n")
        self.process.stdin.flush()

    def messages(self) -> list[dict[str, Any]]:
        """The messages it sent since the last call; EOF (it ended) as ``{"ended": True}``."""
        assert self.process.stdout is not None
        chunk = os.read(self.process.stdout.fileno(), 65536)
        if not chunk:
            return [{"ended": True}]
        lines = (self.pending + chunk).split(b"\n")
        self.pending = lines.pop()
        return [json.loads(line) for line in lines if line]

    def error(self, what: str) -> CompileError:
        """``what`` with the end of its stderr."""
        self.stderr.seek(0)
        tail = self.stderr.read().decode(errors="replace")[-STDERR_TAIL_CHARS:].strip()
        return CompileError(f"compiling the kernels: {what}" + (f"\n{tail}" if tail else ""))

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait()
        for pipe in (self.process.stdin, self.process.stdout):
            if pipe is not None:
                pipe.close()
        self.stderr.close()


def _ready(plan: list[tuple[str, list[str]]], todo: set[str], done: set[str]) -> str | None:
    """The first step of ``plan`` still to do whose ``after`` steps are all done."""
    return next((name for name, after in plan if name in todo and set(after) <= done), None)


def run_plan(jobs: int, on_progress: Callable[[int, int, str], None] | None = None) -> PlanReport:
    """Compile the whole plan with ``jobs`` workers (module docstring)."""
    started_ns = time.time_ns()
    workers = [_Worker() for _ in range(max(1, jobs))]
    report = PlanReport()
    try:
        _schedule(workers, report, on_progress or (lambda done, total, what: None))
    except BaseException:
        for worker in workers:
            worker.kill()
        discard_unfinished(started_ns)
        raise
    for worker in workers:
        assert worker.process.stdin is not None
        worker.process.stdin.close()
        worker.kill()  # at once: each step saved its cache before it said it was done, and an exit takes seconds
    shared = report.shared()
    if shared:
        discard_functions(shared)
        raise CompileError(f"compiling the kernels: steps that ran at once both compiled {sorted(shared)} (their "
                           "cache entries are removed; tpad_rt/compile_plan.py's steps lack an 'after': a bug)")
    return report


def _schedule(workers: list[_Worker], report: PlanReport, on_progress: Callable[[int, int, str], None]) -> None:
    """Hand out the steps and read the workers until every step is done (:func:`run_plan`)."""
    selector = selectors.DefaultSelector()
    for worker in workers:
        assert worker.process.stdout is not None
        selector.register(worker.process.stdout, selectors.EVENT_READ, worker)
    plan: list[tuple[str, list[str]]] | None = None
    todo: set[str] = set()
    done: set[str] = set()
    idle: list[_Worker] = []
    while plan is None or done != {name for name, _ in plan}:
        for key, _ in selector.select():
            worker = key.data
            for message in worker.messages():
                if "ended" in message:
                    raise worker.error(f"a worker ended during '{worker.step or 'start-up'}' "
                                       f"(exit status {worker.process.wait()})")
                if "failed" in message:
                    raise worker.error(f"'{message['failed']}' failed: {message['error']}")
                if "plan" in message:
                    if plan is None:
                        plan = [(name, list(after)) for name, after in message["plan"]]
                        todo = {name for name, _ in plan}
                    idle.append(worker)
                elif "compiling" in message:
                    report.compiled[worker.step].append(message["compiling"])
                    on_progress(len(done), len(plan or ()), message["compiling"].rsplit(".", 1)[-1])
                elif "done" in message:
                    done.add(message["done"])
                    worker.step = None
                    idle.append(worker)
                    on_progress(len(done), len(plan or ()), message["done"])
        while plan is not None and idle and (step := _ready(plan, todo, done)) is not None:
            todo.discard(step)
            worker = idle.pop(0)
            report.compiled[step] = []
            report.concurrent |= {frozenset((step, other.step)) for other in workers
                                  if other.step is not None and other is not worker}
            worker.give(step)
            on_progress(len(done), len(plan), step)
        if plan is not None and todo and len(idle) == len(workers):
            raise CompileError(f"compiling the kernels: the plan's steps {sorted(todo)} wait for steps it lacks")
