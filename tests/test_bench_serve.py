"""The serve latency benchmark (bench/latency/serve_run.py) still runs: on a real JACK dummy server, one
renderer takes samples in process and from a WebSocket client in another process, and every sample the
client sent is tied to the block that read it (the worker refuses a phase where the counts disagree); and a
client's pings are timed idle, under large inline textures and under bad OSC bundles, each load shown to
have run (the server counted its refusals). Figures are the benchmark's to report, not the test's to judge
(docs/testing.md "Three tiers"), how many samples and pings a run timed included: a loaded machine times fewer."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

from conftest import require_program

RUN = Path(__file__).resolve().parents[1] / "bench" / "latency" / "serve_run.py"


def test_the_serve_latency_bench_measures_both_ways_of_pushing(tmp_path: Path) -> None:
    require_program("jackd")
    done = subprocess.run([sys.executable, str(RUN), "--rounds", "1", "--seconds", "0.5", "--ping-rounds", "1",
                           "--ping-seconds", "1", "--out", str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    report = json.loads((tmp_path / "latency_serve.json").read_text())
    for phase in ("in-process", "websocket"):
        row = report["summary"][phase]
        assert row["n"] > 0 and math.isfinite(row["p50_ms"]) and 0 < row["p50_ms"] <= row["p99_ms"]
    assert report["result"]["server"]["samples"] >= report["summary"]["websocket"]["n"]  # all pushed, most timed
    pings = report["summary"]["ping"]
    for phase in ("idle", "texture", "osc-20", "osc-flood"):
        row = pings[phase]
        assert row["n"] > 0 and 0 < row["p50_ms"] <= row["p99_ms"] <= row["max_ms"] and row["ratio_to_idle"]["p50"] > 0
    assert sum(server.get("error_texture", 0) for server in pings["texture"]["server"]) >= 1
    assert all(server.get("error_bad_message", 0) > 0 for server in pings["osc-20"]["server"])
    assert sum(server.get("osc_dropped", 0) for server in pings["osc-flood"]["server"]) > 0
    table = (tmp_path / "latency_serve.md").read_text()
    assert "over a WebSocket on loopback" in table and "WebSocket p50 - in-process p50" in table
    assert "p50 / idle" in table and "bad OSC bundles, 20 a second" in table
