"""Run ``tpad-rt`` in a fresh interpreter and measure it: exit status, output and peak memory.

The peak resident memory is the child's own (``os.wait4`` on its pid), so an earlier
child or the test process cannot hide or inflate it.
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Run:
    """A finished ``tpad-rt`` process."""

    returncode: int
    stdout: str
    stderr: str
    peak_mb: float

    def assert_one_line_error(self, expected: str) -> None:
        """Exit status 1, exactly one line on stderr containing ``expected``, no traceback."""
        assert self.returncode == 1, (self.returncode, self.stderr)
        assert "Traceback" not in self.stderr and "Warning" not in self.stderr, self.stderr
        assert self.stderr.count("\n") == 1 and self.stderr.endswith("\n"), self.stderr
        assert expected in self.stderr, self.stderr


@functools.cache
def warm_numba_cache() -> None:
    """Render and play a few milliseconds once, so numba's on-disk cache holds every kernel compiled.

    With a cold cache (a fresh clone, a kernel file just edited) the first render compiles
    for about a minute and near 1 GB; a measurement of what a refusal allocates must not
    include that, should a case get that far.
    """
    with tempfile.TemporaryDirectory() as folder:
        for args in (("render", "textures/grating.yaml", "--input", "scripted://still?duration_s=0.01",
                      "--out", f"{folder}/warm.wav"),
                     ("play", "textures/grating.yaml", "--input", "scripted://still?duration_s=0.05",
                      "--output", "sim://", "--duration", "0.05")):
            done = tpad_rt(*args, timeout_s=600)
            assert done.returncode == 0, done.stderr


def tpad_rt(*args: str, timeout_s: float = 300.0, env: dict[str, str] | None = None) -> Run:
    """Run ``python -m tpad_rt ARGS`` (stdin closed, no terminal) from the repository root, with
    ``env`` added to the environment.

    ``timeout_s`` is only a safety net (long enough for a cold numba cache): a process
    still running then is killed, and its return code is -9.
    """
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        process = subprocess.Popen([sys.executable, "-m", "tpad_rt", *args], stdin=subprocess.DEVNULL,
                                   stdout=out, stderr=err, cwd=REPO, env={**os.environ, **(env or {})})
        timer = threading.Timer(timeout_s, process.kill)
        timer.start()
        try:
            _, status, usage = os.wait4(process.pid, 0)
        finally:
            timer.cancel()
        process.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        return Run(process.returncode, out.read().decode(), err.read().decode(), usage.ru_maxrss / 1024)
