"""A lying amplifier on the virtual link: the host must keep the envelope within min(the device's max_voltage_v, the
amplifier's clamp) whatever order, timing, duplication or contradiction its answers come in, and refuse reports out
of range in one line naming the amplifier (docs/amp-protocol.md H1-H3, H7, H8, H10; issue 20).

The amplifier is :class:`ScriptedAmp`, at the other end of a
:class:`tpad_rt.amp.virtual_link.VirtualLink` on a virtual clock, which answers each
frame the host sends as its :class:`Script` says, when the frame arrives: a late answer
to a HELLO is sent when the next HELLO arrives, an INFO "after the carrier" right after
SET_CARRIER's ACK, a lying STATUS after the N-th ENVELOPE frame. Between those it sends
honest STATUS frames every 5 ms of its clock (H7's silence would otherwise end the run),
each consistent with its own clock whenever it is sent. Every frame the host sent is
decoded with the emulator's codec (:mod:`tpad_rt.amp.wire`, not the host's) and judged:
each ENVELOPE sample, read with the full scale of every INFO that answered the host's
last HELLO, stays within min(max_voltage_v, that INFO's max_mv); a run that sent START
ends with STOP; an error is one line naming the port. Deterministic: no thread, no
sleep (a HELLO's wait for INFO, H1, passes on the virtual clock).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from virtual_serial import DEVICE, VirtualRun

from tpad_rt.amp import wire
from tpad_rt.amp.virtual_link import VirtualLink
from tpad_rt.clock import VirtualClock
from tpad_rt.errors import TpadError
from tpad_rt.outputs import serial_amp

CARRIER_MHZ = round(DEVICE.carrier_hz * 1000)
U32 = 0xFFFFFFFF
#: The port the host sees (its errors name it).
PORT = "liar"
#: How often (ms) the scripted amplifier sends STATUS, and the period its INFO declares (H7 ends a run after 4
#: periods and 100 ms without one); its INFO's other fields are the emulator's, without measurements.
STATUS_EVERY_MS = 5
STATUS_PERIOD_MS = 100
HONEST = wire.Info(firmware="liar 1.0", serial="L-1", envelope_rates_hz=(8000, 16000, 0, 0),
                   carrier_min_mhz=10_000_000, carrier_max_mhz=80_000_000, carrier_step_mhz=10,
                   full_scale_mv=50_000, max_mv=40_000, slew_mv_per_ms=100_000, buffer_samples=1024,
                   max_frame_samples=256, watchdog_ms=50, status_period_ms=STATUS_PERIOD_MS, measures=0,
                   max_current_ma=0)


def info(full_scale_mv: int, max_mv: int) -> wire.Info:
    """HONEST with another full scale and clamp (mV), the slew limit at least the clamp (A2)."""
    return replace(HONEST, full_scale_mv=full_scale_mv, max_mv=max_mv, slew_mv_per_ms=max(100_000, max_mv))


@dataclass(frozen=True)
class Answer:
    """One INFO sent for a HELLO: ``nonce`` "echo" (the HELLO's), "zero", "earlier" (the HELLO before's) or an
    int; ``when`` "now", "next_hello" (late: when the next HELLO arrives) or "after_carrier" (right after
    SET_CARRIER's ACK)."""

    info: wire.Info
    nonce: str | int = "echo"
    when: str = "now"


@dataclass
class Script:
    """What the scripted amplifier answers: INFOs per HELLO (by the HELLO's number), SET_CARRIER's achieved
    carrier (None: the nearest it makes), START's ACK value, STATUS payload fields that replace the honest ones
    after the N-th ENVELOPE frame (``play_index`` as an int, or "jump" / "back" relative to the honest index,
    "stuck" at the last STATUS's), an INFO sent after the N-th ENVELOPE frame."""

    answers: dict[int, list[Answer]]
    carrier_mhz: int | None = None
    lies: dict[int, dict[str, int | str]] = field(default_factory=dict)
    info_at: dict[int, Answer] = field(default_factory=dict)
    start_ack: int | None = None  # START's ACK value (None: the index it named)


class ScriptedAmp:
    """A test amplifier for the virtual link (the emulator's discrete-event interface: ``receive``, ``advance``,
    ``next_status_s``, ``out``), its clock in s from 0."""

    def __init__(self, script: Script):
        self.script = script
        self.port = PORT
        self.out = bytearray()
        self.now_s = 0.0
        self.on_hello = None
        self.recorder = None
        self.frames: list[wire.Frame] = []  # every valid frame the host sent, in order
        self.infos: list[tuple[int, wire.Info, int]] = []  # (nonce field, INFO, host frames before) of each INFO sent
        self.hello_nonces: list[int] = []
        self._held: list[tuple[str, int, Answer]] = []  # (when, HELLO number, answer) not sent yet
        self._seq = 0
        self._splitter = wire.FrameSplitter()
        self._next_status_s = math.inf  # from the first HELLO on, every STATUS_EVERY_MS
        self._carrier_mhz = 0
        self._start: tuple[float, int, int] | None = None  # (time, start index, rate) of the stream
        self._envelopes = 0
        self._last_play = 0  # the play index of the last STATUS sent

    # --- the discrete-event interface ---

    @property
    def next_status_s(self) -> float:
        return self._next_status_s

    def advance(self, t_s: float) -> None:
        while self._next_status_s <= t_s:
            self._send(wire.Type.STATUS, self._status({}, self._next_status_s))
            self._next_status_s += STATUS_EVERY_MS / 1000
        self.now_s = max(self.now_s, t_s)

    def receive(self, encoded: bytes | None, t_s: float) -> None:
        self.advance(t_s)
        frame = None if encoded is None else wire.decode(encoded)
        if frame is not None and frame.version == wire.VERSION:
            self.frames.append(frame)
            self._act(frame, t_s)

    def _send(self, type_: int, payload: bytes) -> None:
        self.out += wire.encode(type_, self._seq, payload)
        self._seq = (self._seq + 1) & 0xFFFF

    # --- answers ---

    def _info(self, number: int, answer: Answer) -> None:
        nonces = self.hello_nonces
        nonce = {"echo": nonces[number], "zero": 0,
                 "earlier": nonces[number - 1] if number else nonces[number] ^ 1}.get(answer.nonce, answer.nonce)
        assert isinstance(nonce, int)
        self.infos.append((nonce, answer.info, len(self.frames)))
        self._send(wire.Type.INFO, replace(answer.info, hello_nonce=nonce).pack())

    def _release(self, when: str) -> None:
        for held in [held for held in self._held if held[0] == when]:
            self._held.remove(held)
            self._info(held[1], held[2])

    def _ack(self, frame: wire.Frame, value: int, code: int = wire.Code.OK) -> None:
        self._send(wire.Type.ACK, wire.Ack(frame.seq, frame.type, code, value & U32).pack())

    def _act(self, frame: wire.Frame, t_s: float) -> None:
        if frame.type == wire.Type.HELLO:
            number = len(self.hello_nonces)
            self.hello_nonces.append(wire.Hello.unpack(frame.payload).nonce)
            self._seq = 0
            self._start = None
            if math.isinf(self._next_status_s):
                self._next_status_s = t_s + STATUS_EVERY_MS / 1000
            self._release("next_hello")  # late answers to the HELLO before
            for answer in self.script.answers.get(number, []):
                if answer.when == "now":
                    self._info(number, answer)
                else:
                    self._held.append((answer.when, number, answer))
        elif frame.type == wire.Type.SET_CARRIER:
            asked = wire.SetCarrier.unpack(frame.payload).carrier_mhz
            achieved = self.script.carrier_mhz
            self._carrier_mhz = (asked + 5) // 10 * 10 if achieved is None else achieved
            self._ack(frame, self._carrier_mhz)
            self._release("after_carrier")
        elif frame.type == wire.Type.START:
            start = wire.Start.unpack(frame.payload)
            self._start = (t_s, start.start_index, start.envelope_hz)
            self._ack(frame, start.start_index if self.script.start_ack is None else self.script.start_ack)
        elif frame.type == wire.Type.ENVELOPE:
            self._envelopes += 1
            if self._envelopes in self.script.lies:
                self._send(wire.Type.STATUS, self._status(self.script.lies[self._envelopes], t_s))
            if self._envelopes in self.script.info_at:
                self._info(len(self.hello_nonces) - 1, self.script.info_at[self._envelopes])
        elif frame.type == wire.Type.STOP:
            self._ack(frame, 0)
            self._start = None

    def _status(self, lie: dict[str, int | str], now: float) -> bytes:
        """A STATUS payload at ``now`` (s): honest (RUNNING at the envelope rate since START), with the fields of
        ``lie`` instead."""
        fields: dict[str, int] = dict(
            time_us=round(now * 1e6) & U32, play_index=0, buffer_fill=0, state=wire.State.IDLE,
            faults=0, frames_ok=len(self.frames), frames_bad=0, frames_rejected=0, sequence_gaps=0, underruns=0,
            watchdog_trips=0, last_seq=self.frames[-1].seq if self.frames else 0, phase_cdeg=0, envelope_mv=0,
            voltage_mv_rms=0, current_ua_rms=0, carrier_mhz=self._carrier_mhz)
        if self._start is not None:
            started, index, rate = self._start
            fields.update(state=wire.State.RUNNING, play_index=(index + int((now - started) * rate)) & U32)
        honest = fields["play_index"]
        for name, value in lie.items():
            if value == "jump":
                value = honest + 2**31
            elif value == "back":
                value = honest - 200
            elif value == "stuck":
                value = self._last_play  # the last STATUS's, its clock moving on
            assert isinstance(value, int)
            fields[name] = value
        fields["play_index"] &= U32
        self._last_play = fields["play_index"]
        return wire.Status(**fields).pack()


def line_to(amp: ScriptedAmp) -> VirtualLink:
    """A virtual link to ``amp`` on a new clock, named PORT."""
    return VirtualLink(VirtualClock(), amp, name=PORT)


@dataclass
class Outcome:
    """A run against a scripted amplifier: the error it ended with (None: it played), the frames the host sent."""

    error: str | None
    frames: list[wire.Frame]
    amp: ScriptedAmp

    def envelope(self) -> np.ndarray:
        """Every envelope sample the host sent (int16 values)."""
        samples = [wire.Envelope.unpack(frame.payload).samples for frame in self.frames
                   if frame.type == wire.Type.ENVELOPE]
        return np.concatenate(samples) if samples else np.zeros(0, np.int16)

    def types(self) -> list[int]:
        """The type of every frame the host sent, in order."""
        return [frame.type for frame in self.frames]

    def names_the_amplifier(self) -> bool:
        """Whether the error is one line naming the amplifier's port."""
        return self.error is not None and "\n" not in self.error and f"on {self.amp.port}" in self.error


def run(script: Script, seconds: float = 0.3) -> Outcome:
    """The serial driver on the scripted amplifier, swiping for ``seconds`` of the clock (or until it fails), then
    stopped as the Renderer stops it."""
    amp = ScriptedAmp(script)
    error = None
    try:
        streaming = VirtualRun(line_to(amp)).start()
        streaming.swipe(seconds)
        failure = streaming.stop()
        error = None if failure is None else str(failure)
    except TpadError as failure:
        error = str(failure)
    return Outcome(error, amp.frames, amp)


def assert_within_limits(outcome: Outcome) -> None:
    """The property of issue 20: every sample sent, read with each INFO that answered the host's last HELLO (its
    nonce) before the stream began, is within min(max_voltage_v, that INFO's clamp); a run that sent START ended
    with STOP after its last frame; a failure is one line naming the amplifier's port.

    (An INFO sent once the stream runs cannot be read back into the frames sent before the host saw it: the host
    ends the run for it, which its own test checks.)"""
    samples = np.abs(outcome.envelope().astype(np.int64))
    amp, types = outcome.amp, outcome.types()
    began = types.index(wire.Type.START) if wire.Type.START in types else len(types)
    answers = [sent for nonce, sent, at in amp.infos if nonce == amp.hello_nonces[-1] and at <= began]
    if samples.size:
        assert answers, "the host streamed without an INFO answering its HELLO"
    for answer in answers:
        limit_mv = min(DEVICE.max_voltage_v * 1000, answer.max_mv)
        peak_mv = samples.max(initial=0) / 32767 * answer.full_scale_mv
        assert peak_mv <= limit_mv * (1 + 1e-12), f"{peak_mv:.0f} mV sent, limit {limit_mv:.0f} mV ({answer})"
    if wire.Type.START in types:
        last = max(at for at, kind in enumerate(types) if kind in (wire.Type.START, wire.Type.ENVELOPE))
        assert wire.Type.STOP in types[last:], "H8: no STOP after the run's last frame"
    if outcome.error is not None:
        assert outcome.names_the_amplifier(), outcome.error


# --- the handshake ---------------------------------------------------------------------------------------------

def test_a_late_answer_to_a_first_hello_does_not_set_the_envelope_scale() -> None:
    """Issue 20: the first HELLO answered late (when the second arrives) with a 40 V full scale, the second with a
    400 V full scale and clamp: the amplifier runs by the second, so samples must be scaled for 400 V. Taking the
    first INFO to arrive sent 10 times the volts asked (400 V for a 40 V device)."""
    outcome = run(Script({0: [Answer(info(40_000, 40_000), when="next_hello")],
                          1: [Answer(info(400_000, 400_000))]}))
    assert outcome.error is None, outcome.error
    assert [nonce for nonce, _, _ in outcome.amp.infos] == outcome.amp.hello_nonces[:2]
    samples = outcome.envelope()
    assert samples.size and np.abs(samples).max() / 32767 * 400 > 10, "the swipe must drive the plate"
    assert_within_limits(outcome)


@pytest.mark.parametrize("answers", [
    [Answer(info(50_000, 40_000)), Answer(info(400_000, 400_000))],
    [Answer(info(50_000, 40_000)), Answer(info(50_000, 30_000), when="after_carrier")],
    [Answer(info(50_000, 40_000)), Answer(replace(HONEST, serial="L-2"), when="after_carrier")],
], ids=["twice at once", "a clamp after the carrier", "another serial number"])
def test_two_different_answers_to_one_hello_refuse_the_amplifier(answers: list[Answer]) -> None:
    outcome = run(Script({0: answers}))
    assert outcome.error is not None and "contradicts itself: two INFOs answer one HELLO" in outcome.error
    assert wire.Type.ENVELOPE not in outcome.types()
    assert_within_limits(outcome)


def test_a_repeated_answer_and_answers_to_other_hellos_are_passed_over() -> None:
    """The same INFO twice, and INFOs carrying another HELLO's nonce, a zero (a version-1 amplifier's reserved
    field) or a made-up one, with other scales, around the one answer: the host plays by that answer."""
    lies = [Answer(info(1_000, 1_000), nonce) for nonce in ("earlier", "zero", 0x12345678)]
    outcome = run(Script({0: [lies[0], Answer(info(80_000, 60_000)), lies[1], Answer(info(80_000, 60_000)),
                              lies[2]]}))
    assert outcome.error is None, outcome.error
    assert np.abs(outcome.envelope()).max() / 32767 * 80 > 10  # read as 1 V full scale, this would be 80 times over
    assert_within_limits(outcome)


def test_an_amplifier_that_never_echoes_the_nonce_is_not_taken() -> None:
    outcome = run(Script({number: [Answer(HONEST, "zero")] for number in range(3)}))
    assert outcome.error is not None and f"no amplifier answered on {outcome.amp.port} (3 HELLOs" in outcome.error
    assert outcome.types() == [wire.Type.HELLO] * 3


def test_an_info_contradicting_the_handshake_during_the_stream_ends_the_run_with_stop() -> None:
    outcome = run(Script({0: [Answer(HONEST)]}, info_at={40: Answer(info(400_000, 400_000))}))
    assert outcome.error is not None and "contradicts itself: an INFO during the stream" in outcome.error, outcome.error
    assert "full_scale_v 50.0, then 400.0" in outcome.error
    assert outcome.types()[-1] == wire.Type.STOP
    assert_within_limits(outcome)


def test_a_stale_or_repeated_info_during_the_stream_is_passed_over() -> None:
    outcome = run(Script({0: [Answer(HONEST)]}, info_at={20: Answer(info(1_000, 1_000), "zero"), 40: Answer(HONEST)}))
    assert outcome.error is None, outcome.error
    assert_within_limits(outcome)


@settings(max_examples=300, deadline=None)
@given(st.integers(1, U32), st.integers(1, U32), st.floats(0.001, 10_000.0) | st.just(float("inf")))
def test_the_envelope_scale_never_lets_a_sample_past_the_cap(full_scale_mv: int, max_mv: int,
                                                            max_voltage_v: float) -> None:
    """envelope_scale, the one place the scale is decided (H3): the largest sample, read back with the full scale,
    is within the lower of the clamp and the device's cap, and one more would not be (unless it is 32767)."""
    max_mv = min(max_mv, full_scale_mv)
    scale = serial_amp.envelope_scale(full_scale_mv, max_mv, max_voltage_v)
    cap_mv = min(max_mv, max_voltage_v * 1000)
    assert scale.max_v * 1000 == pytest.approx(cap_mv) and scale.full_scale_v * 1000 == pytest.approx(full_scale_mv)
    assert 0 <= scale.level_limit <= 32767
    assert scale.level_limit * full_scale_mv / 32767 <= cap_mv * (1 + 1e-12)
    assert scale.level_limit == 32767 or (scale.level_limit + 1) * full_scale_mv / 32767 > cap_mv


# --- SET_CARRIER's echo ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("achieved_mhz", [
    0, 1, U32, 4_290_000_000, HONEST.carrier_min_mhz - 10, HONEST.carrier_max_mhz + 10,
    CARRIER_MHZ + round(CARRIER_MHZ * 1e-3) + 11, CARRIER_MHZ - round(CARRIER_MHZ * 1e-3) - 11,
])
def test_an_achieved_carrier_out_of_range_ends_in_one_line_naming_the_amplifier(achieved_mhz: int) -> None:
    outcome = run(Script({0: [Answer(HONEST)]}, carrier_mhz=achieved_mhz))
    assert outcome.error is not None and f"(value {achieved_mhz} mHz)" in outcome.error, outcome.error
    assert outcome.error.startswith(f"serial: the amplifier on {outcome.amp.port} answered SET_CARRIER")
    assert wire.Type.START not in outcome.types()
    assert_within_limits(outcome)


