"""libc calls a numba kernel makes without the GIL: the clock, sleeping, and a file descriptor's bytes.

API map
-------
pointer(address) -> void*
    the pointer at an integer address (an inttoptr; no call, no allocation)
monotonic_ns() -> int
    CLOCK_MONOTONIC (ns), the clock of Python's ``time.monotonic_ns``
sleep_until_ns(deadline_ns) -> int
    ``clock_nanosleep`` on CLOCK_MONOTONIC to an absolute time; 0, or an error number (EINTR)
read_fd(fd, address, count) -> int, write_fd(fd, address, count) -> int
    ``read(2)`` and ``write(2)``: bytes moved, or -1 with :func:`errno` set
errno() -> int
    the calling thread's ``errno``
call_stream_callback(address, output, frames, time_info, status_flags, user_data) -> int
    call a PortAudio stream callback (a compiled ``@cfunc``) at an address, as PortAudio would
EAGAIN, EINTR
    the error numbers a non-blocking descriptor returns when it would block, or a signal interrupted

Each is a numba intrinsic: the libc symbol is resolved when the compiled code is loaded
(not baked in as an address), so the kernels that use them stay cacheable; a
``timespec`` lives on the stack, not the heap. Linux (x86-64 and aarch64: ``size_t``
and ``ssize_t`` are 64 bits, ``int`` and ``clockid_t`` 32).
"""

from __future__ import annotations

import errno as _errno

from llvmlite import ir
from numba import types
from numba.core import cgutils
from tpad_rt.kernel.jit import intrinsic

#: Linux clock id of CLOCK_MONOTONIC, and clock_nanosleep's flag for an absolute deadline.
CLOCK_MONOTONIC = 1
TIMER_ABSTIME = 1
EAGAIN = _errno.EAGAIN
EINTR = _errno.EINTR

_I32 = ir.IntType(32)
_I64 = ir.IntType(64)
_TIMESPEC = ir.LiteralStructType([_I64, _I64])
_NS_PER_S = 1_000_000_000


@intrinsic
def pointer(typingctx, address):  # type: ignore[no-untyped-def]
    """The ``void*`` at integer ``address`` (an inttoptr; no call, no allocation)."""
    signature = types.voidptr(types.int64)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        return builder.inttoptr(args[0], cgutils.voidptr_t)

    return signature, codegen


@intrinsic
def monotonic_ns(typingctx):  # type: ignore[no-untyped-def]
    """CLOCK_MONOTONIC in ns, from ``clock_gettime`` into a stack ``timespec``."""
    signature = types.int64()

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(_I32, [_I32, _TIMESPEC.as_pointer()]), "clock_gettime")
        slot = cgutils.alloca_once(builder, _TIMESPEC)
        builder.call(function, [ir.Constant(_I32, CLOCK_MONOTONIC), slot])
        seconds = builder.load(cgutils.gep_inbounds(builder, slot, 0, 0))
        nanoseconds = builder.load(cgutils.gep_inbounds(builder, slot, 0, 1))
        return builder.add(builder.mul(seconds, ir.Constant(_I64, _NS_PER_S)), nanoseconds)

    return signature, codegen


@intrinsic
def sleep_until_ns(typingctx, deadline_ns):  # type: ignore[no-untyped-def]
    """Sleep until CLOCK_MONOTONIC reaches ``deadline_ns``; 0, or clock_nanosleep's error number."""
    signature = types.int64(types.int64)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        function = cgutils.get_or_insert_function(
            builder.module,
            ir.FunctionType(_I32, [_I32, _I32, _TIMESPEC.as_pointer(), _TIMESPEC.as_pointer()]),
            "clock_nanosleep")
        slot = cgutils.alloca_once(builder, _TIMESPEC)
        billion = ir.Constant(_I64, _NS_PER_S)
        builder.store(builder.sdiv(args[0], billion), cgutils.gep_inbounds(builder, slot, 0, 0))
        builder.store(builder.srem(args[0], billion), cgutils.gep_inbounds(builder, slot, 0, 1))
        result = builder.call(function, [ir.Constant(_I32, CLOCK_MONOTONIC), ir.Constant(_I32, TIMER_ABSTIME), slot,
                                         ir.Constant(_TIMESPEC.as_pointer(), None)])
        return builder.sext(result, _I64)

    return signature, codegen


def _byte_call(name: str):  # type: ignore[no-untyped-def]
    """An intrinsic ``(fd, address, count) -> ssize_t`` calling libc's ``name`` (read or write)."""

    @intrinsic
    def call(typingctx, fd, address, count):  # type: ignore[no-untyped-def]
        signature = types.int64(types.int64, types.int64, types.int64)

        def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
            function = cgutils.get_or_insert_function(
                builder.module, ir.FunctionType(_I64, [_I32, cgutils.voidptr_t, _I64]), name)
            return builder.call(function, [builder.trunc(args[0], _I32),
                                           builder.inttoptr(args[1], cgutils.voidptr_t), args[2]])

        return signature, codegen

    return call


read_fd = _byte_call("read")
write_fd = _byte_call("write")


@intrinsic
def errno(typingctx):  # type: ignore[no-untyped-def]
    """The calling thread's ``errno`` (glibc's ``__errno_location``)."""
    signature = types.int64()

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(_I32.as_pointer(), []), "__errno_location")
        return builder.sext(builder.load(builder.call(function, [])), _I64)

    return signature, codegen


@intrinsic
def call_stream_callback(typingctx, address, output, frames, time_info, status_flags, user_data):  # type: ignore[no-untyped-def]
    """Call the PortAudio stream callback (``PaStreamCallback``: ``int(const void *input, void *output,
    unsigned long frames, const PaStreamCallbackTimeInfo *time_info, PaStreamCallbackFlags flags,
    void *user_data)``) at ``address``, with no input; the addresses are integers. Its return value."""
    signature = types.int64(types.int64, types.int64, types.int64, types.int64, types.int64, types.int64)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        voidptr = cgutils.voidptr_t
        function_type = ir.FunctionType(_I32, [voidptr, voidptr, _I64, voidptr, _I64, voidptr])
        function = builder.inttoptr(args[0], function_type.as_pointer())
        result = builder.call(function, [ir.Constant(voidptr, None), builder.inttoptr(args[1], voidptr), args[2],
                                         builder.inttoptr(args[3], voidptr), args[4], builder.inttoptr(args[5], voidptr)])
        return builder.sext(result, _I64)

    return signature, codegen
