"""Texture ranges (docs/formats.md "Ranges, and why"): each bound accepts its limit and refuses just past it."""

from __future__ import annotations

import copy
import math
import re
from pathlib import Path
from typing import Any

import pytest
import yaml

from tpad_rt.config import check_file
from tpad_rt.texture import load_compiled

_FRICTION = {"low": 0.5, "high": 1.0}
BASES: dict[str, dict[str, Any]] = {
    "grating": {"description": "d", "kind": "grating", "period_mm": 2.5, "friction": _FRICTION},
    "temporal": {"description": "d", "kind": "temporal", "frequency_hz": 30.0, "friction": _FRICTION},
    "bitmap": {"description": "d", "kind": "bitmap", "image": str(Path(__file__).parent / "good_files" / "checker.png"),
               "size_mm": [10.0, 10.0], "origin_mm": [0.0, 0.0], "friction": _FRICTION},
    "bump": {"description": "d", "kind": "gradient", "friction": {"base": 0.6, "low": 0.2, "high": 1.0},
             "height": {"shape": "bump", "center_mm": [65.0, 30.0], "radius_mm": 10.0, "height_mm": 1.0}},
    "ridge": {"description": "d", "kind": "gradient", "friction": {"base": 0.6, "low": 0.2, "high": 1.0},
              "height": {"shape": "ridge", "center_mm": [65.0, 30.0], "width_mm": 5.0, "height_mm": 1.0}},
    "sine": {"description": "d", "kind": "gradient", "friction": {"base": 0.6, "low": 0.2, "high": 1.0},
             "height": {"shape": "sine", "period_mm": 5.0, "height_mm": 1.0}},
    "centres": {"description": "d", "kind": "bumps", "centers_mm": [[10.0, 10.0]], "radius_mm": 1.0,
                "friction": {"inside": 0.5, "outside": 1.0}},
    "grid": {"description": "d", "kind": "bumps", "grid": {"spacing_mm": [5.0, 5.0], "offset_mm": [0.0, 0.0]},
             "radius_mm": 1.0, "friction": {"inside": 0.5, "outside": 1.0}},
    "edges": {"description": "d", "kind": "edges", "friction": {"edge": 0.5, "background": 1.0},
              "shapes": [{"rect": {"x_mm": 10.0, "y_mm": 10.0, "w_mm": 20.0, "h_mm": 10.0}},
                         {"circle": {"center_mm": [65.0, 30.0], "radius_mm": 5.0}},
                         {"line": {"from_mm": [0.0, 0.0], "to_mm": [10.0, 0.0]}}]},
    "layers": {"description": "d", "kind": "layers", "layers": [
        {"kind": "grating", "period_mm": 2.0, "friction": _FRICTION,
         "region": {"rect": {"x_mm": 0.0, "y_mm": 0.0, "w_mm": 50.0, "h_mm": 50.0}}}]},
}

