"""A JACK dummy server and CPU hogs for the latency benchmark, started and stopped by PID.

The bench-side twin of tests/jack_server.py (which lives with the tests and depends
on their skip rules): ``jack_server(rate_hz, period_frames)`` starts
``jackd -n NAME -p 16 -d dummy -r RATE -p PERIOD`` with the first NAME of
``tpadrt-bench-0..3`` no running server has (reused, not random: JACK keeps a small
table of servers in shared memory and reclaims the entry of a server that died without
cleaning up only when a new one takes its name), logs to a file (an unread pipe
would block jackd), waits for it with ``jack_wait -s NAME -w``, and yields an environment for child processes
(``JACK_DEFAULT_SERVER=NAME``); on exit it sends SIGTERM to the PID and waits.
This process never loads PortAudio: every measured configuration runs in a fresh
child process, which initialises PortAudio while the server runs (ARCHITECTURE.md
section 5 says why each flag). ``cpu_hogs(n)`` runs ``n`` processes spinning a
pure-Python loop, stopped the same way.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

#: Seconds to wait for the server to come up, and to exit after SIGTERM.
START_TIMEOUT_S = 10
EXIT_TIMEOUT_S = 10
#: Server names tried (JACK's own table holds few servers; the tests use tpadrt-N).
MAX_SERVERS = 4


def _program(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        raise SystemExit(f"bench/latency: program '{name}' not found (Debian: apt-get install jackd2)")
    return path


def _free_name(jack_wait: str) -> str:
    """The first of ``tpadrt-bench-0`` .. ``tpadrt-bench-{MAX_SERVERS - 1}`` no running server has."""
    for index in range(MAX_SERVERS):
        name = f"tpadrt-bench-{index}"
        probe = subprocess.run([jack_wait, "-s", name, "-c"], capture_output=True, text=True, timeout=10)
        if "not running" in probe.stdout:
            return name
    raise RuntimeError(f"{MAX_SERVERS} JACK servers named tpadrt-bench-N already run")


def _stop(process: subprocess.Popen) -> None:
    """SIGTERM ``process`` (by PID), wait; SIGKILL if it does not exit in time."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
    try:
        process.wait(EXIT_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


@contextlib.contextmanager
def jack_server(rate_hz: int, period_frames: int, log: Path | None = None) -> Iterator[dict[str, str]]:
    """Run a dummy JACK server; yields the environment its clients need. ``log``: jackd's output."""
    jackd, jack_wait = _program("jackd"), _program("jack_wait")
    name = _free_name(jack_wait)
    sink = open(log, "w") if log is not None else tempfile.TemporaryFile()  # noqa: SIM115
    process = subprocess.Popen(
        [jackd, "-n", name, "-p", "16", "-d", "dummy", "-r", str(rate_hz), "-p", str(period_frames)],
        stdout=sink, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        waited = subprocess.run([jack_wait, "-s", name, "-w", "-t", str(START_TIMEOUT_S)],
                                capture_output=True, text=True, timeout=START_TIMEOUT_S + 5)
        if waited.returncode != 0 or process.poll() is not None:
            raise RuntimeError(f"jackd {name} did not start: {waited.stdout} {waited.stderr}")
        yield {**os.environ, "JACK_DEFAULT_SERVER": name}
    finally:
        _stop(process)
        sink.close()


@contextlib.contextmanager
def cpu_hogs(count: int) -> Iterator[list[int]]:
    """``count`` processes each spinning ``while True: pass``; yields their PIDs."""
    processes = [subprocess.Popen([sys.executable, "-c", "while True: pass"], start_new_session=True)
                 for _ in range(count)]
    try:
        yield [process.pid for process in processes]
    finally:
        for process in processes:
            _stop(process)
