"""``scripted://`` inputs: finger patterns computed from time, sampled like a touch sensor.

Each pattern is a pure function of time sampled at ``rate_hz`` (samples at
``t = k / rate_hz``, ``k = 0, 1, ...``), so it can be read from any thread, any span,
in any order. Patterns with an end lift the finger there: the sample at or just after
the end is the last one and has ``down = False``.

- ``swipe``: from ``from_mm`` to ``to_mm`` along x at height ``y_mm`` and constant
  ``speed_mm_s``; ``repeat`` passes (0: endless), each followed by ``lift_s`` lifted
  (the finger returns to ``from_mm`` meanwhile), or with ``back_and_forth=1`` turning
  round at each end without lifting.
- ``circle``: around ``center_mm`` with ``radius_mm`` at ``speed_mm_s``, starting at
  ``(cx + r, cy)`` and turning counter-clockwise on screen (y points down); ``turns``
  turns (0: endless).
- ``still``: resting at ``(x_mm, y_mm)`` for ``duration_s`` (``inf``: endless).
- ``tap``: at ``(x_mm, y_mm)``, ``count`` taps (0: endless) of ``down_s`` touching
  then ``up_s`` lifted.

Every pattern presses with ``force_n`` newtons.

Limits (:mod:`tpad_rt.limits`), checked when a URL is opened, each error naming the
option: ``speed_mm_s`` in [0.01, 10000] mm/s; ``force_n`` in [0, MAX_FORCE_N];
``rate_hz`` in (0, 100000]; ``lift_s``, ``down_s``, ``up_s``, ``duration_s`` at most
MAX_INPUT_S (a day); ``repeat``, ``count`` at most 10^9; every position the pattern
reaches (``from_mm``, ``to_mm``, ``y_mm``, ``x_mm``, ``center_mm`` +- ``radius_mm``)
within :func:`tpad_rt.limits.position_range_mm` of the device's plate (of
DEFAULT_PLATE_MM without a device); and a pattern with an end must end within
MAX_INPUT_S.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import numpy.typing as npt

from tpad_rt.inputs.base import FINGER_DTYPE, Input, position_range
from tpad_rt.limits import MAX_FORCE_N, MAX_INPUT_S
from tpad_rt.urls import Option, Url, UrlForm, count, did_you_mean, flag, number, point

if TYPE_CHECKING:
    from tpad_rt.device import Device

_Times = npt.NDArray[np.float64]
_Pose = tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.bool_]]
#: ``(what, position in mm, axis)``: a position a pattern reaches, named by its option(s).
_Reach = list[tuple[str, float, str]]

#: The most samples per second a scripted touch sensor may produce.
MAX_SENSOR_RATE_HZ = 100_000.0
#: Finger speeds (mm/s) a pattern may move at: a crawl to ten metres a second.
SPEED_RANGE_MM_S = (0.01, 10_000.0)
#: Most passes (``repeat``) or taps (``count``) of a pattern.
MAX_REPEATS = 10**9


class _Scripted(Input):
    """A pattern sampled at ``self.rate_hz`` (Hz) pressing with ``self.force_n`` (N)."""

    rate_hz: float
    force_n: float

    @property
    @abstractmethod
    def touch_end_s(self) -> float | None:
        """Time (s) the finger lifts for good, or None when the pattern never ends."""

    @abstractmethod
    def pose(self, t_s: _Times) -> _Pose:
        """Position ``(x_mm, y_mm)`` and touching flag at times ``t_s`` (>= 0, before the end)."""

    @abstractmethod
    def reach(self) -> _Reach:
        """The extreme positions (mm) the pattern reaches, each with the option(s) setting it and its axis."""

    def check_limits(self, x_range_mm: tuple[float, float], y_range_mm: tuple[float, float]) -> None:
        """Raise ValueError (naming the option) when the pattern leaves the position ranges (mm)
        or ends later than MAX_INPUT_S (s)."""
        for what, position_mm, axis in self.reach():
            low, high = x_range_mm if axis == "x" else y_range_mm
            if not low <= position_mm <= high:
                raise ValueError(f"option {what}: must be in [{low:g}, {high:g}] mm ({axis} on the plate, up to one "
                                 f"plate size beyond each edge), got {position_mm:g}")
        end_s = self.touch_end_s
        if end_s is not None and not end_s <= MAX_INPUT_S:
            shown = f"{end_s:,.1f}".removesuffix(".0") if end_s < 1e12 else f"{end_s:.3g}"
            raise ValueError(f"ends after {shown} s, longer than the {MAX_INPUT_S:g} s an input may last")

    @property
    def duration_s(self) -> float | None:
        """Time (s) of the last sample, the first at or after :attr:`touch_end_s`; None when endless."""
        index = self._last_index()
        return None if index is None else index / self.rate_hz

    def _last_index(self) -> int | None:
        """Index of the first sample at or after the end (within a millionth of a sample: float noise)."""
        end = self.touch_end_s
        return None if end is None else math.ceil(end * self.rate_hz - 1e-6)

    def samples_between(self, t0_s: float, t1_s: float) -> np.ndarray:
        """The samples with ``t0_s < t_s <= t1_s`` (see :meth:`Input.samples_between`)."""
        margin = 1e-6  # of a sample period: no sample index can hide in float noise
        if t0_s > -math.inf and math.floor(t1_s * self.rate_hz + margin) == math.floor(t0_s * self.rate_hz - margin):
            return np.empty(0, dtype=FINGER_DTYPE)  # the common case: a span shorter than a sample period
        first = 0 if t0_s == -math.inf else max(0, math.floor(t0_s * self.rate_hz))
        stop = max(first, math.floor(t1_s * self.rate_hz) + 2)
        last = self._last_index()
        if last is not None:
            stop = min(stop, last + 1)
        index = np.arange(first, stop)
        t_s = index / self.rate_hz
        inside = (t_s > t0_s) & (t_s <= t1_s)
        index, t_s = index[inside], t_s[inside]
        x_mm, y_mm, down = self.pose(t_s)
        rows = np.empty(len(t_s), dtype=FINGER_DTYPE)
        rows["t_s"] = t_s
        rows["x_mm"] = x_mm
        rows["y_mm"] = y_mm
        rows["force_n"] = self.force_n
        rows["down"] = down if last is None else down & (index < last)
        return rows


def _touch_end(touches: float, touch_s: float, gap_s: float) -> float | None:
    """End (s) of ``touches`` touches of ``touch_s`` separated by ``gap_s`` (0 touches: endless)."""
    return None if touches == 0 else touches * touch_s + (touches - 1) * gap_s


@dataclass(frozen=True)
class Swipe(_Scripted):
    """Straight passes along x at constant speed (module docstring); mm, mm/s, s, N, Hz."""

    speed_mm_s: float = 100.0
    from_mm: float = 10.0
    to_mm: float = 120.0
    y_mm: float = 30.0
    force_n: float = 0.5
    rate_hz: float = 1000.0
    repeat: int = 1
    back_and_forth: bool = False
    lift_s: float = 0.2

    def __post_init__(self) -> None:
        if self.from_mm == self.to_mm:
            raise ValueError("from_mm and to_mm must differ")

    @property
    def pass_s(self) -> float:
        """Duration (s) of one pass from ``from_mm`` to ``to_mm``."""
        return abs(self.to_mm - self.from_mm) / self.speed_mm_s

    @property
    def touch_end_s(self) -> float | None:
        return _touch_end(self.repeat, self.pass_s, 0.0 if self.back_and_forth else self.lift_s)

    def pose(self, t_s: _Times) -> _Pose:
        period_s = self.pass_s if self.back_and_forth else self.pass_s + self.lift_s
        passes = np.floor(t_s / period_s)
        into_s = t_s - passes * period_s
        travelled_mm = np.minimum(into_s, self.pass_s) * self.speed_mm_s
        direction = math.copysign(1.0, self.to_mm - self.from_mm)
        backwards = self.back_and_forth & (passes % 2 == 1)
        x_mm = np.where(backwards, self.to_mm - direction * travelled_mm, self.from_mm + direction * travelled_mm)
        return x_mm, np.full_like(t_s, self.y_mm), into_s < self.pass_s

    def reach(self) -> _Reach:
        return [("from_mm", self.from_mm, "x"), ("to_mm", self.to_mm, "x"), ("y_mm", self.y_mm, "y")]


@dataclass(frozen=True)
class Circle(_Scripted):
    """Circles at constant speed, counter-clockwise on screen (module docstring); mm, mm/s, N, Hz."""

    center_mm: tuple[float, float] = (65.0, 30.0)
    radius_mm: float = 20.0
    speed_mm_s: float = 100.0
    force_n: float = 0.5
    rate_hz: float = 1000.0
    turns: float = 1.0

    @property
    def touch_end_s(self) -> float | None:
        return _touch_end(self.turns, 2 * math.pi * self.radius_mm / self.speed_mm_s, 0.0)

    def pose(self, t_s: _Times) -> _Pose:
        angle_rad = self.speed_mm_s * t_s / self.radius_mm
        center_x_mm, center_y_mm = self.center_mm
        x_mm = center_x_mm + self.radius_mm * np.cos(angle_rad)
        y_mm = center_y_mm - self.radius_mm * np.sin(angle_rad)
        return x_mm, y_mm, np.ones(len(t_s), dtype=bool)

    def reach(self) -> _Reach:
        (x_mm, y_mm), r_mm = self.center_mm, self.radius_mm
        return [("center_mm x - radius_mm", x_mm - r_mm, "x"), ("center_mm x + radius_mm", x_mm + r_mm, "x"),
                ("center_mm y - radius_mm", y_mm - r_mm, "y"), ("center_mm y + radius_mm", y_mm + r_mm, "y")]


@dataclass(frozen=True)
class Still(_Scripted):
    """A finger resting in one place for ``hold_s`` (URL option ``duration_s``; inf: endless); mm, s, N, Hz."""

    x_mm: float = 65.0
    y_mm: float = 30.0
    force_n: float = 0.5
    rate_hz: float = 1000.0
    hold_s: float = 1.0

    @property
    def touch_end_s(self) -> float | None:
        return None if self.hold_s == math.inf else self.hold_s

    def pose(self, t_s: _Times) -> _Pose:
        return np.full_like(t_s, self.x_mm), np.full_like(t_s, self.y_mm), np.ones(len(t_s), dtype=bool)

    def reach(self) -> _Reach:
        return [("x_mm", self.x_mm, "x"), ("y_mm", self.y_mm, "y")]


@dataclass(frozen=True)
class Tap(_Scripted):
    """``count`` taps in one place (0: endless), ``down_s`` touching then ``up_s`` lifted; mm, s, N, Hz."""

    x_mm: float = 65.0
    y_mm: float = 30.0
    down_s: float = 0.2
    up_s: float = 0.3
    count: int = 3
    force_n: float = 0.5
    rate_hz: float = 1000.0

    @property
    def touch_end_s(self) -> float | None:
        return _touch_end(self.count, self.down_s, self.up_s)

    def pose(self, t_s: _Times) -> _Pose:
        into_s = np.mod(t_s, self.down_s + self.up_s)
        return np.full_like(t_s, self.x_mm), np.full_like(t_s, self.y_mm), into_s < self.down_s

    def reach(self) -> _Reach:
        return [("x_mm", self.x_mm, "x"), ("y_mm", self.y_mm, "y")]


_SPAN_S = number(0.0, low_closed=False, high=MAX_INPUT_S)
_POSITION = number()  # the plate's range is checked once the device is known (_Scripted.check_limits)
#: One parser per option name: a name means the same in every pattern.
_PARSERS = {
    "speed_mm_s": number(SPEED_RANGE_MM_S[0], high=SPEED_RANGE_MM_S[1]),
    "from_mm": _POSITION,
    "to_mm": _POSITION,
    "x_mm": _POSITION,
    "y_mm": _POSITION,
    "center_mm": point,
    "radius_mm": number(0.0, low_closed=False),
    "force_n": number(0.0, high=MAX_FORCE_N),
    "rate_hz": number(0.0, low_closed=False, high=MAX_SENSOR_RATE_HZ),
    "repeat": count(0, high=MAX_REPEATS),
    "count": count(0, high=MAX_REPEATS),
    "turns": number(0.0),
    "back_and_forth": flag,
    "lift_s": _SPAN_S,
    "down_s": _SPAN_S,
    "up_s": _SPAN_S,
    "duration_s": number(0.0, low_closed=False, high=MAX_INPUT_S, allow_inf=True),
}

_KINDS: dict[str, type[_Scripted]] = {"swipe": Swipe, "circle": Circle, "still": Still, "tap": Tap}


#: URL option names that differ from the field's (``Input.duration_s`` is the property of every input).
_URL_NAMES = {"hold_s": "duration_s"}


def _url_name(field_name: str) -> str:
    return _URL_NAMES.get(field_name, field_name)


def _form(kind: str) -> UrlForm:
    options = tuple(
        Option(_url_name(item.name), item.default, _PARSERS[_url_name(item.name)])
        for item in fields(cast(Any, _KINDS[kind]))  # every kind is a dataclass
    )
    return UrlForm("scripted", kind, options)


#: The accepted URLs, one per pattern; the defaults are the dataclass defaults.
FORMS = tuple(_form(kind) for kind in _KINDS)


def open_url(url: Url, *, device: Device | None = None) -> _Scripted:
    """The pattern ``url`` names, on ``device``'s plate (the default plate without one).

    Raises ConfigError for an unknown pattern or option, a value out of its range, a
    position off the plate's range or an end later than MAX_INPUT_S (module docstring).
    """
    if url.target not in _KINDS:
        hint = did_you_mean(url.target, list(_KINDS))
        raise url.fail(f"unknown pattern '{url.target}'{hint} (patterns: {', '.join(_KINDS)})", FORMS)
    form = FORMS[list(_KINDS).index(url.target)]
    values: dict[str, Any] = form.read(url)
    cls = _KINDS[url.target]
    arguments = {item.name: values[_url_name(item.name)] for item in fields(cast(Any, cls))}  # cls: a dataclass
    try:
        pattern = cls(**arguments)
        pattern.check_limits(*position_range(device))
    except ValueError as error:
        raise url.fail(str(error), [form]) from None
    return pattern
