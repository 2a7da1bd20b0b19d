"""The serial amplifier's streamer: a step that takes the time and the bytes read and returns the bytes to write and
when to wake, and one numba call that runs it on a real port for a whole run, without the GIL.

API map
-------
begin(table, link, now_ns)
    set the step's state for a run starting at ``now_ns`` from the table's next sample
reading(link) -> bool
    whether the run reads the port now (not once it ends: STOP's ACK is the Python side's)
on_received(link, buffers, count, now_ns) -> int
    act on ``count`` bytes just read into ``BUF_RX`` at ``LINK_RX_LENGTH`` (negative:
    ``-errno`` of a failed read), dated ``now_ns``; the EXIT_* reason the run now ends for
step(table, link, buffers, envelope, times, now_ns) -> int
    react to the STATUS frames taken, check the timeouts, queue the frames due (rendered
    with the pointer table's arrays, :mod:`tpad_rt.kernel.table`) or, once the run ends,
    STOP (H8); the bytes waiting in ``BUF_TX[LINK_TX_FIRST:LINK_TX_END]``
on_written(link, count) -> int
    the port took ``count`` of them (0: full; negative: ``-errno``); the bytes still waiting
settle(link, now_ns) -> int
    after the writes: the stall check, the prefill's end; when to wake (ns), or RUN_OVER
    (``link[LINK_EXIT]`` says why)
play_position(link, now_ns) -> float
    the stream index the host estimates the amplifier plays at ``now_ns`` (the DAC time its
    blocks are stamped with: each frame's delay is the written index less this)
stream(table, link, buffers, envelope, times) -> int
    the production loop: the steps above on CLOCK_MONOTONIC and the non-blocking
    descriptor ``link[LINK_FD]`` (reads until EAGAIN, writes until EAGAIN, EINTR retried,
    ``clock_nanosleep`` to the wake time), until the run is over; the EXIT_* reason
frame_line_bytes(samples) -> int
    the most bytes an ENVELOPE frame of ``samples`` samples takes on the line (2N + 12 up to 121)
carrier_echo_ok(link, asked_mhz, achieved_mhz) / check_status(link, body, now_ns) / start_checks(link)
    the checks of what the amplifier reports (H2, H10), shared with the Python side
LINK_*, STAGE_*, EXIT_*, EXIT_NAMES, BUF_*
    the layout of the int64 ``link`` array it shares with the Python side (the step's own
    state between calls in its last block), the run's stages, the exit reasons, and the
    uint8 buffers it works in

docs/amp-protocol.md is the protocol (rules H3-H7 are the host's, here) and
docs/realtime.md the design. The Python side (:mod:`tpad_rt.outputs.serial_amp`) makes
the handshake (HELLO, SET_CARRIER, START) on its line, then the line runs the steps: on a
real port (:class:`tpad_rt.outputs.serial_line.SerialLine`) :func:`stream`, in a thread of
its own, one numba call that releases the GIL for the whole run, so the frames keep their
cadence while the application's Python threads hold it; on the virtual link
(:mod:`tpad_rt.amp.virtual_link`) the same compiled steps as events on a virtual clock,
against the in-process amplifier emulator. Every timing decision (pacing, skip-ahead,
restart after the watchdog, the STATUS timeout, a stalled port, the STOP tail) is the
step's; the loop around it only reads the clock, moves bytes and sleeps. The step wakes
every ``WAKE_NS`` (or sooner when a frame is due): it keeps the amplifier's buffer at the
target fill from its own clock, corrected by each STATUS, renders one frame at a time by
calling the audio driver's compiled callback on the same pointer table (the kernel
renders the envelope: ``cfg[CFG_OUTPUT_ENVELOPE]``); bytes a full port refuses wait in
BUF_TX. It allocates nothing.

Play position: the host estimates the sample ``p`` the amplifier plays now as
``ref_index + (now - ref_ns) * envelope_hz`` (LINK_REF_INDEX, LINK_REF_NS), from when the prefill has been written
(or, on a link whose rate the handshake measured, when its last byte arrives at that rate, if later: H11)
until a RUNNING STATUS says which sample (``play_index``, unwrapped from 32 bits) it
played at its own time ``time_us``. That time is put on the host's clock by the
smallest offset (receive time - ``time_us``) seen so far: the STATUS the line and the
scheduler delayed least (allowed to grow by CLOCK_SKEW). So a STATUS read late does
not make the estimate lag. Once the prefill is out, the host sends a frame whenever
``written < p + target_fill + frame``, so that at least the target fill stays buffered
between frames, and never
more than the amplifier's buffer ahead; if ``p`` has passed what was sent (the host was
held up), it skips the stream ahead, since samples for played indices are refused.
A STATUS showing that the amplifier's watchdog tripped (it went IDLE) makes the host
send START again from the next sample (``LINK_RESTARTS``): the run recovers.

Every report is checked before it is acted on (H10): a STATUS's fields against the
document's ranges and the amplifier's INFO, its play index against the last START and
the time since it went out; a SET_CARRIER or START ACK against what was asked; an INFO
(only ever an answer to a HELLO) against the one the handshake took. One out of range
ends the run (EXIT_BAD_REPORT, EXIT_CONTRADICTED; the value in LINK_REPORT*), STOP and
all. Every sample is clamped to LINK_LEVEL_LIMIT, the host's envelope scale (H3).

Tracking (``LINK_TRACK``, rule H9): after each frame the host sends SET_CARRIER when the
carrier the kernel rendered its last step for (``STATE_STEP_CARRIER_HZ``, the model's
resonance at the force) plus the lock's correction has moved from the amplifier's; with
TRACK_LOCKED each RUNNING STATUS moves that correction towards where its voltage, current
and phase put the plate's resonance (:func:`_lock`, docs/amplifiers.md "Tracking").
"""

from __future__ import annotations

import numba
import numpy as np

from tpad_rt.kernel.jit import njit
from tpad_rt.kernel import amp_codec as codec
from tpad_rt.kernel import atomics, libc
from tpad_rt.kernel import table as tab
from tpad_rt.kernel.amp_codec import (
    ACK_ACKED_TYPE,
    ACK_CODE,
    ACK_VALUE,
    ENVELOPE_FIRST_INDEX,
    ENVELOPE_SAMPLES,
    MAX_ENCODED,
    MSG_ACK,
    MSG_ENVELOPE,
    MSG_SET_CARRIER,
    MSG_START,
    MSG_STATUS,
    PAYLOAD,
    START_BYTES,
    START_ENVELOPE_HZ,
    START_INDEX,
    START_PREFILL,
    STATUS_BUFFER_FILL,
    STATUS_BYTES,
    STATUS_CARRIER_MHZ,
    STATUS_CURRENT_UA_RMS,
    STATUS_ENVELOPE_MV,
    STATUS_FAULTS,
    STATUS_FRAMES_BAD,
    STATUS_FRAMES_OK,
    STATUS_FRAMES_REJECTED,
    STATUS_PHASE_CDEG,
    STATUS_PLAY_INDEX,
    STATUS_SEQUENCE_GAPS,
    STATUS_STATE,
    STATUS_UNDERRUNS,
    STATUS_VOLTAGE_MV_RMS,
    STATUS_WATCHDOG_TRIPS,
)
from tpad_rt.kernel.atomics import load_acquire
from tpad_rt.kernel.cache_stamp import stamp_cache
from tpad_rt.kernel import callback, device_lookup, layout
from tpad_rt.kernel.layout import (
    CFG_C0_F,
    CFG_SHUNT_OHM,
    DEV_REACTANCE_OHM,
    DEV_REACTANCE_SLOPE_OHM_PER_HZ,
    STATE_FORCE_N,
    STATE_NEXT_INDEX,
    STATE_STEP_CARRIER_HZ,
)
from tpad_rt.kernel.callback import BLOCK_LATE, BLOCK_PRIMING
from tpad_rt.kernel.device_lookup import device_value, force_cell
from tpad_rt.kernel.libc import (
    EAGAIN,
    EINTR,
    call_stream_callback,
    errno,
    monotonic_ns,
    pointer,
    read_fd,
    sleep_until_ns,
    write_fd,
)
from tpad_rt.kernel.table import kernel_views

