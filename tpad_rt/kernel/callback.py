"""The real-time audio callback: a numba ``@cfunc`` with PortAudio's callback signature.

API map
-------
render_callback, silence_callback
    ``@cfunc``s of type ``PaStreamCallback``: ``.address`` goes to ``Pa_OpenStream``
    with ``userData`` = the address of a pointer table (int64 ``[TAB_SIZE]``, below).
    Each is compiled (or loaded from numba's cache) on first use, not when this module is
    imported: a command that refuses its arguments never pays for it.
    ``render_callback`` renders the drive with :func:`tpad_rt.kernel.render.render_block`;
    ``silence_callback`` writes zeros (the empty-callback baseline of the tests and
    benchmarks). Both keep the same statistics.
TAB_*, SLOT_*, STAT_*, BLOCK_*
    the layout of the pointer table, the statistics and the per-block record ring

docs/realtime.md is the design. A callback receives only raw pointers; it rebuilds
each array with ``numba.carray`` from an address and a size in the table (views: no
allocation, no reference counting, no Python object), never raises and returns
``paContinue`` (0). The table, and every array it points to, is owned by the Python
side (``tpad_rt.engine.Renderer``) and must outlive the stream.

The pointer table (int64; addresses are ``ndarray.ctypes.data``):

- the render kernel's arrays except the texture (``TAB_CFG`` .. ``TAB_TELEM_ROWS``,
  addresses and the sizes a view needs);
- two texture slots at ``TAB_SLOTS + k * SLOT_SIZE``: prog, params, img and stack
  addresses and sizes; ``TAB_ACTIVE_SLOT`` says which one is rendered. The texture's
  start time ``t0_s`` lives with each slot in the float64 array at ``TAB_SLOT_T0``
  and is copied into ``cfg[CFG_TEXTURE_T0_S]`` at each callback, so a texture and its
  time origin change together;
- the output: ``TAB_CHANNELS`` interleaved channels, the drive in ``TAB_CHANNEL``
  (0-based), zeros in the others; a mono scratch buffer (``TAB_SCRATCH``,
  ``TAB_SCRATCH_FRAMES``) the kernel renders into, in pieces if a callback asks for more;
- a drive ring (float32, ``TAB_DRIVE``, ``TAB_DRIVE_FRAMES``) holding the last samples
  rendered (sample ``n`` at ``n % frames``), for recordings;
- the statistics (int64 ``[STAT_SIZE]``) and the per-block record ring (int64
  ``[TAB_BLOCK_ROWS, BLOCK_COLS]``, row ``callbacks % rows``);
- ``TAB_FINGER_SEEN``: the finger count the running callback acquired (below).

The Python side publishes with release stores (:func:`tpad_rt.kernel.atomics.publish`)
and the callback reads with acquire loads, so it never sees an index before the data
it covers, on any CPU: a whole idle slot, then ``TAB_ACTIVE_SLOT`` (read once per
callback); a finger row, then ``finger_count`` (acquired once per callback into
``TAB_FINGER_SEEN``, which the kernel reads in its place).
"""

from __future__ import annotations

import functools

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from tpad_rt.kernel import atomics, render
from tpad_rt.kernel.atomics import load_acquire
from tpad_rt.kernel.cache_stamp import stamp_cache
from tpad_rt.kernel.layout import CFG_TEXTURE_T0_S, FINGER_COLS, STATE_NEXT_INDEX, TEL_COLS, TEX_PROG_COLS
from tpad_rt.kernel.render import render_block

