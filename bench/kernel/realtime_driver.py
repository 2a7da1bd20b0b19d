"""Drive render_block the way the real-time engine does: a numba @cfunc on the callback's pointer table.

``render_stream(table, trajectory, block, blocks, out, driver=RENDER_STREAM) -> samples``
takes a :class:`tpad_rt.realtime.CallbackTable` (the pointer table the audio callback and
the serial streamer read, over a stream's kernel arrays and texture) and, inside a
``@cfunc``, rebuilds every array from it with :func:`tpad_rt.kernel.table.kernel_views`
and ``texture_views`` (views without reference counts, as in the audio callback); then,
per block, pushes the finger samples due by the block's end into the ring (row first, then
count: the producer's protocol) and calls ``render_block``. Nothing crosses into Python
between blocks, so the time measured is the kernel's. ``compile_driver(render_block)``
makes such a ``@cfunc`` around a given ``render_block``.

The ``@cfunc`` is compiled at import (a few seconds: it calls the compiled
``render_block``) and not cached: numba's cache would not notice a change to ``render.py``.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numba
import numpy as np
from numba import types

from tpad_rt.kernel import table as tab
from tpad_rt.kernel.layout import FINGER_COLS, FINGER_T_S
from tpad_rt.kernel.render import render_block
from tpad_rt.realtime import CallbackTable

_SIGNATURE = types.int64(
    types.CPointer(types.int64),  # the pointer table (tpad_rt.kernel.table's layout)
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
    def render_stream_cfunc(table_address, trajectory, rows, block, blocks, out, keep):  # type: ignore[no-untyped-def]
        table = numba.carray(table_address, tab.TAB_SIZE)
        cfg, dev, state, power_ring, finger, finger_count, telem, telem_count = tab.kernel_views(table)
        prog, params, img, stack = tab.texture_views(table, table[tab.TAB_ACTIVE_SLOT])
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


def render_stream(table: CallbackTable, trajectory: np.ndarray, block: int, blocks: int, out: np.ndarray,
                  driver: Any = RENDER_STREAM) -> int:
    """Render ``blocks`` blocks of ``block`` samples from sample 0; returns the samples rendered.

    ``out`` (float32) holds one block (each block overwrites it, as an audio buffer is
    reused) or all of them (kept in order). ``table``'s arrays are used in place (pass a
    table over fresh arrays for a fresh stream); ``trajectory`` rows ``(t_s, x_mm, y_mm,
    force_n, down)`` are pushed as their time comes. ``driver``: a :func:`compile_driver` cfunc.
    """
    if out.dtype != np.float32 or out.size not in (block, block * blocks):
        raise ValueError("out must be float32 with one block or all of them")
    path = np.ascontiguousarray(trajectory, dtype=np.float64)
    return driver.ctypes(
        table.table.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)),
        path.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
        len(path), block, blocks,
        out.ctypes.data_as(ctypes.POINTER(ctypes.c_float)),
        1 if out.size == block * blocks and blocks > 1 else 0,
    )
