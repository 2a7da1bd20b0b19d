"""One conformance suite for the amplifier protocol (docs/amp-protocol.md, version 2), run against every amplifier.

Every test function is parametrised over the targets of tests/amp_targets.py:

- ``emulator``: tpad_rt.amp.emulator.Amplifier, in process, on exact virtual times;
- ``core``: the firmware's portable core (firmware/core) through ctypes, in process, on the same times;
- ``host``: the host build ``firmware/build/host/tpad-amp`` on a real pty, in real time;
- ``qemu``: the microbit build in QEMU (``firmware/run-qemu microbit``) on its pty: protocol only.

The rules that need exact time (A1-A4, A6's 1 ms, STOP's and HELLO's ramps, STATUS's schedule
to the microsecond) run on the in-process targets; a pty target skips them with the reason,
and runs every rule judged on answers, counters and refusals, with waits for answers only.
A stream on a pty runs in one test, :func:`test_a_stream_plays_on_the_amplifiers_clock`,
marked realtime for the pty targets only. The emulator and the core also run side by side on
the same frames at the same times
(:func:`test_emulator_and_core_apply_the_same_envelope_and_carrier`). docs/testing.md "The
amplifier conformance suite" says what runs where.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import math
from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest
from cobs import cobs  # type: ignore[import-untyped]

from amp_targets import (
    REPO, Applied, CoreTarget, EmulatorTarget, Host, LineTarget, Target, VirtualTarget, expected_info, load_core,
)
from conftest import require_program
from firmware_build import build
from tpad_rt.amp import wire
from tpad_rt.amp.emulator import carrier_phase_cycles
from tpad_rt.amp.wire import Code, Fault, State, Type

TARGETS = ("emulator", "core", "host", "qemu")
LINES = ("host", "qemu")
#: The targets on exact (virtual) times.
EXACT = ("emulator", "core")
RATE_HZ = 16_000
CARRIER_MHZ = 31_360_000
#: The document's worked bytes (section 7): what goes on the line.
WORKED_KEEPALIVE = bytes.fromhex("04 02 06 05 03 fd 24 00")
WORKED_HELLO = bytes.fromhex("03 02 01 01 08 74 70 61 64 2d 72 74 01 01 01 01 07 b9 79 37 9e c0 c4 00")
WORKED_HELLO_NONCE = 0x9E3779B9
WORKED_ENVELOPE = bytes.fromhex("04 02 04 03 01 01 01 01 01 01 01 02 40 06 c0 ff 7f 6a 87 00")
WORKED_SAMPLES = (0, 16384, -16384, 32767)


# --- the targets ------------------------------------------------------------------------------------------------

@functools.cache
def core_library() -> ctypes.CDLL:
    return load_core(build("lib"))


def start_line(name: str, *flags: str) -> LineTarget:
    """A new process of the pty target ``name`` (built first); ``flags`` for the host build."""
    if name == "host":
        return LineTarget(name, [str(build("host")), "--device", str(REPO / "tpad_rt" / "devices" / "default.yaml"),
                                 *flags])
    require_program("qemu-system-arm")
    build("microbit")
    return LineTarget(name, [str(REPO / "firmware" / "run-qemu"), "microbit"])


def new_target(name: str) -> Target:
    if name == "emulator":
        return EmulatorTarget()
    if name == "core":
        return CoreTarget(core_library())
    return start_line(name)


@pytest.fixture(scope="module")
def lines() -> Iterator[dict[str, LineTarget]]:
    """The pty targets' processes, started when first needed and shared by the module's tests (each test opens
    its own session with HELLO); each must end with status 0 on SIGTERM."""
    started: dict[str, LineTarget] = {}
    yield started
    with contextlib.ExitStack() as closing:  # every one is closed, whichever fails
        for line in started.values():
            closing.callback(line.close)


@pytest.fixture(params=TARGETS)
def target(request: pytest.FixtureRequest, lines: dict[str, LineTarget]) -> Target:
    name = request.param
    if name in LINES:
        if name not in lines:
            lines[name] = start_line(name)
        return lines[name]
    return new_target(name)


@pytest.fixture(params=TARGETS)
def fresh_target(request: pytest.FixtureRequest) -> Iterator[Target]:
    """A target just powered up (a pty target: a new process)."""
    started = new_target(request.param)
    yield started
    started.close()


@pytest.fixture(params=EXACT)
def exact_target(request: pytest.FixtureRequest) -> VirtualTarget:
    """An in-process target on exact virtual times: the rules judged on exact times run on these only (a pty
    target's times are its host's scheduling)."""
    made = new_target(request.param)
    assert isinstance(made, VirtualTarget)
    return made


# --- helpers ----------------------------------------------------------------------------------------------------

def step_uv(info: wire.Info) -> float:
    """One step of the envelope's integer encoding (uV): full_scale_mv / 32767."""
    return info.full_scale_mv * 1000 / 32767


def request_uv(sample: int, info: wire.Info) -> float:
    """What ``sample`` asks for (uV): s / 32767 * full_scale_mv; -32768 is read as -32767."""
    return max(sample, -32767) / 32767 * info.full_scale_mv * 1000


def limited_uv(requests_uv: list[float], info: wire.Info, rate_hz: int, start_uv: float = 0.0) -> np.ndarray:
    """The applied envelope (uV) the rules give for ``requests_uv`` from ``start_uv``: A1's clamp at max_mv, then
    A2's slew of slew_mv_per_ms / envelope_hz * 1000 mV per sample."""
    slew_uv, max_uv = info.slew_mv_per_ms * 1e6 / rate_hz, info.max_mv * 1000
    level, out = start_uv, []
    for wanted in requests_uv:
        wanted = min(max(wanted, -max_uv), max_uv)
        level = wanted if abs(wanted - level) <= slew_uv else level + math.copysign(slew_uv, wanted - level)
        out.append(level)
    return np.array(out)


def check_info(target: Target, info: wire.Info) -> None:
    """INFO's fields within section 3.2's ranges; on the in-process targets, the emulator's INFO for the device."""
    assert info.max_mv <= info.full_scale_mv and info.slew_mv_per_ms >= info.max_mv  # A1, A2
    assert 0 < info.watchdog_ms <= 50 and 1 <= info.status_period_ms <= 100
    assert 1 <= info.max_frame_samples <= wire.MAX_FRAME_SAMPLES and info.buffer_samples >= info.max_frame_samples
    assert 0 < info.carrier_min_mhz <= info.carrier_max_mhz and RATE_HZ in info.envelope_rates_hz
    if isinstance(target, VirtualTarget):
        assert replace(info, firmware="", serial="", hello_nonce=0) == replace(expected_info(), firmware="", serial="")
    assert info.firmware.startswith("tpad-emu" if target.name == "emulator" else "tpad-amp")


