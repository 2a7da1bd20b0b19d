"""``tpad-rt devices``: audio devices with their accepted rates (a real JACK server), serial ports."""

from __future__ import annotations

import contextlib
import ctypes
import os
import pty
import subprocess
import sys
from collections.abc import Callable, Iterator
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


#: inotify's event for a file opened (linux/inotify.h); an event on a watched file (no name) is 16 bytes.
IN_OPEN = 0x20
EVENT_BYTES = 16


@contextlib.contextmanager
def opens_of(path: str) -> Iterator[Callable[[], int]]:
    """Within: a function counting the opens of ``path`` (inotify IN_OPEN, any process) since it last counted."""
    libc = ctypes.CDLL(None, use_errno=True)
    watch = libc.inotify_init1(os.O_NONBLOCK)
    assert watch >= 0 and libc.inotify_add_watch(watch, os.fsencode(path), IN_OPEN) >= 0, os.strerror(ctypes.get_errno())

    def count() -> int:
        try:
            return len(os.read(watch, 64 * EVENT_BYTES)) // EVENT_BYTES
        except BlockingIOError:
            return 0

    try:
        yield count
    finally:
        os.close(watch)


@pytest.fixture
def pty_name() -> Iterator[str]:
    """A real terminal device (a pty's slave), open meanwhile."""
    master, slave = pty.openpty()
    try:
        yield os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)


def test_listing_a_port_never_opens_it(pty_name: str) -> None:
    """Opening a serial port raises its DTR and RTS and closing drops them (HUPCL): listing touches no port."""
    with opens_of(pty_name) as opens:
        lines = serial_lines([(pty_name, UNDESCRIBED), ("/dev/ttyACM9", "Arduino Uno")])
        assert opens() == 0
        os.close(os.open(pty_name, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK))
        assert opens() == 1  # the watch sees an open
    assert lines == [f"  {pty_name}: a built-in serial port (not a USB adapter; the system describes it no further)",
                     "  /dev/ttyACM9: Arduino Uno"]


def test_a_port_with_no_uart_behind_it_is_left_out(pty_name: str, tmp_path: Path) -> None:
    """The kernel's UART type of a port (``/sys/class/tty/NAME/type``; a folder of that layout here, for the pty)
    0 is a slot with nothing there, named as left out, like a port with no device file; another type is listed."""
    uart_type = tmp_path / Path(pty_name).name / "type"
    uart_type.parent.mkdir()
    missing = str(tmp_path / "ttyS7")
    uart_type.write_text("0\n")
    assert serial_lines([(pty_name, UNDESCRIBED), (missing, UNDESCRIBED)], tmp_path) == [
        "  none", f"  (left out: {pty_name}, {missing}: built-in serial port slots with no hardware behind them)"]
    uart_type.write_text("4\n")  # a 16550A
    assert serial_lines([(pty_name, UNDESCRIBED)], tmp_path) == [
        f"  {pty_name}: a built-in serial port (not a USB adapter; the system describes it no further)"]
