"""Outputs, chosen by URL; every scheme declares what it consumes and what runs it.

API map
-------
output_forms() -> dict[scheme, tuple[UrlForm, ...]]
    every output scheme with the URL forms it accepts
output_kind(url) -> (Url, OutputKind)
    the parsed URL and what its scheme's output consumes (DAC samples or the envelope) and
    what runs it (a native callback, the GIL-free streamer, a paced thread); ConfigError
    (showing the expected forms) for an unknown scheme, option or value, or a missing part
open_output(url, *, device, fs_hz) -> Output
    a paced output (a simulator or a file: what ``tpad-rt render`` writes to); ConfigError as
    output_kind (listing the paced schemes), or for a real-time-only output; BackendError
    when it cannot open
Output, OutputKind, Consumes, Runs
    the paced backends' base class (``write(samples, block)``, ``measurements()``, ``close()``)
    and the declarations

Schemes (one module each, imported when used): ``audio://`` (a PortAudio stream) in
:mod:`tpad_rt.outputs.audio`, ``serial://`` (a serial amplifier, docs/amplifiers.md) in
:mod:`tpad_rt.outputs.serial_amp`, ``sim://`` (simulated plate) in
:mod:`tpad_rt.outputs.sim`, ``wav://`` (32-bit float WAV file) in
:mod:`tpad_rt.outputs.wav`, ``null://`` (discards) in :mod:`tpad_rt.outputs.null`. A
scheme's module has ``FORMS`` and ``KIND``, and a paced one ``open_url(url, *, device,
fs_hz) -> Output``. :mod:`tpad_rt.drivers` runs each kind in real time.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from tpad_rt.device import Device
from tpad_rt.outputs.base import Consumes, Output, OutputKind, Runs
from tpad_rt.urls import Url, UrlForm, parse_url

#: Scheme -> module.
_SCHEMES = {
    "audio": "tpad_rt.outputs.audio",
    "serial": "tpad_rt.outputs.serial_amp",
    "sim": "tpad_rt.outputs.sim",
    "wav": "tpad_rt.outputs.wav",
    "null": "tpad_rt.outputs.null",
}


def _module(scheme: str) -> ModuleType:
    return importlib.import_module(_SCHEMES[scheme])


def output_forms() -> dict[str, tuple[UrlForm, ...]]:
    """Every output scheme with the URL forms it accepts."""
    return {scheme: _module(scheme).FORMS for scheme in _SCHEMES}


def output_kind(url: str) -> tuple[Url, OutputKind]:
    """``url`` parsed, and what its output consumes and what runs it; ConfigError as the module docstring says."""
    parsed = parse_url(url, "output", output_forms())
    return parsed, _module(parsed.scheme).KIND


def open_output(url: str, *, device: Device, fs_hz: int) -> Output:
    """Open the paced output ``url`` names for ``device`` at ``fs_hz`` (Hz); errors as the module docstring says
    (the messages list the paced forms only: they are what may be opened here)."""
    paced = {scheme: forms for scheme, forms in output_forms().items() if not _module(scheme).KIND.realtime_only}
    scheme, separator, _ = url.partition("://")
    if separator and scheme in _SCHEMES and scheme not in paced:
        every_paced = [form for forms in paced.values() for form in forms]
        raise Url(url, "output", scheme, "").fail(
            f"{scheme}:// plays in real time only (tpad-rt play or a Renderer), not offline", every_paced)
    parsed = parse_url(url, "output", paced)
    return _module(parsed.scheme).open_url(parsed, device=device, fs_hz=fs_hz)


__all__ = ["Consumes", "Output", "OutputKind", "Runs", "open_output", "output_forms", "output_kind"]
