"""Breadcrumb formatting and the plain-English translation of pydantic errors."""

from __future__ import annotations

from typing import Any

import pytest
from pydantic import TypeAdapter, ValidationError

from tpad_rt.config.breadcrumb import breadcrumb, format_path, show_value
from tpad_rt.config.device_schema import DeviceFile
from tpad_rt.config.locate import locate
from tpad_rt.config.messages import did_you_mean, explain
from tpad_rt.config.texture_schema import Grating, TextureFile


def test_format_path() -> None:
    assert format_path(("layers", 1, "period_mm")) == "layers[1].period_mm"
    assert format_path((0, "a")) == "[0].a"
    assert format_path(("source", "two words")) == "source['two words']"
    assert format_path(()) == ""


def test_breadcrumb() -> None:
    assert breadcrumb("x.yaml", ("a", 0), "bad", 3) == "x.yaml: a[0]: bad (line 3)"
    assert breadcrumb("x.yaml", (), "bad") == "x.yaml: bad"
    assert breadcrumb(None, ("a",), "bad", 1) == "a: bad (line 1)"


@pytest.mark.parametrize(
    ("value", "shown"),
    [
        (-2, "-2"),
        (2.5, "2.5"),
        (float("nan"), "nan"),
        (float("-inf"), "-inf"),
        ("abc", "'abc'"),
        (True, "true"),
        (None, "null"),
        ([1, [2.0, None]], "[1, [2.0, null]]"),
        ({"a": False}, "{'a': false}"),
    ],
)
def test_show_value(value: Any, shown: str) -> None:
    assert show_value(value) == shown


def test_show_value_is_short_even_for_huge_values() -> None:
    shown = show_value(list(range(10**6)))
    assert len(shown) == 60 and shown.endswith("...")


def test_did_you_mean() -> None:
    assert did_you_mean("perod_mm", ["period_mm", "phase_deg"]) == "; did you mean 'period_mm'?"
    assert did_you_mean("colour", ["period_mm", "phase_deg"]) == ""
    assert did_you_mean(3, ["period_mm"]) == ""


def test_locate_drops_union_tags_but_keeps_keys_named_like_tags() -> None:
    loc = ("layers", "layers", 0, "layers", "layers", 0, "grating", "period_mm")
    clean, spots = locate(TextureFile, loc)
    assert clean == ("layers", 0, "layers", 0, "period_mm")
    assert spots[-2].model.__name__ == "GratingLayer"


def test_locate_gives_the_allowed_keys_and_choices() -> None:
    _, spots = locate(TextureFile, ("gradient", "height"))
    assert spots[-1].choices() == ["bump", "ridge", "sine", "image"]
    _, spots = locate(TextureFile, ("grating", "waveform"))
    assert spots[-1].choices() == ["sine", "square", "triangle", "sawtooth"]
    assert "period_mm" in spots[-2].keys()


def _explained(root: Any, data: Any) -> list[tuple[tuple, str]]:
    with pytest.raises(ValidationError) as caught:
        TypeAdapter(root).validate_python(data)
    return [explain(error, root) for error in caught.value.errors()]


def test_type_errors_in_plain_english() -> None:
    grating = {"description": 3, "kind": "grating", "period_mm": True, "friction": []}
    assert _explained(TextureFile, grating) == [
        (("description",), "must be text, got 3"),
        (("period_mm",), "must be a number, got true"),
        (("friction",), "must be a mapping, got []"),
    ]


def test_empty_text_and_empty_list() -> None:
    edges = {"description": "", "kind": "edges", "shapes": [], "friction": {"edge": 0.5, "background": 1}}
    assert _explained(TextureFile, edges) == [
        (("description",), "must not be empty"),
        (("shapes",), "must have at least 1 item, got 0"),
    ]


def test_too_many_layers() -> None:
    layer = {"kind": "temporal", "frequency_hz": 1, "friction": {"low": 0.5, "high": 1}}
    layers = {"description": "d", "kind": "layers", "layers": [layer] * 17}
    assert _explained(TextureFile, layers) == [(("layers",), "must have at most 16 items, got 17")]


def test_a_texture_that_is_not_a_mapping() -> None:
    assert _explained(TextureFile, "grating") == [((), "must be a mapping, got 'grating'")]


def test_bad_dict_keys_and_values() -> None:
    errors = _explained(DeviceFile.model_fields["source"].annotation, {1: "x", "y": 2, "": "z"})
    assert errors == [
        ((1,), "key must be text, got 1"),
        (("y",), "must be text, got 2"),
        (("",), "key must not be empty"),
    ]


def test_rule_errors_are_located_at_their_key() -> None:
    data = {"description": "d", "kind": "grating", "period_mm": 1, "duty": 0.2, "friction": {"low": 0.5, "high": 1}}
    assert _explained(Grating, data) == [(("duty",), "not allowed with waveform 'sine' (only square and triangle)")]