def test_a_start_acknowledged_for_another_index_ends_in_one_line_with_stop() -> None:
    outcome = run(Script({0: [Answer(HONEST)]}, start_ack=2**31))
    assert outcome.error is not None and f"on {outcome.amp.port} acknowledged START at index" in outcome.error
    assert "with index 2147483648" in outcome.error and wire.Type.ENVELOPE not in outcome.types()
    assert outcome.types()[-1] == wire.Type.STOP
    assert_within_limits(outcome)


@pytest.mark.parametrize("offset_mhz", [-round(CARRIER_MHZ * 1e-3), 10, round(CARRIER_MHZ * 1e-3)])
def test_an_achieved_carrier_near_the_one_asked_plays(offset_mhz: int) -> None:
    outcome = run(Script({0: [Answer(HONEST)]}, carrier_mhz=CARRIER_MHZ + offset_mhz))
    assert outcome.error is None, outcome.error
    assert wire.Type.ENVELOPE in outcome.types()
    assert_within_limits(outcome)


def test_a_zero_hz_echo_is_refused_for_what_it_is() -> None:
    """One line naming the amplifier and what it sent, not a drive setting's ``carrier_hz: must be > 0``."""
    outcome = run(Script({0: [Answer(HONEST)]}, carrier_mhz=0))
    assert outcome.error is not None and outcome.names_the_amplifier()
    assert outcome.error.startswith(f"serial: the amplifier on {PORT} answered SET_CARRIER")
    assert "achieved carrier of 0 Hz (value 0 mHz)" in outcome.error


