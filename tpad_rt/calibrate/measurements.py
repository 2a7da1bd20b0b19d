"""The measurement files ``tpad-rt calibrate`` reads: impedance sweeps and amplitude measurements (CSV).

Both are UTF-8 CSV with a header line naming the columns (any order); blank lines and
lines starting with ``#`` are skipped (docs/calibration.md "CSV formats").

Impedance sweeps: ``freq_hz`` (Hz, > 0), and either ``z_real_ohm`` with ``z_imag_ohm``
(ohm) or ``z_abs_ohm`` (ohm, > 0) with ``z_phase_deg`` (degrees, the phase of Z: about
-90 for a piezo's capacitance); optionally ``force_n`` (N): one sweep per force. A
file without ``force_n`` is one sweep without contact (0 N).

Amplitude measurements: ``force_n`` (N), ``voltage_v`` (V peak, > 0), ``amplitude_um``
(um peak, > 0), optionally ``freq_hz`` (Hz, the drive frequency of each row).

Every file is a regular file of at most MAX_MEASUREMENT_BYTES with at most
MAX_MEASUREMENT_ROWS rows; every value is a finite number in its column's range. Every
problem is one ConfigError ``file:line: problem``.

API map
-------
read_impedance_sweeps(path) -> list[ImpedanceSweep]     one per force, frequencies ascending
read_amplitudes(path) -> AmplitudeMeasurements
MIN_SWEEP_POINTS, MAX_SWEEPS
    fewest points a sweep may have, most sweeps a file may hold
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from tpad_rt.config.device_ranges import FORCE_SLACK_N, MIN_FORCE_STEP_N
from tpad_rt.csv_lines import check_header, data_lines
from tpad_rt.decimal_text import parse_decimal
from tpad_rt.errors import ConfigError, printable
from tpad_rt.files import open_regular
from tpad_rt.limits import MAX_FORCE_N, MAX_MEASUREMENT_BYTES, MAX_MEASUREMENT_ROWS

#: Fewest points an impedance sweep may have (four parameters are fitted to it).
MIN_SWEEP_POINTS = 20
#: Most sweeps (distinct forces) one file may hold: a device's force table is a few to tens of forces.
MAX_SWEEPS = 256

_Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class _Range:
    """A column's accepted values: ``low < value <= high`` (``low <= value`` when ``low_closed``), in ``unit``."""

    low: float
    high: float
    unit: str
    low_closed: bool = True

    def holds(self, value: float) -> bool:
        above = value >= self.low if self.low_closed else value > self.low
        return above and value <= self.high  # False for NaN

    def text(self) -> str:
        return f"{'[' if self.low_closed else '('}{self.low:g}, {self.high:g}] {self.unit}"


#: The smallest |Z| (ohm) a sweep may hold: below it the admittance overflows; no actuator is a short circuit.
MIN_IMPEDANCE_OHM = 1e-6

#: Each column's range: wide around any real rig's values, bounded so that no reciprocal overflows.
_RANGES = {
    "freq_hz": _Range(1.0, 10e6, "Hz"),
    "z_real_ohm": _Range(-1e12, 1e12, "ohm"),
    "z_imag_ohm": _Range(-1e12, 1e12, "ohm"),
    "z_abs_ohm": _Range(MIN_IMPEDANCE_OHM, 1e12, "ohm"),
    "z_phase_deg": _Range(-180.0, 180.0, "degrees"),
    "force_n": _Range(0.0, MAX_FORCE_N, "N"),
    "voltage_v": _Range(1e-6, 10_000.0, "V"),
    "amplitude_um": _Range(1e-6, 1000.0, "um"),
}

_IMPEDANCE_FORM = "freq_hz,z_real_ohm,z_imag_ohm[,force_n] or freq_hz,z_abs_ohm,z_phase_deg[,force_n]"
_AMPLITUDE_FORM = "force_n,voltage_v,amplitude_um[,freq_hz]"


