"""A stalled audio stream.

The watchdog's behaviour in time (reported exactly at the stall limit and never before, the full gap
measured however late the watcher runs, no stall while callbacks go on) is tested on a VirtualClock
(:class:`tpad_rt.drivers.stall_watch.StallWatch`, the audio driver's watchdog). On the real component: a
JACK server stopped by SIGSTOP under ``tpad-rt play`` and under an app using the Renderer (each on a dummy
server of its own, in a subprocess: the test process's PortAudio never sees a server stop) is reported as a
stall, and the stop that meets a server stopping under it returns; two realtime smoke tests
(docs/testing.md) time a short stall and keep a healthy stream under GIL load from counting as stalled.
"""

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

from tpad_rt.clock import MonotonicClock, VirtualClock
from tpad_rt.drivers.audio_callback import STALL_MIN_BLOCKS, AudioCallbackDriver
from tpad_rt.drivers.stall_watch import StallWatch
from tpad_rt.engine import WATCH_PERIOD_S, Renderer
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


#: The default stall limit (s, ns): Renderer's stall_timeout_s, play's --stall-timeout.
STALL_LIMIT_S, STALL_LIMIT_NS = 0.5, 500_000_000
MS = 1_000_000


class Callbacks:
    """A stream's callback count on a VirtualClock: one callback every ``period_ns`` from 0 to ``until_ns``
    (the clock's events)."""

    def __init__(self, clock: VirtualClock, period_ns: int, until_ns: int):
        self.count = 0
        for t_ns in range(0, until_ns + 1, period_ns):
            clock.at(t_ns, self._call)

    def _call(self) -> None:
        self.count += 1

    def read(self) -> int:
        return self.count


def watch_every(watch: StallWatch, clock: VirtualClock, callbacks: Callbacks, period_ns: int,
                end_ns: int) -> tuple[int, int] | None:
    """Poll ``watch`` every ``period_ns`` up to ``end_ns``, as the Renderer's watcher does: (the clock's time,
    the stillness) of the first stall reported, None if none was."""
    t_ns = clock.now_ns()
    while t_ns <= end_ns:
        clock.sleep_until_ns(t_ns)
        still_ns = watch.still_for_ns(callbacks.read)
        if still_ns is not None:
            return clock.now_ns(), still_ns
        t_ns += period_ns
    return None


def test_a_stream_calling_back_is_never_a_stall() -> None:
    clock = VirtualClock()
    callbacks = Callbacks(clock, period_ns=333_333, until_ns=60_000 * MS)
    watch = StallWatch(STALL_LIMIT_NS, clock)
    assert watch_every(watch, clock, callbacks, 10 * MS, 60_000 * MS) is None


def test_a_stall_is_reported_at_the_limit_never_before_with_the_time_without_a_callback() -> None:
    clock = VirtualClock()
    callbacks = Callbacks(clock, period_ns=1 * MS, until_ns=2_000 * MS)  # the last callback at 2 s
    watch = StallWatch(STALL_LIMIT_NS, clock)
    assert watch_every(watch, clock, callbacks, 10 * MS, 10_000 * MS) == (2_500 * MS, STALL_LIMIT_NS)
    assert watch.still_for_ns(callbacks.read) == STALL_LIMIT_NS  # and again while it lasts
    clock.advance_to(7_000 * MS)  # a watcher that comes late measures the whole gap since it saw the count move
    assert watch.still_for_ns(callbacks.read) == 5_000 * MS


def test_a_watcher_held_up_while_callbacks_go_on_sees_no_stall() -> None:
    """The watcher held (by the GIL) for twice the limit between two polls, and between its clock read and its
    count read, while the native callback went on: no stall, and the stillness is counted from the later read."""
    clock = VirtualClock()
    callbacks = Callbacks(clock, period_ns=1 * MS, until_ns=1_500 * MS)  # the last callback at 1.5 s
    watch = StallWatch(STALL_LIMIT_NS, clock)
    assert watch.still_for_ns(callbacks.read) is None
    clock.advance_to(2 * STALL_LIMIT_NS)  # held between two polls: 0 -> 1.0 s
    assert watch.still_for_ns(callbacks.read) is None

    def held_then_read() -> int:
        clock.advance_by(2 * STALL_LIMIT_NS)  # held after its clock read (at 1.0 s) until 2.0 s
        return callbacks.read()

    assert watch.still_for_ns(held_then_read) is None  # the count moved (callbacks to 1.5 s), seen at 2.0 s
    clock.advance_to(2_000 * MS + STALL_LIMIT_NS - 1)
    assert watch.still_for_ns(callbacks.read) is None
    clock.advance_by(1)
    assert watch.still_for_ns(callbacks.read) == STALL_LIMIT_NS


