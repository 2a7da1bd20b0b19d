"""``tpad-rt play`` on the real-time Renderer, in subprocesses: the automatic output and input choices
(no display and no JACK; a JACK dummy server; Xvfb), the live panel and Ctrl-C, one-line errors."""

from __future__ import annotations

import fcntl
import os
import pty
import select
import signal
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import numpy as np
import pytest
from jack_server import jack_server, kill_server_under
from xvfb import display, xvfb_server  # noqa: F401 - fixtures

from tpad_rt.cli.play import auto_swipe
from tpad_rt.config import load_texture
from tpad_rt.kernel.layout import FLAG_WATCHDOG
from tpad_rt.recording import read_recording

REPO = Path(__file__).resolve().parents[1]
#: A machine with no display and no JACK server (a server name nobody runs, never auto-started).
BARE_ENV = {**{k: v for k, v in os.environ.items() if k != "DISPLAY"},
            "JACK_DEFAULT_SERVER": "tpadrt-absent", "JACK_NO_START_SERVER": "1"}


def _play(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tpad_rt", "play", *args], capture_output=True, text=True,
                          cwd=REPO, timeout=300, env=BARE_ENV if env is None else env)


def test_without_sound_card_or_display_it_plays_a_swipe_on_the_simulated_plate() -> None:
    done = _play("textures/grating.yaml", "--duration", "1")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    finger = load_texture("textures/grating.yaml").finger
    assert finger is not None
    assert lines[0] == (f"output sim:// (no audio device runs 192000 Hz), input {auto_swipe(finger)} (no display; "
                        f"the texture's recommended finger: {finger.speed_mm_s:g} mm/s under {finger.force_n:g} N); "
                        "1 s or Ctrl-C stops")
    assert lines[1].startswith("played ")
    friction = [line for line in lines if line.startswith("friction |texture under the finger - simulated plate|")]
    assert len(friction) == 1
    mean_error = float(friction[0].split("mean ")[1].split(",")[0])
    assert mean_error < 0.01  # the simulated plate follows the texture under the finger (render: 0.0024)
    judged = int(friction[0].split(" over ")[1].split(" touching")[0])
    callbacks = int(lines[1].split(": ")[1].split(" callbacks")[0])
    # Blocks the finger touched are judged, from what the plate measured of them (the telemetry's columns). How many
    # a second plays, and so how many the swipe touches, is the host's: the pacing is checked on a virtual clock
    # (tests/test_paced.py), and that every row is measured and read once in tests/test_telemetry.py.
    assert 0 < judged <= callbacks, (lines[1], friction[0])
    # The plate follows the texture but where a touch starts: the drive fades in over ramp_ms there (how many blocks
    # that covers depends on where the texture is when the first sample lands, so on the host's timing).
    departed = int(friction[0].split("departures: ")[1].split(" blocks")[0])
    assert departed == 0 or f"; {departed} of them in a touch's start ramp" in friction[0], friction[0]


def test_an_output_that_measures_no_plate_gets_no_friction_judged() -> None:
    """play judges friction where the run's telemetry holds the plate's measurements, whatever the URL: none
    on null://."""
    done = _play("textures/grating.yaml", "--duration", "0.3", "--output", "null://")
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[1].startswith("played ")
    assert "friction" not in done.stdout


def test_blocks_the_plate_cannot_follow_are_counted_as_departures() -> None:
    """A power budget of 0.02 W leaves the plate far from the texture: play counts those blocks."""
    done = _play("textures/grating.yaml", "--duration", "1", "--power-budget", "0.02")
    assert done.returncode == 0, done.stderr
    friction = [line for line in done.stdout.splitlines() if line.startswith("friction |texture under the finger")]
    departed = int(friction[0].split("departures: ")[1].split(" blocks")[0])
    judged = int(friction[0].split(" over ")[1].split(" touching")[0])
    assert departed > 0.2 * judged


def test_a_finite_input_ends_the_play_and_the_recording_ends_in_silence(tmp_path: Path) -> None:
    record = tmp_path / "r.npz"
    done = _play("textures/grating.yaml", "--input", "scripted://swipe?to_mm=20", "--force", "1",
                 "--record", str(record))
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[0] == "output sim:// (no audio device runs 192000 Hz), " \
                                          "input scripted://swipe?to_mm=20; Ctrl-C stops"
    assert done.stdout.splitlines()[-1] == f"wrote {record}"
    recording = read_recording(record)
    assert np.all(recording.drive[-64:] == 0)
    # the simulated plate and the blocks judged against the texture, as render records them; the input by its URL
    assert recording.has_sim and "departed" in recording.blocks
    assert recording.metadata["input_url"] == "scripted://swipe?to_mm=20"
    assert recording.metadata["departure_tolerance_mu"] == 0.1
    touching = (recording.blocks["saturated"] & FLAG_WATCHDOG) == 0
    assert touching.any() and np.isfinite(recording.blocks["achieved_mu"][touching]).all()
    assert not recording.blocks["departed"][~touching].any()  # how they are judged: tests/test_telemetry.py


