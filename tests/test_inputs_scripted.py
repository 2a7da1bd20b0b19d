"""scripted:// inputs: kinematics of each pattern, lifting at the end, span bookkeeping, URL errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tpad_rt.errors import ConfigError
from tpad_rt.inputs import FINGER_DTYPE, open_input
from tpad_rt.inputs.scripted import Circle, Still, Swipe, Tap


def _all(url: str, until_s: float | None = None) -> np.ndarray:
    source = open_input(url)
    end = source.duration_s if until_s is None else until_s
    return source.samples_between(-math.inf, end)


def test_swipe_defaults_move_at_speed_then_lift_at_to() -> None:
    rows = _all("scripted://swipe?speed_mm_s=100")
    assert rows.dtype == FINGER_DTYPE
    assert open_input("scripted://swipe?speed_mm_s=100").duration_s == pytest.approx(1.1)
    touching, last = rows[:-1], rows[-1]
    assert touching["down"].all() and not last["down"]
    assert (last["x_mm"], last["t_s"]) == pytest.approx((120.0, 1.1))
    assert touching["x_mm"][0] == 10.0
    assert np.diff(rows["t_s"]) == pytest.approx(np.full(len(rows) - 1, 1e-3))
    assert np.diff(rows["x_mm"]) / np.diff(rows["t_s"]) == pytest.approx(np.full(len(rows) - 1, 100.0))
    assert (rows["y_mm"] == 30.0).all() and (rows["force_n"] == 0.5).all()


def test_swipe_right_to_left_with_options() -> None:
    rows = _all("scripted://swipe?speed_mm_s=50&from_mm=100&to_mm=50&y_mm=12&force_n=1.5&rate_hz=250")
    assert len(rows) == 1 + 250  # 1 s of travel at 250 Hz, plus the lift
    assert np.diff(rows["x_mm"]) / np.diff(rows["t_s"]) == pytest.approx(np.full(len(rows) - 1, -50.0))
    assert (rows["y_mm"] == 12.0).all() and (rows["force_n"] == 1.5).all()


def test_swipe_repeat_lifts_between_passes_and_starts_again() -> None:
    swipe = Swipe(speed_mm_s=100, from_mm=0, to_mm=10, repeat=3, lift_s=0.05)
    assert swipe.duration_s == pytest.approx(3 * 0.1 + 2 * 0.05)
    rows = swipe.samples_between(-math.inf, swipe.duration_s)
    down = rows["down"].astype(int)
    lifts, touches = np.flatnonzero(np.diff(down) == -1) + 1, np.flatnonzero(np.diff(down) == 1) + 1
    assert len(lifts) == 3 and len(touches) == 2
    lifted_s = rows["t_s"][touches] - rows["t_s"][lifts[:2]]
    assert lifted_s == pytest.approx([0.05, 0.05], abs=1.5e-3)  # within a sample
    assert rows["x_mm"][lifts] == pytest.approx([10.0, 10.0, 10.0], abs=0.1)  # lifted at to_mm
    assert rows["x_mm"][touches] == pytest.approx([0.0, 0.0], abs=0.1)  # touches down again at from_mm


def test_swipe_back_and_forth_turns_without_lifting() -> None:
    swipe = Swipe(speed_mm_s=100, from_mm=0, to_mm=10, repeat=4, back_and_forth=True)
    rows = swipe.samples_between(-math.inf, swipe.duration_s)
    assert rows["down"][:-1].all() and not rows["down"][-1]
    assert np.abs(np.diff(rows["x_mm"])) == pytest.approx(np.full(len(rows) - 1, 0.1))
    assert rows["x_mm"].max() == pytest.approx(10.0) and rows["x_mm"].min() == pytest.approx(0.0)
    assert rows["x_mm"][-1] == pytest.approx(0.0)  # four passes end where they started
    turns = np.flatnonzero(np.diff(np.sign(np.diff(rows["x_mm"]))) != 0)
    assert len(turns) == 3


def test_repeat_zero_is_endless() -> None:
    source = open_input("scripted://swipe?repeat=0&back_and_forth=1")
    assert source.duration_s is None
    rows = source.samples_between(1000.0, 1000.01)
    assert len(rows) == 10 and rows["down"].all()


def test_circle_keeps_radius_speed_and_turns_counter_clockwise_on_screen() -> None:
    rows = _all("scripted://circle?center_mm=65,30&radius_mm=20&speed_mm_s=100&rate_hz=2000")
    touching = rows[rows["down"]]
    radius = np.hypot(touching["x_mm"] - 65, touching["y_mm"] - 30)
    assert radius == pytest.approx(np.full(len(touching), 20.0))
    step_mm = np.hypot(np.diff(touching["x_mm"]), np.diff(touching["y_mm"]))
    chord = 2 * 20 * math.sin(100 / 2000 / 20 / 2)  # chord of one sample's arc
    assert step_mm == pytest.approx(np.full(len(step_mm), chord))
    assert touching["y_mm"][1] < 30  # starts at (85, 30) going up the screen (y down)
    assert rows["t_s"][-1] == pytest.approx(2 * math.pi * 20 / 100, abs=1 / 2000)
    assert not rows["down"][-1]


def test_still_holds_then_lifts_and_inf_is_endless() -> None:
    rows = _all("scripted://still?x_mm=5&y_mm=6&force_n=0.2&duration_s=0.5")
    assert len(rows) == 501 and rows["down"][:-1].all() and not rows["down"][-1]
    assert set(rows["x_mm"]) == {5.0} and set(rows["y_mm"]) == {6.0} and set(rows["force_n"]) == {0.2}
    assert open_input("scripted://still?duration_s=inf").duration_s is None


def test_tap_touches_count_times_for_down_s() -> None:
    tap = open_input("scripted://tap?x_mm=1&y_mm=2&down_s=0.02&up_s=0.03&count=4")
    assert isinstance(tap, Tap)
    rows = tap.samples_between(-math.inf, tap.duration_s)
    down = rows["down"].astype(int)
    assert np.count_nonzero(np.diff(down) == -1) == 4  # four lifts
    assert down.sum() == 4 * 20
    assert tap.duration_s == pytest.approx(4 * 0.02 + 3 * 0.03)


@pytest.mark.parametrize("pattern", [Swipe(), Circle(), Still(), Tap()])
def test_spans_partition_the_samples(pattern) -> None:  # type: ignore[no-untyped-def]
    whole = pattern.samples_between(-math.inf, pattern.duration_s)
    edges = np.concatenate([[-math.inf], np.sort(np.random.default_rng(1).uniform(0, pattern.duration_s, 50)),
                            [pattern.duration_s + 1]])
    pieces = np.concatenate([pattern.samples_between(a, b) for a, b in zip(edges[:-1], edges[1:])])
    assert np.array_equal(pieces, whole)
    boundary = 64 / 192000 * np.arange(0, 1000)  # block ends as the offline renderer computes them
    pieces = np.concatenate([pattern.samples_between(a, b) for a, b in zip(boundary[:-1], boundary[1:])])
    assert np.array_equal(pieces, pattern.samples_between(0, boundary[-1]))


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("scripted://swip", "unknown pattern 'swip'; did you mean 'swipe'?"),
        ("scripted://swipe?speed=100", "unknown option 'speed'; did you mean 'speed_mm_s'?"),
        ("scripted://swipe?speed_mm_s=0", "option speed_mm_s: must be a number in [0.01, 10000], got '0'"),
        ("scripted://swipe?speed_mm_s=fast", "option speed_mm_s: must be a number in [0.01, 10000], got 'fast'"),
        ("scripted://swipe?repeat=1.5", "option repeat: must be a whole number in [0, 1000000000], got '1.5'"),
        ("scripted://swipe?back_and_forth=yes", "option back_and_forth: must be 0 or 1, got 'yes'"),
        ("scripted://swipe?from_mm=5&to_mm=5", "from_mm and to_mm must differ"),
        ("scripted://swipe?speed_mm_s=1&speed_mm_s=2", "option 'speed_mm_s' given twice"),
        ("scripted://swipe?speed_mm_s=", "option 'speed_mm_s' has no value"),
        ("scripted://circle?center_mm=65", "option center_mm: must be two numbers x,y, got '65'"),
        ("scripted://still?duration_s=-1", "option duration_s: must be a number in (0, 86400] or inf"),
        ("scripted://tap?rate_hz=1e9", "option rate_hz: must be a number in (0, 100000]"),
        ("scripted://swipe?force_n=nan", "option force_n: must be a number in [0, 50], got 'nan'"),
        ("scriptd://swipe", "unknown scheme 'scriptd'; did you mean 'scripted'? (known: scripted://, file://, mouse://)"),
        ("swipe", "not a URL (no 'scheme://')"),
    ],
)
def test_url_errors_say_what_and_show_the_expected_form(url: str, expected: str) -> None:
    with pytest.raises(ConfigError) as caught:
        open_input(url)
    message = str(caught.value)
    assert message.startswith(f"input URL '{url}': ")
    assert expected in message
    assert "expected scripted://" in message


def test_swipe_error_shows_the_full_swipe_form() -> None:
    with pytest.raises(ConfigError, match="swipe") as caught:
        open_input("scripted://swipe?spede_mm_s=1")
    assert str(caught.value).endswith(
        "expected scripted://swipe?speed_mm_s=100&from_mm=10&to_mm=120&y_mm=30&force_n=0.5"
        "&rate_hz=1000&repeat=1&back_and_forth=0&lift_s=0.2"
    )
