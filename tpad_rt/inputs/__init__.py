"""Input backends, chosen by URL: ``open_input("scripted://swipe?speed_mm_s=100")``.

API map
-------
open_input(url) -> Input
    the backend for ``url``'s scheme; ConfigError (showing the expected forms) for an
    unknown scheme, option or value, a missing part, or a bad trajectory file
Input
    base class: ``duration_s``, ``samples_between(t0_s, t1_s)``, ``close()``
FINGER_DTYPE
    the structured dtype of finger samples ``(t_s, x_mm, y_mm, force_n, down)``

Schemes (one module each, imported when used): ``scripted://`` (swipe, circle, still,
tap) in :mod:`tpad_rt.inputs.scripted`, ``file://`` (CSV trajectory) in
:mod:`tpad_rt.inputs.file`.
"""

from __future__ import annotations

import importlib

from tpad_rt.inputs.base import FINGER_DTYPE, Input
from tpad_rt.urls import UrlForm, parse_url

#: Scheme -> module; each module has ``FORMS`` (its UrlForms) and ``open_url(url) -> Input``.
_SCHEMES = {
    "scripted": "tpad_rt.inputs.scripted",
    "file": "tpad_rt.inputs.file",
}


def input_forms() -> dict[str, tuple[UrlForm, ...]]:
    """Every input scheme with the URL forms it accepts."""
    return {scheme: importlib.import_module(module).FORMS for scheme, module in _SCHEMES.items()}


def open_input(url: str) -> Input:
    """Open the input ``url`` names (see the module docstring); raises ConfigError for a bad URL or file."""
    parsed = parse_url(url, "input", input_forms())
    return importlib.import_module(_SCHEMES[parsed.scheme]).open_url(parsed)


__all__ = ["FINGER_DTYPE", "Input", "input_forms", "open_input"]
