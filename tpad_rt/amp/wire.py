"""The amplifier's codec for docs/amp-protocol.md, version 2: framing, frame checks, message layouts.

A frame on the line is a body encoded with COBS and one ``0x00`` (section 2.1). A body is
``version`` (u8), ``type`` (u8), ``seq`` (u16), the payload and a CRC-16/IBM-3740 of all
that (section 2.2); every field is little-endian. :func:`decode` makes steps 1-2 of
section 2.3 (a frame failing them is *bad*); steps 3-5 (version, type and length,
ranges) are the receiver's, :mod:`tpad_rt.amp.emulator`. The messages of section 3 are
the dataclasses below, each with ``pack() -> payload`` and ``unpack(payload)``.

API map
-------
crc16(data) -> int
    CRC-16/IBM-3740 (poly 0x1021, init 0xFFFF, no reflection, no final XOR); ``crc16(b"123456789") == 0x29B1``
encode(type, seq, payload, version=VERSION) -> bytes
    the frame as it goes on the line: the COBS-encoded body, then ``0x00``
decode(encoded) -> Frame | None
    the frame in ``encoded`` (the bytes between two ``0x00``), or None when it is bad (2.3 steps 1-2)
FrameSplitter().feed(data) -> list[bytes | None]
    the candidate frames completed by ``data``; None for each run over MAX_ENCODED bytes (one bad frame)
Type, Code, State, Fault
    message types, ACK codes, STATUS states and fault bits
Hello, SetCarrier, Start, Envelope, Stop; Info, Status, Ack
    the payloads (host to amplifier; amplifier to host); PAYLOAD_BYTES the fixed lengths
"""

from __future__ import annotations

import enum
import struct
import threading
from dataclasses import astuple, dataclass
from typing import ClassVar, NamedTuple, TypeVar

import numpy as np
import numpy.typing as npt
from cobs import cobs  # type: ignore[import-untyped]
from crc import Calculator, Crc16

#: The protocol version this codec speaks (body byte 0).
VERSION = 2
#: Longest body (bytes): an ENVELOPE of 256 samples (section 2.1).
MAX_BODY = 522
#: Shortest body (bytes): the header and the CRC, no payload (2.3 step 1).
MIN_BODY = 6
#: Most encoded bytes a receiver collects without a 0x00; past this it discards up to the next 0x00 (2.1).
MAX_ENCODED = MAX_BODY + MAX_BODY // 254 + 2
#: Bytes before the payload of an ENVELOPE: ``first_index`` (u32).
ENVELOPE_HEADER_BYTES = 4
#: Most samples an ENVELOPE frame may carry (MAX_BODY's); INFO's ``max_frame_samples`` is at most this.
MAX_FRAME_SAMPLES = 256

_HEADER = struct.Struct("<BBH")
_CRC = struct.Struct("<H")
#: One crc.Calculator per thread: a Calculator keeps its register between calls, so it is not thread-safe.
_CALCULATORS = threading.local()


class Type(enum.IntEnum):
    """Message types (section 3): host to amplifier below 0x80, amplifier to host above."""

    HELLO = 0x01
    SET_CARRIER = 0x02
    START = 0x03
    ENVELOPE = 0x04
    STOP = 0x05
    KEEPALIVE = 0x06
    INFO = 0x81
    STATUS = 0x82
    ACK = 0x83


class Code(enum.IntEnum):
    """ACK codes (section 3.2)."""

    OK = 0
    BAD_VERSION = 1
    UNKNOWN_TYPE = 2
    BAD_LENGTH = 3
    OUT_OF_RANGE = 4
    NO_CARRIER = 5
    BAD_RATE = 6
    NOT_STARTED = 7
    OUT_OF_WINDOW = 8
    FAULT = 9


class State(enum.IntEnum):
    """STATUS ``state`` (section 3.2)."""

    IDLE = 0
    PRIMING = 1
    RUNNING = 2
    RAMPING = 3
    FAULT = 4


class Fault(enum.IntFlag):
    """STATUS ``faults`` bits, latched until HELLO (section 3.2, A6)."""

    OVERCURRENT = 1
    OVERVOLTAGE = 2
    OVERTEMPERATURE = 4
    SUPPLY = 8


class Frame(NamedTuple):
    """A frame that passed steps 1-2 of section 2.3 (COBS, length, CRC): a *valid* frame."""

    version: int
    type: int
    seq: int
    payload: bytes


def crc16(data: bytes) -> int:
    """CRC-16/IBM-3740 of ``data`` (section 2.2); safe to call from several threads."""
    calculator = getattr(_CALCULATORS, "crc16", None)
    if calculator is None:
        calculator = _CALCULATORS.crc16 = Calculator(Crc16.IBM_3740.value, optimized=True)
    return int(calculator.checksum(data))