# Compiled in: the codec, the libc calls, the atomics, the table's views, the device lookups, the layout's and the
# callback's constants.
stamp_cache(__file__, codec.__file__, libc.__file__, atomics.__file__, tab.__file__, device_lookup.__file__,
            layout.__file__, callback.__file__)

# --- link: int64[LINK_SIZE]; the Python side writes the first block before the run --------
LINK_FD = 0                   # the port's file descriptor (non-blocking)
LINK_ENVELOPE_HZ = 1          # the envelope rate START agreed
LINK_FRAME_SAMPLES = 2        # samples per ENVELOPE frame (<= the amplifier's max_frame_samples)
LINK_TARGET_FILL = 3          # samples kept buffered ahead of the amplifier's play position, at least (START's prefill)
LINK_BUFFER_SAMPLES = 4       # the amplifier's buffer (INFO)
LINK_STATUS_TIMEOUT_NS = 5    # no STATUS for this long: the amplifier is lost (H7)
LINK_STOP = 6                 # the Python side sets it to 1 (release store) to end the run with STOP (H8)
LINK_SEQ = 7                  # the host's next frame seq: the run continues the handshake's numbering
LINK_START_INDEX = 8          # the stream index the last START named (the host's first; a restart's)
# --- written by the streamer -------------------------------------------------------------
LINK_WRITTEN = 9              # the next stream index to send
LINK_EXIT = 10                # why the run ended (EXIT_*)
LINK_ERRNO = 11               # errno of the read or write that failed
LINK_STATUS_NS = 12           # CLOCK_MONOTONIC (ns) when the last STATUS arrived
LINK_STATUSES = 13            # STATUS frames received
LINK_RX_BAD = 14              # frames from the amplifier that failed COBS, length or CRC
LINK_FRAMES_SENT = 15         # ENVELOPE frames written
LINK_TX_BLOCKED = 16          # writes the port refused for now (its buffer full)
LINK_LATE = 17                # times the amplifier's play position had passed what was sent
LINK_RESTARTS = 18            # STARTs sent again after the amplifier's watchdog tripped
LINK_ACK_TYPE = 19            # the last ACK: the type it answered, its code and value
LINK_ACK_CODE = 20
LINK_ACK_VALUE = 21
LINK_AMP_VERSION = 22         # the version byte of a frame of another protocol version
LINK_AMP_PLAY_INDEX = 23      # the last STATUS, as received (play index unwrapped to the stream's)
LINK_AMP_FILL = 24
LINK_AMP_STATE = 25
LINK_AMP_FAULTS = 26
LINK_AMP_FRAMES_OK = 27
LINK_AMP_FRAMES_BAD = 28
LINK_AMP_FRAMES_REJECTED = 29
LINK_AMP_SEQUENCE_GAPS = 30
LINK_AMP_UNDERRUNS = 31
LINK_AMP_WATCHDOG_TRIPS = 32
LINK_AMP_ENVELOPE_MV = 33
LINK_AMP_VOLTAGE_MV_RMS = 34
LINK_AMP_CURRENT_UA_RMS = 35
LINK_AMP_PHASE_CDEG = 36
LINK_AMP_CARRIER_MHZ = 37
LINK_AMP_TIME_US = 38         # the amplifier's clock when it sent the last STATUS (us, 32 bits)
LINK_STOP_RAMP_MS = 39        # the STOP the run ends with: its ramp (ms), set before the run and again before LINK_STOP
LINK_STOP_SEQ = 40            # the seq that STOP went out with (-1 if it could not)
LINK_CALLBACK = 41            # the address of the compiled render callback (kernel.callback.render_callback)
# --- tracking (docs/amplifiers.md "Tracking"): the Python side writes these before the run ----------------
LINK_TRACK = 42               # TRACK_* (the kernel's cfg has CFG_TRACK set for any but TRACK_OFF)
LINK_CARRIER_MIN_MHZ = 43     # the amplifier's carrier range (INFO)
LINK_CARRIER_MAX_MHZ = 44
LINK_CARRIER_STEP_MHZ = 45    # a carrier this close to the amplifier's is not sent (at least its resolution)
LINK_LOCK_RANGE_MHZ = 46      # the lock's correction stays within +- this of the model's resonance
LINK_LOCK_MIN_CURRENT_UA = 47  # a STATUS with less current (uA RMS) does not move the lock
LINK_CARRIER_MHZ = 48         # the carrier the amplifier makes: the handshake's, then each SET_CARRIER's ACK
# --- written by the streamer while tracking ---------------------------------------------------------------
LINK_CARRIER_ASKED_MHZ = 49   # the last SET_CARRIER sent
LINK_CARRIER_PENDING_NS = 50  # when a SET_CARRIER awaiting its ACK went out (-1: none)
LINK_CARRIER_SETS = 51        # SET_CARRIERs sent
LINK_CARRIER_REFUSED = 52     # SET_CARRIERs the amplifier refused, or left unanswered for CARRIER_ACK_NS
LINK_LOCK_OFFSET_MHZ = 53     # the lock's correction to the model's resonance
LINK_LOCK_UPDATES = 54        # STATUS frames that moved it
# --- what the amplifier's reports are checked against (H1, H3, H10): the Python side writes these at INFO -------
LINK_NONCE = 55               # the nonce of the HELLO whose INFO was taken (buffers[BUF_INFO])
LINK_MAX_MV = 56              # INFO's clamp (mV)
LINK_LEVEL_LIMIT = 57         # no sample sent exceeds this in magnitude (the host's envelope scale, H3)
LINK_START_NS = 58            # CLOCK_MONOTONIC (ns) just before the last START went out (the streamer's restarts too)
# --- written by the streamer's checks ---------------------------------------------------------------------
LINK_CHECK_INDEX = 59         # the highest play index a PRIMING or RUNNING STATUS gave since the last START
LINK_CHECK_TIME_US = 60       # the time_us of the last RUNNING STATUS since that START (-1: none)
LINK_CHECK_RUN_INDEX = 61     # its play index
LINK_REPORT = 62              # the REPORT_* the run ended for (EXIT_BAD_REPORT), and the value sent, the range allowed
LINK_REPORT_VALUE = 63
LINK_REPORT_LOW = 64
LINK_REPORT_HIGH = 65
LINK_INFOS_STALE = 66         # INFO frames passed over: answers to an earlier HELLO, or the taken one again
# --- the step's own state between calls (begin() sets it; nothing else writes it) ---------------------------
LINK_STAGE = 67               # STAGE_*: streaming, flushing the STOP tail, done
LINK_REASON = 68              # the EXIT_* the run is ending for (LINK_EXIT once the STOP tail is done)
LINK_REF_INDEX = 69           # the play position's reference: the amplifier plays this stream index ...
LINK_REF_NS = 70              # ... at this time of the host's clock (ns)
LINK_PRIMED = 71              # 1 once the prefill is out (the amplifier plays), until a restart
LINK_AMP_US = 72              # the last RUNNING STATUS's time_us, unwrapped (us)
LINK_OFFSET_NS = 73           # the smallest (receive time - amplifier time) seen, allowed to grow by CLOCK_SKEW
LINK_SYNCED_NS = 74           # when LINK_OFFSET_NS was last updated (ns)
LINK_TRIPS_AT_START = 75      # the amplifier's watchdog trips when the last START went out
LINK_RX_LENGTH = 76           # bytes of an unfinished frame at the front of BUF_RX
LINK_RX_STATUSES = 77         # STATUS frames taken since the last step
LINK_TX_FIRST = 78            # the bytes waiting for the port: BUF_TX[LINK_TX_FIRST:LINK_TX_END]
LINK_TX_END = 79
LINK_TX_BEFORE = 80           # LINK_TX_FIRST when the last step left bytes waiting (-1: none)
LINK_MOVED_NS = 81            # the last time the port took bytes (ns)
LINK_SKIPPED = 82             # 1: the stream skipped ahead since the last frame (the next is late)
LINK_PRIME_NS = 83            # when the prefill began to go out (ns): at begin(), and at each restart's START
LINK_PRIME_BYTES = 84         # the bytes queued since then while priming (START's, the prefill's frames)
# --- the Python side writes this before the run ----------------------------------------------------------
LINK_LINE_BYTES_PER_S = 85    # the link's rate measured at the handshake (H11; 0: unknown): the prefill's transit
LINK_SIZE = 86

