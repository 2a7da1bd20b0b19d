"""One compile covers every path: ``tpad-rt warm`` in an empty numba cache compiles the whole plan, with progress
as steps done of the total, and stops at Ctrl-C leaving nothing to trust; after it, ``play`` on every output,
``render``, ``serve`` and the README's snippets compile nothing, and ``warm`` says all is compiled already.

One cold compile for the whole module (the ``warmed`` fixture, about a minute of CPU): it is interrupted once
its first step is done, then run again to the end in the same cache.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from amp_emulator import Emulator
from compile_counter import COMPILED
from conftest import REPO_ROOT

from tpad_rt import kernel_cache
from tpad_rt.aot.build import find_compiler
from tpad_rt.compile_plan import STEPS
from tpad_rt.compiling import NOTICE

#: A bound a loaded machine meets for Ctrl-C to end a compile (the 1 s target is measured, not asserted here).
INTERRUPT_BOUND_S = 5.0
#: The longest a cold compile of the whole plan may take here (s): a busy 2-core machine's.
COLD_TIMEOUT_S = 900
PROGRESS = re.compile(r"tpad-rt: compiling: (\d+)/(\d+) steps done \((.+)\), \d+ s")
SCRIPTED = "scripted://swipe?speed_mm_s=100&repeat=0&back_and_forth=1"
README_PYTHON = re.findall(r"```python\n(.*?)```", (REPO_ROOT / "README.md").read_text(), re.S)


@dataclass
class Warmed:
    """The module's numba cache (``env`` names it) and what the interrupted and the finished warm did."""

    env: dict[str, str]
    cache: Path
    interrupted: subprocess.CompletedProcess[str]
    interrupt_s: float
    finished: subprocess.CompletedProcess[str]


def _warm(env: dict[str, str]) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "tpad_rt", "warm", "--jobs", "2"], cwd=REPO_ROOT, env=env,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _interrupt_after_first_step(env: dict[str, str]) -> tuple[subprocess.CompletedProcess[str], float]:
    """Start a cold warm, send it SIGINT once it says its first step is done (a worker compiles the next);
    the result and the seconds from the signal to its exit."""
    warm = _warm(env)
    assert warm.stderr is not None
    seen = []
    for line in warm.stderr:
        seen.append(line)
        if PROGRESS.match(line):
            break
    signalled_s = time.monotonic()
    warm.send_signal(signal.SIGINT)
    try:
        out, err = warm.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        warm.kill()
        raise AssertionError("tpad-rt warm did not end at SIGINT") from None
    return subprocess.CompletedProcess(warm.args, warm.returncode, out, "".join(seen) + err), \
        time.monotonic() - signalled_s


@pytest.fixture(scope="module")
def warmed(tmp_path_factory: pytest.TempPathFactory) -> Warmed:
    cache = tmp_path_factory.mktemp("numba-cache")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(REPO_ROOT))
    interrupted, interrupt_s = _interrupt_after_first_step(env)
    finished = _warm(env)
    out, err = finished.communicate(timeout=COLD_TIMEOUT_S)
    return Warmed(env, cache, interrupted, interrupt_s,
                  subprocess.CompletedProcess(finished.args, finished.returncode, out, err))


def _workers_of(cache: Path) -> list[int]:
    """PIDs of compile workers still running for ``cache``."""
    pids = []
    for proc in Path("/proc").iterdir():
        try:
            if (proc.name.isdigit() and b"tpad_rt.compile_plan" in (proc / "cmdline").read_bytes()
                    and f"NUMBA_CACHE_DIR={cache}".encode() in (proc / "environ").read_bytes()):
                pids.append(int(proc.name))
        except OSError:
            continue
    return pids


def test_ctrl_c_stops_a_compile_at_once_and_leaves_nothing_half_written(warmed: Warmed) -> None:
    done = warmed.interrupted
    assert done.returncode == 130, done.stderr
    assert done.stderr.splitlines()[-1] == "tpad-rt warm: interrupted"
    assert "Traceback" not in done.stderr
    assert warmed.interrupt_s < INTERRUPT_BOUND_S
    assert _workers_of(warmed.cache) == []


