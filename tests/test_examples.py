"""The example programs in examples/ run (on the simulated plate, so anywhere)."""

from __future__ import annotations

import re
import subprocess
import sys

from conftest import REPO_ROOT


def run_example(name: str, stdin: str = "") -> str:
    done = subprocess.run([sys.executable, str(REPO_ROOT / "examples" / name), "sim://"], input=stdin,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout


def unrounded(out: str) -> list[str]:
    """The ``name: value`` lines whose number has more than 4 significant digits (0.26318359375 ms)."""
    found = []
    for line in out.splitlines():
        value = line.partition(": ")[2]
        if re.fullmatch(r"-?\d+\.\d+(e[-+]\d+)?", value) and value != f"{float(value):.4g}":
            found.append(line)
    return found


def test_minimal_app_prints_stats() -> None:
    out = run_example("minimal_app.py")
    assert "callbacks:" in out and "latency_ms_p50:" in out
    assert not unrounded(out), out


def test_swap_textures_cycles_on_enter() -> None:
    out = run_example("swap_textures.py", "\n\nq\n")
    assert "rendering square_grating.yaml" in out and "rendering bumps_grid.yaml" in out
    assert "latency_ms_p50:" in out and not unrounded(out), out
