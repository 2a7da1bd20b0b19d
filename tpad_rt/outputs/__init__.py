"""Outputs, chosen by URL: one registry of schemes, each module declaring its kind and its driver.

API map
-------
output_forms() -> dict[scheme, tuple[UrlForm, ...]]
    every output scheme with the URL forms it accepts
output_kind(url) -> (Url, OutputKind)
    the parsed URL and its scheme's kind: what the output consumes (DAC samples or the
    envelope), the driver that runs it in real time, its capabilities; ConfigError (showing
    the expected forms) for an unknown scheme, option or value, or a missing part
open_output(url, *, device, fs_hz) -> Output
    an output that opens offline (``Capability.OFFLINE``: a simulator or a file, what ``tpad-rt
    render`` writes to); ConfigError as output_kind (listing those schemes), or for a real-time-only
    output; BackendError when it cannot open
register_output(module), unregister_output(scheme)
    add (remove) an output kind: a module, or its import name, with ``FORMS`` and ``KIND``
output_module(scheme) -> module
    the module of a scheme
Output, OutputKind, Capability, Consumes
    the paced backends' base class (``write(samples, block)``, ``latest()``, ``close()``)
    and the declarations

The schemes (one module each, imported when used): ``audio://`` (a PortAudio stream) in
:mod:`tpad_rt.outputs.audio`, ``serial://`` (a serial amplifier, docs/amplifiers.md) in
:mod:`tpad_rt.outputs.serial_amp`, ``sim://`` (simulated plate) in
:mod:`tpad_rt.outputs.sim`, ``wav://`` (32-bit float WAV file) in
:mod:`tpad_rt.outputs.wav`, ``null://`` (discards) in :mod:`tpad_rt.outputs.null`; then
those :func:`register_output` added, and those installed packages declare in the entry
point group ``tpad_rt.outputs`` (name: the scheme, value: the module). A scheme's module
has ``FORMS`` (its URL forms, :class:`tpad_rt.urls.UrlForm`), ``KIND`` (an
:class:`OutputKind`) and, if it opens offline or its driver is the paced one,
``open_url(url, *, device, fs_hz) -> Output``. docs/architecture.md "Adding an output
kind" walks through one.
"""

from __future__ import annotations

import functools
import importlib
import re
from importlib import metadata
from types import ModuleType

from tpad_rt.device import Device
from tpad_rt.errors import ConfigError
from tpad_rt.outputs.base import Capability, Consumes, Output, OutputKind
from tpad_rt.urls import Url, UrlForm, parse_url

#: The schemes tpad-rt ships: scheme -> module.
BUILTIN_SCHEMES = {
    "audio": "tpad_rt.outputs.audio",
    "serial": "tpad_rt.outputs.serial_amp",
    "sim": "tpad_rt.outputs.sim",
    "wav": "tpad_rt.outputs.wav",
    "null": "tpad_rt.outputs.null",
}
#: The entry point group installed packages declare output schemes in.
ENTRY_POINT_GROUP = "tpad_rt.outputs"
#: What a scheme may be spelled with (RFC 3986's scheme, lower case).
_SCHEME = re.compile(r"[a-z][a-z0-9+.-]{0,31}")

_registered: dict[str, ModuleType | str] = {}


def register_output(module: ModuleType | str) -> None:
    """Add the output kind ``module`` (a module, or its import name) declares, under the scheme of its URL
    forms. Raises ConfigError for a module without ``FORMS`` and ``KIND``, forms of several or badly spelled
    schemes, or a scheme already taken (a shipped one included)."""
    module = importlib.import_module(module) if isinstance(module, str) else module
    problem = _declaration_problem(module)
    if problem:
        raise ConfigError(f"register_output: {module.__name__}: {problem}")
    scheme = module.FORMS[0].scheme
    if scheme in _modules():
        raise ConfigError(f"register_output: {scheme}:// is taken (by {_name(_modules()[scheme])})")
    _registered[scheme] = module


def unregister_output(scheme: str) -> None:
    """Remove the output kind :func:`register_output` added under ``scheme``; ConfigError for any other."""
    if scheme not in _registered:
        raise ConfigError(f"unregister_output: {scheme}:// was not registered")
    del _registered[scheme]


