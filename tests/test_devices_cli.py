"""``tpad-rt devices``: audio devices with their accepted rates (a real JACK server), serial ports."""

from __future__ import annotations

import os
import pty
import subprocess
import sys
from pathlib import Path

import pytest
from jack_server import jack_server

from tpad_rt.cli.devices import UNDESCRIBED, serial_lines

DEVICES = "import sys\nfrom tpad_rt.cli import main\nsys.exit(main(['devices']))\n"
NO_PORTAUDIO = (
    "import ctypes.util\n"
    "find = ctypes.util.find_library\n"
    "ctypes.util.find_library = lambda name: None if 'portaudio' in name else find(name)\n"
)


def run_devices(prelude: str = "") -> subprocess.CompletedProcess[str]:
    """``tpad-rt devices`` in a fresh process (PortAudio scans the host APIs when it starts)."""
    return subprocess.run([sys.executable, "-c", prelude + DEVICES], capture_output=True, text=True, timeout=60)


@pytest.mark.system
def test_lists_the_jack_device_with_the_server_rate() -> None:
    with jack_server(192000, 64):
        done = run_devices()
    assert done.returncode == 0, done.stderr
    assert "system (JACK Audio Connection Kit), 2 out, rates 192000 Hz" in done.stdout
    assert "serial ports (serial://PORT):" in done.stdout


def test_missing_portaudio_is_one_line_and_status_1() -> None:
    done = run_devices(NO_PORTAUDIO)
    assert done.returncode == 1
    assert "install the system package libportaudio2" in done.stdout
    assert "serial ports (serial://PORT):" in done.stdout
    assert "Traceback" not in done.stderr


def test_a_port_the_system_does_not_describe_is_listed_in_words_only_when_it_opens(tmp_path: Path) -> None:
    """pyserial's "n/a" (a built-in UART's slot): a port that opens (a pty here) is listed in words, one that does
    not (nothing there) is named as left out; a described port (a USB adapter) is listed as described."""
    master, slave = pty.openpty()
    try:
        name = os.ttyname(slave)
        missing = str(tmp_path / "ttyS7")
        lines = serial_lines([(name, UNDESCRIBED), (missing, UNDESCRIBED), ("/dev/ttyACM9", "Arduino Uno")])
    finally:
        os.close(master)
        os.close(slave)
    assert lines == [f"  {name}: a built-in serial port (not a USB adapter; the system describes it no further)",
                     "  /dev/ttyACM9: Arduino Uno",
                     f"  (left out: {missing}: built-in serial port slots with no hardware answering)"]
    assert serial_lines([(missing, UNDESCRIBED)]) == [
        "  none", f"  (left out: {missing}: built-in serial port slots with no hardware answering)"]
