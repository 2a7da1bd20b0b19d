"""Absurd sizes from the command line end in one line and exit 1, within 500 MB, before anything runs.

Each case runs the real CLI in a fresh interpreter and measures that process's own peak
resident memory (tests/cli_run.py): an import of tpad-rt is about 200 MB with numba's
cache warm (the module warms it first), so a case that started to allocate for the size
it was given (gigabytes) fails here.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_run import tpad_rt, warm_numba_cache
from tpad_rt.errors import ConfigError
from tpad_rt.limits import MAX_TRAJECTORY_BYTES, MAX_TRAJECTORY_ROWS
from tpad_rt.offline import check_render_size

PEAK_MB = 500
GRATING = "textures/grating.yaml"
SWIPE = "scripted://swipe?speed_mm_s=100"


@pytest.fixture(autouse=True, scope="module")
def _warm() -> None:
    """Compile the kernels into numba's cache first (cli_run.warm_numba_cache)."""
    warm_numba_cache()


def _render(tmp_path: Path, *args: str, out: str = "x.npz") -> list[str]:
    return ["render", GRATING, *args, "--out", str(tmp_path / out)]


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--input", "scripted://tap?count=1000000000"],
         "input URL 'scripted://tap?count=1000000000': ends after 499,999,999.7 s, longer than the 86400 s an input "
         "may last; expected scripted://tap?"),
        (["--input", "scripted://swipe?speed_mm_s=1e-300"],
         "option speed_mm_s: must be a number in [0.01, 10000], got '1e-300'"),
        (["--input", "scripted://swipe?repeat=1000000000&speed_mm_s=0.01"], "longer than the 86400 s"),
        (["--input", "scripted://circle?turns=1e300"], "ends after 1.26e+300 s"),
        (["--input", "scripted://still?duration_s=1e9"], "option duration_s: must be a number in (0, 86400] or inf"),
        (["--input", "scripted://tap?down_s=1e300"], "option down_s: must be a number in (0, 86400]"),
        (["--input", "scripted://swipe?to_mm=1e300"],
         "option to_mm: must be in [-130, 260] mm (x on the plate, up to one plate size beyond each edge), got 1e+300"),
        (["--input", "scripted://circle?radius_mm=100"], "option center_mm y - radius_mm: must be in [-60, 120] mm"),
        (["--input", "scripted://still?y_mm=-61"], "option y_mm: must be in [-60, 120] mm"),
        (["--input", "scripted://tap?force_n=1e6"], "option force_n: must be a number in [0, 50], got '1e6'"),
        (["--input", "scripted://tap?count=99999999999"], "option count: must be a whole number in [0, 1000000000]"),
        (["--input", SWIPE, "--rate", "1000000000"],
         "argument --rate: must be a whole number in [1, 768000] (Hz, the highest rate tpad-rt runs at), "
         "got '1000000000'"),
        (["--input", SWIPE, "--block", "100000"], "argument --block: must be a whole number in [1, 65536] (frames)"),
        (["--input", SWIPE, "--block", "0"], "argument --block: must be a whole number in [1, 65536]"),
        (["--input", SWIPE, "--duration", "1e12"],
         "argument --duration: must be a number in (0, 3600] (s), got '1e12'"),
        (["--input", "scripted://swipe?repeat=0", "--duration", "1000"],
         "a recording of 1000 s at 192000 Hz holds 192,001,088 drive samples, more than the 67,108,864 a recording "
         "keeps in memory (349 s at this rate)"),
        (["--input", "scripted://still?duration_s=7200"], "ends after 7200 s, but a render must last"),
        (["--input", "file:///dev/zero"],
         "/dev/zero: not a regular file (a character device); tpad-rt reads trajectories from regular files only"),
        (["--input", "file:///tmp/a%00b.csv"],
         "input URL 'file:///tmp/a%00b.csv': holds the control character \\x00 (after unquoting)"),
        (["--input", "file:///tmp/a%0ab.csv"], "holds the control character \\x0a"),
        (["--input", "scripted://swipe?y_mm=30" + "0" * 5000], "characters long, more than the 4,096 a URL may have"),
    ],
)
def test_render_refuses_absurd_sizes(tmp_path: Path, args: list[str], expected: str) -> None:
    done = tpad_rt(*_render(tmp_path, *args))
    done.assert_one_line_error(expected)
    assert done.stderr.startswith("tpad-rt render: ")
    assert done.peak_mb < PEAK_MB
    assert not (tmp_path / "x.npz").exists()


def test_blocks_are_bounded_for_a_wav_render(tmp_path: Path) -> None:
    done = tpad_rt(*_render(tmp_path, "--input", "scripted://swipe?repeat=0", "--duration", "3000", "--block", "1",
                            out="x.wav"))
    done.assert_one_line_error("3000 s at 192000 Hz in blocks of 1 is 576,000,993 blocks, more than the 4,194,304 a "
                               "render keeps telemetry for")
    assert done.peak_mb < PEAK_MB
    assert not (tmp_path / "x.wav").exists()  # refused before the output opened


