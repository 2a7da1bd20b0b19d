"""``mouse://`` input: the pointer on an X display as a finger on the plate (live only).

``mouse://?rect=screen&plate_mm=device&force_n=0.5&button=left&hover=0``

- ``rect``: ``x,y,w,h`` (pixels) of the screen rectangle mapped onto the plate;
  ``screen`` (default): the whole screen of the X display.
- ``plate_mm``: ``width,height`` (mm) of the plate the rectangle spans; ``device``
  (default): the device's plate length and width when opened with a device, else 130,60.
  At most twice the plate's length and width (:func:`tpad_rt.limits.position_range_mm`),
  so that every sample lies in the positions a finger may have.
- ``force_n``: the force (N) of every sample, at most MAX_FORCE_N.
- ``button``: ``left``, ``right``, ``middle`` or ``any``: the finger touches while it
  is held.
- ``hover=1``: the finger touches whenever the pointer is inside the rectangle, no
  button needed (for a mouse that cannot drag).

A pixel maps to its top-left corner: ``x_mm = (x_px - rect_x) * width_mm / rect_w``,
``y_mm = (y_px - rect_y) * height_mm / rect_h``; inside means ``rect_x <= x_px <
rect_x + rect_w`` and the same along y. Outside the rectangle the finger is lifted.

Every pointer event (motion or button) while touching becomes a finger sample stamped
``time.monotonic()`` (s); when touching ends (button released, pointer left the
rectangle) one lifted sample follows, at the pointer's position clamped onto the plate.
Events while lifted are dropped. Needs an X server (``DISPLAY``) with the RECORD
extension (pynput's xorg backend); BackendError otherwise, in one line.
"""

from __future__ import annotations

import functools
import importlib.util
import math
import os
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from tpad_rt.decimal_text import parse_whole
from tpad_rt.errors import BackendError
from tpad_rt.inputs.base import LiveInput, SampleSink, plate_size_mm, position_range
from tpad_rt.limits import MAX_FORCE_N
from tpad_rt.urls import Option, Url, UrlForm, flag, number, point

if TYPE_CHECKING:
    from tpad_rt.device import Device

BUTTONS = ("left", "right", "middle", "any")
_HINT = "set DISPLAY or use --input scripted://swipe"
#: What to install for the mouse: pynput is an extra (on Linux it pulls in python-evdev, which builds from source).
INSTALL_HINT = "pip install 'tpad-rt[inputs]' (on Linux it needs a C compiler and the kernel headers, for python-evdev)"


def pynput_installed() -> bool:
    """True when pynput (and the python-xlib it brings) can be imported: the extra ``tpad-rt[inputs]``."""
    return importlib.util.find_spec("pynput") is not None and importlib.util.find_spec("Xlib") is not None


def require_pynput() -> None:
    """BackendError, in one line saying what to install, unless :func:`pynput_installed`."""
    if not pynput_installed():
        raise BackendError(f"input mouse://: needs pynput, which is not installed: {INSTALL_HINT}; "
                           "or use --input scripted://swipe")


@dataclass(frozen=True)
class ScreenMap:
    """A screen rectangle ``(x, y, w, h)`` (px) mapped onto a plate ``(width, height)`` (mm)."""

    rect_px: tuple[int, int, int, int]
    plate_mm: tuple[float, float]

    def inside(self, x_px: float, y_px: float) -> bool:
        """True when pixel ``(x_px, y_px)`` lies in the rectangle."""
        x, y, w, h = self.rect_px
        return x <= x_px < x + w and y <= y_px < y + h

    def to_mm(self, x_px: float, y_px: float) -> tuple[float, float]:
        """Plate position (mm) of pixel ``(x_px, y_px)``, clamped onto the plate."""
        x, y, w, h = self.rect_px
        width_mm, height_mm = self.plate_mm
        x_mm = (x_px - x) * width_mm / w
        y_mm = (y_px - y) * height_mm / h
        return min(max(x_mm, 0.0), width_mm), min(max(y_mm, 0.0), height_mm)


