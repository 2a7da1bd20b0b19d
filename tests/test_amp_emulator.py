"""The amplifier emulator against docs/amp-protocol.md, on a virtual clock: every time exact, nothing waited for.

Each test runs the :class:`~tpad_rt.amp.emulator.Emulator` (its real-time loop, the fault
plan of ``--fault``, the Amplifier behind it) on a :class:`~tpad_rt.amp.emulator.MemoryLine`
and a :class:`~tpad_rt.clock.VirtualClock`, with the test as its host: the host's writes are
the clock's events, so a frame arrives at a time the test chose, to the ns, and the
emulator reads it then. The host has a small codec of its own (``cobs`` and ``crc`` used
directly, the struct layouts written again from the document), so a misreading of the
document in tpad_rt/amp/wire.py shows up here. Two tests drive the Amplifier alone on given
times (a restart and HELLO's ramp, sample by sample; STATUS skipped when overdue) and one
the recording's limit. The emulator's process on a real pty is
tests/test_amp_emulator_process.py's.
"""

from __future__ import annotations

import math
import struct
import tracemalloc
from collections import namedtuple
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from cobs import cobs  # type: ignore[import-untyped]
from crc import Calculator, Crc16

from cli_run import tpad_rt
from tpad_rt.amp.emulator import (
    HOST_GONE_WAIT_S, MAX_UNSENT_BYTES, RAMP_MS, READ_LATENCY_S, RECORDED_COLUMNS, TICK_S, WATCHDOG_MS, Amplifier,
    Circuit,
    Emulator, FaultPlan, MemoryLine, Plate, Recorder, amplifier_info, recording_scalars, sim_rate_hz, write_recording,
)
from tpad_rt.cli.amp import fault_plan, fault_spec
from tpad_rt.clock import VirtualClock
from tpad_rt.device import Device
from tpad_rt.errors import ConfigError

DEVICE = Device.default()
#: Contact force (N) at which the emulator simulates the plate and its circuit.
FORCE_N = 0.5
CIRCUIT = Circuit(DEVICE, FORCE_N)
INFO_SENT = amplifier_info(DEVICE, CIRCUIT)
#: The virtual clock's start (ns): the amplifier's origin, 1000 s (nothing may rely on a clock starting at 0).
ORIGIN_NS = 1000 * 10**9
ORIGIN_S = ORIGIN_NS / 1e9
#: A4: the watchdog trips this long (s) after the last valid frame was read: A4's watchdog_ms - R = 40 ms, less 2 ms
#: for the emulator's own reading latency (``tpad-rt amp emulate --help``).
TRIP_S = 0.038
assert TRIP_S == (WATCHDOG_MS - RAMP_MS) / 1000 - READ_LATENCY_S

# --- the test's own codec, from docs/amp-protocol.md ------------------------------------------------------------

_CRC16 = Calculator(Crc16.IBM_3740.value, optimized=True)


def crc16(data: bytes) -> int:
    return int(_CRC16.checksum(data))


#: The protocol version the document describes (byte 0 of every body).
VERSION = 2
HELLO, SET_CARRIER, START, ENVELOPE, STOP, KEEPALIVE = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
INFO, STATUS, ACK = 0x81, 0x82, 0x83
OK, BAD_VERSION, UNKNOWN_TYPE, BAD_LENGTH, OUT_OF_RANGE, NO_CARRIER, BAD_RATE, NOT_STARTED, OUT_OF_WINDOW, FAULT \
    = range(10)
IDLE, PRIMING, RUNNING, RAMPING, FAULTED = range(5)
OVERCURRENT = 1

#: A frame the host received: ``t_s`` when the emulator wrote it (s from the origin).
Received = namedtuple("Received", "type seq payload t_s")
Info = namedtuple("Info", "firmware serial rates carrier_min_mhz carrier_max_mhz carrier_step_mhz full_scale_mv "
                          "max_mv slew_mv_per_ms buffer_samples max_frame_samples watchdog_ms status_period_ms "
                          "measures hello_nonce max_current_ma")
Status = namedtuple("Status", "time_us play_index buffer_fill state faults frames_ok frames_bad frames_rejected "
                              "sequence_gaps underruns watchdog_trips last_seq phase_cdeg envelope_mv "
                              "voltage_mv_rms current_ua_rms carrier_mhz")
Ack = namedtuple("Ack", "acked_seq acked_type code value")


def body(type_: int, seq: int, payload: bytes = b"", version: int = VERSION) -> bytes:
    """Header, payload and CRC (low byte first)."""
    head = struct.pack("<BBH", version, type_, seq & 0xFFFF) + payload
    return head + struct.pack("<H", crc16(head))


def frame(type_: int, seq: int, payload: bytes = b"", version: int = VERSION) -> bytes:
    """The bytes on the line: COBS, then 0x00."""
    return cobs.encode(body(type_, seq, payload, version)) + b"\x00"


def u32(value: int) -> bytes:
    return struct.pack("<I", value & 0xFFFFFFFF)


def envelope(first_index: int, samples: np.ndarray) -> bytes:
    return u32(first_index) + np.asarray(samples, dtype="<i2").tobytes()


def start(rate_hz: int, start_index: int, prefill: int) -> bytes:
    return struct.pack("<IIH", rate_hz, start_index & 0xFFFFFFFF, prefill)


def hello(nonce: int = 0x5EED0001) -> bytes:
    return b"test".ljust(12, b"\x00") + u32(nonce)


def stop(ramp_ms: int) -> bytes:
    return struct.pack("<H", ramp_ms)


def decode(encoded: bytes) -> tuple[int, int, bytes] | None:
    """(type, seq, payload) of the frame between two 0x00, or None unless it is a valid frame of VERSION."""
    try:
        decoded = cobs.decode(encoded)
    except cobs.DecodeError:
        return None
    if len(decoded) < 6 or crc16(decoded[:-2]) != struct.unpack_from("<H", decoded, len(decoded) - 2)[0] \
            or decoded[0] != VERSION:
        return None
    return decoded[1], struct.unpack_from("<H", decoded, 2)[0], decoded[4:-2]


def frames_in(sent: bytes) -> list[tuple[int, int, bytes]]:
    """The frames in bytes an Amplifier sent, each valid: (type, seq, payload)."""
    found = [decode(encoded) for encoded in sent.split(b"\x00") if encoded]
    assert None not in found, sent
    return [received for received in found if received is not None]


def parse_status(payload: bytes) -> Status:
    return Status._make(struct.unpack("<IIHBBIIIIIIHhiIII", payload))


def parse_info(payload: bytes) -> Info:
    fields = struct.unpack("<16s16s4I6I4HB3xII", payload)
    return Info(fields[0].rstrip(b"\0").decode(), fields[1].rstrip(b"\0").decode(), fields[2:6], *fields[6:19])


def impedance(carrier_hz: float) -> complex:
    """The device's load (ohm): the shunt in series with C0 parallel to the motional R + L + C."""
    l_h, c_f, r_ohm = (float(value) for value in DEVICE.motional(FORCE_N))
    omega = 2 * math.pi * carrier_hz
    motional = r_ohm + 1j * omega * l_h + 1 / (1j * omega * c_f)
    return DEVICE.shunt_ohm + 1 / (1j * omega * DEVICE.c0_f + 1 / motional)


RESONANCE_MHZ = round(DEVICE.carrier_hz * 1000)
FULL_SCALE_MV = round(DEVICE.max_voltage_v * 1250)
MAX_MV = round(DEVICE.max_voltage_v * 1000)


def level(volts: float) -> int:
    """The sample value for ``volts`` peak."""
    return round(volts * 1000 / FULL_SCALE_MV * 32767)


def volts(samples: np.ndarray) -> np.ndarray:
    """What the samples ask for (V), as ENVELOPE says (-32768 read as -32767)."""
    return np.maximum(np.asarray(samples, dtype=np.float64), -32767) / 32767 * FULL_SCALE_MV / 1000


