"""The renderer's telemetry: rows drained from the kernel's ring, totals, and the recording of a run.

API map
-------
TelemetryLog(pipeline, rate_hz)
    ``drain(table)`` (the watcher, and readers, call it), ``take()`` (the rows since the
    last take, by TEL_NAMES column), ``totals()``, ``record(path)``, ``recording``,
    ``failure`` (a recording's limit error), ``write_recording(metadata)``
joined(chunks) -> dict[str, ndarray]
    telemetry chunks concatenated column by column

One lock orders the drains: any thread may call any method.
"""

from __future__ import annotations

import threading
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np

from tpad_rt.errors import ConfigError, TpadError
from tpad_rt.files import check_writable_target
from tpad_rt.kernel.layout import FLAG_FAULT, FLAG_POWER, FLAG_VOLTAGE, TEL_NAMES
from tpad_rt.limits import MAX_RECORDING_SAMPLES
from tpad_rt.pipeline import Pipeline
from tpad_rt.realtime import CallbackTable
from tpad_rt.recording import Recording, write_recording

#: Telemetry rows kept for :meth:`TelemetryLog.take` between calls (the oldest go first).
MAX_PENDING_ROWS = 2**18


class TelemetryLog:
    """Telemetry of ``pipeline``'s runs at ``rate_hz`` (Hz: the drive's sample rate, for recordings)."""

    def __init__(self, pipeline: Pipeline, rate_hz: int):
        self._pipeline = pipeline
        self.rate_hz = rate_hz
        self._lock = threading.Lock()
        self._pending: deque[dict[str, np.ndarray]] = deque()
        self._pending_rows = 0
        self._totals: dict[str, Any] = {"blocks": 0, "voltage_saturated": 0, "power_saturated": 0,
                                        "fault_blocks": 0, "energy_w": 0.0, "peak_w": 0.0, "plate_peak_w": 0.0}
        self._record_path: Path | None = None
        self._recorded: list[dict[str, np.ndarray]] = []
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
            frames = table.next_sample
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
            self._pending.append(rows)
            self._pending_rows += count
            while self._pending_rows > MAX_PENDING_ROWS:
                self._pending_rows -= len(self._pending.popleft()["t"])
            if self._record_path is not None:
                self._record(rows, table, frames)

    def _record(self, rows: dict[str, np.ndarray], table: CallbackTable, frames: int) -> None:
        """Keep ``rows`` and the drive samples up to ``frames`` for the recording (under the lock). Past a limit
        the recording ends where it was whole (the metadata says why: ``truncated``) and :attr:`failure` says
        so."""
        if self._truncated is not None:
            return
        if not self._recorded:
            self._drive_from = self._record_from = round(float(rows["t"][0]) * self.rate_hz)
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
        self._drive_chunks.append(table.drive[np.arange(self._drive_from, frames) % len(table.drive)])
        self._drive_from = max(self._drive_from, frames)

    def take(self) -> dict[str, np.ndarray]:
        """The rows drained since the last take (at most MAX_PENDING_ROWS, the newest), by TEL_NAMES column."""
        with self._lock:
            chunks, self._pending, self._pending_rows = list(self._pending), deque(), 0
        return joined(chunks)

    def totals(self) -> dict[str, Any]:
        """``blocks``, ``voltage_saturated``, ``power_saturated``, ``fault_blocks`` (counts), ``energy_w`` (the
        sum of the blocks' drive power, W), ``peak_w`` (W), ``plate_peak_w`` (the most power the plate held as
        the model has it, W), over every row drained."""
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
            self.failure = None

    @property
    def recording(self) -> bool:
        """True after :meth:`record` until :meth:`write_recording`."""
        return self._record_path is not None

    def write_recording(self, metadata: dict[str, Any]) -> None:
        """Write what was recorded, with ``metadata`` and ``truncated`` (None, or why the recording ended
        early), to the path :meth:`record` named (the format of ``tpad-rt render``,
        :mod:`tpad_rt.recording`), and stop recording."""
        with self._lock:
            path, self._record_path = self._record_path, None
            recorded, drive_chunks, truncated = self._recorded, self._drive_chunks, self._truncated
            self._recorded, self._drive_chunks, self._truncated = [], [], None
        assert path is not None, "record() first"
        drive = np.concatenate(drive_chunks) if drive_chunks else np.zeros(0, dtype=np.float32)
        write_recording(path, Recording(self.rate_hz, drive, joined(recorded), {**metadata, "truncated": truncated}))


def joined(chunks: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Telemetry chunks concatenated column by column (empty columns when there are none)."""
    if not chunks:
        return {name: np.zeros(0, dtype=np.int64 if name == "saturated" else np.float64) for name in TEL_NAMES}
    return {name: np.concatenate([chunk[name] for chunk in chunks]) for name in TEL_NAMES}
