"""``tpad-rt devices``: audio devices with their accepted rates (a real JACK server), serial ports."""

from __future__ import annotations

import subprocess
import sys

import pytest
from jack_server import jack_server

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
