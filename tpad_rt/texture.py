"""Texture models compiled to the flat arrays the kernel evaluates (docs/kernel.md "Compiled textures").

API map
-------
compile_texture(model) -> CompiledTexture
    a validated texture model (``tpad_rt.config.load_texture``) as a postfix program
load_compiled(path) -> CompiledTexture
    load, validate and compile a texture file
CompiledTexture
    ``prog`` (int64 ``[N, 4]``), ``params`` (float64), ``img`` (float64), ``stack_depth``,
    ``kind``, ``description``; ``evaluate(x_mm, y_mm, ux, uy, t_s)`` runs the kernel
    over arrays

The parameter records are listed in :mod:`tpad_rt.kernel.texture_eval`. Everything
that does not depend on the point is computed here once: cos/sin of angles,
reciprocals of periods and radii, pixel scales, the bumps' centres sorted by x,
``invert`` applied to the pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import numpy.typing as npt

from tpad_rt.config import load_texture
from tpad_rt.config.shapes import Circle, Outline, Rect, Region
from tpad_rt.config.texture_schema import (
    Bitmap,
    BumpHeight,
    Bumps,
    Edges,
    Gradient,
    Grating,
    ImageHeight,
    Layers,
    RidgeHeight,
    SineHeight,
    Temporal,
    TextureFile,
)
from tpad_rt.errors import ConfigError
from tpad_rt.kernel import layout

_WAVEFORMS = {
    "sine": layout.WAVE_SINE,
    "square": layout.WAVE_SQUARE,
    "triangle": layout.WAVE_TRIANGLE,
    "sawtooth": layout.WAVE_SAWTOOTH,
}
_COMBINE_OPS = {
    "replace": layout.COMBINE_REPLACE,
    "multiply": layout.COMBINE_MULTIPLY,
    "min": layout.COMBINE_MIN,
    "max": layout.COMBINE_MAX,
    "add": layout.COMBINE_ADD,
}
_WRAPS = {"tile": layout.WRAP_TILE, "clamp": layout.WRAP_CLAMP}
_PROFILES = {
    "cosine": layout.PROFILE_COSINE,
    "gaussian": layout.PROFILE_GAUSSIAN,
    "disk": layout.PROFILE_DISK,
    "step": layout.PROFILE_STEP,
}
#: Stack effect of each opcode: COMBINE pops two values and pushes one, the others push one.
_STACK_EFFECT = {layout.OP_COMBINE: -1}


def _read_only_view(array: np.ndarray) -> np.ndarray:
    """A read-only view of ``array`` (which stays writable)."""
    view = array.view()
    view.setflags(write=False)
    return view


@dataclass(frozen=True)
class CompiledTexture:
    """A texture as the kernel evaluates it; arrays C-contiguous, read-only, dtypes exact.

    ``prog`` int64 ``[N, TEX_PROG_COLS]``, ``params`` float64, ``img`` float64 (pixels of
    every image, row major, in [0, 1]); ``stack_depth`` the scratch stack size
    ``eval_texture`` needs; ``kind`` and ``description`` from the file.
    """

    prog: np.ndarray
    params: np.ndarray
    img: np.ndarray
    stack_depth: int
    kind: str
    description: str
    #: Writable arrays behind the read-only ``prog, params, img`` (the same memory), for
    #: :meth:`evaluate`: numba compiles a kernel once per array type, and read-only arrays
    #: are another type than the pipeline's writable ones, so passing these makes
    #: :meth:`evaluate` reuse the texture kernel ``render_block`` compiles (about 4 s of a
    #: first run). The kernel never writes them.
    _kernel_arrays: tuple[np.ndarray, np.ndarray, np.ndarray] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        kernel = (np.array(self.prog, dtype=np.int64, order="C").reshape(-1, layout.TEX_PROG_COLS),
                  np.array(self.params, dtype=np.float64, order="C"),
                  np.array(self.img, dtype=np.float64, order="C"))
        object.__setattr__(self, "_kernel_arrays", kernel)
        for name, array in zip(("prog", "params", "img"), kernel):
            object.__setattr__(self, name, _read_only_view(array))

    def evaluate(
        self,
        x_mm: npt.ArrayLike,
        y_mm: npt.ArrayLike,
        ux: npt.ArrayLike = 0.0,
        uy: npt.ArrayLike = 0.0,
        t_s: npt.ArrayLike = 0.0,
    ) -> np.ndarray:
        """Relative friction (unclamped) at plate points (mm), broadcasting the arguments.

        ``(ux, uy)`` is the unit direction of finger motion ((0, 0): still), ``t_s`` the
        time (s) since the texture was set. Returns float64 of the broadcast shape.
        """
        arrays = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (x_mm, y_mm, ux, uy, t_s)))
        # copies: a size-1 broadcast view passes as contiguous, and numba reading its flags warns (FutureWarning)
        flat = [np.array(a, dtype=np.float64).ravel() for a in arrays]
        out = np.empty(flat[0].size, dtype=np.float64)
        stack = np.empty(self.stack_depth, dtype=np.float64)
        x, y, ux_, uy_, t = flat
        from tpad_rt.kernel.texture_eval import eval_texture_points  # numba: imported when a texture is evaluated

        prog, params, img = self._kernel_arrays
        eval_texture_points(prog, params, img, stack, x, y, ux_, uy_, t, out)
        return out.reshape(arrays[0].shape)


class _Builder:
    """Accumulates program rows, parameters and image pixels."""

    def __init__(self) -> None:
        self.rows: list[tuple[int, int, int, int]] = []
        self.params: list[float] = []
        self.images: list[np.ndarray] = []
        self.img_size = 0

    def emit(self, opcode: int, params: Sequence[float] = (), aux0: int = 0, aux1: int = 0) -> None:
        """Append a row whose parameter record is ``params``."""
        self.rows.append((opcode, len(self.params), aux0, aux1))
        self.params.extend(float(value) for value in params)

    def add_image(self, pixels: np.ndarray) -> int:
        """Append an image's pixels (row major); returns their offset in ``img``."""
        offset = self.img_size
        self.images.append(np.ravel(pixels))
        self.img_size += pixels.size
        return offset


