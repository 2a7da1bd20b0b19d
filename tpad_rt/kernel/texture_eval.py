"""Texture evaluation kernel: relative friction of a compiled texture at a point and time.

API map
-------
eval_texture(prog, params, img, stack, x_mm, y_mm, ux, uy, t_s) -> float
    relative friction asked for at plate point ``(x_mm, y_mm)``; the caller clamps it
    to ``[mu_floor, 1]``
eval_texture_points(prog, params, img, stack, x_mm, y_mm, ux, uy, t_s, out) -> None
    the same at many points (1-D arrays of equal length), written into ``out``
waveform(code, phase, duty) -> float
    one period of a ``WAVE_*`` waveform, in [0, 1]

``eval_texture`` and its helpers are ordinary numba functions without the reference-counted
runtime (``_kernel`` below), which LLVM inlines into a kernel calling them. Every opcode and
record code is matched explicitly: an unknown one gives NaN, never another case's value.
Measured (before that change) along a smooth finger path with
``numba.carray`` arrays (2-core CI machine class): 4-16 ns per call for one grating,
bitmap, gradient, bumps or temporal row (a sine costs ~11 ns of that), ~35 ns for four
edges outlines, 27-51 ns for the example layers textures.

The program (docs/kernel.md "Compiled textures") is postfix: rows ``(opcode,
params_offset, aux0, aux1)`` of int64, evaluated on ``stack`` (float64 scratch of at
least ``CompiledTexture.stack_depth`` values). ``tpad_rt.texture`` writes it; every
constant that can be is precomputed there. Parameter records, from ``params_offset``
(lengths in mm, angles as cos/sin, levels as ``low, span = high - low``):

==========  ==========================  =============================================
opcode      aux0, aux1                  params
==========  ==========================  =============================================
GRATING     WAVE_*, -                   cos_a, sin_a, 1/period, phase (cycles), duty,
                                        low, span
TEMPORAL    WAVE_*, -                   frequency_hz, duty, low, span
BITMAP      image offset, -             image map (7), low, span
GRADIENT    HEIGHT_*, image offset      base, gain, low, high, then the height shape:
                                        bump ``cx, cy, radius, pi/radius, amp``;
                                        ridge ``cx, cy, nx, ny, width/2, 2 pi/width, amp``;
                                        sine ``cos_a, sin_a, 2 pi/period, amp``;
                                        image: image map (7), height_mm
BUMPS       PROFILE_*, n centres        inside, outside, 1/radius, reach, then grid
            (0: grid)                   ``sx, sy, 1/sx, 1/sy, ox, oy`` or the centres'
                                        x (ascending, n values) then their y (n values)
EDGES       PROFILE_*, n shapes         edge, background, width/2, 2 pi/width, then n
                                        shape records of SHAPE_RECORD_SIZE:
                                        ``SHAPE_RECT, cx, cy, w/2, h/2, 0``,
                                        ``SHAPE_CIRCLE, cx, cy, r, 0, 0``,
                                        ``SHAPE_LINE, ax, ay, bx - ax, by - ay, 1/|b - a|^2``
                                        (0 for a point)
COMBINE     COMBINE_*, SHAPE_* region   rect ``x0, y0, x1, y1``; circle ``cx, cy, r^2``;
                                        nothing for SHAPE_EVERYWHERE
==========  ==========================  =============================================

An image map is ``ox, oy, px_per_mm_x, px_per_mm_y, width_px, height_px, WRAP_*``;
its pixels are ``img[offset : offset + width_px * height_px]``, row major, row 0 at
``y = oy``. ``amp`` is the height shape's slope factor (see the shape helpers).
"""

from __future__ import annotations

import math

import numpy as np