# --- the emulator on a virtual clock, and the test as its host --------------------------------------------------

def ns(t_s: float) -> int:
    """The virtual clock's reading (ns) ``t_s`` (s) after the origin."""
    return ORIGIN_NS + round(t_s * 1e9)


@dataclass
class Sent:
    """A frame the host wrote: its seq and time (s from the origin), known once written."""

    seq: int = -1
    t_s: float = math.nan


class Rig:
    """The Emulator with ``plan`` on a MemoryLine and a VirtualClock starting at the origin; the test is its host.

    The host's actions are scheduled at times in s from the origin (``send``, ``write``, ``at``);
    :meth:`run` runs the emulator until a time (or ``stopping``), then what it sent is in
    ``frames`` (each with the time it was written) and what it applied in :meth:`recording`.
    """

    def __init__(self, plan: FaultPlan = FaultPlan(), *, output_room: int | None = None,
                 duration_s: float | None = None):
        self.clock = VirtualClock(ORIGIN_NS)
        self.line = MemoryLine(self.clock, output_room=output_room)
        self.recorder = Recorder()
        self.amplifier = Amplifier(INFO_SENT, CIRCUIT, Plate(DEVICE, FORCE_N, sim_rate_hz(INFO_SENT.carrier_max_mhz)),
                                   ORIGIN_S, self.recorder, on_hello=self.line.discard_output)
        self.emulator = Emulator(self.amplifier, self.line, plan, self.clock, duration_s)
        self.seq = 0
        self.frames: list[Received] = []
        self.bad: list[bytes] = []
        self.stopping = False
        #: Whether the host reads what came before each write of its own (a HELLO drops what it has not read).
        self.reading = True
        #: When (s) the host wrote each valid frame (what resets the watchdog, A4).
        self.fed_s: list[float] = []
        self._pending = b""

    def now_s(self) -> float:
        """The virtual time (s from the origin), exact to the ns."""
        return (self.clock.now_ns() - ORIGIN_NS) / 1e9

    def at(self, t_s: float, action: Callable[[], None]) -> None:
        self.clock.at(ns(t_s), action)

    def write(self, t_s: float, data: bytes, *, feeds: bool = False) -> None:
        """Write ``data`` at ``t_s`` (``feeds``: a valid frame, logged in ``fed_s``)."""
        def written() -> None:
            self._read_before_writing()
            self.line.feed(data)
            if feeds:
                self.fed_s.append(self.now_s())
        self.at(t_s, written)

    def send(self, t_s: float, type_: int, payload: bytes = b"", *, version: int = VERSION) -> Sent:
        """Write one frame at ``t_s`` with the host's next seq then (HELLO: seq 0, and the count restarts)."""
        sent = Sent()

        def written() -> None:
            self._read_before_writing()
            if type_ == HELLO:
                self.seq = 0
            sent.seq, sent.t_s, self.seq = self.seq, self.now_s(), (self.seq + 1) & 0xFFFF
            self.line.feed(frame(type_, sent.seq, payload, version))
            self.fed_s.append(sent.t_s)
        self.at(t_s, written)
        return sent

    def _read_before_writing(self) -> None:
        if self.reading:
            self.receive()

    def run(self, until_s: float, *, whole_frames: bool = True) -> str:
        """Run the emulator until ``until_s`` (or ``stopping``), as SIGTERM would end it; why it ended.

        ``whole_frames``: check that every frame the host read decodes (none cut short or broken).
        """
        self.at(until_s, self.stop_when_sent())
        reason = self.emulator.run(lambda: self.stopping)
        self.receive()
        assert not whole_frames or self.bad == [], self.bad[:3]
        return reason

    # --- what the emulator sent ---

    def receive(self) -> None:
        """Decode what the emulator wrote since the last call into ``frames`` (``bad`` for what does not decode)."""
        for t_ns, data in self.line.take():
            *complete, self._pending = (self._pending + data).split(b"\x00")
            for encoded in complete:
                decoded = decode(encoded) if encoded else None
                if decoded is None:
                    self.bad += [encoded] if encoded else []
                else:
                    self.frames.append(Received(*decoded, (t_ns - ORIGIN_NS) / 1e9))

    def statuses(self, after_s: float = -math.inf) -> list[Status]:
        return [parse_status(received.payload) for received in self.frames
                if received.type == STATUS and received.t_s >= after_s]

    def status_at(self, t_s: float) -> Status:
        """The only STATUS written at ``t_s``."""
        found = [parse_status(received.payload) for received in self.frames
                 if received.type == STATUS and received.t_s == t_s]
        assert len(found) == 1, (t_s, found)
        return found[0]

    def answer(self, sent: Sent) -> Received:
        """The first ACK of ``sent`` (the first with its seq from its time on)."""
        found = [received for received in self.frames if received.type == ACK and received.t_s >= sent.t_s
                 and struct.unpack_from("<H", received.payload)[0] == sent.seq]
        assert found, sent
        return found[0]

    def ack(self, sent: Sent) -> Ack:
        """The first ACK of ``sent``, parsed."""
        return Ack._make(struct.unpack("<HBBI", self.answer(sent).payload))

    def acked(self, sent: Sent) -> bool:
        return any(received.type == ACK and struct.unpack_from("<H", received.payload)[0] == sent.seq
                   and received.t_s >= sent.t_s for received in self.frames)

    def infos(self) -> list[tuple[float, int, Info]]:
        """(time, seq, INFO) of each INFO."""
        return [(received.t_s, received.seq, parse_info(received.payload)) for received in self.frames
                if received.type == INFO]

    def recording(self) -> dict[str, np.ndarray]:
        """What ``--record`` would write: the columns (``t_s`` from the origin) and the scalars."""
        recorded = {name: self.recorder.column(name) for name in RECORDED_COLUMNS}
        recorded["t_s"] = recorded["t_s"] - ORIGIN_S
        scalars = recording_scalars(self.amplifier, self.recorder)
        recorded.update({name: np.asarray(value) for name, value in scalars.items()})
        recorded["watchdog_trip_t_s"] = recorded["watchdog_trip_t_s"] - ORIGIN_S
        return recorded

    # --- a host that streams ---

    def begin(self, t_s: float, rate_hz: int, start_index: int, prefill: int,
              carrier_mhz: int = RESONANCE_MHZ) -> tuple[Sent, Sent, Sent]:
        """HELLO, SET_CARRIER and START at ``t_s``, 1 ms apart; check their answers with :meth:`check_begun`."""
        return (self.send(t_s, HELLO, hello()), self.send(t_s + 0.001, SET_CARRIER, u32(carrier_mhz)),
                self.send(t_s + 0.002, START, start(rate_hz, start_index, prefill)))

    def check_begun(self, begun: tuple[Sent, Sent, Sent], start_index: int) -> Info:
        """INFO answered the HELLO, SET_CARRIER and START were answered OK; the INFO."""
        (info_t_s, _, info), = [found for found in self.infos() if found[0] == begun[0].t_s]
        assert self.ack(begun[1]).code == OK
        assert self.ack(begun[2])[2:] == (OK, start_index & 0xFFFFFFFF)
        return info

    def stream(self, from_s: float, samples: np.ndarray, first_index: int, *, fill: int = 896,
               frame_samples: int = 64, poll_s: float = 0.001,
               instead: dict[int, Callable[[int, np.ndarray], None]] | None = None,
               until: Callable[[Status], bool] = lambda status: False,
               then: Callable[[], None] = lambda: None) -> None:
        """From ``from_s`` on, every ``poll_s``: read what came, and send ``samples`` from stream index
        ``first_index`` on in frames of ``frame_samples``, at most ``fill`` samples ahead of the last STATUS's
        play_index; until all are sent (then ``then()``), a STATUS is ``until``, or the amplifier left the stream.

        A frame starting at an offset in ``instead`` is not sent; ``instead[offset](index, samples)`` is called.
        """
        progress = {"sent": 0, "played": 0, "seen": len(self.frames), "streaming": False}

        def poll() -> None:
            self.receive()
            for received in self.frames[progress["seen"]:]:
                if received.type != STATUS:
                    continue
                status = parse_status(received.payload)
                if until(status):
                    return
                if status.state in (PRIMING, RUNNING):
                    progress["streaming"] = True
                    progress["played"] = (status.play_index - first_index) & 0xFFFFFFFF
                elif progress["streaming"]:
                    return  # it left the stream (a fault, its watchdog): the test's checks say what follows
            progress["seen"] = len(self.frames)
            while progress["sent"] < len(samples) and progress["sent"] - progress["played"] < fill:
                offset = progress["sent"]
                chunk = samples[offset:offset + frame_samples]
                if offset in (instead or {}):
                    instead[offset](first_index + offset, chunk)  # type: ignore[index]
                else:
                    self.send(self.now_s(), ENVELOPE, envelope(first_index + offset, chunk))
                progress["sent"] += len(chunk)
            if progress["sent"] < len(samples):
                self.at(self.now_s() + poll_s, poll)
            else:
                then()
        self.at(from_s, poll)

    def stop_when_sent(self) -> Callable[[], None]:
        """A ``then`` for :meth:`stream`: end the run (as SIGTERM) once everything is sent."""
        def stopping() -> None:
            self.stopping = True
        return stopping


