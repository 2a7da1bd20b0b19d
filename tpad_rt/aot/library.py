"""The ahead-of-time library, checked and loaded with ctypes, or numba's JIT callbacks in its place.

API map
-------
find(folders=None) -> Found
    the file for the current stamp (:func:`tpad_rt.aot.stamp.library_stamp`) in the first of ``folders``
    (default :func:`tpad_rt.aot.stamp.library_dirs`) that has one: ``.path`` (None: none there),
    ``.library`` (:class:`AotLibrary`, or None) and ``.problem`` (why the file there was not loaded, or None).
    Never raises for what the file holds, and never maps a byte it has not checked
load() -> AotLibrary | None
    :func:`find`'s library, once per process; when the file there was refused, one line on stderr says why
    (``tpad-rt warm`` rebuilds it). None when ``NUMBA_DISABLE_JIT`` is set (the kernels then run as Python)
open_library(path, stamp) -> AotLibrary
    the library at ``path`` after every check below; LibraryProblem (its message: what was wrong) otherwise
seal(body) -> bytes
    a built library's bytes with the seal the loader checks appended
AotLibrary
    ``.path``; ``.render_callback``, ``.silence_callback`` (:class:`NativeCallback`);
    ``.publish(array, index, value)``; ``.errors()`` (raises the callbacks met)
NativeCallback
    ``.address`` (int) and ``.ctypes`` (a ctypes function of PortAudio's callback type): the
    attributes of a numba ``@cfunc`` the drivers use
render_callback() / silence_callback()
    the library's callback when it loads, else numba's ``@cfunc`` (compiled or loaded from its cache)
publish(array, index, value)
    ``array[index] = value`` as a release store: the library's, else :func:`tpad_rt.kernel.atomics.publish`

The checks, before the dynamic loader sees a byte (a file cut short would otherwise kill the process with
SIGBUS in ``dlopen``): a regular file of at most MAX_LIBRARY_BYTES; its last SEAL_BYTES are SEAL_TAG and the
SHA-256 of every byte before them (the builder appends them, :func:`seal`); those bytes are an ELF shared
object whose program headers and segments lie within them; they hold the stamp. The checked bytes are then
loaded from an anonymous in-memory file (``memfd_create``), so a later change to the file on disk cannot
reach the mapped code (the file itself where that is refused). After loading: every symbol is there, at a
non-zero address, and the stamp the library carries is the current one.

Nothing here imports numba unless the library is missing: with it, a renderer starts
without numba (docs/kernel.md "Ahead-of-time kernels").
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import stat
import struct
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tpad_rt.aot.stamp import library_dirs, library_name, library_stamp

#: The library's exported symbols: the two callbacks, the release store, the stamp (a C string), the error count.
RENDER_SYMBOL = "tpad_rt_render"
SILENCE_SYMBOL = "tpad_rt_silence"
PUBLISH_SYMBOL = "tpad_rt_publish"
STAMP_SYMBOL = "tpad_rt_aot_stamp"
ERRORS_SYMBOL = "tpad_rt_aot_errors"
#: PortAudio's PaStreamCallback: int(const void *input, void *output, unsigned long frames,
#: const PaStreamCallbackTimeInfo *time_info, PaStreamCallbackFlags flags, void *user_data).
CALLBACK_TYPE = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint64,
                                 ctypes.c_void_p, ctypes.c_uint64, ctypes.c_void_p)
_PUBLISH_TYPE = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int64, ctypes.c_int64)
#: The seal at a library's end: this tag, then the SHA-256 of every byte before the tag.
SEAL_TAG = b"\0tpad-rt aot seal 1\0"
SEAL_BYTES = len(SEAL_TAG) + hashlib.sha256().digest_size
#: The largest file taken for a library (a built one is about 100 kB).
MAX_LIBRARY_BYTES = 32 << 20
#: ELF header fields: the class (32- or 64-bit) -> (program header offset, entry size and count formats,
#: their offsets, a program header's format, the indices of its type, file offset and file size).
_ELF_LAYOUTS = {1: ("I", 28, 42, "IIIIIIII", (0, 1, 4)), 2: ("Q", 32, 54, "IIQQQQQQ", (0, 2, 5))}
_ELF_SHARED_OBJECT = 3


class LibraryProblem(Exception):
    """A library file that is not loaded; the message says what it is (``is cut short ...``)."""


@dataclass(frozen=True)
class NativeCallback:
    """A callback in the library: its ``address`` and a ctypes function at it (which releases the GIL)."""

    address: int
    ctypes: Any


class AotLibrary:
    """The loaded library read from ``path``, whose seal, stamp and symbols were checked."""

    def __init__(self, path: Path, handle: ctypes.CDLL):
        self.path = path
        self._handle = handle  # keeps the library mapped while its addresses are in use
        self.render_callback = _callback(handle, RENDER_SYMBOL)
        self.silence_callback = _callback(handle, SILENCE_SYMBOL)
        self._publish = _PUBLISH_TYPE(_address(handle, PUBLISH_SYMBOL))
        self._errors = ctypes.c_int64.from_address(_address(handle, ERRORS_SYMBOL))

    def publish(self, array: np.ndarray, index: int, value: int) -> None:
        """``array[index] = value`` (C-contiguous int64 1-D ``array``; ``index`` within it, unchecked beyond
        that) as a release store. Raises ValueError for another array."""
        if array.dtype != np.int64 or array.ndim != 1 or not array.flags.c_contiguous:
            raise ValueError("publish: the array must be a C-contiguous 1-D int64 array")
        if not 0 <= index < array.shape[0]:
            raise IndexError(f"publish: index {index} outside [0, {array.shape[0]})")
        self._publish(array.ctypes.data, index, value)

    def errors(self) -> int:
        """How many times a callback met a raise (numba's JIT callback would have printed each as "unraisable";
        the library counts them instead: docs/kernel.md "Ahead-of-time kernels")."""
        return int(self._errors.value)


@dataclass(frozen=True)
class Found:
    """What :func:`find` found: the file at the stamp's name (None: none), its library, or why it was refused."""

    path: Path | None
    library: AotLibrary | None
    problem: str | None