class _Touch:
    """Turns one listener's pointer events into finger samples (module docstring); one thread.

    The first error ``on_sample`` raises ends the delivery and is kept in :attr:`error`.
    """

    def __init__(self, source: MouseInput, on_sample: SampleSink):
        self.source = source
        self.on_sample = on_sample
        self.held: set[str] = set()
        self.down = False
        self.error: Exception | None = None

    def on_move(self, x_px: int, y_px: int) -> None:
        self._update(x_px, y_px)

    def on_click(self, x_px: int, y_px: int, button: Any, pressed: bool) -> None:
        if self.source.button in ("any", button.name):
            (self.held.add if pressed else self.held.discard)(button.name)
        self._update(x_px, y_px)

    def _update(self, x_px: int, y_px: int) -> None:
        source = self.source
        down = source.screen.inside(x_px, y_px) and (source.hover or bool(self.held))
        if (down or self.down) and self.error is None:
            try:
                self.on_sample(time.monotonic(), *source.screen.to_mm(x_px, y_px), source.force_n, down)
            except Exception as error:  # noqa: BLE001 - re-raised by listen()
                self.error = error
        self.down = down


class MouseInput(LiveInput):
    """The pointer as a finger (module docstring); ``force_n`` (N), ``button`` one of :data:`BUTTONS`."""

    scheme = "mouse"

    def __init__(self, screen: ScreenMap, *, force_n: float = 0.5, button: str = "left", hover: bool = False):
        if button not in BUTTONS:
            raise ValueError(f"button must be one of {', '.join(BUTTONS)}, got {button!r}")
        self.screen = screen
        self.force_n = force_n
        self.button = button
        self.hover = hover

    @contextmanager
    def listen(self, on_sample: SampleSink) -> Iterator[None]:
        """Deliver pointer events to ``on_sample`` while open (see :meth:`LiveInput.listen`).

        Raises BackendError when the X display cannot be used (see :func:`screen_size_px`).
        """
        screen_size_px()  # a clear error now rather than a listener thread dying unready
        touch = _Touch(self, on_sample)
        listener = _listener_class()(on_move=touch.on_move, on_click=touch.on_click)
        listener.start()
        try:
            listener.recording.wait()
            yield
        finally:
            _stop(listener)
        if touch.error is not None:
            raise touch.error


#: Attempts (each a RECORD disable, then a join of up to ``_STOP_WAIT_S`` s) to stop a listener.
_STOP_ATTEMPTS, _STOP_WAIT_S = 20, 0.5


def _stop(listener: Any) -> None:
    """Stop and join a listener made by :func:`_listener_class`, re-raising an error raised in its thread.

    pynput's stop queues the RECORD disable request on the recording connection, where
    it stays unsent until the next pointer event wakes that connection. The request is
    sent here from a connection of our own (as pynput's own clean-up does from its
    second one), again until the thread ends; BackendError if it never does.
    """
    import Xlib.display

    if listener.is_alive():
        listener.stop()
    for _ in range(_STOP_ATTEMPTS):
        if not listener.is_alive():
            break
        # pynput's private RECORD context (see _listener_class); None: not recording yet, it ends by itself
        context = getattr(listener, "_context", None)
        if context is not None:
            display = Xlib.display.Display()
            display.set_error_handler(_ignore_x_error)  # BadContext: the context is already gone
            try:
                display.record_disable_context(context)
                display.sync()
            finally:
                display.close()
        listener.join(_STOP_WAIT_S)
    else:
        raise BackendError("input mouse://: the pointer listener did not stop")
    listener.join()


def _ignore_x_error(*error: object) -> None:
    """An Xlib error handler that drops the error."""


def screen_size_px() -> tuple[int, int]:
    """``(width, height)`` (px) of the default screen of the X display ``DISPLAY`` names.

    Raises BackendError (one line, with what to do) when pynput is not installed, DISPLAY is
    unset, no X server answers there, or the server lacks the RECORD extension pynput listens with.
    """
    require_pynput()
    import Xlib.display
    import Xlib.error

    name = os.environ.get("DISPLAY", "")
    if not name:
        raise BackendError(f"input mouse://: no display: {_HINT}")
    try:
        display = Xlib.display.Display(name)
    except (Xlib.error.DisplayError, Xlib.error.ConnectionClosedError, OSError) as error:
        reason = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise BackendError(f"input mouse://: no display: cannot connect to X display {name} ({reason}); {_HINT}") from None
    try:
        if not display.has_extension("RECORD"):
            raise BackendError(f"input mouse://: X display {name} lacks the RECORD extension pynput listens with; "
                               "start the X server with it, or use --input scripted://swipe")
        screen = display.screen()
        return screen.width_in_pixels, screen.height_in_pixels
    finally:
        display.close()


