"""LiveFeed: replays inputs at their times on the feed's clock (exactly, with a fake clock; in order
and complete, with the real one), forwards the mouse, lifts, re-raises errors in join(), and leaves
no thread behind."""

from __future__ import annotations

import queue
import threading
import time
from pathlib import Path

import pytest
from xvfb import display, xvfb_server  # noqa: F401 - fixtures

from tpad_rt.inputs import open_input
from tpad_rt.inputs.base import Input
from tpad_rt.inputs.live import LiveFeed

#: Bound (s) on waiting for something that must happen; a failure bound, not a timing assertion.
TIMEOUT_S = 10.0


class FakeClock:
    """A clock (s) that only moves when the feed pauses: replay without sleeping, times exact."""

    def __init__(self, start_s: float = 1000.0):
        self.now_s = start_s

    def __call__(self) -> float:
        return self.now_s

    def pause(self, seconds: float) -> bool:
        self.now_s += seconds
        return False


class Recorder:
    """A renderer stand-in: records ``("push", x_mm, y_mm, force_n, t, clock at the call)`` and
    ``("lift", clock at the call)``."""

    def __init__(self, clock=time.monotonic) -> None:
        self.clock = clock
        self.calls: list[tuple] = []

    def push_finger(self, x_mm: float, y_mm: float, force_n: float | None = None, t: float | None = None) -> None:
        self.calls.append(("push", x_mm, y_mm, force_n, t, self.clock()))

    def lift(self) -> None:
        self.calls.append(("lift", self.clock()))

    @property
    def pushes(self) -> list[tuple]:
        return [call for call in self.calls if call[0] == "push"]


def _feed(url: str, recorder: Recorder, clock: FakeClock | None = None, **options) -> LiveFeed:
    if clock is None:
        return LiveFeed(open_input(url), recorder.push_finger, recorder.lift, **options)
    return LiveFeed(open_input(url), recorder.push_finger, recorder.lift, clock=clock, pause=clock.pause, **options)


def test_replay_pushes_each_sample_exactly_when_due_on_the_feed_clock() -> None:
    clock = FakeClock()
    recorder = Recorder(clock)
    url = "scripted://swipe?speed_mm_s=1000&from_mm=0&to_mm=100&rate_hz=100&y_mm=20&force_n=0.75"
    with _feed(url, recorder, clock) as feed:
        feed.join()
    assert feed.done and feed.start_s == 1000.0
    pushes = recorder.pushes
    assert [(x, y, force) for _, x, y, force, _, _ in pushes] == [(10.0 * k, 20.0, 0.75) for k in range(10)]
    assert [t for *_, t, _ in pushes] == [1000.0 + k / 100 for k in range(10)]
    assert all(0 <= called - t < 1e-9 for *_, t, called in pushes)  # when due, never before
    assert recorder.calls[-1] == ("lift", pytest.approx(1000.1))  # the swipe's last sample is lifted
    assert len(recorder.calls) == 11


def test_replay_reads_the_input_in_chunks_without_repeating_or_skipping() -> None:
    clock = FakeClock()
    one_chunk, small_chunks = Recorder(clock), Recorder(clock)
    url = "scripted://circle?turns=2&rate_hz=1000"
    with _feed(url, one_chunk, clock, chunk_s=100.0) as feed:
        feed.join()
    clock.now_s = 1000.0
    with _feed(url, small_chunks, clock, chunk_s=0.0123) as feed:
        feed.join()
    assert small_chunks.calls == one_chunk.calls and len(one_chunk.calls) > 2000


def test_file_replay_lifts_on_lifted_rows_and_at_the_end_and_passes_unknown_force(tmp_path: Path) -> None:
    path = tmp_path / "stroke.csv"
    path.write_text("t,x_mm,y_mm,down\n0.5,1,2,1\n0.75,3,4,0\n1.0,5,6,1\n1.25,7,8,1\n", encoding="utf-8")
    clock = FakeClock(0.0)
    recorder = Recorder(clock)
    with _feed(f"file://{path}", recorder, clock) as feed:
        feed.join()
    assert recorder.calls == [
        ("push", 1.0, 2.0, None, 0.5, 0.5),
        ("lift", 0.75),
        ("push", 5.0, 6.0, None, 1.0, 1.0),
        ("push", 7.0, 8.0, None, 1.25, 1.25),
        ("lift", 1.25),  # the input ended touching: the feed lifts the finger
    ]
    assert feed.done


