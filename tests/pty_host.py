"""The test as a host on an amplifier's pty (the emulator's, the firmware's): frames out, frames in, through
tpad_rt/amp/wire.py. Each wait has a generous deadline, a safety net only."""

from __future__ import annotations

import os
import select
import time
from collections.abc import Callable

from tpad_rt.amp import wire
from tpad_rt.amp.wire import Type

#: Safety net for every wait (s); never reached when the amplifier works.
WAIT_S = 60.0


class PtyHost:
    """The test as a host on the emulator's port ``path`` (or an fd it was given): frames out, frames in."""

    def __init__(self, path: str = "", fd: int = -1):
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY) if fd < 0 else fd
        self.seq = 0
        self.splitter = wire.FrameSplitter()

    def send(self, type_: Type, payload: bytes = b"") -> int:
        """Write one frame with the next seq; that seq."""
        seq, self.seq = self.seq, (self.seq + 1) & 0xFFFF
        self.write(wire.encode(type_, seq, payload))
        return seq

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            view = view[os.write(self.fd, view):]

    def wait(self, wanted: Callable[[wire.Frame], bool], what: str) -> wire.Frame:
        """The first valid frame read from now on that is ``wanted`` (AssertionError after WAIT_S or at the
        line's end)."""
        deadline_s = time.monotonic() + WAIT_S
        while (left_s := deadline_s - time.monotonic()) > 0:
            if not select.select([self.fd], [], [], left_s)[0]:
                continue
            try:
                data = os.read(self.fd, 65536)
            except OSError:  # EIO: the emulator's end closed
                data = b""
            assert data, f"the line ended before {what}"
            for encoded in self.splitter.feed(data):
                frame = None if encoded is None else wire.decode(encoded)
                if frame is not None and wanted(frame):
                    return frame
        raise AssertionError(f"no {what} within {WAIT_S:g} s")

    def hello(self, nonce: int) -> wire.Info:
        self.seq = 0
        self.send(Type.HELLO, wire.Hello("test", nonce).pack())
        frame = self.wait(lambda frame: frame.type == Type.INFO and wire.Info.unpack(frame.payload).hello_nonce == nonce,
                          f"INFO for nonce {nonce:#x}")
        return wire.Info.unpack(frame.payload)

    def ack(self, seq: int) -> wire.Ack:
        frame = self.wait(lambda frame: frame.type == Type.ACK and wire.Ack.unpack(frame.payload).acked_seq == seq,
                          f"ACK of seq {seq}")
        return wire.Ack.unpack(frame.payload)

    def status(self, wanted: Callable[[wire.Status], bool], what: str) -> wire.Status:
        frame = self.wait(lambda frame: frame.type == Type.STATUS and wanted(wire.Status.unpack(frame.payload)), what)
        return wire.Status.unpack(frame.payload)

    def ended(self) -> bool:
        """True once a read finds the line's end (end of file, EIO) within WAIT_S; frames before it are skipped."""
        deadline_s = time.monotonic() + WAIT_S
        while (left_s := deadline_s - time.monotonic()) > 0:
            if select.select([self.fd], [], [], left_s)[0]:
                try:
                    if not os.read(self.fd, 65536):
                        return True
                except OSError:
                    return True
        return False

    def close(self) -> None:
        os.close(self.fd)
