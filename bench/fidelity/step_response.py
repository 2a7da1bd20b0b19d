"""Step response of the simulated plate: how fast a friction step reaches the finger, against the floor the limits set.

    python bench/fidelity/step_response.py [--baseline REV] [--levels 0.3 0.5 0.75 0.9] [--out bench/results]

A temporal square texture switches between no vibration (friction 1.0) and a level that
needs a fraction ``k`` of the device's max volts at the finger's speed and force (100
mm/s, 0.5 N, blocks of 16 samples at 192 kHz, default RenderOptions). The drive goes
through ``sim://`` (the resonator of tpad_rt/kernel/sim.py, its mean envelope per block),
and each step is measured on the plate amplitude:

- rise and fall, 10-90 % of the amplitude step (ms);
- settling: from the step until the friction stays within 0.01 of its final value (ms).

The floor for a first-order envelope (time constant ``tau``, drive clamped at
``+-Vmax``): rise ``tau ln((1 - 0.1k) / (1 - 0.9k))``, braking fall
``tau ln((1 + 0.9k) / (1 + 0.1k))``; the issue's bound is ``max(1 ms, 1.25 x floor)``.

``--baseline REV`` measures a git revision too, in the same run: its tree is checked out
in a temporary worktree and this script runs there as a worker (its own ``tpad_rt``,
its own numba cache), with only API both revisions share. Simulated time, so the figures
do not depend on the machine's load. Writes step_response.json and step_response.md.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))  # results_folder: the --out checks every bench script shares
import results_folder  # noqa: E402
FS_HZ = 192000
BLOCK = 16
SPEED_MM_S = 100.0
FORCE_N = 0.5
HALF_PERIOD_S = 0.05  # the square texture: 50 ms without vibration, then 50 ms at the level
SETTLE_MU = 0.01


def floors_ms(tau_s: float, k: float) -> tuple[float, float]:
    """The fastest 10-90 % rise and braking fall (ms) of a first-order envelope to a level at ``k`` x Vmax."""
    return (tau_s * 1e3 * math.log((1 - 0.1 * k) / (1 - 0.9 * k)),
            tau_s * 1e3 * math.log((1 + 0.9 * k) / (1 + 0.1 * k)))


def _crossing_s(t_s: np.ndarray, values: np.ndarray, level: float, rising: bool) -> float:
    """The first time ``values`` reaches ``level`` (from below if ``rising``), linearly interpolated."""
    beyond = values >= level if rising else values <= level
    i = int(np.argmax(beyond))
    if not beyond[i]:
        return math.nan
    if i == 0:
        return float(t_s[0])
    fraction = (level - values[i - 1]) / (values[i] - values[i - 1])
    return float(t_s[i - 1] + fraction * (t_s[i] - t_s[i - 1]))


def transition_ms(t_s: np.ndarray, amplitude: np.ndarray, start: float, end: float) -> float:
    """10-90 % time (ms) of ``amplitude`` going from ``start`` to ``end``."""
    rising = end > start
    return 1e3 * (_crossing_s(t_s, amplitude, start + 0.9 * (end - start), rising)
                  - _crossing_s(t_s, amplitude, start + 0.1 * (end - start), rising))


def settling_ms(t_s: np.ndarray, mu: np.ndarray, final_mu: float) -> float:
    """Time (ms, from t = 0) after which ``mu`` stays within SETTLE_MU of ``final_mu``."""
    outside = np.flatnonzero(np.abs(mu - final_mu) > SETTLE_MU)
    return 0.0 if outside.size == 0 else 1e3 * float(t_s[min(outside[-1] + 1, len(t_s) - 1)])


def measure(k: float, folder: Path) -> dict[str, Any]:
    """Rise, fall and settling on ``sim://`` for a step to ``k`` x max volts (the running tpad_rt's code)."""
    from tpad_rt.device import Device
    from tpad_rt.outputs.sim import SimOutput
    from tpad_rt.physics.friction import relative_friction
    from tpad_rt.pipeline import Pipeline, RenderOptions
    from tpad_rt.texture import load_compiled

    device = Device.default()
    volts = k * device.max_voltage_v
    amplitude_m = volts * float(device.amplitude_m_per_v(FORCE_N))
    # Revisions before device format 2 (one circuit, one gamma) called the carrier resonance_hz.
    carrier_hz = getattr(device, "carrier_hz", None) or getattr(device, "resonance_hz")
    low_mu = float(relative_friction(amplitude_m, carrier_hz, SPEED_MM_S * 1e-3, device.mu0,
                                     device.poisson, device.psi_star))
    texture_file = folder / f"steps_{k}.yaml"
    texture_file.write_text(
        "description: friction steps\nkind: temporal\nwaveform: square\n"
        f"frequency_hz: {1 / (2 * HALF_PERIOD_S)}\nduty: 0.5\nfriction: {{low: {low_mu!r}, high: 1.0}}\n")
    pipeline = Pipeline(device, load_compiled(texture_file), fs_hz=FS_HZ, options=RenderOptions(default_force_n=FORCE_N))
    sim = SimOutput(device, FS_HZ)
    pipeline.start()
    block = np.zeros(BLOCK, dtype=np.float32)
    times, peaks = [], []
    for _ in range(int(3 * HALF_PERIOD_S * FS_HZ / BLOCK)):  # off, on (rise), off (fall)
        t_s = pipeline.time_s
        pipeline.push_finger(t_s, 10 + SPEED_MM_S * t_s, 30.0, force_n=FORCE_N)
        pipeline.render(block)
        row = {name: float(values[-1]) for name, values in pipeline.drain_telemetry().items()}
        sim.write(block, row)
        times.append(t_s + BLOCK / FS_HZ / 2)  # the block's mean envelope, at its middle
        peaks.append(row["voltage_v"])
    t_s = np.array(times)
    measured = sim.measurements()
    amplitude_um, mu = measured["plate_amplitude_um"], measured["achieved_mu"]
    on = (t_s >= HALF_PERIOD_S) & (t_s < 2 * HALF_PERIOD_S)
    off = t_s >= 2 * HALF_PERIOD_S
    level_um = float(amplitude_um[on][-20:].mean())  # settled: the last 1.7 ms of the half
    rise_ms = transition_ms(t_s[on] - HALF_PERIOD_S, amplitude_um[on], 0.0, level_um)
    fall_ms = transition_ms(t_s[off] - 2 * HALF_PERIOD_S, amplitude_um[off], level_um, 0.0)
    tau_s = float(device.envelope_time_constant_s(FORCE_N))
    floor_rise_ms, floor_fall_ms = floors_ms(tau_s, k)
    return {
        "k": k, "level_v": volts, "level_um": level_um, "low_mu": low_mu, "tau_ms": tau_s * 1e3,
        "rise_ms": rise_ms, "fall_ms": fall_ms,
        "rise_settle_ms": settling_ms(t_s[on] - HALF_PERIOD_S, mu[on], float(mu[on][-20:].mean())),
        "fall_settle_ms": settling_ms(t_s[off] - 2 * HALF_PERIOD_S, mu[off], 1.0),
        "floor_rise_ms": floor_rise_ms, "floor_fall_ms": floor_fall_ms,
        "bound_rise_ms": max(1.0, 1.25 * floor_rise_ms), "bound_fall_ms": max(1.0, 1.25 * floor_fall_ms),
        "peak_drive_v": float(max(peaks)),
    }