def _address(handle: ctypes.CDLL, symbol: str) -> int:
    """The address of ``symbol`` in ``handle``; LibraryProblem when it lacks it or it is at 0."""
    try:
        address = ctypes.cast(getattr(handle, symbol), ctypes.c_void_p).value
    except AttributeError:
        raise LibraryProblem(f"lacks the symbol {symbol}") from None
    if not address:
        raise LibraryProblem(f"has the symbol {symbol} at address 0")
    return int(address)


def _callback(handle: ctypes.CDLL, symbol: str) -> NativeCallback:
    """The PortAudio callback ``symbol`` of ``handle``."""
    address = _address(handle, symbol)
    return NativeCallback(address, CALLBACK_TYPE(address))


def seal(body: bytes) -> bytes:
    """``body`` (a linked library) with its seal appended: SEAL_TAG and the SHA-256 of ``body``."""
    return body + SEAL_TAG + hashlib.sha256(body).digest()


def _read(path: Path) -> bytes:
    """Every byte of the regular file at ``path`` (opened without blocking: a FIFO put there does not hang);
    LibraryProblem when it is not a regular file, is larger than MAX_LIBRARY_BYTES or cannot be read."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as error:
        raise LibraryProblem(f"cannot be opened ({error.strerror or error})") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise LibraryProblem("is not a regular file")
        if info.st_size > MAX_LIBRARY_BYTES:
            raise LibraryProblem(f"has {info.st_size} bytes, more than a library's {MAX_LIBRARY_BYTES}")
        data = bytearray()
        while chunk := os.read(fd, 1 << 20):
            data += chunk
            if len(data) > MAX_LIBRARY_BYTES:
                raise LibraryProblem(f"grew past {MAX_LIBRARY_BYTES} bytes while read")
        return bytes(data)
    except OSError as error:
        raise LibraryProblem(f"cannot be read ({error.strerror or error})") from None
    finally:
        os.close(fd)


def _unseal(data: bytes) -> bytes:
    """The library ``data`` holds before its seal; LibraryProblem when the seal is missing or does not match."""
    if len(data) < SEAL_BYTES or not data[:len(data) - SEAL_BYTES + len(SEAL_TAG)].endswith(SEAL_TAG):
        raise LibraryProblem(f"has no seal at its end ({len(data)} bytes: cut short, or not written by the builder)")
    body, digest = data[:-SEAL_BYTES], data[len(data) - SEAL_BYTES + len(SEAL_TAG):]
    if hashlib.sha256(body).digest() != digest:
        raise LibraryProblem("does not match its seal (damaged)")
    return body


def _check_elf(body: bytes) -> None:
    """LibraryProblem unless ``body`` is an ELF shared object of this byte order whose program headers, and
    the file part of every segment they list, lie within it (what the dynamic loader maps and reads)."""
    if len(body) < 64 or body[:4] != b"\x7fELF" or body[4] not in _ELF_LAYOUTS:
        raise LibraryProblem("is not an ELF file")
    if body[5] != (1 if sys.byteorder == "little" else 2):
        raise LibraryProblem("is an ELF file of the other byte order")
    order = "<" if body[5] == 1 else ">"
    word, phoff_at, phentsize_at, header_format, (type_at, offset_at, size_at) = _ELF_LAYOUTS[body[4]]
    (elf_type,) = struct.unpack_from(order + "H", body, 16)
    (phoff,) = struct.unpack_from(order + word, body, phoff_at)
    entry_size, count = struct.unpack_from(order + "HH", body, phentsize_at)
    if elf_type != _ELF_SHARED_OBJECT:
        raise LibraryProblem(f"is an ELF file of type {elf_type}, not a shared object")
    if count == 0 or entry_size < struct.calcsize(order + header_format) or phoff + count * entry_size > len(body):
        raise LibraryProblem("has program headers outside the file (cut short)")
    for index in range(count):
        header = struct.unpack_from(order + header_format, body, phoff + index * entry_size)
        if header[type_at] != 0 and header[offset_at] + header[size_at] > len(body):
            raise LibraryProblem(f"has a segment ending at byte {header[offset_at] + header[size_at]} of "
                                 f"{len(body)} (cut short)")


def _dlopen(path: Path, body: bytes) -> ctypes.CDLL:
    """``body`` (the checked bytes of ``path``) loaded from an anonymous in-memory file; from ``path`` where
    such a file cannot be made or mapped executable. OSError when neither loads.

    The in-memory file stays open for the life of the process: the dynamic loader knows a library by the name it
    was opened under (``/proc/self/fd/N``), so a number closed and given to another file would make a later
    dlopen of that name answer with the library loaded first."""
    try:
        fd = os.memfd_create("tpad_rt_aot", os.MFD_CLOEXEC)
    except (AttributeError, OSError):  # not Linux, or refused
        return ctypes.CDLL(str(path))
    try:
        view = memoryview(body)
        while view:
            view = view[os.write(fd, view):]
        return ctypes.CDLL(f"/proc/self/fd/{fd}")
    except OSError:  # no /proc, or memfd mapped without execute (vm.memfd_noexec)
        os.close(fd)
        return ctypes.CDLL(str(path))


def open_library(path: Path, stamp: str) -> AotLibrary:
    """The library at ``path`` carrying ``stamp``, after the checks of the module docstring; LibraryProblem
    (the message says what is wrong) when one fails."""
    body = _unseal(_read(path))
    _check_elf(body)
    if stamp.encode() + b"\0" not in body:
        raise LibraryProblem("was built for other sources, numba or CPU (another stamp)")
    try:
        handle = _dlopen(path, body)
    except OSError as error:
        raise LibraryProblem(f"does not load ({error})") from None
    carried = ctypes.string_at(_address(handle, STAMP_SYMBOL))
    if carried != stamp.encode():
        raise LibraryProblem("carries another stamp")
    return AotLibrary(path, handle)


def find(folders: Sequence[Path] | None = None) -> Found:
    """The library for the current stamp in the first of ``folders`` (default :func:`library_dirs`) holding a
    file of its name; ``Found(None, None, None)`` when none does, or when ``NUMBA_DISABLE_JIT`` is set."""
    if os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0"):
        return Found(None, None, None)
    stamp = library_stamp()
    for folder in library_dirs() if folders is None else folders:
        path = folder / library_name(stamp)
        if os.path.lexists(path):
            try:
                return Found(path, open_library(path, stamp), None)
            except LibraryProblem as problem:
                return Found(path, None, str(problem))
    return Found(None, None, None)


@functools.cache
def load() -> AotLibrary | None:
    """The library for the current stamp, once per process (module docstring)."""
    found = find()
    if found.problem is not None:
        print(f"tpad-rt: ignored the ahead-of-time library {found.path}: it {found.problem}; the audio callbacks "
              "run on numba's JIT (tpad-rt warm builds it again)", file=sys.stderr)
    return found.library


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