@dataclass(frozen=True)
class _Table:
    """The columns of a measurement file, with the line each row came from."""

    name: str
    columns: dict[str, _Array]
    lines: npt.NDArray[np.int64]


def _rows(name: str, lines: Iterator[tuple[int, list[str]]], columns: list[str]) -> _Table:
    values: list[list[float]] = []
    numbers: list[int] = []
    for line, fields in lines:
        where = f"{name}:{line}"
        if len(values) == MAX_MEASUREMENT_ROWS:
            raise ConfigError(f"{where}: more than {MAX_MEASUREMENT_ROWS:,} rows, the most a measurement file may hold")
        if len(fields) != len(columns):
            raise ConfigError(f"{where}: {len(fields)} fields, expected {len(columns)} ({','.join(columns)})")
        row = []
        for column, text in zip(columns, fields):
            try:
                value = parse_decimal(text)
            except ValueError:
                value = math.nan
            bounds = _RANGES[column]
            if not bounds.holds(value):
                raise ConfigError(f"{where}: column {column}: must be a finite number in {bounds.text()}, "
                                  f"got '{printable(text)}'")
            row.append(value)
        values.append(row)
        numbers.append(line)
    if not values:
        raise ConfigError(f"{name}: no rows after the header")
    table = np.array(values, dtype=np.float64)
    return _Table(name, {column: table[:, index] for index, column in enumerate(columns)},
                  np.array(numbers, dtype=np.int64))


def _read(path: str | Path, what: str, required: tuple[str, ...], optional: tuple[str, ...], form: str,
          check: Callable[[str, list[str]], None] | None = None) -> _Table:
    """The rows of the CSV at ``path`` with a header of ``required`` and ``optional`` columns; ``check(name,
    columns)`` raises ConfigError for a header that is otherwise wrong, before any row is read."""
    name = printable(str(path))
    with open_regular(path, what, MAX_MEASUREMENT_BYTES) as stream:
        lines = data_lines(name, stream)
        first = next(lines, None)
        if first is None:
            raise ConfigError(f"{name}: empty; expected a header line {form} then one row per line")
        header_line, header = first
        columns = check_header(name, header_line, header, required, optional, form)
        if check is not None:
            check(name, columns)
        return _rows(name, lines, columns)


def _check_impedance_form(name: str, columns: list[str]) -> None:
    """ConfigError unless ``columns`` hold exactly one of the two impedance forms."""
    cartesian: list[str] = [column for column in ("z_real_ohm", "z_imag_ohm") if column in columns]
    polar: list[str] = [column for column in ("z_abs_ohm", "z_phase_deg") if column in columns]
    if not (len(cartesian) == 2 and not polar or len(polar) == 2 and not cartesian):
        given = ", ".join(cartesian + polar) or "none"
        raise ConfigError(f"{name}: header: the impedance needs z_real_ohm and z_imag_ohm, or z_abs_ohm and "
                          f"z_phase_deg (got {given}); expected {_IMPEDANCE_FORM}")


@dataclass(frozen=True)
class ImpedanceSweep:
    """One impedance sweep at one contact force: ``freq_hz`` ascending, ``impedance_ohm`` complex."""

    source: str
    force_n: float
    force_given: bool
    freq_hz: _Array
    impedance_ohm: npt.NDArray[np.complex128]

    @property
    def label(self) -> str:
        """``file, 0.5 N`` (``file, 0 N (no force_n column)`` when the file gives no force; the source alone when
        the force is unknown, NaN: a sweep measured through an amplifier)."""
        if math.isnan(self.force_n):
            return self.source
        force = f"{self.force_n:g} N" if self.force_given else "0 N (no force_n column)"
        return f"{self.source}, {force}"