def played(recording: dict[str, np.ndarray]) -> np.ndarray:
    """Positions of the recorded samples that played a stream index from the buffer (a missing one is -1)."""
    return np.flatnonzero(recording["index"] >= 0)


def zero_from(recording: dict[str, np.ndarray]) -> int:
    """Position of the first recorded sample from which the envelope stays 0 to the end."""
    nonzero = np.flatnonzero(recording["envelope_v"] != 0)
    return int(nonzero[-1]) + 1 if nonzero.size else 0


def first_due(anchor_s: float, rate_hz: int, after_s: float) -> float:
    """The first sample time ``anchor_s + n / rate_hz`` at or after ``after_s``."""
    return anchor_s + math.ceil(round((after_s - anchor_s) * rate_hz, 6)) / rate_hz


# --- session, messages, checks ----------------------------------------------------------------------------------

def test_hello_answers_info_and_status_follows() -> None:
    """Nothing but ACKs before the first HELLO; INFO at once, echoing each HELLO's nonce, numbered from 0; STATUS
    one period after the last HELLO, its counters reset (HELLO itself counted)."""
    rig = Rig()
    early = rig.send(0.050, KEEPALIVE, version=1)
    rig.at(0.060, rig.receive)  # read before the HELLO, which drops what the host has not read
    hellos = [rig.send(0.100 + 0.010 * k, HELLO, hello(nonce)) for k, nonce in
              enumerate((0x5EED0001, 0xFFFFFFFF, 0, 0x5EED0001))]
    rig.run(0.150)
    assert [(received.t_s, received.type) for received in rig.frames if received.t_s < 0.100] == [(0.050, ACK)]
    assert rig.ack(early)[2:] == (BAD_VERSION, VERSION)
    infos = rig.infos()
    assert [(t_s, seq, info.hello_nonce) for t_s, seq, info in infos] == [
        (0.100, 0, 0x5EED0001), (0.110, 0, 0xFFFFFFFF), (0.120, 0, 0), (0.130, 0, 0x5EED0001)]
    info = infos[0][2]
    assert info.firmware.startswith("tpad-emu") and info.serial
    assert {8000, 16000} <= set(info.rates) and all(rate in (0, 4000, 8000, 12000, 16000) for rate in info.rates)
    assert info.carrier_min_mhz <= min(10_000_000, RESONANCE_MHZ)
    assert info.carrier_max_mhz >= max(80_000_000, RESONANCE_MHZ)
    assert (info.full_scale_mv, info.max_mv) == (FULL_SCALE_MV, MAX_MV) and info.max_mv <= info.full_scale_mv
    assert info.slew_mv_per_ms * 5 >= info.max_mv  # a 5 ms ramp to max volts is not slew-limited
    assert info.buffer_samples == 1024 and 1 <= info.max_frame_samples <= 256
    assert 0 < info.watchdog_ms <= 50 and 1 <= info.status_period_ms <= 100
    assert info.measures == 7 and info.max_current_ma > 0
    last = [received for received in rig.frames if received.t_s >= hellos[-1].t_s]
    assert last[0].type == INFO and [received.seq for received in last] == list(range(len(last)))
    assert [received.t_s for received in last[1:]] == [0.135, 0.140, 0.145, 0.150]  # STATUS, one period apart
    status = parse_status(last[1].payload)
    assert status.state == IDLE and status.faults == 0 and status.carrier_mhz == 0 and status.time_us == 135_000
    assert status.frames_ok == 1 and status.last_seq == 0  # the HELLO itself, acted on after the reset
    assert (status.frames_bad, status.frames_rejected, status.sequence_gaps, status.underruns,
            status.watchdog_trips, status.envelope_mv) == (0, 0, 0, 0, 0, 0)


def test_status_goes_out_every_period() -> None:
    """A8: STATUS every status_period_ms from HELLO on, on the amplifier's microsecond clock, written at the time
    its time_us says, to the ns; each HELLO restarts the schedule."""
    rig = Rig()
    first, again = rig.send(0.0123457, HELLO, hello()), rig.send(0.3000011, HELLO, hello())
    rig.run(0.400)
    before = [received.t_s for received in rig.frames if received.type == STATUS and received.t_s < again.t_s]
    assert np.allclose(before, (round(first.t_s * 1e6) + 5000 * np.arange(1, 58)) / 1e6, rtol=0, atol=1e-9)
    assert [status.time_us for status in rig.statuses()[:57]] == [round(t_s * 1e6) for t_s in before]
    after = [received.t_s for received in rig.frames if received.type == STATUS and received.t_s > again.t_s]
    assert np.allclose(after, (round(again.t_s * 1e6) + 5000 * np.arange(1, 20)) / 1e6, rtol=0, atol=1e-9)


def test_an_overdue_status_is_skipped_not_sent_late() -> None:
    """The Amplifier alone: advanced 1 s at once (the emulator was stopped), it sends the STATUS of the last 0.1 s
    only."""
    amplifier = Amplifier(INFO_SENT, CIRCUIT, Plate(DEVICE, FORCE_N, sim_rate_hz(INFO_SENT.carrier_max_mhz)), ORIGIN_S)
    amplifier.receive(frame(HELLO, 0, hello())[:-1], ORIGIN_S)
    amplifier.advance(ORIGIN_S + 1.0)
    sent = frames_in(bytes(amplifier.out))
    times_us = [parse_status(payload).time_us for type_, _, payload in sent if type_ == STATUS]
    assert times_us == list(range(900_000, 1_000_001, 5000))


def test_set_carrier_answers_the_achieved_frequency() -> None:
    rig = Rig()
    rig.send(0, HELLO, hello())
    step = INFO_SENT.carrier_step_mhz
    asked = [RESONANCE_MHZ, RESONANCE_MHZ + 4, RESONANCE_MHZ + step // 2 + 1, INFO_SENT.carrier_min_mhz,
             INFO_SENT.carrier_max_mhz, RESONANCE_MHZ + 1]
    refused = [INFO_SENT.carrier_min_mhz - 1, INFO_SENT.carrier_max_mhz + 1, 0, 2**32 - 1]
    sent = [rig.send(0.001 * (k + 1), SET_CARRIER, u32(carrier)) for k, carrier in enumerate(asked + refused)]
    other_version = rig.send(0.020, SET_CARRIER, u32(RESONANCE_MHZ + 3000), version=1)
    rig.run(0.026)
    info = rig.infos()[0][2]
    assert info.carrier_step_mhz == step
    for carrier, command in zip(asked, sent):
        ack = rig.ack(command)
        assert ack.code == OK and ack.value % step == 0 and abs(ack.value - carrier) <= step / 2, (carrier, ack)
        assert info.carrier_min_mhz <= ack.value <= info.carrier_max_mhz
    assert [rig.ack(command).code for command in sent[len(asked):]] == [OUT_OF_RANGE] * len(refused)
    assert rig.ack(other_version) == (other_version.seq, SET_CARRIER, BAD_VERSION, VERSION)  # A5
    assert rig.status_at(0.025).carrier_mhz == rig.ack(sent[len(asked) - 1]).value  # refused frames changed nothing


