"""The texture kernel against the pure-NumPy reference, and against hand-worked values of docs/formats.md."""

from __future__ import annotations

import itertools
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numba.core.runtime import _nrt_python, rtsys
from pydantic import TypeAdapter
from reference.texture_ref import reference_friction

from tpad_rt.config import TextureFile, load_texture
from tpad_rt.config.texture_schema import BASE_DIR
from tpad_rt.kernel import layout
from tpad_rt.kernel.texture_eval import eval_texture, eval_texture_points, waveform
from tpad_rt.texture import CompiledTexture, compile_texture

REPO = Path(__file__).resolve().parents[1]
GOOD = REPO / "tests" / "good_files"
EXAMPLES = sorted((REPO / "textures").glob("*.yaml"))
GOOD_TEXTURES = sorted(path for path in GOOD.glob("*.yaml") if path.name != "device.yaml")
TOLERANCE = 1e-9
#: Relative steps (of max(1, |value|)) to the neighbours whose value a point on a discontinuity may take.
NUDGES = 10.0 ** -np.arange(6, 16)
#: Every combination of -1, 0, 1 for x, y and t, at every step.
_SIGNS = np.array(list(itertools.product((-1.0, 0.0, 1.0), repeat=3)))
_NEIGHBOURS = (_SIGNS[None] * NUDGES[:, None, None]).reshape(-1, 3)
JIT_DISABLED = os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0")

_TEXTURE = TypeAdapter(TextureFile)


def texture_model(spec: dict[str, Any], base_dir: Path = GOOD) -> Any:
    """A validated texture model from a plain mapping (image paths relative to ``base_dir``)."""
    return _TEXTURE.validate_python(spec, context={BASE_DIR: base_dir})


def kernel_friction(compiled: CompiledTexture, x, y, ux, uy, t) -> np.ndarray:
    """The kernel at every point, through a stack one longer than ``stack_depth`` whose last slot must stay NaN."""
    arrays = [np.ascontiguousarray(a, dtype=np.float64).ravel() for a in np.broadcast_arrays(x, y, ux, uy, t)]
    stack = np.full(compiled.stack_depth + 1, np.nan)
    out = np.empty(arrays[0].size)
    eval_texture_points(compiled.prog, compiled.params, compiled.img, stack, *arrays, out)
    assert np.isnan(stack[-1]), "the kernel used more stack than stack_depth"
    return out


def assert_kernel_matches_reference(model: Any, x, y, ux, uy, t) -> np.ndarray:
    """Kernel == reference to TOLERANCE at every point; returns the kernel values.

    Where they differ, the point must sit on a discontinuity that the two sides round
    differently: the kernel's value must then be the reference's at a neighbour (x, y
    and t each moved by -1, 0 or +1 step, steps from 1e-6 down to 1e-15 relative: small
    enough that a steep but continuous part of the texture barely changes).
    """
    x, y, ux, uy, t = (np.asarray(a, dtype=np.float64).ravel() for a in np.broadcast_arrays(x, y, ux, uy, t))
    kernel = kernel_friction(compile_texture(model), x, y, ux, uy, t)
    reference = reference_friction(model, x, y, ux, uy, t)
    for i in np.flatnonzero(np.abs(kernel - reference) > TOLERANCE):
        x_i, y_i, t_i = (v[i] + _NEIGHBOURS[:, k] * max(1.0, abs(v[i])) for k, v in enumerate((x, y, t)))
        around = reference_friction(model, x_i, y_i, ux[i], uy[i], t_i)
        assert np.min(np.abs(around - kernel[i])) <= TOLERANCE, (
            f"kernel {kernel[i]!r} != reference {reference[i]!r} at x={x[i]!r}, y={y[i]!r}, "
            f"u=({ux[i]!r}, {uy[i]!r}), t={t[i]!r}, nor at any neighbour"
        )
    return kernel


def test_a_point_on_a_discontinuity_may_take_either_side() -> None:
    # The kernel's 49 * (1 / 49) rounds below 1 (top of the sawtooth), the reference's 49 / 49 is 1 (bottom).
    model = texture_model({"description": "t", "kind": "grating", "waveform": "sawtooth", "period_mm": 49.0,
                           "friction": {"low": 0.5, "high": 1.0}})
    kernel = kernel_friction(compile_texture(model), 49.0, 0.0, 0.0, 0.0, 0.0)
    assert kernel - reference_friction(model, 49.0, 0.0, 0.0, 0.0, 0.0) == pytest.approx(0.5)
    assert_kernel_matches_reference(model, 49.0, 0.0, 0.0, 0.0, 0.0)


