"""Loading texture and device files into validated models, or into breadcrumb errors."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from pydantic import TypeAdapter, ValidationError

from tpad_rt.config.breadcrumb import breadcrumb
from tpad_rt.config.device_schema import DeviceFile
from tpad_rt.config.messages import explain
from tpad_rt.config.texture_schema import BASE_DIR, IMAGE_PIXELS, TextureFile
from tpad_rt.config.yaml_io import YamlDocument, load_yaml
from tpad_rt.errors import ConfigError
from tpad_rt.shipped import any_file, device_file, texture_file

PathLike = str | os.PathLike[str]

_ADAPTERS: dict[Any, TypeAdapter[Any]] = {TextureFile: TypeAdapter(TextureFile), DeviceFile: TypeAdapter(DeviceFile)}


def load_texture(path: PathLike) -> TextureFile:
    """The texture file at ``path`` (or the shipped texture of that name, :mod:`tpad_rt.shipped`);
    raises ConfigError listing every problem in it."""
    path = texture_file(path)
    return _validate(TextureFile, path, load_yaml(Path(path), str(path)))


def load_device(path: PathLike) -> DeviceFile:
    """The device file at ``path`` (or the shipped device of that name, :mod:`tpad_rt.shipped`);
    raises ConfigError listing every problem in it."""
    path = device_file(path)
    return _validate(DeviceFile, path, load_yaml(Path(path), str(path)))


def load_any(path: PathLike) -> TextureFile | DeviceFile:
    """A device file (it has ``resonance_hz``) or a texture file (it has ``kind``), by path or shipped name.

    Raises ConfigError listing every problem, or saying that the file is neither.
    """
    path = any_file(path)
    document = load_yaml(Path(path), str(path))
    if "resonance_hz" in document.data:
        return _validate(DeviceFile, path, document)
    if "kind" in document.data:
        return _validate(TextureFile, path, document)
    raise ConfigError(
        breadcrumb(str(path), (), "neither a texture (which has a 'kind' key) nor a device (which has 'resonance_hz')")
    )


def check_file(path: PathLike) -> list[str]:
    """Every breadcrumb error of the texture or device file at ``path``; empty if it is fine."""
    try:
        load_any(path)
    except ConfigError as err:
        return err.errors
    return []


def _validate(root: Any, path: PathLike, document: YamlDocument) -> Any:
    """``document`` validated as ``root``; raises ConfigError with one line per problem."""
    try:
        context = {BASE_DIR: Path(path).parent, IMAGE_PIXELS: [0]}
        return _ADAPTERS[root].validate_python(document.data, context=context)
    except ValidationError as err:
        lines = []
        for error in err.errors(include_url=False):
            loc, message = explain(error, root)
            lines.append(breadcrumb(str(path), loc, message, document.line_at(loc)))
        raise ConfigError(lines) from None