def test_refused_frames_are_answered_and_counted() -> None:
    rig = Rig()
    rig.send(0, HELLO, hello())
    refusals = [(rig.send(0.001, 0x07), UNKNOWN_TYPE), (rig.send(0.001, INFO, bytes(92)), UNKNOWN_TYPE),
                (rig.send(0.001, SET_CARRIER, bytes(3)), BAD_LENGTH), (rig.send(0.001, KEEPALIVE, b"\x00"), BAD_LENGTH),
                (rig.send(0.001, HELLO, bytes(15)), BAD_LENGTH)]
    versions = [rig.send(0.002, KEEPALIVE, version=version) for version in (0, 1, 3, 255)]
    keepalive = rig.send(0.003, KEEPALIVE)

    def gap() -> None:
        rig.seq += 10  # a gap of 10 in the host's seq
    rig.at(0.003, gap)
    rig.send(0.003, KEEPALIVE)
    stopped = rig.send(0.004, STOP, stop(5))  # STOP while IDLE: nothing to stop
    rig.send(0.006, HELLO, hello())
    rig.run(0.011)
    assert [rig.ack(sent).code for sent, _ in refusals] == [code for _, code in refusals]
    assert [rig.ack(sent)[2:] for sent in versions] == [(BAD_VERSION, VERSION)] * 4  # A5
    assert not rig.acked(keepalive)
    assert rig.ack(stopped) == (stopped.seq, STOP, OK, 0)
    status = rig.status_at(0.005)
    assert (status.frames_ok, status.frames_rejected, status.frames_bad) == (4, 9, 0)
    assert status.sequence_gaps == 1 and status.last_seq == stopped.seq
    status = rig.status_at(0.011)  # after the second HELLO
    assert (status.frames_ok, status.frames_rejected, status.sequence_gaps) == (1, 0, 0)


def test_start_priming_running_and_the_window() -> None:
    """START's checks in order; PRIMING until prefill, ENVELOPE refused (not answered) out of the window or badly
    sized; RUNNING plays the first index at the sample clock's first due time after the prefill came."""
    rig = Rig()
    first = 2**32 - 8  # the stream wraps at 2**32
    rig.send(0, HELLO, hello())
    no_carrier = rig.send(0.001, START, start(16000, first, 32))
    rig.send(0.002, SET_CARRIER, u32(RESONANCE_MHZ))
    checks = [(rig.send(0.003, START, start(12000, first, 32)), BAD_RATE),
              (rig.send(0.003, START, start(0, first, 32)), BAD_RATE),  # an unused entry of the rates is no rate
              (rig.send(0.003, START, start(16000, first, 0)), OUT_OF_RANGE),
              (rig.send(0.003, START, start(16000, first, 1025)), OUT_OF_RANGE)]
    samples = np.full(16, level(2.0), dtype=np.int16)
    refused = [rig.send(0.004, ENVELOPE, envelope(first, samples))]  # not started
    started = rig.send(0.010, START, start(16000, first, 32))
    rig.send(0.0101, ENVELOPE, envelope(first, samples))
    refused += [
        rig.send(0.0102, ENVELOPE, envelope(first - 1, samples)),  # index first - 1 is before play_index
        rig.send(0.0102, ENVELOPE, envelope(first + 1024 - 15, samples)),  # the last index is past the window
        rig.send(0.0102, ENVELOPE, u32(first + 16)),  # no samples
        rig.send(0.0102, ENVELOPE, u32(first + 16) + b"\x01\x00\x02"),  # half a sample
    ]
    rig.send(0.0102, ENVELOPE, envelope(first + 1024 - 16, samples))  # the window's last 16: accepted
    prefilled = rig.send(0.0123, ENVELOPE, envelope(first + 16, samples))  # 32 samples from first: prefill reached
    stopped = rig.send(0.016, STOP, stop(5))
    rig.run(0.030)
    assert rig.ack(no_carrier).code == NO_CARRIER
    assert [rig.ack(sent).code for sent, _ in checks] == [code for _, code in checks]
    assert rig.ack(started) == (started.seq, START, OK, first)
    status = rig.status_at(0.005 * 3)  # 15 ms: after START, the prefill not yet reached... then reached at 12.3 ms
    assert status.state == RUNNING
    priming = rig.status_at(0.010)  # at START's own time: the STATUS went out before START was read
    assert priming.state == IDLE
    assert not any(rig.acked(sent) for sent in refused)  # ENVELOPE refusals are not answered
    assert rig.ack(stopped) == (stopped.seq, STOP, OK, 0)
    recording = rig.recording()
    assert (recording["frames_ok"], recording["frames_rejected"]) == (7, 10)  # HELLO, SET_CARRIER, START, 3 ENVELOPE, STOP
    index, t_s, state = recording["index"], recording["t_s"], recording["state"]
    assert (state[t_s < prefilled.t_s] == PRIMING).all() and (index[t_s < prefilled.t_s] == -1).all()
    at = played(recording)
    assert t_s[at[0]] == pytest.approx(first_due(started.t_s, 16000, prefilled.t_s + 1e-12), abs=1e-9)
    assert index[at[0]] == first and (np.diff(t_s[at]) == pytest.approx(1 / 16000, abs=1e-9))
    assert index[at].tolist() == [(first + k) % 2**32 for k in range(32)]  # the 16 at the window's end never play
    assert state[-1] == IDLE


def test_a_host_that_goes_away_and_a_new_one() -> None:
    """A host that stops reading leaves STATUS queued; a new host's HELLO drops them, so INFO is the first frame
    it reads. A host gone (reads end) is polled again only after HOST_GONE_WAIT_S: the emulator does not spin."""
    rig = Rig()
    rig.reading = False
    rig.send(0, HELLO, hello())
    unread = []
    rig.at(0.0999, lambda: unread.append(rig.line.unread_bytes))
    rig.send(0.100, HELLO, hello(7))

    def reading_again() -> None:
        rig.reading = True
    rig.at(0.1001, reading_again)

    def hang_up() -> None:
        rig.line.hung_up = True  # the emulator's next read (at once: it wakes for the host's events) finds it gone
        unread.append(rig.line.reads)

    def back() -> None:
        rig.line.hung_up = False
        unread.append(rig.line.reads)
    rig.at(0.2013, hang_up)
    rig.send(0.250, HELLO, hello(8))  # sent while gone: read once the emulator polls again
    rig.at(0.260, back)
    rig.run(0.400)
    assert unread[0] >= 19 * 64  # 19 STATUS
    first_read = [received for received in rig.frames if received.t_s >= 0.100]
    assert (first_read[0].type, first_read[0].seq, first_read[0].t_s) == (INFO, 0, 0.100)
    assert parse_info(first_read[0].payload).hello_nonce == 7
    assert unread[2] - unread[1] == 1  # one read found the host gone, then none until it polled again
    (info_t_s, _, info), = [found for found in rig.infos() if found[2].hello_nonce == 8]
    # read at the emulator's first wake after the wait (a STATUS's time)
    assert 0.2013 + HOST_GONE_WAIT_S <= info_t_s < 0.2013 + HOST_GONE_WAIT_S + 0.005


