"""Offline rendering of many blocks in one native call (``tpad-rt render``'s loop without Python per block).

Before each block, the finger samples due by its end go into the pipeline's finger ring,
as :meth:`tpad_rt.pipeline.Pipeline.push_finger` puts them there; then the block is
rendered by :func:`tpad_rt.kernel.render.render_block`. The samples, the ring and the
blocks are the same as pushing and rendering block by block from Python, so the output
is the same to the bit (tests/test_offline_batch.py).

API map
-------
render_blocks(out, block_frames, start_index, rows, due, cfg, dev, state, power_ring, finger,
              finger_count, prog, params, img, stack, telem, telem_count) -> None
    ``len(due)`` blocks of ``block_frames`` samples into ``out`` from sample ``start_index``
"""

from __future__ import annotations

import numpy as np

from tpad_rt.kernel import render
from tpad_rt.kernel.cache_stamp import stamp_cache
from tpad_rt.kernel.jit import njit
from tpad_rt.kernel.render import render_block

# render_block is compiled into render_blocks: its cache is stamped with render's sources too.
stamp_cache(__file__, *render.COMPILED_SOURCES)


@njit(cache=True, nogil=True, error_model="numpy")
def render_blocks(
    out: np.ndarray,
    block_frames: int,
    start_index: int,
    rows: np.ndarray,
    due: np.ndarray,
    cfg: np.ndarray,
    dev: np.ndarray,
    state: np.ndarray,
    power_ring: np.ndarray,
    finger: np.ndarray,
    finger_count: np.ndarray,
    prog: np.ndarray,
    params: np.ndarray,
    img: np.ndarray,
    stack: np.ndarray,
    telem: np.ndarray,
    telem_count: np.ndarray,
) -> None:
    """Render ``due.shape[0]`` blocks of ``block_frames`` samples into ``out`` (float32, at least that many
    samples) from sample ``start_index``; before block ``k``, append ``rows[due[k - 1]:due[k]]`` (``due[-1]``
    taken as 0) to the finger ring.

    ``rows``: float64 ``[N, FINGER_COLS]`` finger samples the caller has checked as
    ``push_finger`` checks them; ``due``: int64, non-decreasing, at most N. The other
    arrays are the pipeline's (:class:`tpad_rt.pipeline.KernelArrays`). One thread only:
    the ring's count is stored plainly (no real-time reader shares these arrays).
    """
    ring = finger.shape[0]
    pushed = 0
    for k in range(due.shape[0]):
        while pushed < min(due[k], rows.shape[0]):  # never past the rows, whatever due holds
            slot = finger_count[0] % ring
            for column in range(finger.shape[1]):
                finger[slot, column] = rows[pushed, column]
            finger_count[0] += 1
            pushed += 1
        begin = k * block_frames
        if begin + block_frames > out.shape[0]:  # never past out, whatever block_frames and due hold
            return
        render_block(out[begin:begin + block_frames], start_index + begin, cfg, dev, state, power_ring, finger,
                     finger_count, prog, params, img, stack, telem, telem_count)
