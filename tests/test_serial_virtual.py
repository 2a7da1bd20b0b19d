"""``serial://`` on the virtual link: the host's AmpLink, streamer steps and driver against the in-process amplifier
emulator on a virtual clock (tpad_rt/amp/virtual_link.py). Deterministic: no thread, no sleep, no wall clock; every
time below is the clock's, and counts are exact where the run is.

What the emulator applied (its recording) is compared with what the host rendered (the
kernel's drive ring) and mapped through the device's calibration and friction model back
to the texture's levels; faults are the link's (line faults, a frozen host, an amplifier
that stops reading, is killed, unplugged, drifts) or the amplifier's own (overcurrent).
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from virtual_serial import DEVICE, GRATING, REPO, VirtualRun

from tpad_rt.amp import wire
from tpad_rt.amp.emulator import RECORDED_COLUMNS, Amplifier
from tpad_rt.amp.virtual_link import LineFaults, VirtualLink
from tpad_rt.device import Device
from tpad_rt.errors import BackendError
from tpad_rt.kernel import amp_stream
from tpad_rt.kernel import table as tab
from tpad_rt.outputs.serial_amp import AmpLink, parse_serial_url
from tpad_rt.physics.friction import relative_friction

DEFAULT_DEVICE = REPO / "tpad_rt" / "devices" / "default.yaml"
MS = 1_000_000


def fed(recording: dict[str, np.ndarray]) -> np.ndarray:
    """Where the amplifier played a sample from its buffer (one the host sent)."""
    return np.flatnonzero(recording["index"] >= 0)


def host_volts(run: VirtualRun, index: np.ndarray) -> np.ndarray:
    """The volts the host rendered for stream ``index`` (the kernel's drive ring, at the amplifier's full scale)."""
    link = run.driver._last_link
    assert link is not None and link.scale is not None
    drive = run.table.drive
    return drive[index % len(drive)].astype(np.float64) * link.scale.full_scale_v


def unexplained(run: VirtualRun, recording: dict[str, np.ndarray]) -> np.ndarray:
    """Which fed samples match neither the host's value nor a slew-limited step towards it (A2)."""
    info = run.link.amplifier.info
    at = fed(recording)
    volts = recording["envelope_v"]
    wanted = host_volts(run, recording["index"][at])
    matched = np.abs(volts[at] - wanted) <= info.full_scale_mv / 1e3 / 32767
    slew_v = info.slew_mv_per_ms / float(run.link.amplifier.envelope_hz)  # V per sample
    step = volts[at] - volts[np.maximum(at - 1, 0)]
    slewing = (np.abs(np.abs(step) - slew_v) <= 1e-6 * slew_v) & (np.sign(step) == np.sign(wanted - volts[at - 1]))
    return ~(matched | slewing)


def swiped(link: VirtualLink, seconds: float = 1.0, **swipe: float) -> VirtualRun:
    """A started run on ``link`` that swiped for ``seconds`` (stopped: the caller's)."""
    run = VirtualRun(link).start()
    run.swipe(seconds, **swipe)
    return run


# --- the stream ------------------------------------------------------------------------------------------------