from tpad_rt.kernel.jit import njit
from tpad_rt.kernel.layout import (
    COMBINE_ADD,
    COMBINE_MAX,
    COMBINE_MIN,
    COMBINE_MULTIPLY,
    COMBINE_REPLACE,
    HEIGHT_BUMP,
    HEIGHT_IMAGE,
    HEIGHT_RIDGE,
    HEIGHT_SINE,
    LAYER_FLOOR,
    OP_BITMAP,
    OP_BUMPS,
    OP_COMBINE,
    OP_EDGES,
    OP_GRADIENT,
    OP_GRATING,
    OP_PUSH_ONE,
    OP_TEMPORAL,
    PROFILE_COSINE,
    PROFILE_DISK,
    PROFILE_GAUSSIAN,
    PROFILE_STEP,
    SHAPE_CIRCLE,
    SHAPE_EVERYWHERE,
    SHAPE_LINE,
    SHAPE_RECORD_SIZE,
    SHAPE_RECT,
    WAVE_SAWTOOTH,
    WAVE_SINE,
    WAVE_SQUARE,
    WAVE_TRIANGLE,
    WRAP_CLAMP,
    WRAP_TILE,
)

_TWO_PI = 2.0 * math.pi
#: Pixel positions are turned into int64 indices only below this (exact in a float64).
_MAX_PIXEL_INDEX = 2.0**52  # (and phases in cycles: floor() of one gives an int64)

#: ``_nrt=False``: nothing here allocates, and without numba's reference-counted runtime a
#: call passing arrays costs no reference counting, so the helpers are ordinary functions
#: that ``forceinline`` marks for LLVM to inline always (inlining them at numba IR level
#: instead cost about 10 s of the first compile).
#: ``error_model="numpy"``: no division-by-zero checks (``texture.py`` never divides by 0).
_kernel = njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)


@_kernel
def waveform(code: int, phase: float, duty: float) -> float:
    """One period of waveform ``code`` (``WAVE_*``) at ``phase`` in [0, 1] (cycles), in [0, 1].

    sine ``0.5 + 0.5 sin(2 pi p)``; square 1 while ``p < duty``; triangle rising over
    ``duty``, then falling; sawtooth ``p``. At ``phase == 1`` each gives its limit from
    below. ``duty`` is in (0, 1). NaN for an unknown ``code`` (a fault, never a guess).
    """
    if code == WAVE_SINE:
        return 0.5 + 0.5 * math.sin(_TWO_PI * phase)
    if code == WAVE_SQUARE:
        return 1.0 if phase < duty else 0.0
    if code == WAVE_SAWTOOTH:
        return phase
    if code == WAVE_TRIANGLE:
        if phase < duty:
            return phase / duty
        return (1.0 - phase) / (1.0 - duty)
    return math.nan


@_kernel
def _frac(cycles: float) -> float:
    """The fractional part of ``cycles``, in [0, 1] (1 only by rounding of a tiny negative); NaN when
    ``cycles`` is not finite or beyond 2**52 (no fraction is left, and ``floor`` would not fit an int64)."""
    if not abs(cycles) < _MAX_PIXEL_INDEX:
        return math.nan
    return cycles - math.floor(cycles)


@_kernel
def _periodic_level(params: np.ndarray, o: int, code: int, phase: float) -> float:
    """``low + span * waveform`` with ``duty, low, span`` at ``params[o:o + 3]``; NaN for a NaN ``phase``
    (the render kernel counts a texture fault; a square wave's comparison alone would hide it)."""
    if not phase >= 0.0:
        return math.nan
    return params[o + 1] + params[o + 2] * waveform(code, phase, params[o])


@_kernel
def _grating(params: np.ndarray, o: int, code: int, x_mm: float, y_mm: float) -> float:
    """Grating friction: phase ``s / period + phase`` with ``s = x cos_a - y sin_a`` (mm)."""
    s_mm = x_mm * params[o] - y_mm * params[o + 1]
    return _periodic_level(params, o + 4, code, _frac(s_mm * params[o + 2] + params[o + 3]))


@_kernel
def _temporal(params: np.ndarray, o: int, code: int, t_s: float) -> float:
    """Temporal friction: phase ``t_s * frequency_hz``."""
    return _periodic_level(params, o + 1, code, _frac(t_s * params[o]))