def test_garbage_and_floods_leave_it_working() -> None:
    """A 10 MB run without 0x00 is one bad frame and takes no memory beyond a bounded read; random bytes are bad
    frames; it still works."""
    rig = Rig()
    rng = np.random.default_rng(1)
    flood = rng.integers(1, 256, 10 * 2**20, dtype=np.uint8).tobytes() + b"\x00"
    rig.send(0, HELLO, hello())
    rig.write(0.001, flood)
    keepalive = rig.send(0.001, KEEPALIVE)
    rig.write(0.006, rng.integers(0, 256, 200_000, dtype=np.uint8).tobytes() + b"\x00")
    stopped = rig.send(0.006, STOP, stop(0))
    rig.send(0.011, HELLO, hello(2))
    tracemalloc.start()
    try:
        rig.run(0.016)
        _, peak_bytes = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak_bytes < 2**20  # the line holds the flood; the emulator reads it 64 KB at a time and keeps none
    assert not rig.acked(keepalive)
    status = rig.status_at(0.005)
    assert (status.frames_ok, status.frames_bad) == (2, 1)
    assert rig.ack(stopped).code == OK and rig.status_at(0.010).frames_bad > 1
    assert [info.hello_nonce for _, _, info in rig.infos()] == [0x5EED0001, 2]


def test_a_host_that_does_not_read_loses_whole_frames() -> None:
    """Past MAX_UNSENT_BYTES unsent, the emulator drops what it holds and ends a frame cut short with 0x00: the
    host, reading again, finds at most one bad frame, then whole ones."""
    rig = Rig(output_room=4096)
    rig.send(0, HELLO, hello())
    rig.at(6.0, rig.receive)
    rig.run(6.1, whole_frames=False)
    assert rig.emulator.dropped_out_bytes > MAX_UNSENT_BYTES
    assert len(rig.bad) <= 1
    late = rig.statuses(after_s=6.0)
    assert late and np.all(np.diff([status.time_us for status in late]) == 5000)


# --- what plays: the recordings ---------------------------------------------------------------------------------

def test_envelope_plays_at_its_index() -> None:
    """A3: every sample sent plays once, at its index, in order, at its due time; then STOP's ramp."""
    rig = Rig()
    first = 2**32 - 4000
    begun = rig.begin(0, 16000, first, 256)
    t = np.arange(8000) / 16000
    samples = np.round(32767 * (0.35 - 0.25 * np.cos(2 * np.pi * 20 * t))).astype(np.int16)  # 5 V (a slew step)..30 V
    stopped: list[Sent] = []
    rig.stream(0.003, samples, first, then=lambda: stopped.append(rig.send(rig.now_s(), STOP, stop(5))))
    rig.run(0.8)
    info = rig.check_begun(begun, first)
    assert rig.ack(stopped[0]).code == OK
    recording = rig.recording()
    assert recording["envelope_hz"] == 16000
    assert (recording["frames_bad"], recording["frames_rejected"], recording["underruns"],
            recording["watchdog_trips"]) == (0, 0, 0, 0)
    at = played(recording)
    offset = (recording["index"][at].astype(np.int64) - first) % 2**32  # from the first index, across the wrap
    assert (offset == np.arange(len(at))).all()  # each once, in order, none missing
    assert len(samples) - info.buffer_samples < len(at) < len(samples)  # STOP cut the last buffered samples
    assert (recording["envelope_v"][at] == volts(samples[offset])).all()
    due = recording["t_s"][at] - offset / 16000  # each at its due time, one sample period apart
    assert np.allclose(due, due[0], rtol=0, atol=1e-9)
    assert (recording["carrier_hz"][at] == RESONANCE_MHZ / 1000).all()
    assert (recording["state"][at] == RUNNING).all()
    # STOP: from the present value linearly to 0 over 5 ms (80 samples), then IDLE; its first ramp sample is the
    # first due after STOP came.
    ramp = recording["envelope_v"][at[-1] + 1:at[-1] + 81]
    assert np.allclose(ramp, recording["envelope_v"][at[-1]] * (1 - np.arange(1, 81) / 80), rtol=0, atol=1e-12)
    assert zero_from(recording) == at[-1] + 80 and recording["state"][at[-1] + 80] == IDLE
    assert recording["t_s"][at[-1]] < stopped[0].t_s <= recording["t_s"][at[-1] + 1]
    # The plate follows the envelope: near the steady amplitude per volt at the sine's peaks.
    peak = at[np.argmax(recording["envelope_v"][at])]
    steady_um = float(DEVICE.amplitude_m_per_v(FORCE_N)) * 1e6 * recording["envelope_v"][peak]
    assert abs(recording["plate_amplitude_um"][peak] / steady_um - 1) < 0.1


def test_gaps_and_bad_frames_play_as_zero() -> None:
    """A3: a frame lost to a bad CRC, one lost to broken COBS, one of another version: their indices play as 0,
    one underrun each; bad frames are counted and never applied, the other version is answered BAD_VERSION."""
    rig = Rig()
    begun = rig.begin(0, 16000, 0, 64)
    samples = np.full(4000, level(3.0), dtype=np.int16)  # 3 V: within one slew step of 0
    other_version: list[Sent] = []

    def bad_crc(index: int, chunk: np.ndarray) -> None:
        line = bytearray(frame(ENVELOPE, rig.seq, envelope(index, chunk)))
        line[-2] ^= 0x01  # the CRC's high byte
        rig.seq += 1
        rig.write(rig.now_s(), bytes(line))

    def broken_cobs_and_other_version(index: int, chunk: np.ndarray) -> None:
        line = bytearray(frame(ENVELOPE, rig.seq, envelope(index, chunk)))
        line[0] = 0xFF  # the first block now claims more bytes than there are
        rig.seq += 1
        rig.write(rig.now_s(), bytes(line))
        other_version.append(rig.send(rig.now_s(), ENVELOPE, envelope(index, chunk), version=1))

    stopped: list[Sent] = []
    rig.stream(0.003, samples, 0, instead={1600: bad_crc, 1664: broken_cobs_and_other_version},
               then=lambda: stopped.append(rig.send(rig.now_s(), STOP, stop(0))))
    rig.run(0.5)
    rig.check_begun(begun, 0)
    assert rig.ack(other_version[0])[2:] == (BAD_VERSION, VERSION) and rig.ack(stopped[0]).code == OK
    recording = rig.recording()
    assert (recording["frames_bad"], recording["frames_rejected"], recording["underruns"]) == (2, 1, 128)
    assert recording["sequence_gaps"] == 1  # the valid frame after the two bad ones
    at = played(recording)
    index = recording["index"][at]
    assert index.tolist() == [k for k in range(index[-1] + 1) if not 1600 <= k < 1728]
    assert (recording["envelope_v"][at] == volts(samples[index])).all()
    before, after_gap = at[index == 1599][0], at[index == 1728][0]
    assert after_gap - before == 129  # the gap: 128 samples, recorded as no index, played as 0
    assert (recording["index"][before + 1:after_gap] == -1).all()
    assert (recording["envelope_v"][before + 1:after_gap] == 0).all()


def test_a_late_frame_is_refused_and_its_samples_underrun() -> None:
    """A frame arriving after its indices played is refused OUT_OF_WINDOW, not answered; its 64 samples play as 0
    (64 underruns) and the output slews back (A2)."""
    rig = Rig()
    begun = rig.begin(0, 16000, 0, 64)
    samples = np.full(6400, level(20.0), dtype=np.int16)
    late: list[Sent] = []

    def held_back(index: int, chunk: np.ndarray) -> None:
        late.append(rig.send(rig.now_s() + 0.100, ENVELOPE, envelope(index, chunk)))  # 0.1 s: past its due time

    rig.stream(0.003, samples, 0, instead={1600: held_back}, then=rig.stop_when_sent())
    rig.run(1.0)
    rig.check_begun(begun, 0)
    assert not rig.acked(late[0])
    recording = rig.recording()
    assert (recording["frames_bad"], recording["frames_rejected"], recording["underruns"]) == (0, 1, 64)
    at = played(recording)
    assert recording["index"][at].tolist() == [k for k in range(recording["index"][at[-1]] + 1)
                                               if not 1600 <= k < 1664]
    gap = slice(at[recording["index"][at] == 1599][0] + 1, at[recording["index"][at] == 1664][0])
    assert gap.stop - gap.start == 64 and (recording["index"][gap] == -1).all()
    envelope_v = recording["envelope_v"]
    step_v = INFO_SENT.slew_mv_per_ms / 16000
    assert np.abs(np.diff(envelope_v)).max() <= step_v * (1 + 1e-12)  # A2 down to 0 and back
    assert envelope_v[gap.start + 3:gap.stop].max() == 0