# --- STATUS ----------------------------------------------------------------------------------------------------

@pytest.mark.parametrize(("lie", "expected"), [
    ({"play_index": "jump"}, "play_index"),
    ({"play_index": "back"}, "it ran backwards"),
    ({"play_index": 0x9E3779B9}, "play_index"),
    ({"play_index": "stuck", "time_us": 0}, "its clock ran backwards"),
    ({"play_index": "stuck"}, "samples played"),
    ({"state": 5}, "state 5"),
    ({"state": 255}, "state 255"),
    ({"buffer_fill": 1025}, "buffer_fill 1025"),
    ({"envelope_mv": 40_001}, "envelope_mv 40001"),
    ({"envelope_mv": -(2**31)}, "envelope_mv -2147483648"),
    ({"carrier_mhz": 1}, "carrier_mhz 1"),
    ({"phase_cdeg": -18001}, "phase_cdeg -18001"),
], ids=lambda value: str(value))
def test_a_status_out_of_range_ends_the_run_in_one_line_with_stop(lie: dict[str, int | str], expected: str) -> None:
    outcome = run(Script({0: [Answer(HONEST)]}, lies={30: lie}))
    assert outcome.error is not None, "the lie was taken"
    assert outcome.error.startswith(f"serial: the amplifier on {outcome.amp.port} sent a STATUS with ")
    assert expected in outcome.error and "t:" not in outcome.error, outcome.error
    assert outcome.types()[-1] == wire.Type.STOP
    assert_within_limits(outcome)


