"""The pointer table a real-time driver reaches the render kernel through, and the block it renders.

API map
-------
TAB_*, SLOT_*, STAT_*, BLOCK_*
    the layout of the pointer table (int64 ``[TAB_SIZE]``), the statistics and the
    per-block record ring; :class:`tpad_rt.realtime.CallbackTable` owns one. Defined in
    :mod:`tpad_rt.kernel.table_layout` (no numba: the Python side reads them from there)
begin_block(table, first_sample, frames, dac_delay_ns) -> (stats, row, entry_ns)
render_into(table, state, out, frames, channels, channel, dac_delay_ns)
finish_block(stats, row, entry_ns, frames, underflow, priming, lead_over)
    one block, as every driver renders it: record its start, render it from the
    table's arrays (the texture slot it finds active), close its record
kernel_views(table) -> (cfg, dev, state, power_ring, finger, finger_count, telem, telem_count)
texture_views(table, slot) -> (prog, params, img, stack)
    views of the arrays the table points to (render_into's, and the kernel bench's driver)

Both drivers use them: the PortAudio callback (:mod:`tpad_rt.kernel.callback`) and the
serial amplifier's streamer (:mod:`tpad_rt.kernel.amp_stream`). docs/realtime.md is the
design. A driver receives only raw pointers; it rebuilds each array with
``numba.carray`` from an address and a size in the table (views: no allocation, no
reference counting, no Python object) and never raises. The table, and every array it
points to, is owned by the Python side and must outlive the driver.

The pointer table (int64; addresses are ``ndarray.ctypes.data``):

- the render kernel's arrays except the texture (``TAB_CFG`` .. ``TAB_TELEM_ROWS``,
  addresses and the sizes a view needs);
- two texture slots at ``TAB_SLOTS + k * SLOT_SIZE``: prog, params, img and stack
  addresses and sizes; ``TAB_ACTIVE_SLOT`` says which one is rendered. The texture's
  start time ``t0_s`` lives with each slot in the float64 array at ``TAB_SLOT_T0``
  and is copied into ``cfg[CFG_TEXTURE_T0_S]`` at each block, so a texture and its
  time origin change together;
- the output: ``TAB_CHANNELS`` interleaved channels, the drive in ``TAB_CHANNEL``
  (0-based), zeros in the others; a mono scratch buffer (``TAB_SCRATCH``,
  ``TAB_SCRATCH_FRAMES``) the kernel renders into, in pieces if a block asks for more;
- a drive ring (float32, ``TAB_DRIVE``, ``TAB_DRIVE_FRAMES``) holding the last samples
  rendered (sample ``n`` at ``n % frames``), for recordings;
- the statistics (int64 ``[STAT_SIZE]``) and the per-block record ring (int64
  ``[TAB_BLOCK_ROWS, BLOCK_COLS]``, row ``blocks % rows``);
- ``TAB_FINGER_SEEN``: the finger count the running block acquired (below);
- ``TAB_LEAD_BOUND_NS``: the most lead (ns, at most MAX_OUTPUT_LEAD_S) the driver's output can
  honestly have, which the driver writes before it starts (0 until then: no lead). A block's
  reported delay (PortAudio's time info, the serial streamer's buffer) above it, or not a
  number, is taken as this much and counted (``STAT_LEAD_OVER``); a negative one as 0. So a
  bogus time stamp never stretches the finger watchdog past ``watchdog_ms`` plus this.

The Python side publishes with release stores (:func:`tpad_rt.kernel.atomics.publish`)
and a driver reads with acquire loads, so it never sees an index before the data it
covers, on any CPU: a whole idle slot, then ``TAB_ACTIVE_SLOT`` (read once per block);
a finger row, then ``finger_count`` (acquired once per block into ``TAB_FINGER_SEEN``,
which the kernel reads in its place).
"""

from __future__ import annotations

import inspect
from pathlib import Path

import numba
import numpy as np

