"""The example programs in examples/ run (on the simulated plate, so anywhere)."""

from __future__ import annotations

import subprocess
import sys

from conftest import REPO_ROOT


def run_example(name: str, stdin: str = "") -> str:
    done = subprocess.run([sys.executable, str(REPO_ROOT / "examples" / name), "sim://"], input=stdin,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_minimal_app_prints_stats() -> None:
    out = run_example("minimal_app.py")
    assert "callbacks:" in out and "latency_ms_p50:" in out


def test_swap_textures_cycles_on_enter() -> None:
    out = run_example("swap_textures.py", "\n\nq\n")
    assert "rendering square_grating.yaml" in out and "rendering bumps_grid.yaml" in out
