"""Reference texture evaluation: pure NumPy, straight from the texture models and docs/formats.md.

``reference_friction(model, x, y, ux, uy, t)`` broadcasts its array arguments and
returns the relative friction the texture asks for (before the kernel's clamp to
``[mu_floor, 1]``). It is deliberately written differently from the kernel: no
precomputed records, divisions instead of reciprocals, rectangle outlines as four
segments, every bump's profile evaluated and the strongest taken, grid bumps from
the 3 x 3 lattice points around the point, the bilinear written in its monomial form.

Conventions it shares with the kernel (they are the documented semantics):
y points down, angles counter-clockwise on screen, so direction ``a`` is the plate
vector ``(cos a, -sin a)``; a gaussian bump (sigma = radius / 2) ends at 3 sigma;
regions include their boundary; the edges band is ``d <= width / 2``; the gradient
of an image height map is the exact derivative of its bilinear interpolation, taken
in the cell to the right of / below a cell border.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tpad_rt.config.shapes import Circle, Line, Rect

LAYER_FLOOR = 0.01


def _wave(name: str, phase: np.ndarray, duty: float) -> np.ndarray:
    if name == "sine":
        return 0.5 + 0.5 * np.sin(2 * np.pi * phase)
    if name == "square":
        return np.where(phase < duty, 1.0, 0.0)
    if name == "triangle":
        return np.where(phase < duty, phase / duty, (1 - phase) / (1 - duty))
    return phase


def _periodic(model: Any, phase: np.ndarray) -> np.ndarray:
    low, high = model.friction.low, model.friction.high
    return low + (high - low) * _wave(model.waveform, phase, model.duty)


def _along(angle_deg: float, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Coordinate along direction ``angle_deg`` (counter-clockwise on a y-down screen)."""
    a = np.deg2rad(angle_deg)
    return x * np.cos(a) - y * np.sin(a)


def _grating(m: Any, x, y, ux, uy, t) -> np.ndarray:
    return _periodic(m, np.mod(_along(m.angle_deg, x, y) / m.period_mm + m.phase_deg / 360, 1.0))


def _temporal(m: Any, x, y, ux, uy, t) -> np.ndarray:
    return _periodic(m, np.mod(t * m.frequency_hz, 1.0))


def _bilinear_cell(m: Any, pixels: np.ndarray, x: np.ndarray, y: np.ndarray):
    """Monomial coefficients ``a + b tx + c ty + d tx ty`` of the cell around each point, and tx, ty."""
    rows, cols = pixels.shape
    px = (x - m.origin_mm[0]) / (m.size_mm[0] / cols) - 0.5
    py = (y - m.origin_mm[1]) / (m.size_mm[1] / rows) - 0.5
    left, top = np.floor(px), np.floor(py)
    if m.wrap == "tile":
        i = np.mod(left, cols).astype(int), np.mod(left + 1, cols).astype(int)
        j = np.mod(top, rows).astype(int), np.mod(top + 1, rows).astype(int)
    else:
        i = np.clip(left, 0, cols - 1).astype(int), np.clip(left + 1, 0, cols - 1).astype(int)
        j = np.clip(top, 0, rows - 1).astype(int), np.clip(top + 1, 0, rows - 1).astype(int)
    p00, p10 = pixels[j[0], i[0]], pixels[j[0], i[1]]
    p01, p11 = pixels[j[1], i[0]], pixels[j[1], i[1]]
    return (p00, p10 - p00, p01 - p00, p11 - p10 - p01 + p00), px - left, py - top


def _bitmap(m: Any, x, y, ux, uy, t) -> np.ndarray:
    pixels = m.load_image_array()
    if m.invert:
        pixels = 1.0 - pixels
    (a, b, c, d), tx, ty = _bilinear_cell(m, pixels, x, y)
    value = a + b * tx + c * ty + d * tx * ty
    return m.friction.low + (m.friction.high - m.friction.low) * value


def _bump_slope(h: Any, x, y, ux, uy) -> np.ndarray:
    dx, dy = x - h.center_mm[0], y - h.center_mm[1]
    r = np.hypot(dx, dy)
    dh_dr = -h.height_mm / 2 * np.pi / h.radius_mm * np.sin(np.pi * r / h.radius_mm)
    with np.errstate(invalid="ignore", divide="ignore"):
        slope = dh_dr * (dx * ux + dy * uy) / r
    return np.where((r < h.radius_mm) & (r > 0), slope, 0.0)


def _ridge_slope(h: Any, x, y, ux, uy) -> np.ndarray:
    a = np.deg2rad(h.angle_deg)
    along = np.cos(a), -np.sin(a)
    # signed distance across the ridge: the 2-D cross product of the offset with the ridge direction
    n = (x - h.center_mm[0]) * along[1] - (y - h.center_mm[1]) * along[0]
    dh_dn = -h.height_mm / 2 * (2 * np.pi / h.width_mm) * np.sin(2 * np.pi * n / h.width_mm)
    dn_du = along[1] * ux - along[0] * uy
    return np.where(np.abs(n) < h.width_mm / 2, dh_dn * dn_du, 0.0)


def _sine_slope(h: Any, x, y, ux, uy) -> np.ndarray:
    s = _along(h.angle_deg, x, y)
    dh_ds = h.height_mm * 0.5 * np.cos(2 * np.pi * s / h.period_mm) * 2 * np.pi / h.period_mm
    return dh_ds * _along(h.angle_deg, ux, uy)


