"""A virtual serial line: the host's AmpLink and streamer talking to the in-process amplifier emulator on a virtual clock.

The models are AUTD3's emulator link and pyserial's ``loop://``: the host's code runs
unchanged, the line and the amplifier are software, and time is a
:class:`tpad_rt.clock.VirtualClock` that moves only when someone waits on it. So every
behaviour of the protocol in time (pacing, skip-ahead, watchdog and restart, timeouts,
stalls, STOP) runs deterministically, as fast as the host computes, to the nanosecond.

API map
-------
VirtualLink(clock, amplifier, *, name="virtual", baud=921600, capacity_bytes=4096, read_period_ns=0)
    a :class:`tpad_rt.outputs.serial_line.Line` to ``amplifier`` (a
    :class:`tpad_rt.amp.emulator.Amplifier`, or any :class:`AmplifierSide`); give it to ``AmpLink.open(..., line=)`` or a
    ``SerialStreamDriver(..., open_line=)``. Its stream runs the steps of
    :mod:`tpad_rt.kernel.amp_stream` as events on the clock.
VirtualLink.emulating(device, *, clock=None, force_n=0.5, **options) -> VirtualLink
    the same with the emulator's amplifier for ``device`` (``tpad-rt amp emulate``'s), recording
LineFaults(drop_rate, corrupt_rate, duplicate_rate, delay_ns, seed)
    what the line does to the host's bytes (``link.faults = ...``, at any time)
link.freeze_host(duration_ns)    the host's stream runs no step for that long (a stopped process)
link.stop_reading() / resume_reading()   the amplifier reads nothing: the line fills
link.kill()                      the amplifier is gone: it reads nothing and sends nothing (silence)
link.unplug()                    the port is lost: the host's reads and writes fail (EIO)
link.set_drift(fraction)         the amplifier's clock runs ``1 + fraction`` times the host's from now
link.recording() -> dict         the samples the amplifier applied (the emulator's recording columns)

The line carries bytes in both directions at ``baud`` (10 bits a byte: its byte rate is
``baud / 10``, and a low ``baud`` makes a slow link), the host's bytes through ``faults``,
frame by frame; the host's writes take at most ``capacity_bytes`` not yet read by the
amplifier (a full line refuses the rest, as a full pty does). With ``read_period_ns`` the
amplifier reads what waits only at multiples of it on the host's clock (ns), all at once (the
emulator on a pty, a firmware polling its UART's FIFO); 0: each frame as it arrives. The
amplifier's STATUS goes out on its own schedule (its ``next_status_s``), as events on the clock.
"""

from __future__ import annotations

import errno as _errno
import functools
import math
import os
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from tpad_rt.amp import wire
from tpad_rt.amp.emulator import (
    RECORDED_COLUMNS,
    Amplifier,
    Circuit,
    Plate,
    Recorder,
    amplifier_info,
    sim_rate_hz,
)
from tpad_rt.clock import VirtualClock
from tpad_rt.device import Device
from tpad_rt.errors import BackendError
from tpad_rt.kernel import amp_stream

#: Bits a byte takes on the line (start, 8 data, stop).
BITS_PER_BYTE = 10
#: The host's bytes reach the amplifier frame by frame, each when its last byte is through (what the amplifier acts
#: on: a frame is whole or nothing), a run without a delimiter in pieces of at most this many (at 921600 baud, 0.7 ms):
#: a long write arrives as it goes, as on a UART, not all at once at its end.
PIECE_BYTES = 64


class AmplifierSide(Protocol):
    """What the link needs of the amplifier at the other end: :class:`tpad_rt.amp.emulator.Amplifier`'s
    discrete-event interface (times in s on its own clock; what it sends accumulates in ``out``)."""

    out: bytearray
    now_s: float
    on_hello: Callable[[], None] | None
    recorder: Recorder | None

    @property
    def next_status_s(self) -> float:
        """When it sends its next STATUS unasked (s; inf: never)."""

    def receive(self, encoded: bytes | None, t_s: float) -> None:
        """Act on a candidate frame (None: an over-long run) at ``t_s``."""

    def advance(self, t_s: float) -> None:
        """Do what is due up to ``t_s``."""


