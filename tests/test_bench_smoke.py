"""Every benchmark still runs (issue 23: the latency bench once broke unnoticed, since nothing ran it): each
script in its smoke mode, writing to a temporary folder, exits 0 and writes its JSON and its Markdown table,
and no configuration it measured reported an error. Nothing here judges a figure (docs/testing.md "Three
tiers"): a smoke run's windows are too short for its figures to mean anything.

The serve benchmark's smoke run is tests/test_bench_serve.py (it also checks what each phase measured);
bench/kernel/compare.py builds two git revisions, which a shallow clone lacks, and is not run here.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from conftest import require_program

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
#: Script (under bench/) -> its smoke arguments (``--out DIR`` follows) and the stem of its result files.
SMOKES = {
    "kernel/run.py": (["--smoke"], "kernel"),
    "latency/run.py": (["--smoke"], "latency"),
    "latency/serial_run.py": (["--smoke"], "latency_serial"),
    "latency/emulator_pty.py": (["--smoke"], "emulator_pty"),
    "memory/play_rss.py": (["--seconds", "3"], "memory_play"),
    "fidelity/step_response.py": (["--levels", "0.5"], "step_response"),
}
#: Benchmarks smoke-run elsewhere, or not at all: why.
ELSEWHERE = {
    "latency/serve_run.py": "tests/test_bench_serve.py",
    "kernel/compare.py": "compares two git revisions: a shallow clone lacks the history",
}
#: The smoke runs that need a JACK server (jackd, jack_wait, jack_lsp).
NEEDS_JACK = {"latency/run.py"}


def test_every_benchmark_has_a_smoke_run() -> None:
    """A benchmark is a script that writes its results to bench/results by default."""
    benchmarks = {path.relative_to(BENCH).as_posix() for path in BENCH.rglob("*.py")
                  if '"bench" / "results"' in path.read_text()}
    assert benchmarks == set(SMOKES) | set(ELSEWHERE)


def _errors(report: Any, where: str = "") -> Iterator[str]:
    """Where ``report`` (a JSON document) holds an ``error`` entry: a configuration that failed to run."""
    if isinstance(report, dict):
        for key, value in report.items():
            if key == "error":
                yield f"{where}: {value}"
            yield from _errors(value, f"{where}.{key}")
    elif isinstance(report, list):
        for index, value in enumerate(report):
            yield from _errors(value, f"{where}[{index}]")


def _results_state() -> dict[str, float]:
    return {path.name: path.stat().st_mtime for path in (BENCH / "results").iterdir()}


@pytest.mark.slow
@pytest.mark.parametrize("script", [pytest.param(script, marks=[pytest.mark.system] if script in NEEDS_JACK else [])
                                    for script in sorted(SMOKES)])
def test_the_benchmark_runs_in_its_smoke_mode(script: str, tmp_path: Path) -> None:
    arguments, stem = SMOKES[script]
    if script in NEEDS_JACK:
        for program in ("jackd", "jack_wait", "jack_lsp"):
            require_program(program)
    results_before = _results_state()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run([sys.executable, str(BENCH / script), *arguments, "--out", str(tmp_path)], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=280, stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads((tmp_path / f"{stem}.json").read_text())
    assert not list(_errors(report)), list(_errors(report))
    table = (tmp_path / f"{stem}.md").read_text()
    assert any(line.startswith("|") and set(line) <= set("|-: ") for line in table.splitlines()), table
    assert _results_state() == results_before  # bench/results untouched
