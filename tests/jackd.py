"""A JACK server on the dummy backend, started and stopped by PID.

The real-time stand-in for a sound card that the tests and the latency benchmark use
(docs/testing.md says why each flag): ``dummy_server(rate_hz,
period_frames)`` starts ``jackd -n NAME -p 16 -d dummy -r RATE -p PERIOD``, waits for
it with ``jack_wait -s NAME -w``, then until a client of it lists its playback ports (a client
attached: :func:`wait_until_serving`), and yields a :class:`RunningServer` (point clients at
it with ``JACK_DEFAULT_SERVER=NAME``); on exit it sends SIGTERM to the PID and waits.

``sync=True`` adds ``-S``: JACK's synchronous mode, in which the server waits for its
clients within the cycle and declares one period of playback latency on its output
ports. In the default asynchronous mode jackd2 declares (and buffers) two periods, so
that a late client costs a period of latency instead of an xrun: at 64-frame periods
that is 0.333 ms more between a callback and the DAC (bench/latency measures both).

NAME is the first of ``PREFIX-0`` .. ``PREFIX-3`` no running server has: names are
reused, not random, because JACK keeps a small table of servers in shared memory and
reclaims the entry of a server that died without cleaning up (a killed run) only when
a new server takes the same name. jackd logs to a file, never to a pipe nobody reads
(a full pipe would block it).
"""

from __future__ import annotations

import contextlib
import os
import ctypes
import re
import shutil
import signal
import subprocess
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from tpad_rt.errors import BackendError

#: Seconds to wait for the server to come up, and for a process to exit after SIGTERM.
START_TIMEOUT_S = 10
EXIT_TIMEOUT_S = 10
#: Server names tried per prefix (JACK's own table holds few servers).
MAX_SERVERS = 4


def program(name: str) -> str:
    """The path of JACK program ``name``; BackendError naming the Debian package if missing."""
    path = shutil.which(name)
    if path is None:
        raise BackendError(f"program '{name}' not found (Debian: apt-get install jackd2)")
    return path


def free_server_name(jack_wait: str, prefix: str) -> str:
    """The first of ``{prefix}-0`` .. ``{prefix}-{MAX_SERVERS - 1}`` no running server has."""
    for index in range(MAX_SERVERS):
        name = f"{prefix}-{index}"
        probe = subprocess.run([jack_wait, "-s", name, "-c"], capture_output=True, text=True, timeout=10)
        if "not running" in probe.stdout:
            return name
    raise BackendError(f"{MAX_SERVERS} JACK servers named {prefix}-N already run")


def playback_latency_frames(server_name: str) -> int | None:
    """The playback latency (frames, max of the range) server ``server_name`` declares for its
    ``system:playback_1`` port (``jack_lsp -l``); None when it does not say (or is not running)."""
    listing = subprocess.run([program("jack_lsp"), "-s", server_name, "-l", "system:playback_1"],
                             capture_output=True, text=True, timeout=10).stdout
    match = re.search(r"port playback latency = \[ (\d+) (\d+) \]", listing)
    return int(match.group(2)) if match else None


#: Seconds between two looks at a starting server's ports.
_PORTS_POLL_S = 0.02


def wait_until_serving(server_name: str, process: subprocess.Popen, timeout_s: float = START_TIMEOUT_S) -> bool:
    """Wait until a client of server ``server_name`` (``jack_lsp``) attaches and lists its ``system:playback_1``
    port: the server's engine and driver are up, not only its process (``jack_wait -w``). False when ``process``
    ends first or ``timeout_s`` (a start-up failure bound) passes."""
    deadline = time.monotonic() + timeout_s
    while process.poll() is None and time.monotonic() < deadline:
        listing = subprocess.run([program("jack_lsp"), "-s", server_name, "system:playback_1"], capture_output=True,
                                 text=True, timeout=timeout_s).stdout
        if "system:playback_1" in listing.splitlines():
            return True
        time.sleep(_PORTS_POLL_S)
    return False


def stop_process(process: subprocess.Popen) -> None:
    """SIGTERM ``process`` (by PID) and wait; SIGKILL if it does not exit within EXIT_TIMEOUT_S."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
    try:
        process.wait(EXIT_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


@dataclass(frozen=True)
class RunningServer:
    """A running jackd: its server ``name`` (for ``JACK_DEFAULT_SERVER``) and its ``process``."""

    name: str
    process: subprocess.Popen


#: prctl's option: the signal the calling process gets when the thread that started it ends.
_PR_SET_PDEATHSIG = 1


def die_with_parent() -> None:
    """In a child, before exec (``preexec_fn``): SIGTERM when the test thread that started it ends, so a test
    process that crashes (a segfault skips every teardown) leaves no server running behind it (two jackd left
    behind so took a fifth of the machine's CPU from a later run)."""
    ctypes.CDLL(None).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


@contextlib.contextmanager
def dummy_server(rate_hz: int = 192000, period_frames: int = 64, *, sync: bool = False, prefix: str = "tpadrt",
                 log: Path | None = None) -> Iterator[RunningServer]:
    """Run a dummy JACK server at ``rate_hz`` (Hz) with ``period_frames`` periods, synchronous mode if ``sync``.

    ``log``: where jackd's output goes (default: a temporary file). Raises BackendError
    when jackd or jack_wait is missing or the server does not come up. Stopping a
    server the caller already stopped is fine.
    """
    jackd, jack_wait = program("jackd"), program("jack_wait")
    # Each pytest-xdist worker names its servers apart: two workers never race for one free name.
    name = free_server_name(jack_wait, prefix + os.environ.get("PYTEST_XDIST_WORKER", ""))
    sink = open(log, "w+b") if log is not None else tempfile.TemporaryFile()  # noqa: SIM115
    mode = ["-S"] if sync else []
    process = subprocess.Popen(
        [jackd, "-n", name, *mode, "-p", "16", "-d", "dummy", "-r", str(rate_hz), "-p", str(period_frames)],
        stdout=sink, stderr=subprocess.STDOUT, start_new_session=True, preexec_fn=die_with_parent)
    try:
        waited = subprocess.run([jack_wait, "-s", name, "-w", "-t", str(START_TIMEOUT_S)],
                                capture_output=True, text=True, timeout=START_TIMEOUT_S + 5)
        if waited.returncode != 0 or not wait_until_serving(name, process):
            sink.seek(0)
            raise BackendError(f"jackd {name} did not start: {sink.read().decode(errors='replace')[-2000:]}")
        yield RunningServer(name, process)
    finally:
        stop_process(process)
        sink.close()