def test_real_time_replay_is_in_order_complete_and_never_early() -> None:
    recorder = Recorder()
    url = "scripted://swipe?speed_mm_s=1000&from_mm=0&to_mm=100&rate_hz=200"
    with _feed(url, recorder) as feed:
        feed.join(TIMEOUT_S)
    assert feed.done and not feed.is_alive()
    pushes = recorder.pushes
    assert [x for _, x, *_ in pushes] == [5.0 * k for k in range(20)]
    stamps = [t for *_, t, _ in pushes]
    assert stamps == [feed.start_s + k / 200 for k in range(20)]
    assert all(called >= t for *_, t, called in pushes)
    assert [call[0] for call in recorder.calls[-2:]] == ["push", "lift"]


def test_stop_is_idempotent_ends_an_endless_input_and_lifts_a_touching_finger() -> None:
    recorder = Recorder()
    feed = _feed("scripted://still?duration_s=inf&rate_hz=1000", recorder)
    with feed:
        deadline = time.monotonic() + TIMEOUT_S
        while not recorder.pushes and time.monotonic() < deadline:
            time.sleep(0.001)
        feed.stop()
        feed.stop()
    feed.stop()
    assert not feed.is_alive() and not feed.done
    assert recorder.pushes and recorder.calls[-1][0] == "lift"


class Exploding(Input):
    """An input whose samples cannot be read."""

    duration_s = 1.0

    def samples_between(self, t0_s: float, t1_s: float):
        raise OSError("trajectory vanished")


def test_errors_in_the_feeder_are_reraised_in_join_and_on_exit() -> None:
    def push_finger(x_mm: float, y_mm: float, force_n: float | None = None, t: float | None = None) -> None:
        raise ZeroDivisionError("renderer failed")

    feed = LiveFeed(open_input("scripted://tap"), push_finger, lambda: None)
    feed.start()
    with pytest.raises(ZeroDivisionError, match="renderer failed"):
        feed.join(TIMEOUT_S)
    feed.join()  # re-raised once
    with pytest.raises(OSError, match="trajectory vanished"):
        with LiveFeed(Exploding(), push_finger, lambda: None):
            pass


def test_many_feeds_started_and_stopped_leave_no_thread_behind() -> None:
    before = threading.active_count()
    for _ in range(50):
        with LiveFeed(open_input("scripted://circle?turns=0"), Recorder().push_finger, lambda: None):
            pass
    assert threading.active_count() == before


def test_the_feed_forwards_mouse_events_with_their_stamps(display: str) -> None:  # noqa: F811
    from pynput.mouse import Controller

    pointer = Controller()
    pointer.position = (0, 0)
    pushed: queue.Queue[tuple] = queue.Queue()
    lifts: queue.Queue[float] = queue.Queue()
    source = open_input("mouse://?rect=100,50,640,320&plate_mm=160,80&hover=1")
    before = threading.active_count()
    with LiveFeed(source, lambda x_mm, y_mm, force_n=None, t=None: pushed.put((x_mm, y_mm, force_n, t)),
                  lambda: lifts.put(time.monotonic())) as feed:
        start_s = time.monotonic()
        pointer.position = (420, 210)
        pointer.position = (424, 214)
        first, second = pushed.get(timeout=TIMEOUT_S), pushed.get(timeout=TIMEOUT_S)
        pointer.position = (50, 50)
        lifted_s = lifts.get(timeout=TIMEOUT_S)
    assert first[:3] == (80.0, 40.0, 0.5) and second[:3] == (81.0, 41.0, 0.5)
    assert start_s <= first[3] <= second[3] <= lifted_s  # stamped time.monotonic() at the event
    assert not feed.is_alive() and pushed.empty() and lifts.empty()
    for _ in range(10):  # the listener threads end with their feeds
        with LiveFeed(source, lambda *sample, **keys: None, lambda: None):
            pass
    assert threading.active_count() == before



def test_feeds_a_renderer_on_its_stream_clock() -> None:
    from tpad_rt.engine import Renderer

    renderer = Renderer(output="null://")
    with renderer:
        source = open_input("scripted://swipe?speed_mm_s=1000&from_mm=10&to_mm=120&rate_hz=200")
        with LiveFeed(source, renderer.push_finger, renderer.lift, clock=renderer.now_s) as feed:
            feed.join(120.0)  # a failure bound: the first block may wait for the kernels to compile
        assert feed.done and not feed.is_alive()
        finger_x_mm = renderer.telemetry()["x_mm"]
    assert finger_x_mm.min() <= 15.0 and finger_x_mm.max() >= 110.0  # the renderer saw the whole swipe
