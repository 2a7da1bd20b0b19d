"""mouse:// input on a real X server (Xvfb): pixel-to-plate mapping, button, rectangle and hover
rules, driven by pynput's Controller and by xdotool; errors without a display."""

from __future__ import annotations

import math
import queue
import subprocess
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import require_program
from xvfb import SCREEN_PX, display, xvfb_server  # noqa: F401 - fixtures

from tpad_rt.device import Device
from tpad_rt.errors import BackendError, ConfigError
from tpad_rt.inputs import LiveInput, open_input
from tpad_rt.inputs.mouse import MouseInput, ScreenMap

pytestmark = pytest.mark.system

#: 0.25 mm per pixel both ways, so every mapped position is exact in binary.
RECT = "100,50,640,320"
PLATE = "160,80"
#: Bound (s) on waiting for an event that must come; a failure bound, not a timing assertion.
EVENT_TIMEOUT_S = 10.0

Sample = tuple[float, float, float, float, bool]


class Recorder:
    """An ``on_sample`` sink that queues what it receives."""

    def __init__(self) -> None:
        self.samples: queue.Queue[Sample] = queue.Queue()

    def __call__(self, t_s: float, x_mm: float, y_mm: float, force_n: float, down: bool) -> None:
        self.samples.put((t_s, x_mm, y_mm, force_n, down))

    def next(self) -> tuple[float, float, bool]:
        """The next sample's ``(x_mm, y_mm, down)``, waiting for it."""
        _, x_mm, y_mm, _, down = self.samples.get(timeout=EVENT_TIMEOUT_S)
        return x_mm, y_mm, down

    def take(self, count: int) -> list[tuple[float, float, bool]]:
        return [self.next() for _ in range(count)]


@contextmanager
def listening(url: str) -> Iterator[Recorder]:
    recorder = Recorder()
    with open_input(url).listen(recorder):  # type: ignore[attr-defined]
        yield recorder
    assert recorder.samples.empty(), f"unexpected samples: {list(recorder.samples.queue)}"


@pytest.fixture
def pointer(display: str):  # noqa: F811 - the imported fixture
    """A pynput mouse Controller on the test's display, parked at the screen's top-left corner."""
    from pynput.mouse import Controller

    controller = Controller()
    controller.position = (0, 0)
    return controller


def xdotool(*arguments: str) -> None:
    subprocess.run([require_program("xdotool"), *arguments], check=True, timeout=30)


def test_screen_map_corners_and_clamping() -> None:
    screen = ScreenMap((100, 50, 640, 320), (160.0, 80.0))
    assert screen.to_mm(100, 50) == (0.0, 0.0)
    assert screen.to_mm(739, 369) == (159.75, 79.75)
    assert screen.to_mm(0, 1000) == (0.0, 80.0)
    assert screen.inside(100, 50) and screen.inside(739, 369)
    assert not screen.inside(740, 200) and not screen.inside(400, 49)


def test_held_button_touches_at_the_mapped_position_and_release_lifts(pointer) -> None:
    from pynput.mouse import Button

    with listening(f"mouse://?rect={RECT}&plate_mm={PLATE}&force_n=0.75") as recorder:
        pointer.position = (420, 210)  # not pressed: no sample
        pointer.press(Button.left)
        pointer.position = (500, 250)
        pointer.release(Button.left)
        pointer.position = (300, 100)  # released: no sample
        pointer.press(Button.left)
        t_s, x_mm, y_mm, force_n, down = recorder.samples.get(timeout=EVENT_TIMEOUT_S)
        assert (x_mm, y_mm, force_n, down) == (80.0, 40.0, 0.75, True)
        assert recorder.take(3) == [(100.0, 50.0, True), (100.0, 50.0, False), (50.0, 12.5, True)]
        pointer.release(Button.left)
        assert recorder.next() == (50.0, 12.5, False)


def test_samples_are_stamped_with_the_monotonic_clock_in_order(pointer) -> None:
    import time

    from pynput.mouse import Button

    with listening(f"mouse://?rect={RECT}&plate_mm={PLATE}") as recorder:
        before_s = time.monotonic()
        pointer.press(Button.left)  # at (0, 0): outside, no sample
        for x_px in range(200, 260, 10):
            pointer.position = (x_px, 100)
        pointer.release(Button.left)
        stamps = [recorder.samples.get(timeout=EVENT_TIMEOUT_S)[0] for _ in range(7)]
        after_s = time.monotonic()
    assert before_s <= stamps[0] and stamps == sorted(stamps) and stamps[-1] <= after_s


def test_xdotool_drag_maps_exactly(display: str) -> None:  # noqa: F811
    with listening(f"mouse://?rect={RECT}&plate_mm={PLATE}") as recorder:
        xdotool("mousemove", "420", "210", "mousedown", "1", "mousemove", "104", "54", "mouseup", "1")
        assert recorder.take(3) == [(80.0, 40.0, True), (1.0, 1.0, True), (1.0, 1.0, False)]


def test_leaving_the_rectangle_lifts_and_coming_back_touches_again(pointer) -> None:
    from pynput.mouse import Button

    with listening(f"mouse://?rect={RECT}&plate_mm={PLATE}") as recorder:
        pointer.position = (420, 210)
        pointer.press(Button.left)
        pointer.position = (800, 210)  # right of the rectangle
        pointer.position = (900, 300)  # still outside, lifted: no sample
        pointer.position = (420, 210)
        pointer.release(Button.left)
        assert recorder.take(4) == [(80.0, 40.0, True), (160.0, 40.0, False), (80.0, 40.0, True),
                                    (80.0, 40.0, False)]