def test_the_emulated_plate_renders_the_grating_s_friction_levels() -> None:
    levels = yaml.safe_load(GRATING.read_text())["friction"]
    link = VirtualLink.emulating(DEVICE)
    run = swiped(link, 1.2, speed_mm_s=100.0, x0_mm=10.0)
    assert run.stop() is None
    recording = link.recording()
    stats = run.stats()
    # Nothing missed, nothing late, nothing bad: the virtual host is never held up.
    assert stats["amp_underruns"] == stats["late"] == stats["amp_frames_bad"] == stats["rx_bad"] == 0
    assert stats["amp_sequence_gaps"] == stats["amp_frames_rejected"] == stats["restarts"] == 0
    assert recording["carrier_hz"].min() == recording["carrier_hz"].max() == pytest.approx(DEVICE.carrier_hz, abs=0.01)
    at = fed(recording)
    middle = at[len(at) // 10: -len(at) // 10]
    friction = relative_friction(recording["plate_amplitude_um"][middle] * 1e-6, DEVICE.carrier_hz, 0.1, DEVICE.mu0,
                                 DEVICE.poisson, DEVICE.psi_star)
    assert np.percentile(friction, 1) == pytest.approx(levels["low"], rel=0.02)
    assert np.percentile(friction, 99) == pytest.approx(levels["high"], rel=0.02)
    assert not unexplained(run, recording).any()


def test_the_amplifier_applies_what_the_host_rendered_at_its_index_on_its_own_scale(tmp_path) -> None:  # noqa: ANN001
    # An amplifier of another full scale and clamp than the host's device file (32 V max: 40 V full scale, where the
    # device says 50 V and 40 V): the host scales and caps by what INFO said.
    amplifier_device = tmp_path / "amplifier.yaml"
    amplifier_device.write_text(DEFAULT_DEVICE.read_text().replace("max_voltage_v: 40.0", "max_voltage_v: 32.0"))
    link = VirtualLink.emulating(Device.from_file(amplifier_device))
    run = swiped(link, 1.0)
    run.stop()
    recording = link.recording()
    at = fed(recording)
    assert len(at) >= 16000  # every sample of the second, fed
    assert not unexplained(run, recording).any(), "samples applied that the host did not send"
    assert 10.0 < np.abs(recording["envelope_v"]).max() <= 32.0, "the swipe must drive the plate, within its clamp"
    assert link.amplifier.info.full_scale_mv == 40000 != DEVICE.volts_per_full_scale * 1000
    assert run.stats()["carrier_hz"] == pytest.approx(DEVICE.carrier_hz, abs=0.01)


def test_the_buffer_holds_the_target_fill_and_never_more_than_the_amplifier_takes() -> None:
    link = VirtualLink.emulating(DEVICE)
    run = swiped(link, 0.5)
    fills, played = [], []
    for _ in range(200):  # a STATUS every 5 ms: read the amplifier itself, each ms
        run.run_for(0.001)
        link.amplifier.advance(link.amp_s(link.clock.now_ns()))
        fills.append(link.amplifier.buffer.fill(link.amplifier.play_index))
        played.append(link.amplifier.play_index)
    run.stop()
    stats = run.stats()
    target = stats["target_fill"]
    assert min(fills) >= target - stats["frame_samples"] and max(fills) <= target + 2 * stats["frame_samples"]
    # Frames sent account for every index: from the one START named (0), one frame after another.
    link_array = run.driver._last_link.link  # type: ignore[union-attr]
    assert link_array[amp_stream.LINK_WRITTEN] == stats["frames_sent"] * stats["frame_samples"]
    assert np.all(np.diff(played) == 16)  # 1 ms at 16 kHz, every ms


def test_corrupted_dropped_and_duplicated_bytes_are_counted_never_applied_and_the_stream_recovers() -> None:
    link = VirtualLink.emulating(DEVICE)
    link.faults = LineFaults(corrupt_rate=0.0005, drop_rate=0.0005, duplicate_rate=0.01, seed=3)
    run = swiped(link, 1.5)
    run.stop()
    recording = link.recording()
    counters = link.amplifier.counters
    assert counters.frames_bad > 0 and counters.sequence_gaps > 0
    assert not unexplained(run, recording).any(), "samples applied that the host did not send"
    t_s = recording["t_s"][fed(recording)]
    # It recovered: fed to the end, as densely in the last 0.5 s as over the run.
    assert t_s[-1] > 1.4 and np.count_nonzero(t_s > t_s[-1] - 0.5) / 0.5 > 0.9 * len(t_s) / np.ptp(t_s)


def test_a_frozen_host_is_ramped_to_zero_by_the_watchdog_and_the_stream_restarts_where_start_said() -> None:
    link = VirtualLink.emulating(DEVICE)
    run = swiped(link, 0.3)
    frozen_s = link.amp_s(link.clock.now_ns())
    link.freeze_host(300 * MS)  # six watchdogs
    run.swipe(0.5)
    stats = run.stats()
    run.stop()
    recording = link.recording()
    t_s, volts, index = recording["t_s"], np.abs(recording["envelope_v"]), recording["index"]
    assert link.amplifier.counters.watchdog_trips == 1 == stats["restarts"]
    last_fed = np.flatnonzero((t_s < frozen_s + 0.3) & (index >= 0))[-1]
    silent = np.flatnonzero((volts == 0.0) & (np.arange(len(t_s)) > last_fed))[0]
    assert t_s[silent] - t_s[last_fed] <= 0.050, "A4: zero within 50 ms of the last valid frame"
    assert np.all(volts[silent:np.flatnonzero(t_s < frozen_s + 0.3)[-1]] == 0.0)
    after = index[silent:][index[silent:] >= 0]
    assert after[0] == stats["start_index"], "the first sample played after the watchdog is the one START named"
    assert np.any((t_s > frozen_s + 0.3) & (index >= 0) & (volts > 1.0)), "the stream did not restart"


def test_a_host_held_up_less_than_the_watchdog_skips_ahead_and_flags_the_late_frame() -> None:
    link = VirtualLink.emulating(DEVICE)
    run = swiped(link, 0.3)
    link.freeze_host(20 * MS)  # under the watchdog's 38 ms: the amplifier plays zeros (underruns) and waits
    run.swipe(0.2)
    stats = run.stats()
    run.stop()
    assert stats["restarts"] == 0 and link.amplifier.counters.watchdog_trips == 0
    assert stats["late"] == 1 and run.table.stats[tab.STAT_UNDERFLOWS] == 1
    assert 0 < stats["amp_underruns"] <= 20 * 16 + 2 * stats["target_fill"]
    recording = link.recording()
    index = recording["index"][fed(recording)]
    assert np.all(np.diff(index) > 0)  # nothing played twice, nothing out of order
    assert run.table.stats[tab.STAT_PRIMING] == stats["target_fill"] // stats["frame_samples"]


def test_status_frames_piled_up_during_a_freeze_are_dated_when_read_not_taken_for_silence() -> None:
    """A host held up longer than the STATUS timeout (H7: 4 periods + 100 ms) finds the STATUS frames that piled
    up meanwhile: dated by the read that returned them, they show a live amplifier."""
    link = VirtualLink.emulating(DEVICE)
    run = swiped(link, 0.2)
    link.freeze_host(500 * MS)
    run.swipe(0.3)
    assert run.driver.poll(run.table) is None
    assert run.stop() is None
    assert run.stats()["restarts"] == 1


@pytest.mark.parametrize(("fault", "message"), [
    ("kill", "stopped reporting (no STATUS for 120 ms)"),
    ("unplug", "lost the amplifier on virtual: Input/output error"),
    ("stop_reading", "stopped reading (the port took no byte for 120 ms)"),
])
def test_a_lost_silent_or_deaf_amplifier_ends_the_run_in_one_line(fault: str, message: str) -> None:
    link = VirtualLink.emulating(DEVICE)
    run = swiped(link, 0.2)
    at_ns = link.clock.now_ns()
    getattr(link, fault)()
    run.run_for(0.5)
    failure = run.driver.poll(run.table)
    assert isinstance(failure, BackendError) and message in str(failure) and "\n" not in str(failure)
    assert not run.amp_link.streaming  # type: ignore[union-attr]
    stopped = run.amp_link.link  # type: ignore[union-attr]
    if fault != "stop_reading":  # a deaf amplifier still reports
        assert int(stopped[amp_stream.LINK_STATUS_NS]) <= at_ns + 5 * MS  # the last STATUS came before the fault
    assert run.stop() is failure  # reported once, the same object
    if fault == "stop_reading":
        assert run.stats()["tx_blocked"] > 0


def test_after_a_failed_read_nothing_more_goes_to_the_port() -> None:
    """A read that fails loses the port (H7): the bytes still queued for it (an amplifier that read nothing for a
    while left the line full) are not written after it, and no STOP follows, though the line would take them."""
    link = VirtualLink.emulating(DEVICE)
    run = swiped(link, 0.2)
    link.stop_reading()
    run.run_for(0.1)  # the line fills; frames wait in the host's queue (within the 120 ms stall limit)
    queued = run.amp_link.link  # type: ignore[union-attr]
    assert queued[amp_stream.LINK_TX_END] > queued[amp_stream.LINK_TX_FIRST]
    link.lose_reads()
    link.resume_reading()  # the line has room again
    written_after: list[int] = []
    put = link.put
    link.put = lambda data: written_after.append(len(data)) or put(data)  # type: ignore[method-assign]
    run.run_for(0.2)
    failure = run.driver.poll(run.table)
    assert isinstance(failure, BackendError) and "Input/output error" in str(failure)
    assert written_after == []  # not a byte after the failed read
    assert queued[amp_stream.LINK_STOP_SEQ] == -1
    assert run.stop() is failure


def test_an_overcurrent_fault_ends_the_run_with_stop() -> None:
    link = VirtualLink.emulating(DEVICE)
    run = swiped(link, 0.2)
    link.amplifier.fault(wire.Fault.OVERCURRENT, link.amp_s(link.clock.now_ns()))
    run.run_for(0.05)
    failure = run.driver.poll(run.table)
    assert failure is not None and "reported a fault: overcurrent; its output is off" in str(failure)
    assert run.amp_link.link[amp_stream.LINK_STOP_SEQ] >= 0  # type: ignore[union-attr]
    assert link.amplifier.counters.frames_ok > 0 and link.amplifier.output_mv == 0.0


@pytest.mark.parametrize("drift", [-1e-4, 1e-4])
def test_an_amplifier_clock_off_by_a_crystal_s_tolerance_is_followed_without_a_miss(drift: float) -> None:
    link = VirtualLink.emulating(DEVICE)
    link.set_drift(drift)
    run = swiped(link, 2.0)
    stats = run.stats()
    run.stop()
    assert stats["amp_underruns"] == stats["late"] == stats["amp_frames_rejected"] == 0


def test_stop_ramps_the_drive_to_zero_then_sends_stop_after_the_last_frame() -> None:
    link = VirtualLink.emulating(DEVICE)
    sent: list[int] = []
    receive = link.amplifier.receive

    def spy(encoded: bytes | None, t_s: float) -> None:
        frame = wire.decode(encoded) if encoded is not None else None
        if frame is not None:
            sent.append(frame.type)
        receive(encoded, t_s)

    link.amplifier.receive = spy  # type: ignore[method-assign]
    run = swiped(link, 0.3)
    assert run.stop() is None
    assert sent[-1] == wire.Type.STOP and sent.count(wire.Type.STOP) == 1
    recording = link.recording()
    at = fed(recording)
    assert np.abs(recording["envelope_v"][at[-1]]) == 0.0, "the host's last frame ends its ramp at 0"
    run.run_for(0.05)  # STOP's own ramp (A1-A2), from 0
    link.recording()
    assert link.amplifier.at_rest
    assert run.driver.link is None


def test_an_amplifier_of_another_protocol_version_is_refused() -> None:
    class OldAmplifier(Amplifier):
        """Answers every frame with an ACK BAD_VERSION of version 1 (rule A5)."""

        def receive(self, encoded: bytes | None, t_s: float) -> None:
            frame = wire.decode(encoded) if encoded is not None else None
            if frame is not None:
                ack = wire.Ack(frame.seq, frame.type, wire.Code.BAD_VERSION, 1).pack()
                self.out += wire.encode(wire.Type.ACK, 0, ack, version=1)

    emulated = VirtualLink.emulating(DEVICE).amplifier
    old = OldAmplifier(emulated.info, emulated.circuit, emulated.plate, 0.0)
    with pytest.raises(BackendError, match="the amplifier speaks protocol version 1; this tpad-rt speaks version 2"):
        AmpLink.open(parse_serial_url("serial://virtual"), carrier_hz=DEVICE.carrier_hz,
                     line=VirtualLink(VirtualLink.emulating(DEVICE).clock, old))


def test_the_recording_columns_are_the_emulator_s() -> None:
    link = VirtualLink.emulating(DEVICE)
    run = swiped(link, 0.1)
    run.stop()
    recording = link.recording()
    assert set(recording) == set(RECORDED_COLUMNS) and len(recording["t_s"]) > 1600


def test_a_stop_whose_stop_frame_cannot_go_out_ends_as_stalled_without_a_stop_seq() -> None:
    """H8's tail: the run stops on request while the line is full (the amplifier stopped reading 100 ms ago, under
    the stall timeout); STOP waits for the port a STATUS timeout, then the run ends as a failure, no STOP sent."""
    link = VirtualLink.emulating(DEVICE)
    run = swiped(link, 0.2)
    link.stop_reading()
    run.run_for(0.1)
    assert run.driver.poll(run.table) is None and run.stats()["tx_blocked"] > 0
    stopping_ns = link.clock.now_ns()
    failure = run.driver.close(5.0)
    assert failure is None  # nothing had failed when the stop was asked
    stopped = run.driver._last_link.link  # type: ignore[union-attr]
    assert stopped[amp_stream.LINK_EXIT] == amp_stream.EXIT_TX_STALLED and stopped[amp_stream.LINK_STOP_SEQ] == -1
    # It gave up at its first step a STATUS timeout after the port last took a byte (steps WAKE_NS apart).
    waited_ns = link.clock.now_ns() - stopped[amp_stream.LINK_MOVED_NS]
    timeout_ns = stopped[amp_stream.LINK_STATUS_TIMEOUT_NS]
    assert stopped[amp_stream.LINK_MOVED_NS] < stopping_ns and timeout_ns < waited_ns <= timeout_ns + amp_stream.WAKE_NS
    assert "stopped reading" in str(run.driver._last_link.failure())  # type: ignore[union-attr]
