"""The line a :class:`tpad_rt.outputs.serial_amp.AmpLink` talks to its amplifier on: a real serial port, or another.

API map
-------
Line
    the protocol: ``name``, ``clock`` (the :class:`tpad_rt.clock.Clock` its times are on),
    ``read() -> bytes``, ``write(data) -> int``, ``wait(deadline_ns, writable=False)``,
    ``start_stream(table, link, buffers, envelope) -> Streamer``, ``close()``
Streamer
    a running stream: ``alive``, ``join()``, ``crash``, ``realtime``
SerialLine.open(port, baud) -> SerialLine
    a serial port (pyserial), non-blocking, on :class:`tpad_rt.clock.MonotonicClock`; its
    stream is the compiled GIL-free :func:`tpad_rt.kernel.amp_stream.stream` in a thread
    of its own, on the port's descriptor; BackendError naming the port when it cannot open

The other line is :class:`tpad_rt.amp.virtual_link.VirtualLink`: the in-process amplifier
emulator on a :class:`tpad_rt.clock.VirtualClock`, which runs the same steps of
:mod:`tpad_rt.kernel.amp_stream` (docs/amplifiers.md "The virtual link").
"""

from __future__ import annotations

import os
import select
import threading
from typing import Protocol

import numpy as np

from tpad_rt.clock import Clock, MonotonicClock
from tpad_rt.errors import BackendError
from tpad_rt.kernel import amp_stream

#: Most bytes one read() returns.
READ_BYTES = 4096
#: The SCHED_FIFO priority of the streamer thread where allowed (below a JACK server's, typically 70-90): like
#: an audio callback, it sleeps between frames and must run as soon as one is due.
STREAMER_PRIORITY = 20


class Streamer(Protocol):
    """A stream the line runs (:meth:`Line.start_stream`) until the link's LINK_STOP or a failure."""

    crash: BaseException | None  # an exception that ended it (not a failure the link reports: a bug)
    realtime: bool  # whether it runs with real-time scheduling

    @property
    def alive(self) -> bool:
        """True until the stream is over (LINK_EXIT set)."""

    def join(self) -> None:
        """Wait until the stream is over."""


class Line(Protocol):
    """What the host reads and writes an amplifier's bytes through; every time is on ``clock`` (ns)."""

    name: str
    clock: Clock

    def read(self) -> bytes:
        """The bytes waiting now (b"" if none); BackendError when the line is lost."""

    def write(self, data: bytes) -> int:
        """How many of ``data``'s bytes the line took now (0: it is full); BackendError when it is lost."""

    def wait(self, deadline_ns: int, writable: bool = False) -> None:
        """Return once bytes wait to be read (with ``writable``: once the line takes bytes) or at ``deadline_ns``."""

    def start_stream(self, table: np.ndarray, link: np.ndarray, buffers: np.ndarray,
                     envelope: np.ndarray) -> Streamer:
        """Run the streamer's steps (:mod:`tpad_rt.kernel.amp_stream`) on this line for the pointer ``table``."""

    def close(self) -> None:
        """Release the line (safe twice)."""


def port_error(name: str, error: BaseException) -> BackendError:
    """The BackendError for an OSError or pyserial's SerialException on the port ``name``."""
    return BackendError(f"serial: {name}: {reason(error)}")


def reason(error: BaseException) -> str:
    """A short reason from an OSError or pyserial's SerialException (whose first argument is the errno)."""
    number = getattr(error, "errno", None)
    if not isinstance(number, int) and error.args and isinstance(error.args[0], int):
        number = error.args[0]
    if isinstance(number, int) and number > 0:
        return os.strerror(number)
    return str(error) or type(error).__name__


class SerialLine:
    """A serial port opened with pyserial (which owns its descriptor), read and written without blocking."""

    def __init__(self, name: str, port: object, fd: int):
        self.name = name
        self.clock: Clock = MonotonicClock()
        self._port = port
        self._fd = fd

    @classmethod
    def open(cls, name: str, baud: int) -> SerialLine:
        """Open the port ``name`` at ``baud``, exclusively; BackendError naming it when it cannot."""
        import serial  # pyserial

        try:
            port = serial.Serial(name, baud, timeout=0, write_timeout=0, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as error:
            raise BackendError(f"serial: cannot open {name}: {reason(error)}") from None
        fd = port.fileno()
        os.set_blocking(fd, False)
        return cls(name, port, fd)

    def read(self) -> bytes:
        # A tty with VMIN = 0 reads b"" for "nothing now": only a readable port that reads nothing has closed.
        if not select.select([self._fd], [], [], 0)[0]:
            return b""
        try:
            chunk = os.read(self._fd, READ_BYTES)
        except BlockingIOError:
            return b""
        except OSError as error:
            raise port_error(self.name, error) from None
        if not chunk:
            raise BackendError(f"serial: {self.name}: the port closed")
        return chunk

    def write(self, data: bytes) -> int:
        try:
            return os.write(self._fd, data)
        except BlockingIOError:
            return 0
        except OSError as error:
            raise port_error(self.name, error) from None

    def wait(self, deadline_ns: int, writable: bool = False) -> None:
        timeout_s = max(deadline_ns - self.clock.now_ns(), 0) * 1e-9
        if writable:
            select.select([], [self._fd], [], timeout_s)
        else:
            select.select([self._fd], [], [], timeout_s)

    def start_stream(self, table: np.ndarray, link: np.ndarray, buffers: np.ndarray,
                     envelope: np.ndarray) -> Streamer:
        link[amp_stream.LINK_FD] = self._fd
        return ThreadStreamer(table, link, buffers, envelope)

    def close(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()  # type: ignore[attr-defined]
            except OSError:
                pass  # a device that vanished: its descriptor is released all the same


class ThreadStreamer:
    """:func:`tpad_rt.kernel.amp_stream.stream` in a thread of its own (SCHED_FIFO where allowed): one compiled
    call that holds no GIL for the whole run, on the real clock and the descriptor in LINK_FD."""

    def __init__(self, table: np.ndarray, link: np.ndarray, buffers: np.ndarray, envelope: np.ndarray):
        self.crash: BaseException | None = None
        self.realtime = False
        self._thread = threading.Thread(target=self._run, args=(table, link, buffers, envelope),
                                        name="tpad-rt serial streamer", daemon=True)
        self._thread.start()

    def _run(self, table: np.ndarray, link: np.ndarray, buffers: np.ndarray, envelope: np.ndarray) -> None:
        self.realtime = realtime_thread()
        try:
            amp_stream.stream(table, link, buffers, envelope, np.zeros(3))
        except BaseException as error:  # noqa: BLE001 - reported by AmpLink.failure()
            self.crash = error

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def join(self) -> None:
        self._thread.join()


def realtime_thread() -> bool:
    """Give the calling thread SCHED_FIFO STREAMER_PRIORITY, as audio servers give their callbacks; False where
    the system refuses (the stream then runs at normal priority: a loaded machine can delay it)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(STREAMER_PRIORITY))  # 0: this thread (Linux)
    except (OSError, AttributeError):
        return False
    return True
