"""A stalled audio stream: a JACK server stopped by SIGSTOP under ``tpad-rt play`` and under an app using the
Renderer (each on a dummy server of its own, in a subprocess: the test process's PortAudio never sees a
server stop), the stop that meets a server stopping under it, and a healthy stream under GIL load that
must not count as stalled."""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from jack_server import jack_server, server_process, wait_until_playing

from tpad_rt.engine import Renderer
from tpad_rt.limits import MAX_STALL_TIMEOUT_S
from tpad_rt.errors import ConfigError
from jackd import RunningServer, stop_process

REPO = Path(__file__).resolve().parents[1]
GRATING = REPO / "textures" / "grating.yaml"
#: Seconds any subprocess of these tests may take (a safety net, not an expectation).
SAFETY_TIMEOUT_S = 30
#: The environment of a client: no display, the JACK server ``name``.
NO_DISPLAY = {k: v for k, v in os.environ.items() if k != "DISPLAY"}


@contextlib.contextmanager
def client_of(server: RunningServer, command: list[str]) -> Iterator[subprocess.Popen[str]]:
    """Run ``command`` (text pipes on stdin, stdout, stderr) as a client of ``server``; on exit resume the
    server (SIGCONT) and kill the client if it still runs, both by PID."""
    client = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, cwd=REPO, env={**NO_DISPLAY, "JACK_DEFAULT_SERVER": server.name})
    try:
        yield client
    finally:
        os.kill(server.process.pid, signal.SIGCONT)
        stop_process(client)


@pytest.mark.parametrize("value", [0, -1.0, math.nan, math.inf, MAX_STALL_TIMEOUT_S + 1, True, "1"])
def test_a_bad_stall_timeout_is_refused(value: object) -> None:
    with pytest.raises(ConfigError, match=r"stall_timeout_s: must be a number of seconds in \(0, 60\]"):
        Renderer(output="null://", stall_timeout_s=value)  # type: ignore[arg-type]


#: The default stall limit (s): Renderer's stall_timeout_s, play's --stall-timeout.
STALL_LIMIT_S = 0.5


def stalled_for_s(message: str) -> float:
    """The seconds without a callback that a stall ``message`` gives (it is said once the watcher, which a
    loaded machine can hold up, sees the stall limit passed)."""
    match = re.search(r"no callback for (\d+\.\d+) s", message)
    assert match, message
    return float(match[1])


@pytest.mark.system
def test_play_on_a_stopped_server_reports_the_stall_in_one_line_and_status_1() -> None:
    with server_process() as server, client_of(server, [
            sys.executable, "-m", "tpad_rt", "play", "textures/grating.yaml", "--output", "audio://system",
            "--input", "scripted://swipe?speed_mm_s=100&repeat=0&back_and_forth=1", "--duration", "30"]) as play:
        assert play.stdout is not None
        assert play.stdout.readline().startswith("output audio://system, input ")
        assert wait_until_playing(server.name, SAFETY_TIMEOUT_S)
        os.kill(server.process.pid, signal.SIGSTOP)
        out, err = play.communicate(timeout=SAFETY_TIMEOUT_S)
    assert play.returncode == 1, (out, err)
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("tpad-rt play: audio: the stream on device 0 'system' (JACK Audio Connection Kit) "
                          "stalled: no callback for ")
    assert STALL_LIMIT_S <= stalled_for_s(err) < 10 * STALL_LIMIT_S, err
    assert "(device hung or server stopped)" in err


@pytest.mark.system
def test_play_through_a_short_stall_says_how_long_the_output_stalled() -> None:
    """Issue 10: a run whose output stopped for a while used to report its wall time as 'played'; the
    summary now gives the drive played and the run's time, and says the output stalled, as the panel does."""
    with server_process() as server, client_of(server, [
            sys.executable, "-m", "tpad_rt", "play", "textures/grating.yaml", "--output", "audio://system",
            "--input", "scripted://swipe?speed_mm_s=100&repeat=0&back_and_forth=1", "--duration", "3",
            "--stall-timeout", "10"]) as play:
        assert play.stdout is not None
        assert play.stdout.readline().startswith("output audio://system, input ")
        assert wait_until_playing(server.name, SAFETY_TIMEOUT_S)
        os.kill(server.process.pid, signal.SIGSTOP)
        time.sleep(1.0)  # the stimulus: the server held stopped for a second
        os.kill(server.process.pid, signal.SIGCONT)
        out, err = play.communicate(timeout=SAFETY_TIMEOUT_S)
    assert play.returncode == 0, (out, err)
    summary = out.splitlines()[0]
    played_s, ran_s = float(summary.split()[1]), float(summary.split(" in ")[1].split()[0])
    assert summary.startswith("played ") and "; the output stalled for " in summary
    stalled_s = float(summary.split("the output stalled for ")[1].split()[0])
    assert stalled_s == pytest.approx(ran_s - played_s, abs=0.02)  # three figures, each rounded to 0.01 s
    assert stalled_s >= 0.8  # the second the server was stopped (less what the buffers held)


