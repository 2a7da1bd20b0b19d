"""A JACK dummy server and CPU hogs for the latency benchmark, started and stopped by PID.

``jack_server(rate_hz, period_frames)`` runs the tests' :func:`jackd.dummy_server` (tests/jackd.py) under
the names ``tpadrt-bench-0..3``, in JACK's synchronous mode (``-S``) unless
``sync=False``, and yields an environment for child processes
(``JACK_DEFAULT_SERVER=NAME``). This process never loads PortAudio: every measured
configuration runs in a fresh child process, which initialises PortAudio while the
server runs. ``cpu_hogs(n)`` runs ``n`` processes spinning a pure-Python loop, stopped
the same way (SIGTERM to the PID, then wait).
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from tpad_rt.errors import BackendError

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))  # tests/jackd.py: test and bench infrastructure
from jackd import dummy_server, playback_latency_frames, stop_process  # noqa: E402

__all__ = ["cpu_hogs", "jack_server", "playback_latency_frames", "wait_for_no_clients"]


@contextlib.contextmanager
def jack_server(rate_hz: int, period_frames: int, log: Path | None = None, *,
                sync: bool = True) -> Iterator[dict[str, str]]:
    """Run a dummy JACK server (synchronous mode unless ``sync`` is False); yields the environment its
    clients need. ``log``: jackd's output."""
    try:
        with dummy_server(rate_hz, period_frames, sync=sync, prefix="tpadrt-bench", log=log) as server:
            yield {**os.environ, "JACK_DEFAULT_SERVER": server.name}
    except BackendError as err:
        raise SystemExit(f"bench/latency: {err}") from None


def wait_for_no_clients(env: dict[str, str], timeout_s: float = 30.0) -> bool:
    """Poll ``jack_lsp`` until the server has no PortAudio client left (a worker that exited without closing
    its stream stays a client until the server notices), so that each run starts with no client of an
    earlier one; False if one is still there after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        ports = subprocess.run(["jack_lsp", "-s", env["JACK_DEFAULT_SERVER"]], capture_output=True, text=True,
                               env=env).stdout
        if "PortAudio" not in ports:
            return True
        time.sleep(0.05)
    return False


@contextlib.contextmanager
def cpu_hogs(count: int) -> Iterator[list[int]]:
    """``count`` processes each spinning ``while True: pass``; yields their PIDs."""
    processes = [subprocess.Popen([sys.executable, "-c", "while True: pass"], start_new_session=True)
                 for _ in range(count)]
    try:
        yield [process.pid for process in processes]
    finally:
        for process in processes:
            stop_process(process)
