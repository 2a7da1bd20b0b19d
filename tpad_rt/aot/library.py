"""The ahead-of-time library, loaded with ctypes, or numba's JIT callbacks in its place.

API map
-------
load() -> AotLibrary | None
    the library built for the current stamp (:func:`tpad_rt.aot.stamp.library_stamp`), loaded
    once per process; None when there is none, it does not load, lacks a symbol or carries
    another stamp, or when ``NUMBA_DISABLE_JIT`` is set (the kernels then run as Python)
AotLibrary
    ``.path``; ``.render_callback``, ``.silence_callback`` (:class:`NativeCallback`);
    ``.publish(array, index, value)``
NativeCallback
    ``.address`` (int) and ``.ctypes`` (a ctypes function of PortAudio's callback type): the
    attributes of a numba ``@cfunc`` the drivers use
render_callback() / silence_callback()
    the library's callback when it loads, else numba's ``@cfunc`` (compiled or loaded from its cache)
publish(array, index, value)
    ``array[index] = value`` as a release store: the library's, else :func:`tpad_rt.kernel.atomics.publish`

Nothing here imports numba unless the library is missing: with it, a renderer starts
without numba (docs/kernel.md "Ahead-of-time kernels").
"""

from __future__ import annotations

import ctypes
import functools
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tpad_rt.aot.stamp import library_dirs, library_name, library_stamp

#: The library's exported symbols: the two callbacks, the release store, the stamp (a C string).
RENDER_SYMBOL = "tpad_rt_render"
SILENCE_SYMBOL = "tpad_rt_silence"
PUBLISH_SYMBOL = "tpad_rt_publish"
STAMP_SYMBOL = "tpad_rt_aot_stamp"
#: PortAudio's PaStreamCallback: int(const void *input, void *output, unsigned long frames,
#: const PaStreamCallbackTimeInfo *time_info, PaStreamCallbackFlags flags, void *user_data).
CALLBACK_TYPE = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint64,
                                 ctypes.c_void_p, ctypes.c_uint64, ctypes.c_void_p)
_PUBLISH_TYPE = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int64, ctypes.c_int64)


@dataclass(frozen=True)
class NativeCallback:
    """A callback in the library: its ``address`` and a ctypes function at it (which releases the GIL)."""

    address: int
    ctypes: Any


class AotLibrary:
    """The loaded library at ``path``, whose stamp was checked."""

    def __init__(self, path: Path, handle: ctypes.CDLL):
        self.path = path
        self._handle = handle  # keeps the library mapped while its addresses are in use
        self.render_callback = _callback(handle, RENDER_SYMBOL)
        self.silence_callback = _callback(handle, SILENCE_SYMBOL)
        self._publish = _PUBLISH_TYPE(_address(handle, PUBLISH_SYMBOL))

    def publish(self, array: np.ndarray, index: int, value: int) -> None:
        """``array[index] = value`` (C-contiguous int64 1-D ``array``; ``index`` within it, unchecked beyond
        that) as a release store. Raises ValueError for another array."""
        if array.dtype != np.int64 or array.ndim != 1 or not array.flags.c_contiguous:
            raise ValueError("publish: the array must be a C-contiguous 1-D int64 array")
        if not 0 <= index < array.shape[0]:
            raise IndexError(f"publish: index {index} outside [0, {array.shape[0]})")
        self._publish(array.ctypes.data, index, value)


def _address(handle: ctypes.CDLL, symbol: str) -> int:
    """The address of ``symbol`` in ``handle``; AttributeError when it lacks it."""
    return int(ctypes.cast(getattr(handle, symbol), ctypes.c_void_p).value or 0)


def _callback(handle: ctypes.CDLL, symbol: str) -> NativeCallback:
    """The PortAudio callback ``symbol`` of ``handle``."""
    address = _address(handle, symbol)
    return NativeCallback(address, CALLBACK_TYPE(address))


def open_library(path: Path, stamp: str) -> AotLibrary | None:
    """The library at ``path`` if it loads, exports every symbol and carries ``stamp``; else None."""
    try:
        handle = ctypes.CDLL(str(path))
        carried = ctypes.string_at(ctypes.addressof(ctypes.c_char.in_dll(handle, STAMP_SYMBOL)))
        if carried != stamp.encode():
            return None
        return AotLibrary(path, handle)
    except (OSError, AttributeError, ValueError):  # not loadable, or a symbol missing
        return None


@functools.cache
def load() -> AotLibrary | None:
    """The library for the current stamp, once per process (module docstring)."""
    if os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0"):
        return None
    stamp = library_stamp()
    for folder in library_dirs():
        path = folder / library_name(stamp)
        if path.is_file():
            return open_library(path, stamp)
    return None


def render_callback() -> Any:
    """The render callback: the library's, else numba's ``@cfunc`` (``.address``, ``.ctypes``)."""
    library = load()
    if library is not None:
        return library.render_callback
    from tpad_rt.kernel import callback

    return callback.render_callback


def silence_callback() -> Any:
    """The callback writing zeros: the library's, else numba's ``@cfunc`` (``.address``, ``.ctypes``)."""
    library = load()
    if library is not None:
        return library.silence_callback
    from tpad_rt.kernel import callback

    return callback.silence_callback


def publish(array: np.ndarray, index: int, value: int) -> None:
    """``array[index] = value`` (int64 1-D ``array``) as a release store: everything this thread wrote before
    is visible to a reader that load-acquires the element and sees ``value``."""
    library = load()
    if library is not None:
        library.publish(array, index, value)
        return
    from tpad_rt.kernel import atomics

    atomics.publish(array, index, value)
