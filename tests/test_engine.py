"""The Renderer without a sound card: URL and option errors, the paced simulator path, the API contract."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import tpad_rt
import tpad_rt.telemetry
from tpad_rt.engine import Renderer
from tpad_rt.errors import ConfigError, TpadError
from tpad_rt.recording import read_recording

GRATING = Path(__file__).resolve().parents[1] / "textures" / "grating.yaml"
AUDIO_FORM = "audio://[device name or index]?rate=192000&block=64&channel=1"


@pytest.mark.parametrize(("url", "problem"), [
    ("audio://?rate=fast", "option rate: must be a whole number in [1, 768000], got 'fast'"),
    ("audio://?rate=1000000000000", "option rate: must be a whole number in [1, 768000], got '1000000000000'"),
    ("audio://?block=65537", "option block: must be a whole number in [1, 65536]"),
    ("audio://?blok=64", "unknown option 'blok'; did you mean 'block'?"),
    ("audio://?channel=0", "option channel: must be a whole number in [1, 1024]"),
])
def test_bad_audio_url_shows_the_expected_form(url: str, problem: str) -> None:
    with pytest.raises(ConfigError) as caught:
        Renderer(output=url)
    assert problem in str(caught.value) and AUDIO_FORM in str(caught.value)


def test_unknown_scheme_lists_audio() -> None:
    with pytest.raises(ConfigError, match="did you mean 'audio'.*audio://"):
        Renderer(output="audoi://")


def test_carrier_above_the_rate_limit_names_the_rate_needed() -> None:
    with pytest.raises(ConfigError, match="needs a sample rate of at least 69689 Hz"):
        Renderer(output="audio://?rate=48000")


def test_url_rate_and_block_override_the_arguments() -> None:
    renderer = Renderer(output="audio://?rate=96000", rate_hz=192000, block_frames=32)
    assert (renderer.rate_hz, renderer.block_frames) == (96000, 32)


def test_missing_portaudio_names_the_package() -> None:
    script = (
        "import ctypes.util\n"
        "find = ctypes.util.find_library\n"
        "ctypes.util.find_library = lambda name: None if 'portaudio' in name else find(name)\n"
        "from tpad_rt.outputs import audio\n"
        "try:\n    audio.portaudio()\nexcept Exception as error:\n    print(type(error).__name__, error)\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert done.stdout.startswith("BackendError audio: PortAudio is not available"), done.stdout + done.stderr
    assert "install the system package libportaudio2" in done.stdout


def test_sim_output_renders_in_a_paced_thread(tmp_path: Path) -> None:
    """A Renderer on sim://: the rows carry what the simulated plate measured of every block (read once each),
    and the recording ends in the stop's ramp to 0. It waits on the stream, not on the wall clock."""
    path = tmp_path / "sim.npz"
    renderer = Renderer(output="sim://", texture=GRATING)
    renderer.record(path)
    chunks = []
    with renderer:
        start_s = renderer.now_s()
        for k in range(150):
            renderer.push_finger(10.0 + 0.1 * k, 20.0, t=start_s + k * 0.002)
        for rows in renderer.iter_telemetry(period_s=0.01):
            chunks.append(rows)
            if rows["t"][-1] >= start_s + 0.35:
                break
    chunks.append(renderer.telemetry())  # the rest, the stop's ramp included
    telemetry = {name: np.concatenate([chunk[name] for chunk in chunks]) for name in chunks[0]}
    stats = renderer.stats()
    assert stats["callbacks"] == stats["blocks"] == len(telemetry["t"]) > 0
    assert np.all(np.diff(telemetry["t"]) > 0)
    assert telemetry["voltage_v"].max() > 1.0
    assert np.all(np.isfinite(telemetry["achieved_mu"])) and np.all(np.isfinite(telemetry["plate_amplitude_um"]))
    assert telemetry["plate_amplitude_um"].max() > 0.1 and telemetry["achieved_mu"].min() < 0.9  # the plate moved
    recording = read_recording(path)
    assert len(recording.drive) >= (len(recording.blocks["t"]) - 1) * renderer.block_frames
    assert np.all(recording.drive[-renderer.block_frames:] == 0.0)  # stopped with a ramp to 0


def test_stop_is_idempotent_and_start_twice_is_an_error() -> None:
    renderer = Renderer(output="null://")
    renderer.stop()
    with renderer:
        renderer.push_finger(10.0, 20.0)
    renderer.stop()
    with pytest.raises(RuntimeError, match="already running"), renderer:
        renderer.start()
    renderer.start()
    with renderer:  # already running: entering does not start again
        assert renderer.running
    assert not renderer.running


def test_join_returns_when_another_thread_stops() -> None:
    renderer = Renderer(output="null://")
    renderer.start()
    stopper = threading.Timer(0.1, renderer.stop)
    stopper.start()
    renderer.join(timeout_s=10)
    stopper.join()
    assert not renderer.running