def _grid_inputs() -> tuple[np.ndarray, ...]:
    """Points over the plate and a margin around it (off any round number), 5 directions, 2 times."""
    x = np.linspace(-10.0, 140.0, 41) + 0.0123
    y = np.linspace(-10.0, 70.0, 23) + 0.0071
    angles = np.radians([0.0, 90.0, 210.0, 315.0])
    ux = np.append(np.cos(angles), 0.0)
    uy = np.append(np.sin(angles), 0.0)
    t = np.array([0.0, 0.4567])
    gx, gy, gd, gt = np.meshgrid(x, y, np.arange(ux.size), t, indexing="ij")
    return gx, gy, ux[gd], uy[gd], gt


@pytest.mark.parametrize("path", EXAMPLES + GOOD_TEXTURES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_shipped_texture_matches_the_reference(path: Path) -> None:
    values = assert_kernel_matches_reference(load_texture(path), *_grid_inputs())
    assert np.all((values > 0.0) & (values <= 1.0))


# --- hand-worked values of the semantics --------------------------------------


def _at(spec: dict[str, Any], x: float, y: float, ux: float = 0.0, uy: float = 0.0, t: float = 0.0) -> float:
    compiled = compile_texture(texture_model({"description": "test", **spec}))
    return float(kernel_friction(compiled, x, y, ux, uy, t)[0])


@pytest.mark.parametrize(
    ("code", "phase", "duty", "expected"),
    [
        (layout.WAVE_SINE, 0.25, 0.5, 1.0),
        (layout.WAVE_SINE, 0.75, 0.5, 0.0),
        (layout.WAVE_SQUARE, 0.29, 0.3, 1.0),
        (layout.WAVE_SQUARE, 0.3, 0.3, 0.0),
        (layout.WAVE_TRIANGLE, 0.2, 0.2, 1.0),
        (layout.WAVE_TRIANGLE, 0.1, 0.2, 0.5),
        (layout.WAVE_TRIANGLE, 0.6, 0.2, 0.5),
        (layout.WAVE_SAWTOOTH, 0.7, 0.5, 0.7),
    ],
)
def test_waveform(code: int, phase: float, duty: float, expected: float) -> None:
    assert waveform(code, phase, duty) == pytest.approx(expected, abs=1e-15)


GRATING = {"kind": "grating", "period_mm": 4.0, "friction": {"low": 0.5, "high": 1.0}}


def test_grating_angle_is_counter_clockwise_on_a_y_down_screen() -> None:
    # At 90 degrees the friction varies along -y (up the screen): the sine's crest is a quarter period up.
    assert _at({**GRATING, "angle_deg": 90}, 0.0, -1.0) == pytest.approx(1.0)
    assert _at({**GRATING, "angle_deg": 90}, 0.0, 1.0) == pytest.approx(0.5)
    assert _at({**GRATING, "angle_deg": 90}, 7.0, -1.0) == pytest.approx(1.0)


def test_grating_phase_shifts_by_a_fraction_of_the_period() -> None:
    assert _at({**GRATING, "phase_deg": 90}, 0.0, 0.0) == pytest.approx(1.0)
    assert _at({**GRATING, "phase_deg": 90}, -1.0, 0.0) == pytest.approx(0.75)


def test_square_grating_is_high_for_duty_of_the_period() -> None:
    spec = {**GRATING, "waveform": "square", "duty": 0.25}
    assert [_at(spec, x, 0.0) for x in (0.5, 1.5, 2.5, 4.5)] == [1.0, 0.5, 0.5, 1.0]


def test_temporal_follows_time_only() -> None:
    spec = {"kind": "temporal", "frequency_hz": 10, "duty": 0.3, "friction": {"low": 0.4, "high": 0.9}}
    assert [_at(spec, 50.0, 20.0, 1.0, 0.0, t) for t in (0.01, 0.05, 0.11)] == pytest.approx([0.9, 0.4, 0.9])


CHECKER = {"kind": "bitmap", "image": "checker.png", "size_mm": [30, 40], "origin_mm": [10, 5],
           "friction": {"low": 0.2, "high": 1.0}}


def test_bitmap_is_the_pixel_value_at_pixel_centres_and_bilinear_between() -> None:
    pixels = texture_model({"description": "t", **CHECKER}).load_image_array()
    rows, cols = pixels.shape
    for row, col in [(0, 0), (rows - 1, cols - 1), (1, 2)]:
        x, y = 10 + (col + 0.5) * 30 / cols, 5 + (row + 0.5) * 40 / rows
        assert _at(CHECKER, x, y) == pytest.approx(0.2 + 0.8 * pixels[row, col])
        assert _at({**CHECKER, "invert": True}, x, y) == pytest.approx(1.0 - 0.8 * pixels[row, col])
    middle = 0.2 + 0.8 * pixels[:2, :2].mean()
    assert _at(CHECKER, 10 + 30 / cols, 5 + 40 / rows) == pytest.approx(middle)


def test_bitmap_tiles_or_clamps_outside_the_image() -> None:
    assert _at(CHECKER, 12.0 + 30, 7.0 - 40) == pytest.approx(_at(CHECKER, 12.0, 7.0))
    clamped = {**CHECKER, "wrap": "clamp"}
    assert _at(clamped, -100.0, -100.0) == pytest.approx(_at(clamped, 10.0, 5.0))


BUMP = {"kind": "gradient", "height": {"shape": "bump", "center_mm": [50, 30], "radius_mm": 10, "height_mm": 1.0},
        "gain": 2.0, "friction": {"base": 0.6, "low": 0.1, "high": 1.0}}


def test_gradient_friction_rises_climbing_and_falls_descending() -> None:
    slope = 0.5 * math.pi / 10  # steepest slope of a raised cosine of height 1, radius 10: at d = R / 2
    assert _at(BUMP, 45.0, 30.0, 1.0, 0.0) == pytest.approx(0.6 + 2 * slope)
    assert _at(BUMP, 45.0, 30.0, -1.0, 0.0) == pytest.approx(0.6 - 2 * slope)
    assert _at(BUMP, 45.0, 30.0, 0.0, 1.0) == pytest.approx(0.6)
    assert _at(BUMP, 45.0, 30.0) == 0.6
    assert _at(BUMP, 65.0, 30.0, 1.0, 0.0) == 0.6


def test_gradient_ridge_runs_along_its_angle() -> None:
    ridge = {**BUMP, "gain": 0.2,
             "height": {"shape": "ridge", "center_mm": [0, 0], "angle_deg": 90, "width_mm": 4, "height_mm": 1.0}}
    # Running along y: crossing it along x climbs at x = -1 (slope pi / 4), moving along it feels nothing.
    assert _at(ridge, -1.0, 17.0, 1.0, 0.0) == pytest.approx(0.6 + 0.2 * math.pi / 4)
    assert _at(ridge, -1.0, 17.0, 0.0, 1.0) == pytest.approx(0.6)


def test_gradient_friction_is_clamped() -> None:
    steep = {**BUMP, "gain": 100.0}
    assert _at(steep, 45.0, 30.0, 1.0, 0.0) == 1.0
    assert _at(steep, 45.0, 30.0, -1.0, 0.0) == 0.1


def test_bumps_nearest_centre_wins_when_grid_bumps_overlap() -> None:
    spec = {"kind": "bumps", "grid": {"spacing_mm": [4, 4]}, "radius_mm": 3, "profile": "cosine",
            "friction": {"inside": 0.3, "outside": 1.0}}
    # (1.5, 0) and (2.5, 0) are 1.5 mm from their nearest centre, 2.5 mm from the other.
    expected = 1.0 - 0.7 * 0.5 * (1 + math.cos(math.pi * 1.5 / 3))
    assert _at(spec, 1.5, 0.0) == pytest.approx(expected)
    assert _at(spec, 2.5, 0.0) == pytest.approx(expected)


def test_gaussian_bumps_end_at_three_sigma() -> None:
    spec = {"kind": "bumps", "centers_mm": [[0, 0]], "radius_mm": 2, "profile": "gaussian",
            "friction": {"inside": 0.2, "outside": 1.0}}
    assert _at(spec, 0.0, 1.0) == pytest.approx(1.0 - 0.8 * math.exp(-0.5))
    assert _at(spec, 2.9, 0.0) == pytest.approx(1.0 - 0.8 * math.exp(-0.5 * 2.9**2))
    assert _at(spec, 3.0, 0.0) == 1.0


def test_edges_band_around_the_nearest_outline() -> None:
    spec = {"kind": "edges", "shapes": [{"rect": {"x_mm": 10, "y_mm": 10, "w_mm": 20, "h_mm": 10}},
                                        {"line": {"from_mm": [0, 40], "to_mm": [10, 40]}}],
            "width_mm": 2.0, "profile": "cosine", "friction": {"edge": 0.4, "background": 1.0}}
    assert _at(spec, 20.0, 10.0) == pytest.approx(0.4)
    assert _at(spec, 20.0, 10.5) == pytest.approx(0.7)
    assert _at(spec, 20.0, 15.0) == 1.0
    assert _at(spec, 11.0, 40.0) == pytest.approx(1.0)  # the band's border: raised cosine at 0
    assert _at({**spec, "profile": "step"}, 20.0, 11.0) == 0.4


def test_layers_combine_inside_their_region_only() -> None:
    spec = {"kind": "layers", "layers": [
        {"kind": "temporal", "frequency_hz": 1, "waveform": "sawtooth", "friction": {"low": 0.4, "high": 0.9},
         "region": {"rect": {"x_mm": 0, "y_mm": 0, "w_mm": 10, "h_mm": 10}}},
        {"kind": "temporal", "frequency_hz": 1, "waveform": "sawtooth", "friction": {"low": 0.8, "high": 0.8},
         "op": "add", "region": {"circle": {"center_mm": [10, 10], "radius_mm": 5}}},
    ]}
    assert _at(spec, 20.0, 20.0) == 1.0  # no region reaches: vibration off
    assert _at(spec, 5.0, 5.0) == pytest.approx(0.4)  # first layer replaces the starting 1
    assert _at(spec, 9.0, 9.0) == pytest.approx(0.4 + 0.8 - 1.0)  # add: the reductions sum
    assert _at(spec, 14.0, 10.0) == pytest.approx(0.8)  # 1 + 0.8 - 1
    deep = {**spec, "layers": [spec["layers"][0], {**spec["layers"][1], "op": "multiply",
                                                  "friction": {"low": 0.001, "high": 0.001}}]}
    assert _at(deep, 9.0, 9.0) == layout.LAYER_FLOOR


#: Corruptions of a compiled texture, each giving an unknown code where the kernel dispatches:
#: (file, (array, index) to overwrite with 99, a point (x, y) (mm) where that code decides).
_UNKNOWN_CODES = {
    "opcode": ("grating.yaml", ("prog", (0, 0)), (5.0, 5.0)),
    "waveform": ("grating.yaml", ("prog", (0, 2)), (5.0, 5.0)),
    "height shape": ("gradient_bump.yaml", ("prog", (0, 2)), (60.0, 30.0)),
    "bumps profile": ("bumps_centers.yaml", ("prog", (0, 2)), (10.5, 10.0)),
    "edges profile": ("edges.yaml", ("prog", (0, 2)), (10.0, 20.0)),
    "edges shape record": ("edges.yaml", ("params", 4), (10.0, 20.0)),
    "image wrap": ("bitmap.yaml", ("params", 6), (20.0, 20.0)),
    "combine op": ("layers.yaml", ("prog", (-1, 2)), None),
    "combine region": ("layers.yaml", ("prog", (-1, 3)), None),
}


@pytest.mark.parametrize("case", _UNKNOWN_CODES)
def test_an_unknown_code_in_a_program_is_nan_not_another_case(case: str) -> None:
    """A corrupt program must reach the render kernel as a texture fault (NaN), never as some other
    layer's value: every dispatch matches its codes explicitly."""
    name, (array, index), point = _UNKNOWN_CODES[case]
    compiled = compile_texture(load_texture(GOOD / name))
    arrays = {"prog": compiled.prog.copy(), "params": compiled.params.copy()}
    if point is None:  # the last combine: somewhere inside its region
        point = _inside_last_region(compiled)
    x = np.array([point[0]])
    y = np.array([point[1]])
    good = kernel_friction(compiled, x, y, 0.0, 0.0, 0.0)
    assert np.isfinite(good).all(), "the point must evaluate before the corruption"
    arrays[array][index] = 99
    corrupt = CompiledTexture(arrays["prog"], arrays["params"], compiled.img, compiled.stack_depth,
                              compiled.kind, compiled.description)
    assert np.isnan(kernel_friction(corrupt, x, y, 0.0, 0.0, 0.0)).all()


def _inside_last_region(compiled: CompiledTexture) -> tuple[float, float]:
    """A plate point inside the region of the program's last combine row (rect or circle: its first corner
    or centre, or (0, 0) for everywhere)."""
    o, region = int(compiled.prog[-1, 1]), int(compiled.prog[-1, 3])
    if region == layout.SHAPE_EVERYWHERE:
        return 0.0, 0.0
    return float(compiled.params[o]), float(compiled.params[o + 1])


def test_a_layer_that_cannot_be_evaluated_is_nan_through_min_and_max() -> None:
    """``min``/``max`` would drop a NaN layer and keep the other: the combine passes it on."""
    for op in ("min", "max", "multiply", "add"):
        spec = {"kind": "layers", "layers": [
            {"kind": "grating", "period_mm": 2.0, "friction": {"low": 0.4, "high": 0.9}},
            {"kind": "temporal", "frequency_hz": 1, "friction": {"low": 0.5, "high": 0.5}, "op": op},
        ]}
        compiled = compile_texture(texture_model({"description": "test", **spec}))
        prog = compiled.prog.copy()
        prog[np.flatnonzero(prog[:, 0] == layout.OP_GRATING)[0], 2] = 99  # the grating's waveform
        corrupt = CompiledTexture(prog, compiled.params, compiled.img, compiled.stack_depth,
                                  compiled.kind, compiled.description)
        assert np.isnan(kernel_friction(corrupt, 1.0, 1.0, 0.0, 0.0, 0.0)).all(), op


# --- real-time rules ------------------------------------------------------------


def _every_kind() -> Any:
    """One layers texture holding every kind, so one call runs every opcode."""
    paths = [p for p in GOOD_TEXTURES if p.name != "layers.yaml"]
    paths += [REPO / "textures" / "gradient_ridge.yaml", REPO / "textures" / "gradient_ridges.yaml"]
    layers = [{**load_texture(p).model_dump(exclude={"description", "finger"}, exclude_defaults=True), "op": "min"}
              for p in paths]
    layers.append({"kind": "layers", "op": "max", "layers": [layers[0]]})
    return texture_model({"description": "all kinds", "kind": "layers", "layers": layers})


@pytest.mark.skipif(JIT_DISABLED, reason="nothing is compiled under NUMBA_DISABLE_JIT")
def test_kernel_allocates_nothing_per_call() -> None:
    compiled = compile_texture(_every_kind())
    assert {row[0] for row in compiled.prog} == set(range(layout.OP_COMBINE + 1))

    def allocations(n: int) -> list[int]:
        rng = np.random.default_rng(1)
        x, y, t = rng.uniform(-10, 140, n), rng.uniform(-10, 70, n), rng.uniform(0, 1, n)
        ux, uy = np.ones(n), np.zeros(n)
        stack, out = np.empty(compiled.stack_depth), np.empty(n)
        before = rtsys.get_allocation_stats()
        eval_texture_points(compiled.prog, compiled.params, compiled.img, stack, x, y, ux, uy, t, out)
        return [after - start for after, start in zip(rtsys.get_allocation_stats(), before)]

    was_enabled = _nrt_python.memsys_stats_enabled()
    _nrt_python.memsys_enable_stats()
    try:
        allocations(1)  # compile
        assert allocations(1) == allocations(20_000)  # only the call's argument boxing allocates
    finally:
        if not was_enabled:
            _nrt_python.memsys_disable_stats()


@pytest.mark.skipif(JIT_DISABLED, reason="nothing is compiled under NUMBA_DISABLE_JIT")
def test_kernels_compile_in_nopython_mode_with_nogil() -> None:
    for kernel in (eval_texture, eval_texture_points, waveform):
        assert kernel.targetoptions["nopython"] and kernel.targetoptions["nogil"]
