"""The latency benchmark's worker (bench/latency/worker.py, what bench/latency/run.py runs for every measured
configuration) still runs: on a real JACK dummy server it streams the tpad-rt callback and the empty baseline
and reports the figures run.py tabulates. Figures are the benchmark's to report, not the test's to judge
(docs/testing.md "Three tiers"): the native callback under GIL load next to a Python callback is compared there.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from jack_server import server_process

WORKER = Path(__file__).resolve().parents[1] / "bench" / "latency" / "worker.py"

pytestmark = pytest.mark.system


def run_worker(server_name: str, *args: str) -> dict:
    """worker.py ARGS as run.py runs it; its RESULT."""
    done = subprocess.run([sys.executable, str(WORKER), *args], capture_output=True, text=True, timeout=300,
                          stdin=subprocess.DEVNULL, env={**os.environ, "JACK_DEFAULT_SERVER": server_name})
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.splitlines()[-1].removeprefix("RESULT "))


def test_the_latency_worker_reports_the_figures_run_py_tabulates() -> None:
    with server_process() as server:
        tpad = run_worker(server.name, "stream", "tpad", "--block", "64", "--seconds", "0.5", "--gil-threads", "1")
        silence = run_worker(server.name, "stream", "silence", "--block", "64", "--seconds", "0.5")
    for result in (tpad, silence):
        assert result["callbacks"] > 0 and result["records"] > 0, result
        assert result["compute_us"]["n"] > 0 and result["compute_us"]["p50"] <= result["compute_us"]["max"]
        assert math.isfinite(result["output_latency_s"]) and result["output_latency_s"] >= 0.0
    assert tpad["latency_ms"]["n"] > 0 and 0 < tpad["latency_ms"]["p50"] <= tpad["latency_ms"]["p99"]
    assert tpad["renderer_stats"]["callbacks"] >= tpad["callbacks"]