def read_impedance_sweeps(path: str | Path) -> list[ImpedanceSweep]:
    """The impedance sweeps in the CSV at ``path`` (module docstring), one per force, forces ascending.

    Raises ConfigError for a file that cannot be read, a bad header (an unknown,
    repeated or missing column, or not exactly one of the two impedance forms), a value
    outside its column's range, a frequency twice in one sweep, or a sweep of fewer than
    MIN_SWEEP_POINTS points.
    """
    table = _read(path, "impedance sweeps", ("freq_hz",),
                  ("z_real_ohm", "z_imag_ohm", "z_abs_ohm", "z_phase_deg", "force_n"), _IMPEDANCE_FORM,
                  _check_impedance_form)
    columns = table.columns
    if "z_real_ohm" in columns:
        impedance = columns["z_real_ohm"] + 1j * columns["z_imag_ohm"]
    else:
        phase_deg = columns["z_phase_deg"]
        if np.all(np.abs(phase_deg) <= math.pi) and np.max(np.abs(phase_deg)) > 0.1:
            raise ConfigError(f"{table.name}: z_phase_deg: every phase lies within +-pi, as radians would: the column "
                              "is in degrees (a piezo's is about -90)")
        impedance = columns["z_abs_ohm"] * np.exp(1j * np.radians(phase_deg))
    short = np.flatnonzero(np.abs(impedance) < MIN_IMPEDANCE_OHM)
    if short.size:
        raise ConfigError(f"{table.name}:{table.lines[short[0]]}: |Z| is below {MIN_IMPEDANCE_OHM:g} ohm: a short "
                          "circuit, not a sweep")
    forces = columns.get("force_n", np.zeros(len(impedance))) + 0.0  # + 0.0: a force of -0.0 is 0
    distinct = np.unique(forces)
    if len(distinct) > MAX_SWEEPS:
        raise ConfigError(f"{table.name}: {len(distinct):,} forces; a file may hold at most {MAX_SWEEPS} sweeps")
    close = np.flatnonzero(np.diff(distinct) < MIN_FORCE_STEP_N - FORCE_SLACK_N)
    if close.size:
        raise ConfigError(f"{table.name}: force_n: sweeps at {distinct[close[0]]:g} and {distinct[close[0] + 1]:g} N "
                          f"are less than {MIN_FORCE_STEP_N:g} N apart: one sweep per force")
    sweeps = []
    for force in distinct:
        rows = np.flatnonzero(forces == force)
        rows = rows[np.argsort(columns["freq_hz"][rows], kind="stable")]
        freq = columns["freq_hz"][rows]
        where = f"{table.name}, force {force:g} N" if "force_n" in columns else table.name
        repeated = np.flatnonzero(np.diff(freq) == 0)
        if repeated.size:
            lines = sorted(table.lines[rows[repeated[0]:repeated[0] + 2]])
            raise ConfigError(f"{table.name}:{lines[1]}: freq_hz {freq[repeated[0]]:g} Hz appears twice in the sweep "
                              f"at {force:g} N (also line {lines[0]})")
        if len(rows) < MIN_SWEEP_POINTS:
            raise ConfigError(f"{where}: {len(rows)} points; a sweep needs at least {MIN_SWEEP_POINTS}")
        sweeps.append(ImpedanceSweep(table.name, float(force), "force_n" in columns, freq, impedance[rows]))
    return sweeps


@dataclass(frozen=True)
class AmplitudeMeasurements:
    """Plate amplitude against drive: one row per measurement. ``freq_hz`` is None when the file has none."""

    source: str
    force_n: _Array
    voltage_v: _Array
    amplitude_um: _Array
    freq_hz: _Array | None


def read_amplitudes(path: str | Path) -> AmplitudeMeasurements:
    """The amplitude measurements in the CSV at ``path`` (module docstring).

    Raises ConfigError for a file that cannot be read, a bad header or a value outside
    its column's range.
    """
    table = _read(path, "amplitude measurements", ("force_n", "voltage_v", "amplitude_um"), ("freq_hz",),
                  _AMPLITUDE_FORM)
    columns = table.columns
    return AmplitudeMeasurements(table.name, columns["force_n"] + 0.0, columns["voltage_v"], columns["amplitude_um"],
                                 columns.get("freq_hz"))