# --- pointer table: int64[TAB_SIZE] ----------------------------------------------
TAB_CFG = 0                   # cfg [TAB_CFG_SIZE]
TAB_CFG_SIZE = 1
TAB_DEV = 2                   # dev [DEV_ROWS, TAB_DEV_COLS]
TAB_DEV_ROWS = 3
TAB_DEV_COLS = 4
TAB_STATE = 5
TAB_STATE_SIZE = 6
TAB_POWER_RING = 7
TAB_POWER_RING_SIZE = 8
TAB_FINGER = 9                # finger [TAB_FINGER_ROWS, FINGER_COLS]
TAB_FINGER_ROWS = 10
TAB_FINGER_COUNT = 11
TAB_TELEM = 12                # telem [TAB_TELEM_ROWS, TEL_COLS]
TAB_TELEM_ROWS = 13
TAB_TELEM_COUNT = 14
TAB_ACTIVE_SLOT = 15          # 0 or 1: the texture slot rendered
TAB_SLOT_T0 = 16              # float64[2]: each slot's texture start time (s, stream clock)
TAB_CHANNELS = 17             # interleaved output channels
TAB_CHANNEL = 18              # the channel the drive goes to (0-based)
TAB_SCRATCH = 19              # float32[TAB_SCRATCH_FRAMES]: mono render buffer
TAB_SCRATCH_FRAMES = 20
TAB_DRIVE = 21                # float32[TAB_DRIVE_FRAMES]: ring of the last rendered samples
TAB_DRIVE_FRAMES = 22
TAB_STATS = 23                # int64[STAT_SIZE]
TAB_BLOCKS = 24               # int64[TAB_BLOCK_ROWS, BLOCK_COLS]
TAB_BLOCK_ROWS = 25
TAB_FINGER_SEEN = 26          # finger_count as this callback acquired it (written by the callback)
TAB_SLOTS = 27                # two texture slots of SLOT_SIZE entries each
# --- a texture slot: offsets from TAB_SLOTS + k * SLOT_SIZE -------------------------
SLOT_PROG = 0                 # prog [SLOT_PROG_ROWS, TEX_PROG_COLS] int64
SLOT_PROG_ROWS = 1
SLOT_PARAMS = 2               # float64[SLOT_PARAMS_SIZE]
SLOT_PARAMS_SIZE = 3
SLOT_IMG = 4                  # float64[SLOT_IMG_SIZE]
SLOT_IMG_SIZE = 5
SLOT_STACK = 6                # float64[SLOT_STACK_SIZE]: the texture's evaluation scratch
SLOT_STACK_SIZE = 7
SLOT_SIZE = 8
TAB_SIZE = TAB_SLOTS + 2 * SLOT_SIZE

# --- statistics: int64[STAT_SIZE], written by the callback -----------------------
STAT_CALLBACKS = 0            # callbacks so far (written last in a callback)
STAT_FRAMES = 1               # frames written so far
STAT_UNDERFLOWS = 2           # callbacks whose statusFlags had paOutputUnderflow
STAT_PRIMING = 3              # callbacks with paPrimingOutput
STAT_SIZE = 4

# --- per-block records: int64[rows, BLOCK_COLS], row callbacks % rows -----------
BLOCK_SAMPLE_INDEX = 0        # stream sample index of the block's first sample
BLOCK_ENTRY_NS = 1            # CLOCK_MONOTONIC (ns) at callback entry
BLOCK_DAC_DELAY_NS = 2        # outputBufferDacTime - currentTime (ns): entry to first sample at the DAC
BLOCK_COMPUTE_NS = 3          # time spent in the callback (ns)
BLOCK_FINGER_COUNT = 4        # finger samples written when the block started
BLOCK_FRAMES = 5              # frames of the block
BLOCK_COLS = 6

#: PortAudio's paOutputUnderflow and paPrimingOutput status flags, and paContinue.
PA_OUTPUT_UNDERFLOW = 0x4
PA_PRIMING_OUTPUT = 0x10
PA_CONTINUE = 0
#: Linux clock id of CLOCK_MONOTONIC (the clock of Python's ``time.monotonic_ns``).
CLOCK_MONOTONIC = 1

_F8 = np.float64
_F4 = np.float32
_I8 = np.int64

# render_block and everything it inlines is compiled into these callbacks: their disk
# cache is stamped with this file and every source render.py stamps its own with.
stamp_cache(__file__, atomics.__file__, *render.COMPILED_SOURCES)


@intrinsic
def _pointer(typingctx, address):  # type: ignore[no-untyped-def]
    """The ``void*`` at integer ``address`` (an inttoptr; no call, no allocation)."""
    signature = types.voidptr(types.int64)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        return builder.inttoptr(args[0], cgutils.voidptr_t)

    return signature, codegen