@dataclass(frozen=True)
class LineFaults:
    """What the line does to the host's bytes on their way to the amplifier, seeded by ``seed``: each byte is
    dropped (``drop_rate``) or has one bit flipped (``corrupt_rate``), each write arrives twice
    (``duplicate_rate``), and everything arrives ``delay_ns`` (ns) late."""

    drop_rate: float = 0.0
    corrupt_rate: float = 0.0
    duplicate_rate: float = 0.0
    delay_ns: int = 0
    seed: int = 0


class VirtualLink:
    """The host's line to ``amplifier`` on ``clock``: a :class:`tpad_rt.outputs.serial_line.Line` (module docstring).

    The amplifier's clock starts at 0 s when the link is made.
    """

    def __init__(self, clock: VirtualClock, amplifier: AmplifierSide, *, name: str = "virtual", baud: int = 921600,
                 capacity_bytes: int = 4096, read_period_ns: int = 0):
        self.name = name
        self.clock = clock
        self.amplifier = amplifier
        amplifier.on_hello = self._drop_unread_by_host
        self.capacity_bytes = capacity_bytes
        self.read_period_ns = read_period_ns
        self._read_event_ns = -1  # the amplifier's next read of what waits (read_period_ns), scheduled
        self._byte_ns = BITS_PER_BYTE * 1e9 / baud
        self._faults = LineFaults()
        self._rng = np.random.default_rng(0)
        self._anchor_ns, self._anchor_s, self._rate = clock.now_ns(), amplifier.now_s, 1.0
        self._splitter = wire.FrameSplitter()
        self._to_amp_free_ns = 0  # when the line towards the amplifier has sent all it took
        self._to_host_free_ns = 0
        self._in_flight = 0  # bytes on their way to the amplifier
        self._unread = bytearray()  # bytes that reached the amplifier and wait for it to read them
        self._to_host: deque[tuple[int, bytes]] = deque()  # (arrival ns, bytes) for the host
        self._status_event_ns = -1  # the amplifier's next STATUS event, scheduled
        self.reading = True
        self.alive = True
        self.lost = False
        self.reads_lost = False  # the host's reads fail (EIO) while its writes still go out
        self.frozen_until_ns = -1
        self.closed = False

    @classmethod
    def emulating(cls, device: Device, *, clock: VirtualClock | None = None, force_n: float = 0.5,
                  **options: Any) -> VirtualLink:
        """A link to ``tpad-rt amp emulate``'s amplifier for ``device`` under a finger pressing ``force_n`` (N),
        recording what it applies, on ``clock`` (a new VirtualClock if None); ``options`` as VirtualLink's."""
        clock = clock if clock is not None else VirtualClock()
        circuit = Circuit(device, force_n)
        info = amplifier_info(device, circuit)
        plate = Plate(device, force_n, sim_rate_hz(info.carrier_max_mhz))
        return cls(clock, Amplifier(info, circuit, plate, 0.0, recorder=Recorder()), **options)

    # --- the amplifier's clock ---

    def amp_s(self, t_ns: int) -> float:
        """The amplifier's clock (s) at the host's ``t_ns`` (ns)."""
        return self._anchor_s + (t_ns - self._anchor_ns) * 1e-9 * self._rate

    def _host_ns(self, t_s: float) -> int:
        """The host's time (ns) when the amplifier's clock reaches ``t_s`` (s), rounded up past it."""
        return self._anchor_ns + math.ceil((t_s - self._anchor_s) / self._rate * 1e9) + 1

    def set_drift(self, fraction: float) -> None:
        """From now on the amplifier's clock runs ``1 + fraction`` times as fast as the host's."""
        now_ns = self.clock.now_ns()
        self._anchor_s, self._anchor_ns, self._rate = self.amp_s(now_ns), now_ns, 1.0 + fraction
        self._schedule_status()

    # --- what a test does to the line ---

    @property
    def faults(self) -> LineFaults:
        """What the line does to the host's bytes from now on."""
        return self._faults

    @faults.setter
    def faults(self, faults: LineFaults) -> None:
        self._faults = faults
        self._rng = np.random.default_rng(faults.seed)

    def freeze_host(self, duration_ns: int) -> None:
        """The host's stream runs no step from now for ``duration_ns`` (ns): a process stopped, a thread held up."""
        self.frozen_until_ns = self.clock.now_ns() + duration_ns

    def stop_reading(self) -> None:
        """The amplifier reads nothing from now on: the bytes stay on the line, which fills up."""
        self.reading = False

    def resume_reading(self) -> None:
        """The amplifier reads again, first what waited."""
        self.reading = True
        data, self._unread = bytes(self._unread), bytearray()
        self._feed(data)

    def kill(self) -> None:
        """The amplifier is gone: what reaches it is lost, and it sends nothing more (the line stays open)."""
        self.alive = False
        self._to_host.clear()

    def unplug(self) -> None:
        """The port is lost: the host's reads and writes fail with EIO."""
        self.lost = True

    def lose_reads(self) -> None:
        """Half a lost port: the host's reads fail with EIO, its writes still reach the amplifier."""
        self.reads_lost = True

    def recording(self) -> dict[str, np.ndarray]:
        """The samples the amplifier applied so far (the emulator's RECORDED_COLUMNS); ValueError without a
        recorder."""
        recorder = self.amplifier.recorder
        if recorder is None:
            raise ValueError("VirtualLink.recording: the amplifier records nothing (no recorder)")
        self.amplifier.advance(self.amp_s(self.clock.now_ns()))
        return {name: recorder.column(name) for name in RECORDED_COLUMNS}

    # --- the host's end: the Line protocol ---

    def read(self) -> bytes:
        """The bytes that reached the host by now (b"" if none); BackendError when the port is lost."""
        data = self.take(1 << 20)
        if data is None:
            raise BackendError(f"serial: {self.name}: {os.strerror(_errno.EIO)}")
        return data

    def take(self, limit: int) -> bytes | None:
        """At most ``limit`` of the bytes that reached the host by now; None when the port (or its reading) is
        lost."""
        if self.lost or self.reads_lost or self.closed:
            return None
        now_ns = self.clock.now_ns()
        chunks: list[bytes] = []
        size = 0
        while self._to_host and self._to_host[0][0] <= now_ns and size < limit:
            arrival_ns, data = self._to_host.popleft()
            if size + len(data) > limit:
                self._to_host.appendleft((arrival_ns, data[limit - size:]))
                data = data[:limit - size]
            chunks.append(data)
            size += len(data)
        return b"".join(chunks)

    def write(self, data: bytes) -> int:
        """How many of ``data``'s bytes the line took now (0: full); BackendError when the port is lost."""
        taken = self.put(data)
        if taken < 0:
            raise BackendError(f"serial: {self.name}: {os.strerror(-taken)}")
        return taken

    def put(self, data: bytes) -> int:
        """How many of ``data``'s bytes the line took now; ``-errno`` when the port is lost."""
        if self.lost or self.closed:
            return -_errno.EIO
        room = max(0, self.capacity_bytes - self._in_flight - len(self._unread))
        taken = data[:room]
        if taken:
            self._send_to_amp(taken)
            if self._faults.duplicate_rate and self._rng.random() < self._faults.duplicate_rate:
                self._send_to_amp(taken)
        return len(taken)

    def wait(self, deadline_ns: int, writable: bool = False) -> None:
        """Advance the clock (running what is due on the way) until bytes reached the host (with ``writable``:
        the line has room) or to ``deadline_ns``."""
        clock = self.clock
        while clock.now_ns() < deadline_ns and not self.lost:
            ready = (self._in_flight + len(self._unread) < self.capacity_bytes if writable
                     else bool(self._to_host) and self._to_host[0][0] <= clock.now_ns())
            if ready:
                return
            next_ns = clock.next_event_ns()
            clock.advance_to(deadline_ns if next_ns is None else min(next_ns, deadline_ns))

    def start_stream(self, table: np.ndarray, link: np.ndarray, buffers: np.ndarray,
                     envelope: np.ndarray) -> VirtualStreamer:
        """Run the streamer's steps on this line, as events on the clock, from now."""
        return VirtualStreamer(self, table, link, buffers, envelope)

    def close(self) -> None:
        """The host closes its end."""
        self.closed = True

    # --- the line ---

    def _send_to_amp(self, data: bytes) -> None:
        """Put the host's ``data`` on the line (through the faults) at ``baud``: each frame (up to its delimiter; a
        longer run in pieces of PIECE_BYTES) reaches the amplifier once its last byte is through, as on a UART."""
        for piece in _pieces(data):
            self._to_amp_free_ns = max(self._to_amp_free_ns, self.clock.now_ns()) + round(len(piece) * self._byte_ns)
            arrival_ns = self._to_amp_free_ns + self._faults.delay_ns
            self._in_flight += len(piece)
            self.clock.at(arrival_ns, functools.partial(self._arrive, len(piece), self._line_faults(piece)))

    def _line_faults(self, data: bytes) -> bytes:
        """``data`` after the drop and corrupt faults (one pair of draws per byte, in order)."""
        faults = self._faults
        if not (faults.drop_rate or faults.corrupt_rate):
            return data
        draws = self._rng.random((len(data), 2))
        received = np.frombuffer(data, dtype=np.uint8).copy()
        flipped = draws[:, 1] < faults.corrupt_rate
        bits = (draws[flipped, 1] / faults.corrupt_rate * 8).astype(np.uint8)
        received[flipped] ^= np.left_shift(1, bits).astype(np.uint8)
        return received[draws[:, 0] >= faults.drop_rate].tobytes()

    def _arrive(self, sent: int, data: bytes) -> None:
        self._in_flight -= sent
        if not self.alive:
            return
        if not self.reading or self.read_period_ns > 0:
            self._unread += data
            if self.reading:
                self._schedule_read()
            return
        self._feed(data)

    def _schedule_read(self) -> None:
        """The amplifier reads what waits at the next multiple of read_period_ns (ns) after now."""
        due_ns = (self.clock.now_ns() // self.read_period_ns + 1) * self.read_period_ns
        if due_ns != self._read_event_ns:
            self._read_event_ns = due_ns
            self.clock.at(due_ns, self._read_waiting)

    def _read_waiting(self) -> None:
        self._read_event_ns = -1
        if self.reading and self.alive and self._unread:
            data, self._unread = bytes(self._unread), bytearray()
            self._feed(data)

    def _feed(self, data: bytes) -> None:
        """The amplifier reads ``data`` now: each frame it completes is received at this time."""
        t_s = self.amp_s(self.clock.now_ns())
        for frame in self._splitter.feed(data):
            self.amplifier.receive(frame, t_s)
        self._forward()

    def _drop_unread_by_host(self) -> None:
        """A HELLO: the bytes the amplifier sent that the host has not read are stale (the emulator flushes them)."""
        self._to_host.clear()

    def _forward(self) -> None:
        """Put what the amplifier sent on the line to the host, and schedule its next STATUS."""
        out = self.amplifier.out
        if out and self.alive:
            now_ns = self.clock.now_ns()
            self._to_host_free_ns = max(self._to_host_free_ns, now_ns) + round(len(out) * self._byte_ns)
            self._to_host.append((self._to_host_free_ns, bytes(out)))
            self.clock.at(self._to_host_free_ns, _nothing)  # a host waiting for bytes wakes then
        out.clear()
        self._schedule_status()

    def _schedule_status(self) -> None:
        due_s = self.amplifier.next_status_s
        if not self.alive or math.isinf(due_s):
            return
        due_ns = max(self._host_ns(due_s), self.clock.now_ns())
        if due_ns != self._status_event_ns:
            self._status_event_ns = due_ns
            self.clock.at(due_ns, lambda: self._status_due(due_ns))

    def _status_due(self, due_ns: int) -> None:
        if due_ns != self._status_event_ns or not self.alive:
            return  # rescheduled since, or the amplifier is gone
        self._status_event_ns = -1
        self.amplifier.advance(self.amp_s(self.clock.now_ns()))
        self._forward()


def _pieces(data: bytes) -> list[bytes]:
    """``data`` cut after each delimiter (0x00) and after every PIECE_BYTES without one."""
    pieces = []
    first = 0
    while first < len(data):
        end = data.find(0, first, first + PIECE_BYTES)
        end = first + PIECE_BYTES if end < 0 else end + 1
        pieces.append(data[first:end])
        first = end
    return pieces


def _nothing() -> None:
    """An event that only wakes the clock's waiter."""


class VirtualStreamer:
    """The host's stream on a :class:`VirtualLink`: each step of :mod:`tpad_rt.kernel.amp_stream` at the time the
    last one asked to wake, with the bytes that reached the host by then (a frozen host steps when it thaws)."""

    def __init__(self, line: VirtualLink, table: np.ndarray, link: np.ndarray, buffers: np.ndarray,
                 envelope: np.ndarray):
        self.crash: BaseException | None = None
        self.realtime = False
        self._line, self._table, self._link, self._buffers, self._envelope = line, table, link, buffers, envelope
        self._times = np.zeros(3)
        amp_stream.begin(table, link, line.clock.now_ns())
        line.clock.at(line.clock.now_ns(), self._step)

    @property
    def alive(self) -> bool:
        return self.crash is None and self._link[amp_stream.LINK_STAGE] != amp_stream.STAGE_DONE

    def join(self) -> None:
        """Advance the clock until the stream is over."""
        clock = self._line.clock
        while self.alive:
            next_ns = clock.next_event_ns()
            if next_ns is None:
                raise RuntimeError("VirtualStreamer.join: nothing left on the clock, the stream still runs")
            clock.advance_to(next_ns)

    def _step(self) -> None:
        line, link, buffers = self._line, self._link, self._buffers
        now_ns = line.clock.now_ns()
        if now_ns < line.frozen_until_ns:
            line.clock.at(line.frozen_until_ns, self._step)
            return
        try:
            while amp_stream.reading(link):
                offset = int(link[amp_stream.LINK_RX_LENGTH])
                data = line.take(buffers.shape[1] - offset)
                if data is None:
                    amp_stream.on_received(link, buffers, -_errno.EIO, now_ns)
                    break
                if not data:
                    break
                buffers[amp_stream.BUF_RX, offset:offset + len(data)] = np.frombuffer(data, dtype=np.uint8)
                amp_stream.on_received(link, buffers, len(data), now_ns)
            pending = amp_stream.step(self._table, link, buffers, self._envelope, self._times, now_ns)
            while pending > 0:
                first = int(link[amp_stream.LINK_TX_FIRST])
                wrote = line.put(buffers[amp_stream.BUF_TX, first:first + pending].tobytes())
                pending = amp_stream.on_written(link, wrote)
                if wrote <= 0:
                    break
            wake_ns = amp_stream.settle(link, line.clock.now_ns())
        except BaseException as error:  # noqa: BLE001 - reported by AmpLink.failure(), as the thread's
            self.crash = error
            return
        if wake_ns != amp_stream.RUN_OVER:
            line.clock.at(int(wake_ns), self._step)