def _angle_cos_sin(angle_deg: float) -> list[float]:
    """``[cos a, sin a]`` of an angle in degrees."""
    angle = math.radians(angle_deg)
    return [math.cos(angle), math.sin(angle)]


def _image_map(m: Bitmap | ImageHeight, pixels: np.ndarray) -> list[float]:
    """The image-map record: origin (mm), pixels per mm along x and y, size (px), wrap code."""
    height_px, width_px = pixels.shape
    return [
        m.origin_mm[0], m.origin_mm[1], width_px / m.size_mm[0], height_px / m.size_mm[1],
        width_px, height_px, _WRAPS[m.wrap],
    ]


def _emit_grating(b: _Builder, m: Grating) -> None:
    friction = m.friction
    b.emit(
        layout.OP_GRATING,
        [*_angle_cos_sin(m.angle_deg), 1.0 / m.period_mm, m.phase_deg / 360.0, m.duty,
         friction.low, friction.high - friction.low],
        _WAVEFORMS[m.waveform],
    )


def _emit_temporal(b: _Builder, m: Temporal) -> None:
    friction = m.friction
    b.emit(
        layout.OP_TEMPORAL,
        [m.frequency_hz, m.duty, friction.low, friction.high - friction.low],
        _WAVEFORMS[m.waveform],
    )


def _emit_bitmap(b: _Builder, m: Bitmap) -> None:
    pixels = m.load_image_array()
    if m.invert:
        pixels = 1.0 - pixels
    offset = b.add_image(pixels)
    b.emit(layout.OP_BITMAP, [*_image_map(m, pixels), m.friction.low, m.friction.high - m.friction.low], offset)


def _bump_record(h: BumpHeight) -> list[float]:
    k = math.pi / h.radius_mm
    return [*h.center_mm, h.radius_mm, k, -0.5 * h.height_mm * k]


def _ridge_record(h: RidgeHeight) -> list[float]:
    cos_a, sin_a = _angle_cos_sin(h.angle_deg)
    k = 2.0 * math.pi / h.width_mm
    # (cos a, -sin a) runs along the ridge (y down); (-sin a, -cos a) is its normal.
    return [*h.center_mm, -sin_a, -cos_a, 0.5 * h.width_mm, k, -0.5 * h.height_mm * k]


def _sine_record(h: SineHeight) -> list[float]:
    k = 2.0 * math.pi / h.period_mm
    return [*_angle_cos_sin(h.angle_deg), k, 0.5 * h.height_mm * k]


def _emit_gradient(b: _Builder, m: Gradient) -> None:
    h = m.height
    head = [m.friction.base, m.gain, m.friction.low, m.friction.high]
    if isinstance(h, ImageHeight):
        pixels = h.load_image_array()
        offset = b.add_image(pixels)
        b.emit(layout.OP_GRADIENT, [*head, *_image_map(h, pixels), h.height_mm], layout.HEIGHT_IMAGE, offset)
        return
    records: dict[str, tuple[int, Callable[[Any], list[float]]]] = {
        "bump": (layout.HEIGHT_BUMP, _bump_record),
        "ridge": (layout.HEIGHT_RIDGE, _ridge_record),
        "sine": (layout.HEIGHT_SINE, _sine_record),
    }
    code, record = records[h.shape]
    b.emit(layout.OP_GRADIENT, [*head, *record(h)], code)


