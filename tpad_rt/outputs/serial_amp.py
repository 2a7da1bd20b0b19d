"""``serial://PORT``: a serial amplifier that makes the carrier itself and takes the envelope from the host.

API map
-------
FORMS
    ``serial:///dev/ttyACM0?envelope_hz=16000&buffer_ms=2&frame_ms=0.5&baud=921600``
parse_serial_url(url) -> SerialTarget
    the port and options; ConfigError (showing the expected form) for a bad one
AmpLink.open(target, *, carrier_hz, max_voltage_v=inf, timeout_s=None, line=None) -> AmpLink
    open the port (pyserial: :class:`tpad_rt.outputs.serial_line.SerialLine`; or talk on
    ``line``, any :class:`~tpad_rt.outputs.serial_line.Line`, e.g. the virtual link of
    :mod:`tpad_rt.amp.virtual_link`), say HELLO with a new nonce, take the INFO that echoes it
    (rule H1), decide the envelope's scale from it (H3: ``.scale``), set the carrier and
    check the achieved one (H2), measure the link (H11: ``.link_rate``; larger frames than
    the URL's where it needs them, said in ``.link_note``; :mod:`tpad_rt.outputs.serial_rate`),
    choose the frame and target fill (``.frame_samples``, ``.target_fill``); BackendError naming
    the port for one that cannot open, no or a bad answer, an amplifier that contradicts itself,
    another protocol version, a carrier or envelope rate the amplifier cannot make, a link too
    slow for the envelope; ConfigError for a ``buffer_ms`` its buffer cannot hold
AmpLink.start(table, track=False, ramp_ms=STOP_RAMP_MS) / .failure() / .stop(ramp_ms) / .stats() / .info / .scale / .carrier_hz
    stream with the streamer's steps (:mod:`tpad_rt.kernel.amp_stream`) as the line runs
    them (a real port: the GIL-free compiled loop in a thread);
    the error that ended the stream (a BackendError), or None; end with STOP (H8, also
    after a failure), close
envelope_scale(full_scale_mv, max_mv, max_voltage_v) -> EnvelopeScale
    the one place the host's envelope scale and cap are decided (H3)
AmpLink.set_carrier(carrier_hz) / .tone(envelope_v, seconds) -> AmpStatus
    measuring instead of rendering (``tpad-rt calibrate sweep``): move the carrier, hold a
    constant envelope from Python and read the amplifier's measured voltage, current, phase
warm_up(table)
    compile the streamer before a port opens
warm_checks()
    compile the codec and the report checks the Python side calls (AmpLink.open does, before its port)

docs/amp-protocol.md is the protocol, docs/amplifiers.md how to connect one. The
handshake runs in Python with the same codec the streamer uses
(:mod:`tpad_rt.kernel.amp_codec`), every wait on the line's clock; on a real port the
stream runs in one numba call that holds no GIL.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields

import numpy as np

from tpad_rt.errors import BackendError, ConfigError
from tpad_rt.kernel import amp_codec as codec
from tpad_rt.kernel import amp_stream
from tpad_rt.kernel.atomics import publish
from tpad_rt.outputs.base import Consumes, OutputKind
from tpad_rt.outputs import serial_rate
from tpad_rt.outputs.serial_line import Line, SerialLine, Streamer
from tpad_rt.pipeline import LOCK_RANGE
from tpad_rt.urls import Option, Url, UrlForm, count, number, parse_url

FORMS = (UrlForm("serial", "/dev/ttyACM0", (
    Option("envelope_hz", 16000, count(1000, 100_000)), Option("buffer_ms", 2.0, number(0.1, high=1000.0)),
    Option("frame_ms", 0.5, number(0.05, high=20.0)), Option("baud", 921600, count(1200, 20_000_000)))),)
#: The envelope (the amplifier makes the carrier), streamed by the GIL-free streamer (tpad_rt.drivers.serial_stream).
KIND = OutputKind(Consumes.ENVELOPE, "tpad_rt.drivers.serial_stream:SerialStreamDriver")
#: Seconds to wait for INFO after a HELLO (H1), and HELLOs sent before giving up.
HELLO_TIMEOUT_S = 0.5
HELLO_TRIES = 3
#: STOP's ramp (ms) after a failure, unless AmpLink.start is given the run's.
STOP_RAMP_MS = 5.0
#: Seconds to wait for the ACK of SET_CARRIER, START and STOP.
ACK_TIMEOUT_S = 0.5
STOP_ACK_TIMEOUT_S = 0.2
#: How long (s) a write waits at a time for a full line to take bytes.
WRITE_WAIT_S = 0.01
#: INFO's ``measures`` bits a phase lock needs: current, voltage and phase.
MEASURES_FOR_LOCK = 1 | 2 | 4
#: A tracked carrier closer than this (mHz) to the amplifier's is not sent (nor closer than its resolution).
CARRIER_RESEND_MHZ = 10
#: Less current than this (uA RMS) and a STATUS does not move the lock: its measured phase is then too coarse.
LOCK_MIN_CURRENT_UA = 1000
#: AmpLink.stats()["tracking"] for LINK_TRACK's values.
TRACKING_NAMES = ("off", "model", "model + phase lock")
#: What the host calls itself in HELLO (then the HELLO's nonce).
HOST_NAME = b"tpad-rt"


@dataclass(frozen=True)
class SerialTarget:
    """A parsed ``serial://`` URL: the port's path and the stream's settings."""

    port: str
    envelope_hz: int
    buffer_ms: float
    frame_ms: float
    baud: int


@dataclass(frozen=True)
class AmpInfo:
    """What an amplifier's INFO says (docs/amp-protocol.md 3.2), in SI units."""

    firmware: str
    serial: str
    envelope_rates_hz: tuple[int, ...]
    carrier_min_hz: float
    carrier_max_hz: float
    carrier_step_hz: float
    full_scale_v: float
    max_v: float
    slew_v_per_ms: float
    buffer_samples: int
    max_frame_samples: int
    watchdog_ms: int
    status_period_ms: int
    measures: int
    max_current_a: float
    full_scale_mv: int
    max_mv: int


@dataclass(frozen=True)
class EnvelopeScale:
    """How the host scales the envelope (H3), decided once from the INFO the handshake took: sample 32767 is
    ``full_scale_v`` (V peak), the drive is capped at ``max_v`` (V peak: the lower of the amplifier's clamp and the
    device's max_voltage_v), and no sample sent exceeds ``level_limit`` in magnitude (``level_limit / 32767 *
    full_scale_v <= max_v``)."""

    full_scale_v: float
    max_v: float
    level_limit: int


def envelope_scale(full_scale_mv: int, max_mv: int, max_voltage_v: float) -> EnvelopeScale:
    """The envelope scale for an amplifier of ``full_scale_mv`` and clamp ``max_mv`` (INFO, mV peak, 0 < max_mv <=
    full_scale_mv) on a device capped at ``max_voltage_v`` (V peak, > 0; inf: the amplifier's clamp alone)."""
    cap_mv = min(float(max_mv), max_voltage_v * 1000.0)
    return EnvelopeScale(full_scale_mv / 1000, cap_mv / 1000, min(32767, math.floor(32767 * cap_mv / full_scale_mv)))