def _image_slope(h: Any, x, y, ux, uy) -> np.ndarray:
    pixels = h.load_image_array()
    (a, b, c, d), tx, ty = _bilinear_cell(h, pixels, x, y)
    rows, cols = pixels.shape
    dv_dx = (b + d * ty) / (h.size_mm[0] / cols)
    dv_dy = (c + d * tx) / (h.size_mm[1] / rows)
    return h.height_mm * (dv_dx * ux + dv_dy * uy)


_SLOPES = {"bump": _bump_slope, "ridge": _ridge_slope, "sine": _sine_slope, "image": _image_slope}


def _gradient(m: Any, x, y, ux, uy, t) -> np.ndarray:
    slope = _SLOPES[m.height.shape](m.height, x, y, ux, uy)
    return np.clip(m.friction.base + m.gain * slope, m.friction.low, m.friction.high)


def _bump_profile(name: str, q: np.ndarray) -> np.ndarray:
    """Profile at ``q = d / radius``: 1 at the centre, 0 from the bump's end on."""
    if name == "cosine":
        return np.where(q < 1, (1 + np.cos(np.pi * q)) / 2, 0.0)
    if name == "gaussian":
        sigma = 0.5
        return np.where(q < 3 * sigma, np.exp(-(q**2) / (2 * sigma**2)), 0.0)
    return np.where(q < 1, 1.0, 0.0)


def _bump_centres(m: Any, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Candidate centres per point, on a trailing axis: every listed centre, or the 3 x 3 grid points around."""
    if m.centers_mm is not None:
        centres = np.asarray(m.centers_mm, dtype=float)
        return centres[:, 0], centres[:, 1]
    (sx, sy), (ox, oy) = m.grid.spacing_mm, m.grid.offset_mm
    steps = np.array([-1, 0, 1, -1, 0, 1, -1, 0, 1]), np.array([-1, -1, -1, 0, 0, 0, 1, 1, 1])
    col = np.floor((x - ox) / sx)[..., None] + steps[0]
    row = np.floor((y - oy) / sy)[..., None] + steps[1]
    return ox + col * sx, oy + row * sy


def _bumps(m: Any, x, y, ux, uy, t) -> np.ndarray:
    cx, cy = _bump_centres(m, x, y)
    q = np.hypot(x[..., None] - cx, y[..., None] - cy) / m.radius_mm
    strongest = _bump_profile(m.profile, q).max(axis=-1)
    return m.friction.outside + (m.friction.inside - m.friction.outside) * strongest


def _segment_distance(a, b, x, y) -> np.ndarray:
    (ax, ay), (bx, by) = a, b
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    t = 0.0 if length2 == 0 else np.clip(((x - ax) * dx + (y - ay) * dy) / length2, 0, 1)
    return np.hypot(x - (ax + t * dx), y - (ay + t * dy))


def _outline_distance(shape: Rect | Circle | Line, x, y) -> np.ndarray:
    if isinstance(shape, Rect):
        x0, y0, x1, y1 = shape.x_mm, shape.y_mm, shape.x_mm + shape.w_mm, shape.y_mm + shape.h_mm
        corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
        sides = [_segment_distance(corners[k], corners[(k + 1) % 4], x, y) for k in range(4)]
        return np.minimum.reduce(sides)
    if isinstance(shape, Circle):
        return np.abs(np.hypot(x - shape.center_mm[0], y - shape.center_mm[1]) - shape.radius_mm)
    return _segment_distance(shape.from_mm, shape.to_mm, x, y)


def _edges(m: Any, x, y, ux, uy, t) -> np.ndarray:
    d = np.minimum.reduce([_outline_distance(outline.shape, x, y) for outline in m.shapes])
    half = m.width_mm / 2
    band = np.ones_like(d) if m.profile == "step" else (1 + np.cos(np.pi * d / half)) / 2
    weight = np.where(d <= half, band, 0.0)
    return m.friction.background + (m.friction.edge - m.friction.background) * weight


def _in_region(region: Any, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    if region is None:
        return np.ones(x.shape, dtype=bool)
    shape = region.shape
    if isinstance(shape, Rect):
        return (shape.x_mm <= x) & (x <= shape.x_mm + shape.w_mm) & (shape.y_mm <= y) & (y <= shape.y_mm + shape.h_mm)
    return (x - shape.center_mm[0]) ** 2 + (y - shape.center_mm[1]) ** 2 <= shape.radius_mm**2


_OPS = {
    "replace": lambda r, v: v,
    "multiply": lambda r, v: r * v,
    "min": np.minimum,
    "max": np.maximum,
    "add": lambda r, v: r + v - 1,
}


def _layers(m: Any, x, y, ux, uy, t) -> np.ndarray:
    result = np.ones(x.shape)
    for index, layer in enumerate(m.layers):
        value = reference_friction(layer, x, y, ux, uy, t)
        combined = np.clip(_OPS["replace" if index == 0 else layer.op](result, value), LAYER_FLOOR, 1.0)
        result = np.where(_in_region(layer.region, x, y), combined, result)
    return result


_KINDS = {
    "grating": _grating,
    "temporal": _temporal,
    "bitmap": _bitmap,
    "gradient": _gradient,
    "bumps": _bumps,
    "edges": _edges,
    "layers": _layers,
}


def reference_friction(model: Any, x, y, ux, uy, t) -> np.ndarray:
    """Relative friction of texture ``model`` at plate points (mm), finger directions, times (s).

    ``(ux, uy)`` is the unit direction of motion ((0, 0) when still); all five
    arguments broadcast. Returns float64 of the broadcast shape.
    """
    x, y, ux, uy, t = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x, y, ux, uy, t)))
    return np.asarray(_KINDS[model.kind](model, x, y, ux, uy, t), dtype=np.float64)