def test_clamp_slew_measurements_and_the_ramp_at_sigterm() -> None:
    """A1 and A2 on the recording; STATUS's measurements against the device's circuit; the end (SIGTERM) ramps to
    0 over R from the present value."""
    rig = Rig()
    begun = rig.begin(0, 16000, 0, 64)
    samples = np.concatenate([np.full(800, 32767), np.full(800, -32768), np.full(1600, 16384)]).astype(np.int16)
    rig.stream(0.003, samples, 0, then=rig.stop_when_sent())  # ends with hundreds of samples still buffered
    assert rig.run(1.0) == "stopped"
    info = rig.check_begun(begun, 0)
    plateau = next((status for status in rig.statuses() if status.envelope_mv == info.max_mv), None)
    assert plateau is not None, "no STATUS at the clamp"
    z = impedance(plateau.carrier_mhz / 1000)
    assert plateau.voltage_mv_rms == round(info.max_mv / math.sqrt(2))
    assert plateau.current_ua_rms == pytest.approx(info.max_mv / math.sqrt(2) / abs(z) * 1000, rel=1e-3)
    assert plateau.phase_cdeg == pytest.approx(-math.degrees(math.atan2(z.imag, z.real)) * 100, abs=1)
    recording = rig.recording()
    assert (recording["frames_bad"], recording["frames_rejected"], recording["underruns"]) == (0, 0, 0)
    envelope_v = recording["envelope_v"]
    max_v, step_v = info.max_mv / 1000, info.slew_mv_per_ms / 16000
    assert np.abs(envelope_v).max() == max_v  # A1: reached, never passed
    assert np.abs(np.diff(envelope_v)).max() <= step_v * (1 + 1e-12)  # A2, ramps included
    top, bottom = np.flatnonzero(envelope_v == max_v), np.flatnonzero(envelope_v == -max_v)
    assert bottom[0] - top[-1] == math.ceil(2 * max_v / step_v)  # the swing takes the slew's time
    at = played(recording)
    end = zero_from(recording)
    assert (recording["index"][at[-1] + 1:] == -1).all()
    assert end - at[-1] == RAMP_MS * 16  # R, 10 ms, from the present value
    assert np.allclose(np.diff(envelope_v[at[-1]:end + 1]), -envelope_v[at[-1]] / (end - at[-1]), rtol=1e-9)


def test_watchdog_zeroes_the_output_within_watchdog_ms() -> None:
    """A4: the host stops with 120 ms of samples buffered; the watchdog trips at the first sample due
    watchdog_ms - R - READ_LATENCY_S after its last frame, the output is 0 R later, within watchdog_ms, and the
    buffer is emptied, not played out."""
    rig = Rig()
    begun = rig.begin(0, 8000, 0, 64)
    samples = np.full(3000, level(10.0), dtype=np.int16)
    rig.stream(0.003, samples, 0, fill=1024 - 64)
    rig.run(1.0)
    info = rig.check_begun(begun, 0)
    last_frame_s = rig.fed_s[-1]
    recording = rig.recording()
    assert recording["watchdog_trips"] == 1 and recording["underruns"] == 0
    (trip_s,) = recording["watchdog_trip_t_s"]
    anchor_s = recording["t_s"][0]  # START's time: the sample clock's anchor
    assert trip_s == pytest.approx(first_due(anchor_s, 8000, last_frame_s + TRIP_S), abs=1e-9)
    t_s, envelope_v = recording["t_s"], recording["envelope_v"]
    tripped = np.flatnonzero(t_s == trip_s)[0]
    assert (envelope_v[:tripped][t_s[:tripped] > last_frame_s] == volts(samples[:1])[0]).all()  # played till then
    assert zero_from(recording) == tripped + RAMP_MS * 8 - 1  # R's ramp at 8 kHz, its last sample 0
    assert t_s[zero_from(recording)] - last_frame_s <= info.watchdog_ms / 1000
    assert (recording["state"][tripped:tripped + RAMP_MS * 8 - 1] == RAMPING).all()
    at = played(recording)
    assert recording["index"][at[-1]] < len(samples) - 100  # the buffer was emptied, not played out
    assert rig.statuses(after_s=trip_s + RAMP_MS / 1000)[0].state == IDLE


def test_watchdog_counts_valid_frames_only() -> None:
    """A4 in PRIMING: KEEPALIVEs every 30 ms hold the watchdog off; bad frames do not; it trips at the first
    sample due watchdog_ms - R - READ_LATENCY_S after the last valid frame."""
    rig = Rig()
    begun = rig.begin(0, 16000, 0, 64)
    for k in range(1, 8):
        rig.send(0.002 + 0.030 * k, KEEPALIVE)
    broken = bytearray(frame(KEEPALIVE, 99))
    broken[-2] ^= 0x01
    rig.write(0.212 + 0.020, bytes(broken))
    rig.run(0.400)
    rig.check_begun(begun, 0)
    recording = rig.recording()
    assert recording["frames_bad"] == 1
    assert recording["watchdog_trip_t_s"] == pytest.approx([first_due(0.002, 16000, 0.212 + TRIP_S)], abs=1e-9)
    assert (recording["state"][recording["t_s"] < recording["watchdog_trip_t_s"][0]] == PRIMING).all()


def test_overcurrent_faults_until_hello() -> None:
    """A6, from the circuit: at the highest carrier the device draws more than max_current_ma below the clamp; the
    fault's STATUS goes out at once, START is refused FAULT until HELLO."""
    rig = Rig()
    z = impedance(INFO_SENT.carrier_max_mhz / 1000)
    trip_v = INFO_SENT.max_current_ma * abs(z) * math.sqrt(2) / 1000
    assert trip_v * 1.2 < INFO_SENT.max_mv / 1000
    begun = rig.begin(0, 16000, 0, 64, carrier_mhz=INFO_SENT.carrier_max_mhz)
    rig.stream(0.003, np.full(256, level(trip_v * 1.2), dtype=np.int16), 0, fill=256)
    refused = rig.send(0.100, START, start(16000, 0, 64))
    rig.send(0.200, HELLO, hello())
    carrier = rig.send(0.201, SET_CARRIER, u32(RESONANCE_MHZ))
    started = rig.send(0.202, START, start(16000, 0, 64))
    rig.run(0.300)
    rig.check_begun(begun, 0)
    recording = rig.recording()
    faulted = np.flatnonzero(recording["state"] == FAULTED)
    fault_s = recording["t_s"][faulted[0] - 1]  # the sample that drew too much: FAULT from the next one on
    # The emulator makes the samples due at each tick (TICK_S while playing), and the fault's STATUS goes out in
    # the tick that made the sample, stamped with the sample's time: not the periodic STATUS, its own.
    at_once = next(received for received in rig.frames if received.type == STATUS and received.t_s > fault_s)
    status = parse_status(at_once.payload)
    assert status.state == FAULTED and status.faults == OVERCURRENT and status.time_us == round(fault_s * 1e6)
    assert at_once.t_s <= fault_s + TICK_S and status.time_us % 5000 != 0
    assert_fault_ramp(recording)
    assert rig.ack(refused).code == FAULT
    assert (rig.ack(carrier).code, rig.ack(started).code) == (OK, OK)
    assert rig.status_at(0.205).faults == 0 and rig.status_at(0.205).state == PRIMING


