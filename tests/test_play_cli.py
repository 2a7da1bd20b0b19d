"""tpad-rt play (interim): says what it renders, paces, shows a live status on a terminal, stops on Ctrl-C."""

from __future__ import annotations

import fcntl
import os
import pty
import re
import select
import signal
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import numpy as np

from tpad_rt.cli.play import STATUS_HEADER
from tpad_rt.recording import read_recording

REPO = Path(__file__).resolve().parents[1]


def _play(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tpad_rt", "play", "textures/grating.yaml", *args],
                          capture_output=True, text=True, cwd=REPO, timeout=300)


def test_without_a_terminal_it_reports_and_records(tmp_path: Path) -> None:
    done = _play("--input", "scripted://swipe?to_mm=20", "--record", str(tmp_path / "r.npz"))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == "no audio engine yet: rendering to sim:// from scripted://swipe?to_mm=20 (real-time pacing)"
    assert lines[1].startswith("rendered 0.106 s of audio in ")
    assert any(line.startswith("friction |texture under the finger - achieved|") for line in lines)
    assert lines[-1] == f"wrote {tmp_path / 'r.npz'}"
    recording = read_recording(tmp_path / "r.npz")
    assert recording.has_sim and np.all(recording.drive[-64:] == 0)


def test_defaults_to_a_swipe_on_the_simulated_plate() -> None:
    done = _play("--duration", "0.02")
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[0] == (
        "no audio engine yet: rendering to sim:// from scripted://swipe?speed_mm_s=100 (real-time pacing)"
    )


def test_bad_record_name_is_one_line() -> None:
    done = _play("--record", "r.wav")
    assert done.returncode == 1 and done.stderr == "tpad-rt play: --record: must end in .npz, got 'r.wav'\n"


def _read_until(master: int, wanted: bytes, deadline_s: float, seen: bytearray) -> bool:
    """Append the terminal's output to ``seen`` until ``wanted`` shows up (True) or EOF/deadline (False)."""
    while time.monotonic() < deadline_s:
        ready, _, _ = select.select([master], [], [], 0.2)
        if not ready:
            continue
        try:
            chunk = os.read(master, 65536)
        except OSError:  # EIO: the child closed the terminal
            return wanted in seen
        if not chunk:
            return wanted in seen
        seen += chunk
        if wanted in seen:
            return True
    return False


def test_on_a_terminal_it_shows_a_live_status_and_stops_cleanly_on_ctrl_c(tmp_path: Path) -> None:
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 220, 0, 0))
    record = tmp_path / "r.npz"
    command = [sys.executable, "-m", "tpad_rt", "play", "textures/grating.yaml",
               "--input", "scripted://swipe?repeat=0&back_and_forth=1", "--record", str(record)]
    child = subprocess.Popen(command, stdin=slave, stdout=slave, stderr=slave, cwd=REPO, start_new_session=True)
    os.close(slave)
    seen = bytearray()
    try:
        assert _read_until(master, b"100 mm/s", time.monotonic() + 120, seen), seen.decode(errors="replace")
        child.send_signal(signal.SIGINT)
        _read_until(master, b"wrote ", time.monotonic() + 120, seen)
        _read_until(master, b"\n", time.monotonic() + 10, seen[seen.index(b"wrote "):] if b"wrote " in seen else seen)
        assert child.wait(timeout=120) == 0
    finally:
        if child.poll() is None:
            child.kill()
        os.close(master)
    text = seen.decode(errors="replace")
    assert text.startswith("no audio engine yet: rendering to sim:// from scripted://swipe?repeat=0&back_and_forth=1")
    assert STATUS_HEADER in text
    status = r"\d+\.\d\d s  \(\s*\d+\.\d,\s*30\.0\) mm 100 mm/s\s+\d\.\d\d→\d\.\d\d\s+\d+\.\d/40 V \d\.\d\d/0\.55 W"
    assert re.search(status, text)
    assert "stopped by Ctrl-C" in text and "Traceback" not in text
    recording = read_recording(record)
    assert np.all(recording.drive[-64:] == 0)  # ramped down after the stop
