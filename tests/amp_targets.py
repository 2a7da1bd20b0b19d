"""The amplifiers the conformance suite (tests/test_amp_conformance.py) runs against, behind one interface.

A target takes frames (bytes) and gives back the frames the amplifier sent. Two kinds:

- :class:`VirtualTarget`, in process on exact virtual times (integer us from the amplifier's
  power-up): bytes arrive at ``now_us``, :meth:`VirtualTarget.advance_to` moves time on, and
  every applied envelope sample and watchdog trip (and the core's carrier samples) can be read back.
  :class:`EmulatorTarget` drives :class:`tpad_rt.amp.emulator.Amplifier` directly;
  :class:`CoreTarget` drives the firmware's portable core (firmware/core/amp.h) through ctypes
  on ``firmware/build/host/libtpadamp.so``, with a board of the emulator's INFO for the same
  device (:func:`board_for`), so that the two can be compared sample by sample.
- :class:`LineTarget`, a real process on a pty in real time: the host build
  (``firmware/build/host/tpad-amp``) or QEMU's microbit (``firmware/run-qemu microbit``). Its
  times are the process's own; a wait is only for an answer, bounded by ANSWER_TIMEOUT_S.

:class:`Host` is the test's side of the line, on either kind: it numbers its frames, sends
them (tpad_rt.amp.wire's codec builds and parses every frame: no third codec), and waits for
answers (on a virtual target they are there at once; on a line up to ANSWER_TIMEOUT_S).
"""

from __future__ import annotations

import ctypes
import os
import select
import signal
import time
import tty
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from amp_process import COUNTERS, AmplifierProcess, parse_counters
from tpad_rt.amp import wire
from tpad_rt.amp.emulator import (
    Amplifier, Circuit, Plate, Recorder, amplifier_info, sim_rate_hz,
)
from tpad_rt.amp.wire import Type
from tpad_rt.device import Device

REPO = Path(__file__).resolve().parents[1]
#: The device both in-process amplifiers serve, and the contact force (N) of the emulator's plate.
DEVICE = Device.default()
FORCE_N = 0.5
#: The amplifier's power-up on its own clock (us): 1000 s, so that nothing relies on a clock starting at 0.
ORIGIN_US = 1_000_000_000
#: Longest step (us) a virtual target takes at once: what it made is collected after each.
STEP_US = 500
#: Longest wait (s) for an answer from a process on a pty: it only turns a hang into a message.
ANSWER_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class Received:
    """A frame the amplifier sent: ``t_us`` when (a virtual target's time; None on a line)."""

    t_us: int | None
    frame: wire.Frame


@dataclass(frozen=True)
class Applied:
    """The applied envelope samples so far: time (us from power-up, float: 16 kHz is 62.5 us), envelope (uV),
    carrier (mHz), stream index (-1: none, a ramp or an underrun) and state, one entry per sample."""

    t_us: npt.NDArray[np.float64]
    envelope_uv: npt.NDArray[np.float64]
    carrier_mhz: npt.NDArray[np.int64]
    index: npt.NDArray[np.int64]
    state: npt.NDArray[np.int64]

    def where(self, keep: npt.NDArray[np.bool_]) -> Applied:
        """The samples ``keep`` selects."""
        return Applied(self.t_us[keep], self.envelope_uv[keep], self.carrier_mhz[keep], self.index[keep],
                       self.state[keep])