@_kernel
def _pixel_pair(index: int, size: int, wrap: float) -> tuple[int, int]:
    """Indices of pixel ``index`` and the next one along a side of ``size`` pixels, wrapped (tiled,
    else clamped: :func:`_image_cell` admits only the two)."""
    if wrap == WRAP_TILE:
        first = index % size
        return first, (first + 1) % size
    return min(max(index, 0), size - 1), min(max(index + 1, 0), size - 1)


@_kernel
def _image_cell(
    params: np.ndarray, o: int, img: np.ndarray, img_offset: int, x_mm: float, y_mm: float
) -> tuple[float, float, float, float, float, float]:
    """The bilinear cell around a plate point of the image map at ``params[o:o + 7]``.

    Returns ``(v00, v10, v01, v11, tx, ty)``: the four pixel values (``v10`` one pixel
    to the right of ``v00``, ``v01`` one below) and the point's fractions across the
    cell. Pixel ``i`` has its centre at ``ox + (i + 0.5) / px_per_mm``. A pixel position
    that is not finite or beyond 2**52, or an image that does not fit in ``img`` or has an
    unknown ``WRAP_*`` (a corrupt record), gives NaN values: no index is made from them.
    """
    fx = (x_mm - params[o]) * params[o + 2] - 0.5
    fy = (y_mm - params[o + 1]) * params[o + 3] - 0.5
    fits = (1.0 <= params[o + 4] <= img.shape[0] and 1.0 <= params[o + 5] <= img.shape[0]
            and (params[o + 6] == WRAP_TILE or params[o + 6] == WRAP_CLAMP))
    if not (fits and abs(fx) < _MAX_PIXEL_INDEX and abs(fy) < _MAX_PIXEL_INDEX
            and 0 <= img_offset <= img.shape[0] - int(params[o + 4]) * int(params[o + 5])):
        return math.nan, math.nan, math.nan, math.nan, 0.0, 0.0
    width = int(params[o + 4])
    ix = math.floor(fx)
    iy = math.floor(fy)
    i0, i1 = _pixel_pair(ix, width, params[o + 6])
    j0, j1 = _pixel_pair(iy, int(params[o + 5]), params[o + 6])
    row0 = img_offset + j0 * width
    row1 = img_offset + j1 * width
    return img[row0 + i0], img[row0 + i1], img[row1 + i0], img[row1 + i1], fx - ix, fy - iy


@_kernel
def _bitmap(params: np.ndarray, o: int, img: np.ndarray, img_offset: int, x_mm: float, y_mm: float) -> float:
    """Bitmap friction: ``low + span * bilinear(pixels)``."""
    v00, v10, v01, v11, tx, ty = _image_cell(params, o, img, img_offset, x_mm, y_mm)
    top = v00 + tx * (v10 - v00)
    bottom = v01 + tx * (v11 - v01)
    return params[o + 7] + params[o + 8] * (top + ty * (bottom - top))


@_kernel
def _bump_slope(params: np.ndarray, o: int, x_mm: float, y_mm: float, ux: float, uy: float) -> float:
    """Slope along (ux, uy) of ``h = H/2 (1 + cos(pi d / R))`` for ``d < R`` (0 outside).

    ``dh/dd = amp * sin(pi d / R)`` with ``amp = -H pi / (2 R)``.
    """
    dx = x_mm - params[o]
    dy = y_mm - params[o + 1]
    d_mm = math.sqrt(dx * dx + dy * dy)
    if d_mm >= params[o + 2] or d_mm == 0.0:
        return 0.0
    return params[o + 4] * math.sin(params[o + 3] * d_mm) * (dx * ux + dy * uy) / d_mm