@pytest.mark.system
@pytest.mark.parametrize(("sync", "periods"), [(False, 2), (True, 1)])
def test_with_a_jack_server_auto_picks_the_jack_device_and_says_how_it_buffers(sync: bool, periods: int) -> None:
    with jack_server(192000, 64, sync=sync):
        done = _play("textures/grating.yaml", "--duration", "1",
                     env={k: v for k, v in os.environ.items() if k != "DISPLAY"})
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("output audio://") and "JACK" in lines[0] and "runs 192000 Hz" in lines[0]
    callbacks = int(lines[1].split(": ")[1].split()[0])
    assert callbacks > 0
    period_ms = 64 / 192000 * 1e3
    latency = next(line for line in lines if line.startswith("push-to-output latency"))
    assert latency.endswith(f"(of which the host reports {periods * period_ms:.2f} ms from callback to DAC)")
    hint = [line for line in lines if line.startswith("the JACK server buffers")]
    assert hint == ([] if sync else [f"the JACK server buffers 2 periods before the DAC: started with jackd -S "
                                     f"(synchronous mode) it buffers one, {period_ms:.2f} ms less"])


@pytest.mark.system
def test_with_a_display_auto_picks_the_mouse(display: str) -> None:  # noqa: F811 - fixture
    done = _play("textures/grating.yaml", "--duration", "1", env={**BARE_ENV, "DISPLAY": display})
    assert done.returncode == 0, done.stderr
    first = done.stdout.splitlines()[0]
    assert first.startswith("output sim:// (no audio device runs 192000 Hz), input mouse://?force_n=0.5 ("), first
    assert "left button held touches; the texture's recommended finger: 60 mm/s under 0.5 N); 1 s" in first, first


@pytest.mark.parametrize(("args", "message"), [
    (("textures/none.yaml",), "tpad-rt play: "),
    (("textures/grating.yaml", "--input", "scripted://swoop"), "tpad-rt play: "),
    (("textures/grating.yaml", "--output", "audio://no-such-device"), "tpad-rt play: audio: "),
    (("textures/grating.yaml", "--record", "r.wav"), "tpad-rt play: --record: must end in .npz, got 'r.wav'"),
])
def test_errors_are_one_line_and_status_1(args: tuple[str, ...], message: str) -> None:
    done = _play(*args)
    assert done.returncode == 1
    assert done.stderr.startswith(message) and done.stderr.count("\n") == 1, done.stderr
    assert "Traceback" not in done.stderr


def _read_until(master: int, wanted: bytes, seen: bytearray, timeout_s: float = 120) -> bool:
    """Append the terminal's output to ``seen`` until ``wanted`` shows up (True) or EOF/timeout (False)."""
    deadline = time.monotonic() + timeout_s
    while wanted not in seen and time.monotonic() < deadline:
        if not select.select([master], [], [], 0.2)[0]:
            continue
        try:
            chunk = os.read(master, 65536)
        except OSError:  # EIO: the child closed the terminal
            break
        if not chunk:
            break
        seen += chunk
    return wanted in seen


def test_on_a_terminal_it_shows_the_panel_and_ctrl_c_stops_with_a_ramp(tmp_path: Path) -> None:
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 160, 0, 0))
    record = tmp_path / "r.npz"
    child = subprocess.Popen([sys.executable, "-m", "tpad_rt", "play", "textures/grating.yaml", "--record",
                              str(record)], stdin=slave, stdout=slave, stderr=slave, cwd=REPO, env=BARE_ENV,
                             start_new_session=True)
    os.close(slave)
    seen = bytearray()
    try:
        assert _read_until(master, b"(the friction the simulated plate gives now)", seen), seen.decode(errors="replace")
        child.send_signal(signal.SIGINT)
        _read_until(master, b"wrote ", seen)
        assert child.wait(timeout=120) == 0
    finally:
        if child.poll() is None:
            child.kill()
        os.close(master)
    text = seen.decode(errors="replace")
    for label in ("finger", "friction", "drive", "power", "callbacks", "underflows", "load p99", "time"):
        assert label in text
    assert "(stopped by Ctrl-C)" in text and "Traceback" not in text
    assert np.all(read_recording(record).drive[-64:] == 0)


@pytest.mark.system
def test_a_jack_server_dying_mid_play_ends_in_one_line_and_status_1() -> None:
    done = kill_server_under([sys.executable, "-m", "tpad_rt", "play", "textures/grating.yaml", "--input",
                              "scripted://swipe?speed_mm_s=1", "--duration", "600"], cwd=REPO,
                             env={k: v for k, v in os.environ.items() if k != "DISPLAY"})
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert done.stdout.startswith("output audio://") and "JACK" in done.stdout.splitlines()[0]
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr
    assert done.stderr.startswith("tpad-rt play: audio: the stream on device ")
    assert "(device lost or server gone)" in done.stderr