def test_hover_touches_inside_without_a_button(pointer) -> None:
    with listening(f"mouse://?rect={RECT}&plate_mm={PLATE}&hover=1") as recorder:
        pointer.position = (420, 210)
        pointer.position = (424, 214)
        pointer.position = (50, 214)
        assert recorder.take(3) == [(80.0, 40.0, True), (81.0, 41.0, True), (0.0, 41.0, False)]


def test_button_option_selects_which_button_touches(pointer) -> None:
    from pynput.mouse import Button

    with listening(f"mouse://?rect={RECT}&plate_mm={PLATE}&button=right") as recorder:
        pointer.position = (420, 210)
        pointer.click(Button.left)  # the wrong button: no sample
        pointer.press(Button.right)
        pointer.release(Button.right)
        assert recorder.take(2) == [(80.0, 40.0, True), (80.0, 40.0, False)]
    with listening(f"mouse://?rect={RECT}&plate_mm={PLATE}&button=any") as recorder:
        pointer.press(Button.middle)
        pointer.press(Button.left)
        pointer.release(Button.middle)  # left still held: touching
        pointer.release(Button.left)
        assert recorder.take(4) == [(80.0, 40.0, True), (80.0, 40.0, True), (80.0, 40.0, True),
                                    (80.0, 40.0, False)]


def test_defaults_whole_screen_and_the_plate_of_the_device(display: str) -> None:  # noqa: F811
    source = open_input("mouse://")
    assert isinstance(source, MouseInput) and isinstance(source, LiveInput) and source.live
    width_px, height_px = SCREEN_PX
    assert source.screen == ScreenMap((0, 0, width_px, height_px), (130.0, 60.0))
    assert (source.force_n, source.button, source.hover) == (0.5, "left", False)
    device = Device.default()
    wide = replace(device, plate=replace(device.plate, length_m=0.2, width_m=0.1))
    assert open_input("mouse://", device=wide).screen.plate_mm == pytest.approx((200.0, 100.0))
    assert open_input(f"mouse://?plate_mm={PLATE}", device=wide).screen.plate_mm == (160.0, 80.0)


def test_rectangle_must_fit_the_screen(display: str) -> None:  # noqa: F811
    with pytest.raises(ConfigError, match=r"option rect: 1000,0,300,10 does not fit the 1280x800 screen"):
        open_input("mouse://?rect=1000,0,300,10")


def test_a_live_input_cannot_be_read_offline(display: str) -> None:  # noqa: F811
    source = open_input("mouse://")
    assert source.duration_s is None
    with pytest.raises(BackendError, match=r"^input mouse://: a live input .* cannot be rendered offline"):
        source.samples_between(-math.inf, 1.0)


def test_an_error_in_the_sink_is_reraised_on_exit(pointer) -> None:
    called = threading.Event()

    def sink(*sample: object) -> None:
        called.set()
        raise ZeroDivisionError("sink failed")

    with pytest.raises(ZeroDivisionError, match="sink failed"):
        with open_input(f"mouse://?rect={RECT}&hover=1").listen(sink):  # type: ignore[attr-defined]
            pointer.position = (420, 210)
            assert called.wait(EVENT_TIMEOUT_S)


def test_no_display_is_a_one_line_backend_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    with pytest.raises(BackendError) as error:
        open_input("mouse://")
    assert str(error.value) == "input mouse://: no display: set DISPLAY or use --input scripted://swipe"


def test_a_display_without_a_server_is_a_one_line_backend_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DISPLAY", ":1999")
    with pytest.raises(BackendError) as error:
        open_input("mouse://")
    message = str(error.value)
    assert message.startswith("input mouse://: no display: cannot connect to X display :1999 (")
    assert message.endswith("); set DISPLAY or use --input scripted://swipe") and "\n" not in message


@pytest.mark.parametrize(("url", "problem"), [
    ("mouse://left", "unexpected 'left' after mouse://"),
    ("mouse://?rect=1,2,3", "option rect: must be 'screen' or four whole numbers"),
    ("mouse://?rect=0,0,0,10", "option rect: must be 'screen' or four whole numbers"),
    ("mouse://?plate_mm=0,60", "option plate_mm: must be 'device' or two numbers"),
    ("mouse://?button=thumb", "option button: must be one of left, right, middle, any"),
    ("mouse://?hover=yes", "option hover: must be 0 or 1"),
    ("mouse://?force=1", "unknown option 'force'; did you mean 'force_n'?"),
])
def test_url_errors_show_the_expected_form(url: str, problem: str) -> None:
    with pytest.raises(ConfigError) as error:
        open_input(url)
    assert problem in str(error.value)
    assert str(error.value).endswith("expected mouse://?rect=screen&plate_mm=device&force_n=0.5&button=left&hover=0")


def test_render_refuses_a_live_input_in_one_line(display: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:  # noqa: F811 - the fixture
    from tpad_rt.cli import main

    status = main(["render", "textures/grating.yaml", "--input", "mouse://", "--duration", "1",
                   "--out", str(tmp_path / "x.npz")])
    err = capsys.readouterr().err
    assert status == 1 and not (tmp_path / "x.npz").exists()
    assert err == ("tpad-rt render: input mouse://: follows a live finger, which cannot be rendered offline; "
                   "use tpad-rt play, or a scripted:// or file:// input\n")
