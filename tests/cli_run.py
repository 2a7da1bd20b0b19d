"""Run ``tpad-rt`` as a user would and measure it: exit status, output and peak memory.

Commands run as children of a fork server (tests/cli_forkserver.py) that has made the
imports every command makes, once: a command that refuses its input in one line then
takes milliseconds instead of the second a new interpreter spends importing. A call
whose environment changes settings those imports read once (``NUMBA_*``, ``PYTHON*``)
runs in a new interpreter instead.

The peak resident memory is the command's own. Linux counts a process's peak from the
memory it was forked from, and Python's subprocess forks (vfork) from the test process,
whose memory (over a GB late in a run) would then be every command's peak. The fork
server's children start from the server's imports (which the command would have made),
a new interpreter from a small launcher's few MB; both report the ``os.wait4`` figure.
"""

from __future__ import annotations

import functools
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import typing
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


#: Environment variables read once, at import, by the modules the fork server has imported.
_READ_AT_IMPORT = ("NUMBA_", "PYTHON")


class _ForkServer:
    """The fork server process (started on first use, restarted should it die); one command at a time."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._process: subprocess.Popen[bytes] | None = None

    def _started(self) -> subprocess.Popen[bytes]:
        if self._process is None or self._process.poll() is not None:
            self._process = subprocess.Popen([sys.executable, str(REPO / "tests" / "cli_forkserver.py")],
                                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, cwd=REPO)
        return self._process

    def run(self, args: tuple[str, ...], env: dict[str, str], stdout: str, stderr: str,
            timeout_s: float) -> tuple[int, float]:
        """(exit status, peak RSS in kB) of ``python -m tpad_rt ARGS`` forked with ``env``, output to the files."""
        with self._lock:
            server = self._started()
            assert server.stdin is not None and server.stdout is not None
            request = {"args": list(args), "cwd": str(REPO), "env": env, "stdout": stdout, "stderr": stderr}
            server.stdin.write(json.dumps(request).encode() + b"\n")
            server.stdin.flush()
            pid = json.loads(server.stdout.readline())["pid"]
            timer = threading.Timer(timeout_s, lambda: os.killpg(pid, signal.SIGKILL))
            timer.start()
            try:
                reply = json.loads(server.stdout.readline())
            finally:
                timer.cancel()
            return reply["status"], float(reply["peak_kb"])


_FORK_SERVER = _ForkServer()


def tpad_rt(*args: str, timeout_s: float = 300.0, env: dict[str, str] | None = None) -> Run:
    """Run ``python -m tpad_rt ARGS`` (stdin closed, no terminal) from the repository root, with
    ``env`` added to the environment.

    ``timeout_s`` is only a safety net (long enough for a cold numba cache): a command
    still running then is killed (with everything it started), and its return code is -9.
    """
    with tempfile.NamedTemporaryFile() as out, tempfile.NamedTemporaryFile() as err:
        if any(key.startswith(_READ_AT_IMPORT) for key in env or {}):
            returncode, peak_kb = _new_interpreter(args, env or {}, out, err, timeout_s)
        else:
            returncode, peak_kb = _FORK_SERVER.run(args, {**os.environ, **(env or {})}, out.name, err.name, timeout_s)
        out.seek(0)
        err.seek(0)
        return Run(returncode, out.read().decode(), err.read().decode(), peak_kb / 1024)


def _new_interpreter(args: tuple[str, ...], env: dict[str, str], out: typing.IO[bytes], err: typing.IO[bytes],
                     timeout_s: float) -> tuple[int, float]:
    """(exit status, peak RSS in kB) of ``python -m tpad_rt ARGS`` in a new interpreter, forked by _LAUNCHER."""
    with tempfile.NamedTemporaryFile("r") as peak:
        process = subprocess.Popen([sys.executable, "-c", _LAUNCHER, peak.name, *args], stdin=subprocess.DEVNULL,
                                   stdout=out, stderr=err, cwd=REPO, env={**os.environ, **env},
                                   start_new_session=True)
        timer = threading.Timer(timeout_s, lambda: os.killpg(process.pid, signal.SIGKILL))
        timer.start()
        try:
            process.wait()
        finally:
            timer.cancel()
        return process.returncode, float(peak.read() or "nan")