#: A Renderer on audio:// whose server the test stops (SIGSTOP) after "playing": join re-raises the stall,
#: stop returns, audio is refused after, and the interpreter exits.
STALLED_SERVER_APP = f"""
import sys
from tpad_rt.engine import Renderer
from tpad_rt.errors import BackendError
renderer = Renderer(output="audio://", texture={str(GRATING)!r})
renderer.start()
print("playing", flush=True)
sys.stdin.readline()  # the server is stopped
try:
    renderer.join(timeout_s=5)
    print("join: no error", flush=True)
except BackendError as error:
    print("join:", error, flush=True)
renderer.stop()
print("stopped", renderer.running, flush=True)
try:
    Renderer(output="audio://").start()
except BackendError as error:
    print("again:", error, flush=True)
"""


@pytest.mark.system
def test_a_renderer_on_a_stopped_server_reports_the_stall_and_stops_and_exits() -> None:
    with server_process() as server, client_of(server, [sys.executable, "-c", STALLED_SERVER_APP]) as app:
        assert app.stdout is not None and app.stdin is not None
        assert app.stdout.readline() == "playing\n"
        os.kill(server.process.pid, signal.SIGSTOP)
        out, err = app.communicate("stopped\n", timeout=SAFETY_TIMEOUT_S)
    assert app.returncode == 0, err  # stop() did not hang, nor did the interpreter's exit
    lines = out.splitlines()
    assert lines[0].startswith("join: audio: the stream on device 0 'system' (JACK Audio Connection Kit) stalled: "
                               "no callback for "), lines
    assert STALL_LIMIT_S <= stalled_for_s(lines[0]) < 10 * STALL_LIMIT_S, lines
    assert lines[1] == "stopped False"
    assert lines[2].startswith("again: audio: an output stream was lost earlier in this process")


#: A Renderer whose server stops (SIGSTOP, sent by the app itself) just as its stream is being stopped, after
#: the drive ramped down: Pa_StopStream waits for the stopped server, yet stop() reports the stall and returns.
STOPPING_INTO_A_STALL_APP = f"""
import os, signal, sys
from tpad_rt.engine import Renderer
from tpad_rt.errors import BackendError
renderer = Renderer(output="audio://", texture={str(GRATING)!r})
renderer.start()
stream = renderer.driver.stream
stop_stream = stream.stop

def stop_on_a_stopped_server():
    os.kill(int(sys.argv[1]), signal.SIGSTOP)
    stop_stream()

stream.stop = stop_on_a_stopped_server
try:
    renderer.stop()
    print("stop: no error", flush=True)
except BackendError as error:
    print("stop:", error, flush=True)
print("stopped", renderer.running, flush=True)
"""


@pytest.mark.system
def test_a_server_stopping_while_the_stream_stops_is_a_stall_and_stop_returns() -> None:
    with server_process() as server, client_of(server, [sys.executable, "-c", STOPPING_INTO_A_STALL_APP,
                                                        str(server.process.pid)]) as app:
        out, err = app.communicate(timeout=SAFETY_TIMEOUT_S)
    assert app.returncode == 0, err
    lines = out.splitlines()
    assert lines[0].startswith("stop: audio: the stream on device 0 'system' (JACK Audio Connection Kit) stalled: "
                               "stopping it took over 1.50 s"), lines
    assert lines[1] == "stopped False"


class GilHolder:
    """A thread that holds the GIL for ``hold_s`` at a time (libc's usleep called through ctypes.PyDLL, which
    keeps the GIL), with short breaks, until the block ends; ``.holds`` counts the holds completed."""

    def __init__(self, hold_s: float):
        self.hold_us = round(hold_s * 1e6)
        self.holds = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._hold, daemon=True)

    def _hold(self) -> None:
        usleep = ctypes.PyDLL(None).usleep
        while not self._stop.wait(0.01):
            usleep(self.hold_us)
            self.holds += 1

    def __enter__(self) -> GilHolder:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


@pytest.mark.system
def test_a_healthy_stream_under_gil_load_is_not_a_stall() -> None:
    with jack_server():
        with Renderer(output="audio://", texture=GRATING) as renderer:
            before = renderer.stats()["callbacks"]
            with GilHolder(2 * renderer.stall_timeout_s) as holder:
                while holder.holds < 3:  # the watcher waits for the GIL twice its stall timeout, 3 times
                    renderer.join(timeout_s=0.05)  # raises if the watcher reported a stall
            renderer.check()
            during = renderer.stats()["callbacks"] - before
    assert during > 0
