"""JSON Schemas of the file formats, for editors that validate YAML as you type."""

from __future__ import annotations

from typing import Any, Literal

SchemaKind = Literal["texture", "device"]
#: The kinds, for ``tpad-rt schema``'s parser: this module loads pydantic and the models only in schema_json.
SCHEMA_KINDS: tuple[SchemaKind, ...] = ("texture", "device")


def schema_json(kind: SchemaKind) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of texture or device files; raises ValueError for another kind."""
    from pydantic import TypeAdapter

    from tpad_rt.config.device_schema import DeviceFile
    from tpad_rt.config.texture_schema import TextureFile

    roots: dict[str, Any] = {"texture": TextureFile, "device": DeviceFile}
    if kind not in roots:
        raise ValueError(f"kind must be one of {', '.join(SCHEMA_KINDS)}, got {kind!r}")
    schema = TypeAdapter(roots[kind]).json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema, "title": f"tpad-rt {kind} file"}