@intrinsic
def _monotonic_ns(typingctx):  # type: ignore[no-untyped-def]
    """CLOCK_MONOTONIC in ns, from libc's ``clock_gettime`` into a stack ``timespec``.

    The symbol is resolved when the code is loaded (not baked in as an address), so
    the callback stays cacheable; the timespec is on the stack, not the heap.
    """
    signature = types.int64()

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        i32, i64 = ir.IntType(32), ir.IntType(64)
        timespec = ir.LiteralStructType([i64, i64])
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(i32, [i32, timespec.as_pointer()]), "clock_gettime")
        slot = cgutils.alloca_once(builder, timespec)
        builder.call(function, [ir.Constant(i32, CLOCK_MONOTONIC), slot])
        seconds = builder.load(cgutils.gep_inbounds(builder, slot, 0, 0))
        nanoseconds = builder.load(cgutils.gep_inbounds(builder, slot, 0, 1))
        return builder.add(builder.mul(seconds, ir.Constant(i64, 1_000_000_000)), nanoseconds)

    return signature, codegen


@numba.njit(inline="always", nogil=True, error_model="numpy")
def _begin(table, first_sample, frames, time_info):  # type: ignore[no-untyped-def]
    """Start a callback's record: its row in the block ring (``first_sample``, entry time, DAC delay,
    finger count, ``frames``). The finger count is load-acquired once into ``TAB_FINGER_SEEN``: the
    rows of those samples are then visible, and the kernel reads that count, not the live one."""
    entry_ns = _monotonic_ns()
    stats = numba.carray(_pointer(table[TAB_STATS]), STAT_SIZE, _I8)
    blocks = numba.carray(_pointer(table[TAB_BLOCKS]), (table[TAB_BLOCK_ROWS], BLOCK_COLS), _I8)
    times = numba.carray(time_info, 3, _F8)  # PaStreamCallbackTimeInfo: adc, current, dac (s)
    finger_count = numba.carray(_pointer(table[TAB_FINGER_COUNT]), 1, _I8)
    table[TAB_FINGER_SEEN] = load_acquire(finger_count, 0)
    row = blocks[stats[STAT_CALLBACKS] % blocks.shape[0]]
    row[BLOCK_SAMPLE_INDEX] = first_sample
    row[BLOCK_ENTRY_NS] = entry_ns
    row[BLOCK_DAC_DELAY_NS] = np.int64((times[2] - times[1]) * 1e9)
    row[BLOCK_FINGER_COUNT] = table[TAB_FINGER_SEEN]
    row[BLOCK_FRAMES] = frames
    return stats, row, entry_ns


@numba.njit(inline="always", nogil=True, error_model="numpy")
def _finish(stats, row, entry_ns, frames, status_flags):  # type: ignore[no-untyped-def]
    """Close a callback's record: compute time, counters (the callback count last)."""
    if status_flags & PA_OUTPUT_UNDERFLOW:
        stats[STAT_UNDERFLOWS] += 1
    if status_flags & PA_PRIMING_OUTPUT:
        stats[STAT_PRIMING] += 1
    stats[STAT_FRAMES] += frames
    row[BLOCK_COMPUTE_NS] = _monotonic_ns() - entry_ns
    stats[STAT_CALLBACKS] += 1


_SIGNATURE = types.int32(types.voidptr, types.voidptr, types.uint64, types.voidptr, types.uint64, types.voidptr)


def _silence(input_buffer, output_buffer, frames, time_info, status_flags, user_data):  # type: ignore[no-untyped-def]
    """Write zeros to every channel; keep the statistics (the empty-callback baseline)."""
    table = numba.carray(user_data, TAB_SIZE, _I8)
    stats = numba.carray(_pointer(table[TAB_STATS]), STAT_SIZE, _I8)
    stats, row, entry_ns = _begin(table, stats[STAT_FRAMES], frames, time_info)
    out = numba.carray(output_buffer, frames * table[TAB_CHANNELS], _F4)
    for i in range(out.shape[0]):
        out[i] = 0.0
    _finish(stats, row, entry_ns, frames, status_flags)
    return PA_CONTINUE


