"""The serial link's rate, measured at the handshake, and the frames it can carry (docs/amp-protocol.md H11).

API map
-------
LINK_MARGIN, KEEPALIVE_LINE_BYTES, BOUND_PASSES, BOUND_READ_PERIOD_S, MEASURE_MIN_S, MEASURE_BURSTS,
STALL_STATUS_PERIODS
    the margin the link must have over the envelope's need, a KEEPALIVE's bytes on the
    line, the links the whole-burst bound passes, the measurement's bounds
needed_bytes_per_s(envelope_hz, frame_samples) -> float
    what the envelope takes on the line in frames of ``frame_samples`` (bytes/s, no margin)
burst_s(status_period_ms) -> float
    how long the burst lasts at the rate it must show (s)
burst_frames(envelope_hz, frame_samples, status_period_ms) -> int
    the KEEPALIVE frames of the burst: long enough for the whole-burst bound to pass a link
    of BOUND_PASSES times the rate the envelope needs with the margin
measure_limit_s(status_period_ms) -> float
    the longest the measurement lasts (s), from its start (the first STATUS awaited)
stall_status_periods(status_period_ms) -> int
    the STATUS periods without more of the burst that end the measurement
LinkRate(bytes_per_s, at_least, frames, elapsed_s) / link_rate(reports, frames) -> LinkRate
    the rate the amplifier's own STATUS frames show the burst arrived at
frames_for(rate, envelope_hz, frame_samples, fill_samples, max_frame_samples, buffer_samples) -> int | None
    the smallest frame (samples, at least the URL's) the measured rate carries with the margin, within the
    amplifier's frame and buffer limits; None if none

Method (H11): after INFO and SET_CARRIER the host sends a burst of KEEPALIVE frames (8 bytes
each on the line; each resets the watchdog and counts in STATUS's ``frames_ok``) as fast as
the line takes them, and reads the STATUS frames the amplifier sends every
``status_period_ms`` meanwhile: ``frames_ok + frames_bad`` against ``time_us``, the
amplifier's own clock. The rate is the higher of two the link showed: between the first and
the last STATUS taken while the burst arrived (exact on a line the burst keeps busy), and
the whole burst over the time from the STATUS taken before it was written to the first after
all of it (a lower bound,
the one left when the burst came within two STATUS periods or the amplifier read it in
bursts of its own). That bound counts more time than the burst took: up to a STATUS period
before it, one after it, and the wait of an amplifier that reads what came only now and then
(at most BOUND_READ_PERIOD_S apart), so it can only pass a link faster than the rate needed:
the burst is sized (:func:`burst_s`) for it to pass every link of at least BOUND_PASSES times
that rate with the margin (87.5 kB/s for 0.5 ms frames at 16 kHz); a link between the two
whose amplifier reads in bursts may be measured low and get larger frames (or be refused),
never starved. The protocol's bytes do not change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tpad_rt.kernel.amp_stream import frame_line_bytes

#: The link must carry this times what the envelope needs (scheduling, STATUS's own bytes, SET_CARRIER frames).
LINK_MARGIN = 1.25
#: A KEEPALIVE on the line: a 6-byte body, COBS's code byte and the delimiter.
KEEPALIVE_LINE_BYTES = 8
#: The whole-burst bound passes every link of at least this times the rate the envelope needs with the margin ...
BOUND_PASSES = 1.25
#: ... whose amplifier reads what came at least this often (s).
BOUND_READ_PERIOD_S = 0.02
#: The measurement ends this long (s) after it began (the first STATUS awaited) whatever came, or after
#: MEASURE_BURSTS times the burst's duration at the rate needed if that is longer (a link this slow carries less).
MEASURE_MIN_S = 1.0
MEASURE_BURSTS = 2
#: It also ends when, once the burst began arriving, this many STATUS periods pass without more of it (the rest was
#: lost), and at least two BOUND_READ_PERIOD_S (an amplifier reading now and then is not taken for a lost burst).
STALL_STATUS_PERIODS = 4


def needed_bytes_per_s(envelope_hz: int, frame_samples: int) -> float:
    """Bytes per second the envelope at ``envelope_hz`` takes on the line in frames of ``frame_samples`` samples
    (frame_line_bytes each, ``envelope_hz / frame_samples`` frames a second), without the margin."""
    return frame_line_bytes(frame_samples) * envelope_hz / frame_samples


def burst_s(status_period_ms: int) -> float:
    """How long (s) the burst lasts at the rate it must show, N. The whole-burst bound of a burst of B bytes on a link
    of R bytes/s is at least B / (B / R + S), S = 2 status periods + BOUND_READ_PERIOD_S; for it to be >= N at
    R = k N (k = BOUND_PASSES): B >= S N k / (k - 1), a burst of S k / (k - 1) s at N (150 ms with the emulator's
    5 ms period)."""
    slack_s = 2 * status_period_ms * 1e-3 + BOUND_READ_PERIOD_S
    return slack_s * BOUND_PASSES / (BOUND_PASSES - 1.0)


def burst_frames(envelope_hz: int, frame_samples: int, status_period_ms: int) -> int:
    """KEEPALIVE frames in the burst that measures the link for frames of ``frame_samples`` at ``envelope_hz``:
    :func:`burst_s` at the rate needed with LINK_MARGIN."""
    need = needed_bytes_per_s(envelope_hz, frame_samples) * LINK_MARGIN
    return math.ceil(need * burst_s(status_period_ms) / KEEPALIVE_LINE_BYTES)


def measure_limit_s(status_period_ms: int) -> float:
    """The longest the measurement lasts (s) from its start: MEASURE_MIN_S, or MEASURE_BURSTS times the
    burst's duration at the rate needed if longer (1 s up to a 40 ms STATUS period, 2.2 s at the 100 ms the
    protocol allows)."""
    return max(MEASURE_MIN_S, MEASURE_BURSTS * burst_s(status_period_ms))


def stall_status_periods(status_period_ms: int) -> int:
    """STATUS periods that, once the burst began arriving, pass without more of it before the measurement ends:
    STALL_STATUS_PERIODS, and at least two BOUND_READ_PERIOD_S (8 at the emulator's 5 ms)."""
    return max(STALL_STATUS_PERIODS, math.ceil(2 * BOUND_READ_PERIOD_S * 1e3 / status_period_ms))


@dataclass(frozen=True)
class LinkRate:
    """The link's measured rate (bytes/s; ``at_least``: a lower bound, the burst came faster than the STATUS
    frames resolve), from ``frames`` KEEPALIVE frames, over ``elapsed_s`` of the amplifier's clock."""

    bytes_per_s: float
    at_least: bool
    frames: int
    elapsed_s: float

    def text(self) -> str:
        """``48.2 kB/s`` or ``at least 120.0 kB/s``."""
        return f"{'at least ' if self.at_least else ''}{self.bytes_per_s / 1e3:.1f} kB/s"


def link_rate(reports: list[tuple[int, int]], frames: int) -> LinkRate:
    """The rate from ``reports``: (``time_us``, frames the amplifier took since the burst began) of each STATUS read,
    the first one sent before the burst (0 frames taken), times unwrapped; ``frames`` the burst's.

    Two rates the link showed, the higher one: between the first and the last STATUS taken while the burst arrived
    (exact on a line the burst keeps busy), and over the whole burst, from the STATUS taken before it was written
    (the first report) to the first after all of it (a lower bound: it counts the time from that STATUS to the
    burst's start, and from the last read of it to the next STATUS; the only one when it arrived between two STATUS
    frames, or in bursts of its own, as an amplifier reading a fast line may). A later STATUS that counts none of it
    is no start: an amplifier that reads now and then may not have read the bytes already there."""
    before_us = reports[0][0]
    t_us, taken = next(((t_us, taken) for t_us, taken in reports if taken >= frames), reports[-1])
    whole = LinkRate(taken * KEEPALIVE_LINE_BYTES / ((t_us - before_us) * 1e-6) if t_us > before_us else 0.0,
                     taken >= frames, frames, max(t_us - before_us, 0) * 1e-6)
    during = [(t_us, taken) for t_us, taken in reports if 0 < taken < frames]
    if len(during) >= 2 and during[-1][0] > during[0][0]:
        (t0_us, taken0), (t1_us, taken1) = during[0], during[-1]
        elapsed_s = (t1_us - t0_us) * 1e-6
        busy = LinkRate((taken1 - taken0) * KEEPALIVE_LINE_BYTES / elapsed_s, False, frames, elapsed_s)
        if busy.bytes_per_s >= whole.bytes_per_s:
            return busy
    return whole


def frames_for(rate: LinkRate, envelope_hz: int, frame_samples: int, fill_samples: int, max_frame_samples: int,
               buffer_samples: int) -> int | None:
    """The smallest frame (samples, from ``frame_samples`` up to ``max_frame_samples``) whose envelope at
    ``envelope_hz`` the measured ``rate`` carries with LINK_MARGIN, while the amplifier's buffer (``buffer_samples``)
    holds a frame past the target fill (``fill_samples``, at least a frame); None if none does."""
    for samples in range(max(1, frame_samples), max_frame_samples + 1):
        if max(samples, fill_samples) + samples > buffer_samples:
            return None
        if needed_bytes_per_s(envelope_hz, samples) * LINK_MARGIN <= rate.bytes_per_s:
            return samples
    return None