def _declaration_problem(module: ModuleType) -> str:
    """Why ``module`` does not declare an output kind, or ''."""
    forms, kind = getattr(module, "FORMS", None), getattr(module, "KIND", None)
    if not (isinstance(forms, tuple) and forms and all(isinstance(form, UrlForm) for form in forms)):
        return "FORMS: must be a non-empty tuple of UrlForm"
    if len({form.scheme for form in forms}) != 1 or not _SCHEME.fullmatch(forms[0].scheme):
        return ("FORMS: its forms must share one scheme, a lower-case letter then up to 31 letters, digits, "
                f"'+', '-' or '.'; got {sorted({form.scheme for form in forms})}")
    if not isinstance(kind, OutputKind):
        return "KIND: must be an OutputKind"
    if not re.fullmatch(r"[\w.]+:\w+", kind.driver):
        return f"KIND.driver: must name a driver class as 'module:Class', got {kind.driver!r}"
    if kind.can(Capability.OFFLINE) and not callable(getattr(module, "open_url", None)):
        return "open_url: an output that opens offline must define open_url(url, *, device, fs_hz)"
    return ""


@functools.cache
def _installed() -> dict[str, str]:
    """The schemes installed packages declare (entry point group ENTRY_POINT_GROUP) -> module name; read once."""
    return {entry.name: entry.value for entry in metadata.entry_points(group=ENTRY_POINT_GROUP)
            if _SCHEME.fullmatch(entry.name)}


def _modules() -> dict[str, ModuleType | str]:
    """Every scheme -> its module (or its import name, imported when used): shipped, registered, installed."""
    return {**_installed(), **_registered, **BUILTIN_SCHEMES}  # nothing takes a shipped scheme


def _name(module: ModuleType | str) -> str:
    return module if isinstance(module, str) else module.__name__


def output_module(scheme: str) -> ModuleType:
    """The module of the output ``scheme`` (imported now); KeyError for an unknown scheme, ConfigError for an
    installed one that does not import or does not declare an output kind."""
    module = _modules()[scheme]
    if isinstance(module, ModuleType):
        return module
    if scheme in BUILTIN_SCHEMES:
        return importlib.import_module(module)
    try:
        imported = importlib.import_module(module)
    except ImportError as error:
        raise ConfigError(f"output {scheme}://: the installed package's module {module} does not import: "
                          f"{error}") from None
    problem = _declaration_problem(imported)
    if problem:
        raise ConfigError(f"output {scheme}://: the package's module {module}: {problem}")
    return imported


def output_forms() -> dict[str, tuple[UrlForm, ...]]:
    """Every output scheme with the URL forms it accepts."""
    return {scheme: output_module(scheme).FORMS for scheme in _modules()}


def output_kind(url: str) -> tuple[Url, OutputKind]:
    """``url`` parsed, and its scheme's :class:`OutputKind`; ConfigError as the module docstring says."""
    parsed = parse_url(url, "output", output_forms())
    return parsed, output_module(parsed.scheme).KIND


def open_output(url: str, *, device: Device, fs_hz: int) -> Output:
    """Open the output ``url`` names offline, for ``device`` at ``fs_hz`` (Hz); errors as the module docstring
    says (the messages list the offline forms only: they are what may be opened here)."""
    forms = output_forms()
    offline = {scheme: scheme_forms for scheme, scheme_forms in forms.items()
               if output_module(scheme).KIND.can(Capability.OFFLINE)}
    scheme, separator, _ = url.partition("://")
    if separator and scheme in forms and scheme not in offline:
        every_offline = [form for scheme_forms in offline.values() for form in scheme_forms]
        raise Url(url, "output", scheme, "").fail(
            f"{scheme}:// plays in real time only (tpad-rt play or a Renderer), not offline", every_offline)
    parsed = parse_url(url, "output", offline)
    return output_module(parsed.scheme).open_url(parsed, device=device, fs_hz=fs_hz)


__all__ = ["Capability", "Consumes", "Output", "OutputKind", "open_output", "output_forms", "output_kind",
           "output_module", "register_output", "unregister_output"]
