"""wav:// output: a 32-bit float WAV that SciPy reads back sample for sample."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from tpad_rt.device import Device
from tpad_rt.errors import BackendError, ConfigError
from tpad_rt.outputs import open_output


def test_blocks_round_trip_through_scipy(tmp_path: Path) -> None:
    path = tmp_path / "out.wav"
    samples = np.random.default_rng(3).uniform(-1, 1, 1000).astype(np.float32)
    with open_output(f"wav://{path}", device=Device.default(), fs_hz=192000) as output:
        for start in range(0, len(samples), 64):
            output.write(samples[start:start + 64], {})
    rate, data = wavfile.read(path)
    assert rate == 192000 and data.dtype == np.float32
    assert np.array_equal(data, samples)
    header = path.read_bytes()[:58]
    assert header[:4] == b"RIFF" and header[8:12] == b"WAVE"
    assert struct.unpack("<I", header[4:8])[0] == path.stat().st_size - 8
    fmt_tag, channels, fs, byte_rate, align, bits = struct.unpack("<HHIIHH", header[20:36])
    assert (fmt_tag, channels, fs, byte_rate, align, bits) == (3, 1, 192000, 768000, 4, 32)
    assert header[38:42] == b"fact" and struct.unpack("<I", header[46:50])[0] == 1000


def test_empty_file_is_still_valid(tmp_path: Path) -> None:
    path = tmp_path / "empty.wav"
    output = open_output(f"wav://{path}", device=Device.default(), fs_hz=48000)
    output.close()
    output.close()
    rate, data = wavfile.read(path)
    assert rate == 48000 and data.shape == (0,)


def test_relative_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    with open_output("wav://sub.wav", device=Device.default(), fs_hz=48000) as output:
        output.write(np.zeros(8, dtype=np.float32), {})
    assert wavfile.read(tmp_path / "sub.wav")[1].shape == (8,)


def test_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"output URL 'wav://': missing the file path; expected wav:///path/out\.wav"):
        open_output("wav://", device=Device.default(), fs_hz=48000)
    with pytest.raises(ConfigError, match=r"unknown option 'rate' \(options: none\)"):
        open_output(f"wav://{tmp_path}/a.wav?rate=1", device=Device.default(), fs_hz=48000)
    with pytest.raises(ConfigError, match=r"/no/such/dir/a\.wav: cannot write WAV files there: no folder .*/no/such/dir"):
        open_output(f"wav://{tmp_path}/no/such/dir/a.wav", device=Device.default(), fs_hz=48000)


@pytest.mark.parametrize(("bad", "problem"), [(np.nan, "not finite"), (-np.inf, "not finite"),
                                              (1.5, r"beyond full scale \(\|sample\| > 1\)")])
def test_a_bad_sample_is_refused_and_the_file_kept_valid_up_to_its_block(
    tmp_path: Path, bad: float, problem: str
) -> None:
    path = tmp_path / "out.wav"
    good = np.full(64, 0.5, dtype=np.float32)
    block = good.copy()
    block[10] = bad
    output = open_output(f"wav://{path}", device=Device.default(), fs_hz=192000)
    output.write(good, {})
    expected = (rf"wav: .*out\.wav: drive sample 74 is {bad!r}, {problem}: .*this is a bug in tpad-rt, please "
                r"report it; the file was closed holding the 64 samples written before this write")
    with pytest.raises(BackendError, match=expected):
        output.write(block, {})
    rate, data = wavfile.read(path)
    assert rate == 192000 and np.array_equal(data, good)
    with pytest.raises(BackendError, match=r"out\.wav is closed; nothing more can be written to it"):
        output.write(good, {})
    output.close()  # closing again is fine
    assert np.array_equal(wavfile.read(path)[1], good)


def test_full_scale_itself_is_written(tmp_path: Path) -> None:
    samples = np.array([1.0, -1.0, 0.0], dtype=np.float32)
    with open_output(f"wav://{tmp_path}/edge.wav", device=Device.default(), fs_hz=48000) as output:
        output.write(samples, {})
    assert np.array_equal(wavfile.read(tmp_path / "edge.wav")[1], samples)
