"""The textures and device files that ship inside the package, and references to them by name.

They are package data (``tpad_rt/textures/``, ``tpad_rt/devices/``), found through
:mod:`importlib.resources`, so an installed wheel has them wherever it runs; in a clone
of the repository ``textures/`` links to the same folder.

API map
-------
TEXTURES_DIR, DEVICES_DIR
    the two folders (``Path``)
texture_names() -> list[str], device_names() -> list[str]
    the shipped files' names without ``.yaml``, sorted
texture_file(ref) -> ref or Path, device_file(ref) -> ref or Path
    ``ref`` itself when it names a file or looks like a path (it has a folder or a
    ``.yaml``/``.yml`` suffix), else the shipped file of that name; ConfigError naming
    the shipped ones when there is none, or naming the shipped file when a missing path
    ends in a shipped file's name (``textures/grating.yaml`` run outside the repository);
    a name or missing path close to a shipped name or a YAML file in its folder gets
    "did you mean" (difflib)
any_file(ref) -> ref or Path
    the same for a ref that may name either (``tpad-rt check``): a shipped texture first
DEFAULT_DEVICE
    ``DEVICES_DIR / "default.yaml"`` (SLG_0.56)
"""

from __future__ import annotations

import difflib
import importlib.resources
import os
from pathlib import Path

from tpad_rt.errors import ConfigError


def _package_folder(name: str) -> Path:
    """The package-data folder ``tpad_rt/<name>`` as a file-system path (pip installs wheels unpacked)."""
    return Path(str(importlib.resources.files("tpad_rt").joinpath(name)))


TEXTURES_DIR = _package_folder("textures")
DEVICES_DIR = _package_folder("devices")
DEFAULT_DEVICE = DEVICES_DIR / "default.yaml"
_SUFFIXES = (".yaml", ".yml")
PathLike = str | os.PathLike[str]


def _present(text: str) -> bool:
    """Whether something (a file, a folder, a FIFO, a dangling link) is at path ``text``; False for a name the
    system refuses (too long, a NUL byte): os.path answers where pathlib raises."""
    return os.path.lexists(text)


def _names(folder: Path) -> list[str]:
    """Names (without ``.yaml``) of the YAML files in ``folder``, sorted; empty if it is missing."""
    return sorted(path.stem for path in folder.glob("*.yaml")) if folder.is_dir() else []


def texture_names() -> list[str]:
    """Names of the shipped textures (``grating``, ...), sorted."""
    return _names(TEXTURES_DIR)


def device_names() -> list[str]:
    """Names of the shipped device files (``SLG_0.56``, ``default``, ...), sorted."""
    return _names(DEVICES_DIR)


def _yaml_files(folder: str) -> list[str]:
    """Names of the YAML files in ``folder`` (``""``: the working folder); empty when it cannot be listed."""
    try:
        with os.scandir(folder or ".") as entries:
            return [entry.name for entry in entries if os.path.splitext(entry.name)[1].lower() in _SUFFIXES]
    except (OSError, ValueError):
        return []


def _did_you_mean(text: str, candidates: list[str], folder: str = "") -> str:
    """``"; did you mean 'FOLDER/X'?"`` for the candidate X closest to ``text`` (difflib, on the names without a
    ``.yaml`` suffix: the suffix alone would make two names alike), or ``""`` when none is close."""
    by_stem = {_stem(candidate): candidate for candidate in reversed(candidates)}  # the first of a stem wins
    close = difflib.get_close_matches(_stem(text), list(by_stem), n=1)
    return f"; did you mean '{os.path.join(folder, by_stem[close[0]])}'?" if close else ""


def _stem(name: str) -> str:
    """``name`` without a ``.yaml``/``.yml`` suffix."""
    root, suffix = os.path.splitext(name)
    return root if suffix.lower() in _SUFFIXES else name


def _resolve(ref: PathLike, folder: Path, what: str) -> PathLike:
    """``ref`` itself, or the shipped ``folder / (ref + ".yaml")`` for a bare name (module docstring)."""
    path = Path(ref)
    text = os.fspath(ref)
    looks_like_path = text == "" or os.sep in text or "/" in text or path.suffix.lower() in _SUFFIXES
    if _present(text):
        return ref
    if looks_like_path:
        if path.suffix.lower() in _SUFFIXES and os.path.isfile(folder / f"{path.stem}.yaml"):
            # textures/grating.yaml outside a clone of the repository: the name reaches the shipped file
            raise ConfigError(f"{text}: no such file; the package ships a {what} of that name: give just "
                              f"'{path.stem}'")
        parent, name = os.path.split(text)
        hint = _did_you_mean(name, _yaml_files(parent), parent) if name else ""
        if hint:  # textures/gratin.yaml: a file next to it is what was meant
            raise ConfigError(f"{text}: no such file{hint}")
        return ref
    shipped = folder / f"{text}.yaml"
    if os.path.isfile(shipped):
        return shipped
    names = _names(folder)
    hint = _did_you_mean(text, names + _yaml_files(""))
    raise ConfigError(f"{text}: no such file, nor a shipped {what} of that name{hint} "
                      f"(shipped: {', '.join(names) if names else 'none found in ' + str(folder)})")


def texture_file(ref: PathLike) -> PathLike:
    """The texture file ``ref`` names: a path, or a shipped texture's name; ConfigError if neither."""
    return _resolve(ref, TEXTURES_DIR, "texture")


def device_file(ref: PathLike) -> PathLike:
    """The device file ``ref`` names: a path, or a shipped device's name; ConfigError if neither."""
    return _resolve(ref, DEVICES_DIR, "device")


def any_file(ref: PathLike) -> PathLike:
    """The texture or device file ``ref`` names: a path, or a shipped texture's or device's name (a texture
    first); ConfigError naming both lists when it is none of them, or with the hint of
    :func:`texture_file` or :func:`device_file` for a missing path ending in a shipped file's name."""
    if _present(os.fspath(ref)):
        return ref
    refused = 0
    for resolve in (texture_file, device_file):
        try:
            resolved = resolve(ref)
        except ConfigError as error:
            if "no such file, nor" not in str(error):
                raise  # a missing path ending in a shipped file's name: its hint
            refused += 1
            continue
        if resolved is not ref:
            return resolved  # a shipped name
    if refused == 2:
        text = os.fspath(ref)
        hint = _did_you_mean(text, texture_names() + device_names() + _yaml_files(""))
        raise ConfigError(f"{text}: no such file, nor a shipped texture or device of that name{hint} "
                          f"(textures: {', '.join(texture_names())}; devices: {', '.join(device_names())})")
    return ref  # a path naming nothing shipped: reading it says it is missing