# --- LINK_STAGE ---------------------------------------------------------------------------------
STAGE_STREAMING = 0           # pacing frames
STAGE_FLUSHING = 1            # the run ended (LINK_REASON): STOP is queued, its bytes are being written
STAGE_DONE = 2                # over: LINK_EXIT says why; settle() returns RUN_OVER

# --- LINK_TRACK --------------------------------------------------------------------------------
TRACK_OFF = 0                 # the handshake's carrier throughout
TRACK_MODEL = 1               # the kernel's carrier at each step (the device circuit's resonance at its force)
TRACK_LOCKED = 2              # that, corrected by the motional reactance the amplifier's STATUS implies

# --- exit reasons -----------------------------------------------------------------------------
EXIT_RUNNING = 0
EXIT_STOPPED = 1              # LINK_STOP was set
EXIT_PORT_LOST = 2            # a read or write failed (LINK_ERRNO), or the port reached its end
EXIT_STATUS_TIMEOUT = 3       # no STATUS for LINK_STATUS_TIMEOUT_NS
EXIT_FAULT = 4                # a STATUS reported a fault (LINK_AMP_FAULTS)
EXIT_VERSION = 5              # a frame of another protocol version (LINK_AMP_VERSION), or ACK BAD_VERSION
EXIT_REFUSED = 6              # the amplifier refused a restart (LINK_ACK_CODE)
EXIT_TX_STALLED = 7           # the port took no byte for LINK_STATUS_TIMEOUT_NS
EXIT_CONTRADICTED = 8         # an INFO answering the HELLO otherwise than the one taken (buffers[BUF_INFO_OTHER])
EXIT_BAD_REPORT = 9           # a value the amplifier reported out of range (LINK_REPORT*)
EXIT_NAMES = ("running", "stopped", "port lost", "status timeout", "fault", "version", "refused", "stalled",
              "contradicted", "bad report")

# --- LINK_REPORT: the value out of range (docs/amp-protocol.md H10) ----------------------------------------------
REPORT_STATE = 1
REPORT_BUFFER_FILL = 2
REPORT_ENVELOPE_MV = 3
REPORT_CARRIER_MHZ = 4
REPORT_PHASE_CDEG = 5
REPORT_PLAY_BACKWARDS = 6     # play index before START's or an earlier STATUS's
REPORT_PLAY_AHEAD = 7         # play index past what the envelope rate allows since START
REPORT_PLAY_RATE = 8          # the play index moved otherwise than its own time_us says (value: samples moved)
REPORT_TIME_BACKWARDS = 9     # time_us ran backwards (value: us, signed)
REPORT_CARRIER_ACK = 10       # SET_CARRIER's achieved carrier (value; LOW: the carrier asked)
REPORT_START_ACK = 11         # START's ACK value (value; LOW: the index asked)
#: (field, why) for the STATUS reports' messages.
REPORT_TEXT = {
    REPORT_STATE: ("state", "no such state"),
    REPORT_BUFFER_FILL: ("buffer_fill", "more than its buffer holds"),
    REPORT_ENVELOPE_MV: ("envelope_mv", "more than its own clamp (A1)"),
    REPORT_CARRIER_MHZ: ("carrier_mhz", "a carrier outside its own range"),
    REPORT_PHASE_CDEG: ("phase_cdeg", "not a phase"),
    REPORT_PLAY_BACKWARDS: ("play_index", "it ran backwards, or before the index START named"),
    REPORT_PLAY_AHEAD: ("play_index", "further than the envelope rate allows since START"),
    REPORT_PLAY_RATE: ("samples played", "not what its own time_us says passed at the envelope rate"),
    REPORT_TIME_BACKWARDS: ("time_us step", "its clock ran backwards"),
}

# --- buffers: uint8[BUF_ROWS, BUF_BYTES] ------------------------------------------------------
BUF_RX = 0                    # bytes received, up to a delimiter
BUF_BODY = 1                  # a decoded body
BUF_FRAME = 2                 # a body being built
BUF_TX = 3                    # encoded bytes waiting for the port
BUF_INFO = 4                  # the INFO body the handshake took (H1)
BUF_INFO_OTHER = 5            # an INFO body that contradicted it (EXIT_CONTRADICTED)
BUF_ROWS = 6
BUF_BYTES = 1 << 16
#: The longest time (ns) between two steps when no frame is due sooner, and the shortest one ahead.
WAKE_NS = 250_000
MIN_WAKE_NS = 20_000
#: What settle() returns once the run is over.
RUN_OVER = -1
#: LINK_OFFSET_NS before any RUNNING STATUS: larger than any offset.
NO_OFFSET_NS = 1 << 62
#: How fast (s per s) the host lets the amplifier's clock offset grow: an amplifier clock up to this much
#: slower than the host's is followed (a crystal is within 1e-4).
CLOCK_SKEW = 1e-4
#: Float32 envelope scratch (samples): the largest frame.
ENVELOPE_SCRATCH = codec.MAX_FRAME_SAMPLES
#: A SET_CARRIER unanswered this long (ns) counts as refused, and the next may go.
CARRIER_ACK_NS = 100_000_000
#: An achieved carrier may lie this share of the carrier asked from it (or a carrier step, if more) (H2).
CARRIER_ECHO_FRACTION = 1e-3
#: The amplifier's envelope clock may run this much faster than the host's (a play index is checked against
#: the time since START: H10), and its play index may move this much (share, samples) otherwise than its own
#: time_us says between two RUNNING STATUS.
RATE_TOLERANCE = 1e-3
PLAY_SLACK = 2
STEP_TOLERANCE = 0.01
#: The share of the way from its correction to the shift a STATUS implies that the lock moves per STATUS
#: (a first-order filter over STATUS periods: the amplifier's measurement is quantised, 0.01 degree and 1 uA).
LOCK_GAIN = 0.25

_F4 = np.float32
_F8 = np.float64
_I8 = np.int64
_U32 = 1 << 32
_KERNEL = dict(nogil=True, cache=True, error_model="numpy")


@njit(inline="always", **_KERNEL)
def _unwrap(index_u32: int, near: int) -> int:
    """The number whose low 32 bits are ``index_u32`` closest to ``near`` (a stream index, a time in us)."""
    delta = (index_u32 - near) % _U32
    if delta >= _U32 // 2:
        delta -= _U32
    return near + delta


@njit(**_KERNEL)
def _report(link: np.ndarray, code: int, value: int, low: int, high: int) -> int:
    """Note the report ``code`` out of range (its value, the range allowed) in the link; ``code``."""
    link[LINK_REPORT] = code
    link[LINK_REPORT_VALUE] = value
    link[LINK_REPORT_LOW] = low
    link[LINK_REPORT_HIGH] = high
    return code


@njit(**_KERNEL)
def carrier_echo_tolerance_mhz(link: np.ndarray, asked_mhz: int) -> int:
    """How far (mHz) an achieved carrier may lie from ``asked_mhz``: a carrier step, or CARRIER_ECHO_FRACTION of
    it if more (H2)."""
    return max(link[LINK_CARRIER_STEP_MHZ], np.int64(asked_mhz * CARRIER_ECHO_FRACTION))


@njit(**_KERNEL)
def carrier_echo_ok(link: np.ndarray, asked_mhz: int, achieved_mhz: int) -> bool:
    """Whether a SET_CARRIER ACK's ``achieved_mhz`` may answer ``asked_mhz``: within the amplifier's carrier range
    (LINK_CARRIER_MIN/MAX_MHZ, from INFO) and carrier_echo_tolerance_mhz of the carrier asked (H2, H10)."""
    return (link[LINK_CARRIER_MIN_MHZ] <= achieved_mhz <= link[LINK_CARRIER_MAX_MHZ]
            and abs(achieved_mhz - asked_mhz) <= carrier_echo_tolerance_mhz(link, asked_mhz))


