"""file:// input: CSV trajectories, optional columns, and errors with file:line breadcrumbs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tpad_rt.errors import ConfigError
from tpad_rt.inputs import open_input


def _write(tmp_path: Path, text: str, name: str = "traj.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_reads_every_column_skipping_comments_and_blank_lines(tmp_path: Path) -> None:
    text = "# a recorded stroke\n\nx_mm, t ,y_mm,down,force_n\n10,0,30,1,0.5\n\n# gap\n11,0.01,31,0,0.25\n"
    path = _write(tmp_path, text)
    source = open_input(f"file://{path}")
    rows = source.samples_between(-math.inf, 1.0)
    assert rows["t_s"].tolist() == [0.0, 0.01]
    assert rows["x_mm"].tolist() == [10.0, 11.0] and rows["y_mm"].tolist() == [30.0, 31.0]
    assert rows["force_n"].tolist() == [0.5, 0.25] and rows["down"].tolist() == [True, False]
    assert source.duration_s == 0.01


def test_optional_columns_default_to_unknown_force_and_touching(tmp_path: Path) -> None:
    _write(tmp_path, "t,x_mm,y_mm\n0,1,2\n0.5,3,4\n1.0,5,6\n")
    source = open_input(f"file://{tmp_path}/traj.csv")
    rows = source.samples_between(0.0, 1.0)  # (0, 1]: the first sample is excluded
    assert rows["t_s"].tolist() == [0.5, 1.0]
    assert np.isnan(rows["force_n"]).all() and rows["down"].all()


def test_relative_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _write(tmp_path, "t,x_mm,y_mm\n0,1,2\n")
    monkeypatch.chdir(tmp_path)
    assert open_input("file://traj.csv").duration_s == 0.0


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("t,x_mm,y_mm\n0,1,2\n0.1,abc,2\n",
         "traj.csv:3: column x_mm: must be a finite number in [-130, 260] mm, got 'abc'"),
        ("t,x_mm,y_mm\n0,1,2\n0.1,1,inf\n",
         "traj.csv:3: column y_mm: must be a finite number in [-60, 120] mm, got 'inf'"),
        ("t,x_mm,y_mm\n0,1,2\n# c\n0,1,2\n", "traj.csv:4: column t: must be greater than the previous line's 0, got 0"),
        ("t,x_mm,y_mm\n0.2,1,2\n0.1,1,2\n",
         "traj.csv:3: column t: must be greater than the previous line's 0.2, got 0.1"),
        ("t,x_mm,y_mm\n-1,1,2\n", "traj.csv:2: column t: must be a finite number in [0, 86400] s, got '-1'"),
        ("t,x_mm,y_mm\n0,1\n", "traj.csv:2: 2 fields, expected 3 (t,x_mm,y_mm)"),
        ("t,x_mm,y_mm,down\n0,1,2,yes\n", "traj.csv:2: column down: must be 0 or 1, got 'yes'"),
        ("t,x_mm,y_mm,force_n\n0,1,2,-0.5\n",
         "traj.csv:2: column force_n: must be a finite number in [0, 50] N, got '-0.5'"),
        ("t,x_mm,y_mm,forse_n\n", "traj.csv:1: header: unknown column 'forse_n'; did you mean 'force_n'?"),
        ("# c\nt,x,y_mm\n", "traj.csv:2: header: unknown column 'x'"),
        ("t,x_mm,t\n", "traj.csv:1: header: column 't' appears twice"),
        ("t,x_mm\n0,1\n", "traj.csv:1: header: missing column y_mm; expected t,x_mm,y_mm[,force_n][,down]"),
        ("t,x_mm,y_mm\n", "traj.csv: no samples after the header"),
        ("# only a comment\n\n", "traj.csv: empty; expected a header line t,x_mm,y_mm[,force_n][,down]"),
        ("t,x_mm,y_mm\r0,10,10\r0.1,20,10\r", "traj.csv:1: not a CSV line (new-line character seen in unquoted"),
    ],
)
def test_errors_name_the_file_and_line(tmp_path: Path, text: str, expected: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as caught:
        open_input(f"file://{path}")
    assert str(caught.value).startswith(f"{tmp_path}/{expected}")


HINT = "it holds a carriage return (CR): lines must end in LF or CR LF, not CR alone (old Mac line ends)"


@pytest.mark.parametrize("rows", [2, 400])
def test_old_mac_line_ends_get_the_line_end_hint_short_or_long(tmp_path: Path, rows: int) -> None:
    """Lines ending in CR alone read as one line: under 4 KiB the csv module refuses it, over 4 KiB its length
    does; both messages say why."""
    text = "t,x_mm,y_mm\r" + "".join(f"{0.001 * row:.3f},10,10\r" for row in range(rows))
    assert (len(text) > 4096) == (rows == 400)
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as caught:
        open_input(f"file://{path}")
    assert str(caught.value).startswith(f"{path}:1: ") and str(caught.value).endswith(f"; {HINT}")
    assert ("line longer than 4,096 bytes" in str(caught.value)) == (rows == 400)


@pytest.mark.parametrize("end", ["\n", "\r\n"])
def test_a_long_line_ending_in_lf_or_cr_lf_gets_no_line_end_hint(tmp_path: Path, end: str) -> None:
    path = _write(tmp_path, "t,x_mm,y_mm" + end + "0,10," + "1" * 5000 + end)
    with pytest.raises(ConfigError) as caught:
        open_input(f"file://{path}")
    assert str(caught.value) == f"{path}:2: line longer than 4,096 bytes"


def test_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"missing\.csv: cannot read: no such file or directory"):
        open_input(f"file://{tmp_path}/missing.csv")
    (tmp_path / "latin1.csv").write_bytes(b"t,x_mm,y_mm\n0,1,2\xe9\n")
    with pytest.raises(ConfigError, match=r"latin1\.csv:2: not UTF-8 text"):
        open_input(f"file://{tmp_path}/latin1.csv")
    with pytest.raises(ConfigError, match=r"not a regular file \(a directory\); tpad-rt reads trajectories"):
        open_input(f"file://{tmp_path}")


def test_url_errors(tmp_path: Path) -> None:
    expected = r"input URL 'file://': missing the file path; expected file:///path/trajectory\.csv"
    with pytest.raises(ConfigError, match=expected):
        open_input("file://")
    with pytest.raises(ConfigError, match=r"unknown option 'rate_hz' \(options: none\)"):
        open_input(f"file://{tmp_path}/x.csv?rate_hz=5")


def test_too_many_rows_are_counted_before_any_is_parsed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The row limit is judged by a pass over the lines (comments, blank lines and the header not counted) before
    the rows are parsed: a file one row over it names the line of that row, even when a row before it is bad."""
    import tpad_rt.inputs.file as file_module

    monkeypatch.setattr(file_module, "MAX_TRAJECTORY_ROWS", 4)
    rows = ["0,10,30", "# a comment", "", "0.001,10,30", "0.002,nan,30", "0.003,10,30"]
    at_limit = tmp_path / "four.csv"
    at_limit.write_text("# header next\nt,x_mm,y_mm\n" + "\n".join(rows) + "\n")
    with pytest.raises(ConfigError, match=r"four\.csv:7: column x_mm: must be a finite number"):
        open_input(f"file://{at_limit}")  # four rows: parsed, and the bad one found
    over = tmp_path / "five.csv"
    over.write_text("t,x_mm,y_mm\n" + "\n".join(rows) + "\n0.004,10,30\n")
    with pytest.raises(ConfigError, match=r"five\.csv:8: more than 4 samples, the most a trajectory may hold"):
        open_input(f"file://{over}")
    good = tmp_path / "good.csv"
    good.write_text("t,x_mm,y_mm\n# c\n\n0,10,30\n0.001,10,30\n# c\n0.002,10,30\n0.003,10,30\n\n# end\n")
    assert len(open_input(f"file://{good}").samples) == 4