@pytest.mark.parametrize("lie", [{"play_index": "jump"}, {"play_index": "back"}, {"play_index": "stuck"},
                                 {"envelope_mv": 40_001}])
def test_a_tone_refuses_a_status_out_of_range_and_stops(lie: dict[str, int | str]) -> None:
    """``calibrate sweep``'s tone (a Python loop, not the streamer) checks STATUS the same way, STOP and all."""
    amp = ScriptedAmp(Script({0: [Answer(HONEST)]}, lies={12: lie}))
    link = serial_amp.AmpLink.open(serial_amp.parse_serial_url(f"serial://{amp.port}"), carrier_hz=DEVICE.carrier_hz,
                                   line=line_to(amp))
    try:
        with pytest.raises(TpadError) as failure:
            link.tone(1.0, 1.0)
    finally:
        link.stop(5.0)
    frames = amp.frames
    assert str(failure.value).startswith(f"serial: the amplifier on {amp.port} sent a STATUS with "), failure.value
    assert frames[-1].type == wire.Type.STOP


# --- any sequence ----------------------------------------------------------------------------------------------

MV = st.integers(0, U32)
PLAUSIBLE_MV = st.integers(1_000, 500_000)


U16 = st.integers(0, 0xFFFF)


@st.composite
def infos(draw: st.DrawFn) -> wire.Info:
    """An INFO's full scale and clamp: a plausible pair, or (one time in four) anything the fields hold, its other
    fields too."""
    if draw(st.integers(0, 3)) == 0:
        return replace(info(draw(MV), draw(MV)), **draw(st.fixed_dictionaries({}, optional={
            "envelope_rates_hz": st.tuples(MV, MV, MV, MV), "carrier_min_mhz": MV, "carrier_max_mhz": MV,
            "carrier_step_mhz": MV, "slew_mv_per_ms": MV, "buffer_samples": U16, "max_frame_samples": U16,
            "watchdog_ms": U16, "status_period_ms": U16, "measures": st.integers(0, 255), "max_current_ma": MV})))
    full_scale = draw(PLAUSIBLE_MV)
    return info(full_scale, draw(st.integers(1, full_scale)))


