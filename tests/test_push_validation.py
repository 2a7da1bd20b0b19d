"""Finger samples are validated where they enter (Pipeline and Renderer), and several producer
threads may push at once: README "Safety", docs/realtime.md "Safety"."""

from __future__ import annotations

import math
import threading
from pathlib import Path

import numpy as np
import pytest

from tpad_rt.device import Device
from tpad_rt.engine import Renderer
from tpad_rt.errors import SampleError, TpadError
from tpad_rt.kernel import layout
from tpad_rt.limits import FINGER_TIME_WINDOW_S, MAX_FORCE_N
from tpad_rt.pipeline import Pipeline
from tpad_rt.texture import load_compiled

GRATING = Path(__file__).resolve().parents[1] / "textures" / "grating.yaml"
PLATE_X = "in [-130, 260] mm (one plate length beyond each edge of the 130 x 60 mm plate)"
PLATE_Y = "in [-60, 120] mm (one plate width beyond each edge of the 130 x 60 mm plate)"

#: (arguments of Pipeline.push_finger after t_s as keywords, the message's start)
BAD_SAMPLES = [
    ({"x_mm": math.nan}, f"x_mm: must be a finite number {PLATE_X}, got nan"),
    ({"x_mm": math.inf}, f"x_mm: must be a finite number {PLATE_X}, got inf"),
    ({"x_mm": -math.inf}, f"x_mm: must be a finite number {PLATE_X}, got -inf"),
    ({"x_mm": 1e308}, f"x_mm: must be a finite number {PLATE_X}, got 1e+308"),
    ({"x_mm": 260.5}, f"x_mm: must be a finite number {PLATE_X}, got 260.5"),
    ({"x_mm": -131.0}, f"x_mm: must be a finite number {PLATE_X}, got -131.0"),
    ({"x_mm": "12"}, f"x_mm: must be a finite number {PLATE_X}, got '12'"),
    ({"x_mm": None}, f"x_mm: must be a finite number {PLATE_X}, got None"),
    ({"x_mm": True}, f"x_mm: must be a finite number {PLATE_X}, got True"),
    ({"x_mm": 10**400}, f"x_mm: must be a finite number {PLATE_X}, got 1000000000000000000000000000000000000..."),
    ({"x_mm": "x" * 10**6}, f"x_mm: must be a finite number {PLATE_X}, got 'xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx..."),
    ({"y_mm": math.nan}, f"y_mm: must be a finite number {PLATE_Y}, got nan"),
    ({"y_mm": -1e308}, f"y_mm: must be a finite number {PLATE_Y}, got -1e+308"),
    ({"y_mm": 121.0}, f"y_mm: must be a finite number {PLATE_Y}, got 121.0"),
    ({"force_n": -1.0}, f"force_n: must be a finite number in [0, {MAX_FORCE_N:g}] N"),
    ({"force_n": -5e-324}, f"force_n: must be a finite number in [0, {MAX_FORCE_N:g}] N"),
    ({"force_n": math.nan}, f"force_n: must be a finite number in [0, {MAX_FORCE_N:g}] N"),
    ({"force_n": math.inf}, f"force_n: must be a finite number in [0, {MAX_FORCE_N:g}] N"),
    ({"force_n": 1e308}, f"force_n: must be a finite number in [0, {MAX_FORCE_N:g}] N"),
    ({"force_n": MAX_FORCE_N * 1.01}, f"force_n: must be a finite number in [0, {MAX_FORCE_N:g}] N"),
]
#: Values accepted at the ends of the ranges.
GOOD_SAMPLES = [
    {"x_mm": -130.0}, {"x_mm": 260.0}, {"y_mm": -60.0}, {"y_mm": 120.0}, {"x_mm": -0.0}, {"x_mm": 5e-324},
    {"force_n": 0.0}, {"force_n": -0.0}, {"force_n": MAX_FORCE_N}, {"force_n": None}, {"x_mm": np.float32(3.5)},
    {"x_mm": np.int64(7)},
]
BAD_TIMES = [math.nan, math.inf, -math.inf, 1e9, -1e9, FINGER_TIME_WINDOW_S + 0.5, 10**400, "0", None, 1e308]


def pipeline() -> Pipeline:
    return Pipeline(Device.default(), load_compiled(GRATING))


def sample(**given: object) -> dict[str, object]:
    return {"x_mm": 50.0, "y_mm": 30.0, "force_n": 0.5, **given}


@pytest.mark.parametrize(("given", "message"), BAD_SAMPLES)
def test_pipeline_refuses_a_bad_sample_naming_the_argument_and_range(given: dict, message: str) -> None:
    p = pipeline()
    with pytest.raises(SampleError) as caught:
        p.push_finger(0.0, **sample(**given))
    assert str(caught.value).startswith(message)
    assert isinstance(caught.value, ValueError) and isinstance(caught.value, TpadError)
    assert p.arrays.finger_count[0] == 0  # nothing was pushed


@pytest.mark.parametrize("given", GOOD_SAMPLES)
def test_pipeline_accepts_the_ends_of_the_ranges(given: dict) -> None:
    p = pipeline()
    p.push_finger(0.0, **sample(**given))
    assert p.arrays.finger_count[0] == 1
    assert np.all(np.isfinite(p.arrays.finger[0, :layout.FINGER_FORCE_N]))


