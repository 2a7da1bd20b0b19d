"""A slow serial line between a host and the amplifier emulator: a new pty for the host, relayed to the emulator's.

``SlowLine(amplifier_port, bytes_per_s)`` opens a pty pair (``.port`` is the path to give
the host) and a thread that relays the host's bytes to the amplifier's port at most at
``bytes_per_s`` (a token bucket refilled on the monotonic clock, as a UART at a low baud
rate drains its buffer), and the amplifier's bytes back at once. A pty itself carries
megabytes a second whatever baud rate it is set to; this makes a slow link honestly,
with real descriptors on both sides. ``close()`` (or leaving the ``with`` block) ends it.
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from types import TracebackType

#: The relay's tick (s): it forwards what the rate allows at least this often.
TICK_S = 0.0005


class SlowLine:
    """The host's pty ``.port``, relayed to ``amplifier_port`` at ``bytes_per_s`` (host to amplifier)."""

    def __init__(self, amplifier_port: str, bytes_per_s: float):
        self._host_fd, slave_fd = os.openpty()
        tty.setraw(slave_fd)
        self.port = os.ttyname(slave_fd)
        self._slave_fd = slave_fd  # kept open: the host may close and reopen its end
        self._amp_fd = os.open(amplifier_port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self._amp_fd)
        os.set_blocking(self._host_fd, False)
        self._rate = bytes_per_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._relay, name="slow line", daemon=True)
        self._thread.start()

    def _relay(self) -> None:
        pending = b""
        allowance = 0.0
        last_s = time.monotonic()
        while not self._stop.is_set():
            readable, _, _ = select.select([self._host_fd, self._amp_fd], [], [], TICK_S)
            if self._host_fd in readable:
                try:
                    pending += os.read(self._host_fd, 65536)
                except OSError:  # the host closed its end (EIO on the master) for now
                    pass
            if self._amp_fd in readable:
                try:
                    data = os.read(self._amp_fd, 65536)
                    if data:
                        os.write(self._host_fd, data)
                except (BlockingIOError, OSError):
                    pass
            now_s = time.monotonic()
            allowance = min(allowance + (now_s - last_s) * self._rate, max(64.0, self._rate * 0.002))
            last_s = now_s
            if pending and allowance >= 1.0:
                try:
                    sent = os.write(self._amp_fd, pending[:int(allowance)])
                except BlockingIOError:
                    sent = 0
                pending = pending[sent:]
                allowance -= sent

    def close(self) -> None:
        """Stop relaying and close every descriptor."""
        self._stop.set()
        self._thread.join()
        for fd in (self._host_fd, self._slave_fd, self._amp_fd):
            os.close(fd)

    def __enter__(self) -> SlowLine:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.close()
