"""Whatever is in a file, loading it ends in a model or a ConfigError, never another exception."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tpad_rt.config import check_file, load_any
from tpad_rt.errors import ConfigError

GOOD_FILES = Path(__file__).parent / "good_files"
GOOD_DATA = {path.name: yaml.safe_load(path.read_text()) for path in sorted(GOOD_FILES.glob("*.yaml"))}

_SETTINGS = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.sampled_from(["grating", "layers", "sine", "rect", "circle", "kind", "ramp.npy", "checker.png", "x.jpg"]),
)
values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=10) | scalars, inner, max_size=4),
    max_leaves=12,
)
yaml_chars = st.text(alphabet=st.sampled_from(list("ab1.:-[]{}&*!#|>'\"%@`,?<= \n\t\\~")), max_size=60)


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder holding the good files' images, where the fuzzed files are written."""
    path = tmp_path_factory.mktemp("fuzz")
    for image in ("checker.png", "ramp.npy"):
        shutil.copy(GOOD_FILES / image, path / image)
    return path


def _load_ends_cleanly(path: Path) -> None:
    try:
        load_any(path)
    except ConfigError as err:
        assert err.errors and all(line.startswith(f"{path}: ") for line in err.errors)
        assert check_file(path) == err.errors


@_SETTINGS
@given(text=st.text(max_size=200) | yaml_chars)
def test_junk_text(folder: Path, text: str) -> None:
    path = folder / "junk.yaml"
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    _load_ends_cleanly(path)


@_SETTINGS
@given(blob=st.binary(max_size=200))
def test_junk_bytes(folder: Path, blob: bytes) -> None:
    path = folder / "junk.yaml"
    path.write_bytes(blob)
    _load_ends_cleanly(path)


@_SETTINGS
@given(name=st.sampled_from(sorted(GOOD_DATA)), data=st.data())
def test_mutated_good_files(folder: Path, name: str, data: st.DataObject) -> None:
    document = _mutate(GOOD_DATA[name], data)
    path = folder / name
    path.write_text(yaml.safe_dump(document, allow_unicode=True))
    _load_ends_cleanly(path)


@_SETTINGS
@given(name=st.sampled_from(sorted(GOOD_DATA)), cut=st.integers(min_value=0), junk=yaml_chars)
def test_good_files_with_text_spliced_in(folder: Path, name: str, cut: int, junk: str) -> None:
    text = (GOOD_FILES / name).read_text()
    cut %= len(text) + 1
    path = folder / name
    path.write_text(text[:cut] + junk + text[cut:])
    _load_ends_cleanly(path)


def _mutate(value: Any, data: st.DataObject) -> Any:
    """``value`` with one random change somewhere inside: replaced, dropped or added to."""
    children = list(value) if isinstance(value, dict) else range(len(value)) if isinstance(value, list) else []
    if children and data.draw(st.booleans(), label="descend"):
        key = data.draw(st.sampled_from(list(children)), label="key")
        copy = dict(value) if isinstance(value, dict) else list(value)
        action = data.draw(st.sampled_from(["mutate", "drop", "add"]), label="action")
        if action == "mutate":
            copy[key] = _mutate(value[key], data)
        elif action == "drop":
            del copy[key]
        elif isinstance(copy, dict):
            copy[data.draw(st.text(max_size=12), label="new key")] = data.draw(values, label="new value")
        else:
            copy.append(data.draw(values, label="new item"))
        return copy
    return data.draw(values, label="replacement")