@functools.cache
def _listener_class() -> Any:
    """pynput's mouse Listener, imported now (its import needs a display), that also knows when it records.

    ``listener.recording`` (an Event) is set once the X server has started recording
    for it (pynput's ``wait()`` returns before that, and events in between are lost)
    or its thread has ended; an error that ends the thread is re-raised by ``join()``
    (pynput only does that for errors in callbacks). Raises BackendError when pynput
    cannot load.

    Private pynput names, used here and in :func:`_stop` only, because pynput offers no
    public way: ``_handler`` (its xorg backend's RECORD callback, the only place the
    StartOfData reply is seen), ``_queue`` (where ``join()`` finds the error it
    re-raises) and ``_context`` (the RECORD context to disable).
    """
    try:
        from pynput import mouse
    except ImportError as error:
        raise BackendError(f"input mouse://: pynput cannot use the display ({str(error).splitlines()[0]}); "
                           f"{_HINT}") from None
    import Xlib.ext.record

    class Listener(mouse.Listener):
        def __init__(self, **callbacks: Any):
            super().__init__(**callbacks)
            self.recording = threading.Event()

        def run(self) -> None:
            try:
                super().run()
            except Exception as error:  # noqa: BLE001 - re-raised by join(), as pynput does for callbacks
                self._queue.put((type(error), error, error.__traceback__))
            finally:
                self.recording.set()

        def _handler(self, events: Any) -> None:
            if events.category == Xlib.ext.record.StartOfData:
                self.recording.set()
            super()._handler(events)

    return Listener


def _rect(text: str) -> str | tuple[int, int, int, int]:
    """Parse ``screen`` or ``x,y,w,h`` (whole pixels, ``w, h > 0``); ValueError otherwise."""
    if text == "screen":
        return text
    try:
        values = tuple(parse_whole(part) for part in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 4 or values[0] < 0 or values[1] < 0 or values[2] <= 0 or values[3] <= 0:
        raise ValueError("must be 'screen' or four whole numbers x,y,w,h (pixels, x,y >= 0, w,h > 0)")
    return values


def _plate(text: str) -> str | tuple[float, float]:
    """Parse ``device`` or ``width,height`` (mm, > 0); ValueError otherwise."""
    if text == "device":
        return text
    try:
        values = point(text)
    except ValueError:
        values = (math.nan, math.nan)
    if not all(value > 0 for value in values):
        raise ValueError("must be 'device' or two numbers width,height (mm, > 0)")
    return values


def _button(text: str) -> str:
    if text not in BUTTONS:
        raise ValueError(f"must be one of {', '.join(BUTTONS)}")
    return text


#: The accepted URL.
FORMS = (UrlForm("mouse", "", (
    Option("rect", "screen", _rect),
    Option("plate_mm", "device", _plate),
    Option("force_n", 0.5, number(0.0, high=MAX_FORCE_N)),
    Option("button", "left", _button),
    Option("hover", False, flag),
)),)


def open_url(url: Url, *, device: Device | None = None) -> MouseInput:
    """The mouse ``url`` describes, its plate from ``device`` unless ``plate_mm`` is given.

    Raises ConfigError for a target after ``mouse://``, an unknown option, a bad value,
    a plate larger than the device's position range allows or a rectangle that does
    not fit the screen; BackendError when there is no usable
    X display (see :func:`screen_size_px`).
    """
    values = FORMS[0].read(url)
    if url.target:
        raise url.fail(f"unexpected '{url.target}' after mouse:// (options only)", FORMS)
    plate_mm = plate_size_mm(device) if values["plate_mm"] == "device" else values["plate_mm"]
    (_, x_high_mm), (_, y_high_mm) = position_range(device)
    if plate_mm[0] > x_high_mm or plate_mm[1] > y_high_mm:
        raise url.fail(f"option plate_mm: must be at most {x_high_mm:g},{y_high_mm:g} mm (samples must stay within "
                       f"one plate size of the plate), got {plate_mm[0]:g},{plate_mm[1]:g}", FORMS)
    width_px, height_px = screen_size_px()
    rect = values["rect"]
    if rect == "screen":
        rect = (0, 0, width_px, height_px)
    elif rect[0] + rect[2] > width_px or rect[1] + rect[3] > height_px:
        raise url.fail(f"option rect: {','.join(map(str, rect))} does not fit the {width_px}x{height_px} screen",
                       FORMS)
    return MouseInput(ScreenMap(rect, plate_mm), force_n=values["force_n"], button=values["button"],
                      hover=values["hover"])