@_kernel
def _ridge_slope(params: np.ndarray, o: int, x_mm: float, y_mm: float, ux: float, uy: float) -> float:
    """Slope along (ux, uy) of ``h = H/2 (1 + cos(2 pi n / W))`` for ``|n| < W/2`` (0 outside).

    ``n`` is the distance across the ridge along its unit normal ``(nx, ny)``;
    ``dh/dn = amp * sin(2 pi n / W)`` with ``amp = -H pi / W``.
    """
    n_mm = (x_mm - params[o]) * params[o + 2] + (y_mm - params[o + 1]) * params[o + 3]
    if abs(n_mm) >= params[o + 4]:
        return 0.0
    return params[o + 6] * math.sin(params[o + 5] * n_mm) * (params[o + 2] * ux + params[o + 3] * uy)


@_kernel
def _sine_slope(params: np.ndarray, o: int, x_mm: float, y_mm: float, ux: float, uy: float) -> float:
    """Slope along (ux, uy) of ``h = H (0.5 + 0.5 sin(2 pi s / P))``, ``s = x cos_a - y sin_a``.

    ``dh/ds = amp * cos(2 pi s / P)`` with ``amp = H pi / P``.
    """
    s_mm = x_mm * params[o] - y_mm * params[o + 1]
    return params[o + 3] * math.cos(params[o + 2] * s_mm) * (params[o] * ux - params[o + 1] * uy)


@_kernel
def _image_slope(
    params: np.ndarray, o: int, img: np.ndarray, img_offset: int, x_mm: float, y_mm: float, ux: float, uy: float
) -> float:
    """Slope along (ux, uy) of ``height_mm * bilinear(pixels)``: the bilinear's exact derivative.

    Inside a cell the derivative along x is linear in ``ty`` (and along y in ``tx``); on a
    cell border the cell to the right (below) is used. Clamped edges have slope 0.
    """
    v00, v10, v01, v11, tx, ty = _image_cell(params, o, img, img_offset, x_mm, y_mm)
    dv_dx = ((1.0 - ty) * (v10 - v00) + ty * (v11 - v01)) * params[o + 2]
    dv_dy = ((1.0 - tx) * (v01 - v00) + tx * (v11 - v10)) * params[o + 3]
    return params[o + 7] * (dv_dx * ux + dv_dy * uy)


@_kernel
def _gradient(
    params: np.ndarray, o: int, shape: int, img: np.ndarray, img_offset: int,
    x_mm: float, y_mm: float, ux: float, uy: float,
) -> float:
    """Gradient friction: ``clamp(base + gain * slope, low, high)``, slope in mm/mm along (ux, uy)."""
    h = o + 4
    if shape == HEIGHT_BUMP:
        slope = _bump_slope(params, h, x_mm, y_mm, ux, uy)
    elif shape == HEIGHT_RIDGE:
        slope = _ridge_slope(params, h, x_mm, y_mm, ux, uy)
    elif shape == HEIGHT_SINE:
        slope = _sine_slope(params, h, x_mm, y_mm, ux, uy)
    elif shape == HEIGHT_IMAGE:
        slope = _image_slope(params, h, img, img_offset, x_mm, y_mm, ux, uy)
    else:
        return math.nan
    return min(max(params[o] + params[o + 1] * slope, params[o + 2]), params[o + 3])


@_kernel
def _nearest_grid_d2(params: np.ndarray, o: int, x_mm: float, y_mm: float) -> float:
    """Squared distance (mm^2) to the nearest centre of the grid ``sx, sy, 1/sx, 1/sy, ox, oy``."""
    gx = x_mm - params[o + 4]
    gy = y_mm - params[o + 5]
    dx = gx - params[o] * math.floor(gx * params[o + 2] + 0.5)
    dy = gy - params[o + 1] * math.floor(gy * params[o + 3] + 0.5)
    return dx * dx + dy * dy


@_kernel
def _nearest_centre_d2(params: np.ndarray, o: int, n: int, x_mm: float, y_mm: float, reach_mm: float) -> float:
    """Squared distance (mm^2) to the nearest of ``n`` centres sorted by x, or ``reach^2`` if none is closer.

    Binary search for the first centre with ``cx >= x - reach``, then a scan while
    ``cx <= x + reach``.
    """
    lo = 0
    hi = n
    while lo < hi:
        mid = (lo + hi) // 2
        if params[o + mid] < x_mm - reach_mm:
            lo = mid + 1
        else:
            hi = mid
    best = reach_mm * reach_mm
    k = lo
    while k < n and params[o + k] <= x_mm + reach_mm:
        dx = params[o + k] - x_mm
        dy = params[o + n + k] - y_mm
        best = min(best, dx * dx + dy * dy)
        k += 1
    return best