def encode(type_: int, seq: int, payload: bytes, version: int = VERSION) -> bytes:
    """The frame for ``type_``, ``seq`` (taken mod 65536) and ``payload`` as sent: COBS(body), then 0x00.

    Raises ValueError when the body would exceed MAX_BODY.
    """
    body = _HEADER.pack(version, type_, seq & 0xFFFF) + payload
    body += _CRC.pack(crc16(body))
    if len(body) > MAX_BODY:
        raise ValueError(f"a body holds at most {MAX_BODY} bytes, this one {len(body)}")
    return bytes(cobs.encode(body)) + b"\x00"


def decode(encoded: bytes) -> Frame | None:
    """The frame in ``encoded`` (the bytes between two 0x00), or None when it is bad.

    Bad (section 2.3 steps 1-2): the COBS decoding fails, the body is not MIN_BODY to
    MAX_BODY bytes long, or its CRC does not match.
    """
    try:
        body = bytes(cobs.decode(encoded))
    except cobs.DecodeError:
        return None
    if not MIN_BODY <= len(body) <= MAX_BODY:
        return None
    if crc16(body[:-2]) != _CRC.unpack_from(body, len(body) - 2)[0]:
        return None
    version, type_, seq = _HEADER.unpack_from(body)
    return Frame(version, type_, seq, body[_HEADER.size:-2])


class FrameSplitter:
    """Cuts the received byte stream at each 0x00 into candidate frames (section 2.1).

    Empty frames (a 0x00 alone) are ignored. A run of more than MAX_ENCODED bytes
    without a 0x00 is discarded up to the next 0x00 and reported once, as None (one
    bad frame); memory stays within MAX_ENCODED bytes whatever arrives.
    """

    def __init__(self) -> None:
        self._pending = bytearray()
        self._discarding = False

    def feed(self, data: bytes) -> list[bytes | None]:
        """The candidate frames ``data`` completes, in order; None for each over-long run."""
        found: list[bytes | None] = []
        start = 0
        while (end := data.find(0, start)) >= 0:
            self._collect(data[start:end], found)
            if self._pending:
                found.append(bytes(self._pending))
            self._pending.clear()
            self._discarding = False
            start = end + 1
        self._collect(data[start:], found)
        return found

    def _collect(self, chunk: bytes, found: list[bytes | None]) -> None:
        if self._discarding or not chunk:
            return
        if len(self._pending) + len(chunk) > MAX_ENCODED:
            self._pending.clear()
            self._discarding = True
            found.append(None)
            return
        self._pending += chunk


def _text(raw: bytes) -> str:
    """An ASCII string field without its 0x00 padding (other bytes escaped)."""
    return raw.rstrip(b"\x00").decode("ascii", errors="backslashreplace")


def _field(text: str, size: int) -> bytes:
    """``text`` as an ASCII string field of ``size`` bytes (cut to fit; the packer pads with 0x00)."""
    return text.encode("ascii", errors="replace")[:size]


_M = TypeVar("_M", bound="_Flat")


class _Flat:
    """A fixed-length payload whose fields are its struct's, in order."""

    LAYOUT: ClassVar[struct.Struct]

    def pack(self) -> bytes:
        """The payload."""
        return self.LAYOUT.pack(*astuple(self))  # type: ignore[call-overload]

    @classmethod
    def unpack(cls: type[_M], payload: bytes) -> _M:
        """The message in ``payload``; struct.error unless it is exactly the layout's length."""
        return cls(*cls.LAYOUT.unpack(payload))


@dataclass(frozen=True)
class Hello:
    """HELLO (0x01): opens a session; ``host`` names the host (12-byte string), ``nonce`` (u32) is echoed by the
    INFO that answers it."""

    host: str
    nonce: int = 0
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<12sI")

    def pack(self) -> bytes:
        return self.LAYOUT.pack(_field(self.host, 12), self.nonce)

    @classmethod
    def unpack(cls, payload: bytes) -> Hello:
        host, nonce = cls.LAYOUT.unpack(payload)
        return cls(_text(host), nonce)


@dataclass(frozen=True)
class SetCarrier(_Flat):
    """SET_CARRIER (0x02): the carrier asked for (mHz)."""

    carrier_mhz: int
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<I")


@dataclass(frozen=True)
class Start(_Flat):
    """START (0x03): stream rate (Hz), index of its first sample, samples buffered before playing."""

    envelope_hz: int
    start_index: int
    prefill: int
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<IIH")