def test_a_wav_past_4_gib_is_refused_before_rendering(tmp_path: Path) -> None:
    done = tpad_rt("render", GRATING, "--input", "scripted://still?duration_s=inf", "--duration", "1500",
                   "--rate", "768000", "--block", "65536", "--out", str(tmp_path / "big.wav"))
    done.assert_one_line_error("bytes of WAV samples, more than the 4,294,967,245 a WAV file holds (4 GiB)")
    assert done.peak_mb < PEAK_MB
    assert not list(tmp_path.glob("*.wav"))  # refused before the output opened


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--duration", "1e12"], "argument --duration: must be a number in (0, 86400] (s), got '1e12'"),
        (["--rate", "1000000000"], "argument --rate: must be a whole number in [1, 768000]"),
        (["--block", "100000"], "argument --block: must be a whole number in [1, 65536]"),
        (["--input", "scripted://tap?count=1000000000"], "ends after 499,999,999.7 s"),
    ],
)
def test_play_refuses_absurd_sizes(args: list[str], expected: str) -> None:
    done = tpad_rt("play", GRATING, "--output", "null://", *args)
    done.assert_one_line_error(expected)
    assert done.peak_mb < PEAK_MB


def test_a_trajectory_sample_at_1e12_s_is_refused_at_its_line(tmp_path: Path) -> None:
    path = tmp_path / "far.csv"
    path.write_text("t,x_mm,y_mm\n0,10,30\n1e12,20,30\n")
    done = tpad_rt(*_render(tmp_path, "--input", f"file://{path}"))
    done.assert_one_line_error(f"{path}:3: column t: must be a finite number in [0, 86400] s, got '1e12'")
    assert done.peak_mb < PEAK_MB


def test_a_trajectory_larger_than_64_mib_is_refused_before_reading(tmp_path: Path) -> None:
    path = tmp_path / "huge.csv"
    with path.open("wb") as stream:  # sparse: ten million rows' worth of bytes, none written
        stream.write(b"t,x_mm,y_mm\n")
        stream.truncate(MAX_TRAJECTORY_BYTES + 1)
    done = tpad_rt(*_render(tmp_path, "--input", f"file://{path}", "--duration", "0.05"))
    done.assert_one_line_error(f"{path}: file is larger than 64 MiB")
    assert done.peak_mb < PEAK_MB


@pytest.mark.slow
def test_a_trajectory_with_too_many_rows_is_refused_within_bounded_memory(tmp_path: Path) -> None:
    path = tmp_path / "long.csv"
    rows = MAX_TRAJECTORY_ROWS + 1
    with path.open("w") as stream:
        stream.write("t,x_mm,y_mm\n")
        for start in range(0, rows, 100_000):
            stream.write("".join(f"{k / 1000},10,30\n" for k in range(start, min(rows, start + 100_000))))
    assert path.stat().st_size < MAX_TRAJECTORY_BYTES  # the row limit is hit, not the size limit
    done = tpad_rt(*_render(tmp_path, "--input", f"file://{path}", "--duration", "0.05"))
    done.assert_one_line_error(f"{path}:{rows + 1}: more than 2,000,000 samples, the most a trajectory may hold")
    assert done.peak_mb < PEAK_MB


@pytest.mark.parametrize("command", [
    ["render", GRATING, "--input", "scripted://tap?count=1000000000", "--out", "x.npz"],
    ["play", GRATING, "--input", "scripted://tap?count=1000000000", "--output", "null://"],
    ["play", GRATING, "--input", "file:///dev/zero", "--output", "null://"],
    ["play", "tests/bad_files/negative_period.yaml", "--input", "scripted://swipe", "--output", "null://"],
    ["play", GRATING, "--input", "scripted://swipe", "--output", "nul://"],
])
def test_a_refusal_compiles_nothing_even_with_a_cold_numba_cache(tmp_path: Path, command: list[str]) -> None:
    """An empty numba cache: a refusal must not pay for compiling the kernels (about 1 GB and a minute)."""
    done = tpad_rt(*command, env={"NUMBA_CACHE_DIR": str(tmp_path / "cold-cache")})
    done.assert_one_line_error("")
    assert done.peak_mb < 300, done.peak_mb
    compiled = [path.name for path in (tmp_path / "cold-cache").rglob("*.nbi")]
    assert not [name for name in compiled if name.startswith(("render.", "callback."))], compiled  # no kernel


def test_a_wav_output_url_counts_for_the_wav_size_limit() -> None:
    check_render_size(1500.0, 0.0, 768000, 65536, keep_drive=False)  # no WAV: within the other limits
    with pytest.raises(ConfigError, match="more than the 4,294,967,245 a WAV file holds"):
        check_render_size(1500.0, 0.0, 768000, 65536, keep_drive=False, writes_wav=True)