def start_stream(host: Host, *, start_index: int = 0, prefill: int = 16, rate_hz: int = RATE_HZ) -> wire.Info:
    """HELLO, SET_CARRIER and START (acknowledged OK); the INFO."""
    info = host.hello()
    assert host.command(Type.SET_CARRIER, wire.SetCarrier(CARRIER_MHZ).pack()).code == Code.OK
    ack = host.command(Type.START, wire.Start(rate_hz, start_index, prefill).pack())
    assert (ack.code, ack.value) == (Code.OK, start_index)
    return info


def envelope(first_index: int, samples: list[int] | np.ndarray) -> bytes:
    return wire.Envelope(first_index & 0xFFFFFFFF, np.asarray(samples, dtype=np.int16)).pack()


def send_samples(host: Host, first_index: int, samples: list[int] | np.ndarray, frame_samples: int = 64) -> int:
    """ENVELOPE frames of at most ``frame_samples`` from ``first_index`` on; the index after the last."""
    for offset in range(0, len(samples), frame_samples):
        host.send(Type.ENVELOPE, envelope(first_index + offset, samples[offset:offset + frame_samples]))
    return first_index + len(samples)


def played(applied: Applied, after_us: float) -> Applied:
    """The samples applied from ``after_us`` on."""
    return applied.where(applied.t_us >= after_us)


def from_stream(applied: Applied) -> Applied:
    """The samples that came from the buffer (an index)."""
    return applied.where(applied.index >= 0)


def bad_crc(type_: int, seq: int, payload: bytes = b"") -> bytes:
    """A frame on the line whose CRC does not match (its body's CRC with one bit flipped)."""
    body = bytearray(cobs.decode(wire.encode(type_, seq, payload)[:-1]))
    body[-2] ^= 1
    return bytes(cobs.encode(bytes(body))) + b"\x00"


def hung_acks(host: Host, since: int, seqs: set[int]) -> list[wire.Ack]:
    """ACKs received since ``since`` for the frames ``seqs`` (should be none)."""
    return [ack for ack in host.acks_since(since) if ack.acked_seq in seqs]


# --- section 7: the worked bytes ----------------------------------------------------------------------------------

def test_worked_hello_is_answered_by_info_echoing_its_nonce(target: Target) -> None:
    """Section 7's HELLO (nonce 0x9E3779B9) gets INFO seq 0 with that hello_nonce; its KEEPALIVE (seq 5) is a
    valid frame after HELLO's seq 0: counted, and one sequence gap."""
    host = Host(target)
    since = host.mark()
    host.write(WORKED_HELLO)
    answer = host.wait_for(lambda frame: frame.type == Type.INFO, "INFO", since)
    info = wire.Info.unpack(answer.frame.payload)
    assert (answer.frame.seq, info.hello_nonce) == (0, WORKED_HELLO_NONCE)
    check_info(target, info)
    host.write(WORKED_KEEPALIVE)
    host.seq = 6
    status = host.status()
    assert (status.frames_ok, status.frames_bad, status.frames_rejected, status.sequence_gaps) == (3, 0, 0, 1)
    assert (status.state, status.envelope_mv, status.last_seq) == (State.IDLE, 0, 6)


def test_worked_envelope_plays_its_four_samples(exact_target: VirtualTarget) -> None:
    """Section 6's session with section 7's bytes: HELLO, SET_CARRIER seq 1, START seq 2 (prefill 4), the worked
    ENVELOPE seq 3: indices 0-3 play 0, +half, -half (anti-phase) and full scale, through A1 and A2."""
    amp = exact_target
    host = Host(amp)
    host.write(WORKED_HELLO)
    info = wire.Info.unpack(host.wait_for(lambda frame: frame.type == Type.INFO, "INFO").frame.payload)
    host.seq = 1
    assert host.command(Type.SET_CARRIER, wire.SetCarrier(CARRIER_MHZ).pack()).code == Code.OK
    assert host.command(Type.START, wire.Start(RATE_HZ, 0, 4).pack()).code == Code.OK
    host.write(WORKED_ENVELOPE)
    host.wait_us(1000)
    stream = from_stream(amp.applied())
    assert list(stream.index) == [0, 1, 2, 3]
    expected = limited_uv([request_uv(sample, info) for sample in WORKED_SAMPLES], info, RATE_HZ)
    np.testing.assert_allclose(stream.envelope_uv, expected, atol=step_uv(info))
    assert set(stream.carrier_mhz) == {CARRIER_MHZ} and set(stream.state) == {State.RUNNING}
    assert amp.counters()["frames_ok"] == 4 and amp.counters()["sequence_gaps"] == 0


# --- section 3: HELLO, SET_CARRIER, START, STOP ---------------------------------------------------------------

def test_hello_resets_the_session_and_info_comes_first(target: Target) -> None:
    """A second HELLO forgets the carrier, zeroes the counters, restarts the amplifier's seq at 0 and answers the
    same INFO (its new nonce aside) before it answers any frame after the HELLO."""
    host = Host(target)
    first = host.hello(0x11111111)
    assert host.command(Type.SET_CARRIER, wire.SetCarrier(CARRIER_MHZ).pack()).code == Code.OK
    host.send(Type.KEEPALIVE, seq=host.seq + 7)  # a gap
    assert host.status().sequence_gaps == 1
    since = host.mark()
    hello_seq = host.send(Type.HELLO, wire.Hello("again", 0x22222222).pack(), seq=0x4321)  # HELLO: never a gap
    start_seq = host.send(Type.START, wire.Start(RATE_HZ, 0, 16).pack())
    answers = host.wait_for(lambda frame: frame.type == Type.ACK and wire.Ack.unpack(frame.payload).acked_seq
                            == start_seq, "ACK of START", since)
    received = [item.frame for item in host.frames[since:]]
    infos = [frame for frame in received if frame.type == Type.INFO]
    assert len(infos) == 1 and infos[0].seq == 0
    second = wire.Info.unpack(infos[0].payload)
    assert replace(second, hello_nonce=first.hello_nonce) == first and second.hello_nonce == 0x22222222
    assert received.index(infos[0]) < received.index(answers.frame)
    assert wire.Ack.unpack(answers.frame.payload).code == Code.NO_CARRIER  # the carrier was forgotten
    status = host.status()
    assert (status.frames_ok, status.frames_rejected, status.sequence_gaps) == (2, 1, 0)
    assert (status.carrier_mhz, status.last_seq, hello_seq) == (0, 0x4323, 0x4321)


