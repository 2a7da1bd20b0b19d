"""Property tests: random valid textures of every kind (layers nested, with regions) at random points.

For every one: it compiles, the kernel equals the reference (up to the rounding of
a discontinuity, see ``assert_kernel_matches_reference``) and the friction is in
(0, 1]. Sizes are kept where a 1e-9 comparison is meaningful (no sub-millimetre
periods at 250 mm from the origin, at most 5 pixels per mm).
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Any

import numba
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from test_texture_eval import assert_kernel_matches_reference, texture_model

from tpad_rt.config.fields import MIN_LENGTH_MM
from tpad_rt.texture import compile_texture

WAVEFORMS = ("sine", "square", "triangle", "sawtooth")
LEAF_KINDS = ("grating", "temporal", "bitmap", "gradient", "bumps", "edges")
MAX_DEPTH = 4


def _floats(low: float, high: float) -> st.SearchStrategy[float]:
    return st.floats(low, high, allow_nan=False, allow_infinity=False)


_LEVEL = _floats(0.001, 1.0)
_LENGTH_MM = _floats(0.5, 60.0)
_ANGLE_DEG = _floats(-720.0, 720.0)
_POINT_MM = st.lists(_floats(-100.0, 200.0), min_size=2, max_size=2)
_SIZE_MM = st.lists(_LENGTH_MM, min_size=2, max_size=2)


def _sorted_levels(n: int) -> st.SearchStrategy[list[float]]:
    return st.lists(_LEVEL, min_size=n, max_size=n).map(sorted)


_FRICTION_RANGE = _sorted_levels(2).map(lambda v: {"low": v[0], "high": v[1]})


@st.composite
def _image(draw: st.DrawFn) -> dict[str, Any]:
    """An image map: pixels as an array (saved to a file by ``_materialise``), at most 5 px per mm."""
    pixels = draw(arrays(np.float64, st.tuples(st.integers(1, 6), st.integers(1, 6)), elements=_floats(0.0, 1.0)))
    rows, cols = pixels.shape
    size = [draw(_floats(cols / 5, 80.0)), draw(_floats(rows / 5, 80.0))]
    wrap = draw(st.sampled_from(["tile", "clamp"]))
    return {"image": pixels, "size_mm": size, "origin_mm": draw(_POINT_MM), "wrap": wrap}


@st.composite
def _periodic(draw: st.DrawFn) -> dict[str, Any]:
    spec = {"waveform": draw(st.sampled_from(WAVEFORMS)), "friction": draw(_FRICTION_RANGE)}
    if spec["waveform"] in ("square", "triangle") and draw(st.booleans()):
        spec["duty"] = draw(_floats(0.01, 0.99))
    return spec


@st.composite
def _grating(draw: st.DrawFn) -> dict[str, Any]:
    return {"kind": "grating", **draw(_periodic()), "period_mm": draw(_LENGTH_MM),
            "angle_deg": draw(_ANGLE_DEG), "phase_deg": draw(_ANGLE_DEG)}


@st.composite
def _temporal(draw: st.DrawFn) -> dict[str, Any]:
    return {"kind": "temporal", **draw(_periodic()), "frequency_hz": draw(_floats(0.01, 1000.0))}


@st.composite
def _bitmap(draw: st.DrawFn) -> dict[str, Any]:
    return {"kind": "bitmap", **draw(_image()), "invert": draw(st.booleans()), "friction": draw(_FRICTION_RANGE)}


@st.composite
def _height(draw: st.DrawFn) -> dict[str, Any]:
    shape = draw(st.sampled_from(["bump", "ridge", "sine", "image"]))
    height = {"shape": shape, "height_mm": draw(_floats(-5.0, 5.0))}
    if shape == "bump":
        return {**height, "center_mm": draw(_POINT_MM), "radius_mm": draw(_LENGTH_MM)}
    if shape == "ridge":
        return {**height, "center_mm": draw(_POINT_MM), "angle_deg": draw(_ANGLE_DEG), "width_mm": draw(_LENGTH_MM)}
    if shape == "sine":
        return {**height, "period_mm": draw(_LENGTH_MM), "angle_deg": draw(_ANGLE_DEG)}
    return {**height, **draw(_image())}


@st.composite
def _gradient(draw: st.DrawFn) -> dict[str, Any]:
    low, base, high = draw(_sorted_levels(3))
    return {"kind": "gradient", "height": draw(_height()), "gain": draw(_floats(-10.0, 10.0)),
            "friction": {"base": base, "low": low, "high": high}}


@st.composite
def _bumps(draw: st.DrawFn) -> dict[str, Any]:
    profile = draw(st.sampled_from(["cosine", "gaussian", "disk"]))
    spec = {"kind": "bumps", "radius_mm": draw(_LENGTH_MM), "profile": profile,
            "friction": {"inside": draw(_LEVEL), "outside": draw(_LEVEL)}}
    if draw(st.booleans()):
        return {**spec, "centers_mm": draw(st.lists(_POINT_MM, min_size=1, max_size=10))}
    return {**spec, "grid": {"spacing_mm": draw(_SIZE_MM), "offset_mm": draw(_POINT_MM)}}


@st.composite
def _shape(draw: st.DrawFn, outlines: bool) -> dict[str, Any]:
    """A rect or circle, or for an outline also a line (possibly of zero length)."""
    name = draw(st.sampled_from(["rect", "circle", "line"] if outlines else ["rect", "circle"]))
    if name == "rect":
        (x, y), (w, h) = draw(_POINT_MM), draw(_SIZE_MM)
        return {"rect": {"x_mm": x, "y_mm": y, "w_mm": w, "h_mm": h}}
    if name == "circle":
        return {"circle": {"center_mm": draw(_POINT_MM), "radius_mm": draw(_LENGTH_MM)}}
    start = draw(_POINT_MM)
    apart = _POINT_MM.filter(lambda end: math.dist(start, end) >= MIN_LENGTH_MM)  # shorter lines are refused
    return {"line": {"from_mm": start, "to_mm": draw(st.one_of(st.just(start), apart))}}


@st.composite
def _edges(draw: st.DrawFn) -> dict[str, Any]:
    return {"kind": "edges", "shapes": draw(st.lists(_shape(outlines=True), min_size=1, max_size=5)),
            "width_mm": draw(_floats(0.1, 10.0)), "profile": draw(st.sampled_from(["step", "cosine"])),
            "friction": {"edge": draw(_LEVEL), "background": draw(_LEVEL)}}


_LEAVES = {"grating": _grating, "temporal": _temporal, "bitmap": _bitmap, "gradient": _gradient,
           "bumps": _bumps, "edges": _edges}


@st.composite
def _layers(draw: st.DrawFn, depth: int = 1) -> dict[str, Any]:
    """A layers texture at nesting ``depth`` (1: the file's own), each layer with optional op and region."""
    kinds = [*LEAF_KINDS, "layers"] if depth < MAX_DEPTH else list(LEAF_KINDS)
    layers = []
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(kinds))
        layer = draw(_layers(depth + 1) if kind == "layers" else _LEAVES[kind]())
        if draw(st.booleans()):
            layer["op"] = draw(st.sampled_from(["multiply", "min", "max", "add"]))
        if draw(st.booleans()):
            layer["region"] = draw(_shape(outlines=False))
        layers.append(layer)
    return {"kind": "layers", "layers": layers}


