"""Texture and device files: safe YAML loading, validation, breadcrumb errors, JSON Schema.

API map
-------
load_texture(path, image_dirs=None) -> TextureFile
    one of Grating, Bitmap, Gradient, Bumps, Edges, Temporal, Layers (images only from
    ``image_dirs`` when given)
parse_texture(text, source, base_dir, image_dirs) -> TextureFile
    a texture file's bytes (``tpad-rt serve``'s inline textures)
load_device(path) -> DeviceFile
load_any(path) -> TextureFile | DeviceFile
    a device file has ``format_version`` (format 1: ``resonance_hz``), a texture file has ``kind``
check_file(path) -> list[str]
    every breadcrumb error of a file (empty if it is fine)
schema_json("texture" | "device") -> dict
    JSON Schema of a format

Loading raises :class:`tpad_rt.errors.ConfigError`, one breadcrumb line per
problem: ``textures/x.yaml: layers[1].period_mm: must be >= 0.01, got -2 (line 9)``.
The models are frozen pydantic models; image-based textures have
``load_image_array()``. docs/formats.md is the contract.

The names above are imported on first use: importing one of this package's modules
that needs no model (``yaml_io``, ``breadcrumb``, ``device_ranges``) does not load pydantic,
and a command that reads no file starts without it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tpad_rt.config.device_schema import DeviceFile
    from tpad_rt.config.json_schema import schema_json
    from tpad_rt.config.loader import check_file, load_any, load_device, load_texture, parse_texture
    from tpad_rt.config.texture_schema import Bitmap, Bumps, Edges, Gradient, Grating, Layers, Temporal, TextureFile

#: Each exported name -> the module of this package that defines it.
_HOMES = {
    "DeviceFile": "device_schema",
    "schema_json": "json_schema",
    **dict.fromkeys(("check_file", "load_any", "load_device", "load_texture", "parse_texture"), "loader"),
    **dict.fromkeys(("Bitmap", "Bumps", "Edges", "Gradient", "Grating", "Layers", "Temporal", "TextureFile"),
                    "texture_schema"),
}

__all__ = [
    "Bitmap",
    "Bumps",
    "DeviceFile",
    "Edges",
    "Gradient",
    "Grating",
    "Layers",
    "Temporal",
    "TextureFile",
    "check_file",
    "load_any",
    "load_device",
    "load_texture",
    "parse_texture",
    "schema_json",
]


def __getattr__(name: str) -> Any:
    """An exported name, imported from its module on first use; AttributeError for another name."""
    if name not in _HOMES:
        raise AttributeError(f"module 'tpad_rt.config' has no attribute '{name}'")
    return getattr(importlib.import_module(f"tpad_rt.config.{_HOMES[name]}"), name)