def test_set_carrier_rounds_to_its_step_and_refuses_out_of_range(target: Target) -> None:
    """The nearest carrier the amplifier makes (ties up), within [carrier_min_mhz, carrier_max_mhz]; outside it
    OUT_OF_RANGE (value 0) and the carrier unchanged."""
    host = Host(target)
    info = host.hello()
    step = max(info.carrier_step_mhz, 1)
    for asked in (CARRIER_MHZ + 4, CARRIER_MHZ + step // 2, 31_360_007, info.carrier_min_mhz, info.carrier_max_mhz):
        ack = host.command(Type.SET_CARRIER, wire.SetCarrier(asked).pack())
        assert (ack.code, ack.value) == (Code.OK, (asked + step // 2) // step * step), asked
        assert info.carrier_min_mhz <= ack.value <= info.carrier_max_mhz
        assert host.status().carrier_mhz == ack.value
    made = ack.value
    for asked in (info.carrier_min_mhz - 1, info.carrier_max_mhz + 1, 0, 0xFFFFFFFF):
        ack = host.command(Type.SET_CARRIER, wire.SetCarrier(asked).pack())
        assert (ack.acked_type, ack.code, ack.value) == (Type.SET_CARRIER, Code.OUT_OF_RANGE, 0), asked
        assert host.status().carrier_mhz == made


def test_start_checks_in_order(target: Target) -> None:
    """START: FAULT, then BAD_RATE, NO_CARRIER, OUT_OF_RANGE (prefill in [1, buffer_samples]); OK answers its
    start_index; STOP answers OK (0) in a stream and outside one."""
    host = Host(target)
    info = host.hello()
    bad_prefill = info.buffer_samples + 1
    refusals = [((12345, 0, 0), Code.BAD_RATE), ((0, 0, 0), Code.BAD_RATE), ((RATE_HZ, 0, 0), Code.NO_CARRIER),
                ((RATE_HZ, 0, bad_prefill), Code.NO_CARRIER)]
    for fields, code in refusals:
        assert host.command(Type.START, wire.Start(*fields).pack()).code == code, fields
    assert host.command(Type.SET_CARRIER, wire.SetCarrier(CARRIER_MHZ).pack()).code == Code.OK
    for fields, code in [((12345, 0, 0), Code.BAD_RATE), ((RATE_HZ, 0, 0), Code.OUT_OF_RANGE),
                         ((RATE_HZ, 0, bad_prefill), Code.OUT_OF_RANGE)]:
        assert host.command(Type.START, wire.Start(*fields).pack()).code == code, fields
    status = host.status()
    assert (status.state, status.frames_rejected) == (State.IDLE, 7)
    for rate_hz in (rate for rate in info.envelope_rates_hz if rate):
        ack = host.command(Type.START, wire.Start(rate_hz, 0xFFFFFFFE, info.buffer_samples).pack())
        assert (ack.code, ack.value) == (Code.OK, 0xFFFFFFFE)
        stop = host.command(Type.STOP, wire.Stop(5).pack())
        assert (stop.acked_type, stop.code, stop.value) == (Type.STOP, Code.OK, 0)
    assert host.command(Type.STOP, wire.Stop(5).pack()).code == Code.OK  # outside a stream too
    if isinstance(target, VirtualTarget):  # FAULT comes first (the pty targets: test_a6 with a fault option)
        target.fault(Fault.OVERCURRENT)
        assert host.command(Type.START, wire.Start(12345, 0, 0).pack()).code == Code.FAULT


def test_stop_ramps_linearly_then_idle(exact_target: VirtualTarget) -> None:
    """STOP ramps from the present value to 0 over min(ramp_ms, 50) ms (at least one sample), ACK at once, then
    IDLE with the buffer emptied; every ramp passes A2, and the output ends at 0 however short the ramp."""
    amp = exact_target
    host = Host(amp)
    level = 20000
    for ramp_ms, samples in ((5, 80), (1000, 800), (0, 1)):
        info = start_stream(host, prefill=64)
        index = send_samples(host, 0, [level] * 960)  # 60 ms
        host.wait_us(20_000)
        level_uv = amp.counters()["envelope_uv"]
        assert level_uv == pytest.approx(request_uv(level, info), abs=step_uv(info))
        since, stop_us = host.mark(), amp.now_us
        seq = host.send(Type.STOP, wire.Stop(ramp_ms).pack())
        answer = host.wait_for(lambda frame: frame.type == Type.ACK, "ACK", since)
        assert answer.t_us == stop_us and wire.Ack.unpack(answer.frame.payload).acked_seq == seq
        host.wait_us(60_000)
        ramp = played(amp.applied(), stop_us + 0.5)  # a sample due at stop_us plays before the STOP acts
        wanted = [level_uv * (1 - done / samples) for done in range(1, samples + 1)]
        expected = limited_uv(wanted + [0.0] * 10, info, RATE_HZ, level_uv)
        reaches_zero = int(np.flatnonzero(expected == 0)[0]) + 1  # samples (the clock may stop at rest after them)
        assert len(ramp.t_us) >= reaches_zero and np.all(ramp.envelope_uv[reaches_zero:] == 0)
        compared = min(len(ramp.t_us), len(expected))
        np.testing.assert_allclose(ramp.envelope_uv[:compared], expected[:compared], atol=step_uv(info))
        assert (amp.counters()["envelope_uv"], amp.counters()["state"], set(ramp.index)) == (0, State.IDLE, {-1})
        since = host.mark()
        host.send(Type.ENVELOPE, envelope(index, [level] * 8))  # the stream is over: NOT_STARTED
        assert host.status().frames_rejected == 1 and host.acks_since(since) == []


def test_hello_ramps_the_output_down_on_the_old_carrier(exact_target: VirtualTarget) -> None:
    """HELLO during a stream ramps the output linearly to 0 over R (<= 10 ms: A4's ramp) on the carrier it had,
    then IDLE with no carrier; INFO goes out at once."""
    amp = exact_target
    host = Host(amp)
    info = start_stream(host, prefill=64)
    send_samples(host, 0, [20000] * 640)
    host.wait_us(20_000)
    level_uv, hello_us = amp.counters()["envelope_uv"], amp.now_us
    since = host.mark()
    host.send(Type.HELLO, wire.Hello("again", 9).pack())
    assert host.wait_for(lambda frame: frame.type == Type.INFO, "INFO", since).t_us == hello_us
    host.wait_us(20_000)
    ramp = played(amp.applied(), hello_us + 0.5)
    samples = int(np.flatnonzero(ramp.envelope_uv == 0)[0]) + 1
    assert 1 <= samples <= 10 * RATE_HZ // 1000  # R <= 10 ms
    wanted = limited_uv([level_uv * (1 - done / samples) for done in range(1, samples + 1)], info, RATE_HZ, level_uv)
    np.testing.assert_allclose(ramp.envelope_uv[:samples], wanted, atol=step_uv(info))
    assert set(ramp.carrier_mhz[:samples]) == {CARRIER_MHZ} and set(ramp.index) == {-1}
    assert set(ramp.state[:samples - 1]) == {State.RAMPING}
    counters = amp.counters()
    assert (counters["state"], counters["carrier_mhz"], counters["envelope_uv"]) == (State.IDLE, 0, 0)


# --- section 2.3: what a receiver checks -----------------------------------------------------------------------

def test_bad_frames_are_counted_never_acted_on_nor_answered(target: Target) -> None:
    """Step 1-2 failures (bad COBS, a body under 6 or over MAX_BODY bytes, a bad CRC, a run of more than
    MAX_ENCODED bytes without 0x00) count one bad frame each, are not answered, set no seq, reset nothing;
    an empty frame is ignored; the next good frame is served."""
    host = Host(target)
    host.hello()
    since = host.mark()
    over_body = bytes([wire.VERSION, Type.ENVELOPE, 9, 0]) + bytes(520)
    over_body += wire.crc16(over_body).to_bytes(2, "little")
    bad = [b"\x05\x11\x22\x00",  # COBS: the code byte runs past the end
           bytes(cobs.encode(b"\x02\x06\x05")) + b"\x00",  # a body of 3 bytes
           bytes(cobs.encode(over_body)) + b"\x00",  # 524 bytes: over MAX_BODY
           bad_crc(Type.SET_CARRIER, host.seq, wire.SetCarrier(CARRIER_MHZ).pack()),
           b"\x55" * (wire.MAX_ENCODED + 1) + b"\x00",  # over-long: one bad frame
           b"\x37" * 5000 + b"\x00"]  # far over: still one
    for data in bad:
        host.write(data)
    host.write(b"\x00\x00")  # empty frames: ignored
    status = host.status()
    assert (status.frames_bad, status.frames_ok, status.frames_rejected, status.sequence_gaps) == (6, 2, 0, 0)
    assert (status.carrier_mhz, host.acks_since(since)) == (0, [])
    assert host.command(Type.SET_CARRIER, wire.SetCarrier(CARRIER_MHZ).pack()).code == Code.OK


def test_refused_frames_are_answered_with_their_reason(target: Target) -> None:
    """Step 3-4 refusals of valid frames: another version (A5: BAD_VERSION, value the amplifier's version, before
    the type and length are looked at, an ENVELOPE too), an unknown type, a wrong length (an ENVELOPE of this
    version only counted); each counted in frames_rejected, counted for seq, never acted on."""
    host = Host(target)
    info = host.hello()
    since = host.mark()
    answered: list[tuple[int, int, int]] = []  # (seq, type, code)
    for version in (1, 3, 255):
        for type_, payload in ((Type.HELLO, wire.Hello("old", 7).pack()), (Type.SET_CARRIER,
                               wire.SetCarrier(CARRIER_MHZ).pack()), (Type.ENVELOPE, envelope(0, [1000] * 4)),
                               (0x42, b""), (Type.STOP, b"\x01")):
            answered.append((host.send(type_, payload, version=version), type_, Code.BAD_VERSION))
    for type_ in (0x00, 0x07, 0x7F, Type.INFO, Type.STATUS, Type.ACK, 0xFF):
        answered.append((host.send(type_, bytes(8)), type_, Code.UNKNOWN_TYPE))
    for type_, size in ((Type.HELLO, 15), (Type.HELLO, 17), (Type.SET_CARRIER, 3), (Type.SET_CARRIER, 5),
                        (Type.START, 9), (Type.START, 11), (Type.STOP, 1), (Type.STOP, 3), (Type.KEEPALIVE, 1)):
        answered.append((host.send(type_, bytes(size), seq=host.seq), type_, Code.BAD_LENGTH))  # seq runs on
    silent = {host.send(Type.ENVELOPE, payload) for payload in (b"", b"\x00" * 3, b"\x00" * 4, b"\x00" * 7,
                                                                 envelope(0, [1] * info.max_frame_samples)[:-1])}
    status = host.status()
    acks = host.acks_since(since)
    assert [(ack.acked_seq, ack.acked_type, ack.code) for ack in acks] == answered
    assert {ack.value for ack in acks if ack.code == Code.BAD_VERSION} == {wire.VERSION}
    assert hung_acks(host, since, silent) == []
    assert (status.frames_rejected, status.frames_ok, status.sequence_gaps) == (len(answered) + len(silent), 2, 0)
    assert (status.carrier_mhz, status.state) == (0, State.IDLE)  # nothing acted on: no SET_CARRIER, no HELLO


def test_envelope_outside_a_stream_or_its_window_is_counted_not_answered(target: Target) -> None:
    """ENVELOPE while IDLE is refused (NOT_STARTED), and one not wholly in [play_index, play_index +
    buffer_samples) mod 2**32 (OUT_OF_WINDOW): counted, never answered; the window wraps at 2**32 and
    buffer_fill counts what is buffered from play_index on."""
    host = Host(target)
    info = host.hello()
    since = host.mark()
    seqs = {host.send(Type.ENVELOPE, envelope(0, [100] * 8))}
    status = host.status()
    assert (status.frames_rejected, hung_acks(host, since, seqs)) == (1, [])
    if not isinstance(target, VirtualTarget):
        return  # the window needs a stream whose watchdog the host's frames keep in time: exact targets only
    amp = target
    start = 2**32 - 16
    start_stream(host, start_index=start, prefill=info.buffer_samples)
    since = host.mark()
    window = info.buffer_samples
    refused = [(start - 1, 1), (start + window - 1, 2), (start + window, 1), (0x7FFFFFFF, 8), (start - 300, 8)]
    taken = [(start + window - 1, 1), (start + 8, 16), (start, 8)]
    seqs = {host.send(Type.ENVELOPE, envelope(first, [100] * count)) for first, count in refused + taken}
    status = host.status()
    assert (status.frames_rejected, status.frames_ok, status.buffer_fill) == (len(refused), 3 + len(taken) + 1, 24)
    assert (status.state, status.play_index, hung_acks(host, since, seqs)) == (State.PRIMING, start, [])
    assert amp.counters()["play_index"] == start


def test_sequence_gaps_are_counted_across_valid_frames(target: Target) -> None:
    """A valid frame whose seq is not the last valid one's + 1 (mod 65536) counts one gap; rejected valid frames
    count for seq, bad ones do not; HELLO sets the count's start."""
    host = Host(target)
    host.hello()
    host.send(Type.KEEPALIVE)  # 1
    host.send(Type.KEEPALIVE, seq=5)  # gap
    host.send(0x42, b"")  # 6, refused: counts for seq
    host.write(bad_crc(Type.KEEPALIVE, 100))  # bad: not counted for seq
    host.send(Type.KEEPALIVE)  # 7
    host.send(Type.KEEPALIVE, seq=0xFFFF)  # gap
    host.send(Type.KEEPALIVE)  # 0: wraps, no gap
    status = host.status()  # 1
    assert (status.sequence_gaps, status.frames_bad, status.frames_rejected, status.last_seq) == (2, 1, 1, 1)
    host.send(Type.HELLO, wire.Hello("again", 3).pack(), seq=0x8000)  # no gap, and the counters restart
    host.send(Type.KEEPALIVE, seq=0x8002)  # gap
    assert host.status().sequence_gaps == 1


# --- section 4: the amplifier's rules -----------------------------------------------------------------------------

def test_a1_clamp_applies_samples_above_max_mv_at_max_mv(exact_target: VirtualTarget) -> None:
    """A1: no applied sample exceeds max_mv in magnitude; samples above it (full scale is above max_mv) apply at
    max_mv, anti-phase ones at -max_mv."""
    amp = exact_target
    host = Host(amp)
    info = start_stream(host, prefill=64)
    samples = [32767] * 64 + [-32768] * 64 + [30000] * 64 + [10000] * 64 + [-32767] * 64
    send_samples(host, 0, samples)
    host.wait_us(len(samples) * 1_000_000 // RATE_HZ + 1000)
    stream = from_stream(amp.applied())
    assert list(stream.index) == list(range(len(samples)))
    max_uv = info.max_mv * 1000
    assert np.abs(stream.envelope_uv).max() <= max_uv
    for block, sign in ((0, 1), (1, -1), (2, 1), (4, -1)):
        assert stream.envelope_uv[block * 64 + 32:block * 64 + 64] == pytest.approx(sign * max_uv, abs=1)
    expected = limited_uv([request_uv(sample, info) for sample in samples], info, RATE_HZ)
    np.testing.assert_allclose(stream.envelope_uv, expected, atol=step_uv(info))


def test_a2_slew_limits_every_step(exact_target: VirtualTarget) -> None:
    """A2: the applied envelope moves by at most slew_mv_per_ms / envelope_hz * 1000 mV per sample (at 8 kHz:
    two 16 kHz steps), on steps, swings and underruns alike, and reaches the asked level at that pace."""
    amp = exact_target
    host = Host(amp)
    info = start_stream(host, prefill=64, rate_hz=8000)
    samples = [0] * 8 + [32767] * 40 + [-32767] * 40 + [5000] * 40 + [-5000] * 2 + [0] * 30
    send_samples(host, 0, samples)
    host.wait_us((len(samples) + 40) * 1_000_000 // 8000)  # and 40 underruns after them
    applied = amp.applied()
    slew_uv = info.slew_mv_per_ms * 1e6 / 8000
    assert np.abs(np.diff(np.concatenate([[0.0], applied.envelope_uv]))).max() <= slew_uv + 1
    stream = from_stream(applied)
    expected = limited_uv([request_uv(sample, info) for sample in samples], info, 8000)
    np.testing.assert_allclose(stream.envelope_uv, expected, atol=step_uv(info))
    assert amp.counters()["underruns"] >= 40


def test_a3_samples_play_at_their_index_once(exact_target: VirtualTarget) -> None:
    """A3: samples play at their index whatever the frames' order; a repeated index is replaced; a missing index
    plays 0 (through A2) and counts one underrun per sample; a bad frame's samples are never applied."""
    amp = exact_target
    host = Host(amp)
    info = start_stream(host, start_index=1000, prefill=16)
    levels = {"a": 1000, "b": 2000, "c": 3000, "d": 4000, "e": 1500, "bad": 9000}
    host.send(Type.ENVELOPE, envelope(1008, [levels["b"]] * 8))
    host.send(Type.ENVELOPE, envelope(1000, [levels["a"]] * 8))  # now 16 buffered: RUNNING
    host.send(Type.ENVELOPE, envelope(1016, [levels["c"]] * 8))
    host.send(Type.ENVELOPE, envelope(1016, [levels["d"]] * 8))  # replaces c
    host.write(bad_crc(Type.ENVELOPE, host.seq, envelope(1024, [levels["bad"]] * 8)))  # 1024-1031 missing
    host.send(Type.ENVELOPE, envelope(1032, [levels["e"]] * 8))
    host.wait_us(40 * 1_000_000 // RATE_HZ + 100)
    applied = amp.applied()
    running = applied.where(applied.state == State.RUNNING)
    order = [levels["a"]] * 8 + [levels["b"]] * 8 + [levels["d"]] * 8 + [0] * 8 + [levels["e"]] * 8
    assert list(running.index[:40]) == [*range(1000, 1024), *[-1] * 8, *range(1032, 1040)]
    expected = limited_uv([request_uv(sample, info) for sample in order], info, RATE_HZ)
    np.testing.assert_allclose(running.envelope_uv[:40], expected, atol=step_uv(info))
    assert amp.counters()["underruns"] == np.count_nonzero(running.index == -1) >= 8
    assert amp.counters()["frames_bad"] == 1


def test_a4_watchdog_zeroes_the_output_within_watchdog_ms(exact_target: VirtualTarget) -> None:
    """A4: with no valid frame for watchdog_ms - R (R <= 10 ms) the amplifier counts a trip, ramps to 0 and goes
    IDLE: output 0 within watchdog_ms of the last valid frame; bad frames do not hold it off, rejected valid ones
    do; frames every 30 ms never trip it; START is needed again."""
    amp = exact_target
    host = Host(amp)
    info = start_stream(host, prefill=16)
    index = send_samples(host, 0, [20000] * 640)  # 40 ms ahead: still playing when the watchdog trips
    for _ in range(40):  # 20 ms at 0.5 ms frames
        host.wait_us(500)
        index = send_samples(host, index, [20000] * 8)
    last_valid_us = amp.now_us
    host.wait_us(20_000)
    host.write(bad_crc(Type.KEEPALIVE, host.seq))  # not a valid frame: the watchdog runs on
    host.wait_us(info.watchdog_ms * 1000 - 20_000)
    zero_by_us = last_valid_us + info.watchdog_ms * 1000
    counters = amp.counters()
    assert (counters["watchdog_trips"], counters["state"], counters["envelope_uv"]) == (1, State.IDLE, 0)
    (trip_us,) = amp.trips_us()
    assert last_valid_us + (info.watchdog_ms - 10) * 1000 - 2000 <= trip_us <= zero_by_us  # R <= 10, 2 ms early
    after = played(amp.applied(), zero_by_us)
    assert np.all(after.envelope_uv == 0)
    ramp = played(amp.applied(), trip_us)
    assert abs(ramp.envelope_uv[0]) > request_uv(19000, info)  # it ramps from the level played
    assert np.all(np.diff(np.abs(ramp.envelope_uv)) <= 0) and set(ramp.index) == {-1}
    assert ramp.t_us[np.flatnonzero(ramp.envelope_uv)[-1]] < trip_us + 10_000  # over R <= 10 ms
    since = host.mark()
    host.send(Type.ENVELOPE, envelope(index, [20000] * 8))  # NOT_STARTED now
    assert host.status().frames_rejected == 1 and host.acks_since(since) == []
    # Valid frames, even refused, hold it off: PRIMING for 150 ms with a refused frame every 30 ms.
    assert host.command(Type.START, wire.Start(RATE_HZ, 0, 16).pack()).code == Code.OK
    for _ in range(5):
        host.wait_us(30_000)
        host.send(0x42)
    assert amp.counters()["watchdog_trips"] == 1 and amp.counters()["state"] == State.PRIMING
    host.wait_us(info.watchdog_ms * 1000)
    assert amp.counters()["watchdog_trips"] == 2 and amp.counters()["state"] == State.IDLE


@pytest.mark.parametrize("target", [name for name in TARGETS if name != "qemu"], indirect=True)
def test_a6_fault_ramps_within_1_ms_and_holds_until_hello(target: Target) -> None:
    """A6: a fault ramps the output to 0 within 1 ms, sets its bit, sends STATUS at once (for a new bit), goes to
    FAULT and refuses START with FAULT (first of START's checks) until HELLO; envelope frames are refused.
    The host build checks the refusals with an overcurrent at its start (``--fault overcurrent:0``); the
    microbit build injects no faults."""
    if isinstance(target, LineTarget):
        faulty = start_line("host", "--fault", "overcurrent:0")
        try:
            refuses_start_until_hello(faulty)
        finally:
            faulty.close()
        assert faulty.final_counters["faults"] == 0  # cleared by HELLO
        return
    assert isinstance(target, VirtualTarget)
    amp = target
    host = Host(amp)
    start_stream(host, prefill=64)
    index = send_samples(host, 0, [32767] * 320)
    host.wait_us(10_000)
    since, fault_us = host.mark(), amp.now_us
    amp.fault(Fault.OVERCURRENT)
    host.mark()
    (sent,) = [item for item in host.frames[since:] if item.frame.type == Type.STATUS]
    status = wire.Status.unpack(sent.frame.payload)
    assert (sent.t_us, status.faults, status.state) == (fault_us, Fault.OVERCURRENT, State.FAULT)
    host.wait_us(5_000)
    after = played(amp.applied(), fault_us + 1000)
    assert len(after.t_us) > 0 and np.all(after.envelope_uv == 0) and set(after.state) == {State.FAULT}
    since = host.mark()
    amp.fault(Fault.OVERCURRENT)  # latched: no new STATUS at once
    assert host.frames_since(since, Type.STATUS) == []
    amp.fault(Fault.SUPPLY)  # a new bit: STATUS at once, both bits
    (new,) = host.frames_since(since, Type.STATUS)
    assert wire.Status.unpack(new.payload).faults == Fault.OVERCURRENT | Fault.SUPPLY
    for start in (wire.Start(RATE_HZ, 0, 16), wire.Start(12345, 0, 0)):
        assert host.command(Type.START, start.pack()).code == Code.FAULT
    since = host.mark()
    host.send(Type.ENVELOPE, envelope(index, [100] * 8))
    status = host.status()
    assert (status.state, status.faults, status.frames_rejected, host.acks_since(since)) == (
        State.FAULT, Fault.OVERCURRENT | Fault.SUPPLY, 3, [])
    host.hello()
    assert wait_for_state(host, State.IDLE).faults == 0  # after HELLO's ramp
    start_stream(host)


def refuses_start_until_hello(line: LineTarget) -> None:
    """A6 on a pty, from an overcurrent at 0 s, before any HELLO: START refused FAULT whatever else it holds (and
    no carrier is set), until HELLO clears it. The answer to a first frame comes from a pass of the board's loop
    that took its faults due by then (amp_run_once: read, receive, faults, ..., transmit): the fault is in."""
    host = Host(line)
    assert host.command(Type.KEEPALIVE, version=wire.VERSION + 1).code == Code.BAD_VERSION
    for start in (wire.Start(RATE_HZ, 0, 16), wire.Start(12345, 0, 0)):
        assert host.command(Type.START, start.pack()).code == Code.FAULT
    host.hello()
    assert wait_for_state(host, State.IDLE).faults == 0
    start_stream(host)
    assert host.command(Type.STOP, wire.Stop(5).pack()).code == Code.OK


def test_a7_power_up_is_idle_at_zero_with_no_carrier(fresh_target: Target) -> None:
    """A7: at power-up the output is 0, the state IDLE and no carrier is set (START before any HELLO: NO_CARRIER,
    the first frame the amplifier sends); STATUS then says so."""
    host = Host(fresh_target)
    if isinstance(fresh_target, VirtualTarget):
        fresh_target.advance_to(20_000)
        assert fresh_target.counters() == {
            "frames_ok": 0, "frames_bad": 0, "frames_rejected": 0, "sequence_gaps": 0, "underruns": 0,
            "watchdog_trips": 0, "faults": 0, "state": State.IDLE, "envelope_uv": 0, "carrier_mhz": 0,
            "play_index": 0}
        assert len(fresh_target.applied().t_us) == 0 and host.mark() == 0  # nothing sent before HELLO
    ack = host.command(Type.START, wire.Start(RATE_HZ, 0, 16).pack())
    assert ack.code == Code.NO_CARRIER and host.frames[0].frame.type == Type.ACK
    host.hello()
    status = host.status()
    assert (status.state, status.envelope_mv, status.carrier_mhz, status.faults) == (State.IDLE, 0, 0, 0)


def test_a8_status_goes_out_every_period(target: Target) -> None:
    """A8: STATUS every status_period_ms from HELLO on, whatever the host does. In process: its time_us at HELLO +
    k * period exactly. On a pty: time_us steps by whole periods from the INFO on (what came before it may be
    the last session's, on its own schedule)."""
    host = Host(target)
    if isinstance(target, VirtualTarget):
        target.advance_to(1_234)
    since = host.mark()
    info = host.hello()
    period_us = info.status_period_ms * 1000
    if isinstance(target, VirtualTarget):
        hello_us = target.now_us
        host.wait_us(3_217)
        host.write(b"\x13" * 100 + b"\x00")  # whatever the host does
        host.send(Type.SET_CARRIER, wire.SetCarrier(CARRIER_MHZ).pack())
        host.wait_us(100_000 - 3_217)
        statuses = [wire.Status.unpack(frame.payload) for frame in host.frames_since(since, Type.STATUS)]
        assert [status.time_us for status in statuses] == [hello_us + k * period_us for k in range(1, 21)]
        return
    since = next(index for index in range(since, len(host.frames)) if host.frames[index].frame.type == Type.INFO)
    times: list[int] = []
    while len(times) < 6:
        found = host.wait_for(lambda frame: frame.type == Type.STATUS, "STATUS", since)
        since = host.frames.index(found) + 1
        times.append(wire.Status.unpack(found.frame.payload).time_us)
    steps = [(later - earlier) % (1 << 32) for earlier, later in zip(times, times[1:])]  # time_us wraps
    assert all(step > 0 and step % period_us == 0 for step in steps), steps


# --- a stream, end to end -----------------------------------------------------------------------------------------

LINE_PARAMS = [pytest.param(name, marks=pytest.mark.realtime) if name in LINES else name for name in TARGETS]


@pytest.mark.parametrize("target", LINE_PARAMS, indirect=True)
def test_a_stream_plays_on_the_amplifiers_clock(target: Target) -> None:
    """A stream judged on answers and STATUS, with nothing timed by the host: HELLO, SET_CARRIER, START with a
    whole buffer of prefill, that buffer of full scale at once (A1: every STATUS at most max_mv, and some at it),
    a sequence gap and an OUT_OF_WINDOW frame (counted, not answered), then silence: the watchdog trips before the
    buffer runs out (A4: one trip, no underrun, IDLE); ENVELOPE refused after it; STOP and START answered.

    Realtime on a pty: an amplifier process stalled for 100 ms skips the STATUS it owes (A8's rule for a late one),
    which may be every one of the 40 ms at max_mv."""
    host = Host(target)
    info = host.hello()
    assert host.command(Type.SET_CARRIER, wire.SetCarrier(CARRIER_MHZ).pack()).code == Code.OK
    assert host.command(Type.START, wire.Start(RATE_HZ, 0, info.buffer_samples).pack()).code == Code.OK
    broken = target.broken
    since = host.mark()
    index = send_samples(host, 0, [32767] * info.buffer_samples, min(64, info.max_frame_samples))
    host.seq += 1  # a gap
    oow = host.send(Type.ENVELOPE, envelope(index + 4 * info.buffer_samples, [1] * 8))
    tripped = wait_for_state(host, State.IDLE, advance_us=200_000)
    seen = [wire.Status.unpack(frame.payload) for frame in host.frames_since(since, Type.STATUS)]
    assert all(abs(item.envelope_mv) <= info.max_mv for item in seen)
    assert any(item.envelope_mv == info.max_mv for item in seen)
    assert (tripped.watchdog_trips, tripped.underruns, tripped.envelope_mv) == (1, 0, 0)
    assert (tripped.sequence_gaps, tripped.frames_rejected, tripped.frames_bad) == (1, 1, 0)
    late = host.send(Type.ENVELOPE, envelope(index, [1000] * 8))
    status = host.status()
    assert (status.frames_rejected, status.watchdog_trips, hung_acks(host, since, {oow, late})) == (2, 1, [])
    assert host.command(Type.STOP, wire.Stop(5).pack()).code == Code.OK
    assert host.command(Type.START, wire.Start(RATE_HZ, 0, 16).pack()).code == Code.OK
    assert host.command(Type.STOP, wire.Stop(5).pack()).code == Code.OK
    assert wait_for_state(host, State.IDLE).watchdog_trips == 1
    assert target.broken == broken  # every frame whole while the host reads


def wait_for_state(host: Host, state: int, advance_us: int = 100_000) -> wire.Status:
    """The first STATUS from now on in ``state`` (a virtual target moves on up to ``advance_us`` for it)."""
    since = host.mark()
    found = host.wait_for(lambda frame: frame.type == Type.STATUS and wire.Status.unpack(frame.payload).state == state,
                          f"STATUS in state {state}", since, advance_us=advance_us)
    return wire.Status.unpack(found.frame.payload)


# --- the emulator and the core, side by side ----------------------------------------------------------------------

#: The largest difference (in steps of the envelope's integer encoding, full_scale_mv / 32767) the emulator's and
#: the core's applied envelopes may show at any sample.
ENVELOPE_TOLERANCE_STEPS = 1.0
#: The largest difference (in steps of 1/32767 of full_scale_mv, the core's output LSB) between the core's carrier
#: samples and the emulator's (Plate.drive's phase accumulator, carrier_phase_cycles, on the same samples): the
#: core's sine is within 2 LSB of double precision, its envelope within one step.
CARRIER_TOLERANCE_LSB = 3.0
#: STATUS fields the two need not share: the measurements (the emulator computes them from its circuit; the core
#: demodulates ADC samples, none here).
MEASURED = {"voltage_mv_rms", "current_ua_rms", "phase_cdeg"}


def equivalence_stream() -> tuple[list[tuple[int, bytes]], int]:
    """A session as tpad-rt runs it, as (time in us from power-up, bytes) and its end: HELLO, SET_CARRIER, START,
    250 ms of envelope in 0.5 ms frames 20 ms ahead (a ramp up, full scale held past the clamp, a ramp into
    anti-phase, 5 ms never sent, a modulated level), a sequence gap, SET_CARRIER while RUNNING, STOP; then START
    again with 40 ms of envelope and silence: a watchdog trip."""
    frames: list[tuple[int, int, bytes]] = []  # (t_us, type, payload)

    def stream(start_us: int, first: int, samples: np.ndarray, lead: int, skip: range = range(0)) -> None:
        for offset in range(0, len(samples), 8):
            if offset not in skip:
                frames.append((start_us + 20 + max(0, offset - lead) * 1_000_000 // RATE_HZ, Type.ENVELOPE,
                               envelope(first + offset, samples[offset:offset + 8])))

    n = np.arange(4000)
    first = np.select([n < 1600, n < 2080, n < 2880],
                      [n / 1600 * 30000, np.full(4000, 32767), 32767 - (n - 2080) / 800 * 52767],
                      10000 + 8000 * np.sin(2 * np.pi * 200 * n / RATE_HZ)).astype(np.int16)
    frames += [(1_000, Type.HELLO, wire.Hello("equivalence", 7).pack()),
               (1_500, Type.SET_CARRIER, wire.SetCarrier(CARRIER_MHZ).pack()),
               (2_000, Type.START, wire.Start(RATE_HZ, 0, 32).pack())]
    stream(2_000, 0, first, 320, skip=range(2880, 2960))
    gap_us = 222_037  # this frame's seq skips one
    frames += [(gap_us, Type.SET_CARRIER, wire.SetCarrier(31_500_005).pack()),
               (245_037, Type.STOP, wire.Stop(5).pack()),
               (400_000, Type.START, wire.Start(RATE_HZ, 1_000_000, 16).pack())]
    stream(400_000, 1_000_000, np.full(640, 15000, np.int16), 160)
    frames.sort(key=lambda frame: frame[0])
    events, seq = [], 0
    for t_us, type_, payload in frames:
        seq = 0 if type_ == Type.HELLO else seq + (t_us == gap_us)
        events.append((t_us, wire.encode(type_, seq, payload)))
        seq += 1
    return events, 560_000


def run_side_by_side() -> dict[str, float]:
    """The emulator and the core on equivalence_stream(); what they did, compared (AssertionError where they
    differ beyond the tolerances); the figures: largest envelope difference (steps), largest carrier difference
    (LSB), samples and carrier samples compared."""
    emulator, core = EmulatorTarget(), CoreTarget(core_library())
    events, end_us = equivalence_stream()
    for target in (emulator, core):
        for t_us, data in events:
            target.advance_to(t_us)
            target.write(data)
        target.advance_to(end_us)
    assert emulator.counters() == core.counters()
    assert core.counters()["watchdog_trips"] == 1 and core.counters()["underruns"] >= 80
    assert core.counters()["sequence_gaps"] == 1
    np.testing.assert_allclose(core.trips_us(), emulator.trips_us(), atol=1e-3)
    sent = [[item.frame for item in target.take()] for target in (emulator, core)]
    assert [(frame.type, frame.seq) for frame in sent[0]] == [(frame.type, frame.seq) for frame in sent[1]]
    info = expected_info()
    for ours, theirs in zip(*sent):
        if ours.type == Type.STATUS:
            mine, other = (vars(wire.Status.unpack(frame.payload)) for frame in (ours, theirs))
            assert abs(mine.pop("envelope_mv") - other.pop("envelope_mv")) <= info.full_scale_mv / 32767
            assert {key: mine[key] for key in mine.keys() - MEASURED} == {key: other[key] for key in
                                                                          other.keys() - MEASURED}
        elif ours.type == Type.INFO:
            assert replace(wire.Info.unpack(ours.payload), firmware="", serial="") == replace(
                wire.Info.unpack(theirs.payload), firmware="", serial="")
        else:
            assert ours.payload == theirs.payload
    # Samples, matched by due time: the emulator's sample clock also runs while its plate rings after the output
    # came to rest (zeros the core, whose clock stops at rest, does not make).
    emulated, made = emulator.applied(), core.applied()
    matched = np.isin(np.round(emulated.t_us, 3), np.round(made.t_us, 3))
    assert matched.sum() == len(made.t_us) > 5000
    extra = emulated.where(~matched)
    assert np.all(extra.envelope_uv == 0) and set(extra.state) <= {State.IDLE}
    emulated = emulated.where(matched)
    for name in ("carrier_mhz", "index", "state"):
        np.testing.assert_array_equal(getattr(emulated, name), getattr(made, name), err_msg=name)
    envelope_steps = np.abs(emulated.envelope_uv - made.envelope_uv) / step_uv(info)
    assert envelope_steps.max() <= ENVELOPE_TOLERANCE_STEPS
    # The carrier: Plate.drive's, on the samples both made (its phase runs on only while the core's does too).
    per_sample = core.output_rate_hz // RATE_HZ
    phase, _ = carrier_phase_cycles(emulated.carrier_mhz / 1000, per_sample, core.output_rate_hz, 0.0)
    reference_mv = np.repeat(emulated.envelope_uv / 1000, per_sample) * np.sin(2 * np.pi * phase)
    made_mv = core.carrier_mv()
    assert len(made_mv) == len(reference_mv)
    carrier_lsb = np.abs(made_mv - reference_mv) / (info.full_scale_mv / 32767)
    assert carrier_lsb.max() <= CARRIER_TOLERANCE_LSB
    return {"envelope_steps": float(envelope_steps.max()), "carrier_lsb": float(carrier_lsb.max()),
            "samples": float(len(made.t_us)), "carrier_samples": float(len(made_mv))}


def test_emulator_and_core_apply_the_same_envelope_and_carrier() -> None:
    """Driven in process on the same frames at the same virtual times, the emulator and the firmware core send
    the same frames (STATUS's measurements aside), count the same, trip at the same time, apply the same envelope
    within ENVELOPE_TOLERANCE_STEPS of its integer encoding at every sample, and make the same carrier samples
    within CARRIER_TOLERANCE_LSB."""
    figures = run_side_by_side()
    assert figures["samples"] > 5000