TEXTURES = {**_LEAVES, "layers": _layers}


@st.composite
def _inputs(draw: st.DrawFn, n: int = 16) -> tuple[np.ndarray, ...]:
    """``n`` points (mm), unit directions or still, and times (s)."""
    x = draw(arrays(np.float64, n, elements=_floats(-150.0, 250.0)))
    y = draw(arrays(np.float64, n, elements=_floats(-150.0, 250.0)))
    angle = draw(arrays(np.float64, n, elements=_floats(0.0, 2 * np.pi)))
    moving = draw(arrays(np.bool_, n))
    t = draw(arrays(np.float64, n, elements=_floats(0.0, 50.0)))
    return x, y, np.where(moving, np.cos(angle), 0.0), np.where(moving, np.sin(angle), 0.0), t


def _materialise(spec: Any, folder: Path) -> Any:
    """``spec`` with every pixel array saved as ``.npy`` in ``folder`` and replaced by its file name."""
    if isinstance(spec, np.ndarray):
        name = hashlib.sha1(repr(spec.shape).encode() + spec.tobytes()).hexdigest() + ".npy"
        np.save(folder / name, spec)
        return name
    if isinstance(spec, dict):
        return {key: _materialise(value, folder) for key, value in spec.items()}
    if isinstance(spec, list):
        return [_materialise(value, folder) for value in spec]
    return spec


def _expected_stack_depth(spec: dict[str, Any]) -> int:
    """A leaf needs one slot; a layers texture one for its result plus what its deepest layer needs."""
    if spec["kind"] != "layers":
        return 1
    return 1 + max(_expected_stack_depth(layer) for layer in spec["layers"])


@pytest.fixture(scope="module")
def image_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("texture_images")


#: Random textures per kind: fewer under NUMBA_DISABLE_JIT (the coverage run: the kernel runs as Python, and
#: coverage needs its lines reached, not the jitted run's breadth).
EXAMPLES = 150 if not numba.config.DISABLE_JIT else 40


@pytest.mark.parametrize("kind", list(TEXTURES))
@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(data=st.data())
def test_random_texture_kernel_matches_reference(kind: str, image_dir: Path, data: st.DataObject) -> None:
    spec = _materialise({"description": "random", **data.draw(TEXTURES[kind](), label="texture")}, image_dir)
    model = texture_model(spec, image_dir)
    assert compile_texture(model).stack_depth == _expected_stack_depth(spec)
    values = assert_kernel_matches_reference(model, *data.draw(_inputs(), label="inputs"))
    assert np.all((values > 0.0) & (values <= 1.0))