@_kernel
def _bumps(params: np.ndarray, o: int, profile: int, n: int, x_mm: float, y_mm: float) -> float:
    """Bumps friction from the nearest centre (the strongest: every bump has the same falling profile).

    ``outside + (inside - outside) * profile(d / R)`` within ``reach`` (R; 1.5 R for
    gaussian), ``outside`` beyond.
    """
    reach_mm = params[o + 3]
    if n == 0:
        d2 = _nearest_grid_d2(params, o + 4, x_mm, y_mm)
    else:
        d2 = _nearest_centre_d2(params, o + 4, n, x_mm, y_mm, reach_mm)
    if d2 >= reach_mm * reach_mm:
        return params[o + 1]
    q = math.sqrt(d2) * params[o + 2]
    if profile == PROFILE_COSINE:
        weight = 0.5 + 0.5 * math.cos(math.pi * q)
    elif profile == PROFILE_GAUSSIAN:
        weight = math.exp(-2.0 * q * q)
    elif profile == PROFILE_DISK:
        weight = 1.0
    else:
        return math.nan
    return params[o + 1] + (params[o] - params[o + 1]) * weight


@_kernel
def _outline_distance(params: np.ndarray, r: int, x_mm: float, y_mm: float) -> float:
    """Unsigned distance (mm) from a point to the outline in the shape record at ``params[r]``."""
    code = params[r]
    if code == SHAPE_RECT:
        dx = abs(x_mm - params[r + 1]) - params[r + 3]
        dy = abs(y_mm - params[r + 2]) - params[r + 4]
        outside = math.sqrt(max(dx, 0.0) ** 2 + max(dy, 0.0) ** 2)
        return abs(outside + min(max(dx, dy), 0.0))
    if code == SHAPE_CIRCLE:
        return abs(math.hypot(x_mm - params[r + 1], y_mm - params[r + 2]) - params[r + 3])
    ax = x_mm - params[r + 1]
    ay = y_mm - params[r + 2]
    if code == SHAPE_LINE:
        t = min(max((ax * params[r + 3] + ay * params[r + 4]) * params[r + 5], 0.0), 1.0)
        return math.hypot(ax - t * params[r + 3], ay - t * params[r + 4])
    return math.nan


@_kernel
def _edges(params: np.ndarray, o: int, profile: int, n: int, x_mm: float, y_mm: float) -> float:
    """Edges friction from the nearest outline: the band ``d <= width/2``, step or raised cosine."""
    d_mm = math.inf
    for k in range(n):
        outline_mm = _outline_distance(params, o + 4 + k * SHAPE_RECORD_SIZE, x_mm, y_mm)
        if not outline_mm >= 0.0:
            return math.nan  # an unknown shape record (min() would drop the NaN)
        d_mm = min(d_mm, outline_mm)
    if d_mm > params[o + 2]:
        return params[o + 1]
    if profile == PROFILE_STEP:
        return params[o]
    if profile == PROFILE_COSINE:
        weight = 0.5 + 0.5 * math.cos(params[o + 3] * d_mm)
        return params[o + 1] + (params[o] - params[o + 1]) * weight
    return math.nan


@_kernel
def _in_region(params: np.ndarray, o: int, shape: int, x_mm: float, y_mm: float) -> int:
    """1 where a point lies in a layer's region (edges included), 0 where not, -1 for an unknown ``shape``."""
    if shape == SHAPE_EVERYWHERE:
        return 1
    if shape == SHAPE_RECT:
        return int(params[o] <= x_mm <= params[o + 2] and params[o + 1] <= y_mm <= params[o + 3])
    if shape == SHAPE_CIRCLE:
        dx = x_mm - params[o]
        dy = y_mm - params[o + 1]
        return int(dx * dx + dy * dy <= params[o + 2])
    return -1