@dataclass(frozen=True, eq=False)
class Envelope:
    """ENVELOPE (0x04): samples ``first_index ..`` of the stream (int16; 32767 is full scale)."""

    first_index: int
    samples: npt.NDArray[np.int16]
    _INDEX: ClassVar[struct.Struct] = struct.Struct("<I")

    def pack(self) -> bytes:
        return self._INDEX.pack(self.first_index) + np.asarray(self.samples, dtype="<i2").tobytes()

    @classmethod
    def unpack(cls, payload: bytes) -> Envelope:
        """ValueError unless the payload is ``first_index`` and a whole number of samples."""
        if len(payload) < ENVELOPE_HEADER_BYTES or (len(payload) - ENVELOPE_HEADER_BYTES) % 2:
            raise ValueError(f"an ENVELOPE payload of {len(payload)} bytes is not 4 + 2N")
        samples = np.frombuffer(payload, dtype="<i2", offset=ENVELOPE_HEADER_BYTES).astype(np.int16)
        return cls(cls._INDEX.unpack_from(payload)[0], samples)


@dataclass(frozen=True)
class Stop(_Flat):
    """STOP (0x05): ramp to zero over ``min(ramp_ms, 50)`` ms."""

    ramp_ms: int
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<H")


@dataclass(frozen=True)
class Info:
    """INFO (0x81, 92 bytes): what the amplifier is and accepts (section 3.2; units in the names)."""

    firmware: str
    serial: str
    envelope_rates_hz: tuple[int, int, int, int]
    carrier_min_mhz: int
    carrier_max_mhz: int
    carrier_step_mhz: int
    full_scale_mv: int
    max_mv: int
    slew_mv_per_ms: int
    buffer_samples: int
    max_frame_samples: int
    watchdog_ms: int
    status_period_ms: int
    measures: int
    max_current_ma: int
    hello_nonce: int = 0  # the nonce of the HELLO this INFO answers (at offset 84)
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<16s16s4I6I4HB3xII")

    def pack(self) -> bytes:
        return self.LAYOUT.pack(
            _field(self.firmware, 16), _field(self.serial, 16), *self.envelope_rates_hz,
            self.carrier_min_mhz, self.carrier_max_mhz, self.carrier_step_mhz, self.full_scale_mv, self.max_mv,
            self.slew_mv_per_ms, self.buffer_samples, self.max_frame_samples, self.watchdog_ms,
            self.status_period_ms, self.measures, self.hello_nonce, self.max_current_ma)

    @classmethod
    def unpack(cls, payload: bytes) -> Info:
        (firmware, serial, rate_0, rate_1, rate_2, rate_3, carrier_min_mhz, carrier_max_mhz, carrier_step_mhz,
         full_scale_mv, max_mv, slew_mv_per_ms, buffer_samples, max_frame_samples, watchdog_ms, status_period_ms,
         measures, hello_nonce, max_current_ma) = cls.LAYOUT.unpack(payload)
        return cls(_text(firmware), _text(serial), (rate_0, rate_1, rate_2, rate_3), carrier_min_mhz, carrier_max_mhz,
                   carrier_step_mhz, full_scale_mv, max_mv, slew_mv_per_ms, buffer_samples, max_frame_samples,
                   watchdog_ms, status_period_ms, measures, max_current_ma, hello_nonce)


@dataclass(frozen=True)
class Status(_Flat):
    """STATUS (0x82, 56 bytes): the amplifier's clock, stream position, counters and measurements."""

    time_us: int
    play_index: int
    buffer_fill: int
    state: int
    faults: int
    frames_ok: int
    frames_bad: int
    frames_rejected: int
    sequence_gaps: int
    underruns: int
    watchdog_trips: int
    last_seq: int
    phase_cdeg: int
    envelope_mv: int
    voltage_mv_rms: int
    current_ua_rms: int
    carrier_mhz: int
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<IIHBBIIIIIIHhiIII")


@dataclass(frozen=True)
class Ack(_Flat):
    """ACK (0x83, 8 bytes, the same in every version): the frame answered, a Code and a value."""

    acked_seq: int
    acked_type: int
    code: int
    value: int
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<HBBI")


#: Payload length (bytes) of every type but ENVELOPE (section 3).
PAYLOAD_BYTES = {
    Type.HELLO: Hello.LAYOUT.size,
    Type.SET_CARRIER: SetCarrier.LAYOUT.size,
    Type.START: Start.LAYOUT.size,
    Type.STOP: Stop.LAYOUT.size,
    Type.KEEPALIVE: 0,
    Type.INFO: Info.LAYOUT.size,
    Type.STATUS: Status.LAYOUT.size,
    Type.ACK: Ack.LAYOUT.size,
}
