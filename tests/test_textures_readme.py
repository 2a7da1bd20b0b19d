"""textures/README.md tells the truth: one row per shipped texture, its kind, and the range of
relative friction it asks for, as its file gives it."""

from __future__ import annotations

import re

import numpy as np
import pytest

from tpad_rt import shipped
from tpad_rt.texture import load_compiled

README = shipped.TEXTURES_DIR / "README.md"
_ROW = re.compile(r"^\| \[(?P<file>[\w.]+)\]\([\w.]+\) \| (?P<kind>\w+) \| (?P<range>[\d.]+-[\d.]+) \| .+ \|$")
#: Directions of motion (gradients depend on them).
_DIRECTIONS = ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))


def friction_range(name: str) -> str:
    """``low-high`` (2 decimals) of the friction the shipped texture ``name`` asks for: over a 0.05 x 0.25 mm
    grid of the 130 x 60 mm plate in four directions of motion at one time, and over a 0.25 x 2 mm grid at 101
    times across 1 s (temporal layers)."""
    texture = load_compiled(name)
    fine_x, fine_y = np.meshgrid(np.arange(0.0, 130.0001, 0.05), np.arange(0.0, 60.0001, 0.25))
    values = [texture.evaluate(fine_x, fine_y, ux, uy, 0.0013) for ux, uy in _DIRECTIONS]
    coarse_x, coarse_y = np.meshgrid(np.arange(0.0, 130.0001, 0.25), np.arange(0.0, 60.0001, 2.0))
    times_s = np.linspace(0.0, 1.0, 101)[:, None, None] + 0.0013
    values.append(texture.evaluate(coarse_x, coarse_y, 1.0, 0.0, times_s))
    low = min(float(v.min()) for v in values)
    high = max(float(v.max()) for v in values)
    return f"{low:.2f}-{high:.2f}"


def _rows() -> dict[str, re.Match[str]]:
    rows = {}
    for line in README.read_text().splitlines():
        if (match := _ROW.match(line)) is not None:
            rows[match["file"]] = match
    return rows


def test_every_shipped_texture_has_one_row() -> None:
    assert sorted(_rows()) == sorted(f"{name}.yaml" for name in shipped.texture_names())


@pytest.mark.parametrize("name", shipped.texture_names())
def test_the_row_gives_the_files_kind_and_friction_range(name: str) -> None:
    row = _rows()[f"{name}.yaml"]
    texture = load_compiled(name)
    assert row["kind"] == texture.kind
    assert row["range"] == friction_range(name), f"textures/README.md: {name}: range"