def assert_fault_ramp(recording: dict[str, np.ndarray]) -> None:
    """A6 on the recording: 0 within 1 ms of the sample that faulted, linearly, and 0 while FAULT lasts."""
    faulted = np.flatnonzero(recording["state"] == FAULTED)
    envelope_v, t_s = recording["envelope_v"], recording["t_s"]
    ramp_end = faulted[0] + np.flatnonzero(envelope_v[faulted[0]:] == 0)[0]
    assert t_s[ramp_end] - t_s[faulted[0] - 1] <= 0.001 + 1e-9
    rate_hz = round(1 / (t_s[faulted[0]] - t_s[faulted[0] - 1]))
    ramp = envelope_v[faulted[0]:ramp_end + 1]
    assert len(ramp) == rate_hz // 1000 and np.allclose(ramp, envelope_v[faulted[0] - 1] * (
        1 - np.arange(1, len(ramp) + 1) / len(ramp)), rtol=0, atol=1e-12)
    assert (envelope_v[faulted[faulted >= ramp_end]] == 0).all()


def test_overcurrent_on_demand() -> None:
    """--fault overcurrent:AT_S: the fault of A6 at AT_S exactly, while streaming, whatever the current."""
    rig = Rig(FaultPlan(overcurrent_at_s=(0.5,)))
    rig.begin(0, 16000, 0, 64)
    rig.stream(0.003, np.full(16000, level(10.0), dtype=np.int16), 0, until=lambda status: status.faults)
    rig.run(0.6)
    at_once = [received for received in rig.frames if received.type == STATUS and received.t_s == 0.5]
    assert [parse_status(received.payload)[3:5] for received in at_once] == [(RUNNING, 0), (FAULTED, OVERCURRENT)]
    recording = rig.recording()
    assert recording["faults"] == OVERCURRENT and recording["watchdog_trips"] == 0
    assert recording["t_s"][np.flatnonzero(recording["state"] == FAULTED)[0] - 1] == pytest.approx(0.5, abs=1e-9)
    assert_fault_ramp(recording)


def test_disconnect_fault_closes_the_line_and_ends() -> None:
    """--fault disconnect:AT_S: the line closes at AT_S while streaming; the output ramps to 0 over R."""
    rig = Rig(FaultPlan(disconnect_at_s=0.3))
    rig.begin(0, 16000, 0, 64)
    rig.stream(0.003, np.full(16000, level(5.0), dtype=np.int16), 0)
    assert rig.run(1.0) == "disconnected"
    assert rig.line.closed and rig.now_s() < 0.3 + RAMP_MS / 1000 + 0.002
    assert max(received.t_s for received in rig.frames) <= 0.3  # nothing written after
    recording = rig.recording()
    ramp = recording["t_s"] >= 0.3
    assert (recording["index"][ramp] == -1).all() and recording["envelope_v"][-1] == 0
    assert np.count_nonzero(recording["envelope_v"][ramp]) == RAMP_MS * 16 - 1
    assert recording["frames_ok"] > 10 and recording["watchdog_trips"] == 0


def test_duration_ends_it_and_a_stop_request_too() -> None:
    rig = Rig(duration_s=0.2)
    assert rig.run(10.0) == "duration" and rig.now_s() == 0.2
    recording = rig.recording()
    assert recording["t_s"].shape == (0,) and recording["envelope_hz"] == 0 and recording["frames_ok"] == 0
    rig = Rig()
    rig.at(0.05, rig.stop_when_sent())
    assert rig.run(10.0) == "stopped" and rig.now_s() == 0.05


# --- the line faults --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("plan", [FaultPlan(corrupt_rate=0.001, seed=3), FaultPlan(drop_rate=0.001, seed=3)],
                         ids=["corrupt", "drop"])
