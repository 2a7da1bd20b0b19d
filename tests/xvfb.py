"""An Xvfb X server for tests (docs/testing.md), started and stopped by PID.

Import the fixtures into a test module: ``from xvfb import display, xvfb_server``.
``xvfb_server`` (one per module) starts ``Xvfb :N -screen 0 1280x800x24 -nolisten tcp -noreset``
on a free display number and waits until it accepts connections; ``display`` sets
``DISPLAY`` to it for one test. Without Xvfb the tests skip locally and fail under
``TPAD_RT_REQUIRE_SYSTEM=1`` (see conftest.py).
"""

from __future__ import annotations

import gc
import os
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import require_program
from jackd import die_with_parent

SCREEN_PX = (1280, 800)
#: Display numbers tried (high enough to miss a desktop's own), from one that depends on the
#: process: concurrent test runs rarely race for the same number (Xvfb's lock is not safe
#: against two servers starting on one number at the same instant).
_CANDIDATES = range(90, 490)
#: Connection attempts per server, ``_RETRY_S`` (s) apart: Xvfb is up within a second.
_ATTEMPTS, _RETRY_S = 400, 0.025


def _in_use(number: int) -> bool:
    """True when display ``number`` has a lock file or a socket (another server owns it)."""
    return Path(f"/tmp/.X{number}-lock").exists() or Path(f"/tmp/.X11-unix/X{number}").exists()


def _lock_owner(number: int) -> int | None:
    """The PID written in display ``number``'s lock file (the server that owns it), or None."""
    try:
        return int(Path(f"/tmp/.X{number}-lock").read_text().strip())
    except (OSError, ValueError):
        return None


def _accepts_connections(name: str) -> bool:
    import Xlib.display
    import Xlib.error

    try:
        Xlib.display.Display(name).close()
    except (Xlib.error.DisplayError, Xlib.error.ConnectionClosedError, OSError):
        return False
    return True


def _start(program: str, number: int) -> subprocess.Popen[bytes] | None:
    """Xvfb on ``:number`` once it owns the number and accepts connections; None when another
    server took the number first (a concurrent test run: then ours exits).

    Raises RuntimeError when Xvfb exits for another reason or never accepts a connection.
    """
    width, height = SCREEN_PX
    # -noreset: by default an X server resets when its last client disconnects (between two
    # tests), and a client connecting meanwhile is reset too.
    server = subprocess.Popen([program, f":{number}", "-screen", "0", f"{width}x{height}x24", "-nolisten", "tcp",
                               "-noreset"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, preexec_fn=die_with_parent)
    for _ in range(_ATTEMPTS):
        if server.poll() is not None:
            if _in_use(number):
                return None
            raise RuntimeError(f"Xvfb :{number} exited ({server.returncode}): {server.stderr.read().decode()[-500:]}")
        if _lock_owner(number) == server.pid and _accepts_connections(f":{number}"):
            return server
        time.sleep(_RETRY_S)
    _stop(server)
    raise RuntimeError(f"Xvfb :{number} accepted no connection in {_ATTEMPTS} attempts")


def _stop(server: subprocess.Popen[bytes]) -> None:
    """SIGTERM to the server's PID, then wait for it to exit."""
    server.terminate()
    try:
        server.wait(timeout=10)
    except subprocess.TimeoutExpired:
        server.kill()
        server.wait()
    if server.stderr is not None:
        server.stderr.close()


@pytest.fixture(scope="module")
def xvfb_server() -> Iterator[str]:
    """The display name (``:N``) of an Xvfb server running for the test module."""
    program = require_program("Xvfb")
    first = os.getpid() % len(_CANDIDATES)
    for number in (*_CANDIDATES[first:], *_CANDIDATES[:first]):
        if _in_use(number):
            continue
        server = _start(program, number)
        if server is not None:
            break
    else:
        raise RuntimeError(f"no free X display number in {_CANDIDATES}")
    try:
        yield f":{number}"
    finally:
        gc.collect()  # clients left in reference cycles (pynput Controllers) close while the server runs
        _stop(server)


@pytest.fixture
def display(xvfb_server: str, monkeypatch: pytest.MonkeyPatch) -> str:
    """``DISPLAY`` set to the module's Xvfb server for one test; returns its name."""
    monkeypatch.setenv("DISPLAY", xvfb_server)
    return xvfb_server
