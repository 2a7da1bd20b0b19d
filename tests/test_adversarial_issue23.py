"""Adversarial checks of what issue 23 changed: each test names a defect found by attacking the new boundaries
(the ahead-of-time library's loader, ``show``'s time hint, play's headroom hints, the whole-run latency
histogram, the benchmarks' ``--out``, the AOT builder's compiler choice). Real components, no mocks; each runs in
seconds at most."""

from __future__ import annotations

import _ctypes
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from cli_run import tpad_rt
from conftest import REPO_ROOT
from tpad_rt.aot.stamp import library_name, library_stamp
from tpad_rt.cli import main
from tpad_rt.cli.headroom import FingerTally, hint_lines
from tpad_rt.device import Device
from tpad_rt.log_histogram import LogHistogram

TEXTURES = REPO_ROOT / "textures"


def _python(code: str, env: dict[str, str], timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
    """Run ``python -c code`` from the repository root with the worktree first on the path and ``env`` added."""
    full_env = {**os.environ, "PYTHONPATH": str(REPO_ROOT), **env}
    return subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, env=full_env, capture_output=True, text=True,
                          timeout=timeout_s)


def test_aot_loader_survives_a_truncated_library_at_the_stamped_path(tmp_path: Path) -> None:
    """Defect: a shared object cut short (a full disk, an interrupted copy) at the stamped path kills the process
    with SIGBUS inside dlopen (exit 135, no message): ``tpad-rt play`` dies before its first sample. The loader must
    refuse it and fall back to the JIT (load() returns None)."""
    folder = tmp_path / "tpad_rt_aot"
    folder.mkdir()
    whole = Path(_ctypes.__file__).read_bytes()  # any real ELF shared object, cut after its first page
    (folder / library_name(library_stamp())).write_bytes(whole[:4096])
    result = _python("from tpad_rt.aot import library; print(library.load())", {"NUMBA_CACHE_DIR": str(tmp_path)})
    assert result.returncode == 0, f"exit {result.returncode} (-7/135: SIGBUS in dlopen); stderr: {result.stderr!r}"
    assert result.stdout.strip() == "None"


def test_show_refuses_an_absurd_time_in_one_line(tmp_path: Path) -> None:
    """Defect: ``tpad-rt show temporal_pulse --t-s 1e20`` ends in a traceback (ValueError: mu_rel must be in (0, 1],
    got nan, from plate_maps); a time the texture cannot be evaluated at must be refused in one line."""
    run = tpad_rt("show", "temporal_pulse", "--t-s", "1e20", "--resolution-mm", "4", "--out", str(tmp_path / "show.png"))
    assert run.returncode == 1
    assert "Traceback" not in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1, run.stderr