ANSWERS = st.builds(Answer, infos(), st.sampled_from(["echo", "echo", "zero", "earlier"]) | st.integers(0, U32),
                    st.sampled_from(["now", "now", "next_hello", "after_carrier"]))


@st.composite
def answer_lists(draw: st.DrawFn) -> dict[int, list[Answer]]:
    """INFOs for each of the three HELLOs: a few of any kind, around (mostly) one plausible echo sent at once."""
    answers = {}
    for number in range(3):
        sent = draw(st.lists(ANSWERS, max_size=2))
        if draw(st.integers(0, 3)):
            full_scale = draw(PLAUSIBLE_MV)
            sent.insert(draw(st.integers(0, len(sent))), Answer(info(full_scale, draw(st.integers(1, full_scale)))))
        answers[number] = sent
    return answers
#: STATUS fields a lie may replace, with any value their widths hold (play_index also relative to the honest one).
LIE_FIELDS: dict[str, st.SearchStrategy[int | str]] = {
    "play_index": st.sampled_from(["jump", "back", "stuck"]) | st.integers(0, U32),
    "time_us": st.integers(0, U32), "state": st.integers(0, 255), "buffer_fill": st.integers(0, 0xFFFF),
    "envelope_mv": st.integers(-(2**31), 2**31 - 1), "carrier_mhz": st.integers(0, U32),
    "phase_cdeg": st.integers(-(2**15), 2**15 - 1)}
#: A lying STATUS: one field (mostly), or several.
LIES = st.one_of(*(st.fixed_dictionaries({name: values}) for name, values in LIE_FIELDS.items()),
                 st.fixed_dictionaries({}, optional=LIE_FIELDS))


@settings(max_examples=30, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(answers=answer_lists(),
       carrier=st.integers(0, 3).flatmap(lambda lie: st.integers(0, U32) | st.sampled_from(
           [0, U32, CARRIER_MHZ + 10, CARRIER_MHZ - 10**5]) if lie == 0 else st.none()),
       lies=st.dictionaries(st.integers(1, 150), LIES, max_size=3),
       info_at=st.dictionaries(st.integers(1, 150), ANSWERS, max_size=1),
       start_ack=st.integers(0, 7).flatmap(lambda lie: st.integers(0, U32) if lie == 0 else st.none()))
def test_any_sequence_of_answers_keeps_the_envelope_within_the_limits(
        answers: dict[int, list[Answer]], carrier: int | None, lies: dict[int, dict[str, int | str]],
        info_at: dict[int, Answer], start_ack: int | None) -> None:
    assert_within_limits(run(Script(answers, carrier, lies, info_at, start_ack), seconds=0.15))

