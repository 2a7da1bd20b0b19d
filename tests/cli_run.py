"""Run ``tpad-rt`` in a fresh interpreter and measure it: exit status, output and peak memory.

The peak resident memory is the command's own. Linux counts a process's peak from the
memory it was forked from, and Python's subprocess forks (vfork) from the test process,
whose memory (over a GB late in a run) would then be every command's peak. So a small
launcher interpreter forks the command and reports its ``os.wait4`` figure: the command's
peak then starts from the launcher's few MB.
"""

from __future__ import annotations

import functools
import os
import signal
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


#: Forks ``python -m tpad_rt ARGS`` from a small interpreter; writes the command's peak RSS (kB) to the file
#: named by the first argument and exits with the command's status.
_LAUNCHER = """
import os, sys
pid = os.fork()
if pid == 0:
    os.execv(sys.executable, [sys.executable, "-m", "tpad_rt", *sys.argv[2:]])
_, status, usage = os.wait4(pid, 0)
with open(sys.argv[1], "w") as peak:
    peak.write(str(usage.ru_maxrss))
sys.exit(os.waitstatus_to_exitcode(status))
"""


def tpad_rt(*args: str, timeout_s: float = 300.0, env: dict[str, str] | None = None) -> Run:
    """Run ``python -m tpad_rt ARGS`` (stdin closed, no terminal) from the repository root, with
    ``env`` added to the environment.

    ``timeout_s`` is only a safety net (long enough for a cold numba cache): a command
    still running then is killed (with its launcher), and its return code is -9.
    """
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err, \
            tempfile.NamedTemporaryFile("r") as peak:
        process = subprocess.Popen([sys.executable, "-c", _LAUNCHER, peak.name, *args], stdin=subprocess.DEVNULL,
                                   stdout=out, stderr=err, cwd=REPO, env={**os.environ, **(env or {})},
                                   start_new_session=True)
        timer = threading.Timer(timeout_s, lambda: os.killpg(process.pid, signal.SIGKILL))
        timer.start()
        try:
            process.wait()
        finally:
            timer.cancel()
        out.seek(0)
        err.seek(0)
        peak_kb = float(peak.read() or "nan")
        return Run(process.returncode, out.read().decode(), err.read().decode(), peak_kb / 1024)
