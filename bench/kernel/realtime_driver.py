"""Drive render_block the way the real-time engine does: a numba @cfunc on raw pointers.

``render_stream(arrays, trajectory, block, blocks, out, driver=RENDER_STREAM) -> samples``
rebuilds every array from its address inside a ``@cfunc`` (views without reference
counts, as in the audio callback), then, per block, pushes the finger samples due by the
block's end into the ring (row first, then count: the producer's protocol) and calls
``render_block``. Nothing crosses into Python between blocks, so the time measured is
the kernel's. ``compile_driver(render_block)`` makes such a ``@cfunc`` around another
``render_block`` (bench/kernel/unguarded.py: the kernel before its fault guard).

The ``@cfunc`` is compiled at import (about 20 s: ``render_block`` is inlined into it)
and not cached: numba's cache would not notice a change to ``render.py``.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numba
import numpy as np
from numba import types

from tpad_rt.kernel.layout import FINGER_COLS, FINGER_T_S
from tpad_rt.kernel.render import render_block
from tpad_rt.pipeline import KernelArrays

_F8 = np.float64
_I8 = np.int64
#: Shapes are passed as (rows, columns) per array, in KernelArrays order.
_SIGNATURE = types.int64(
    types.CPointer(types.voidptr),  # array addresses
    types.CPointer(types.int64),  # shapes
    types.CPointer(types.float64),  # trajectory rows (t_s, x_mm, y_mm, force_n, down)
    types.int64,  # trajectory rows
    types.int64,  # block (samples)
    types.int64,  # blocks
    types.CPointer(types.float32),  # out: one block, or every block when the next argument is 1
    types.int64,  # 1: each block goes after the previous one in out; 0: every block into out[:block]
)


def compile_driver(kernel: Any) -> Any:
    """A ``@cfunc`` of signature _SIGNATURE that renders with ``kernel`` (a ``render_block``)."""

    @numba.cfunc(_SIGNATURE, nopython=True)
    def render_stream_cfunc(addresses, shapes, trajectory, rows, block, blocks, out, keep):  # type: ignore[no-untyped-def]
        p = numba.carray(addresses, 12)
        s = numba.carray(shapes, 24)
        cfg = numba.carray(p[0], s[0], _F8)
        dev = numba.carray(p[1], (s[2], s[3]), _F8)
        state = numba.carray(p[2], s[4], _F8)
        power_ring = numba.carray(p[3], s[6], _F8)
        finger = numba.carray(p[4], (s[8], s[9]), _F8)
        finger_count = numba.carray(p[5], s[10], _I8)
        prog = numba.carray(p[6], (s[12], s[13]), _I8)
        params = numba.carray(p[7], s[14], _F8)
        img = numba.carray(p[8], s[16], _F8)
        stack = numba.carray(p[9], s[18], _F8)
        telem = numba.carray(p[10], (s[20], s[21]), _F8)
        telem_count = numba.carray(p[11], s[22], _I8)
        path = numba.carray(trajectory, (rows, FINGER_COLS))
        samples = numba.carray(out, block * (blocks if keep else 1))
        fs_hz = cfg[0]
        ring_rows = finger.shape[0]
        pushed = 0
        n = 0
        for _ in range(blocks):
            end_s = (n + block) / fs_hz
            while pushed < rows and path[pushed, FINGER_T_S] <= end_s:
                for column in range(FINGER_COLS):
                    finger[pushed % ring_rows, column] = path[pushed, column]
                finger_count[0] = pushed + 1
                pushed += 1
            first = n if keep else 0
            kernel(samples[first : first + block], n, cfg, dev, state, power_ring, finger, finger_count,
                   prog, params, img, stack, telem, telem_count)
            n += block
        return n

    return render_stream_cfunc


#: The driver around the current kernel.
RENDER_STREAM = compile_driver(render_block)


def render_stream(arrays: KernelArrays, trajectory: np.ndarray, block: int, blocks: int, out: np.ndarray,
                  driver: Any = RENDER_STREAM) -> int:
    """Render ``blocks`` blocks of ``block`` samples from sample 0; returns the samples rendered.

    ``out`` (float32) holds one block (each block overwrites it, as an audio buffer is
    reused) or all of them (kept in order). ``arrays`` are used in place (pass fresh
    copies for a fresh stream); ``trajectory`` rows ``(t_s, x_mm, y_mm, force_n, down)``
    are pushed as their time comes. ``driver``: a :func:`compile_driver` cfunc.
    """
    if out.dtype != np.float32 or out.size not in (block, block * blocks):
        raise ValueError("out must be float32 with one block or all of them")
    if any(array.ndim > 2 or not array.flags.c_contiguous for array in arrays):
        raise ValueError("arrays must be C-contiguous, 1-D or 2-D")
    path = np.ascontiguousarray(trajectory, dtype=np.float64)
    addresses = (ctypes.c_void_p * len(arrays))(*(array.ctypes.data for array in arrays))
    shapes = np.array([(array.shape + (0,))[:2] for array in arrays], dtype=np.int64).ravel()
    return driver.ctypes(
        addresses,
        shapes.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)),
        path.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
        len(path), block, blocks,
        out.ctypes.data_as(ctypes.POINTER(ctypes.c_float)),
        1 if out.size == block * blocks and blocks > 1 else 0,
    )