@pytest.mark.parametrize("t_s", BAD_TIMES)
def test_pipeline_refuses_a_time_far_from_the_stream_clock(t_s: object) -> None:
    p = pipeline()
    with pytest.raises(SampleError, match=r"^t_s: must be a finite number in \[-10, 10\] s \(within 10 s of the "
                                          r"stream clock, now 0.000 s\), got "):
        p.push_finger(t_s, 50.0, 30.0)  # type: ignore[arg-type]
    with pytest.raises(SampleError, match=r"^t_s: "):
        p.lift(t_s)  # type: ignore[arg-type]


def test_the_time_window_follows_the_stream_clock_and_times_never_decrease() -> None:
    p = pipeline()
    out = np.zeros(48000, dtype=np.float32)
    for _ in range(48):  # 12 s of stream
        p.render(out)
    assert p.stream_time_s == pytest.approx(12.0)
    with pytest.raises(SampleError, match="within 10 s of the stream clock, now 12.000 s"):
        p.push_finger(1.9, 50.0, 30.0)
    p.push_finger(2.5, 50.0, 30.0)
    p.push_finger(21.5, 50.0, 30.0)
    with pytest.raises(SampleError, match="must be >= the previous sample's time 21.5"):
        p.push_finger(21.0, 50.0, 30.0)


@pytest.mark.parametrize(("given", "message"), BAD_SAMPLES[:12] + BAD_SAMPLES[12::2])
def test_renderer_refuses_a_bad_sample_and_keeps_running(given: dict, message: str) -> None:
    with Renderer(output="null://", texture=GRATING) as renderer:
        args = sample(**given)
        with pytest.raises(SampleError) as caught:
            renderer.push_finger(args["x_mm"], args["y_mm"], args["force_n"])  # type: ignore[arg-type]
        assert str(caught.value).startswith(message)
        renderer.push_finger(50.0, 30.0, 0.5)
        renderer.check()  # the refusal ended nothing
    assert renderer.stats()["faults"] == 0


@pytest.mark.parametrize("t", BAD_TIMES[:-2] + [1e308])
def test_renderer_refuses_a_bad_time_for_push_and_lift(t: float) -> None:
    renderer = Renderer(output="null://", texture=GRATING)
    with pytest.raises(SampleError, match=r"^t: must be a finite number in \[-10, 10\] s"):
        renderer.push_finger(50.0, 30.0, t=t)
    with pytest.raises(SampleError, match=r"^t: "):
        renderer.lift(t=t)
    assert renderer.recent_fingers().size == 0


def test_a_refused_time_does_not_hold_later_samples_back() -> None:
    """Renderer raises earlier times to the previous one: a refused far-future time must not become it."""
    renderer = Renderer(output="null://", texture=GRATING)
    with pytest.raises(SampleError):
        renderer.push_finger(50.0, 30.0, t=1e9)
    renderer.push_finger(50.0, 30.0, t=0.5)
    renderer.push_finger(51.0, 30.0, t=0.25)  # earlier: raised to 0.5
    assert renderer.recent_fingers()["t_s"].tolist()[-2:] == [0.5, 0.5]


PRODUCERS = 4
PUSHES = 3000


def test_several_producer_threads_lose_and_tear_no_sample() -> None:
    """Each sample's x encodes its thread and sequence number: the ring must hold exactly the samples
    pushed, each whole, each thread's in order, and the count must be exact."""
    renderer = Renderer(output="null://", texture=GRATING)
    start = threading.Barrier(PRODUCERS)

    def produce(thread: int) -> None:
        start.wait()
        for k in range(PUSHES):
            renderer.push_finger(10.0 * thread + k * 1e-3, 10.0 + thread, 0.1 * (thread + 1), t=1e-6 * k)

    threads = [threading.Thread(target=produce, args=(thread,)) for thread in range(PRODUCERS)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    arrays = renderer._pipeline.arrays  # the ring itself
    assert arrays.finger_count[0] == PRODUCERS * PUSHES
    fingers = renderer.recent_fingers()
    assert len(fingers) == renderer.options.finger_ring - 2
    thread = np.round(fingers["y_mm"] - 10.0).astype(int)
    assert np.array_equal(fingers["y_mm"], 10.0 + thread)
    assert np.allclose(fingers["force_n"], 0.1 * (thread + 1))  # each row one thread's, whole
    sequence = np.round((fingers["x_mm"] - 10.0 * thread) * 1e3).astype(int)
    for k in range(PRODUCERS):
        mine = sequence[thread == k]
        assert np.all(np.diff(mine) == 1)  # in order, none lost between the ring's oldest and newest
    assert np.all(np.diff(fingers["t_s"]) >= 0)


def test_a_lift_under_other_producers_is_where_the_last_sample_was() -> None:
    """lift() reads the last position and writes its row under the producers' lock."""
    renderer = Renderer(output="null://", texture=GRATING)

    def produce() -> None:
        for k in range(500):  # with the lifts, fewer than the ring holds
            renderer.push_finger(10.0 + k * 0.01, 30.0, t=1e-6 * k)

    pusher = threading.Thread(target=produce)
    pusher.start()
    for _ in range(500):
        renderer.lift(t=0.0)
    pusher.join()
    fingers = renderer.recent_fingers()  # the newest ring - 2, oldest first
    lifts = np.flatnonzero(~fingers["down"])
    lifts = lifts[lifts > 0]
    assert len(lifts) > 0 and np.array_equal(fingers["x_mm"][lifts], fingers["x_mm"][lifts - 1])


def test_set_texture_refuses_a_start_time_far_from_the_stream_clock() -> None:
    p = pipeline()
    for t_s in (math.nan, math.inf, 1e300, 10**400, "x"):
        with pytest.raises(SampleError, match="^t_s: must be a finite number in"):
            p.set_texture(p.texture, t_s)  # type: ignore[arg-type]