#: (base, path to the key, accepted limit, refused value just past it, the refusal's message)
BOUNDS = [
    ("grating", ("period_mm",), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    ("grating", ("period_mm",), 10000.0, 10000.5, "must be <= 10000, got 10000.5"),
    ("grating", ("angle_deg",), 3600.0, 3600.5, "must be <= 3600, got 3600.5"),
    ("grating", ("angle_deg",), -3600.0, -3600.5, "must be >= -3600, got -3600.5"),
    ("grating", ("phase_deg",), -3600.0, -3600.5, "must be >= -3600, got -3600.5"),
    ("temporal", ("frequency_hz",), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    ("temporal", ("frequency_hz",), 1000.0, 1000.5, "must be <= 1000, got 1000.5"),
    ("bitmap", ("size_mm", 0), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    ("bitmap", ("size_mm", 1), 10000.0, 10000.5, "must be <= 10000, got 10000.5"),
    ("bitmap", ("origin_mm", 1), -10000.0, -10000.5, "must be >= -10000, got -10000.5"),
    ("bump", ("gain",), 1000.0, 1000.5, "must be <= 1000, got 1000.5"),
    ("bump", ("gain",), -1000.0, -1000.5, "must be >= -1000, got -1000.5"),
    ("bump", ("height", "height_mm"), 100.0, 100.5, "must be <= 100, got 100.5"),
    ("bump", ("height", "height_mm"), -100.0, -100.5, "must be >= -100, got -100.5"),
    ("bump", ("height", "radius_mm"), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    ("bump", ("height", "center_mm", 0), 10000.0, 10000.5, "must be <= 10000, got 10000.5"),
    ("ridge", ("height", "width_mm"), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    ("ridge", ("height", "angle_deg"), 3600.0, 3600.5, "must be <= 3600, got 3600.5"),
    ("sine", ("height", "period_mm"), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    ("centres", ("radius_mm",), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    ("centres", ("centers_mm", 0, 1), -10000.0, -10000.5, "must be >= -10000, got -10000.5"),
    ("grid", ("grid", "spacing_mm", 1), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    ("grid", ("grid", "offset_mm", 0), 10000.0, 10000.5, "must be <= 10000, got 10000.5"),
    ("edges", ("width_mm",), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    ("edges", ("shapes", 0, "rect", "w_mm"), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    ("edges", ("shapes", 0, "rect", "x_mm"), 10000.0, 10000.5, "must be <= 10000, got 10000.5"),
    ("edges", ("shapes", 1, "circle", "radius_mm"), 10000.0, 10000.5, "must be <= 10000, got 10000.5"),
    ("edges", ("shapes", 2, "line", "to_mm", 0), 0.01, 0.0099,
     "must equal from_mm (a dot) or lie at least 0.01 mm from it, got 0.0099 mm away"),
    ("layers", ("layers", 0, "region", "rect", "h_mm"), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
]


def _with(base: str, path: tuple[str | int, ...], value: float) -> dict[str, Any]:
    tree = copy.deepcopy(BASES[base])
    node = tree
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return tree


def _location(path: tuple[str | int, ...]) -> str:
    """The breadcrumb of a key path; an edges line's rule is reported at its ``to_mm``."""
    if "line" in path:
        path = path[: path.index("to_mm") + 1]
    return "".join(f"[{key}]" if isinstance(key, int) else f".{key}" for key in path).lstrip(".")


def _write(tmp_path: Path, tree: dict[str, Any]) -> Path:
    path = tmp_path / "texture.yaml"
    path.write_text(yaml.safe_dump(tree))
    return path


@pytest.mark.parametrize(("base", "path", "inside", "outside", "message"), BOUNDS,
                         ids=[f"{case[0]}-{'.'.join(map(str, case[1]))}-{case[2]:g}" for case in BOUNDS])
def test_the_limit_is_accepted_and_just_past_it_refused(
    tmp_path: Path, base: str, path: tuple[str | int, ...], inside: float, outside: float, message: str
) -> None:
    accepted = _write(tmp_path, _with(base, path, inside))
    assert check_file(accepted) == []
    assert load_compiled(accepted).prog.shape[0] >= 1
    refused = _write(tmp_path, _with(base, path, outside))
    [error] = check_file(refused)
    assert re.fullmatch(re.escape(f"{refused}: {_location(path)}: {message}") + r" \(line \d+\)", error), error


def test_a_line_may_be_a_dot(tmp_path: Path) -> None:
    dot = _with("edges", ("shapes", 2, "line", "to_mm"), [0.0, 0.0])
    assert check_file(_write(tmp_path, dot)) == []


@pytest.mark.parametrize("magnitude", [1e300, 1.7976931348623157e308])
def test_huge_values_past_a_bound_are_refused(tmp_path: Path, magnitude: float) -> None:
    for base, path, inside, outside, _ in BOUNDS:
        errors = check_file(_write(tmp_path, _with(base, path, math.copysign(magnitude, outside - inside))))
        assert len(errors) == 1 and "must" in errors[0], (base, path, errors)


@pytest.mark.parametrize("tiny", [5e-324, 1e-300, -5e-324])
def test_vanishing_lengths_are_refused(tmp_path: Path, tiny: float) -> None:
    for base, path, inside, outside, _ in BOUNDS:
        if inside > 0.0 and outside < inside:  # a length's lower bound
            errors = check_file(_write(tmp_path, _with(base, path, tiny)))
            assert len(errors) == 1 and "must" in errors[0], (base, path, errors)
