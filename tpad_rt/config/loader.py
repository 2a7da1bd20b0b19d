"""Loading texture and device files into validated models, or into breadcrumb errors."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from pydantic import TypeAdapter, ValidationError

from tpad_rt.config.breadcrumb import breadcrumb
from tpad_rt.config.device_schema import DEVICE_FORMAT_VERSION, DeviceFile
from tpad_rt.config.messages import MAX_LISTED_ERRORS, explain, listed
from tpad_rt.config.texture_schema import BASE_DIR, IMAGE_DIRS, IMAGE_PIXELS, TextureFile
from tpad_rt.config.yaml_io import YamlDocument, load_yaml, parse_yaml
from tpad_rt.errors import ConfigError, printable
from tpad_rt.shipped import any_file, device_file, texture_file

PathLike = str | os.PathLike[str]

_ADAPTERS: dict[Any, TypeAdapter[Any]] = {TextureFile: TypeAdapter(TextureFile), DeviceFile: TypeAdapter(DeviceFile)}


def load_texture(path: PathLike, image_dirs: list[Path] | None = None) -> TextureFile:
    """The texture file at ``path`` (or the shipped texture of that name, :mod:`tpad_rt.shipped`), its images
    only from ``image_dirs`` (resolved folders) when given; raises ConfigError listing every problem in it."""
    path = texture_file(path)
    return _validate(TextureFile, path, load_yaml(Path(path), str(path)), image_dirs=image_dirs)


def parse_texture(text: bytes, source: str, base_dir: Path, image_dirs: list[Path]) -> TextureFile:
    """The texture file whose bytes are ``text`` (its errors prefixed with ``source``); relative image paths
    start from ``base_dir`` and every image must lie in one of ``image_dirs`` (resolved folders). Raises
    ConfigError listing every problem."""
    return _validate(TextureFile, source, parse_yaml(text, source), base_dir, image_dirs)


def load_device(path: PathLike) -> DeviceFile:
    """The device file at ``path`` (or the shipped device of that name, :mod:`tpad_rt.shipped`);
    raises ConfigError listing every problem in it."""
    path = device_file(path)
    return _validate_device(path, load_yaml(Path(path), str(path)))


def load_any(path: PathLike) -> TextureFile | DeviceFile:
    """A device file (it has ``format_version``, or format 1's ``resonance_hz``) or a texture file (it has
    ``kind``), by path or shipped name.

    Raises ConfigError listing every problem, or saying that the file is neither.
    """
    path = any_file(path)
    document = load_yaml(Path(path), str(path))
    if _DEVICE_KEYS & set(document.data):
        return _validate_device(path, document)
    if "kind" in document.data:
        return _validate(TextureFile, path, document)
    raise ConfigError(
        breadcrumb(str(path), (), "neither a texture (which has a 'kind' key) nor a device (which has "
                   "'format_version')")
    )


#: Keys that only device files have: format 2's version, format 1's carrier.
_DEVICE_KEYS = {"format_version", "resonance_hz"}


def device_format_problem(data: dict[str, Any], path: PathLike) -> str | None:
    """Why the device document at ``path`` of another format cannot be read, saying what to do; None for
    format 2.

    Format 1 (no ``format_version``) is what tpad-rt wrote before the one-gamma circuit model.
    """
    version = data.get("format_version")
    if version is None and "kind" in data and "circuit" not in data:
        return "a texture file (it has 'kind'), not a device file (which has format_version and a circuit)"
    if version is None and "resonance_hz" in data:
        return (f"a device file of format 1 (it has no format_version), which tpad-rt no longer reads: its "
                f"amplitude table and circuit are two models that disagree. Convert it to format "
                f"{DEVICE_FORMAT_VERSION}, one circuit with one transduction factor: "
                f"tpad-rt calibrate convert {printable(str(path))} --out NEW.yaml (docs/formats.md \"Format versions\")")
    if isinstance(version, int) and not isinstance(version, bool) and version > DEVICE_FORMAT_VERSION:
        return (f"format_version {version} is newer than this tpad-rt reads ({DEVICE_FORMAT_VERSION}): "
                "upgrade tpad-rt")
    return None


def _validate_device(path: PathLike, document: YamlDocument) -> DeviceFile:
    """``document`` validated as a format-2 device file; ConfigError saying how to convert another format."""
    problem = device_format_problem(document.data, path)
    if problem is not None:
        raise ConfigError(breadcrumb(str(path), (), problem))
    return validate_device(path, document)


def validate_device(path: PathLike, document: YamlDocument) -> DeviceFile:
    """``document.data`` validated as a format 2 device file, whatever its ``format_version`` says; ConfigError
    with one breadcrumb per problem, naming ``path`` and the lines of ``document.root`` (a converted file's
    values keep their original lines)."""
    device: DeviceFile = _validate(DeviceFile, path, document)
    return device


def check_file(path: PathLike) -> list[str]:
    """Every breadcrumb error of the texture or device file at ``path``; empty if it is fine."""
    try:
        load_any(path)
    except ConfigError as err:
        return err.errors
    return []


def _validate(root: Any, path: PathLike, document: YamlDocument, base_dir: Path | None = None,
              image_dirs: list[Path] | None = None) -> Any:
    """``document`` validated as ``root`` (relative image paths from ``base_dir``, default the file's folder;
    images only within ``image_dirs`` when given); raises ConfigError with one line per problem (the first
    MAX_LISTED_ERRORS, then how many more)."""
    try:
        context: dict[str, Any] = {BASE_DIR: Path(path).parent if base_dir is None else base_dir, IMAGE_PIXELS: [0]}
        if image_dirs is not None:
            context[IMAGE_DIRS] = image_dirs
        return _ADAPTERS[root].validate_python(document.data, context=context)
    except ValidationError as err:
        lines = []
        for error in err.errors(include_url=False)[:MAX_LISTED_ERRORS]:
            loc, message = explain(error, root)
            lines.append(breadcrumb(str(path), loc, message, document.line_at(loc)))
        raise ConfigError(listed(lines, str(path), err.error_count())) from None