def test_corrupted_or_dropped_bytes_are_never_applied(plan: FaultPlan) -> None:
    """corrupt:RATE, drop:RATE: the frames hit are bad (CRC-16 catches a flipped bit, COBS or the CRC a missing
    byte) and their samples play as underruns, never as values."""
    rig = Rig(plan)
    rig.begin(0, 16000, 0, 64)
    samples = np.full(8000, level(3.0), dtype=np.int16)
    rig.stream(0.003, samples, 0, then=rig.stop_when_sent())
    rig.run(1.0)
    assert rig.infos()  # the handshake passed (this seed's faults hit later frames)
    recording = rig.recording()
    assert recording["frames_bad"] > 0 and recording["watchdog_trips"] == 0
    running = np.flatnonzero(recording["state"] == RUNNING)
    consumed = np.arange(len(running))  # RUNNING takes one index a sample, from 0 on
    index = recording["index"][running]
    assert ((index == consumed) | (index == -1)).all()
    assert (recording["envelope_v"][running[index >= 0]] == volts(samples[:1])[0]).all()
    assert (recording["envelope_v"][running[index == -1]] == 0).all()
    lost = consumed[index == -1]
    assert recording["underruns"] == len(lost)
    lost_frames, counts = np.unique(lost // 64, return_counts=True)
    assert len(lost_frames) > 2 and (counts[:-1] == 64).all()  # whole frames (the last one cut by the end)


def test_stall_trips_the_watchdog_and_status_goes_on() -> None:
    """stall:AT_S:FOR_S: nothing is read for FOR_S, so the watchdog trips at its time after the last frame read;
    STATUS keeps its period (A8); the frames written meanwhile are read at the stall's end, refused unanswered."""
    rig = Rig(FaultPlan(stalls_s=((0.5, 0.3),)))
    begun = rig.begin(0, 16000, 0, 64)
    rig.stream(0.0035, np.full(16000, level(5.0), dtype=np.int16), 0,
               until=lambda status: bool(status.watchdog_trips))
    rig.run(1.0)
    rig.check_begun(begun, 0)
    times_us = np.array([status.time_us for status in rig.statuses()], dtype=np.int64)
    assert (np.diff(times_us) == 5000).all() and times_us[-1] == 1_000_000
    recording = rig.recording()
    read_s = max(t_s for t_s in rig.fed_s if t_s < 0.5)
    assert recording["watchdog_trip_t_s"] == pytest.approx([first_due(0.002, 16000, read_s + TRIP_S)], abs=1e-9)
    stalled = [t_s for t_s in rig.fed_s if t_s >= 0.5]
    assert stalled and recording["frames_rejected"] == len(stalled)  # read at 0.8: NOT_STARTED, not answered
    assert not [received for received in rig.frames if received.type == ACK and received.t_s > 0.1]


def test_delay_holds_every_byte_back() -> None:
    """delay:MS: every frame is acted on MS after it was written, to the ns: INFO, ACK, the first sample."""
    rig = Rig(FaultPlan(delay_s=0.030))
    greeting = rig.send(0, HELLO, hello())
    rig.send(0.001, SET_CARRIER, u32(RESONANCE_MHZ))
    started = rig.send(0.1, START, start(16000, 0, 16))
    rig.send(0.1, ENVELOPE, envelope(0, np.full(16, level(1.0), dtype=np.int16)))
    rig.send(0.11, STOP, stop(0))
    rig.run(0.2)
    assert [t_s for t_s, _, _ in rig.infos()] == [greeting.t_s + 0.030]
    assert rig.answer(started).t_s == pytest.approx(started.t_s + 0.030, abs=1e-9)
    assert rig.ack(started)[2:] == (OK, 0)
    recording = rig.recording()
    # the sample due at START's own time is PRIMING's, held at 0; the first index plays at the next
    assert recording["t_s"][played(recording)[0]] == pytest.approx(started.t_s + 0.030 + 1 / 16000, abs=1e-9)


# --- the amplifier in-process, on given times -------------------------------------------------------------------

def test_restart_holds_the_output_and_hello_ramps_with_the_old_carrier() -> None:
    """START while RUNNING: PRIMING holds the present output and RUNNING slews on from it (3.1, A2); HELLO ramps
    to 0 over R still making the carrier, then forgets it (3.1, A4's ramp)."""
    recorder = Recorder()
    amplifier = Amplifier(INFO_SENT, CIRCUIT, Plate(DEVICE, FORCE_N, sim_rate_hz(INFO_SENT.carrier_max_mhz)),
                          ORIGIN_S, recorder)
    seq = iter(range(100))

    def receive(t_s: float, type_: int, payload: bytes = b"") -> None:
        amplifier.receive(frame(type_, next(seq), payload)[:-1], ORIGIN_S + t_s)

    receive(0, HELLO, bytes(16))
    receive(0, SET_CARRIER, u32(RESONANCE_MHZ))
    receive(0, START, start(16000, 0, 16))
    receive(0, ENVELOPE, envelope(0, np.full(64, level(10.0))))
    receive(0.002, START, start(16000, 5000, 16))  # a restart, 33 samples in
    receive(0.003, ENVELOPE, envelope(5000, np.full(16, level(20.0))))
    receive(0.004, HELLO, bytes(16))
    amplifier.advance(ORIGIN_S + 0.020)
    sent = frames_in(bytes(amplifier.out))
    statuses = [parse_status(payload) for type_, _, payload in sent if type_ == STATUS]
    recorded = {name: recorder.column(name) for name in RECORDED_COLUMNS}
    t_s, envelope_v, index, state = (recorded[name] for name in ("t_s", "envelope_v", "index", "state"))
    ten, twenty = volts(np.array([level(10.0), level(20.0)]))
    step = INFO_SENT.slew_mv_per_ms / 16000
    first = np.flatnonzero(index == 0)[0]  # the START's own instant was held (PRIMING), at 0
    restart = first + np.flatnonzero(index[first:] == -1)[0]
    again = np.flatnonzero(index == 5000)[0]
    hello_at = np.flatnonzero(state == RAMPING)[0]
    assert np.allclose(envelope_v[first:first + 3], [step, ten, ten])
    assert (index[first:restart] == np.arange(restart - first)).all() and restart - first == 32  # 2 ms
    assert (envelope_v[restart:again] == ten).all() and (state[restart:again] == PRIMING).all()  # held
    assert again - restart == 16  # 1 ms of PRIMING
    assert np.allclose(envelope_v[again:again + 3], [ten + step, twenty, twenty])  # slewed on from the held value
    assert t_s[hello_at] - t_s[again] == pytest.approx(0.001, abs=1e-9)
    ramp = envelope_v[hello_at:hello_at + 160]
    assert np.allclose(ramp, envelope_v[hello_at - 1] * (1 - np.arange(1, 161) / 160))  # R = 10 ms at 16 kHz
    assert (state[hello_at:hello_at + 159] == RAMPING).all() and state[hello_at + 159] == IDLE
    assert (recorded["carrier_hz"][hello_at:hello_at + 160] == RESONANCE_MHZ / 1000).all()
    assert (recorded["carrier_hz"][hello_at + 160:] == 0).all() and (envelope_v[hello_at + 160:] == 0).all()
    during, after = statuses[-3], statuses[-1]  # 5 and 15 ms after the second HELLO
    assert (during.state, during.carrier_mhz, after.state, after.carrier_mhz) == (RAMPING, RESONANCE_MHZ, IDLE, 0)
    assert sent[0][0] == INFO and after.frames_ok == 1


def test_recording_keeps_at_most_its_limit(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """The recording stops at its limit with one note; it is written whole or not at all."""
    recorder = Recorder(limit=100)
    for _ in range(3):
        recorder.add(**{name: np.arange(60).astype(dtype) for name, dtype in RECORDED_COLUMNS.items()})
    assert recorder.count == 100 and recorder.truncated
    assert capsys.readouterr().err.count("\n") == 1
    write_recording(str(tmp_path / "r.npz"), recorder, {"frames_ok": 3, "truncated": True})
    with np.load(tmp_path / "r.npz", allow_pickle=False) as data:
        assert (data["t_s"] == np.concatenate([np.arange(60), np.arange(40)])).all()
        assert data["index"].dtype == np.int64 and data["frames_ok"] == 3 and data["truncated"]
    assert sorted(path.name for path in tmp_path.iterdir()) == ["r.npz"]
    with pytest.raises(ConfigError, match="cannot write recordings there: no folder"):
        write_recording(str(tmp_path / "missing" / "r.npz"), recorder, {})
    (tmp_path / "link.npz").symlink_to(tmp_path / "victim")  # a link planted at the target: replaced, not followed
    (tmp_path / "victim").write_bytes(b"kept")
    write_recording(str(tmp_path / "link.npz"), recorder, {})
    assert (tmp_path / "victim").read_bytes() == b"kept" and not (tmp_path / "link.npz").is_symlink()


# --- the command line -------------------------------------------------------------------------------------------

def test_fault_specs_make_the_plan() -> None:
    """``--fault`` specs as the FaultPlan the tests above run (times in s, delay in ms)."""
    specs = ["drop:0.01", "corrupt:0.5", "delay:30", "stall:1:0.3", "stall:4:1", "overcurrent:2", "overcurrent:3",
             "disconnect:9"]
    assert fault_plan([fault_spec(spec) for spec in specs], 7) == FaultPlan(
        drop_rate=0.01, corrupt_rate=0.5, delay_s=0.030, stalls_s=((1.0, 0.3), (4.0, 1.0)),
        overcurrent_at_s=(2.0, 3.0), disconnect_at_s=9.0, seed=7)
    assert fault_plan([], 0) == FaultPlan()


@pytest.mark.parametrize(("flags", "expected"), [
    ((), "the following arguments are required: ACTION"),
    (("emulate", "--bogus"), "unrecognized arguments: --bogus"),
    (("emulate", "--duration", "0"), "argument --duration: must be a number in (0, 86400]"),
    (("emulate", "--duration", "1e9"), "argument --duration: must be a number in (0, 86400]"),
    (("emulate", "--seed", "-1"), "argument --seed: must be a whole number"),
    (("emulate", "--fault", "flood:1"), "argument --fault: unknown fault 'flood'"),
    (("emulate", "--fault", "drop"), "fault drop is written drop:RATE, got 'drop'"),
    (("emulate", "--fault", "drop:1.5"), "drop RATE must be a number in [0, 1]"),
    (("emulate", "--fault", "corrupt:nan"), "corrupt RATE must be a number in [0, 1]"),
    (("emulate", "--fault", "delay:-1"), "delay MS must be a number in [0, 10000]"),
    (("emulate", "--fault", "stall:1"), "fault stall is written stall:AT_S:FOR_S"),
    (("emulate", "--fault", "stall:1:x"), "stall FOR_S must be a number"),
    (("emulate", "--fault", "disconnect:1", "--fault", "disconnect:2"), "--fault disconnect given 2 times"),
    (("emulate", "--device", "/nonexistent/device.yaml"), "/nonexistent/device.yaml"),
    (("emulate", "--record", "/nonexistent/folder/x.npz"), "cannot write recordings there: no folder /nonexistent/folder"),
    (("emulate", "--record", "/tmp"), "exists and is not a regular file (a directory)"),
    (("emulate", "--record", "/dev/null"), "exists and is not a regular file (a character device)"),
    (("emulate", "--port", "/nonexistent/tty"), "/nonexistent/tty: cannot open the port"),
    (("emulate", "--port", "pyproject.toml"), "pyproject.toml: not a serial port"),
])
def test_mistakes_are_one_line_and_status_1(flags: tuple[str, ...], expected: str) -> None:
    tpad_rt("amp", *flags).assert_one_line_error(expected)
