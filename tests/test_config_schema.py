"""JSON Schemas of the formats agree with the pydantic models."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from tpad_rt.config import schema_json

GOOD_FILES = Path(__file__).parent / "good_files"
BAD_FILES = Path(__file__).parent / "bad_files"


@pytest.mark.parametrize("kind", ["texture", "device"])
def test_schema_header(kind: str) -> None:
    schema = schema_json(kind)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["title"] == f"tpad-rt {kind} file"
    json.dumps(schema)  # plain JSON


def test_texture_schema_is_a_union_on_kind() -> None:
    schema = schema_json("texture")
    assert schema["discriminator"]["propertyName"] == "kind"
    kinds = {"grating", "bitmap", "gradient", "bumps", "edges", "temporal", "layers"}
    assert set(schema["discriminator"]["mapping"]) == kinds
    assert schema["$defs"]["Grating"]["additionalProperties"] is False


def test_device_schema_names() -> None:
    schema = schema_json("device")
    assert set(schema["required"]) == {
        "format_version", "label", "description", "plate", "actuator", "carrier_hz", "amplifier",
        "circuit", "power_budget_w", "source",
    }  # fmt: skip
    assert set(schema["properties"]) == set(schema["required"]) | {"friction_model", "speed_floor_mm_s", "preemphasis",
                                                                  "mode_shape"}


def test_unknown_kind() -> None:
    with pytest.raises(ValueError, match="texture, device"):
        schema_json("sound")  # type: ignore[arg-type]


def _validator(kind: str):
    jsonschema = pytest.importorskip("jsonschema")
    return jsonschema.Draft202012Validator(schema_json(kind))


@pytest.mark.parametrize("path", sorted(GOOD_FILES.glob("*.yaml")), ids=lambda path: path.stem)
def test_good_files_satisfy_the_schema(path: Path) -> None:
    kind = "device" if path.stem == "device" else "texture"
    _validator(kind).validate(yaml.safe_load(path.read_text()))


@pytest.mark.parametrize(
    "name", ["negative_period", "unknown_key_typo", "unknown_kind_typo", "friction_out_of_range", "layers_top_level_op"]
)
def test_bad_files_fail_the_schema(name: str) -> None:
    data = yaml.safe_load((BAD_FILES / f"{name}.yaml").read_text())
    assert not _validator("texture").is_valid(data)