def test_warm_compiles_the_whole_plan_with_progress_as_steps_done_of_the_total(warmed: Warmed) -> None:
    done = warmed.finished
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    assert lines[0].startswith(NOTICE) and "no complete compile" in lines[0] and "Ctrl-C stops" in lines[0]
    progress = [PROGRESS.fullmatch(line) for line in lines[1:-1]]
    assert all(progress) and 1 <= len(progress) <= 10, lines
    counts = [(int(match[1]), int(match[2])) for match in progress if match]
    assert {total for _, total in counts} == {len(STEPS)}
    assert [count for count, _ in counts] == sorted({count for count, _ in counts}) and counts[-1][0] == len(STEPS)
    final = re.fullmatch(r"tpad-rt: compiled (\d+) functions in [\d.]+ s with 2 jobs, cached in (.+)", lines[-1])
    assert final is not None, lines[-1]
    built = re.fullmatch(r"tpad-rt warm: built the ahead-of-time audio callbacks: (.+)\n", done.stdout)
    if find_compiler() is None:
        assert done.stdout.startswith("tpad-rt warm: no C compiler"), done.stdout
    else:  # the library for these sources, where numba's cache is (NUMBA_CACHE_DIR)
        assert built is not None, done.stdout
        assert Path(built[1]).parent == warmed.cache / "tpad_rt_aot" and Path(built[1]).is_file()
    assert int(final[1]) > 20  # the rest of the plan after the interrupted run's first step
    assert list(Path(final[2]).glob("render.render_block-*.nbi"))  # where numba itself put the render kernel
    assert not list(warmed.cache.rglob("*.tmp.*"))


def test_warm_again_says_everything_is_compiled(warmed: Warmed) -> None:
    again = subprocess.run([sys.executable, "-m", "tpad_rt", "warm"], cwd=REPO_ROOT, env=warmed.env,
                           capture_output=True, text=True, timeout=120)
    assert again.returncode == 0 and again.stderr == ""
    assert again.stdout.startswith("tpad-rt warm: every kernel is compiled already, cached in ")
    if find_compiler() is not None:  # and the ahead-of-time library is not built twice
        assert again.stdout.splitlines()[1].startswith("tpad-rt warm: the ahead-of-time audio callbacks are built "
                                                       f"already: {warmed.cache / 'tpad_rt_aot'}")


def _counted(args: list[str], env: dict[str, str]) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, str(REPO_ROOT / "tests" / "compile_counter.py"), *args], cwd=REPO_ROOT,
                            env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def _assert_compiled_nothing(name: str, process: subprocess.Popen[str], err: str) -> None:
    assert process.returncode == 0, (name, err)
    last = err.splitlines()[-1]
    assert last.startswith(COMPILED), (name, err)
    assert json.loads(last[len(COMPILED):]) == [], (name, err)
    assert NOTICE not in err, (name, err)


def test_after_warm_no_path_compiles_anything(warmed: Warmed, tmp_path: Path) -> None:
    """Every path, each in its own process: play on sim://, wav://, null:// (at once with the rest) and
    serial:// (the emulator on a pty; alone, so that the link's measured rate is not the machine's load),
    render, serve, the README's Pipeline and Renderer snippets. None compiles a function of tpad-rt nor starts a
    compile of the plan."""
    for index, code in enumerate(README_PYTHON[1:]):
        (tmp_path / f"readme_{index}.py").write_text(code)
    play = ["play", "textures/grating.yaml", "--input", SCRIPTED, "--duration", "0.3", "--output"]
    paths = {
        "play sim": [*play, "sim://"],
        "play wav": [*play, f"wav://{tmp_path / 'drive.wav'}"],
        "play null": [*play, "null://"],
        "render": ["render", "textures/grating.yaml", "--input", SCRIPTED, "--duration", "0.3",
                   "--out", str(tmp_path / "render.npz")],
        "serve": ["serve", "grating", "--output", "sim://", "--port", "0", "--no-osc", "--duration", "0.3"],
        "Pipeline snippet": [str(tmp_path / "readme_0.py")],
        "Renderer snippet": [str(tmp_path / "readme_1.py")],
    }
    running = {name: _counted(args, warmed.env) for name, args in paths.items()}
    for name, process in running.items():
        _assert_compiled_nothing(name, process, process.communicate(timeout=300)[1])
    with Emulator(tmp_path / "amp") as emulator:
        serial = _counted([*play, f"serial://{emulator.port}"], warmed.env)
        _assert_compiled_nothing("play serial", serial, serial.communicate(timeout=300)[1])


def test_the_mark_is_where_numba_caches_the_kernels(warmed: Warmed, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(warmed.cache))
    assert kernel_cache.plan_complete()
    assert list(kernel_cache.cache_dir(kernel_cache.COMPILED_PACKAGES[0]).glob("render.render_block-*.nbi"))
    assert list(kernel_cache.cache_dir(kernel_cache.COMPILED_PACKAGES[1]).glob("friction.*.nbi"))