class Target(ABC):
    """An amplifier the suite talks to."""

    name: str
    #: True for the in-process targets on exact virtual times.
    virtual: bool = False

    def __init__(self) -> None:
        self._splitter = wire.FrameSplitter()
        self._received: list[Received] = []
        #: Frames from the amplifier that did not decode (a pty target only: see _sent).
        self.broken = 0

    @abstractmethod
    def write(self, data: bytes) -> None:
        """Bytes from the host, arriving now."""

    @abstractmethod
    def _pull(self, timeout_s: float) -> None:
        """Collect what the amplifier sent (a line: waiting up to ``timeout_s`` for bytes)."""

    def close(self) -> None:
        """End the amplifier."""

    def take(self, timeout_s: float = 0.0) -> list[Received]:
        """The frames sent since the last take (a line: waiting up to ``timeout_s`` for the first bytes)."""
        self._pull(timeout_s)
        taken, self._received = self._received, []
        return taken

    def _sent(self, data: bytes, t_us: int | None) -> None:
        for encoded in self._splitter.feed(data):
            frame = None if encoded is None else wire.decode(encoded)
            if frame is not None:
                self._received.append(Received(t_us, frame))
                continue
            # In process every byte is taken at once: each frame must decode. On a pty a HELLO drops the bytes
            # still queued for a host that had not read them (stale), which can cut a frame: the host drops it.
            assert not self.virtual, f"{self.name} sent a frame that does not decode: {encoded!r}"
            self.broken += 1


class VirtualTarget(Target):
    """An in-process amplifier on exact virtual times: ``now_us`` (us from power-up) moves only by advance_to."""

    virtual = True

    def __init__(self) -> None:
        super().__init__()
        self.now_us = 0

    def advance_to(self, t_us: int) -> None:
        """Play the samples and send the STATUS due up to ``t_us`` (in steps of at most STEP_US)."""
        assert t_us >= self.now_us, (t_us, self.now_us)
        while self.now_us < t_us:
            self.now_us = min(t_us, self.now_us + STEP_US)
            self._advance()
            self._collect()

    def _pull(self, timeout_s: float) -> None:
        self._collect()

    @abstractmethod
    def _advance(self) -> None:
        """Let the amplifier run up to ``now_us``."""

    @abstractmethod
    def _collect(self) -> None:
        """Take what the amplifier queued for the host and its carrier samples."""

    @abstractmethod
    def fault(self, bits: int) -> None:
        """A hardware fault (STATUS's fault bits) now: A6."""

    @abstractmethod
    def counters(self) -> dict[str, int]:
        """STATUS's counters now (``frames_ok`` .. ``watchdog_trips``, ``faults``), ``state``, ``envelope_uv``
        (applied), ``carrier_mhz`` (made) and ``play_index``."""

    @abstractmethod
    def applied(self) -> Applied:
        """Every envelope sample applied so far."""

    @abstractmethod
    def trips_us(self) -> list[float]:
        """When (us from power-up) each watchdog trip came."""

    #: Carrier samples per second (the emulator's plate simulation; the core's output).
    output_rate_hz: int


def expected_info() -> wire.Info:
    """The emulator's INFO for DEVICE (its serial aside): what both in-process amplifiers say."""
    return amplifier_info(DEVICE, Circuit(DEVICE, FORCE_N))


class EmulatorTarget(VirtualTarget):
    """:class:`tpad_rt.amp.emulator.Amplifier` for DEVICE, driven directly; its origin is power-up."""

    name = "emulator"

    def __init__(self) -> None:
        super().__init__()
        info = expected_info()
        self.output_rate_hz = sim_rate_hz(info.carrier_max_mhz)
        self._recorder = Recorder()
        self._from_host = wire.FrameSplitter()
        self.amplifier = Amplifier(info, Circuit(DEVICE, FORCE_N), Plate(DEVICE, FORCE_N, self.output_rate_hz),
                                   self._s(0), self._recorder)

    @staticmethod
    def _s(t_us: float) -> float:
        return (ORIGIN_US + t_us) / 1e6

    def write(self, data: bytes) -> None:
        t_s = self._s(self.now_us)
        for encoded in self._from_host.feed(data):
            self.amplifier.receive(encoded, t_s)
        self.amplifier.advance(t_s)
        self._collect()

    def _advance(self) -> None:
        self.amplifier.advance(self._s(self.now_us))

    def _collect(self) -> None:
        if self.amplifier.out:
            self._sent(bytes(self.amplifier.out), self.now_us)
            self.amplifier.out.clear()

    def fault(self, bits: int) -> None:
        self.amplifier.fault(wire.Fault(bits), self._s(self.now_us))
        self._collect()

    def counters(self) -> dict[str, int]:
        amplifier = self.amplifier
        return {**vars(amplifier.counters), "faults": amplifier.faults, "state": int(amplifier.state),
                "envelope_uv": round(amplifier.output_mv * 1000), "carrier_mhz": amplifier.carrier_made_mhz,
                "play_index": amplifier.play_index}

    def applied(self) -> Applied:
        recorder = self._recorder
        return Applied(t_us=recorder.column("t_s") * 1e6 - ORIGIN_US, envelope_uv=recorder.column("envelope_v") * 1e6,
                       carrier_mhz=np.round(recorder.column("carrier_hz") * 1000).astype(np.int64),
                       index=recorder.column("index"), state=recorder.column("state").astype(np.int64))

    def trips_us(self) -> list[float]:
        return [t_s * 1e6 - ORIGIN_US for t_s in self.amplifier.watchdog_trip_t_s]