@_kernel
def _combine(op: int, result: float, layer: float) -> float:
    """``op(result, layer)`` clamped to ``[LAYER_FLOOR, 1]``; replace returns ``layer``. NaN for an unknown
    ``op``, or when either value is NaN (a layer's fault must reach the render kernel: ``min`` would drop it)."""
    if math.isnan(result) or math.isnan(layer):
        return math.nan
    if op == COMBINE_MULTIPLY:
        value = result * layer
    elif op == COMBINE_MIN:
        value = min(result, layer)
    elif op == COMBINE_MAX:
        value = max(result, layer)
    elif op == COMBINE_ADD:
        value = result + layer - 1.0
    elif op == COMBINE_REPLACE:
        value = layer
    else:
        return math.nan
    return min(max(value, LAYER_FLOOR), 1.0)


@_kernel
def eval_texture(
    prog: np.ndarray,
    params: np.ndarray,
    img: np.ndarray,
    stack: np.ndarray,
    x_mm: float,
    y_mm: float,
    ux: float,
    uy: float,
    t_s: float,
) -> float:
    """Relative friction the texture asks for at plate point ``(x_mm, y_mm)`` (mm).

    ``prog`` int64 ``[N, 4]``, ``params`` and ``img`` float64 (module docstring),
    ``stack`` float64 scratch of at least the program's stack depth (overwritten);
    ``(ux, uy)`` the unit direction of finger motion in plate coordinates ((0, 0) when
    still); ``t_s`` seconds since the texture was set. Allocates nothing. The value is
    in (0, 1] for a program from ``tpad_rt.texture``; the caller clamps it to
    ``[mu_floor, 1]``. NaN for a corrupt program (an unknown opcode, or an unknown code in
    a record) or a point no layer can evaluate: the render kernel counts it as a texture
    fault and ramps the drive down.
    """
    sp = 0
    for row in range(prog.shape[0]):
        op = prog[row, 0]
        o = prog[row, 1]
        aux0 = prog[row, 2]
        aux1 = prog[row, 3]
        if op == OP_COMBINE:
            sp -= 1
            inside = _in_region(params, o, aux1, x_mm, y_mm)
            if inside == 1:
                stack[sp - 1] = _combine(aux0, stack[sp - 1], stack[sp])
            elif inside == -1:
                stack[sp - 1] = math.nan
            continue
        if op == OP_GRATING:
            value = _grating(params, o, aux0, x_mm, y_mm)
        elif op == OP_PUSH_ONE:
            value = 1.0
        elif op == OP_TEMPORAL:
            value = _temporal(params, o, aux0, t_s)
        elif op == OP_BITMAP:
            value = _bitmap(params, o, img, aux0, x_mm, y_mm)
        elif op == OP_GRADIENT:
            value = _gradient(params, o, aux0, img, aux1, x_mm, y_mm, ux, uy)
        elif op == OP_BUMPS:
            value = _bumps(params, o, aux0, aux1, x_mm, y_mm)
        elif op == OP_EDGES:
            value = _edges(params, o, aux0, aux1, x_mm, y_mm)
        else:
            value = math.nan  # an unknown opcode: a texture fault, never another layer's guess
        stack[sp] = value
        sp += 1
    return stack[0]


@_kernel
def eval_texture_points(
    prog: np.ndarray,
    params: np.ndarray,
    img: np.ndarray,
    stack: np.ndarray,
    x_mm: np.ndarray,
    y_mm: np.ndarray,
    ux: np.ndarray,
    uy: np.ndarray,
    t_s: np.ndarray,
    out: np.ndarray,
) -> None:
    """:func:`eval_texture` at every index of the equal-length 1-D arrays, written into ``out``."""
    for i in range(out.shape[0]):
        out[i] = eval_texture(prog, params, img, stack, x_mm[i], y_mm[i], ux[i], uy[i], t_s[i])