def parse_serial_url(url: Url | str) -> SerialTarget:
    """Read a ``serial://`` URL; ConfigError (showing the expected form) for a bad option or no port."""
    if isinstance(url, str):
        url = parse_url(url, "output", {"serial": FORMS})
    values = FORMS[0].read(url)
    if not url.target:
        raise url.fail("no port: name the serial port, e.g. serial:///dev/ttyACM0", FORMS)
    return SerialTarget(url.target, values["envelope_hz"], values["buffer_ms"], values["frame_ms"], values["baud"])


def _text(field: np.ndarray) -> str:
    """An INFO string field: ASCII up to its first NUL, unprintable bytes shown as '?'."""
    raw = bytes(field).split(b"\0", 1)[0]
    return "".join(chr(b) if 32 <= b < 127 else "?" for b in raw)


def _parse_info(body: np.ndarray) -> AmpInfo:
    """AmpInfo from an INFO body, unchecked."""
    p = codec.PAYLOAD
    u16 = lambda at: int(codec.get_u16(body, p + at))  # noqa: E731
    u32 = lambda at: int(codec.get_u32(body, p + at))  # noqa: E731
    rates = tuple(rate for rate in (u32(codec.INFO_RATES + 4 * k) for k in range(4)) if rate)
    info = AmpInfo(
        firmware=_text(body[p + codec.INFO_FIRMWARE:p + codec.INFO_FIRMWARE + 16]),
        serial=_text(body[p + codec.INFO_SERIAL:p + codec.INFO_SERIAL + 16]),
        envelope_rates_hz=rates,
        carrier_min_hz=u32(codec.INFO_CARRIER_MIN_MHZ) / 1000, carrier_max_hz=u32(codec.INFO_CARRIER_MAX_MHZ) / 1000,
        carrier_step_hz=u32(codec.INFO_CARRIER_STEP_MHZ) / 1000,
        full_scale_v=u32(codec.INFO_FULL_SCALE_MV) / 1000, max_v=u32(codec.INFO_MAX_MV) / 1000,
        slew_v_per_ms=u32(codec.INFO_SLEW_MV_PER_MS) / 1000, buffer_samples=u16(codec.INFO_BUFFER_SAMPLES),
        max_frame_samples=u16(codec.INFO_MAX_FRAME_SAMPLES), watchdog_ms=u16(codec.INFO_WATCHDOG_MS),
        status_period_ms=u16(codec.INFO_STATUS_PERIOD_MS), measures=int(body[p + codec.INFO_MEASURES]),
        max_current_a=u32(codec.INFO_MAX_CURRENT_MA) / 1000,
        full_scale_mv=u32(codec.INFO_FULL_SCALE_MV), max_mv=u32(codec.INFO_MAX_MV),
    )
    return info


def _read_info(body: np.ndarray, port: str) -> AmpInfo:
    """AmpInfo from an INFO body; BackendError naming the amplifier's ``port`` and the first field out of the
    document's ranges (H1)."""
    info = _parse_info(body)
    rates = info.envelope_rates_hz
    for problem, bad in (
        ("no envelope rate", not rates),
        (f"carrier range {info.carrier_min_hz:g}-{info.carrier_max_hz:g} Hz is empty",
         not 0 < info.carrier_min_hz <= info.carrier_max_hz),
        (f"full scale {info.full_scale_v:g} V is 0", info.full_scale_v <= 0),
        (f"max {info.max_v:g} V is not in (0, full scale {info.full_scale_v:g} V]",
         not 0 < info.max_v <= info.full_scale_v),
        (f"slew {info.slew_v_per_ms:g} V/ms is below max {info.max_v:g} V per ms (A2)", info.slew_v_per_ms < info.max_v),
        (f"max_frame_samples {info.max_frame_samples} is not in [1, {codec.MAX_FRAME_SAMPLES}]",
         not 1 <= info.max_frame_samples <= codec.MAX_FRAME_SAMPLES),
        (f"a buffer of {info.buffer_samples} sample(s) cannot hold one frame and the start of the next",
         info.buffer_samples < 2),
        (f"watchdog {info.watchdog_ms} ms is not in [1, 50]", not 1 <= info.watchdog_ms <= 50),
        (f"status period {info.status_period_ms} ms is not in [1, 100]", not 1 <= info.status_period_ms <= 100),
    ):
        if bad:
            raise BackendError(f"serial: the amplifier on {port} sent an INFO out of the protocol's ranges: {problem}")
    return info


def _info_difference(first: np.ndarray, second: np.ndarray) -> str:
    """How two INFO bodies differ: the first field by name, with both values."""
    one, two = _parse_info(first), _parse_info(second)
    for field in fields(AmpInfo):
        a, b = getattr(one, field.name), getattr(two, field.name)
        if a != b:
            return f"{field.name} {a!r}, then {b!r}"
    return "their reserved bytes differ"


@dataclass(frozen=True)
class AmpStatus:
    """What one STATUS measured (docs/amp-protocol.md 3.2), in SI units: the applied envelope (V peak, signed),
    rms voltage (V) and current (A), the phase of current against voltage (degrees), the carrier (Hz)."""

    envelope_v: float
    voltage_v_rms: float
    current_a_rms: float
    phase_deg: float
    carrier_hz: float


#: Envelope the amplifier holds buffered while :meth:`AmpLink.tone` plays (s): a Python loop keeps it filled.
TONE_BUFFER_S = 0.03
#: How long past its dwell :meth:`AmpLink.tone` waits for a STATUS showing the tone applied on the carrier (s).
TONE_APPLY_LIMIT_S = 1.0
#: How many times one :meth:`AmpLink.tone` STARTs the stream again after the amplifier's watchdog ended it.
MAX_TONE_RESTARTS = 3


