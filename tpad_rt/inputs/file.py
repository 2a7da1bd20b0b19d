"""``file://`` input: a finger trajectory from a CSV file, loaded whole when opened.

``file:///abs/path.csv`` or ``file://relative/path.csv``. The file is UTF-8 text; lines
starting with ``#`` and blank lines are skipped; the first other line is the header.
Columns (any order): ``t`` (s, >= 0, strictly increasing), ``x_mm``, ``y_mm``, and
optionally ``force_n`` (N, >= 0; without it the renderer's default force applies) and
``down`` (1 touching, 0 lifted; without it every sample touches). Values are plain
numbers; nothing in the file is evaluated. Errors name the file and line:
``traj.csv:7: column x_mm: must be a number, got 'abc'``.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from tpad_rt.errors import ConfigError
from tpad_rt.inputs.base import FINGER_DTYPE, Input
from tpad_rt.urls import Url, UrlForm, did_you_mean

#: The accepted URL.
FORMS = (UrlForm("file", "/path/trajectory.csv"),)

_REQUIRED = ("t", "x_mm", "y_mm")
_OPTIONAL = ("force_n", "down")
_HEADER = "t,x_mm,y_mm[,force_n][,down]"
#: Larger files are refused (a 1 kHz trajectory of an hour is about 150 MB less than this).
MAX_FILE_BYTES = 256 * 1024 * 1024


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


def open_url(url: Url) -> FileInput:
    """Load the trajectory ``url`` names; ConfigError for a missing path or option, or a bad file."""
    FORMS[0].read(url)
    if not url.target:
        raise url.fail("missing the file path", FORMS)
    return load_trajectory(url.target)


def load_trajectory(path: str | Path) -> FileInput:
    """Read the trajectory CSV at ``path`` (module docstring).

    Raises ConfigError ``path:line: problem`` for an unreadable or oversized file, a
    bad header (missing, unknown or repeated column), a row with the wrong number of
    fields, a value that is not a finite number in range, a time not after the one
    before, or a file without data rows.
    """
    path = Path(path)
    try:
        if path.stat().st_size > MAX_FILE_BYTES:
            raise ConfigError(f"{path}: larger than {MAX_FILE_BYTES // 2**20} MiB")
        data = path.read_bytes()
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except OSError as error:
        raise ConfigError(f"{path}: cannot read ({error.strerror})") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = data[:error.start].count(b"\n") + 1
        raise ConfigError(f"{path}:{line}: not UTF-8 text") from None
    return FileInput(_parse(path, text))


def _data_lines(text: str) -> list[tuple[int, list[str]]]:
    """``(line number, fields)`` of every line that is neither blank nor a comment."""
    numbered = [(number, line) for number, line in enumerate(text.splitlines(), start=1)
                if line.strip() and not line.lstrip().startswith("#")]
    rows = csv.reader(line for _, line in numbered)
    return [(number, [field.strip() for field in row]) for (number, _), row in zip(numbered, rows)]


def _parse(path: Path, text: str) -> np.ndarray:
    lines = _data_lines(text)
    if not lines:
        raise ConfigError(f"{path}: empty; expected a header line {_HEADER} then one sample per line")
    header_line, header = lines[0]
    columns = _columns(path, header_line, header)
    samples = np.zeros(len(lines) - 1, dtype=FINGER_DTYPE)
    samples["force_n"] = math.nan
    samples["down"] = True
    previous_t_s = -math.inf
    for index, (line, fields) in enumerate(lines[1:]):
        where = f"{path}:{line}"
        if len(fields) != len(columns):
            raise ConfigError(f"{where}: {len(fields)} fields, expected {len(columns)} ({','.join(columns)})")
        for name, field in zip(columns, fields):
            samples[index][_FIELD[name]] = _value(where, name, field)
        t_s = float(samples[index]["t_s"])
        if t_s <= previous_t_s:
            raise ConfigError(
                f"{where}: column t: must be greater than the previous line's {previous_t_s:g}, got {t_s:g}"
            )
        previous_t_s = t_s
    if not len(samples):
        raise ConfigError(f"{path}: no samples after the header")
    return samples


#: The FINGER_DTYPE field each column fills.
_FIELD = {"t": "t_s", "x_mm": "x_mm", "y_mm": "y_mm", "force_n": "force_n", "down": "down"}


def _columns(path: Path, line: int, header: list[str]) -> list[str]:
    known = _REQUIRED + _OPTIONAL
    for name in header:
        if name not in known:
            hint = did_you_mean(name, list(known)) or f" (columns: {', '.join(known)})"
            raise ConfigError(f"{path}:{line}: header: unknown column '{name}'{hint}; expected {_HEADER}")
        if header.count(name) > 1:
            raise ConfigError(f"{path}:{line}: header: column '{name}' appears twice; expected {_HEADER}")
    missing = [name for name in _REQUIRED if name not in header]
    if missing:
        raise ConfigError(f"{path}:{line}: header: missing column {', '.join(missing)}; expected {_HEADER}")
    return header


def _value(where: str, column: str, text: str) -> float | bool:
    if column == "down":
        if text not in ("0", "1"):
            raise ConfigError(f"{where}: column down: must be 0 or 1, got '{text}'")
        return text == "1"
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    low = -math.inf if column in ("x_mm", "y_mm") else 0.0
    if not (math.isfinite(value) and value >= low):
        expected = "a number" if low == -math.inf else "a number >= 0"
        raise ConfigError(f"{where}: column {column}: must be {expected}, got '{text}'")
    return value
