"""Input backends, chosen by URL: ``open_input("scripted://swipe?speed_mm_s=100")``.

API map
-------
open_input(url, device=None) -> Input
    the backend for ``url``'s scheme; ConfigError (showing the expected forms) for an
    unknown scheme, option or value, a value beyond tpad_rt.limits (positions off the
    device's plate range), a missing part, or a bad trajectory file;
    BackendError when a live input's device (the X display) is unusable
Input
    base class: ``live``, ``duration_s``, ``samples_between(t0_s, t1_s)``, ``close()``
LiveInput
    base class of live-only inputs (``live = True``): ``listen(on_sample)``
FINGER_DTYPE
    the structured dtype of finger samples ``(t_s, x_mm, y_mm, force_n, down)``

Schemes (one module each, imported when used): ``scripted://`` (swipe, circle, still,
tap) in :mod:`tpad_rt.inputs.scripted`, ``file://`` (CSV trajectory) in
:mod:`tpad_rt.inputs.file`, ``mouse://`` (the pointer on an X display, live only) in
:mod:`tpad_rt.inputs.mouse`. :class:`tpad_rt.inputs.live.LiveFeed` feeds any input into
a renderer in real time.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from tpad_rt.inputs.base import FINGER_DTYPE, Input, LiveInput
from tpad_rt.urls import UrlForm, parse_url

if TYPE_CHECKING:
    from tpad_rt.device import Device

#: Scheme -> module; each module has ``FORMS`` (its UrlForms) and ``open_url(url, *, device) -> Input``
#: (the device's plate bounds the positions an input may report; the mouse maps the screen onto it).
_SCHEMES = {
    "scripted": "tpad_rt.inputs.scripted",
    "file": "tpad_rt.inputs.file",
    "mouse": "tpad_rt.inputs.mouse",
}


def input_forms() -> dict[str, tuple[UrlForm, ...]]:
    """Every input scheme with the URL forms it accepts."""
    return {scheme: importlib.import_module(module).FORMS for scheme, module in _SCHEMES.items()}


def open_input(url: str, device: Device | None = None) -> Input:
    """Open the input ``url`` names (see the module docstring), for ``device`` when given.

    Positions are checked against :func:`tpad_rt.limits.position_range_mm` of the
    device's plate (of DEFAULT_PLATE_MM without a device). Raises ConfigError for a bad
    URL, file or value (one beyond the limits of :mod:`tpad_rt.limits` included),
    BackendError for an unusable X display.
    """
    parsed = parse_url(url, "input", input_forms())
    return importlib.import_module(_SCHEMES[parsed.scheme]).open_url(parsed, device=device)


__all__ = ["FINGER_DTYPE", "Input", "LiveInput", "input_forms", "open_input"]