@pytest.mark.parametrize("limit_ns", [0, -1, 0.5, True])
def test_a_stall_watch_refuses_a_limit_that_is_not_a_positive_whole_ns(limit_ns: object) -> None:
    with pytest.raises(ValueError, match="positive whole number of ns"):
        StallWatch(limit_ns, VirtualClock())  # type: ignore[arg-type]


def test_the_audio_driver_watches_on_the_host_clock_for_at_least_four_blocks() -> None:
    renderer = Renderer(output="audio://?rate=192000&block=4096", stall_timeout_s=0.01)
    assert isinstance(renderer.driver, AudioCallbackDriver) and isinstance(renderer.driver.clock, MonotonicClock)
    assert renderer.driver.stall_limit_s() == STALL_MIN_BLOCKS * 4096 / 192000
    assert Renderer(output="audio://", stall_timeout_s=2.5).driver.stall_limit_s() == 2.5


def assert_no_callback_since_the_limit(message: str) -> None:
    """A stall ``message`` gives the time without a callback, at least the limit (how much more depends on
    when the watcher ran: the watchdog's timing is tested on the VirtualClock above)."""
    match = re.search(r"no callback for (\d+\.\d+) s", message)
    assert match, message
    assert float(match[1]) >= STALL_LIMIT_S, message


def stray_stderr(err: str) -> list[str]:
    """Lines on stderr other than the kernels' compile notice (a first run in a fresh numba cache)."""
    return [line for line in err.splitlines() if not line.startswith("tpad-rt: compil")]


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
    lines = stray_stderr(err)
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("tpad-rt play: audio: the stream on device 0 'system' (JACK Audio Connection Kit) "
                               "stalled: no callback for ")
    assert_no_callback_since_the_limit(lines[0])
    assert "(device hung or server stopped)" in lines[0]


@pytest.mark.system
@pytest.mark.realtime
def test_play_through_a_short_stall_says_how_long_the_output_stalled() -> None:
    """Issue 10: a run whose output stopped for a while used to report its wall time as 'played'; the
    summary now gives the drive played and the run's time, and says the output stalled, as the panel does.
    Realtime: the stall it reports is held against the second the server was stopped for."""
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
    renderer.join()  # until the watcher reports the stall (the test's SAFETY_TIMEOUT_S bounds it)
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
    assert_no_callback_since_the_limit(lines[0])
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


#: The holder's break between two holds (s): five of the Renderer's watcher periods, in which the watcher drains
#: the telemetry a hold left (a 10 ms break, half a period, was missed three times in a row on a loaded machine:
#: 9191 rows undrained overflowed the 8192-row ring).
HOLD_BREAK_S = 5 * WATCH_PERIOD_S


class GilHolder:
    """A thread that holds the GIL for ``hold_s`` at a time (libc's usleep called through ctypes.PyDLL, which
    keeps the GIL), with HOLD_BREAK_S breaks, until the block ends; ``.holds`` counts the holds completed."""

    def __init__(self, hold_s: float):
        self.hold_us = round(hold_s * 1e6)
        self.holds = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._hold, daemon=True)

    def _hold(self) -> None:
        usleep = ctypes.PyDLL(None).usleep
        while not self._stop.wait(HOLD_BREAK_S):
            usleep(self.hold_us)
            self.holds += 1

    def __enter__(self) -> GilHolder:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


@pytest.mark.system
@pytest.mark.realtime
def test_a_healthy_stream_under_gil_load_is_not_a_stall() -> None:
    """The real component's side of test_a_watcher_held_up_while_callbacks_go_on_sees_no_stall: PortAudio goes on
    calling the native callback while a Python thread holds the GIL. Realtime: a host that holds the JACK server
    itself up for the stall limit makes a stall."""
    with jack_server():
        with Renderer(output="audio://", texture=GRATING) as renderer:
            before = renderer.stats()["callbacks"]
            with GilHolder(2 * renderer.stall_timeout_s) as holder:
                while holder.holds < 3:  # the watcher waits for the GIL twice its stall timeout, 3 times
                    renderer.join(timeout_s=0.05)  # raises if the watcher reported a stall
            renderer.check()
            during = renderer.stats()["callbacks"] - before
    assert during > 0