class LineTarget(Target):
    """A real amplifier process on a pty: ``command`` prints ``amplifier on /dev/pts/N`` first and runs until
    SIGTERM, then prints its counters (``name=value`` pairs on one line: ``final_counters``)."""

    def __init__(self, name: str, command: list[str]):
        super().__init__()
        self.name = name
        self.final_counters: dict[str, int] = {}
        self.amplifier = AmplifierProcess(command, "amplifier on ", name, cwd=REPO)
        self.port = self.amplifier.port
        self.fd = os.open(self.port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self.fd)

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                view = view[os.write(self.fd, view):]
            except BlockingIOError:
                select.select([], [self.fd], [], ANSWER_TIMEOUT_S)

    def _pull(self, timeout_s: float) -> None:
        ready, _, _ = select.select([self.fd], [], [], timeout_s)
        while ready:
            try:
                chunk = os.read(self.fd, 65536)
            except BlockingIOError:
                break
            self._sent(chunk, None)
            ready, _, _ = select.select([self.fd], [], [], 0)

    def close(self) -> None:
        """SIGTERM (by PID), then its counters from its last line; it must exit 0."""
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1
        out = self.amplifier.end(signal.SIGTERM)
        lines = out.strip().splitlines()
        self.final_counters = parse_counters(lines[-1] if lines else "")
        assert set(self.final_counters) == set(COUNTERS), (self.name, out)