def test_output_that_cannot_open_fails_start(tmp_path: Path) -> None:
    renderer = Renderer(output=f"wav://{tmp_path}/missing/out.wav")
    with pytest.raises(ConfigError, match="out.wav: cannot write WAV files there: no folder "):
        renderer.start()
    assert not renderer.running


#: A Renderer writing a WAV under a file-size limit (RLIMIT_FSIZE; SIGXFSZ ignored, so a write past it fails with
#: EFBIG, as on a full disk): the paced driver's error must end the run, in the app's thread, once.
FAILING_OUTPUT_APP = """
import resource, signal, sys
from tpad_rt.engine import Renderer
from tpad_rt.errors import BackendError
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
renderer = Renderer(output="wav://" + sys.argv[1], texture=sys.argv[2], rate_hz=96000, block_frames=256)
renderer.start()
resource.setrlimit(resource.RLIMIT_FSIZE, (65536, resource.RLIM_INFINITY))
try:
    renderer.join(timeout_s=60)
    print("join: no error")
except BackendError as error:
    print("join:", error)
print("running:", renderer.running)
renderer.stop()
print("stopped:", renderer.running)
"""


def test_an_output_failing_mid_run_ends_it_with_the_output_s_error(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-c", FAILING_OUTPUT_APP, str(tmp_path / "out.wav"), str(GRATING)],
                          capture_output=True, text=True, timeout=120)
    lines = done.stdout.splitlines()
    assert lines[0] == f"join: {tmp_path / 'out.wav'}: cannot write WAV files there: file too large", \
        done.stdout + done.stderr
    assert lines[1:] == ["running: True", "stopped: False"], done.stdout + done.stderr
    assert done.returncode == 0, done.stderr
    assert list(tmp_path.iterdir()) == []  # no part of a WAV at the path, no temporary file beside it


def test_a_recording_past_its_limit_ends_the_run_once_and_keeps_what_came_before(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tpad_rt.telemetry, "MAX_RECORDING_SAMPLES", 20000)
    renderer = Renderer(output="null://", texture=GRATING)
    renderer.record(tmp_path / "r.npz")
    renderer.start()
    with pytest.raises(TpadError, match="longer than the 20000 drive samples a recording may keep"):
        renderer.join(timeout_s=60)
    renderer.stop()  # reported once: stop() does not raise it again
    assert not renderer.running
    recording = read_recording(tmp_path / "r.npz")
    assert recording.metadata["truncated"].startswith("longer than the 20000 drive samples")
    blocks = len(recording.blocks["t"])
    assert 0 < len(recording.drive) <= 20000
    assert abs(len(recording.drive) - blocks * renderer.block_frames) <= renderer.block_frames  # drive and rows agree


def test_record_needs_npz_and_a_place_to_write(tmp_path: Path) -> None:
    """Refused when asked for, not when the run stops and its recording would be lost."""
    with pytest.raises(ConfigError, match="must end in .npz"):
        Renderer(output="null://").record("out.wav")
    (tmp_path / "d.npz").mkdir()
    for path, problem in [(tmp_path / "missing" / "r.npz", "cannot write recordings there: no folder "),
                          (tmp_path / "d.npz", "exists and is not a regular file (a directory)")]:
        with pytest.raises(ConfigError, match=problem.replace("(", r"\(").replace(")", r"\)")):
            Renderer(output="null://").record(path)


def test_the_package_offers_the_renderer_and_imports_it_only_when_asked() -> None:
    code = ("import sys, tpad_rt; assert 'tpad_rt.engine' not in sys.modules; "
            "from tpad_rt import Renderer; import tpad_rt.engine; assert Renderer is tpad_rt.engine.Renderer; "
            "print('ok')")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.stdout == "ok\n", done.stderr
    with pytest.raises(AttributeError, match="has no attribute 'Renderr'"):
        tpad_rt.Renderr  # noqa: B018


def test_telemetry_can_be_iterated_while_it_runs_until_it_stops() -> None:
    """Stopped from the loop after three periods' rows: iteration yields what came after, then ends; every row
    once, in order (on sim://, each with the plate's measurement)."""
    renderer = Renderer(output="sim://", texture=GRATING)
    with pytest.raises(RuntimeError, match="not running"):
        next(renderer.iter_telemetry())
    renderer.start()
    chunks = []
    for rows in renderer.iter_telemetry(period_s=0.02):
        renderer.push_finger(30.0, 20.0)
        chunks.append(rows)
        if len(chunks) == 3:
            renderer.stop()
    t = np.concatenate([rows["t"] for rows in chunks])
    assert len(chunks) >= 3 and np.all(np.diff(t) > 0)
    assert len(t) == renderer.stats()["blocks"]  # every row, once
    assert all(np.isfinite(rows["achieved_mu"]).all() for rows in chunks)
