"""Output backends, chosen by URL: ``open_output("sim://", device=device, fs_hz=192000)``.

API map
-------
open_output(url, *, device, fs_hz) -> Output
    the backend for ``url``'s scheme; ConfigError (showing the expected forms) for an
    unknown scheme, option or value, or a missing part; BackendError when it cannot open
Output
    base class: ``write(samples, block)``, ``measurements()``, ``close()``

Schemes (one module each, imported when used): ``sim://`` (simulated plate) in
:mod:`tpad_rt.outputs.sim`, ``wav://`` (32-bit float WAV file) in
:mod:`tpad_rt.outputs.wav`, ``null://`` (discards) in :mod:`tpad_rt.outputs.null`.
"""

from __future__ import annotations

import importlib

from tpad_rt.device import Device
from tpad_rt.outputs.base import Output
from tpad_rt.urls import UrlForm, parse_url

#: Scheme -> module; each has ``FORMS`` and ``open_url(url, *, device, fs_hz) -> Output``.
_SCHEMES = {
    "sim": "tpad_rt.outputs.sim",
    "wav": "tpad_rt.outputs.wav",
    "null": "tpad_rt.outputs.null",
}


def output_forms() -> dict[str, tuple[UrlForm, ...]]:
    """Every output scheme with the URL forms it accepts."""
    return {scheme: importlib.import_module(module).FORMS for scheme, module in _SCHEMES.items()}


def open_output(url: str, *, device: Device, fs_hz: int) -> Output:
    """Open the output ``url`` names for ``device`` at ``fs_hz`` (Hz); errors as the module docstring says."""
    parsed = parse_url(url, "output", output_forms())
    return importlib.import_module(_SCHEMES[parsed.scheme]).open_url(parsed, device=device, fs_hz=fs_hz)


__all__ = ["Output", "open_output", "output_forms"]