class Host:
    """The test's side of the line to ``target``: numbers its frames (HELLO restarts at 0), keeps every frame
    received in ``frames``, and waits for answers (on a virtual target they are there at once)."""

    def __init__(self, target: Target):
        self.target = target
        self.seq = 0
        self.frames: list[Received] = []

    # --- sending ---

    def send(self, type_: int, payload: bytes = b"", *, version: int = wire.VERSION, seq: int | None = None) -> int:
        """Send one frame (``seq``: this one instead of the next; the count goes on from it; a HELLO of this version
        restarts it at 0); its seq."""
        if seq is None:
            seq = 0 if type_ == Type.HELLO and version == wire.VERSION else self.seq
        self.seq = (seq + 1) & 0xFFFF
        self.target.write(wire.encode(type_, seq, payload, version))
        return seq

    def write(self, data: bytes) -> None:
        """Raw bytes on the line."""
        self.target.write(data)

    def wait_us(self, duration_us: int) -> None:
        """Let ``duration_us`` pass (a virtual target only)."""
        assert isinstance(self.target, VirtualTarget)
        self.target.advance_to(self.target.now_us + duration_us)

    # --- receiving ---

    def mark(self) -> int:
        """Where the frames received from now on start in ``frames``."""
        self.frames += self.target.take()
        return len(self.frames)

    def wait_for(self, match: Callable[[wire.Frame], bool], what: str, since: int = 0,
                 advance_us: int = 0) -> Received:
        """The first frame from ``frames[since]`` on that ``match`` takes. A virtual target may move on by up to
        ``advance_us`` (in 100 us steps) for it; a line is waited on up to ANSWER_TIMEOUT_S."""
        deadline = time.monotonic() + ANSWER_TIMEOUT_S
        advanced_us, index = 0, since
        while True:
            self.frames += self.target.take()
            for received in self.frames[index:]:
                if match(received.frame):
                    return received
            index = len(self.frames)
            if isinstance(self.target, VirtualTarget):
                if advanced_us >= advance_us:
                    raise AssertionError(f"{self.target.name}: no {what}")
                step_us = min(100, advance_us - advanced_us)
                self.wait_us(step_us)
                advanced_us += step_us
            else:
                remaining_s = deadline - time.monotonic()
                if remaining_s <= 0:
                    raise AssertionError(f"{self.target.name}: no {what} within {ANSWER_TIMEOUT_S} s")
                self.frames += self.target.take(remaining_s)

    def frames_since(self, since: int, type_: int) -> list[wire.Frame]:
        """The frames of ``type_`` received from ``frames[since]`` on (those taken so far)."""
        self.frames += self.target.take()
        return [received.frame for received in self.frames[since:] if received.frame.type == type_]

    def acks_since(self, since: int) -> list[wire.Ack]:
        return [wire.Ack.unpack(frame.payload) for frame in self.frames_since(since, Type.ACK)]

    # --- exchanges ---

    def hello(self, nonce: int = 0x5EED0001) -> wire.Info:
        """HELLO with ``nonce``; the INFO that echoes it."""
        since = self.mark()
        self.send(Type.HELLO, wire.Hello("conformance", nonce).pack())
        received = self.wait_for(lambda frame: frame.type == Type.INFO
                                 and wire.Info.unpack(frame.payload).hello_nonce == nonce, "INFO", since)
        return wire.Info.unpack(received.frame.payload)

    def command(self, type_: int, payload: bytes = b"", **send: int) -> wire.Ack:
        """Send a frame; the ACK that answers it."""
        since = self.mark()
        seq = self.send(type_, payload, **send)
        received = self.wait_for(lambda frame: frame.type == Type.ACK and wire.Ack.unpack(frame.payload).acked_seq == seq,
                                 f"ACK of seq {seq}", since)
        return wire.Ack.unpack(received.frame.payload)

    def status(self, period_ms: int = 100) -> wire.Status:
        """A KEEPALIVE, then the first STATUS sent after it was acted on (its ``last_seq``): every frame sent
        before is in its counters. A virtual target moves on by up to two ``period_ms`` for it."""
        since = self.mark()
        seq = self.send(Type.KEEPALIVE)
        received = self.wait_for(lambda frame: frame.type == Type.STATUS
                                 and wire.Status.unpack(frame.payload).last_seq == seq, "STATUS", since,
                                 advance_us=2 * period_ms * 1000)
        return wire.Status.unpack(received.frame.payload)


# --- the firmware core through ctypes (firmware/core/amp.h) ---------------------------------------------------

class HalBoard(ctypes.Structure):
    """hal.h's hal_board_t."""

    _fields_ = [("name", ctypes.c_char_p), ("output_rate_hz", ctypes.c_uint32), ("full_scale_mv", ctypes.c_uint32),
                ("max_mv", ctypes.c_uint32), ("carrier_min_mhz", ctypes.c_uint32), ("carrier_max_mhz", ctypes.c_uint32),
                ("max_current_ma", ctypes.c_uint32), ("measures", ctypes.c_uint8),
                ("voltage_uv_per_lsb", ctypes.c_uint32), ("current_na_per_lsb", ctypes.c_uint32)]


class AmpCounters(ctypes.Structure):
    """amp.h's amp_counters_t."""

    _fields_ = [("frames_ok", ctypes.c_uint32), ("frames_bad", ctypes.c_uint32), ("frames_rejected", ctypes.c_uint32),
                ("sequence_gaps", ctypes.c_uint32), ("underruns", ctypes.c_uint32), ("watchdog_trips", ctypes.c_uint32),
                ("faults", ctypes.c_uint8), ("state", ctypes.c_uint8), ("envelope_uv", ctypes.c_int32),
                ("carrier_mhz", ctypes.c_uint32), ("play_index", ctypes.c_uint32), ("tx_dropped", ctypes.c_uint32)]