@njit(**_KERNEL)
def status_problem(link: np.ndarray, body: np.ndarray) -> int:
    """The first value of the STATUS ``body`` out of the document's ranges or the amplifier's INFO (H10: state,
    buffer_fill, envelope_mv, carrier_mhz, phase_cdeg; the play index is :func:`_play_problem`'s), noted in the
    link as :func:`_report` does; 0 if none."""
    p = PAYLOAD
    state = int(body[p + STATUS_STATE])
    if state > codec.STATE_FAULT:
        return _report(link, REPORT_STATE, state, 0, codec.STATE_FAULT)
    fill = codec.get_u16(body, p + STATUS_BUFFER_FILL)
    if fill > link[LINK_BUFFER_SAMPLES]:
        return _report(link, REPORT_BUFFER_FILL, fill, 0, link[LINK_BUFFER_SAMPLES])
    envelope_mv = codec.get_i32(body, p + STATUS_ENVELOPE_MV)
    if abs(envelope_mv) > link[LINK_MAX_MV]:
        return _report(link, REPORT_ENVELOPE_MV, envelope_mv, -link[LINK_MAX_MV], link[LINK_MAX_MV])
    carrier_mhz = codec.get_u32(body, p + STATUS_CARRIER_MHZ)
    if carrier_mhz != 0 and not link[LINK_CARRIER_MIN_MHZ] <= carrier_mhz <= link[LINK_CARRIER_MAX_MHZ]:
        return _report(link, REPORT_CARRIER_MHZ, carrier_mhz, link[LINK_CARRIER_MIN_MHZ], link[LINK_CARRIER_MAX_MHZ])
    phase_cdeg = codec.get_i16(body, p + STATUS_PHASE_CDEG)
    if abs(phase_cdeg) > 18000:
        return _report(link, REPORT_PHASE_CDEG, phase_cdeg, -18000, 18000)
    return 0


