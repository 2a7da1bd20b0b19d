"""``file://`` input: a finger trajectory from a CSV file, read whole when opened.

``file:///abs/path.csv`` or ``file://relative/path.csv``. The file is UTF-8 text; lines
starting with ``#`` and blank lines are skipped; the first other line is the header.
Columns (any order): ``t`` (s, in [0, MAX_INPUT_S], strictly increasing), ``x_mm``,
``y_mm`` (within :func:`tpad_rt.limits.position_range_mm` of the device's plate, or of
the default 130 x 60 mm plate without a device: [-130, 260] x [-60, 120] mm), and
optionally ``force_n`` (N, in [0, MAX_FORCE_N]; without it the renderer's default force
applies) and ``down`` (1 touching, 0 lifted; without it every sample touches). Values
are plain numbers; nothing in the file is evaluated. Errors name the file and line:
``traj.csv:7: column x_mm: must be a finite number in [-130, 260] mm, got 'nan'``.

Bounded memory: the file must be a regular file of at most MAX_TRAJECTORY_BYTES
(64 MiB, refused before a byte is read) with at most MAX_TRAJECTORY_ROWS samples
(2,000,000, refused at the line past them) and lines of at most 4096 bytes. It is
parsed line by line into chunks of FINGER_DTYPE rows (33 bytes each), so at most 66 MB
of samples are held, about twice that while the chunks are joined, never the whole text.
"""

from __future__ import annotations

import math
from typing import BinaryIO
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from tpad_rt.csv_lines import check_header, data_lines
from tpad_rt.decimal_text import parse_decimal
from tpad_rt.errors import ConfigError, printable
from tpad_rt.files import open_regular
from tpad_rt.inputs.base import FINGER_DTYPE, Input, position_range
from tpad_rt.limits import MAX_FORCE_N, MAX_INPUT_S, MAX_TRAJECTORY_BYTES, MAX_TRAJECTORY_ROWS
from tpad_rt.urls import Url, UrlForm

if TYPE_CHECKING:
    from tpad_rt.device import Device

#: The accepted URL.
FORMS = (UrlForm("file", "/path/trajectory.csv"),)

_REQUIRED = ("t", "x_mm", "y_mm")
_OPTIONAL = ("force_n", "down")
_HEADER = "t,x_mm,y_mm[,force_n][,down]"
#: Samples parsed into one array before it is kept (about 2 MB).
_CHUNK_ROWS = 65_536


class FileInput(Input):
    """The samples of a trajectory CSV (module docstring), held in a FINGER_DTYPE array."""

    def __init__(self, samples: np.ndarray):
        self.samples = samples
        self.samples.setflags(write=False)

    @property
    def duration_s(self) -> float:
        """Time (s) of the file's last sample."""
        return float(self.samples["t_s"][-1])

    def samples_between(self, t0_s: float, t1_s: float) -> np.ndarray:
        """The samples with ``t0_s < t_s <= t1_s`` (see :meth:`Input.samples_between`)."""
        times = self.samples["t_s"]
        return self.samples[np.searchsorted(times, t0_s, "right"):np.searchsorted(times, t1_s, "right")]


def open_url(url: Url, *, device: Device | None = None) -> FileInput:
    """Load the trajectory ``url`` names, its positions checked against ``device``'s plate.

    Raises ConfigError for a missing path, an option, or a bad file (:func:`load_trajectory`).
    """
    FORMS[0].read(url)
    if not url.target:
        raise url.fail("missing the file path", FORMS)
    return load_trajectory(url.target, device)


def load_trajectory(path: str | Path, device: Device | None = None) -> FileInput:
    """Read the trajectory CSV at ``path`` (module docstring), positions on ``device``'s plate.

    Raises ConfigError ``path:line: problem`` for a missing, unreadable, non-regular or
    oversized file, text that is not UTF-8, a bad header (missing, unknown or repeated
    column), a row with the wrong number of fields, a value that is not a finite number
    in its range, a time not after the one before, more than MAX_TRAJECTORY_ROWS
    samples, a line longer than 4096 bytes, or a file without data rows.
    """
    name = printable(str(path))
    with open_regular(path, "trajectories", MAX_TRAJECTORY_BYTES) as stream:
        _refuse_too_many_rows(name, stream)
        return FileInput(_parse(name, data_lines(name, stream), _Ranges.of(device)))


