"""JSON Schemas of the file formats, for editors that validate YAML as you type."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import TypeAdapter

from tpad_rt.config.device_schema import DeviceFile
from tpad_rt.config.texture_schema import TextureFile

SchemaKind = Literal["texture", "device"]
SCHEMA_KINDS: tuple[SchemaKind, ...] = ("texture", "device")

_ROOTS: dict[str, Any] = {"texture": TextureFile, "device": DeviceFile}


def schema_json(kind: SchemaKind) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of texture or device files; raises ValueError for another kind."""
    if kind not in _ROOTS:
        raise ValueError(f"kind must be one of {', '.join(SCHEMA_KINDS)}, got {kind!r}")
    schema = TypeAdapter(_ROOTS[kind]).json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema, "title": f"tpad-rt {kind} file"}