@njit(**_KERNEL)
def _play_problem(link: np.ndarray, body: np.ndarray, now_ns: int) -> int:
    """The play index of a PRIMING or RUNNING STATUS checked (H10): not before the last START's index nor an
    earlier STATUS's, not past what the envelope rate (RATE_TOLERANCE) allows since START went out, and, from one
    RUNNING STATUS to the next, moved by what its own time_us says passed (STEP_TOLERANCE, PLAY_SLACK). A REPORT_*
    code noted as :func:`_report` does, or 0 (the check's state then moves on)."""
    p = PAYLOAD
    state = body[p + STATUS_STATE]
    if state != codec.STATE_PRIMING and state != codec.STATE_RUNNING:
        return 0
    index = _unwrap(codec.get_u32(body, p + STATUS_PLAY_INDEX), link[LINK_WRITTEN])
    rate_hz = link[LINK_ENVELOPE_HZ]
    if index < link[LINK_CHECK_INDEX]:
        return _report(link, REPORT_PLAY_BACKWARDS, index, link[LINK_CHECK_INDEX], link[LINK_WRITTEN])
    elapsed_s = max(now_ns - link[LINK_START_NS], 0) * 1e-9
    highest = link[LINK_START_INDEX] + np.int64(elapsed_s * rate_hz * (1.0 + RATE_TOLERANCE)) + PLAY_SLACK
    if index > highest:
        return _report(link, REPORT_PLAY_AHEAD, index, link[LINK_CHECK_INDEX], highest)
    time_us = codec.get_u32(body, p + codec.STATUS_TIME_US)
    if state == codec.STATE_RUNNING:
        if link[LINK_CHECK_TIME_US] >= 0:
            step_us = _unwrap(time_us, link[LINK_CHECK_TIME_US]) - link[LINK_CHECK_TIME_US]
            if step_us < 0:
                return _report(link, REPORT_TIME_BACKWARDS, step_us, 0, _U32 // 2)
            expected = step_us * 1e-6 * rate_hz
            low = int(np.floor(expected * (1.0 - STEP_TOLERANCE))) - PLAY_SLACK
            high = int(np.ceil(expected * (1.0 + STEP_TOLERANCE))) + PLAY_SLACK
            moved = index - link[LINK_CHECK_RUN_INDEX]
            if not low <= moved <= high:
                return _report(link, REPORT_PLAY_RATE, moved, low, high)
        link[LINK_CHECK_TIME_US] = time_us
        link[LINK_CHECK_RUN_INDEX] = index
    link[LINK_CHECK_INDEX] = index
    return 0


@njit(**_KERNEL)
def check_status(link: np.ndarray, body: np.ndarray, now_ns: int) -> int:
    """Check the STATUS ``body`` received at ``now_ns`` (H10): :func:`status_problem`, then the play index against
    the last START (:func:`start_checks`) and the stream's next index LINK_WRITTEN; 0, or the REPORT_* code of a
    value out of range, noted in the link."""
    problem = status_problem(link, body)
    return problem if problem != 0 else _play_problem(link, body, now_ns)


@njit(**_KERNEL)
def _take_status(link: np.ndarray, body: np.ndarray, now_ns: int) -> int:
    """Check a STATUS payload (docs/amp-protocol.md 3.2, H10) and copy it into the link; 0, or the REPORT_* code
    of a value out of range (nothing copied then)."""
    problem = check_status(link, body, now_ns)
    if problem != 0:
        return problem
    p = PAYLOAD
    link[LINK_AMP_PLAY_INDEX] = _unwrap(codec.get_u32(body, p + STATUS_PLAY_INDEX), link[LINK_WRITTEN])
    link[LINK_AMP_FILL] = codec.get_u16(body, p + STATUS_BUFFER_FILL)
    link[LINK_AMP_STATE] = body[p + STATUS_STATE]
    link[LINK_AMP_FAULTS] = body[p + STATUS_FAULTS]
    link[LINK_AMP_FRAMES_OK] = codec.get_u32(body, p + STATUS_FRAMES_OK)
    link[LINK_AMP_FRAMES_BAD] = codec.get_u32(body, p + STATUS_FRAMES_BAD)
    link[LINK_AMP_FRAMES_REJECTED] = codec.get_u32(body, p + STATUS_FRAMES_REJECTED)
    link[LINK_AMP_SEQUENCE_GAPS] = codec.get_u32(body, p + STATUS_SEQUENCE_GAPS)
    link[LINK_AMP_UNDERRUNS] = codec.get_u32(body, p + STATUS_UNDERRUNS)
    link[LINK_AMP_WATCHDOG_TRIPS] = codec.get_u32(body, p + STATUS_WATCHDOG_TRIPS)
    link[LINK_AMP_ENVELOPE_MV] = codec.get_i32(body, p + STATUS_ENVELOPE_MV)
    link[LINK_AMP_VOLTAGE_MV_RMS] = codec.get_u32(body, p + STATUS_VOLTAGE_MV_RMS)
    link[LINK_AMP_CURRENT_UA_RMS] = codec.get_u32(body, p + STATUS_CURRENT_UA_RMS)
    link[LINK_AMP_PHASE_CDEG] = codec.get_i16(body, p + STATUS_PHASE_CDEG)
    link[LINK_AMP_CARRIER_MHZ] = codec.get_u32(body, p + STATUS_CARRIER_MHZ)
    link[LINK_AMP_TIME_US] = codec.get_u32(body, p + codec.STATUS_TIME_US)
    link[LINK_STATUS_NS] = now_ns
    link[LINK_STATUSES] += 1
    return 0


@njit(**_KERNEL)
def _same_info(body: np.ndarray, taken: np.ndarray) -> bool:
    """Whether the INFO ``body`` says what the INFO ``taken`` says (their payloads; their seq may differ)."""
    for k in range(PAYLOAD, PAYLOAD + codec.INFO_BYTES):
        if body[k] != taken[k]:
            return False
    return True


@njit(**_KERNEL)
def _take_frame(link: np.ndarray, encoded: np.ndarray, length: int, body: np.ndarray, info: np.ndarray,
                now_ns: int) -> int:
    """Decode and act on one frame from the amplifier (``encoded[:length]``, no delimiter).

    Returns 1 for a STATUS, 0 for anything else, or -EXIT_VERSION for a frame of another
    version or an ACK BAD_VERSION, -EXIT_BAD_REPORT for a value out of range (H10),
    -EXIT_CONTRADICTED for an INFO answering the handshake's HELLO otherwise than the
    INFO taken (``info[0]``; it is copied to ``info[1]``). Bad frames are counted and
    dropped; INFO frames answering an earlier HELLO are passed over.
    """
    if length == 0:
        return 0  # an empty frame (a lone delimiter)
    size = codec.cobs_decode(encoded, length, body)
    kind = codec.open_body(body, size) if size >= 0 else codec.CHECK_SHORT
    if kind == codec.CHECK_VERSION:
        link[LINK_AMP_VERSION] = body[0]
        return -EXIT_VERSION
    if kind < 0:
        link[LINK_RX_BAD] += 1
        return 0
    payload = size - PAYLOAD - codec.CRC_BYTES
    if kind == MSG_STATUS and payload == STATUS_BYTES:
        return 1 if _take_status(link, body, now_ns) == 0 else -EXIT_BAD_REPORT
    if kind == codec.MSG_INFO and payload == codec.INFO_BYTES:
        if codec.get_u32(body, PAYLOAD + codec.INFO_HELLO_NONCE) != link[LINK_NONCE] or _same_info(body, info[0]):
            link[LINK_INFOS_STALE] += 1  # an answer to an earlier HELLO, or the same INFO again
            return 0
        info[1, :size] = body[:size]
        return -EXIT_CONTRADICTED
    if kind == MSG_ACK and payload == codec.ACK_BYTES:
        link[LINK_ACK_TYPE] = body[PAYLOAD + ACK_ACKED_TYPE]
        link[LINK_ACK_CODE] = body[PAYLOAD + ACK_CODE]
        link[LINK_ACK_VALUE] = codec.get_u32(body, PAYLOAD + ACK_VALUE)
        if link[LINK_ACK_CODE] == codec.ACK_BAD_VERSION:
            link[LINK_AMP_VERSION] = link[LINK_ACK_VALUE]
            return -EXIT_VERSION
        if (link[LINK_ACK_TYPE] == MSG_START and link[LINK_ACK_CODE] == codec.ACK_OK
                and link[LINK_ACK_VALUE] != link[LINK_START_INDEX] % _U32):
            _report(link, REPORT_START_ACK, link[LINK_ACK_VALUE], link[LINK_START_INDEX], link[LINK_START_INDEX])
            return -EXIT_BAD_REPORT
        if link[LINK_ACK_TYPE] == MSG_SET_CARRIER and link[LINK_CARRIER_PENDING_NS] >= 0:
            if link[LINK_ACK_CODE] == codec.ACK_OK:
                if not carrier_echo_ok(link, link[LINK_CARRIER_ASKED_MHZ], link[LINK_ACK_VALUE]):
                    _report(link, REPORT_CARRIER_ACK, link[LINK_ACK_VALUE], link[LINK_CARRIER_ASKED_MHZ],
                            link[LINK_CARRIER_ASKED_MHZ])
                    return -EXIT_BAD_REPORT
                link[LINK_CARRIER_MHZ] = link[LINK_ACK_VALUE]
            else:
                link[LINK_CARRIER_REFUSED] += 1
            link[LINK_CARRIER_PENDING_NS] = -1
        return 0
    link[LINK_RX_BAD] += 1  # a type the host does not expect, or a wrong length
    return 0


@njit(**_KERNEL)
def _queue(link: np.ndarray, buffers: np.ndarray, payload_length: int, msg_type: int, end: int) -> int:
    """Seal the body in BUF_FRAME (payload written) as the next host frame, appended to BUF_TX at ``end``;
    the new end."""
    seq = link[LINK_SEQ]
    link[LINK_SEQ] = (seq + 1) & 0xFFFF
    return end + codec.seal(buffers[BUF_FRAME], payload_length, msg_type, seq, buffers[BUF_TX][end:])


@njit(**_KERNEL)
def frame_line_bytes(samples: int) -> int:
    """The most bytes an ENVELOPE frame of ``samples`` samples takes on the line: its body (2 x samples + 10), COBS's
    code bytes (one per 254 started) and the delimiter; 2 x samples + 12 up to 121 samples (docs/amp-protocol.md 1)."""
    body_bytes = PAYLOAD + ENVELOPE_SAMPLES + 2 * samples + codec.CRC_BYTES
    return body_bytes + body_bytes // 254 + 2


@njit(**_KERNEL)
def start_checks(link: np.ndarray) -> None:
    """A new START (LINK_START_INDEX, sent after LINK_START_NS): the play index checks (H10) begin again from it."""
    link[LINK_CHECK_INDEX] = link[LINK_START_INDEX]
    link[LINK_CHECK_TIME_US] = -1
    link[LINK_CHECK_RUN_INDEX] = link[LINK_START_INDEX]


@njit(**_KERNEL)
def _queue_start(link: np.ndarray, buffers: np.ndarray, now_ns: int, end: int) -> int:
    """Queue a START from LINK_WRITTEN with the target fill as prefill (a restart after the watchdog), at ``now_ns``
    (ns: before it can go out, so no sample of it plays earlier)."""
    frame = buffers[BUF_FRAME]
    codec.put_u32(frame, PAYLOAD + START_ENVELOPE_HZ, link[LINK_ENVELOPE_HZ])
    codec.put_u32(frame, PAYLOAD + START_INDEX, link[LINK_WRITTEN])
    link[LINK_START_INDEX] = link[LINK_WRITTEN]
    link[LINK_START_NS] = now_ns
    start_checks(link)
    codec.put_u16(frame, PAYLOAD + START_PREFILL, min(link[LINK_TARGET_FILL], link[LINK_BUFFER_SAMPLES]))
    return _queue(link, buffers, START_BYTES, MSG_START, end)


@njit(**_KERNEL)
def _queue_envelope(table: np.ndarray, state: np.ndarray, link: np.ndarray, buffers: np.ndarray,
                    envelope: np.ndarray, times: np.ndarray, delay_ns: int, late: bool, priming: bool,
                    end: int) -> int:
    """Render the next frame's samples and queue its ENVELOPE frame; the new end.

    The samples come from the audio driver's own compiled callback (LINK_CALLBACK), called
    as PortAudio calls it: one block of the pointer table, its record and statistics
    (the time info says its first sample plays ``delay_ns`` from now; the callback's status
    flags say BLOCK_LATE, the stream having skipped ahead before it, or BLOCK_PRIMING, part
    of a prefill). So the render kernel is compiled once, for both drivers. Its samples are in
    [-1, 1] of full scale (the output guard); each becomes round(32767 x sample), clamped
    to +-LINK_LEVEL_LIMIT (the host's envelope scale: H3), and anything else (never
    expected) is sent as 0.
    """
    count = link[LINK_FRAME_SAMPLES]
    first = int(state[STATE_NEXT_INDEX])
    times[0] = 0.0
    times[1] = 0.0
    times[2] = delay_ns * 1e-9
    flags = (BLOCK_LATE if late else 0) | (BLOCK_PRIMING if priming else 0)
    call_stream_callback(link[LINK_CALLBACK], envelope.ctypes.data, count, times.ctypes.data, flags,
                         table.ctypes.data)
    frame = buffers[BUF_FRAME]
    codec.put_u32(frame, PAYLOAD + ENVELOPE_FIRST_INDEX, first)
    limit = min(max(link[LINK_LEVEL_LIMIT], 0), 32767)
    for k in range(count):
        value = envelope[k]
        level = int(round(value * 32767.0)) if abs(value) <= 1.0 else 0  # NaN is not <= 1
        codec.put_i16(frame, PAYLOAD + ENVELOPE_SAMPLES + 2 * k, min(max(level, -limit), limit))
    queued = _queue(link, buffers, ENVELOPE_SAMPLES + 2 * count, MSG_ENVELOPE, end)
    if priming:
        link[LINK_PRIME_BYTES] += queued - end
    end = queued
    link[LINK_WRITTEN] = first + count
    link[LINK_FRAMES_SENT] += 1
    return end


@njit(**_KERNEL)
def _queue_carrier(state: np.ndarray, link: np.ndarray, buffers: np.ndarray, now_ns: int, end: int) -> int:
    """While tracking: queue a SET_CARRIER when the carrier of the kernel's last step, plus the lock's
    correction (within the amplifier's range), is LINK_CARRIER_STEP_MHZ or more from the amplifier's; one at
    a time (its ACK, or CARRIER_ACK_NS without one, clears the way). The new end."""
    if link[LINK_CARRIER_PENDING_NS] >= 0:
        if now_ns - link[LINK_CARRIER_PENDING_NS] < CARRIER_ACK_NS:
            return end
        link[LINK_CARRIER_PENDING_NS] = -1
        link[LINK_CARRIER_REFUSED] += 1
    step_hz = state[STATE_STEP_CARRIER_HZ]
    if not 0.0 < step_hz <= link[LINK_CARRIER_MAX_MHZ] * 1e-3 * 2.0:  # NaN too: a corrupt state sends nothing
        return end
    wanted_mhz = min(max(np.int64(round(step_hz * 1000.0)) + link[LINK_LOCK_OFFSET_MHZ], link[LINK_CARRIER_MIN_MHZ]),
                     link[LINK_CARRIER_MAX_MHZ])
    if abs(wanted_mhz - link[LINK_CARRIER_MHZ]) < link[LINK_CARRIER_STEP_MHZ] or \
            end + MAX_ENCODED > buffers[BUF_TX].shape[0]:
        return end
    codec.put_u32(buffers[BUF_FRAME], PAYLOAD, wanted_mhz)
    link[LINK_CARRIER_ASKED_MHZ] = wanted_mhz
    link[LINK_CARRIER_PENDING_NS] = now_ns
    link[LINK_CARRIER_SETS] += 1
    return _queue(link, buffers, 4, MSG_SET_CARRIER, end)


@njit(**_KERNEL)
def _lock(cfg: np.ndarray, dev: np.ndarray, state: np.ndarray, link: np.ndarray) -> None:
    """From a RUNNING STATUS (no carrier change in flight, enough current): the motional reactance its RMS
    voltage, current and phase imply (the amplifier's output across the shunt, then C0's current taken out),
    against the model's at the kernel's last force and the amplifier's carrier, gives how far the plate's
    resonance sits from the model's; the lock's correction moves LOCK_GAIN of the way there, within
    LINK_LOCK_RANGE_MHZ."""
    carrier_mhz = link[LINK_AMP_CARRIER_MHZ]
    if (link[LINK_CARRIER_PENDING_NS] >= 0 or carrier_mhz != link[LINK_CARRIER_MHZ] or carrier_mhz <= 0
            or link[LINK_AMP_CURRENT_UA_RMS] < max(link[LINK_LOCK_MIN_CURRENT_UA], 1)
            or link[LINK_AMP_VOLTAGE_MV_RMS] <= 0):
        return
    carrier_hz = carrier_mhz * 1e-3
    omega = 2.0 * np.pi * carrier_hz
    phase_rad = link[LINK_AMP_PHASE_CDEG] * (np.pi / 18000.0)  # of the current against the voltage
    total = (link[LINK_AMP_VOLTAGE_MV_RMS] * 1e-3) / (link[LINK_AMP_CURRENT_UA_RMS] * 1e-6) * complex(
        np.cos(-phase_rad), np.sin(-phase_rad))
    plate = total - cfg[CFG_SHUNT_OHM]
    if plate == 0.0:
        return
    motional = 1.0 / plate - 1j * omega * cfg[CFG_C0_F]
    if motional == 0.0:
        return
    measured_ohm = (1.0 / motional).imag
    cell = force_cell(cfg, dev, state[STATE_FORCE_N])
    slope = device_value(dev, DEV_REACTANCE_SLOPE_OHM_PER_HZ, cell)
    model_ohm = device_value(dev, DEV_REACTANCE_OHM, cell) + slope * (carrier_hz - state[STATE_STEP_CARRIER_HZ])
    shift_hz = (model_ohm - measured_ohm) / slope
    if not abs(shift_hz) < np.inf:
        return
    range_hz = link[LINK_LOCK_RANGE_MHZ] * 1e-3
    offset_hz = link[LINK_LOCK_OFFSET_MHZ] * 1e-3
    offset_hz = min(max(offset_hz + LOCK_GAIN * (shift_hz - offset_hz), -range_hz), range_hz)
    link[LINK_LOCK_OFFSET_MHZ] = np.int64(round(offset_hz * 1000.0))
    link[LINK_LOCK_UPDATES] += 1


@njit(**_KERNEL)
def _skip_to(table: np.ndarray, state: np.ndarray, link: np.ndarray, index: int) -> None:
    """Continue the stream at ``index`` (past the next one): the kernel renders on from there as if no
    sample were missing, and the drive ring's skipped samples read 0 (a recording shows the gap)."""
    drive = numba.carray(pointer(table[tab.TAB_DRIVE]), table[tab.TAB_DRIVE_FRAMES], _F4)
    for n in range(max(link[LINK_WRITTEN], index - drive.shape[0]), index):
        drive[n % drive.shape[0]] = 0.0
    state[STATE_NEXT_INDEX] = index
    link[LINK_WRITTEN] = index


# --- the step: every decision of the run, given the time and the bytes -----------------------------------------

@njit(**_KERNEL)
def _end(link: np.ndarray, reason: int) -> int:
    """End the run for ``reason`` (EXIT_*) unless it already ends for another; the reason it ends for."""
    if link[LINK_REASON] == EXIT_RUNNING:
        link[LINK_REASON] = reason
    return link[LINK_REASON]


@njit(**_KERNEL)
def begin(table: np.ndarray, link: np.ndarray, now_ns: int) -> None:
    """Set the step's state for a run that starts at ``now_ns`` (ns) from the table's next sample (the index the
    handshake's START named); the Python side has written the link's first block."""
    state = kernel_views(table)[2]
    link[LINK_WRITTEN] = np.int64(state[STATE_NEXT_INDEX])
    link[LINK_STATUS_NS] = now_ns
    link[LINK_REF_INDEX] = link[LINK_WRITTEN]
    link[LINK_REF_NS] = now_ns
    link[LINK_PRIMED] = 0
    link[LINK_AMP_US] = 0
    link[LINK_OFFSET_NS] = NO_OFFSET_NS
    link[LINK_SYNCED_NS] = now_ns
    link[LINK_TRIPS_AT_START] = link[LINK_AMP_WATCHDOG_TRIPS]
    start_checks(link)
    link[LINK_RX_LENGTH] = 0
    link[LINK_RX_STATUSES] = 0
    link[LINK_TX_FIRST] = 0
    link[LINK_TX_END] = 0
    link[LINK_TX_BEFORE] = -1
    link[LINK_MOVED_NS] = now_ns
    link[LINK_SKIPPED] = 0
    link[LINK_PRIME_NS] = now_ns
    link[LINK_PRIME_BYTES] = 0
    link[LINK_STAGE] = STAGE_STREAMING
    link[LINK_REASON] = EXIT_RUNNING
    link[LINK_EXIT] = EXIT_RUNNING


@njit(**_KERNEL)
def reading(link: np.ndarray) -> bool:
    """Whether the run reads the port now: it streams, no failure and no stop request has come (the STOP tail
    leaves STOP's ACK to the Python side)."""
    return (link[LINK_STAGE] == STAGE_STREAMING and link[LINK_REASON] == EXIT_RUNNING
            and load_acquire(link, LINK_STOP) == 0)


@njit(**_KERNEL)
def on_received(link: np.ndarray, buffers: np.ndarray, count: int, now_ns: int) -> int:
    """Act on ``count`` bytes just read into BUF_RX at LINK_RX_LENGTH, at ``now_ns`` (ns: the time of that read,
    never an earlier reading: a host held up before it must not date the STATUS frames that piled up meanwhile
    to before the hold, and take the hold for the amplifier's silence, H7). ``count < 0``: the read failed with
    errno ``-count`` (the port is lost). Each whole frame is decoded and checked (H10); the EXIT_* reason the
    run now ends for, or EXIT_RUNNING."""
    if count < 0:
        link[LINK_ERRNO] = -count
        return _end(link, EXIT_PORT_LOST)
    rx = buffers[BUF_RX]
    body = buffers[BUF_BODY]
    info = buffers[BUF_INFO:BUF_INFO_OTHER + 1]
    rx_length = link[LINK_RX_LENGTH]
    end = rx_length + count
    start = 0
    for i in range(rx_length, end):
        if rx[i] == 0:
            taken = _take_frame(link, rx[start:i], i - start, body, info, now_ns)
            if taken < 0:
                link[LINK_RX_LENGTH] = 0
                return _end(link, -taken)
            link[LINK_RX_STATUSES] += taken
            start = i + 1
    rx_length = end - start
    for k in range(rx_length if start > 0 else 0):  # keep the unfinished frame at the front
        rx[k] = rx[start + k]
    if rx_length > MAX_ENCODED:  # no delimiter where one had to be: drop the bytes, count a bad frame
        link[LINK_RX_BAD] += 1
        rx_length = 0
    link[LINK_RX_LENGTH] = rx_length
    return EXIT_RUNNING


@njit(**_KERNEL)
def _react(cfg: np.ndarray, dev: np.ndarray, state: np.ndarray, link: np.ndarray, buffers: np.ndarray,
           now_ns: int) -> None:
    """Act on the STATUS frames taken since the last step (the last one's values): a fault ends the run; a
    watchdog trip (A4: the amplifier went IDLE) queues START again from the next sample (H7: recover); a RUNNING
    one moves the phase lock and puts its play position on the host's clock. Then the run ends for a refused
    START or no STATUS for LINK_STATUS_TIMEOUT_NS."""
    if link[LINK_RX_STATUSES] > 0:
        link[LINK_RX_STATUSES] = 0
        if link[LINK_AMP_FAULTS] != 0:
            _end(link, EXIT_FAULT)
            return
        if link[LINK_AMP_WATCHDOG_TRIPS] > link[LINK_TRIPS_AT_START]:
            link[LINK_TRIPS_AT_START] = link[LINK_AMP_WATCHDOG_TRIPS]
            link[LINK_RESTARTS] += 1
            before = link[LINK_TX_END]
            link[LINK_TX_END] = _queue_start(link, buffers, now_ns, before)
            link[LINK_PRIME_NS] = now_ns
            link[LINK_PRIME_BYTES] = link[LINK_TX_END] - before
            link[LINK_PRIMED] = 0
            link[LINK_REF_INDEX] = link[LINK_WRITTEN]
            link[LINK_REF_NS] = now_ns
        elif link[LINK_AMP_STATE] == codec.STATE_RUNNING:
            if link[LINK_TRACK] == TRACK_LOCKED:
                _lock(cfg, dev, state, link)
            # The amplifier played sample play_index at its time time_us: on the host's clock, at time_us + offset,
            # where offset is the smallest (receive time - time_us) seen, the one the line delayed least (allowed
            # to grow by CLOCK_SKEW, for a slower amplifier clock).
            amp_ns = _unwrap(link[LINK_AMP_TIME_US], link[LINK_AMP_US]) * 1000
            link[LINK_AMP_US] = amp_ns // 1000
            link[LINK_OFFSET_NS] = min(np.int64(now_ns - amp_ns), link[LINK_OFFSET_NS] + np.int64(
                (now_ns - link[LINK_SYNCED_NS]) * CLOCK_SKEW))
            link[LINK_SYNCED_NS] = now_ns
            link[LINK_REF_INDEX] = link[LINK_AMP_PLAY_INDEX]
            link[LINK_REF_NS] = amp_ns + link[LINK_OFFSET_NS]
            link[LINK_PRIMED] = 1
    if link[LINK_ACK_TYPE] == MSG_START and link[LINK_ACK_CODE] != codec.ACK_OK:
        _end(link, EXIT_REFUSED)
    elif now_ns - link[LINK_STATUS_NS] > link[LINK_STATUS_TIMEOUT_NS]:
        _end(link, EXIT_STATUS_TIMEOUT)


@njit(**_KERNEL)
def play_position(link: np.ndarray, now_ns: int) -> float:
    """The stream index the amplifier plays at ``now_ns``: from the reference, at the envelope rate once primed."""
    if link[LINK_PRIMED] == 0:
        return float(link[LINK_REF_INDEX])
    return link[LINK_REF_INDEX] + (now_ns - link[LINK_REF_NS]) * 1e-9 * link[LINK_ENVELOPE_HZ]


@njit(**_KERNEL)
def _pace(table: np.ndarray, state: np.ndarray, link: np.ndarray, buffers: np.ndarray, envelope: np.ndarray,
          times: np.ndarray, now_ns: int) -> None:
    """Queue the frames due at ``now_ns``: skip ahead of a play position that passed what was sent, then render
    frames while fewer than the target fill (and a frame, once primed) are ahead of it, never more than the
    amplifier's buffer ahead of it, with room left in BUF_TX for a START or a STOP; each followed by a SET_CARRIER if
    tracking moved the carrier."""
    rate_hz = link[LINK_ENVELOPE_HZ]
    frame_samples = link[LINK_FRAME_SAMPLES]
    room = buffers[BUF_TX].shape[0] - frame_line_bytes(frame_samples) - MAX_ENCODED
    play = play_position(link, now_ns)
    if link[LINK_WRITTEN] < play - frame_samples:
        # The amplifier played past what it was sent (an underrun: it plays 0 and moves on), so samples for those
        # indices would be refused as already played: skip the stream ahead of it.
        link[LINK_LATE] += 1
        _skip_to(table, state, link, np.int64(play) + frame_samples)
        link[LINK_SKIPPED] = 1
    end = link[LINK_TX_END]
    while (link[LINK_WRITTEN] < play + link[LINK_TARGET_FILL] + frame_samples * link[LINK_PRIMED]
           and link[LINK_WRITTEN] + frame_samples <= play + link[LINK_BUFFER_SAMPLES] and end <= room):
        delay_ns = int((link[LINK_WRITTEN] - play) * 1e9 / rate_hz)
        end = _queue_envelope(table, state, link, buffers, envelope, times, delay_ns, link[LINK_SKIPPED] != 0,
                              link[LINK_PRIMED] == 0, end)
        link[LINK_SKIPPED] = 0
        if link[LINK_TRACK] != TRACK_OFF:
            end = _queue_carrier(state, link, buffers, now_ns, end)
    link[LINK_TX_END] = end


@njit(**_KERNEL)
def _begin_stop(link: np.ndarray, buffers: np.ndarray) -> None:
    """The run ended (LINK_REASON). H8: STOP right after the last envelope frame, to be flushed whole, also when a
    failure ended the run (H7), unless the port is lost."""
    link[LINK_STOP_SEQ] = -1
    if link[LINK_REASON] == EXIT_PORT_LOST:
        _finish(link, False)
        link[LINK_TX_FIRST] = link[LINK_TX_END] = 0  # nothing more goes to a lost port, queued frames included
        return
    codec.put_u16(buffers[BUF_FRAME], PAYLOAD, min(max(link[LINK_STOP_RAMP_MS], 1), 0xFFFF))
    link[LINK_STOP_SEQ] = link[LINK_SEQ]
    link[LINK_TX_END] = _queue(link, buffers, codec.STOP_BYTES, codec.MSG_STOP, link[LINK_TX_END])
    link[LINK_STAGE] = STAGE_FLUSHING


@njit(**_KERNEL)
def _finish(link: np.ndarray, lost: bool) -> None:
    """The run is over: LINK_EXIT is its reason. A STOP that did not go out whole has no seq (LINK_STOP_SEQ -1);
    a requested stop that could not flush it ends as a failure (the port lost if ``lost``, else stalled)."""
    pending = link[LINK_TX_END] > link[LINK_TX_FIRST]
    if pending:
        link[LINK_STOP_SEQ] = -1
    reason = link[LINK_REASON]
    if reason == EXIT_STOPPED and (lost or pending):
        reason = EXIT_PORT_LOST if lost else EXIT_TX_STALLED
    link[LINK_EXIT] = reason
    link[LINK_STAGE] = STAGE_DONE


@njit(**_KERNEL)
def step(table: np.ndarray, link: np.ndarray, buffers: np.ndarray, envelope: np.ndarray, times: np.ndarray,
         now_ns: int) -> int:
    """One step of the run at ``now_ns`` (ns), after the bytes read were given to :func:`on_received`: react to
    the STATUS frames taken, check the timeouts, queue the frames due (or, once the run ends, STOP); the bytes
    now waiting for the port, BUF_TX[LINK_TX_FIRST:LINK_TX_END] (hand what the port takes to :func:`on_written`).

    ``table`` is the pointer table (its kernel's cfg set for envelope output), ``envelope``
    float32 of at least LINK_FRAME_SAMPLES samples, ``times`` float64[3] (the callback's
    time info).
    """
    if link[LINK_STAGE] == STAGE_STREAMING:
        if link[LINK_REASON] == EXIT_RUNNING and load_acquire(link, LINK_STOP) != 0:
            _end(link, EXIT_STOPPED)
        if link[LINK_REASON] == EXIT_RUNNING:
            cfg, dev, state = kernel_views(table)[:3]
            _react(cfg, dev, state, link, buffers, now_ns)
            if link[LINK_REASON] == EXIT_RUNNING:
                _pace(table, state, link, buffers, envelope, times, now_ns)
        if link[LINK_REASON] != EXIT_RUNNING:
            _begin_stop(link, buffers)
    pending = link[LINK_TX_END] - link[LINK_TX_FIRST]
    link[LINK_TX_BEFORE] = link[LINK_TX_FIRST] if pending > 0 else -1
    return pending


@njit(**_KERNEL)
def on_written(link: np.ndarray, count: int) -> int:
    """The port took ``count`` of the waiting bytes (0: it is full for now; negative: the write failed with errno
    ``-count``, the port is lost); the bytes still waiting."""
    if count < 0:
        link[LINK_ERRNO] = -count
        if link[LINK_STAGE] == STAGE_FLUSHING:
            _finish(link, True)
        elif link[LINK_STAGE] == STAGE_STREAMING:
            _end(link, EXIT_PORT_LOST)
        return 0
    if count == 0:
        link[LINK_TX_BLOCKED] += 1
    link[LINK_TX_FIRST] += count
    if link[LINK_TX_FIRST] >= link[LINK_TX_END]:
        link[LINK_TX_FIRST] = 0
        link[LINK_TX_END] = 0
    return link[LINK_TX_END] - link[LINK_TX_FIRST]


@njit(**_KERNEL)
def settle(link: np.ndarray, now_ns: int) -> int:
    """After the step's bytes were offered to the port, at ``now_ns`` (ns): a port that took none of them for
    LINK_STATUS_TIMEOUT_NS ends the run (stalled) or the STOP tail; the prefill out, the amplifier plays from
    now. The time (ns) of the next step: when the next frame is due, at most WAKE_NS away (at once when the run
    just ended, so that its STOP goes out); RUN_OVER once the run is over (LINK_EXIT says why)."""
    stage = link[LINK_STAGE]
    if stage == STAGE_DONE:
        return RUN_OVER
    first, end, before = link[LINK_TX_FIRST], link[LINK_TX_END], link[LINK_TX_BEFORE]
    if before >= 0:
        if first != before or end == 0:
            link[LINK_MOVED_NS] = now_ns
        elif now_ns - link[LINK_MOVED_NS] > link[LINK_STATUS_TIMEOUT_NS]:
            if stage == STAGE_FLUSHING:
                _finish(link, False)
                return RUN_OVER
            _end(link, EXIT_TX_STALLED)
    if stage == STAGE_FLUSHING:
        if end <= first:
            _finish(link, False)
            return RUN_OVER
        return now_ns + WAKE_NS
    if link[LINK_REASON] != EXIT_RUNNING:
        return now_ns
    rate_hz = link[LINK_ENVELOPE_HZ]
    if link[LINK_PRIMED] == 0 and end == 0 and link[LINK_WRITTEN] >= link[LINK_REF_INDEX] + link[LINK_TARGET_FILL]:
        # The prefill is out: the amplifier starts playing once its last byte arrived, at the link's measured rate
        # from when it began to go out (a long prefill on a slow line is still on its way), or about now.
        link[LINK_PRIMED] = 1
        link[LINK_REF_NS] = now_ns
        if link[LINK_LINE_BYTES_PER_S] > 0:
            link[LINK_REF_NS] = max(now_ns, link[LINK_PRIME_NS] + np.int64(
                link[LINK_PRIME_BYTES] * 1e9 / link[LINK_LINE_BYTES_PER_S]))
    next_due_ns = link[LINK_REF_NS] + np.int64((link[LINK_WRITTEN] - link[LINK_TARGET_FILL]
                                                - link[LINK_FRAME_SAMPLES] - link[LINK_REF_INDEX]) * 1e9 / rate_hz)
    return min(now_ns + WAKE_NS, max(next_due_ns, now_ns + MIN_WAKE_NS))


# --- the production loop: the real clock and the port's descriptor, around the step --------------------------

@njit(**_KERNEL)
def _read_port(link: np.ndarray, buffers: np.ndarray, now_ns: int) -> int:
    """Read what the port (LINK_FD, non-blocking) holds into the step (:func:`on_received`), each read timed by
    the clock after it; the time of the last read that returned bytes, else ``now_ns``."""
    rx = buffers[BUF_RX]
    while reading(link):
        offset = link[LINK_RX_LENGTH]
        got = read_fd(link[LINK_FD], rx.ctypes.data + offset, rx.shape[0] - offset)
        if got == 0:  # a tty with VMIN = 0 says "nothing now" so; a silent loss shows as no STATUS (H7)
            break
        if got < 0:
            error = errno()
            if error == EAGAIN:
                break
            if error != EINTR:
                on_received(link, buffers, -error, now_ns)
            continue
        now_ns = max(now_ns, monotonic_ns())
        on_received(link, buffers, got, now_ns)
    return now_ns


@njit(**_KERNEL)
def _write_port(link: np.ndarray, buffers: np.ndarray, pending: int) -> None:
    """Offer the ``pending`` bytes the step left in BUF_TX to the port until it takes them all, is full, or
    fails (:func:`on_written`)."""
    tx = buffers[BUF_TX]
    while pending > 0:
        wrote = write_fd(link[LINK_FD], tx.ctypes.data + link[LINK_TX_FIRST], pending)
        if wrote < 0:
            error = errno()
            if error == EINTR:
                continue
            wrote = 0 if error == EAGAIN else -error
        pending = on_written(link, wrote)
        if wrote <= 0:
            break


@njit(**_KERNEL)
def stream(table: np.ndarray, link: np.ndarray, buffers: np.ndarray, envelope: np.ndarray,
           times: np.ndarray) -> int:
    """Stream until LINK_STOP or a failure (module docstring) on the port LINK_FD with CLOCK_MONOTONIC, running
    :func:`step` as the module docstring says; the EXIT_* reason, also in LINK_EXIT. Arguments as :func:`step`."""
    begin(table, link, monotonic_ns())
    while True:
        now_ns = _read_port(link, buffers, monotonic_ns())
        _write_port(link, buffers, step(table, link, buffers, envelope, times, now_ns))
        wake_ns = settle(link, monotonic_ns())
        if wake_ns == RUN_OVER:
            return link[LINK_EXIT]
        sleep_until_ns(wake_ns)