class AmpEvent(ctypes.Structure):
    """amp.h's amp_event_t: a sample applied (kind 0) or a watchdog trip (kind 1), at t_us + t_rem / rate_hz."""

    _fields_ = [("kind", ctypes.c_uint8), ("state", ctypes.c_uint8), ("t_us", ctypes.c_uint64),
                ("t_rem", ctypes.c_uint32), ("rate_hz", ctypes.c_uint32), ("envelope_uv", ctypes.c_int32),
                ("carrier_mhz", ctypes.c_uint32), ("index", ctypes.c_int64)]


OBSERVER = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.POINTER(AmpEvent))
EVENT_SAMPLE, EVENT_WATCHDOG_TRIP = 0, 1


def load_core(path: Path) -> ctypes.CDLL:
    """The core's shared library with its functions' signatures."""
    lib = ctypes.CDLL(str(path))
    u8p, u64 = ctypes.POINTER(ctypes.c_uint8), ctypes.c_uint64
    signatures = {
        "amp_init": (ctypes.c_int, [ctypes.c_void_p, ctypes.POINTER(HalBoard), ctypes.c_char_p, u64]),
        "amp_receive": (None, [ctypes.c_void_p, u8p, ctypes.c_size_t, u64]),
        "amp_advance": (None, [ctypes.c_void_p, u64]),
        "amp_fault": (None, [ctypes.c_void_p, ctypes.c_uint8, u64]),
        "amp_transmit": (ctypes.c_size_t, [ctypes.c_void_p, u8p, ctypes.c_size_t]),
        "amp_synthesize": (ctypes.c_size_t, [ctypes.c_void_p, ctypes.POINTER(ctypes.c_int16), ctypes.c_size_t]),
        "amp_counters": (None, [ctypes.c_void_p, ctypes.POINTER(AmpCounters)]),
        "amp_set_observer": (None, [ctypes.c_void_p, OBSERVER, ctypes.c_void_p]),
        "amp_sizeof": (ctypes.c_size_t, []),
        "amp_board_layout": (ctypes.c_size_t, [ctypes.POINTER(ctypes.c_size_t), ctypes.POINTER(ctypes.c_size_t),
                                               ctypes.c_size_t]),
    }
    for name, (result, arguments) in signatures.items():
        function = getattr(lib, name)
        function.restype, function.argtypes = result, arguments
    return lib


def board_layout_mismatch(lib: ctypes.CDLL) -> str | None:
    """How HalBoard differs from hal.h's hal_board_t as the library was built (amp_board_layout: its size,
    each field's offset and size), or None."""
    count = len(HalBoard._fields_)
    offsets, sizes = (ctypes.c_size_t * count)(), (ctypes.c_size_t * count)()
    theirs = (lib.amp_board_layout(offsets, sizes, count), list(zip(offsets, sizes)))
    fields = [getattr(HalBoard, field[0]) for field in HalBoard._fields_]
    ours = (ctypes.sizeof(HalBoard), [(field.offset, field.size) for field in fields])
    return None if theirs == ours else f"hal.h's (size, [(offset, size)]): {theirs}; HalBoard's: {ours}"