def _render(input_buffer, output_buffer, frames, time_info, status_flags, user_data):  # type: ignore[no-untyped-def]
    """Render ``frames`` drive samples into the table's channel (zeros elsewhere); keep the statistics."""
    table = numba.carray(user_data, TAB_SIZE, _I8)
    state = numba.carray(_pointer(table[TAB_STATE]), table[TAB_STATE_SIZE], _F8)
    stats, row, entry_ns = _begin(table, np.int64(state[STATE_NEXT_INDEX]), frames, time_info)
    cfg = numba.carray(_pointer(table[TAB_CFG]), table[TAB_CFG_SIZE], _F8)
    dev = numba.carray(_pointer(table[TAB_DEV]), (table[TAB_DEV_ROWS], table[TAB_DEV_COLS]), _F8)
    power_ring = numba.carray(_pointer(table[TAB_POWER_RING]), table[TAB_POWER_RING_SIZE], _F8)
    finger = numba.carray(_pointer(table[TAB_FINGER]), (table[TAB_FINGER_ROWS], FINGER_COLS), _F8)
    finger_count = table[TAB_FINGER_SEEN:TAB_FINGER_SEEN + 1]  # acquired in _begin
    telem = numba.carray(_pointer(table[TAB_TELEM]), (table[TAB_TELEM_ROWS], TEL_COLS), _F8)
    telem_count = numba.carray(_pointer(table[TAB_TELEM_COUNT]), 1, _I8)
    active = load_acquire(table, TAB_ACTIVE_SLOT)  # the slot's contents were written before it
    slot = table[TAB_SLOTS + active * SLOT_SIZE: TAB_SLOTS + (active + 1) * SLOT_SIZE]
    prog = numba.carray(_pointer(slot[SLOT_PROG]), (slot[SLOT_PROG_ROWS], TEX_PROG_COLS), _I8)
    params = numba.carray(_pointer(slot[SLOT_PARAMS]), slot[SLOT_PARAMS_SIZE], _F8)
    img = numba.carray(_pointer(slot[SLOT_IMG]), slot[SLOT_IMG_SIZE], _F8)
    stack = numba.carray(_pointer(slot[SLOT_STACK]), slot[SLOT_STACK_SIZE], _F8)
    cfg[CFG_TEXTURE_T0_S] = numba.carray(_pointer(table[TAB_SLOT_T0]), 2, _F8)[active]
    scratch = numba.carray(_pointer(table[TAB_SCRATCH]), table[TAB_SCRATCH_FRAMES], _F4)
    drive = numba.carray(_pointer(table[TAB_DRIVE]), table[TAB_DRIVE_FRAMES], _F4)
    channels = table[TAB_CHANNELS]
    channel = table[TAB_CHANNEL]
    out = numba.carray(output_buffer, frames * channels, _F4)
    for i in range(out.shape[0]):
        out[i] = 0.0
    done = 0
    while done < frames:
        count = min(frames - done, scratch.shape[0])
        piece = scratch[:count]
        start = np.int64(state[STATE_NEXT_INDEX])
        render_block(piece, start, cfg, dev, state, power_ring, finger, finger_count,
                     prog, params, img, stack, telem, telem_count)
        for k in range(count):
            out[(done + k) * channels + channel] = piece[k]
            drive[(start + k) % drive.shape[0]] = piece[k]
        done += count
    _finish(stats, row, entry_ns, frames, status_flags)
    return PA_CONTINUE


#: The callbacks' Python sources, by their public names.
_SOURCES = {"render_callback": _render, "silence_callback": _silence}


@functools.cache
def _compiled(name: str) -> numba.core.ccallback.CFunc:
    """The ``@cfunc`` ``name`` (a key of _SOURCES), compiled or loaded from numba's cache once."""
    return numba.cfunc(_SIGNATURE, nopython=True, cache=True, error_model="numpy")(_SOURCES[name])


def __getattr__(name: str) -> numba.core.ccallback.CFunc:
    """``render_callback`` and ``silence_callback``, compiled on first use (module docstring)."""
    if name in _SOURCES:
        return _compiled(name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
