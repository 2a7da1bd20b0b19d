"""Safe YAML loading: limits, tags, duplicate keys, line numbers."""

from __future__ import annotations

from pathlib import Path

import pytest

from tpad_rt.config.yaml_io import MAX_DEPTH, YamlDocument, load_yaml
from tpad_rt.errors import ConfigError


def _load(tmp_path: Path, text: str) -> YamlDocument:
    path = tmp_path / "f.yaml"
    path.write_text(text)
    return load_yaml(path, "f.yaml")


def _errors(tmp_path: Path, text: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        _load(tmp_path, text)
    return caught.value.errors


def test_plain_data_and_line_numbers(tmp_path: Path) -> None:
    document = _load(tmp_path, "a: 1\nb:\n  - x\n  - {c: 2.5, d: [true, null]}\n")
    assert document.data == {"a": 1, "b": ["x", {"c": 2.5, "d": [True, None]}]}
    assert document.line_at(("a",)) == 1
    assert document.line_at(("b", 1, "d", 0)) == 4
    assert document.line_at(("b", 0)) == 3


def test_line_of_a_missing_key_falls_back_to_its_parent(tmp_path: Path) -> None:
    document = _load(tmp_path, "a: 1\nb:\n  c: 2\n")
    assert document.line_at(("b", "missing")) == 2
    assert document.line_at(("b", "c", "deeper")) == 3
    assert document.line_at(()) == 1


def test_aliases_and_merge_keys_are_plain_yaml(tmp_path: Path) -> None:
    document = _load(tmp_path, "base: &b {low: 0.5, high: 1}\nf:\n  <<: *b\n  high: 0.9\ng: *b\n")
    assert document.data["f"] == {"low": 0.5, "high": 0.9}
    assert document.data["g"] == {"low": 0.5, "high": 1}
    assert document.line_at(("f", "low")) == 1
    assert document.line_at(("f", "high")) == 4


def test_every_duplicate_key_is_reported(tmp_path: Path) -> None:
    errors = _errors(tmp_path, "a: 1\nb: {c: 1, 'c': 2}\na: 3\nlist:\n  - {x: 1, x: 1}\n")
    assert errors == [
        "f.yaml: b.c: duplicate key (first given on line 2) (line 2)",
        "f.yaml: a: duplicate key (first given on line 1) (line 3)",
        "f.yaml: list[0].x: duplicate key (first given on line 5) (line 5)",
    ]


@pytest.mark.parametrize(
    ("value", "tag"),
    [
        ("!!python/object:os.system x", "!!python/object:os.system"),
        ("!!python/name:os.system ''", "!!python/name:os.system"),
        ("!custom 3", "!custom"),
    ],
)
def test_tags_other_than_plain_data_are_refused(tmp_path: Path, value: str, tag: str) -> None:
    assert _errors(tmp_path, f"ok: 1\nbad: {value}\n") == [
        f"f.yaml: bad: tag '{tag}' is not allowed: files hold plain data only (safe YAML) (line 2)"
    ]


def test_depth_at_the_limit_is_fine_and_one_more_is_not(tmp_path: Path) -> None:
    inner = MAX_DEPTH - 1
    assert _load(tmp_path, "a: " + "[" * inner + "]" * inner + "\n").data["a"] is not None
    more = inner + 1
    errors = _errors(tmp_path, "a: " + "[" * more + "]" * more + "\n")
    assert errors == ["f.yaml: nested deeper than 32 levels (line 1)"]


def test_depth_counts_expanded_aliases(tmp_path: Path) -> None:
    deep = "[" * 20 + "]" * 20
    errors = _errors(tmp_path, f"a: &deep {deep}\nb: [[[[[[[[[[[[*deep]]]]]]]]]]]]\n")
    assert errors == ["f.yaml: nested deeper than 32 levels once this alias is expanded (line 2)"]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("a: 2024-13-01\n", "invalid YAML: bad value: month must be in 1..12 (line 1)"),
        ("a: !!int x\n", "invalid YAML: bad value: invalid literal for int() with base 10: 'x' (line 1)"),
        ("a: *nowhere\n", "invalid YAML: found undefined alias 'nowhere' (line 1)"),
        (
            "a: 1\n---\nb: 2\n",
            "invalid YAML: expected a single document in the stream: but found another document (line 2)",
        ),
        (
            "a: [1, 2\n",
            "invalid YAML: while parsing a flow sequence: expected ',' or ']', but got '<stream end>' (line 2)",
        ),
        ("plain text\n", "top level must be a mapping of keys to values, got the single value 'plain text'"),
        ("!!set {a, b}\n", "top level must be a mapping of keys to values, got a !!set collection"),
    ],
)
def test_bad_yaml_is_one_breadcrumb(tmp_path: Path, text: str, message: str) -> None:
    assert _errors(tmp_path, text) == [f"f.yaml: {message}"]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (b"a: \xff\n", "cannot decode as utf-8: byte #xff at offset 3 (invalid start byte)"),
        (b"a: \x01\n", "character #x0001 is not allowed"),
    ],
)
def test_bytes_that_are_not_yaml_text(tmp_path: Path, text: bytes, message: str) -> None:
    path = tmp_path / "f.yaml"
    path.write_bytes(text)
    with pytest.raises(ConfigError) as caught:
        load_yaml(path, "f.yaml")
    assert caught.value.errors == [f"f.yaml: invalid YAML: {message}"]
