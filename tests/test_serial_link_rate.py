"""The link's rate, measured at the handshake (docs/amp-protocol.md H11), on the virtual link and clock.

A burst of KEEPALIVE frames, read back through the amplifier's STATUS (``frames_ok`` against
its own ``time_us``), measures the line; the virtual link's ``baud`` is its byte rate
(``baud / 10``). A link that carries the envelope with LINK_MARGIN keeps the URL's frames, a
slower one gets larger frames (said in one line, in the stats and the play summary), and one
too slow for any frame the amplifier takes is refused in one line naming the measured and
needed rates: never a run starved of frames. Deterministic.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest
from virtual_serial import DEVICE, VirtualRun

from tpad_rt.amp.virtual_link import VirtualLink
from tpad_rt.errors import BackendError
from tpad_rt.outputs import serial_rate
from tpad_rt.outputs.serial_rate import LinkRate, frames_for, link_rate, needed_bytes_per_s

MS = 1_000_000


def started(baud: int, query: str = "") -> VirtualRun:
    """A run started on a virtual link of ``baud`` (bytes/s: baud / 10)."""
    return VirtualRun(VirtualLink.emulating(DEVICE, baud=baud), query=query).start()


@pytest.mark.parametrize("baud", [921600, 700000, 500000, 420000])
def test_the_burst_measures_the_line_s_byte_rate_on_the_amplifier_s_clock(baud: int) -> None:
    run = started(baud)
    rate = run.amp_link.link_rate
    # Frame by frame, quantised by the STATUS frames' 5 ms: within 2 % below the line's rate, above it by at most a
    # frame (a frame counts when its last byte is through) over the time measured.
    assert not rate.at_least
    assert baud / 10 * 0.98 <= rate.bytes_per_s <= baud / 10 + serial_rate.KEEPALIVE_LINE_BYTES / rate.elapsed_s
    stats = run.stats()
    assert stats["link_kb_s"] == pytest.approx(rate.bytes_per_s / 1e3)
    run.stop()
    stats = run.stats()
    # The burst's frames were taken in sequence and none tripped anything.
    assert stats["amp_sequence_gaps"] == stats["amp_frames_bad"] == stats["amp_watchdog_trips"] == 0


def test_a_line_faster_than_the_status_frames_resolve_is_measured_as_a_bound_that_passes() -> None:
    link = VirtualLink.emulating(DEVICE, baud=20_000_000)
    start_ns = link.clock.now_ns()
    run = VirtualRun(link).start()
    rate = run.amp_link.link_rate
    assert rate.at_least and rate.bytes_per_s >= 2 * needed_bytes_per_s(16000, 8) * serial_rate.LINK_MARGIN
    assert run.amp_link.frame_samples == 8 and run.amp_link.link_note == ""
    # The whole handshake, measurement included, is tens of ms of the clock on a good line.
    assert link.clock.now_ns() - start_ns < 40 * MS
    run.stop()


def test_a_link_too_slow_for_the_url_s_frames_gets_larger_ones_says_so_and_plays_without_a_miss() -> None:
    run = started(510000)
    amp_link = run.amp_link
    assert amp_link.frame_samples == 22  # the smallest frame 51 kB/s carries with the margin at 16 kHz
    assert needed_bytes_per_s(16000, 21) * serial_rate.LINK_MARGIN > 51e3
    assert needed_bytes_per_s(16000, 22) * serial_rate.LINK_MARGIN <= amp_link.link_rate.bytes_per_s
    assert amp_link.link_note == (
        "serial: the link to the amplifier on virtual carries 51.0 kB/s, less than the 70.0 kB/s frames of 8 samples "
        "need at 16000 Hz with a 1.25x margin: sending frames of 22 samples (1.375 ms, 40.7 kB/s)")
    run.swipe(1.0)
    assert run.stop() is None
    stats = run.stats()
    assert stats["frame_samples"] == 22 and stats["link_note"] == amp_link.link_note
    assert stats["amp_underruns"] == stats["amp_frames_rejected"] == stats["late"] == stats["amp_sequence_gaps"] == 0
    assert amp_link.link_note in run.driver.summary_lines(run.driver.stats())


def test_a_link_too_slow_for_any_frame_is_refused_in_one_line_naming_the_rates() -> None:
    with pytest.raises(BackendError) as refused:
        started(400000)
    assert str(refused.value) == (
        "serial: the link to the amplifier on virtual carries 40.0 kB/s (measured at the handshake), too slow for the "
        "envelope at 16000 Hz: it needs 70.0 kB/s in frames of 8 samples, 41.1 kB/s in the largest the amplifier "
        "takes (1.25x margin included); envelope_hz=8000 fits (docs/amp-protocol.md H11)")
    run = started(400000, "envelope_hz=8000")  # the rate it names does fit
    run.swipe(0.5)
    assert run.stop() is None
    assert run.stats()["amp_underruns"] == run.stats()["amp_frames_rejected"] == 0


@pytest.mark.parametrize("baud", [350000, 450000, 600000, 800000])
def test_a_slow_link_is_adapted_or_refused_never_starved(baud: int) -> None:
    try:
        run = started(baud)
    except BackendError as error:
        assert "too slow for the envelope" in str(error)
        return
    run.swipe(0.5)
    assert run.stop() is None
    stats = run.stats()
    assert stats["amp_underruns"] == stats["amp_frames_rejected"] == stats["late"] == 0


def test_an_amplifier_that_reads_in_bursts_keeps_the_url_s_frames_on_a_link_that_carries_them() -> None:
    # 100 kB/s carries the 70 kB/s that 0.5 ms frames need with the margin; the amplifier reads what came every
    # 20 ms (BOUND_READ_PERIOD_S), all at once, so the whole-burst bound may be all the measurement has.
    read_period_ns = round(serial_rate.BOUND_READ_PERIOD_S * 1e9)
    link = VirtualLink.emulating(DEVICE, baud=1_000_000, read_period_ns=read_period_ns)
    run = VirtualRun(link, query="buffer_ms=40").start()
    amp_link = run.amp_link
    need = needed_bytes_per_s(16000, 8) * serial_rate.LINK_MARGIN
    assert need * serial_rate.BOUND_PASSES <= 100e3
    assert need <= amp_link.link_rate.bytes_per_s <= 100e3 / 0.98
    assert amp_link.frame_samples == 8 and amp_link.link_note == ""
    run.swipe(0.5)
    assert run.stop() is None
    stats = run.stats()
    assert stats["amp_underruns"] == stats["amp_frames_rejected"] == stats["late"] == stats["amp_sequence_gaps"] == 0


def test_an_amplifier_that_reads_every_30_ms_is_waited_for_not_taken_for_a_lost_burst() -> None:
    # The measurement ends after 4 STATUS periods without more of the burst, and at least two BOUND_READ_PERIOD_S:
    # with 4 periods alone (20 ms) it ended after the first read, at 48.6 kB/s. Never above the line's 100 kB/s.
    link = VirtualLink.emulating(DEVICE, baud=1_000_000, read_period_ns=30 * MS)
    run = VirtualRun(link, query="buffer_ms=40").start()
    rate = run.amp_link.link_rate
    assert rate.frames == serial_rate.burst_frames(16000, 8, 5)
    assert needed_bytes_per_s(16000, 8) * serial_rate.LINK_MARGIN <= rate.bytes_per_s <= 100e3 / 0.98
    run.stop()


def test_the_whole_burst_bound_passes_a_link_of_bound_passes_times_the_need_however_late_it_is_read() -> None:
    # The burst alone, at exactly BOUND_PASSES x the need, with the most slack the bound allows for: a STATUS period
    # before it, one after it and BOUND_READ_PERIOD_S of reading late.
    for status_period_ms in (1, 5, 20, 100):
        need = needed_bytes_per_s(16000, 8) * serial_rate.LINK_MARGIN
        frames = serial_rate.burst_frames(16000, 8, status_period_ms)
        burst_bytes = frames * serial_rate.KEEPALIVE_LINE_BYTES
        slack_s = 2 * status_period_ms * 1e-3 + serial_rate.BOUND_READ_PERIOD_S
        assert burst_bytes / (burst_bytes / (serial_rate.BOUND_PASSES * need) + slack_s) >= need
        # Bounded: the burst at the rate needed fits the measurement's limit twice over.
        assert 2 * burst_bytes / need <= serial_rate.measure_limit_s(status_period_ms) + 1e-3


class DeafAfterTheCarrier(VirtualLink):
    """A link whose amplifier reads nothing the host writes after its first two frames (HELLO, SET_CARRIER):
    no frame of the burst arrives."""

    frames_to_hear = 2

    def put(self, data: bytes) -> int:
        if self.frames_to_hear <= 0:
            self.stop_reading()
        taken = super().put(data)
        self.frames_to_hear -= data[:max(taken, 0)].count(0)
        return taken


def test_a_burst_that_never_arrives_is_measured_as_nothing_within_the_bound() -> None:
    link = DeafAfterTheCarrier.emulating(DEVICE)
    start_ns = link.clock.now_ns()
    with pytest.raises(BackendError, match=r"carries 0\.0 kB/s \(measured at the handshake\), too slow"):
        VirtualRun(link).start()
    assert link.clock.now_ns() - start_ns <= (serial_rate.measure_limit_s(5) + 0.1) * 1e9


def test_the_rate_estimate_from_status_reports() -> None:
    # Two reports while the burst arrived: their difference. 100 frames of 8 bytes between 5 and 15 ms: 80 kB/s.
    assert link_rate([(0, 0), (5000, 50), (15000, 150), (20000, 175)], 175) == LinkRate(80000.0, False, 175, 0.01)
    # All of it between two reports 5 ms apart: at least the burst over the time from the report taken before it
    # was written (the amplifier may have left it unread at 5 ms).
    assert link_rate([(0, 0), (5000, 0), (10000, 175)], 175) == LinkRate(140000.0, True, 175, 0.01)
    # An amplifier that reads a fast line in bursts of its own (the emulator on a pty): the whole burst's bound.
    assert link_rate([(0, 0), (5000, 0), (10000, 1472), (15000, 1472), (20000, 1472), (25000, 2000)], 2000) == \
        LinkRate(640000.0, True, 2000, pytest.approx(0.025))
    # Nothing came.
    assert link_rate([(0, 0), (5000, 0), (10000, 0)], 175).bytes_per_s == 0.0


def test_frames_grow_until_the_link_carries_them_within_the_amplifier_s_buffer() -> None:
    def rate(kb_s: float) -> LinkRate:
        return LinkRate(kb_s * 1e3, False, 1, 1.0)

    assert frames_for(rate(92.0), 16000, 8, 32, 256, 1024) == 8
    assert frames_for(rate(50.0), 16000, 8, 32, 256, 1024) == 24
    assert frames_for(rate(40.0), 16000, 8, 32, 256, 1024) is None  # below 2 bytes a sample with the margin
    assert frames_for(rate(41.5), 16000, 8, 32, 256, 1024) == 174  # 2N + 13 bytes past 121 samples (COBS)
    assert frames_for(rate(41.5), 16000, 8, 900, 256, 1024) is None  # the buffer holds no such frame past the fill


#: Opens a link on the virtual link, plays a tone and stops, in a fresh process; prints the compiled functions
#: the host asked for after AmpLink.open's warm_checks (numba compiles, or loads from its cache, on first use).
_LATE_COMPILES = textwrap.dedent("""
    import numba.core.dispatcher as dispatcher
    from tpad_rt.amp.virtual_link import VirtualLink
    from tpad_rt.device import Device
    from tpad_rt.outputs import serial_amp
    warmed, late = [], []
    warm_checks, compile_for_args = serial_amp.warm_checks, dispatcher.Dispatcher._compile_for_args
    def warm():
        warm_checks()
        warmed.append(True)
    def watched(self, *args, **kwargs):
        if warmed:
            late.append(self.py_func.__qualname__)
        return compile_for_args(self, *args, **kwargs)
    serial_amp.warm_checks, dispatcher.Dispatcher._compile_for_args = warm, watched
    device = Device.default()
    link = serial_amp.AmpLink.open(serial_amp.parse_serial_url("serial://virtual"), carrier_hz=device.carrier_hz,
                                   line=VirtualLink.emulating(device))
    try:
        link.tone(5.0, 0.02)
    finally:
        link.stop(ramp_ms=5.0)
    print(warmed, late)
""")


def test_nothing_is_compiled_once_the_port_is_open() -> None:
    """Whatever the host calls from Python after opening the port (the handshake, the link check, a tone) was
    compiled before it by warm_checks: a compile then delays the timed handshake, and a Ctrl-C landing in LLVM
    printed llvmlite's traceback (the link check's frame_line_bytes did). In a fresh process, where nothing was
    compiled by earlier tests."""
    done = subprocess.run([sys.executable, "-c", _LATE_COMPILES], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["[True]", "[]"]