def _worker(levels: list[float]) -> list[dict[str, Any]]:
    with tempfile.TemporaryDirectory() as folder:
        return [measure(k, Path(folder)) for k in levels]


def _baseline(rev: str, levels: list[float]) -> list[dict[str, Any]]:
    """``_worker(levels)`` run with revision ``rev``'s tpad_rt, in a temporary git worktree."""
    with tempfile.TemporaryDirectory() as folder:
        tree = Path(folder) / "tree"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(tree), rev], check=True)
        try:
            env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_CACHE_DIR=str(Path(folder) / "numba"))
            done = subprocess.run(
                [sys.executable, str(Path(__file__).resolve()), "--worker", *map(str, levels)],
                cwd=tree, env=env, check=True, capture_output=True, text=True)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False)
        return list(json.loads(done.stdout))


def _table(rows: list[dict[str, Any]], baseline: dict[float, dict[str, Any]], rev: str | None) -> str:
    head = "| level (x Vmax) | rise 10-90 % (ms) | floor / bound | fall 10-90 % (ms) | floor / bound | settle to 0.01 in friction, rise / fall (ms) |"
    lines = [head, "| --- | --- | --- | --- | --- | --- |"]
    for row in rows:
        old = baseline.get(row["k"])
        before = (lambda name: f" (was {old[name]:.2f})") if old else (lambda name: "")
        lines.append(
            f"| {row['k']:.2f} ({row['level_v']:.1f} V) | {row['rise_ms']:.2f}{before('rise_ms')} | "
            f"{row['floor_rise_ms']:.2f} / {row['bound_rise_ms']:.2f} | {row['fall_ms']:.2f}{before('fall_ms')} | "
            f"{row['floor_fall_ms']:.2f} / {row['bound_fall_ms']:.2f} | {row['rise_settle_ms']:.2f}{before('rise_settle_ms')} / "
            f"{row['fall_settle_ms']:.2f}{before('fall_settle_ms')} |")
    note = f"'was': revision {rev}, measured in the same run." if rev else ""
    return "\n".join(lines) + ("\n\n" + note if note else "") + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--levels", type=float, nargs="+", default=[0.3, 0.5, 0.75, 0.9])
    parser.add_argument("--baseline", metavar="REV", help="also measure this git revision (a worktree of it)")
    parser.add_argument("--out", type=results_folder.folder, default=ROOT / "bench" / "results")
    parser.add_argument("--worker", type=float, nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        json.dump(_worker(args.worker), sys.stdout)
        return 0
    if not all(0.0 < k < 1.0 for k in args.levels):
        parser.error("--levels: each must be a fraction of max volts in (0, 1)")
    rows = _worker(args.levels)
    baseline = {row["k"]: row for row in _baseline(args.baseline, args.levels)} if args.baseline else {}
    table = _table(rows, baseline, args.baseline)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "step_response.json").write_text(json.dumps(
        {"fs_hz": FS_HZ, "block": BLOCK, "speed_mm_s": SPEED_MM_S, "force_n": FORCE_N, "steps": rows,
         "baseline": {"rev": args.baseline, "steps": list(baseline.values())}}, indent=1) + "\n")
    (args.out / "step_response.md").write_text(
        "# Step response on the simulated plate\n\n`python bench/fidelity/step_response.py"
        + (f" --baseline {args.baseline}" if args.baseline else "") + "`: default device, "
        f"{SPEED_MM_S:g} mm/s, {FORCE_N:g} N, blocks of {BLOCK} at {FS_HZ} Hz (simulated time).\n\n" + table)
    print(table, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
