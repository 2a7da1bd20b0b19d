"""Outputs, chosen by URL: one registry of schemes, each module declaring its kind and its driver.

API map
-------
output_forms() -> dict[scheme, tuple[UrlForm, ...]]
    every output scheme with the URL forms it accepts
output_kind(url) -> (Url, OutputKind)
    the parsed URL and its scheme's kind: what the output consumes (DAC samples or the
    envelope), the driver that runs it in real time, its capabilities; ConfigError (showing
    the expected forms) for an unknown scheme, option or value, or a missing part
open_paced(url, *, device, fs_hz) -> Output
    the output the paced driver hands blocks to (what its scheme's ``open_url`` opens)
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

import contextlib
import functools
import importlib
import re
from collections.abc import Sequence
from types import ModuleType
from typing import TYPE_CHECKING

from tpad_rt.errors import ConfigError
from tpad_rt.outputs.base import Capability, Consumes, Output, OutputKind
from tpad_rt.urls import Url, UrlForm, parse_url

if TYPE_CHECKING:
    from importlib import metadata

    from tpad_rt.device import Device  # annotations only: the device model loads pydantic

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

#: The driver most outputs run on (a Python thread hands it blocks): its kinds need ``open_url``.
PACED_DRIVER = "tpad_rt.drivers.paced:PacedDriver"

_registered: dict[str, ModuleType] = {}


def register_output(module: ModuleType | str) -> None:
    """Add the output kind ``module`` (a module, or its import name) declares, under the scheme of its URL
    forms. Raises ConfigError for a module that does not import or lacks ``FORMS`` and ``KIND``, forms of
    several or badly spelled schemes, or a scheme already taken (a shipped one included)."""
    if isinstance(module, str):
        try:
            module = importlib.import_module(module)
        except Exception as error:  # noqa: BLE001 - whatever its import raised, one message
            raise ConfigError(f"register_output: module {module!r} does not import: {error}") from None
    if not isinstance(module, ModuleType):
        raise ConfigError(f"register_output: must be a module or its name, got {module!r}")
    problem = _declaration_problem(module)
    if problem:
        raise ConfigError(f"register_output: {module.__name__}: {problem}")
    scheme = module.FORMS[0].scheme
    if scheme in BUILTIN_SCHEMES or scheme in _registered or scheme in _installed():
        taken_by = BUILTIN_SCHEMES.get(scheme) or getattr(_registered.get(scheme), "__name__", None) or \
            f"the installed package's {_installed()[scheme].value}"
        raise ConfigError(f"register_output: {scheme}:// is taken (by {taken_by})")
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
    if (kind.can(Capability.OFFLINE) or kind.driver == PACED_DRIVER) and not callable(getattr(module, "open_url",
                                                                                                 None)):
        return ("open_url: an output that opens offline or runs on the paced driver must define "
                "open_url(url, *, device, fs_hz)")
    return ""


@functools.cache
def _installed() -> dict[str, metadata.EntryPoint]:
    """The schemes installed packages declare (entry point group ENTRY_POINT_GROUP, by name), read once; a
    name that is no scheme (see _SCHEME) could never be typed in a URL and is left out."""
    from importlib import metadata  # 20 ms: when a URL is parsed, not when the package is imported

    return {entry.name: entry for entry in metadata.entry_points(group=ENTRY_POINT_GROUP)
            if _SCHEME.fullmatch(entry.name) and entry.name not in BUILTIN_SCHEMES}


def output_module(scheme: str) -> ModuleType:
    """The module of the output ``scheme`` (imported now); KeyError for an unknown scheme, ConfigError for an
    installed one that does not import, is not a module, declares no output kind or another scheme."""
    if scheme in BUILTIN_SCHEMES:
        return importlib.import_module(BUILTIN_SCHEMES[scheme])
    if scheme in _registered:
        return _registered[scheme]
    entry = _installed()[scheme]
    where = f"output {scheme}://: the installed package's {entry.value}"
    try:
        module = entry.load()
    except Exception as error:  # noqa: BLE001 - whatever its import raised, one message
        raise ConfigError(f"{where} does not import: {error}") from None
    if not isinstance(module, ModuleType):
        raise ConfigError(f"{where} is not a module")
    problem = _declaration_problem(module)
    if not problem and module.FORMS[0].scheme != scheme:
        problem = f"FORMS: its scheme is {module.FORMS[0].scheme}://, not {scheme}://"
    if problem:
        raise ConfigError(f"{where}: {problem}")
    return module


def _schemes(offline: bool = False) -> dict[str, Sequence[UrlForm | str]]:
    """Every scheme -> its forms (with ``offline``, those that open offline); an installed package's scheme is
    named, not imported (so one broken package does not stop the others), until a URL uses it."""
    known: dict[str, Sequence[UrlForm | str]] = {}
    for scheme in (*BUILTIN_SCHEMES, *_registered):
        module = output_module(scheme)
        if not offline or module.KIND.can(Capability.OFFLINE):
            known[scheme] = module.FORMS
    for scheme, entry in _installed().items():
        known.setdefault(scheme, (f"{scheme}://... (from the installed package's {entry.value})",))
    return known


def output_forms() -> dict[str, tuple[UrlForm, ...]]:
    """Every output scheme with the URL forms it accepts (shipped, registered, and installed ones that import;
    ConfigError as :func:`output_module` for an installed one that does not)."""
    return {scheme: output_module(scheme).FORMS for scheme in (*BUILTIN_SCHEMES, *_registered, *_installed())}


def output_kind(url: str) -> tuple[Url, OutputKind]:
    """``url`` parsed, and its scheme's :class:`OutputKind`; ConfigError as the module docstring says. A URL of a
    shipped or registered scheme that parses imports that scheme's module only (a renderer on ``audio://``
    imports no other output); any other is parsed against every scheme, for the message."""
    scheme, separator, _ = url.partition("://") if isinstance(url, str) else ("", "", "")
    if separator and (scheme in BUILTIN_SCHEMES or scheme in _registered):
        with contextlib.suppress(ConfigError):
            parsed = parse_url(url, "output", {scheme: output_module(scheme).FORMS})
            return parsed, output_module(scheme).KIND
    parsed = parse_url(url, "output", _schemes())
    return parsed, output_module(parsed.scheme).KIND


def open_output(url: str, *, device: Device, fs_hz: int) -> Output:
    """Open the output ``url`` names offline, for ``device`` at ``fs_hz`` (Hz); errors as the module docstring
    says (the messages list the offline forms only: they are what may be opened here)."""
    offline = _schemes(offline=True)  # an installed package's scheme is among them until it is imported
    scheme, separator, _ = url.partition("://")
    if separator and scheme in _schemes() and not output_module(scheme).KIND.can(Capability.OFFLINE):
        raise Url(url, "output", scheme, "").fail(
            f"{scheme}:// plays in real time only (tpad-rt play or a Renderer), not offline",
            [form for forms in offline.values() for form in forms])
    parsed = parse_url(url, "output", offline)
    return output_module(parsed.scheme).open_url(parsed, device=device, fs_hz=fs_hz)


def open_paced(url: Url, *, device: Device, fs_hz: int) -> Output:
    """Open the output of ``url`` (parsed) for the paced driver, offline or not (ConfigError, BackendError as
    its ``open_url`` says)."""
    return output_module(url.scheme).open_url(url, device=device, fs_hz=fs_hz)


__all__ = ["Capability", "Consumes", "Output", "OutputKind", "open_output", "open_paced", "output_forms", "output_kind",
           "output_module", "register_output", "unregister_output"]