class AmpLink:
    """An open session with a serial amplifier (create it with :meth:`open`)."""

    def __init__(self, target: SerialTarget, line: Line):
        self.target = target
        self._line: Line | None = line
        self.clock = line.clock
        self._rx = b""
        self._frame = np.zeros(codec.MAX_BODY, dtype=np.uint8)
        self._body = np.zeros(codec.MAX_BODY, dtype=np.uint8)
        self._out = np.zeros(codec.MAX_ENCODED, dtype=np.uint8)
        self.link = np.zeros(amp_stream.LINK_SIZE, dtype=np.int64)
        self._buffers = np.zeros((amp_stream.BUF_ROWS, amp_stream.BUF_BYTES), dtype=np.uint8)
        self._envelope = np.zeros(amp_stream.ENVELOPE_SCRATCH, dtype=np.float32)
        self.link[amp_stream.LINK_STOP_SEQ] = -1  # no STOP sent yet
        self._stream: Streamer | None = None  # while streaming (start() to stop())
        self._last_stream: Streamer | None = None  # the last, for failure() and realtime after stop()
        self._failure: BackendError | None = None  # the error that ended the stream, made once
        self._start_sent = False  # a START went out: the amplifier may be streaming
        self.info: AmpInfo | None = None
        self.scale: EnvelopeScale | None = None  # decided once, from info (H3)
        self._nonce = -1  # the nonce of the last HELLO sent (-1: none yet)
        self._nonces = {-1}  # those of every HELLO sent
        self._info_body: np.ndarray | None = None  # the INFO taken, to compare any other answer with (H1)
        self.carrier_hz = float("nan")
        self.frame_samples = 0
        self.target_fill = 0
        self.link_rate: serial_rate.LinkRate | None = None  # measured at the handshake (H11)
        self.link_note = ""  # how the stream was adapted to a slow link (H11), "" if it was not
        self._tone_index = -1  # the next envelope index tone() writes; -1 before its START
        self._tone_started_ns = 0  # the clock (ns) when tone() sent its last START

    # --- opening ----------------------------------------------------------------------

    @classmethod
    def open(cls, target: SerialTarget, *, carrier_hz: float, max_voltage_v: float = math.inf,
             timeout_s: float | None = None, line: Line | None = None) -> AmpLink:
        """Open ``target``'s port (or talk on ``line``, closed with the link), make the handshake (H1: HELLO_TRIES
        HELLOs, ``timeout_s`` each, HELLO_TIMEOUT_S unless given), decide the envelope's scale for a device capped
        at ``max_voltage_v`` (V peak) and set the carrier to ``carrier_hz`` (H2); errors as the module says."""
        warm_checks()
        link = cls(target, line if line is not None else SerialLine.open(target.port, target.baud))
        try:
            link._hello(HELLO_TIMEOUT_S if timeout_s is None else timeout_s, max_voltage_v)
            link._set_carrier(carrier_hz)
            link._check_rate()
            link.link_rate = link._measure_link()
            link._plan()
        except BaseException:
            link.close()
            raise
        return link

    def _send(self, payload: bytes, msg_type: int) -> int:
        """Send one host frame with ``payload``; its seq."""
        seq = int(self.link[amp_stream.LINK_SEQ])
        self._write(self._sealed(payload, msg_type))
        return seq

    def _sealed(self, payload: bytes, msg_type: int) -> bytes:
        """The next host frame with ``payload``, as it goes on the line (it takes the next seq)."""
        seq = int(self.link[amp_stream.LINK_SEQ])
        self._frame[codec.PAYLOAD:codec.PAYLOAD + len(payload)] = np.frombuffer(payload, dtype=np.uint8)
        size = codec.seal(self._frame, len(payload), msg_type, seq, self._out)
        self.link[amp_stream.LINK_SEQ] = (seq + 1) & 0xFFFF
        return bytes(self._out[:size])

    @property
    def line(self) -> Line:
        """The open line; BackendError once it was closed."""
        if self._line is None:
            raise BackendError(f"serial: {self.target.port}: the port was closed")
        return self._line

    def _deadline_ns(self, seconds: float) -> int:
        """The clock's time ``seconds`` (s) from now (ns)."""
        return self.clock.now_ns() + round(seconds * 1e9)

    def _write(self, data: bytes) -> None:
        """Write ``data`` whole (waiting, at most ACK_TIMEOUT_S, while the line is full)."""
        line = self.line
        deadline_ns = self._deadline_ns(ACK_TIMEOUT_S)
        while data:
            taken = line.write(data)
            data = data[taken:]
            if data and not taken:
                now_ns = self.clock.now_ns()
                if now_ns > deadline_ns:
                    raise BackendError(f"serial: {self.target.port}: the amplifier does not read")
                line.wait(min(deadline_ns, now_ns + round(WRITE_WAIT_S * 1e9)), writable=True)

    def _receive(self, wanted: int, deadline_ns: int) -> np.ndarray | None:
        """The next valid body of type ``wanted`` before ``deadline_ns`` (the clock's, ns); None on timeout.

        Other valid frames (STATUS) are passed over, and so is an INFO that does not answer the
        last HELLO (H1: its ``hello_nonce`` is another's, or its length wrong); once an INFO was
        taken, another answering the same HELLO with other bytes is a BackendError (the
        amplifier contradicts itself), as are an ACK BAD_VERSION, a frame of another version
        (H6) and a lost port.
        """
        while True:
            while b"\0" in self._rx:
                encoded, self._rx = self._rx.split(b"\0", 1)
                body = self._decode(encoded)
                if body is None:
                    continue
                if body[1] == codec.MSG_ACK and body[codec.PAYLOAD + codec.ACK_CODE] == codec.ACK_BAD_VERSION:
                    raise _version_error(int(codec.get_u32(body, codec.PAYLOAD + codec.ACK_VALUE)))
                if body[1] == codec.MSG_INFO and not self._answers_hello(body):
                    continue
                if body[1] == wanted:
                    return body
            # Past the deadline, what the port already holds is still read once: a host held up (preempted,
            # stopped) past it must not take the frames that came meanwhile for silence.
            chunk = self.line.read()
            if chunk:
                self._rx = (self._rx + chunk)[-4 * codec.MAX_ENCODED:]
                continue
            if self.clock.now_ns() >= deadline_ns:
                return None
            self.line.wait(deadline_ns)

    def _answers_hello(self, body: np.ndarray) -> bool:
        """Whether the INFO ``body`` answers the last HELLO and none was taken yet; BackendError if it answers it
        with other bytes than the INFO taken."""
        if len(body) != codec.PAYLOAD + codec.INFO_BYTES + codec.CRC_BYTES or \
                codec.get_u32(body, codec.PAYLOAD + codec.INFO_HELLO_NONCE) != self._nonce:
            return False  # an answer to an earlier HELLO (or no INFO at all): passed over
        taken = self._info_body
        if taken is None:
            return True
        payload = slice(codec.PAYLOAD, codec.PAYLOAD + codec.INFO_BYTES)
        if not np.array_equal(taken[payload], body[payload]):  # its seq may differ, its content may not
            raise BackendError(f"serial: the amplifier on {self.target.port} contradicts itself: two INFOs answer one "
                               f"HELLO, {_info_difference(taken, body)} (refused: which one it runs by is unknown)")
        return False  # the same INFO again

    def _decode(self, encoded: bytes) -> np.ndarray | None:
        """The checked body of one received frame, or None for an empty or bad one."""
        if not encoded or len(encoded) > codec.MAX_ENCODED:
            return None
        size = codec.cobs_decode(np.frombuffer(encoded, dtype=np.uint8), len(encoded), self._body)
        kind = codec.open_body(self._body, size) if size >= 0 else codec.CHECK_SHORT
        if kind == codec.CHECK_VERSION:
            raise _version_error(int(self._body[0]))
        return self._body[:size].copy() if kind >= 0 else None

    def _command(self, payload: bytes, msg_type: int, what: str) -> int:
        """Send a command and wait for its ACK: its value; BackendError for no ACK or a refusal."""
        seq = self._send(payload, msg_type)
        deadline_ns = self._deadline_ns(ACK_TIMEOUT_S)
        while (body := self._receive(codec.MSG_ACK, deadline_ns)) is not None:
            if codec.get_u16(body, codec.PAYLOAD + codec.ACK_ACKED_SEQ) != seq:
                continue
            code = int(body[codec.PAYLOAD + codec.ACK_CODE])
            value = int(codec.get_u32(body, codec.PAYLOAD + codec.ACK_VALUE))
            if code != codec.ACK_OK:
                name = codec.ACK_NAMES[code] if code < len(codec.ACK_NAMES) else f"code {code}"
                raise BackendError(f"serial: the amplifier on {self.target.port} refused {what}: {name}")
            return value
        raise BackendError(f"serial: the amplifier on {self.target.port} did not acknowledge {what} "
                           f"within {ACK_TIMEOUT_S:g} s")

    def _hello(self, timeout_s: float, max_voltage_v: float) -> None:
        """HELLO with a new nonce until the INFO echoing it comes (H1), HELLO_TRIES times at most; the envelope's
        scale from that INFO (H3), for a device capped at ``max_voltage_v`` (V peak)."""
        for _ in range(HELLO_TRIES):
            self.link[amp_stream.LINK_SEQ] = 0
            nonce = self._nonce
            while nonce in self._nonces:  # never an earlier HELLO's: a late answer to it must not pass
                nonce = int.from_bytes(os.urandom(4), "little")
            self._nonce = nonce
            self._nonces.add(nonce)
            self._send(HOST_NAME.ljust(codec.HELLO_NAME_BYTES, b"\0") + nonce.to_bytes(4, "little"), codec.MSG_HELLO)
            body = self._receive(codec.MSG_INFO, self._deadline_ns(timeout_s))
            if body is not None:
                info = self.info = _read_info(body, self.target.port)
                self._info_body = body.copy()
                self.scale = envelope_scale(info.full_scale_mv, info.max_mv, max_voltage_v)
                self._set_limits(info)
                return
        raise BackendError(f"serial: no amplifier answered on {self.target.port} ({HELLO_TRIES} HELLOs, "
                           f"{timeout_s:g} s each): is it powered, and does it speak tpad-rt's protocol "
                           f"version {codec.VERSION}? (docs/amplifiers.md)")

    def _set_limits(self, info: AmpInfo) -> None:
        """Give the streamer what it checks the amplifier's reports against and clamps to (H3, H10): the INFO
        taken and its nonce, the carrier range, the clamp and the scale's sample limit."""
        link, scale = self.link, self.scale
        assert self._info_body is not None and scale is not None
        self._buffers[amp_stream.BUF_INFO, :len(self._info_body)] = self._info_body
        link[amp_stream.LINK_NONCE] = self._nonce
        link[amp_stream.LINK_BUFFER_SAMPLES] = info.buffer_samples
        link[amp_stream.LINK_MAX_MV] = info.max_mv
        link[amp_stream.LINK_LEVEL_LIMIT] = scale.level_limit
        link[amp_stream.LINK_CARRIER_MIN_MHZ] = round(info.carrier_min_hz * 1000)
        link[amp_stream.LINK_CARRIER_MAX_MHZ] = round(info.carrier_max_hz * 1000)
        link[amp_stream.LINK_CARRIER_STEP_MHZ] = max(round(info.carrier_step_hz * 1000), CARRIER_RESEND_MHZ)

    def _set_carrier(self, carrier_hz: float) -> None:
        """SET_CARRIER (H2): the achieved carrier goes to ``carrier_hz``; BackendError out of the amplifier's range,
        for a refusal, and for an achieved carrier out of its range or far from the one asked (H10)."""
        info, link = self.info, self.link
        assert info is not None
        if not info.carrier_min_hz <= carrier_hz <= info.carrier_max_hz:
            raise BackendError(f"serial: the device's carrier {carrier_hz:g} Hz is outside the amplifier's range "
                               f"{info.carrier_min_hz:g}-{info.carrier_max_hz:g} Hz")
        asked_mhz = round(carrier_hz * 1000)
        achieved_mhz = self._command(asked_mhz.to_bytes(4, "little"), codec.MSG_SET_CARRIER,
                                     f"the carrier {carrier_hz:g} Hz")
        if not amp_stream.carrier_echo_ok(link, asked_mhz, achieved_mhz):
            raise BackendError(_carrier_echo_error(self.target.port, link, asked_mhz, achieved_mhz))
        self.carrier_hz = achieved_mhz / 1000

    def _check_rate(self) -> None:
        """BackendError unless INFO offers the URL's envelope rate."""
        info, target = self.info, self.target
        assert info is not None
        if target.envelope_hz not in info.envelope_rates_hz:
            raise BackendError(f"serial: the amplifier takes envelope rates of "
                               f"{', '.join(map(str, info.envelope_rates_hz))} Hz, not {target.envelope_hz} "
                               f"(envelope_hz=)")

    def _url_frame_samples(self, envelope_hz: int) -> int:
        """The URL's frame (``frame_ms``) in samples at ``envelope_hz``, within the amplifier's frame limit."""
        info = self.info
        assert info is not None
        return max(1, min(info.max_frame_samples, round(self.target.frame_ms * 1e-3 * envelope_hz)))

    def _plan(self) -> None:
        """Frame size and target fill from the URL, INFO and the measured link (H11: larger frames if the link
        needs them, said in ``link_note``); ConfigError for a buffer the amplifier cannot hold, BackendError for a
        link too slow for any frame."""
        info, target, rate = self.info, self.target, self.link_rate
        assert info is not None and rate is not None
        url_samples = self._url_frame_samples(target.envelope_hz)
        fill = round(target.buffer_ms * 1e-3 * target.envelope_hz)
        if max(url_samples, fill) + url_samples > info.buffer_samples:
            most_ms = (info.buffer_samples - url_samples) / target.envelope_hz * 1e3
            raise ConfigError(f"serial: buffer_ms={target.buffer_ms:g} is more than the amplifier's buffer holds "
                              f"at {target.envelope_hz} Hz (at most {most_ms:g} ms)")
        samples = serial_rate.frames_for(rate, target.envelope_hz, url_samples, fill, info.max_frame_samples,
                                         info.buffer_samples)
        if samples is None:
            raise BackendError(self._too_slow(url_samples, fill))
        if samples != url_samples:
            self.link_note = (
                f"serial: the link to the amplifier on {target.port} carries {rate.text()}, less than the "
                f"{serial_rate.needed_bytes_per_s(target.envelope_hz, url_samples) * serial_rate.LINK_MARGIN / 1e3:.1f}"
                f" kB/s frames of {url_samples} samples need at {target.envelope_hz} Hz with a "
                f"{serial_rate.LINK_MARGIN:g}x margin: sending frames of {samples} samples "
                f"({samples / target.envelope_hz * 1e3:g} ms, "
                f"{serial_rate.needed_bytes_per_s(target.envelope_hz, samples) / 1e3:.1f} kB/s)")
        self.frame_samples = samples
        self.target_fill = max(samples, fill)

    def _too_slow(self, url_samples: int, fill: int) -> str:
        """The one-line refusal of a link too slow for the envelope in any frame the amplifier takes (H11): the
        measured and needed rates, and an envelope rate INFO offers that the link would carry, if one does."""
        info, target, rate = self.info, self.target, self.link_rate
        assert info is not None and rate is not None
        largest = min(info.max_frame_samples, info.buffer_samples // 2, max(1, info.buffer_samples - fill))
        need = serial_rate.needed_bytes_per_s(target.envelope_hz, url_samples) * serial_rate.LINK_MARGIN
        least = serial_rate.needed_bytes_per_s(target.envelope_hz, max(url_samples, largest)) * serial_rate.LINK_MARGIN
        hint = ""
        for envelope_hz in sorted(info.envelope_rates_hz, reverse=True):
            samples = self._url_frame_samples(envelope_hz)
            if envelope_hz < target.envelope_hz and serial_rate.frames_for(
                    rate, envelope_hz, samples, round(target.buffer_ms * 1e-3 * envelope_hz), info.max_frame_samples,
                    info.buffer_samples) is not None:
                hint = f"; envelope_hz={envelope_hz} fits"
                break
        return (f"serial: the link to the amplifier on {target.port} carries {rate.text()} (measured at the "
                f"handshake), too slow for the envelope at {target.envelope_hz} Hz: it needs {need / 1e3:.1f} kB/s "
                f"in frames of {url_samples} samples, {least / 1e3:.1f} kB/s in the largest the amplifier takes "
                f"({serial_rate.LINK_MARGIN:g}x margin included){hint} (docs/amp-protocol.md H11)")

    def _measure_link(self) -> serial_rate.LinkRate:
        """Measure the link (H11): a burst of KEEPALIVE frames for the URL's frames at its envelope rate, read back
        through the amplifier's STATUS frames (``frames_ok + frames_bad`` against ``time_us``); bounded by
        serial_rate.measure_limit_s. BackendError if the amplifier stops reporting meanwhile, or as the reads say."""
        info = self.info
        assert info is not None
        frames = serial_rate.burst_frames(self.target.envelope_hz, self._url_frame_samples(self.target.envelope_hz),
                                          info.status_period_ms)
        limit_ns = self._deadline_ns(serial_rate.measure_limit_s(info.status_period_ms))
        silent_s = (4 * info.status_period_ms + 100) * 1e-3
        first = self._receive(codec.MSG_STATUS, self._deadline_ns(silent_s))
        if first is None:
            raise BackendError(f"serial: the amplifier on {self.target.port} sent no STATUS for {silent_s * 1e3:.0f} ms "
                               "after its INFO (A8): it hung or the line failed")
        base, first_us = self._taken(first), int(codec.get_u32(first, codec.PAYLOAD + codec.STATUS_TIME_US))
        reports = [(first_us, 0)]
        sent = self._burst(frames, limit_ns)
        stall = serial_rate.stall_status_periods(info.status_period_ms)
        while reports[-1][1] < sent and (len(reports) <= stall or reports[-1][1] > reports[-1 - stall][1]
                                         or reports[-1][1] == 0):
            body = self._receive(codec.MSG_STATUS, min(limit_ns, self._deadline_ns(silent_s)))
            if body is None:
                break
            time_us = reports[-1][0] + ((int(codec.get_u32(body, codec.PAYLOAD + codec.STATUS_TIME_US))
                                         - reports[-1][0]) & 0xFFFFFFFF)
            reports.append((time_us, (self._taken(body) - base) & 0xFFFFFFFF))
        return serial_rate.link_rate(reports, sent)

    @staticmethod
    def _taken(body: np.ndarray) -> int:
        """Host frames a STATUS says the amplifier took: valid and bad (a line fault does not slow the count)."""
        return int(codec.get_u32(body, codec.PAYLOAD + codec.STATUS_FRAMES_OK)) + \
            int(codec.get_u32(body, codec.PAYLOAD + codec.STATUS_FRAMES_BAD))

    def _burst(self, frames: int, deadline_ns: int) -> int:
        """Write ``frames`` KEEPALIVE frames as fast as the line takes them, until ``deadline_ns``; how many went
        out whole (a part of one left on the line is ended by a delimiter)."""
        data = b"".join(self._sealed(b"", codec.MSG_KEEPALIVE) for _ in range(frames))
        line, total = self.line, len(data)
        while data:
            taken = line.write(data)
            data = data[taken:]
            if data and not taken:
                if self.clock.now_ns() >= deadline_ns:
                    break
                line.wait(deadline_ns, writable=True)
        sent = (total - len(data)) // serial_rate.KEEPALIVE_LINE_BYTES
        self.link[amp_stream.LINK_SEQ] = (int(self.link[amp_stream.LINK_SEQ]) - frames + sent) & 0xFFFF
        if (total - len(data)) % serial_rate.KEEPALIVE_LINE_BYTES:
            self._write(b"\0")
        return sent

    # --- measuring (calibrate sweep) ---------------------------------------------------

    def set_carrier(self, carrier_hz: float) -> float:
        """SET_CARRIER (also while a tone plays: the amplifier keeps the phase continuous); the achieved carrier
        (Hz). BackendError outside the amplifier's range or for a refusal."""
        self._set_carrier(carrier_hz)
        return self.carrier_hz

    def tone(self, envelope_v: float, seconds: float) -> AmpStatus:
        """Hold a constant envelope of ``envelope_v`` (V peak, at most the amplifier's clamp) for ``seconds``;
        the last STATUS read, once the amplifier applied the envelope on the present carrier (BackendError if it
        has not TONE_APPLY_LIMIT_S after the dwell).

        The first call STARTs a stream; this loop (Python, not the streamer) keeps TONE_BUFFER_S of envelope
        buffered from the play index each STATUS reports, and STARTs it again (at most MAX_TONE_RESTARTS times)
        where the amplifier's watchdog ended it, held up longer than that. :meth:`stop` ends it as it ends a
        stream.
        BackendError for a fault, a lost port, an amplifier that stops reporting, or one that refuses START.
        """
        info = self.info
        assert info is not None and self._stream is None
        limit = self.scale.level_limit if self.scale is not None else 0
        value = min(max(round(envelope_v / info.full_scale_v * 32767), -limit), limit)
        fill = min(info.buffer_samples - self.frame_samples,
                   max(self.target_fill, round(TONE_BUFFER_S * self.target.envelope_hz)))
        if self._tone_index < 0:
            self._start_tone(value, 0, fill)
        clock = self.clock
        deadline_ns = self._deadline_ns(seconds)
        give_up_ns = deadline_ns + round(TONE_APPLY_LIMIT_S * 1e9)
        silent_s = (4 * info.status_period_ms + 100) * 1e-3
        last: AmpStatus | None = None
        restarts = 0
        while True:
            if clock.now_ns() > give_up_ns:
                raise BackendError(f"serial: the amplifier on {self.target.port} did not apply a {envelope_v:g} V tone "
                                   f"at {self.carrier_hz:g} Hz within {seconds + TONE_APPLY_LIMIT_S:g} s (its STATUS "
                                   "never showed it RUNNING with that envelope and carrier)")
            body = self._receive(codec.MSG_STATUS, self._deadline_ns(silent_s))
            if body is None:
                raise BackendError(f"serial: the amplifier on {self.target.port} stopped reporting (no STATUS for "
                                   f"{silent_s * 1e3:.0f} ms)")
            status = self._status(body)
            play_index = int(codec.get_u32(body, codec.PAYLOAD + codec.STATUS_PLAY_INDEX))
            idle = int(body[codec.PAYLOAD + codec.STATUS_STATE]) == codec.STATE_IDLE
            if idle and clock.now_ns() - self._tone_started_ns > info.watchdog_ms * 1_000_000:
                # The amplifier's watchdog ended the stream (no earlier than watchdog_ms after a START: an IDLE
                # STATUS before that was sent before the START): this loop was held up for longer than the
                # watchdog (a loaded host). START again where it stopped, and measure a whole dwell after that.
                restarts += 1
                if restarts > MAX_TONE_RESTARTS:
                    raise BackendError(f"serial: the amplifier on {self.target.port} ended the tone {restarts} times "
                                       f"(its {info.watchdog_ms} ms watchdog): this host does not keep its buffer "
                                       "filled")
                self._start_tone(value, play_index, fill)
                deadline_ns = self._deadline_ns(seconds)
                give_up_ns = deadline_ns + round(TONE_APPLY_LIMIT_S * 1e9)
                last = None
                continue
            self._write_tone(value, play_index, fill)
            if status is not None and abs(status.carrier_hz - self.carrier_hz) < 1e-3 and \
                    abs(status.envelope_v * 32767 / info.full_scale_v - value) <= 1.0:
                last = status
            if clock.now_ns() >= deadline_ns and last is not None:
                return last

    def _start_tone(self, value: int, start_index: int, fill: int) -> None:
        """START a stream at ``start_index`` primed with ``fill`` samples of the envelope ``value``, and write them."""
        info = self.info
        assert info is not None
        rate = self.target.envelope_hz
        payload = (rate.to_bytes(4, "little") + (start_index & 0xFFFFFFFF).to_bytes(4, "little")
                   + min(fill, info.buffer_samples).to_bytes(2, "little"))
        self._start_sent = True
        link = self.link
        link[amp_stream.LINK_START_NS] = self.clock.now_ns()  # no sample can play before this (H10)
        link[amp_stream.LINK_START_INDEX] = start_index & 0xFFFFFFFF
        link[amp_stream.LINK_ENVELOPE_HZ] = rate
        amp_stream.start_checks(link)
        self._check_start_ack(start_index, self._command(payload, codec.MSG_START, f"START at {rate} Hz"))
        self._tone_started_ns = self.clock.now_ns()
        self._tone_index = start_index & 0xFFFFFFFF
        self._write_tone(value, start_index, fill)

    def _check_start_ack(self, start_index: int, value: int) -> None:
        """BackendError unless START's ACK ``value`` is the ``start_index`` it answers (H10)."""
        if value != start_index & 0xFFFFFFFF:
            raise BackendError(f"serial: the amplifier on {self.target.port} acknowledged START at index "
                               f"{start_index & 0xFFFFFFFF} with index {value} (refused: its reports cannot be trusted)")

    def _status(self, body: np.ndarray) -> AmpStatus | None:
        """The STATUS ``body`` measured, or None while it plays nothing; BackendError for a fault or a value out
        of range (H10: the play index too, against the tone's START)."""
        info = self.info
        assert info is not None
        self.link[amp_stream.LINK_WRITTEN] = self._tone_index
        if amp_stream.check_status(self.link, body, self.clock.now_ns()):
            raise BackendError(self._report_error())
        at = codec.PAYLOAD
        faults = int(body[at + codec.STATUS_FAULTS])
        if faults:
            names = [name for bit, name in codec.FAULT_BITS if faults & bit] or [f"bits {faults:#x}"]
            raise BackendError(f"serial: the amplifier on {self.target.port} reported a fault: {', '.join(names)}; "
                               "its output is off")
        if int(body[at + codec.STATUS_STATE]) != codec.STATE_RUNNING:
            return None
        envelope_mv = int(np.frombuffer(body[at + codec.STATUS_ENVELOPE_MV:at + codec.STATUS_ENVELOPE_MV + 4].tobytes(),
                                        dtype="<i4")[0])
        phase_cdeg = int(np.frombuffer(body[at + codec.STATUS_PHASE_CDEG:at + codec.STATUS_PHASE_CDEG + 2].tobytes(),
                                       dtype="<i2")[0])
        return AmpStatus(
            envelope_v=envelope_mv / 1e3,
            voltage_v_rms=codec.get_u32(body, at + codec.STATUS_VOLTAGE_MV_RMS) / 1e3,
            current_a_rms=codec.get_u32(body, at + codec.STATUS_CURRENT_UA_RMS) / 1e6,
            phase_deg=phase_cdeg / 100,
            carrier_hz=codec.get_u32(body, at + codec.STATUS_CARRIER_MHZ) / 1e3,
        )

    def _write_tone(self, value: int, play_index: int, fill: int) -> None:
        """ENVELOPE frames of ``value`` from the next unwritten index until ``fill`` samples past ``play_index``
        (skipping indices already played: the amplifier counts those as underruns)."""
        info = self.info
        assert info is not None
        lag = (play_index - self._tone_index) & 0xFFFFFFFF
        if lag < 0x80000000:  # the amplifier played past what was written
            self._tone_index = play_index
        samples = np.full(self.frame_samples, value, dtype="<i2").tobytes()
        while ((self._tone_index - play_index) & 0xFFFFFFFF) + self.frame_samples <= fill:
            self._send((self._tone_index & 0xFFFFFFFF).to_bytes(4, "little") + samples, codec.MSG_ENVELOPE)
            self._tone_index = (self._tone_index + self.frame_samples) & 0xFFFFFFFF

    # --- streaming --------------------------------------------------------------------

    def lead_bound_s(self) -> float:
        """The most a frame the streamer renders can lead the sample the amplifier plays (s): it renders while
        fewer than the target fill and a frame are ahead of the play position, and never more than the
        amplifier's buffer less a frame (amp_stream's pacing)."""
        info = self.info
        assert info is not None
        ahead = min(self.target_fill + self.frame_samples, info.buffer_samples - self.frame_samples)
        return max(ahead, 0) / self.target.envelope_hz

    def start(self, table: object, track: bool = False, ramp_ms: float = STOP_RAMP_MS) -> None:
        """START at the table's next sample (prefill: the target fill), then stream in a thread of its own;
        with ``track`` (the kernel's cfg tracking too) send the carrier of each control step as it moves, and
        lock it onto the plate's resonance if the amplifier measures voltage, current and phase. A failure
        that ends the stream sends STOP with ``ramp_ms`` (ms; :meth:`stop` gives its own). The table's lead bound
        is set to :meth:`lead_bound_s`."""
        link = self.link
        info = self.info
        assert info is not None
        table.set_lead_bound_s(self.lead_bound_s())  # type: ignore[attr-defined]
        index = int(table.next_sample)  # type: ignore[attr-defined]
        payload = (self.target.envelope_hz.to_bytes(4, "little") + (index & 0xFFFFFFFF).to_bytes(4, "little")
                   + min(self.target_fill, info.buffer_samples).to_bytes(2, "little"))
        self._start_sent = True  # even if its ACK never comes, the amplifier may have started
        link[amp_stream.LINK_START_NS] = self.clock.now_ns()  # no sample can play before this (H10)
        self._check_start_ack(index, self._command(payload, codec.MSG_START, f"START at {self.target.envelope_hz} Hz"))
        link[amp_stream.LINK_ENVELOPE_HZ] = self.target.envelope_hz
        link[amp_stream.LINK_FRAME_SAMPLES] = self.frame_samples
        link[amp_stream.LINK_TARGET_FILL] = self.target_fill
        link[amp_stream.LINK_BUFFER_SAMPLES] = info.buffer_samples
        link[amp_stream.LINK_STATUS_TIMEOUT_NS] = (4 * info.status_period_ms + 100) * 1_000_000
        link[amp_stream.LINK_START_INDEX] = index
        link[amp_stream.LINK_STOP_RAMP_MS] = _ramp(ramp_ms)
        link[amp_stream.LINK_CALLBACK] = render_callback_address()
        link[amp_stream.LINK_LINE_BYTES_PER_S] = round(self.link_rate.bytes_per_s) if self.link_rate else 0
        self._track_with(track)
        self._stream = self._last_stream = self.line.start_stream(
            table.table, link, self._buffers, self._envelope)  # type: ignore[attr-defined]

    def _track_with(self, track: bool) -> None:
        """Set the link's tracking fields: off, the model's carrier, or that locked by the measured phase."""
        link, info = self.link, self.info
        assert info is not None
        locked = info.measures & MEASURES_FOR_LOCK == MEASURES_FOR_LOCK
        link[amp_stream.LINK_TRACK] = (amp_stream.TRACK_OFF if not track
                                       else amp_stream.TRACK_LOCKED if locked else amp_stream.TRACK_MODEL)
        link[amp_stream.LINK_LOCK_RANGE_MHZ] = round(LOCK_RANGE * self.carrier_hz * 1000)
        link[amp_stream.LINK_LOCK_MIN_CURRENT_UA] = LOCK_MIN_CURRENT_UA
        link[amp_stream.LINK_CARRIER_MHZ] = round(self.carrier_hz * 1000)
        link[amp_stream.LINK_CARRIER_PENDING_NS] = -1

    def failure(self) -> BaseException | None:
        """The error that ended the stream (a BackendError, the same object at every call), or None while it runs
        or after a requested stop."""
        crash = self._last_stream.crash if self._last_stream is not None else None
        if crash is not None:
            return crash
        if self._failure is None:
            reason = int(self.link[amp_stream.LINK_EXIT])
            if reason in (amp_stream.EXIT_RUNNING, amp_stream.EXIT_STOPPED):
                return None
            self._failure = BackendError(self._describe(reason))
        return self._failure

    def _describe(self, reason: int) -> str:
        """The one-line message for an exit reason."""
        link, port, info = self.link, self.target.port, self.info
        assert info is not None
        if reason == amp_stream.EXIT_PORT_LOST:
            error = int(link[amp_stream.LINK_ERRNO])
            why = os.strerror(error) if error else "the port closed"
            return f"serial: lost the amplifier on {port}: {why} (unplugged, or its program ended)"
        if reason == amp_stream.EXIT_STATUS_TIMEOUT:
            return (f"serial: the amplifier on {port} stopped reporting (no STATUS for "
                    f"{4 * info.status_period_ms + 100} ms): it hung or the line failed")
        if reason == amp_stream.EXIT_FAULT:
            faults = int(link[amp_stream.LINK_AMP_FAULTS])
            names = [name for bit, name in codec.FAULT_BITS if faults & bit] or [f"bits {faults:#x}"]
            return f"serial: the amplifier on {port} reported a fault: {', '.join(names)}; its output is off"
        if reason == amp_stream.EXIT_VERSION:
            return str(_version_error(int(link[amp_stream.LINK_AMP_VERSION])))
        if reason == amp_stream.EXIT_CONTRADICTED:
            taken, other = self._buffers[amp_stream.BUF_INFO], self._buffers[amp_stream.BUF_INFO_OTHER]
            size = codec.PAYLOAD + codec.INFO_BYTES + codec.CRC_BYTES
            return (f"serial: the amplifier on {port} contradicts itself: an INFO during the stream answers its "
                    f"HELLO otherwise, {_info_difference(taken[:size], other[:size])} (the run ended)")
        if reason == amp_stream.EXIT_BAD_REPORT:
            return self._report_error()
        if reason == amp_stream.EXIT_REFUSED:
            code = int(link[amp_stream.LINK_ACK_CODE])
            name = codec.ACK_NAMES[code] if code < len(codec.ACK_NAMES) else f"code {code}"
            return f"serial: the amplifier on {port} refused to start again after its watchdog: {name}"
        return (f"serial: the amplifier on {port} stopped reading (the port took no byte for "
                f"{4 * info.status_period_ms + 100} ms)")

    def _report_error(self) -> str:
        """The one-line message for the report the streamer (or :func:`amp_stream.status_problem`) refused (H10)."""
        link, s = self.link, amp_stream
        code = int(link[s.LINK_REPORT])
        value, low, high = (int(link[k]) for k in (s.LINK_REPORT_VALUE, s.LINK_REPORT_LOW, s.LINK_REPORT_HIGH))
        port = self.target.port
        if code == s.REPORT_CARRIER_ACK:
            return _carrier_echo_error(port, link, low, value)
        if code == s.REPORT_START_ACK:
            return (f"serial: the amplifier on {port} acknowledged START at index {low & 0xFFFFFFFF} with index "
                    f"{value & 0xFFFFFFFF} (the run ended: its reports cannot be trusted)")
        name, why = s.REPORT_TEXT.get(code, (f"field {code}", "out of range"))
        sent = f"{name} {value & 0xFFFFFFFF} (the stream's index {value})" if name == "play_index" else f"{name} {value}"
        return (f"serial: the amplifier on {port} sent a STATUS with {sent}, outside {low}..{high}: {why} "
                "(the run ended: its reports cannot be trusted)")

    @property
    def streaming(self) -> bool:
        """True while the stream runs."""
        return self._stream is not None and self._stream.alive

    @property
    def realtime(self) -> bool:
        """Whether the stream ran with real-time scheduling (a real port's streamer thread, SCHED_FIFO)."""
        return self._last_stream is not None and self._last_stream.realtime

    def stop(self, ramp_ms: float) -> None:
        """End the stream with STOP and ``ramp_ms`` (H8: the streamer sends it right after the last envelope
        frame; after a START that no stream followed, this does), wait (STOP_ACK_TIMEOUT_S at most) for its
        ACK, and close the port. A missing ACK is not an error: the amplifier's watchdog ramps to 0 anyway
        (A4)."""
        ramp = _ramp(ramp_ms)
        if self._stream is not None:
            self.link[amp_stream.LINK_STOP_RAMP_MS] = ramp
            publish(self.link, amp_stream.LINK_STOP, 1)
            self._stream.join()
            self._stream = None
        elif self._start_sent:  # START went out, no stream followed (its ACK lost, or refused): STOP all the same
            try:
                self.link[amp_stream.LINK_STOP_SEQ] = self._send(ramp.to_bytes(2, "little"), codec.MSG_STOP)
            except BackendError:
                pass  # the port is gone: the amplifier's watchdog ramps to 0 (A4)
        self._start_sent = False
        try:
            seq = int(self.link[amp_stream.LINK_STOP_SEQ])
            if seq >= 0 and int(self.link[amp_stream.LINK_EXIT]) != amp_stream.EXIT_PORT_LOST:
                self._rx = b""
                deadline_ns = self._deadline_ns(STOP_ACK_TIMEOUT_S)
                while (body := self._receive(codec.MSG_ACK, deadline_ns)) is not None:
                    if codec.get_u16(body, codec.PAYLOAD + codec.ACK_ACKED_SEQ) == seq:
                        break
        except BackendError:
            pass  # the port went away after the stream: nothing left to stop
        finally:
            self.close()

    def close(self) -> None:
        """Close the line (safe twice)."""
        line, self._line = self._line, None
        if line is not None:
            line.close()

    def stats(self) -> dict[str, float | int | str]:
        """The link's and the amplifier's counters (the last STATUS), by name."""
        link, s = self.link, amp_stream
        info = self.info
        return {
            "firmware": info.firmware if info else "", "carrier_hz": self.carrier_hz, "realtime": self.realtime,
            "envelope_hz": self.target.envelope_hz, "frame_samples": self.frame_samples,
            "target_fill": self.target_fill, "frames_sent": int(link[s.LINK_FRAMES_SENT]),
            "statuses": int(link[s.LINK_STATUSES]), "rx_bad": int(link[s.LINK_RX_BAD]),
            "tx_blocked": int(link[s.LINK_TX_BLOCKED]), "late": int(link[s.LINK_LATE]),
            "restarts": int(link[s.LINK_RESTARTS]), "start_index": int(link[s.LINK_START_INDEX]),
            "amp_state": codec.STATE_NAMES[int(link[s.LINK_AMP_STATE]) % 5],
            "amp_fill": int(link[s.LINK_AMP_FILL]), "amp_frames_ok": int(link[s.LINK_AMP_FRAMES_OK]),
            "amp_frames_bad": int(link[s.LINK_AMP_FRAMES_BAD]),
            "amp_frames_rejected": int(link[s.LINK_AMP_FRAMES_REJECTED]),
            "amp_sequence_gaps": int(link[s.LINK_AMP_SEQUENCE_GAPS]), "amp_underruns": int(link[s.LINK_AMP_UNDERRUNS]),
            "amp_watchdog_trips": int(link[s.LINK_AMP_WATCHDOG_TRIPS]),
            "amp_voltage_v_rms": link[s.LINK_AMP_VOLTAGE_MV_RMS] / 1e3,
            "amp_current_a_rms": link[s.LINK_AMP_CURRENT_UA_RMS] / 1e6,
            "amp_phase_deg": link[s.LINK_AMP_PHASE_CDEG] / 100,
            "tracking": TRACKING_NAMES[int(link[s.LINK_TRACK]) % len(TRACKING_NAMES)],
            "tracked_carrier_hz": link[s.LINK_CARRIER_MHZ] / 1e3 if link[s.LINK_TRACK] else self.carrier_hz,
            "carrier_sets": int(link[s.LINK_CARRIER_SETS]), "carrier_refused": int(link[s.LINK_CARRIER_REFUSED]),
            "lock_offset_hz": link[s.LINK_LOCK_OFFSET_MHZ] / 1e3, "lock_updates": int(link[s.LINK_LOCK_UPDATES]),
            "infos_passed_over": int(link[s.LINK_INFOS_STALE]),
            "link_kb_s": self.link_rate.bytes_per_s / 1e3 if self.link_rate else math.nan,
            "link_at_least": bool(self.link_rate and self.link_rate.at_least),
            "link_needed_kb_s": (serial_rate.needed_bytes_per_s(self.target.envelope_hz, self.frame_samples) / 1e3
                                 if self.frame_samples else math.nan),
            "link_note": self.link_note,
        }


def _ramp(ramp_ms: float) -> int:
    """STOP's ``ramp_ms`` field for a ramp of ``ramp_ms`` (ms): whole, 1 to 65535."""
    return min(0xFFFF, max(1, round(ramp_ms)))


def warm_checks() -> None:
    """Compile (or load from numba's cache) the codec and the checks of the amplifier's reports that this module
    calls from Python, on scratch arrays of the types it passes: before a port is opened, so that no timed wait (the
    handshake's, a tone's dwell) waits for a compile (check_status alone took 1.5 s cold, 0.3 s from the cache:
    more than a tone may wait, and far more than the amplifier's watchdog)."""
    link = np.zeros(amp_stream.LINK_SIZE, dtype=np.int64)
    body, frame = np.zeros(codec.MAX_BODY, dtype=np.uint8), np.zeros(codec.MAX_BODY, dtype=np.uint8)
    out = np.zeros(codec.MAX_ENCODED, dtype=np.uint8)
    size = codec.seal(frame, 0, codec.MSG_HELLO, 0, out)
    decoded = codec.cobs_decode(np.frombuffer(bytes(out[:size - 1]), dtype=np.uint8), size - 1, body)
    codec.open_body(body, decoded)
    codec.get_u16(body, 0)
    codec.get_u32(body, 0)
    amp_stream.start_checks(link)
    amp_stream.check_status(link, body, 0)
    amp_stream.carrier_echo_ok(link, 1, 1)
    amp_stream.carrier_echo_tolerance_mhz(link, 1)
    amp_stream.frame_line_bytes(1)  # the link check's need (tpad_rt.outputs.serial_rate)


def warm_up(table: object) -> None:
    """Compile the streamer (or load it from numba's cache) with a run that ends at once, on ``table`` (a copy
    of the real one): before a port is opened, so that the amplifier's watchdog never waits for a compile."""
    link = np.zeros(amp_stream.LINK_SIZE, dtype=np.int64)
    link[[amp_stream.LINK_FD, amp_stream.LINK_STOP]] = (-1, 1)
    link[[amp_stream.LINK_ENVELOPE_HZ, amp_stream.LINK_FRAME_SAMPLES]] = (1000, 1)
    buffers = np.zeros((amp_stream.BUF_ROWS, amp_stream.BUF_BYTES), dtype=np.uint8)
    amp_stream.stream(table.table, link, buffers, np.zeros(amp_stream.ENVELOPE_SCRATCH, dtype=np.float32),  # type: ignore[attr-defined]
                      np.zeros(3))


def render_callback_address() -> int:
    """The address of the compiled audio callback, which the streamer calls for each frame."""
    from tpad_rt.kernel import callback

    address = callback.render_callback.address
    if address is None:  # numba types it Optional: a compiled cfunc always has one
        raise BackendError("serial: the audio callback has no address (it did not compile)")
    return int(address)


def _carrier_echo_error(port: str, link: np.ndarray, asked_mhz: int, achieved_mhz: int) -> str:
    """The message for a SET_CARRIER ACK whose achieved carrier ``carrier_echo_ok`` refused (H2, H10)."""
    low, high = link[amp_stream.LINK_CARRIER_MIN_MHZ] / 1000, link[amp_stream.LINK_CARRIER_MAX_MHZ] / 1000
    return (f"serial: the amplifier on {port} answered SET_CARRIER {asked_mhz / 1000:g} Hz with an achieved carrier "
            f"of {achieved_mhz / 1000:g} Hz (value {achieved_mhz} mHz), outside its own range {low:g}-{high:g} Hz or "
            f"more than {amp_stream.carrier_echo_tolerance_mhz(link, asked_mhz) / 1000:g} Hz from the carrier asked "
            "(refused: its reports cannot be trusted)")


def _version_error(version: int) -> BackendError:
    """The error for an amplifier speaking another protocol version (H6)."""
    return BackendError(f"serial: the amplifier speaks protocol version {version}; this tpad-rt speaks version "
                        f"{codec.VERSION} (update one of them: docs/amp-protocol.md)")