from tpad_rt.kernel.jit import njit
from tpad_rt.kernel import atomics, libc, render
from tpad_rt.kernel.atomics import load_acquire, store_release
from tpad_rt.kernel.libc import monotonic_ns, pointer
from tpad_rt.kernel.layout import (
    CFG_FS_HZ,
    CFG_OUTPUT_LEAD_S,
    CFG_TEXTURE_T0_S,
    FINGER_COLS,
    MAX_OUTPUT_LEAD_S,
    STATE_NEXT_INDEX,
    TEL_COLS,
    TEX_PROG_COLS,
)
from tpad_rt.kernel.render import render_block
from tpad_rt.kernel import table_layout
from tpad_rt.kernel.table_layout import *  # noqa: F403  (the layout, re-exported: table_layout.__all__)
from tpad_rt.kernel.table_layout import (
    TAB_CFG,
    TAB_CFG_SIZE,
    TAB_DEV,
    TAB_DEV_ROWS,
    TAB_DEV_COLS,
    TAB_STATE,
    TAB_STATE_SIZE,
    TAB_POWER_RING,
    TAB_POWER_RING_SIZE,
    TAB_FINGER,
    TAB_FINGER_ROWS,
    TAB_FINGER_COUNT,
    TAB_TELEM,
    TAB_TELEM_ROWS,
    TAB_TELEM_COUNT,
    TAB_ACTIVE_SLOT,
    TAB_SLOT_T0,
    TAB_SCRATCH,
    TAB_SCRATCH_FRAMES,
    TAB_DRIVE,
    TAB_DRIVE_FRAMES,
    TAB_STATS,
    TAB_BLOCKS,
    TAB_BLOCK_ROWS,
    TAB_FINGER_SEEN,
    TAB_SLOTS,
    SLOT_PROG,
    SLOT_PROG_ROWS,
    SLOT_PARAMS,
    SLOT_PARAMS_SIZE,
    SLOT_IMG,
    SLOT_IMG_SIZE,
    SLOT_STACK,
    SLOT_STACK_SIZE,
    SLOT_SIZE,
    STAT_CALLBACKS,
    STAT_FRAMES,
    STAT_UNDERFLOWS,
    STAT_PRIMING,
    STAT_LEAD_OVER,
    STAT_SIZE,
    BLOCK_SAMPLE_INDEX,
    BLOCK_ENTRY_NS,
    BLOCK_DAC_DELAY_NS,
    BLOCK_COMPUTE_NS,
    BLOCK_FINGER_COUNT,
    BLOCK_FRAMES,
    BLOCK_COLS,
)

#: The table's layout (kernel.table_layout), re-exported with the block functions.
__all__ = [*table_layout.__all__, "begin_block", "finish_block", "kernel_views", "texture_views", "render_into",
           "COMPILED_SOURCES"]

#: The sources compiled into a driver that renders a block (its cache stamp: cache_stamp.stamp_cache).
COMPILED_SOURCES: tuple[str | Path, ...] = (__file__, inspect.getfile(atomics), inspect.getfile(libc),
                                             *render.COMPILED_SOURCES)

_F8 = np.float64
_F4 = np.float32
_I8 = np.int64


@njit(inline="always", nogil=True, error_model="numpy")
def begin_block(table, first_sample, frames, dac_delay_ns):  # type: ignore[no-untyped-def]
    """Start a block's record: its row in the block ring (``first_sample``, entry time, ``dac_delay_ns``
    from now to the first sample at the DAC or amplifier, finger count, ``frames``). The finger count is
    load-acquired once into ``TAB_FINGER_SEEN``: the rows of those samples are then visible, and the
    kernel reads that count, not the live one. Returns (stats, row, entry time in ns)."""
    entry_ns = monotonic_ns()
    stats = numba.carray(pointer(table[TAB_STATS]), STAT_SIZE, _I8)
    blocks = numba.carray(pointer(table[TAB_BLOCKS]), (table[TAB_BLOCK_ROWS], BLOCK_COLS), _I8)
    finger_count = numba.carray(pointer(table[TAB_FINGER_COUNT]), 1, _I8)
    table[TAB_FINGER_SEEN] = load_acquire(finger_count, 0)
    row = blocks[stats[STAT_CALLBACKS] % blocks.shape[0]]
    row[BLOCK_SAMPLE_INDEX] = first_sample
    row[BLOCK_ENTRY_NS] = entry_ns
    row[BLOCK_DAC_DELAY_NS] = dac_delay_ns
    row[BLOCK_FINGER_COUNT] = table[TAB_FINGER_SEEN]
    row[BLOCK_FRAMES] = frames
    return stats, row, entry_ns


@njit(inline="always", nogil=True, error_model="numpy")
def finish_block(stats, row, entry_ns, frames, underflow, priming, lead_over):  # type: ignore[no-untyped-def]
    """Close a block's record: compute time, counters (the block count last)."""
    if lead_over:
        stats[STAT_LEAD_OVER] += 1
    if underflow:
        stats[STAT_UNDERFLOWS] += 1
    if priming:
        stats[STAT_PRIMING] += 1
    stats[STAT_FRAMES] += frames
    row[BLOCK_COMPUTE_NS] = monotonic_ns() - entry_ns
    # Last, released: a reader that acquires the count sees this block's record and the drive ring's samples
    # of it written (CallbackTable.drive_end).
    store_release(stats, STAT_CALLBACKS, stats[STAT_CALLBACKS] + 1)


