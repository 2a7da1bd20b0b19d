"""Acquire loads and release stores on int64 array elements: publishing data to the audio callback.

The Python side publishes data to the audio callback by writing it, then storing a
count or an index the callback reads first (a finger sample, then ``finger_count``;
a texture slot, then ``TAB_ACTIVE_SLOT``). That is only safe if the callback cannot
see the new index before the data: x86-64 keeps stores (and loads) in program order,
but ARM64 and other weakly ordered CPUs do not, and a compiler may reorder plain
accesses. The store of the index is therefore a *release* store (every write before
it is visible before it) and the callback's load of it an *acquire* load (nothing
after it is read before it); on x86-64 both compile to plain moves that the compiler
may not reorder across.

API map
-------
load_acquire(array, index) -> int64
    ``@intrinsic`` for compiled code: an acquire load of ``array[index]`` (int64, 1-D)
store_release(array, index, value)
    ``@intrinsic`` for compiled code: a release store of ``value`` into ``array[index]``
publish(array, index, value)
    from Python: ``array[index] = value`` as a release store (a compiled call; a plain
    store when ``NUMBA_DISABLE_JIT`` is set, where nothing runs concurrently compiled)
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from numba import types
from numba.core import cgutils
from tpad_rt.kernel.jit import njit
from tpad_rt.kernel.jit import intrinsic

#: Bytes of an int64: the alignment of the atomic accesses.
_INT64_BYTES = 8


def _element_pointer(context: Any, builder: Any, array_type: Any, array: Any, index_type: Any, index: Any) -> Any:
    """The LLVM pointer to ``array[index]`` (no bounds or negative-index handling: callers own the index)."""
    view = context.make_array(array_type)(context, builder, array)
    position = context.cast(builder, index, index_type, types.intp)
    return cgutils.get_item_pointer(context, builder, array_type, view, [position], wraparound=False)


def _int64_vector(array: Any, index: Any) -> bool:
    """True for a 1-D int64 array and an integer index (the only operands these intrinsics accept)."""
    return (isinstance(array, types.Array) and array.ndim == 1 and array.dtype == types.int64
            and isinstance(index, types.Integer))


@intrinsic
def load_acquire(typingctx, array, index):  # type: ignore[no-untyped-def]
    """``array[index]`` read with acquire ordering (int64 arrays only)."""
    if not _int64_vector(array, index):
        return None
    signature = types.int64(array, index)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        pointer = _element_pointer(context, builder, sig.args[0], args[0], sig.args[1], args[1])
        return builder.load_atomic(pointer, "acquire", _INT64_BYTES)

    return signature, codegen


@intrinsic
def store_release(typingctx, array, index, value):  # type: ignore[no-untyped-def]
    """``array[index] = value`` written with release ordering (int64 arrays only)."""
    if not (_int64_vector(array, index) and isinstance(value, types.Integer)):
        return None
    signature = types.void(array, index, value)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        pointer = _element_pointer(context, builder, sig.args[0], args[0], sig.args[1], args[1])
        stored = context.cast(builder, args[2], sig.args[2], types.int64)
        builder.store_atomic(stored, pointer, "release", _INT64_BYTES)
        return context.get_dummy_value()

    return signature, codegen


@njit(cache=True, nogil=True)
def _publish(array, index, value):  # type: ignore[no-untyped-def]
    store_release(array, index, value)


def publish(array: np.ndarray, index: int, value: int) -> None:
    """``array[index] = value`` (int64 1-D array) as a release store: everything this thread wrote before
    is visible to a reader that load-acquires the element and sees ``value``."""
    if numba.config.DISABLE_JIT:  # type: ignore[attr-defined]  # read from the environment; not in its stubs
        array[index] = value
    else:
        _publish(array, np.int64(index), np.int64(value))
