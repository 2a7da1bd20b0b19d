"""The pieces of compiling once that need no compile: the plan's mark in numba's cache folder, the clean-up after
killed workers, the check that steps running at once compile disjoint functions, and the wait for another
process's compile. tests/test_compiling_plan.py runs the whole plan."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO_ROOT

from tpad_rt import kernel_cache
from tpad_rt.compile_runner import PlanReport


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty numba cache (NUMBA_CACHE_DIR); the kernels' folder in it."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    folder = kernel_cache.cache_dir(kernel_cache.COMPILED_PACKAGES[0])
    folder.mkdir(parents=True)
    return folder


def test_the_mark_says_the_plan_finished_for_these_sources_only(cache: Path) -> None:
    assert not kernel_cache.plan_complete() and not kernel_cache.marked_before()
    (cache / "tpad-rt-plan.0123456789abcdef.done").write_text("an older source's\n")
    assert not kernel_cache.plan_complete() and kernel_cache.marked_before()
    kernel_cache.mark_plan_complete()
    assert kernel_cache.plan_complete() and not kernel_cache.marked_before()  # the old mark is gone
    assert [path.name for path in cache.iterdir()] == [f"tpad-rt-plan.{kernel_cache.plan_stamp()[:16]}.done"]


def _write(path: Path, mtime_ns: int) -> Path:
    path.write_bytes(b"x")
    os.utime(path, ns=(mtime_ns, mtime_ns))
    return path


def test_a_killed_write_leaves_nothing_a_later_run_would_trust(cache: Path) -> None:
    """An index written since the run began whose newest data file is older (or missing) goes, as do temporary
    files; an older index, or one whose data followed it, stays."""
    since_ns = 1_000_000_000_000_000_000
    before, after = since_ns - 10**9, since_ns + 10**9
    stale = _write(cache / "render.render_block-215.py311.nbi", after)
    _write(cache / "render.render_block-215.py311.1.nbc", before)  # the old source's data under a reused name
    missing = _write(cache / "render._ring_sum-300.py311.nbi", after)
    finished = _write(cache / "sim.resonate-50.py311.nbi", after)
    _write(cache / "sim.resonate-50.py311.1.nbc", after + 1)
    untouched = _write(cache / "sim.felt_friction-90.py311.nbi", before)
    _write(cache / "sim.felt_friction-90.py311.1.nbc", before - 1)
    partial = _write(cache / "sim.resonate-50.py311.2.nbc.tmp.0123456789abcdef", after)
    assert kernel_cache.discard_unfinished(since_ns) == 3
    assert not stale.exists() and not missing.exists() and not partial.exists()
    assert finished.exists() and untouched.exists()


def test_functions_two_steps_running_at_once_both_compiled_are_found() -> None:
    report = PlanReport(compiled={"a": ["tpad_rt.kernel.render.f", "tpad_rt.kernel.render.g"],
                                  "b": ["tpad_rt.kernel.render.g"], "c": ["tpad_rt.kernel.render.f"]},
                        concurrent={frozenset(("a", "b"))})
    assert report.shared() == {"tpad_rt.kernel.render.g"}  # a and c compiled f one after the other: safe
    assert report.functions == 4


def test_discarding_a_function_removes_its_index(cache: Path) -> None:
    index = _write(cache / "render.render_block-215.py311.nbi", 1)
    other = _write(cache / "render.render_blocks-30.py311.nbi", 1)
    kernel_cache.discard_functions({"tpad_rt.kernel.render.render_block"})
    assert not index.exists() and other.exists()


def test_a_second_process_waits_for_the_compile_in_progress(cache: Path) -> None:
    """While one process holds the compile lock, ``tpad-rt warm`` says it waits, and once the plan is marked
    complete and the lock let go it finds nothing to compile."""
    waited = []
    with kernel_cache.compile_lock(lambda: waited.append(True)):
        assert not waited
        warm = subprocess.Popen([sys.executable, "-m", "tpad_rt", "warm"], cwd=REPO_ROOT, stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=dict(os.environ, PYTHONPATH=str(REPO_ROOT), CC="no-such-compiler"))
        assert warm.stderr is not None
        assert warm.stderr.readline() == "tpad-rt: waiting for another tpad-rt that is compiling the kernels\n"
        kernel_cache.mark_plan_complete()
    out, err = warm.communicate(timeout=120)
    assert warm.returncode == 0 and err == ""
    assert out.splitlines() == [f"tpad-rt warm: every kernel is compiled already, cached in {cache}",
                                "tpad-rt warm: no C compiler ($CC (no-such-compiler) names no program): the ahead-of-time audio "
                                "callbacks are not built; the renderer uses numba's, which start about half a second "
                                "later"]


def test_warm_refuses_a_job_count_out_of_range_in_one_line() -> None:
    done = subprocess.run([sys.executable, "-m", "tpad_rt", "warm", "--jobs", "0"], cwd=REPO_ROOT, capture_output=True,
                          text=True, timeout=120, env=dict(os.environ, PYTHONPATH=str(REPO_ROOT)))
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr == ("tpad-rt warm: error: argument --jobs: must be a whole number in [1, 64] (workers), got '0' "
                           "(see 'tpad-rt warm --help')\n")