def test_show_time_hint_names_a_time_that_draws_another_level(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Defect: at ``--t-s 86401`` the flat-map hint prints its time with 4 significant digits ("--t-s 8.64e+04
    draws it at 0.6"): 86400 s, a whole number of the texture's 2 s periods, where the map is flat again and the
    hint repeats itself. The time it names must draw another level."""
    out = tmp_path / "show.png"
    texture = str(TEXTURES / "temporal_pulse.yaml")
    assert main(["show", texture, "--t-s", "86401", "--resolution-mm", "4", "--out", str(out)]) == 0
    hint = capsys.readouterr().out
    suggested = re.search(r"--t-s (\S+) draws it at", hint)
    assert suggested is not None, hint
    assert main(["show", texture, "--t-s", suggested.group(1), "--resolution-mm", "4", "--out", str(out)]) == 0
    again = capsys.readouterr().out
    # a temporal texture is flat over the plate at every time, so the second run says so too: at the level named
    drawn = re.search(r"flat at t = \S+ s \((\S+) everywhere\)", again)
    levels = re.search(r"\((\S+) everywhere\).*draws it at (\S+)$", hint.strip())
    assert drawn is not None and levels is not None, (hint, again)
    assert drawn.group(1) == levels.group(2) != levels.group(1), f"--t-s {suggested.group(1)} (from {hint!r}): {again!r}"


def _saturated_tally(speed_mm_s: float, force_n: float, lowest_mu: float) -> FingerTally:
    """100 touching blocks, all saturated, at ``speed_mm_s`` (mm/s) and ``force_n`` (N), asking ``lowest_mu``."""
    return FingerTally(touching=100, saturated=100, speed_sum_mm_s=100 * speed_mm_s, force_sum_n=100 * force_n,
                       lowest_mu=lowest_mu)


def test_headroom_hint_never_suggests_a_finger_faster_than_the_fastest_it_names() -> None:
    """Defect: for a texture asking friction below what the drive reaches near the speed floor (``friction.low:
    0.001``; play at 30 mm/s), the hint says "a finger at most 1 mm/s reaches 0.01: try --input
    'scripted://swipe?speed_mm_s=5...'": the suggested speed is rounded up to a 5 mm/s floor, above the fastest it
    just named. Played at that suggestion, the summary saturates again and suggests the very input it ran."""
    lines = hint_lines(_saturated_tally(30.0, 0.5, 0.01), Device.default(), 40.0, 0.8, 100, 50, 50)
    text = " ".join(lines)
    fastest = re.search(r"a finger at most (\S+) mm/s reaches", text)
    suggested = re.search(r"speed_mm_s=([0-9.e+-]+)&", text)
    if suggested is not None:  # a speed suggested is one the hint says reaches the level
        assert fastest is not None and float(suggested.group(1)) <= float(fastest.group(1)), text
    else:  # below the speed floor no finger reaches it: the hint says so instead of naming a speed
        assert fastest is None and "no finger speed reaches 0.01" in text, text


def test_headroom_hint_does_not_suggest_the_input_the_run_used() -> None:
    """Defect: a run that saturated at 5 mm/s is told "a slower finger leaves more headroom (try --input
    'scripted://swipe?speed_mm_s=5&force_n=0.5...')": the very finger it ran with (the 5 mm/s rounding floor)."""
    lines = hint_lines(_saturated_tally(5.0, 0.5, 0.75), Device.default(), 40.0, 0.8, 100, 50, 0)
    text = " ".join(lines)
    assert "speed_mm_s=5&force_n=0.5&" not in text, text


def test_log_histogram_refuses_a_percentile_beyond_100() -> None:
    """Defect: percentile(150) reads one bin past the last and answers 1.01 for a histogram bounded at 1.0 holding
    only 0.001 (a value above every value added and above ``high``). A q outside [0, 100] must raise ValueError."""
    histogram = LogHistogram(1e-6, 1.0)
    histogram.add([1e-3])
    with pytest.raises(ValueError):
        histogram.percentile(150.0)


def test_bench_smoke_out_naming_a_file_is_one_line(tmp_path: Path) -> None:
    """Defect: ``python bench/kernel/run.py --smoke --out FILE`` (and emulator_pty.py) runs the whole benchmark,
    then ends in a traceback (FileExistsError from Path.mkdir) and loses the results. --out must be checked up front
    and refused in one line."""
    target = tmp_path / "a_file"
    target.write_text("not a folder\n")
    script = "kernel/run.py"  # latency/emulator_pty.py, latency/run.py and the others do the same (suite time)
    result = subprocess.run([sys.executable, str(REPO_ROOT / "bench" / script), "--smoke", "--out", str(target)],
                            cwd=REPO_ROOT, env={**os.environ, "PYTHONPATH": str(REPO_ROOT)}, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode != 0
    assert "Traceback" not in result.stderr, result.stderr[-600:]


def test_aot_build_names_the_cc_it_could_not_find() -> None:
    """Defect: with ``CC=/nonexistent/cc`` (or ``CC='gcc -m64'``, a compiler with flags, as make allows) the builder
    says "no C compiler (set CC, or install cc, gcc or clang)" although CC is set and cc is installed: the line
    must name the CC it could not run."""
    result = _python("from tpad_rt.aot.build import main; raise SystemExit(main())", {"CC": "/nonexistent/cc"})
    assert result.returncode == 1
    assert "/nonexistent/cc" in result.stderr, result.stderr


def test_plot_along_x_of_a_run_that_never_touches_says_so(tmp_path: Path) -> None:
    """Defect: ``tpad-rt plot REC --along x`` of a recording whose finger never touched (play --record with the
    mouse and no button held; here a file:// trajectory with down = 0) writes four empty panels, x from -0.05 to
    0.05 mm, and says only "wrote FILE" (exit 0). It must say there is no touching block to plot along x."""
    trajectory = tmp_path / "lifted.csv"
    trajectory.write_text("t,x_mm,y_mm,down\n0,40,30,0\n0.1,60,30,0\n0.2,80,30,0\n")
    recording = tmp_path / "lifted.npz"
    rendered = tpad_rt("render", "grating", "--input", f"file://{trajectory}", "--out", str(recording))
    assert rendered.returncode == 0, rendered.stderr
    run = tpad_rt("plot", str(recording), "--along", "x", "--out", str(tmp_path / "plot.png"))
    assert "Traceback" not in run.stderr
    assert run.returncode != 0 or "touch" in run.stdout, (run.returncode, run.stdout, run.stderr)


def test_bench_smoke_without_out_leaves_the_committed_results_alone() -> None:
    """Defect: ``python bench/kernel/run.py --smoke`` (no --out; emulator_pty.py too) overwrites the committed
    bench/results/kernel.{json,md} with a smoke run's figures, which its own docstring calls meaningless. A smoke
    run must write elsewhere (a temporary folder) or ask for --out. The files are restored afterwards."""
    script, stem = "kernel/run.py", "kernel"  # emulator_pty.py does the same (suite time: one is enough)
    results = [REPO_ROOT / "bench" / "results" / f"{stem}.{suffix}" for suffix in ("json", "md")]
    before = [path.read_bytes() for path in results]
    try:
        done = subprocess.run([sys.executable, str(REPO_ROOT / "bench" / script), "--smoke"], cwd=REPO_ROOT,
                              env={**os.environ, "PYTHONPATH": str(REPO_ROOT)}, capture_output=True, text=True,
                              timeout=120)
        after = [path.read_bytes() for path in results]
    finally:  # put back only what changed: other tests watch these files' times
        for path, content in zip(results, before):
            if path.read_bytes() != content:
                path.write_bytes(content)
    assert after == before, f"a smoke run without --out rewrote {[str(path) for path in results]}"
    assert done.returncode != 0 and "--out" in done.stderr and "Traceback" not in done.stderr, done.stderr


def test_aot_build_interrupted_ends_without_a_traceback() -> None:
    """Defect: Ctrl-C during ``python -m tpad_rt.aot.build`` (once it says "aot: compiling ...") ends in a
    KeyboardInterrupt traceback. Issue 23 asks that Ctrl-C stop a compile at once; it must end in one line and a
    non-zero exit, as every tpad-rt command does."""
    process = subprocess.Popen([sys.executable, "-m", "tpad_rt.aot.build"], cwd=REPO_ROOT, text=True,
                               env={**os.environ, "PYTHONPATH": str(REPO_ROOT)}, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert process.stderr is not None
    first = process.stderr.readline()  # the builder's first progress line: it is under way
    process.send_signal(signal.SIGINT)
    _, rest = process.communicate(timeout=60)
    assert first.startswith("aot: "), first
    assert process.returncode != 0
    assert "Traceback" not in rest, rest[-600:]
