"""The renderer's telemetry: rows drained from the kernel's ring, what the output measured per block, totals,
push-to-DAC latency, and the recording of a run.

API map
-------
TelemetryLog(pipeline, rate_hz)
    ``drain(table)`` (the watcher, and readers, call it), ``take()`` (the rows since the
    last take, by TEL_NAMES column, and the output's measured columns), ``totals()``,
    ``record(path)``, ``recording``, ``failure`` (a recording's limit error),
    ``write_recording(metadata, texture=None, texture_t0_s=0.0)``;
    measurements: ``begin_measurements(names)``, ``add_measurements(t_s, columns)``,
    ``end_measurements()``, ``measured_names``;
    latency: ``note_push(index, pushed_ns)``, ``latency_ms()`` (over every block drained)
joined(chunks, names=TEL_NAMES) -> dict[str, ndarray]
    telemetry chunks concatenated column by column

An output that measures something per block (``sim://``: the simulated plate's amplitude
and friction) has its driver hand the measurements here, each block's with the block's
time ``t``: :meth:`TelemetryLog.take` gives them as more columns of the same rows, and
holds a row back until its measurement came (or the measuring ended), so a reader sees
every block once, measured. Everything kept between takes is bounded (MAX_PENDING_ROWS
rows each), whoever reads or not. A recording keeps the measurements too, and the finger
samples (at most MAX_RECORDED_FINGERS), and writes them as ``tpad-rt render`` does: the
simulated plate's columns, and ``departed`` judged against the texture under the finger
(:func:`tpad_rt.felt.judge_blocks`).

Push-to-DAC latency covers every block of every run: each drain folds the blocks since the
last one into a :class:`~tpad_rt.log_histogram.LogHistogram` (fixed memory), so a run whose
finger stopped long before its end still reports the latency of its pushes.

One lock orders the drains: any thread may call any method (:meth:`TelemetryLog.note_push`
takes none: one producer at a time, the Renderer's).
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from tpad_rt.errors import ConfigError, TpadError
from tpad_rt.felt import DEPARTURE_TOLERANCE_MU, judge_blocks
from tpad_rt.files import check_writable_target
from tpad_rt.kernel import table_layout as tab
from tpad_rt.kernel.layout import FLAG_FAULT, FLAG_POWER, FLAG_SHAPER_LIMIT, FLAG_VOLTAGE, TEL_NAMES
from tpad_rt.limits import MAX_RECORDING_SAMPLES, MAX_TRAJECTORY_ROWS
from tpad_rt.log_histogram import LogHistogram
from tpad_rt.pipeline import Pipeline
from tpad_rt.realtime import CallbackTable
from tpad_rt.recording import Recording, write_recording
from tpad_rt.texture import CompiledTexture

#: Telemetry rows kept for :meth:`TelemetryLog.take` between calls (the oldest go first); as many rows wait at
#: most for their measurements, and as many measured blocks for their rows.
MAX_PENDING_ROWS = 2**18
#: The range (ms) of the latency histogram: a latency outside it counts at its end.
LATENCY_RANGE_MS = (1e-3, 1e4)
#: Finger samples a recording keeps to judge its blocks with (as many as a trajectory file may hold): past them
#: it is written without ``departed``.
MAX_RECORDED_FINGERS = MAX_TRAJECTORY_ROWS

class TelemetryLog:
    """Telemetry of ``pipeline``'s runs at ``rate_hz`` (Hz: the drive's sample rate, for recordings)."""

    def __init__(self, pipeline: Pipeline, rate_hz: int):
        self._pipeline = pipeline
        self.rate_hz = rate_hz
        self._lock = threading.Lock()
        self._pending: deque[dict[str, np.ndarray]] = deque()
        self._pending_rows = 0
        self._measured = _MeasuredBlocks()
        self._push_ns = np.zeros(len(pipeline.arrays.finger), dtype=np.int64)  # by finger ring row
        self._latency_ms = LogHistogram(*LATENCY_RANGE_MS)
        self._latency_table: CallbackTable | None = None  # the run whose blocks were folded in last
        self._latency_next = 0  # that run's next block to fold in
        self._latency_seen: int | None = None  # the finger count the block before it read (None: not known)
        self._totals: dict[str, Any] = {"blocks": 0, "voltage_saturated": 0, "power_saturated": 0,
                                        "fault_blocks": 0, "energy_w": 0.0, "peak_w": 0.0, "plate_peak_w": 0.0,
                                        "peak_v": 0.0, "kick_blocks": 0, "peak_outside_kicks_v": 0.0}
        self._record_path: Path | None = None
        self._recorded: list[dict[str, np.ndarray]] = []
        self._recorded_measured: list[dict[str, np.ndarray]] = []  # "t" and the measured names, oldest first
        self._recorded_fingers: list[np.ndarray] = []  # FINGER_DTYPE chunks, oldest first (emptied past the limit)
        self._fingers_kept: int | None = 0  # samples in _recorded_fingers; None once past MAX_RECORDED_FINGERS
        self._finger_from = 0  # the next finger sample to copy out of the ring while recording
        self._drive_chunks: list[np.ndarray] = []
        self._drive_from = 0  # next drive sample to copy out of the ring while recording
        self._record_from = 0  # the recording's first drive sample
        self._truncated: str | None = None  # why the recording ended early, if it did
        #: The recording's limit error (see :meth:`drain`), or None.
        self.failure: TpadError | None = None

    def drain(self, table: CallbackTable) -> None:
        """Move new telemetry rows (and drive samples, when recording) out of ``table``'s rings.

        When recording and the drive ring wrapped past samples not yet copied, or the recording grew past
        MAX_RECORDING_SAMPLES, the recording ends where it was whole and :attr:`failure` holds a TpadError
        saying so (for the renderer's watcher to end the run with; drain itself never raises).
        """
        with self._lock:
            frames = table.drive_end()  # not the next index: a block's samples reach the ring after it is published
            self._fold_latency(table)
            rows = self._pipeline.drain_telemetry()
            count = len(rows["t"])
            if count == 0:
                return
            flags = rows["saturated"]
            totals = self._totals
            totals["blocks"] += count
            totals["voltage_saturated"] += int(np.count_nonzero(flags & FLAG_VOLTAGE))
            totals["power_saturated"] += int(np.count_nonzero(flags & FLAG_POWER))
            totals["fault_blocks"] += int(np.count_nonzero(flags & FLAG_FAULT))
            totals["energy_w"] += float(rows["power_w"].sum())
            totals["peak_w"] = max(totals["peak_w"], float(rows["power_w"].max()))
            totals["plate_peak_w"] = max(totals["plate_peak_w"], float(rows["plate_w"].max()))
            kicks = (flags & FLAG_SHAPER_LIMIT) != 0
            totals["kick_blocks"] += int(np.count_nonzero(kicks))
            totals["peak_v"] = max(totals["peak_v"], float(rows["voltage_v"].max()))
            totals["peak_outside_kicks_v"] = max(totals["peak_outside_kicks_v"],
                                                 float(rows["voltage_v"][~kicks].max(initial=0.0)))
            self._keep(self._measured.rows_in(rows))
            if self._record_path is not None:
                self._record(rows, table, frames)

    def _keep(self, chunks: list[dict[str, np.ndarray]]) -> None:
        """Keep ``chunks`` (rows ready to read) for :meth:`take`, at most MAX_PENDING_ROWS (under the lock)."""
        for chunk in chunks:
            self._pending.append(chunk)
            self._pending_rows += len(chunk["t"])
        self._pending_rows = _keep_newest(self._pending, self._pending_rows)

    def _record(self, rows: dict[str, np.ndarray], table: CallbackTable, frames: int | None) -> None:
        """Keep ``rows`` and the drive samples up to ``frames`` (None: none yet) for the recording (under the
        lock). Past a limit
        the recording ends where it was whole (the metadata says why: ``truncated``) and :attr:`failure` says
        so."""
        if self._truncated is not None:
            return
        if not self._recorded:
            self._drive_from = self._record_from = round(float(rows["t"][0]) * self.rate_hz)
        frames = self._drive_from if frames is None else frames
        problem = None
        if frames - self._drive_from > len(table.drive):
            problem = (f"{frames - self._drive_from} drive samples were due but the ring holds {len(table.drive)}: "
                       "the recording lost samples (the watcher thread was held up for too long)")
        elif frames - self._record_from > MAX_RECORDING_SAMPLES:
            problem = (f"longer than the {MAX_RECORDING_SAMPLES} drive samples a recording may keep in memory "
                       f"({MAX_RECORDING_SAMPLES / self.rate_hz:.0f} s at {self.rate_hz} Hz); record shorter runs")
        if problem is not None:
            self._truncated = problem
            self.failure = TpadError(f"record: {problem}; the recording ends before it (written on stop)")
            return
        self._recorded.append(rows)
        fingers, self._finger_from = self._pipeline.fingers_since(self._finger_from)
        if self._fingers_kept is not None and self._fingers_kept + len(fingers) <= MAX_RECORDED_FINGERS:
            self._recorded_fingers.append(fingers)
            self._fingers_kept += len(fingers)
        else:
            self._recorded_fingers, self._fingers_kept = [], None
        self._drive_chunks.append(table.drive[np.arange(self._drive_from, frames) % len(table.drive)])
        self._drive_from = max(self._drive_from, frames)

    def take(self) -> dict[str, np.ndarray]:
        """The rows drained since the last take (at most MAX_PENDING_ROWS, the newest), by TEL_NAMES column and
        :attr:`measured_names` column (NaN for a block the output did not measure); a row whose measurement has
        not come yet stays for the next take."""
        with self._lock:
            chunks, self._pending, self._pending_rows = list(self._pending), deque(), 0
            names = (*TEL_NAMES, *self._measured.names)
        return joined(chunks, names)

    # --- what the output measured per block ------------------------------------------

    @property
    def measured_names(self) -> tuple[str, ...]:
        """The columns the output measures per block (as :meth:`begin_measurements` named them; none before)."""
        return self._measured.names

    def begin_measurements(self, names: Sequence[str]) -> None:
        """From now on an output measures ``names`` per block (:meth:`add_measurements`): rows wait for theirs.
        Raises ValueError for no names, a name of the telemetry's, or other names than a previous run's (a
        reader's columns stay the same)."""
        with self._lock:
            self._measured.begin(tuple(names))

    def add_measurements(self, t_s: npt.NDArray[np.float64], columns: Mapping[str, npt.NDArray[np.float64]]) -> None:
        """The measurements of the blocks starting at stream times ``t_s`` (s, each its telemetry row's ``t``,
        oldest first): ``columns`` by :attr:`measured_names` name, as long as ``t_s``. Raises ValueError for
        columns of other names or lengths, or before :meth:`begin_measurements`."""
        with self._lock:
            self._measured.add(np.asarray(t_s, dtype=np.float64), columns)
            self._keep(self._measured.release())
            if self._record_path is not None and self._truncated is None and len(t_s):
                self._recorded_measured.append({"t": np.asarray(t_s, dtype=np.float64),
                                                **{name: np.asarray(columns[name], dtype=np.float64)
                                                   for name in self._measured.names}})

    def end_measurements(self) -> None:
        """The output measures no more blocks (it closed or failed): rows stop waiting (a row drained from now
        on without a measurement has NaN in the measured columns)."""
        with self._lock:
            self._measured.end()
            self._keep(self._measured.release())

    # --- latency ---------------------------------------------------------------------

    def note_push(self, index: int, pushed_ns: int) -> None:
        """Finger sample number ``index`` (the pipeline's count before it) was pushed at CLOCK_MONOTONIC
        ``pushed_ns`` (ns). Takes no lock: one producer at a time."""
        self._push_ns[index % len(self._push_ns)] = pushed_ns

    def latency_ms(self) -> dict[str, float]:
        """``latency_ms_p50``, ``latency_ms_p99`` (ms; NaN without any): from the push of each finger sample to
        the DAC time of the first block that read it, over every block drained (every run's), within 1.2 %
        (:class:`~tpad_rt.log_histogram.LogHistogram`). A sample read by a run's first block (pushed before
        the run) or whose push time was overwritten before its block was drained (more than ``finger_ring``
        pushes since) is not counted."""
        with self._lock:
            return {f"latency_ms_p{q}": self._latency_ms.percentile(q) for q in (50, 99)}

    def _fold_latency(self, table: CallbackTable) -> None:
        """Add the latencies of ``table``'s blocks since the last fold to the histogram (under the lock)."""
        if table is not self._latency_table:
            self._latency_table, self._latency_next, self._latency_seen = table, 0, None
        blocks, first = table.blocks_since(self._latency_next)
        if not len(blocks):
            return
        counts = blocks[:, tab.BLOCK_FINGER_COUNT]
        seen = self._latency_seen  # what the block before them read (None: not known, or lost from the ring)
        before = int(counts[0]) if seen is None or first != self._latency_next else seen
        self._latency_ms.add(self._latencies_ms(before, blocks))
        self._latency_next, self._latency_seen = first + len(blocks), int(counts[-1])

    def _latencies_ms(self, before: int, blocks: np.ndarray) -> np.ndarray:
        """Push-to-DAC latency (ms) of each finger sample first read by one of ``blocks`` (oldest first), the
        block before them having read ``before`` samples."""
        counts = np.r_[before, blocks[:, tab.BLOCK_FINGER_COUNT]]
        new = np.diff(counts)
        first_seen = np.flatnonzero(new > 0)  # the blocks that read new samples
        new = new[first_seen]
        samples = np.repeat(counts[first_seen + 1], new) - (np.arange(new.sum()) - np.repeat(np.cumsum(new) - new, new)) - 1
        out_ns = np.repeat(blocks[first_seen, tab.BLOCK_ENTRY_NS] + blocks[first_seen, tab.BLOCK_DAC_DELAY_NS], new)
        pushed = int(self._pipeline.arrays.finger_count[0])
        kept = samples >= pushed - len(self._push_ns)  # their push times are still in the ring
        return (out_ns[kept] - self._push_ns[samples[kept] % len(self._push_ns)]) * 1e-6

    def totals(self) -> dict[str, Any]:
        """``blocks``, ``voltage_saturated``, ``power_saturated``, ``fault_blocks``, ``kick_blocks`` (blocks in
        which the shaper held the drive at a limit: FLAG_SHAPER_LIMIT) (counts), ``energy_w`` (the sum of the
        blocks' drive power, W), ``peak_w`` (W), ``plate_peak_w`` (the most power the plate held as the model has
        it, W), ``peak_v`` (the drive's peak, V) and ``peak_outside_kicks_v`` (its peak in the other blocks, V),
        over every row drained."""
        with self._lock:
            return dict(self._totals)

    def record(self, path: str | Path) -> None:
        """Record the drive and telemetry from now on, for :meth:`write_recording` to ``path`` (.npz). Raises
        ConfigError unless ``path`` ends in ``.npz``, or when it is no place to write (no folder, one that cannot
        be written, a FIFO: :func:`tpad_rt.files.check_writable_target`), before anything is recorded."""
        path = Path(path)
        if path.suffix.lower() != ".npz":
            raise ConfigError(f"record: the path must end in .npz, got '{path}'")
        check_writable_target(path, "recordings")
        with self._lock:
            self._record_path = path
            self._recorded, self._drive_chunks, self._truncated = [], [], None
            self._recorded_measured, self._recorded_fingers, self._fingers_kept, self._finger_from = [], [], 0, 0
            self.failure = None

    @property
    def recording(self) -> bool:
        """True after :meth:`record` until :meth:`write_recording`."""
        return self._record_path is not None

    def write_recording(self, metadata: dict[str, Any], texture: CompiledTexture | None = None,
                        texture_t0_s: float = 0.0) -> None:
        """Write what was recorded, with ``metadata`` and ``truncated`` (None, or why the recording ended
        early), to the path :meth:`record` named (the format of ``tpad-rt render``,
        :mod:`tpad_rt.recording`), and stop recording. The output's measurements are columns of their blocks
        (NaN for a block not measured); with the simulated plate's friction (``achieved_mu``) and ``texture``
        (the one rendered all along, started at stream time ``texture_t0_s``, s), ``departed`` judges each
        block against it under the recorded finger, and ``metadata`` gets ``departure_tolerance_mu``."""
        with self._lock:
            path, self._record_path = self._record_path, None
            recorded, drive_chunks, truncated = self._recorded, self._drive_chunks, self._truncated
            measured_chunks, finger_chunks = self._recorded_measured, self._recorded_fingers
            fingers_kept, names = self._fingers_kept is not None, self._measured.names
            self._recorded, self._drive_chunks, self._truncated = [], [], None
            self._recorded_measured, self._recorded_fingers = [], []
        assert path is not None, "record() first"
        drive = np.concatenate(drive_chunks) if drive_chunks else np.zeros(0, dtype=np.float32)
        blocks = joined(recorded)
        metadata = {**metadata, "truncated": truncated}
        if names:
            blocks.update(_at_times(blocks["t"], joined(measured_chunks, ("t", *names)), names))
        if "achieved_mu" in blocks and texture is not None and fingers_kept and finger_chunks:
            judged = judge_blocks(blocks, np.concatenate(finger_chunks), texture,
                                  block_s=metadata["block_frames"] / self.rate_hz,
                                  mu_floor=self._pipeline.options.mu_floor, texture_t0_s=texture_t0_s)
            blocks["departed"] = judged.departed.astype(np.int8)
            metadata["departure_tolerance_mu"] = DEPARTURE_TOLERANCE_MU
        write_recording(path, Recording(self.rate_hz, drive, blocks, metadata))


def joined(chunks: list[dict[str, np.ndarray]], names: Sequence[str] = TEL_NAMES) -> dict[str, np.ndarray]:
    """Telemetry chunks concatenated column by column, for ``names`` (empty columns when there are no chunks; NaN
    for a chunk without one of the names)."""
    return {name: np.concatenate([np.zeros(0, dtype=np.int64 if name == "saturated" else np.float64)]
                                 + [chunk.get(name, np.full(len(chunk["t"]), math.nan)) for chunk in chunks])
            for name in names}


class _MeasuredBlocks:
    """Telemetry rows joined with what the output measured of the same blocks, by the block's time ``t`` (s).

    The watcher may drain a block's row before its driver hands in the block's measurement:
    while measuring (``live``) rows wait until a measurement as new as they are came. Not
    thread-safe (the log's lock guards it); each queue holds at most MAX_PENDING_ROWS rows.
    """

    def __init__(self) -> None:
        self.names: tuple[str, ...] = ()
        self.live = False
        self._waiting: deque[dict[str, np.ndarray]] = deque()  # rows, oldest first
        self._measured: deque[dict[str, np.ndarray]] = deque()  # measured blocks ("t" and names), oldest first
        self._measured_rows = 0

    def begin(self, names: tuple[str, ...]) -> None:
        if not names or set(names) & set(TEL_NAMES) or len(set(names)) != len(names):
            raise ValueError(f"measured columns: need distinct names that are not the telemetry's, got {names}")
        if self.names and names != self.names:
            raise ValueError(f"measured columns: {names}, but the log's readers have {self.names}")
        self.names, self.live = names, True

    def end(self) -> None:
        self.live = False

    def add(self, t_s: np.ndarray, columns: Mapping[str, npt.NDArray[np.float64]]) -> None:
        if not self.names:
            raise ValueError("add_measurements: begin_measurements() first")
        if set(columns) != set(self.names) or any(len(columns[name]) != len(t_s) for name in self.names):
            raise ValueError(f"add_measurements: need {self.names} for {len(t_s)} blocks, got "
                             f"{ {name: len(column) for name, column in columns.items()} }")
        if len(t_s):
            self._measured.append({"t": t_s, **{name: np.asarray(columns[name], dtype=np.float64)
                                                for name in self.names}})
            self._measured_rows = _keep_newest(self._measured, self._measured_rows + len(t_s))

    def rows_in(self, rows: dict[str, np.ndarray]) -> list[dict[str, np.ndarray]]:
        """Take drained ``rows``; the rows now ready to read (measured, or not waiting for a measurement)."""
        if not self.names:
            return [rows]
        self._waiting.append(rows)
        return self.release()

    def release(self) -> list[dict[str, np.ndarray]]:
        """The waiting rows that are ready, with their measured columns; drops measurements of rows gone by."""
        if not self._waiting:
            return []
        rows = joined(list(self._waiting))
        measured = joined(list(self._measured), ("t", *self.names))
        ready = len(rows["t"])
        if self.live:  # wait for a measurement as new as the row, but keep at most MAX_PENDING_ROWS waiting
            newest_s = measured["t"][-1] if len(measured["t"]) else -math.inf
            ready = max(int(np.searchsorted(rows["t"], newest_s, side="right")), ready - MAX_PENDING_ROWS)
        self._waiting = deque([{name: column[ready:] for name, column in rows.items()}] if ready < len(rows["t"])
                              else [])
        if ready == 0:
            return []
        out = {name: column[:ready] for name, column in rows.items()}
        out.update(_at_times(out["t"], measured, self.names))
        left = measured["t"] > out["t"][-1]  # measurements of blocks not drained yet
        self._measured = deque([{name: column[left] for name, column in measured.items()}] if left.any() else [])
        self._measured_rows = int(np.count_nonzero(left))
        return [out]


def _at_times(t_s: np.ndarray, measured: dict[str, np.ndarray], names: Sequence[str]) -> dict[str, np.ndarray]:
    """The ``names`` columns of ``measured`` (blocks by their time ``"t"``, s, in order) at the block times ``t_s``
    (s): NaN for a block not measured."""
    at = np.minimum(np.searchsorted(measured["t"], t_s), max(len(measured["t"]) - 1, 0))
    hit = measured["t"][at] == t_s if len(measured["t"]) else np.zeros(len(t_s), dtype=bool)
    columns = {}
    for name in names:
        columns[name] = np.full(len(t_s), math.nan)
        columns[name][hit] = measured[name][at[hit]]
    return columns


def _keep_newest(chunks: deque[dict[str, np.ndarray]], rows: int) -> int:
    """Drop the oldest rows of ``chunks`` (``rows`` in all, each chunk's ``"t"`` as long as its columns) past
    MAX_PENDING_ROWS; the rows left."""
    while rows > MAX_PENDING_ROWS:
        oldest = len(chunks[0]["t"])
        if oldest <= rows - MAX_PENDING_ROWS:
            chunks.popleft()
            rows -= oldest
        else:
            cut = rows - MAX_PENDING_ROWS
            chunks[0] = {name: column[cut:] for name, column in chunks[0].items()}
            rows -= cut
    return rows
