"""Lookups in the kernel's device tables (``dev``): the cell of a grid around a position, a row's value in it.

API map
-------
grid_cell(dev, position) -> (i, i_next, weight)
    columns ``(i, i + 1)`` of ``dev`` around the fractional column ``position``, clamped to the table
force_cell(cfg, dev, force_n) -> (i, i_next, weight)
    the grid cell of the force grid (``cfg[CFG_FORCE_GRID_START_N]``, ``cfg[CFG_FORCE_GRID_STEP_N]``)
    around ``force_n`` (N)
device_value(dev, row, cell) -> float
    ``dev[row]`` linearly interpolated in a cell

The render kernel (:mod:`tpad_rt.kernel.render`) and the serial streamer's phase lock
(:mod:`tpad_rt.kernel.amp_stream`) both read the device's tables through these. Compiled
with the render kernel's options (no runtime, forced inline, numpy's error model: never
raises); a module that compiles them in stamps its cache with this file.
"""

from __future__ import annotations

import numpy as np

from tpad_rt.kernel.jit import njit
from tpad_rt.kernel.layout import CFG_FORCE_GRID_START_N, CFG_FORCE_GRID_STEP_N

_lookup = njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)


@_lookup
def grid_cell(dev: np.ndarray, position: float) -> tuple[int, int, float]:
    """Columns ``(i, i + 1)`` of ``dev`` around the fractional column ``position`` and the weight of the
    second, clamped to the table (a NaN position is column 0: never an index from a non-finite value)."""
    last = dev.shape[1] - 1
    if not position > 0.0:
        position = 0.0
    position = min(position, float(last))
    i = min(int(position), max(last - 1, 0))
    return i, min(i + 1, last), position - i


@_lookup
def force_cell(cfg: np.ndarray, dev: np.ndarray, force_n: float) -> tuple[int, int, float]:
    """The :func:`grid_cell` of the force grid around ``force_n`` (N)."""
    return grid_cell(dev, (force_n - cfg[CFG_FORCE_GRID_START_N]) / cfg[CFG_FORCE_GRID_STEP_N])


@_lookup
def device_value(dev: np.ndarray, row: int, cell: tuple[int, int, float]) -> float:
    """``dev[row]`` linearly interpolated in a :func:`force_cell` (or any :func:`grid_cell`)."""
    i, i_next, weight = cell
    return dev[row, i] + weight * (dev[row, i_next] - dev[row, i])