def board_for(info: wire.Info, output_rate_hz: int) -> HalBoard:
    """A board whose INFO is ``info``'s (the core adds its own constants: rates, buffer, watchdog, slew...)."""
    return HalBoard(name=b"conformance", output_rate_hz=output_rate_hz, full_scale_mv=info.full_scale_mv,
                    max_mv=info.max_mv, carrier_min_mhz=info.carrier_min_mhz, carrier_max_mhz=info.carrier_max_mhz,
                    max_current_ma=info.max_current_ma, measures=info.measures,
                    voltage_uv_per_lsb=info.full_scale_mv * 1000 // 32767, current_na_per_lsb=1000)


class CoreTarget(VirtualTarget):
    """The firmware's portable core in process (``lib``: load_core's), on a board of the emulator's INFO for
    DEVICE with the emulator's plate rate as its output rate, so that the carriers compare sample by sample."""

    name = "core"
    #: Carrier samples taken at once (the core keeps AMP_SYNTH_QUEUE envelope samples: 128 x 12 at 192 kHz).
    SYNTH_CHUNK = 4096

    def __init__(self, lib: ctypes.CDLL):
        super().__init__()
        self._lib = lib
        info = expected_info()
        self.full_scale_mv = info.full_scale_mv
        self.output_rate_hz = sim_rate_hz(info.carrier_max_mhz)
        self._board = board_for(info, self.output_rate_hz)  # the core keeps a pointer: it lives as long as this
        self._amp = ctypes.create_string_buffer(lib.amp_sizeof())
        self._samples: list[tuple[float, int, int, int, int]] = []
        self._trips_us: list[float] = []
        self._carrier: list[npt.NDArray[np.int16]] = []
        self._tx = (ctypes.c_uint8 * 4096)()
        self._synth = (ctypes.c_int16 * self.SYNTH_CHUNK)()
        self._observer = OBSERVER(self._observe)  # kept: the core calls it
        refused = lib.amp_init(self._amp, ctypes.byref(self._board), b"CONF-1", ORIGIN_US)
        assert refused == 0, f"the core refused the conformance board (amp.h AMP_BOARD_* {refused})"
        lib.amp_set_observer(self._amp, self._observer, None)

    def _observe(self, _ctx: int | None, event_p: ctypes._Pointer[AmpEvent]) -> None:
        event = event_p.contents
        t_us = event.t_us - ORIGIN_US + event.t_rem / event.rate_hz
        if event.kind == EVENT_SAMPLE:
            self._samples.append((t_us, event.envelope_uv, event.carrier_mhz, event.index, event.state))
        elif event.kind == EVENT_WATCHDOG_TRIP:
            self._trips_us.append(t_us)

    def write(self, data: bytes) -> None:
        buffer = (ctypes.c_uint8 * len(data)).from_buffer_copy(data)
        self._lib.amp_receive(self._amp, buffer, len(data), ORIGIN_US + self.now_us)
        self._collect()

    def _advance(self) -> None:
        self._lib.amp_advance(self._amp, ORIGIN_US + self.now_us)

    def _collect(self) -> None:
        while count := self._lib.amp_transmit(self._amp, self._tx, len(self._tx)):
            self._sent(bytes(self._tx[:count]), self.now_us)
        while count := self._lib.amp_synthesize(self._amp, self._synth, self.SYNTH_CHUNK):
            self._carrier.append(np.ctypeslib.as_array(self._synth)[:count].copy())

    def fault(self, bits: int) -> None:
        self._lib.amp_fault(self._amp, bits, ORIGIN_US + self.now_us)
        self._collect()

    def counters(self) -> dict[str, int]:
        counters = AmpCounters()
        self._lib.amp_counters(self._amp, ctypes.byref(counters))
        return {name: int(getattr(counters, name)) for name, *_ in AmpCounters._fields_ if name != "tx_dropped"}

    def applied(self) -> Applied:
        columns = list(zip(*self._samples)) or [(), (), (), (), ()]
        return Applied(t_us=np.array(columns[0], np.float64), envelope_uv=np.array(columns[1], np.float64),
                       carrier_mhz=np.array(columns[2], np.int64), index=np.array(columns[3], np.int64),
                       state=np.array(columns[4], np.int64))

    def trips_us(self) -> list[float]:
        return list(self._trips_us)

    def carrier_mv(self) -> npt.NDArray[np.float64]:
        """Every carrier sample amp_synthesize gave so far (mV at the output), at ``output_rate_hz``."""
        samples = np.concatenate(self._carrier) if self._carrier else np.zeros(0, np.int16)
        return samples.astype(np.float64) * self.full_scale_mv / 32767
