"""Resident memory of a real-time ``tpad-rt play`` over a long run: ``sim://`` next to ``null://``.

    python bench/memory/play_rss.py                  # 60 s each (the issue's figure)
    python bench/memory/play_rss.py --seconds 20     # shorter
    python bench/memory/play_rss.py --repo /path/to/another/checkout --label before
    python bench/memory/play_rss.py --seconds 3 --out DIR    # the test suite's smoke run (figures meaningless)

Runs ``python -m tpad_rt play textures/grating.yaml --output URL --duration S`` (no display:
the endless back-and-forth swipe; no JACK) with the tree of ``--repo`` on PYTHONPATH, reads
the child's VmRSS from /proc every 0.1 s, and reports its RSS one second after play
started (the ``output ...`` line, printed just before the renderer starts) and at the end,
the growth in between (MB, and MB/s), and the peak. ``null://`` is the baseline measured
in the same run, at the same time (both plays run at once, a thread reading each): the same
renderer, input and telemetry with no plate simulated. The issue's target: ``sim://`` grows
by at most 5 MB after its first second over 60 s.

Writes bench/results/memory_play.json and memory_play.md (with ``--label``: memory_play_LABEL.*; ``--out``: elsewhere)
and prints the table. Not a test (docs/testing.md "Benchmarks are not tests").
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))  # results_folder: the --out checks every bench script shares
import results_folder  # noqa: E402
RESULTS = ROOT / "bench" / "results"
#: The shortest run measured: RSS is read from one second in until one second before the end.
MIN_SECONDS = 3.0
#: Seconds between two reads of the child's VmRSS.
SAMPLE_PERIOD_S = 0.1


def _rss_mb(pid: int) -> float | None:
    """VmRSS of ``pid`` (MB), None once it is gone."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except (FileNotFoundError, ProcessLookupError):
        return None
    return None


def measure(repo: Path, output: str, seconds: float) -> dict[str, Any]:
    """One play on ``output`` for ``seconds`` from ``repo``'s tree: RSS one second in, at the end, the peak."""
    env = {key: value for key, value in os.environ.items() if key != "DISPLAY"}
    env.update(PYTHONPATH=str(repo), JACK_NO_START_SERVER="1", JACK_DEFAULT_SERVER="tpadrt-absent")
    child = subprocess.Popen([sys.executable, "-m", "tpad_rt", "play", "textures/grating.yaml", "--output", output,
                              "--duration", f"{seconds:g}"], cwd=repo, env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    assert child.stdout is not None
    first_line = child.stdout.readline()  # printed just before the renderer starts
    started = time.monotonic()
    samples: list[tuple[float, float]] = []
    while child.poll() is None:
        rss = _rss_mb(child.pid)
        if rss is not None:
            samples.append((time.monotonic() - started, rss))
        time.sleep(SAMPLE_PERIOD_S)
    rest, errors = child.communicate()
    if child.returncode != 0:
        raise RuntimeError(f"play {output} failed ({child.returncode}): {errors}")
    during = [(t_s, rss) for t_s, rss in samples if 1.0 <= t_s <= seconds - 1.0]  # not the stop and summary
    one_s = during[0][1]
    ten_s = next((rss for t_s, rss in during if t_s >= min(10.0, seconds - 1.0)), during[-1][1])
    end = during[-1][1]
    after_first = [rss for _, rss in during]
    summary = (first_line + rest).splitlines()
    return {"output": output, "seconds": seconds, "rss_at_1s_mb": one_s, "rss_at_end_mb": end,
            "rss_at_10s_mb": ten_s, "growth_after_10s_mb": end - ten_s,
            "growth_mb": end - one_s, "peak_growth_mb": max(after_first) - one_s,
            "growth_mb_per_s": (end - one_s) / max(during[-1][0] - 1.0, 1e-9),
            "peak_mb": max(rss for _, rss in samples), "samples": len(samples),
            "played": next((line for line in summary if line.startswith("played ")), "")}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0,
                        help=f"play duration (s, default 60, at least {MIN_SECONDS:g})")
    parser.add_argument("--repo", type=Path, default=ROOT, help="the checkout to run (default: this one)")
    parser.add_argument("--label", default="", help="suffix of the result files")
    parser.add_argument("--out", type=results_folder.folder, default=RESULTS, help="folder for the results (default bench/results)")
    args = parser.parse_args(argv)
    if not args.seconds >= MIN_SECONDS:
        parser.error(f"--seconds: at least {MIN_SECONDS:g} (RSS is read from 1 s in to 1 s before the end)")
    with ThreadPoolExecutor(max_workers=2) as pool:
        rows = list(pool.map(lambda output: measure(args.repo.resolve(), output, args.seconds), ("sim://", "null://")))
    result = {"repo": str(args.repo.resolve()), "python": platform.python_version(), "machine": platform.machine(),
              "cpus": os.cpu_count(), "load_average": os.getloadavg(), "rows": rows}
    stem = "memory_play" + (f"_{args.label}" if args.label else "")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{stem}.json").write_text(json.dumps(result, indent=2) + "\n")
    lines = [f"# tpad-rt play: resident memory over {args.seconds:g} s (`python bench/memory/play_rss.py`)", "",
             f"Checkout `{result['repo']}`; {result['cpus']} CPUs, load average "
             + " / ".join(f"{value:.1f}" for value in result["load_average"]) + " at the end.", "",
             "| output | RSS at 1 s (MB) | at 10 s | at the end - 1 s | growth after 1 s (MB) | growth after 10 s (MB) "
             "| growth after 1 s (MB/s) | highest after 1 s, over RSS at 1 s (MB) | peak of the process (MB) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    lines += [f"| `{row['output']}` | {row['rss_at_1s_mb']:.1f} | {row['rss_at_10s_mb']:.1f} | {row['rss_at_end_mb']:.1f} "
              f"| {row['growth_mb']:+.2f} | {row['growth_after_10s_mb']:+.2f} | {row['growth_mb_per_s']:+.4f} "
              f"| {row['peak_growth_mb']:+.2f} | {row['peak_mb']:.1f} |" for row in rows]
    lines += ["", "`null://` is the same run's baseline (no plate simulated). What each run printed:", ""]
    lines += [f"- `{row['output']}`: {row['played']}" for row in rows]
    (args.out / f"{stem}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
