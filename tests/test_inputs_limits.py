"""Inputs, URLs and the file helpers at their limits, in process (tests/test_limits_cli.py runs the CLI)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

from tpad_rt.device import Device
from tpad_rt.errors import ConfigError
from tpad_rt.files import check_writable_target, read_regular
from tpad_rt.inputs import file as file_input
from tpad_rt.inputs import open_input
from tpad_rt.inputs.base import position_range
from tpad_rt.limits import DEFAULT_PLATE_MM, position_range_mm

DEVICE = Device.default()


def _error(url: str, device: Device | None = None) -> str:
    with pytest.raises(ConfigError) as caught:
        open_input(url, device=device)
    message = str(caught.value)
    assert "\n" not in message
    return message


def test_positions_are_bounded_by_the_devices_plate() -> None:
    length_mm, width_mm = DEVICE.plate.length_m * 1e3, DEVICE.plate.width_m * 1e3
    assert position_range(DEVICE) == position_range_mm(length_mm, width_mm)
    assert position_range(None) == position_range_mm(*DEFAULT_PLATE_MM)
    x_high = 2 * length_mm
    assert f"option x_mm: must be in [{-length_mm:g}, {x_high:g}] mm" in _error(
        f"scripted://still?x_mm={x_high + 1}", DEVICE)
    open_input(f"scripted://still?x_mm={x_high}", device=DEVICE)  # the edge itself is fine


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("scripted://swipe?from_mm=-131", "option from_mm: must be in [-130, 260] mm"),
        ("scripted://swipe?y_mm=121", "option y_mm: must be in [-60, 120] mm"),
        ("scripted://circle?center_mm=250,30", "option center_mm x + radius_mm: must be in [-130, 260] mm (x on"),
        ("scripted://circle?center_mm=65,110", "option center_mm y + radius_mm: must be in [-60, 120] mm"),
        ("scripted://tap?x_mm=1e308", "option x_mm: must be in [-130, 260] mm"),
        ("scripted://swipe?speed_mm_s=10001", "option speed_mm_s: must be a number in [0.01, 10000]"),
        ("scripted://swipe?lift_s=86401", "option lift_s: must be a number in (0, 86400]"),
        ("scripted://tap?up_s=86400&count=2", "ends after 86,400.4 s, longer than the 86400 s"),
        ("scripted://circle?turns=1e308&radius_mm=20", "ends after 1.26e+308 s"),
        ("scripted://swipe?repeat=10000000000", "option repeat: must be a whole number in [0, 1000000000]"),
        ("mouse://?force_n=51", "option force_n: must be a number in [0, 50]"),
        ("mouse://?plate_mm=261,60", "option plate_mm: must be at most 260,120 mm"),
    ],
)
def test_scripted_and_mouse_options_out_of_range(url: str, expected: str) -> None:
    message = _error(url)
    assert message.startswith(f"input URL '{url}': ") and expected in message


def test_endless_and_longest_patterns_are_accepted() -> None:
    assert open_input("scripted://swipe?repeat=0").duration_s is None
    assert open_input("scripted://still?duration_s=inf").duration_s is None
    assert open_input("scripted://still?duration_s=86400").duration_s == 86400


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("\u0000", "\\x00"), ("%00", "\\x00"), ("%1b[31m", "\\x1b"), ("%0d%0a", "\\x0d"), ("%7f", "\\x7f"),
    ],
)
def test_control_characters_in_urls_are_refused(text: str, expected: str) -> None:
    for url in (f"file:///tmp/a{text}.csv", f"scripted://swipe?y_mm=3{text}", f"scripted://swipe?a{text}=1"):
        message = _error(url)
        assert f"holds the control character {expected} (after unquoting)" in message
        assert all(ord(char) >= 32 and char != "\x7f" for char in message)


def test_long_urls_are_refused_and_cut_in_the_message() -> None:
    message = _error("scripted://swipe?y_mm=" + "3" * 5000)
    assert "5,022 characters long, more than the 4,096 a URL may have" in message
    assert len(message) < 1000


def _csv(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "traj.csv"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("rows", "expected"),
    [
        ("0,300,30\n", "traj.csv:2: column x_mm: must be a finite number in [-130, 260] mm, got '300'"),
        ("0,10,nan\n", "traj.csv:2: column y_mm: must be a finite number in [-60, 120] mm, got 'nan'"),
        ("0,10,30,51\n", "traj.csv:2: column force_n: must be a finite number in [0, 50] N, got '51'"),
        ("0,10,30,1\n86400.5,10,30,1\n",
         "traj.csv:3: column t: must be a finite number in [0, 86400] s, got '86400.5'"),
        ("0,10,30,\x1b[2J\n", "traj.csv:2: column force_n: must be a finite number in [0, 50] N, got '\\x1b[2J'"),
    ],
)
def test_trajectory_values_out_of_range(tmp_path: Path, rows: str, expected: str) -> None:
    header = "t,x_mm,y_mm" + (",force_n" if rows.split("\n")[0].count(",") == 3 else "")
    path = _csv(tmp_path, f"{header}\n{rows}")
    assert _error(f"file://{path}") == f"{tmp_path}/{expected}"


def test_a_trajectory_line_is_at_most_4096_bytes(tmp_path: Path) -> None:
    path = _csv(tmp_path, "t,x_mm,y_mm\n" + "1," * 3000 + "\n")
    assert _error(f"file://{path}") == f"{path}:2: line longer than 4,096 bytes"
    path = _csv(tmp_path, "t,x_mm,y_mm\n0,1,1" + " " * (4096 - 6) + "\n")  # 4096 bytes with the newline
    assert open_input(f"file://{path}").duration_s == 0.0


def test_trajectory_positions_follow_the_device_given(tmp_path: Path) -> None:
    path = _csv(tmp_path, "t,x_mm,y_mm\n0,-130,-60\n1,260,120\n")
    assert open_input(f"file://{path}").duration_s == 1.0
    _csv(tmp_path, "t,x_mm,y_mm\n0,260.001,0\n")
    assert "column x_mm: must be a finite number in [-130, 260] mm" in _error(f"file://{path}", DEVICE)


def test_trajectory_chunks_join_in_order(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(file_input, "_CHUNK_ROWS", 2)
    path = _csv(tmp_path, "t,x_mm,y_mm,down\n" + "".join(f"{k},{k},1,{k % 2}\n" for k in range(7)))
    rows = open_input(f"file://{path}").samples_between(-math.inf, math.inf)
    assert rows["t_s"].tolist() == list(range(7)) and rows["x_mm"].tolist() == list(range(7))
    assert rows["down"].tolist() == [bool(k % 2) for k in range(7)] and np.isnan(rows["force_n"]).all()


def test_trajectory_rows_are_bounded_at_the_line_past_them(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(file_input, "MAX_TRAJECTORY_ROWS", 3)
    path = _csv(tmp_path, "t,x_mm,y_mm\n# c\n0,1,1\n1,1,1\n2,1,1\n")
    assert len(open_input(f"file://{path}").samples_between(-math.inf, math.inf)) == 3
    _csv(tmp_path, "t,x_mm,y_mm\n# c\n0,1,1\n1,1,1\n2,1,1\n3,1,1\n")
    assert _error(f"file://{path}") == f"{path}:6: more than 3 samples, the most a trajectory may hold"


def test_read_regular_refuses_special_and_oversized_files(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "big").write_bytes(b"x" * 11)
    cases = {
        tmp_path / "fifo": "not a regular file (a FIFO); tpad-rt reads things from regular files only",
        tmp_path: "not a regular file (a directory)",
        Path("/dev/null"): "not a regular file (a character device)",
        tmp_path / "big": "file is larger than 10 bytes",
        tmp_path / "absent": "cannot read: no such file or directory",
        f"{tmp_path}/a\0b": "the path contains a NUL byte",
    }
    for path, expected in cases.items():
        with pytest.raises(ConfigError) as caught:
            read_regular(path, "things", 10)
        assert expected in str(caught.value) and "\x00" not in str(caught.value)
    assert read_regular(tmp_path / "big", "things", 11) == b"x" * 11


def test_check_writable_target(tmp_path: Path) -> None:
    check_writable_target(tmp_path / "new.npz", "recordings")  # a new path is fine
    (tmp_path / "old.npz").write_bytes(b"")
    check_writable_target(tmp_path / "old.npz", "recordings")  # so is an existing regular file
    os.symlink("/dev/null", tmp_path / "link.npz")
    for path, kind in [(tmp_path, "a directory"), (tmp_path / "link.npz", "a character device")]:
        with pytest.raises(ConfigError, match=f"exists and is not a regular file \\({kind}\\); tpad-rt writes"):
            check_writable_target(path, "recordings")
    with pytest.raises(ConfigError, match="NUL byte"):
        check_writable_target(f"{tmp_path}/a\0.npz", "recordings")
