"""The real-time audio callback: a numba ``@cfunc`` with PortAudio's callback signature.

API map
-------
render_callback, silence_callback
    ``@cfunc``s of type ``PaStreamCallback``: ``.address`` goes to ``Pa_OpenStream``
    with ``userData`` = the address of a pointer table (int64 ``[TAB_SIZE]``, laid out in
    :mod:`tpad_rt.kernel.table`). Each is compiled (or loaded from numba's cache) on first
    use, not when this module is imported: a command that refuses its arguments never
    pays for it. ``render_callback`` renders the drive with
    :func:`tpad_rt.kernel.table.render_into`; ``silence_callback`` writes zeros (the
    empty-callback baseline of the tests and benchmarks). Both keep the same statistics.
BLOCK_LATE, BLOCK_PRIMING
    the status flags a caller passes with a block (the callback's contract with every
    caller: PortAudio, and the serial streamer, which calls it once per frame)

docs/realtime.md is the design. A callback receives only raw pointers, never raises
and returns ``paContinue`` (0). It writes zeros to every channel but the drive's.
"""

from __future__ import annotations

import functools

import numba
import numpy as np
from numba import types

from tpad_rt.kernel.jit import njit
from tpad_rt.kernel import table as tab
from tpad_rt.kernel.cache_stamp import stamp_cache
from tpad_rt.kernel.layout import STATE_NEXT_INDEX
from tpad_rt.kernel.libc import pointer
from tpad_rt.kernel.table import (
    STAT_FRAMES,
    STAT_SIZE,
    TAB_CHANNEL,
    TAB_CHANNELS,
    TAB_LEAD_BOUND_NS,
    TAB_SIZE,
    TAB_STATE,
    TAB_STATE_SIZE,
    TAB_STATS,
    begin_block,
    finish_block,
    render_into,
)

#: The status flags of a block, bits of the callback's ``status_flags``: BLOCK_LATE, the output fell behind
#: before this block (counted as an underflow: PortAudio's output underflowed, the serial stream skipped
#: ahead); BLOCK_PRIMING, the block fills the output's buffer before it plays (PortAudio priming its
#: buffers, a serial amplifier's prefill). Other bits are ignored. The values are PortAudio's
#: paOutputUnderflow and paPrimingOutput, since PortAudio calls the callback with its own flags.
BLOCK_LATE = 0x4
BLOCK_PRIMING = 0x10
#: PortAudio's paContinue: what the callback returns.
PA_CONTINUE = 0
_F8 = np.float64
_F4 = np.float32
_I8 = np.int64

# render_block and everything it inlines is compiled into these callbacks: their disk
# cache is stamped with this file and every source the table's block compiles in.
stamp_cache(__file__, *tab.COMPILED_SOURCES)

_SIGNATURE = types.int32(types.voidptr, types.voidptr, types.uint64, types.voidptr, types.uint64, types.voidptr)


@njit(inline="always", nogil=True, error_model="numpy")
def _dac_delay_ns(time_info, table):  # type: ignore[no-untyped-def]
    """outputBufferDacTime - currentTime (ns) of PortAudio's PaStreamCallbackTimeInfo (adc, current, dac; s),
    within ``[0, table[TAB_LEAD_BOUND_NS]]``, and whether it was above that bound or not a number:
    ``(delay_ns, over)`` (a negative delay is 0, not over)."""
    times = numba.carray(time_info, 3, _F8)
    delay_ns = (times[2] - times[1]) * 1e9
    bound_ns = table[TAB_LEAD_BOUND_NS]
    if not delay_ns <= bound_ns:  # NaN too
        return np.int64(bound_ns), True
    return np.int64(delay_ns) if delay_ns > 0.0 else np.int64(0), False


def _silence(input_buffer, output_buffer, frames, time_info, status_flags, user_data):  # type: ignore[no-untyped-def]
    """Write zeros to every channel; keep the statistics (the empty-callback baseline)."""
    table = numba.carray(user_data, TAB_SIZE, _I8)
    stats = numba.carray(pointer(table[TAB_STATS]), STAT_SIZE, _I8)
    delay_ns, lead_over = _dac_delay_ns(time_info, table)
    stats, row, entry_ns = begin_block(table, stats[STAT_FRAMES], frames, delay_ns)
    out = numba.carray(output_buffer, frames * table[TAB_CHANNELS], _F4)
    for i in range(out.shape[0]):
        out[i] = 0.0
    finish_block(stats, row, entry_ns, frames, status_flags & BLOCK_LATE, status_flags & BLOCK_PRIMING, lead_over)
    return PA_CONTINUE


def _render(input_buffer, output_buffer, frames, time_info, status_flags, user_data):  # type: ignore[no-untyped-def]
    """Render ``frames`` drive samples into the table's channel (zeros elsewhere); keep the statistics. The
    block's lead is its reported delay within the driver's bound (:func:`_dac_delay_ns`)."""
    table = numba.carray(user_data, TAB_SIZE, _I8)
    state = numba.carray(pointer(table[TAB_STATE]), table[TAB_STATE_SIZE], _F8)
    delay_ns, lead_over = _dac_delay_ns(time_info, table)
    stats, row, entry_ns = begin_block(table, np.int64(state[STATE_NEXT_INDEX]), frames, delay_ns)
    channels = table[TAB_CHANNELS]
    out = numba.carray(output_buffer, frames * channels, _F4)
    for i in range(out.shape[0]):
        out[i] = 0.0
    render_into(table, state, out, frames, channels, table[TAB_CHANNEL], delay_ns)
    finish_block(stats, row, entry_ns, frames, status_flags & BLOCK_LATE, status_flags & BLOCK_PRIMING, lead_over)
    return PA_CONTINUE


#: The callbacks' Python sources, by their public names.
_SOURCES = {"render_callback": _render, "silence_callback": _silence}


@functools.cache
def _compiled(name: str) -> numba.core.ccallback.CFunc:
    """The ``@cfunc`` ``name`` (a key of _SOURCES), compiled or loaded from numba's cache once."""
    return numba.cfunc(_SIGNATURE, cache=True, error_model="numpy")(_SOURCES[name])  # a cfunc is nopython


def __getattr__(name: str) -> numba.core.ccallback.CFunc:
    """``render_callback`` and ``silence_callback``, compiled on first use (module docstring)."""
    if name in _SOURCES:
        return _compiled(name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