@njit(inline="always", nogil=True, error_model="numpy")
def kernel_views(table):  # type: ignore[no-untyped-def]
    """Views of the render kernel's arrays the table points to, except the texture: ``(cfg, dev, state,
    power_ring, finger, finger_count, telem, telem_count)``; ``finger_count`` is the live count (a driver
    running beside producers passes the one it acquired, ``TAB_FINGER_SEEN``, instead)."""
    cfg = numba.carray(pointer(table[TAB_CFG]), table[TAB_CFG_SIZE], _F8)
    dev = numba.carray(pointer(table[TAB_DEV]), (table[TAB_DEV_ROWS], table[TAB_DEV_COLS]), _F8)
    state = numba.carray(pointer(table[TAB_STATE]), table[TAB_STATE_SIZE], _F8)
    power_ring = numba.carray(pointer(table[TAB_POWER_RING]), table[TAB_POWER_RING_SIZE], _F8)
    finger = numba.carray(pointer(table[TAB_FINGER]), (table[TAB_FINGER_ROWS], FINGER_COLS), _F8)
    finger_count = numba.carray(pointer(table[TAB_FINGER_COUNT]), 1, _I8)
    telem = numba.carray(pointer(table[TAB_TELEM]), (table[TAB_TELEM_ROWS], TEL_COLS), _F8)
    telem_count = numba.carray(pointer(table[TAB_TELEM_COUNT]), 1, _I8)
    return cfg, dev, state, power_ring, finger, finger_count, telem, telem_count


@njit(inline="always", nogil=True, error_model="numpy")
def texture_views(table, slot):  # type: ignore[no-untyped-def]
    """Views of texture slot ``slot``'s arrays (0 or 1): ``(prog, params, img, stack)``."""
    entries = table[TAB_SLOTS + slot * SLOT_SIZE: TAB_SLOTS + (slot + 1) * SLOT_SIZE]
    prog = numba.carray(pointer(entries[SLOT_PROG]), (entries[SLOT_PROG_ROWS], TEX_PROG_COLS), _I8)
    params = numba.carray(pointer(entries[SLOT_PARAMS]), entries[SLOT_PARAMS_SIZE], _F8)
    img = numba.carray(pointer(entries[SLOT_IMG]), entries[SLOT_IMG_SIZE], _F8)
    stack = numba.carray(pointer(entries[SLOT_STACK]), entries[SLOT_STACK_SIZE], _F8)
    return prog, params, img, stack


@njit(inline="always", nogil=True, error_model="numpy")
def render_into(table, state, out, frames, channels, channel, dac_delay_ns):  # type: ignore[no-untyped-def]
    """Render ``frames`` samples with the table's arrays into ``out[k * channels + channel]`` (other
    channels untouched) and the drive ring, in pieces of at most the scratch's length; the block's first sample
    plays ``dac_delay_ns`` (ns) from now (the callback's, within TAB_LEAD_BOUND_NS), which the kernel's finger
    watchdog takes off the fingers' ages (``cfg[CFG_OUTPUT_LEAD_S]`` for each piece, clamped to
    ``[0, MAX_OUTPUT_LEAD_S]``). Call it after
    :func:`begin_block` (which acquires the finger count the kernel reads)."""
    cfg, dev, _, power_ring, finger, _, telem, telem_count = kernel_views(table)
    finger_count = table[TAB_FINGER_SEEN:TAB_FINGER_SEEN + 1]  # acquired in begin_block
    active = load_acquire(table, TAB_ACTIVE_SLOT)  # the slot's contents were written before it
    prog, params, img, stack = texture_views(table, active)
    cfg[CFG_TEXTURE_T0_S] = numba.carray(pointer(table[TAB_SLOT_T0]), 2, _F8)[active]
    scratch = numba.carray(pointer(table[TAB_SCRATCH]), table[TAB_SCRATCH_FRAMES], _F4)
    drive = numba.carray(pointer(table[TAB_DRIVE]), table[TAB_DRIVE_FRAMES], _F4)
    lead_s = dac_delay_ns * 1e-9
    lead_s = min(lead_s, MAX_OUTPUT_LEAD_S) if lead_s > 0.0 else 0.0  # NaN: 0
    done = 0
    while done < frames:
        cfg[CFG_OUTPUT_LEAD_S] = min(lead_s + done / cfg[CFG_FS_HZ], MAX_OUTPUT_LEAD_S)
        count = min(frames - done, scratch.shape[0])
        piece = scratch[:count]
        start = int(state[STATE_NEXT_INDEX])
        render_block(piece, start, cfg, dev, state, power_ring, finger, finger_count,
                     prog, params, img, stack, telem, telem_count)
        for k in range(count):
            out[(done + k) * channels + channel] = piece[k]
            drive[(start + k) % drive.shape[0]] = piece[k]
        done += count