def _emit_bumps(b: _Builder, m: Bumps) -> None:
    reach_mm = m.radius_mm * (0.5 * layout.GAUSSIAN_REACH_SIGMAS if m.profile == "gaussian" else 1.0)
    head = [m.friction.inside, m.friction.outside, 1.0 / m.radius_mm, reach_mm]
    if m.grid is not None:
        (sx, sy), (ox, oy) = m.grid.spacing_mm, m.grid.offset_mm
        b.emit(layout.OP_BUMPS, [*head, sx, sy, 1.0 / sx, 1.0 / sy, ox, oy], _PROFILES[m.profile], 0)
        return
    centres = np.array(m.centers_mm, dtype=np.float64)
    centres = centres[np.argsort(centres[:, 0], kind="stable")]
    b.emit(layout.OP_BUMPS, [*head, *centres[:, 0], *centres[:, 1]], _PROFILES[m.profile], len(centres))


def _outline_record(outline: Outline) -> list[float]:
    """The edges shape record of an outline (SHAPE_RECORD_SIZE floats)."""
    shape = outline.shape
    if isinstance(shape, Rect):
        half_w, half_h = 0.5 * shape.w_mm, 0.5 * shape.h_mm
        return [layout.SHAPE_RECT, shape.x_mm + half_w, shape.y_mm + half_h, half_w, half_h, 0.0]
    if isinstance(shape, Circle):
        return [layout.SHAPE_CIRCLE, *shape.center_mm, shape.radius_mm, 0.0, 0.0]
    dx, dy = shape.to_mm[0] - shape.from_mm[0], shape.to_mm[1] - shape.from_mm[1]
    length2 = dx * dx + dy * dy
    return [layout.SHAPE_LINE, *shape.from_mm, dx, dy, 1.0 / length2 if length2 > 0.0 else 0.0]


def _emit_edges(b: _Builder, m: Edges) -> None:
    head = [m.friction.edge, m.friction.background, 0.5 * m.width_mm, 2.0 * math.pi / m.width_mm]
    records = [value for outline in m.shapes for value in _outline_record(outline)]
    b.emit(layout.OP_EDGES, [*head, *records], _PROFILES[m.profile], len(m.shapes))


def _region_record(region: Region | None) -> tuple[int, list[float]]:
    """``(SHAPE_* code, params)`` of a layer's region (None: everywhere)."""
    if region is None:
        return layout.SHAPE_EVERYWHERE, []
    rect, circle = region.rect, region.circle
    if rect is not None:
        return layout.SHAPE_RECT, [rect.x_mm, rect.y_mm, rect.x_mm + rect.w_mm, rect.y_mm + rect.h_mm]
    if circle is not None:
        return layout.SHAPE_CIRCLE, [*circle.center_mm, circle.radius_mm**2]
    raise ConfigError("region: holds no shape (a validated Region holds exactly one)")


def _emit_layers(b: _Builder, m: Layers) -> None:
    b.emit(layout.OP_PUSH_ONE)
    for index, layer in enumerate(m.layers):
        _emit(b, layer)
        shape, region = _region_record(layer.region)
        b.emit(layout.OP_COMBINE, region, _COMBINE_OPS["replace" if index == 0 else layer.op], shape)


#: Each kind's emitter, by the model's ``kind`` (which selects the model class the emitter takes).
_EMITTERS: dict[str, Callable[[_Builder, Any], None]] = {
    "grating": _emit_grating,
    "temporal": _emit_temporal,
    "bitmap": _emit_bitmap,
    "gradient": _emit_gradient,
    "bumps": _emit_bumps,
    "edges": _emit_edges,
    "layers": _emit_layers,
}


def _emit(b: _Builder, model: TextureFile) -> None:
    _EMITTERS[model.kind](b, model)


def _stack_depth(rows: list[tuple[int, int, int, int]]) -> int:
    """The largest number of values the postfix program holds on its stack at once."""
    depth = deepest = 0
    for opcode, *_ in rows:
        depth += _STACK_EFFECT.get(opcode, 1)
        deepest = max(deepest, depth)
    return deepest


def compile_texture(model: TextureFile) -> CompiledTexture:
    """Compile a validated texture model (any kind, layers nested) for ``eval_texture``.

    Raises ConfigError if an image the model refers to can no longer be read.
    """
    b = _Builder()
    _emit(b, model)
    images = np.concatenate(b.images) if b.images else np.zeros(0)
    return CompiledTexture(
        prog=np.array(b.rows, dtype=np.int64),
        params=np.array(b.params, dtype=np.float64),
        img=images,
        stack_depth=_stack_depth(b.rows),
        kind=model.kind,
        description=model.description or "",
    )


def load_compiled(path: str | Path) -> CompiledTexture:
    """Load, validate and compile the texture file at ``path``; ConfigError listing every problem."""
    return compile_texture(load_texture(path))