def _refuse_too_many_rows(path: str, stream: BinaryIO) -> None:
    """ConfigError ``path:line: more than MAX_TRAJECTORY_ROWS samples`` for a file with more data rows than that,
    before any row is parsed (a file of millions of rows is refused in a second, not after parsing them all);
    the stream is left at its start. Only a file with more lines than that is looked at line by line."""
    if stream.read().count(b"\n") + 1 <= MAX_TRAJECTORY_ROWS + 1:  # rows + the header, at most
        stream.seek(0)
        return
    stream.seek(0)
    rows = -1  # the header is the first line that is neither blank nor a comment
    for number, raw in enumerate(stream, start=1):
        stripped = raw.strip()
        if stripped and not stripped.startswith(b"#"):
            rows += 1
            if rows > MAX_TRAJECTORY_ROWS:
                raise ConfigError(f"{path}:{number}: more than {MAX_TRAJECTORY_ROWS:,} samples, the most a "
                                  "trajectory may hold")
    stream.seek(0)


class _Ranges:
    """The accepted value of each numeric column: ``(low, high, unit)``."""

    def __init__(self, x_mm: tuple[float, float], y_mm: tuple[float, float]):
        self.bounds = {"t": (0.0, MAX_INPUT_S, "s"), "x_mm": (*x_mm, "mm"), "y_mm": (*y_mm, "mm"),
                       "force_n": (0.0, MAX_FORCE_N, "N")}

    @classmethod
    def of(cls, device: Device | None) -> _Ranges:
        """The ranges on ``device``'s plate (the default plate without one)."""
        return cls(*position_range(device))


def _parse(path: str, lines: Iterator[tuple[int, list[str]]], ranges: _Ranges) -> np.ndarray:
    first = next(lines, None)
    if first is None:
        raise ConfigError(f"{path}: empty; expected a header line {_HEADER} then one sample per line")
    header_line, header = first
    columns = check_header(path, header_line, header, _REQUIRED, _OPTIONAL, _HEADER)
    places = [_FIELD_ORDER.index(name) for name in columns]
    chunks: list[np.ndarray] = []
    rows: list[tuple[float, float, float, float, bool]] = []
    previous_t_s = -math.inf
    for line, fields in lines:
        where = f"{path}:{line}"  # (more rows than the limit were refused before: _refuse_too_many_rows)
        if len(fields) != len(columns):
            raise ConfigError(f"{where}: {len(fields)} fields, expected {len(columns)} ({','.join(columns)})")
        row: list[float | bool] = [math.nan, math.nan, math.nan, math.nan, True]
        for place, name, field in zip(places, columns, fields):
            row[place] = _value(where, name, field, ranges)
        t_s = row[0]
        if t_s <= previous_t_s:
            raise ConfigError(
                f"{where}: column t: must be greater than the previous line's {previous_t_s:g}, got {t_s:g}"
            )
        previous_t_s = t_s
        rows.append(tuple(row))  # type: ignore[arg-type]
        if len(rows) == _CHUNK_ROWS:
            chunks.append(np.array(rows, dtype=FINGER_DTYPE))
            rows.clear()
    chunks.append(np.array(rows, dtype=FINGER_DTYPE))
    samples = np.concatenate(chunks) if len(chunks) > 1 else chunks[0]
    if not len(samples):
        raise ConfigError(f"{path}: no samples after the header")
    return samples


#: Columns in the order of FINGER_DTYPE's fields (``t`` fills ``t_s``).
_FIELD_ORDER = ("t", "x_mm", "y_mm", "force_n", "down")


def _value(where: str, column: str, text: str, ranges: _Ranges) -> float | bool:
    """The value of ``column`` written ``text``; ConfigError naming the range unless it is in it."""
    if column == "down":
        if text not in ("0", "1"):
            raise ConfigError(f"{where}: column down: must be 0 or 1, got '{printable(text)}'")
        return text == "1"
    try:
        value = parse_decimal(text)
    except ValueError:
        value = math.nan
    low, high, unit = ranges.bounds[column]
    if not low <= value <= high:  # False for NaN; the bounds are finite
        raise ConfigError(f"{where}: column {column}: must be a finite number in [{low:g}, {high:g}] {unit}, "
                          f"got '{printable(text)}'")
    return value
