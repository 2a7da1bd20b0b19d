"""Real-time latency benchmark: callback compute time, underflows under load, push-to-output
latency and start-up time, on a JACK dummy server at 192 kHz.

    python bench/latency/run.py                 # full run: 30 s per load and callback, in 6 runs
    python bench/latency/run.py --quick         # 6 s in 3 runs, fewer start-ups
    python bench/latency/run.py --seconds 60    # longer load runs
    python bench/latency/run.py --smoke --out DIR  # every part once, idle, in short windows, the parts sharing
                                                   # their servers: figures meaningless

Writes bench/results/latency.json and latency.md and prints the tables. Every measured
configuration runs in a fresh process (bench/latency/worker.py) against a dummy JACK
server this script starts and stops by PID (bench/latency/jack.py), in JACK's
synchronous mode (``jackd -S``) but for one comparison; every figure is a distribution
or a count next to a baseline measured in the same run:

1. compute time per block (p50/p99/max, us) of the tpad-rt ``render_callback``
   (a Renderer rendering the grating under a moving finger) next to the empty
   ``silence_callback``, at blocks 16, 32, 64 and 256 (one server per period size),
   from the callbacks' own per-block records;
2. at 64 frames, callbacks delivered (against the stream clock) and underflows, idle,
   under GIL load (Python threads spinning in this process) and under CPU load (one
   spinning process per core), for the empty ``@cfunc``, the tpad-rt ``@cfunc`` and a
   sounddevice Python callback running ``Pipeline.render``: in rounds of one run of
   each callback (rotated order), each callback compared with the baseline run of its
   round by a one-sided sign test;
3. push-to-output latency of the tpad-rt callback: from ``push_finger`` to the DAC time
   of the first block that read the sample (its entry time plus the host's
   ``outputBufferDacTime - currentTime``), split into the wait for that callback
   (tpad-rt's part) and the DAC delay (the server's); also on a server in JACK's
   default asynchronous mode, which buffers one period more;
4. start-up: from spawning a process that imports tpad_rt, builds a Renderer on
   ``audio://`` and starts it, to its first sample at the DAC (warm numba cache), next
   to ``python -c "import tpad_rt"``.

bench/latency/README.md says what each figure means. Nothing here is a pass/fail test
(docs/testing.md); the Markdown says which of issue 4's targets were met.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "bench"))  # results_folder: the --out checks every bench script shares
import results_folder  # noqa: E402
sys.path.insert(0, str(HERE))

from jack import cpu_hogs, jack_server, playback_latency_frames, wait_for_no_clients  # noqa: E402

from tpad_rt.kernel_cache import plan_complete  # noqa: E402

RATE_HZ = 192000
COMPUTE_BLOCKS = (16, 32, 64, 256)
LOAD_BLOCK = 64
WORKER = HERE / "worker.py"
CALLBACKS = {"silence": "empty @cfunc (baseline)", "tpad": "tpad-rt @cfunc", "python": "sounddevice Python callback"}
LOADS = ("idle", "gil", "cpu")
#: Issue 4's latency target at 64 frames: one block plus one period (s).
TARGET_S = 2 * LOAD_BLOCK / RATE_HZ


@dataclass(frozen=True)
class Plan:
    """Seconds per compute-time run, at each of ``compute_blocks``; seconds per load (of ``loads``) and callback,
    split into ``load_runs`` runs; start-up runs, warm and with an empty numba cache; whether the parts share
    their JACK servers (:class:`Servers`)."""

    compute_s: float
    load_s: float
    startups: int
    load_runs: int = 6
    cold_startups: int = 3
    compute_blocks: tuple[int, ...] = COMPUTE_BLOCKS
    loads: tuple[str, ...] = LOADS
    shared_servers: bool = False

    @property
    def run_s(self) -> float:
        """Seconds of one load run."""
        return self.load_s / self.load_runs


#: The test suite's smoke run (tests/test_bench_smoke.py): every part once, at 64 frames, idle, in short windows,
#: on one synchronous and one asynchronous server.
SMOKE = Plan(compute_s=0.2, load_s=0.2, startups=1, load_runs=1, cold_startups=0, compute_blocks=(LOAD_BLOCK,),
             loads=("idle",), shared_servers=True)


class Servers(contextlib.ExitStack):
    """The dummy JACK servers the parts run on: a fresh one for each part, or (``shared``) one per period size
    and mode, started when a part first asks for it and stopped when this context exits (the smoke run's: a
    server takes a second to start). Each server's output goes to ``logs``/jackd-NAME.log."""

    def __init__(self, logs: Path, shared: bool) -> None:
        super().__init__()
        self._logs, self._shared = logs, shared
        self._running: dict[tuple[int, bool], dict[str, str]] = {}

    @contextlib.contextmanager
    def server(self, block: int, name: str, *, sync: bool = True) -> Iterator[dict[str, str]]:
        """The environment of a running server of ``block``-frame periods, synchronous unless ``sync`` is
        False; ``name`` names its log."""
        if not self._shared:
            with jack_server(RATE_HZ, block, self._logs / f"jackd-{name}.log", sync=sync) as env:
                yield env
            return
        if (block, sync) not in self._running:
            self._running[block, sync] = self.enter_context(
                jack_server(RATE_HZ, block, self._logs / f"jackd-{name}.log", sync=sync))
        yield self._running[block, sync]


def _worker(args: list[str], env: dict[str, str], timeout_s: float) -> dict[str, Any]:
    """Run worker.py with ``args``; its RESULT as a dict (``{"error": ...}`` if it failed)."""
    try:
        done = subprocess.run([sys.executable, str(WORKER), *args], env=env, capture_output=True, text=True,
                              timeout=timeout_s, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout_s:.0f} s"}
    for line in reversed(done.stdout.splitlines()):
        if line.startswith("RESULT "):
            return json.loads(line[len("RESULT "):])
    return {"error": f"exit {done.returncode}: {done.stderr.strip()[-500:]}"}


#: Seconds a worker may take to fill an empty numba cache (the kernels compile: minutes on a loaded machine).
WARM_TIMEOUT_S = 900


def warm_up(env: dict[str, str], modes: list[str]) -> str | None:
    """Run the worker once in each of ``modes``, unmeasured, to fill the numba cache if it is cold (a
    measured worker's timeout leaves no room for the compile); the first error, or None. Runs nothing when the
    whole compile plan is in the cache already (``tpad-rt warm`` ran for these sources: tests/run runs it)."""
    if plan_complete():
        return None
    for mode in modes:
        result = _worker([mode], env, WARM_TIMEOUT_S)
        if "error" in result:
            return f"{mode}: {result['error']}"
    return None


def measure_compute(plan: Plan, log: Callable[[str], None], servers: Servers) -> list[dict[str, Any]]:
    """Part 1: compute time per block, empty vs tpad-rt callback, one server per block size (the numba cache
    filled first)."""
    rows = []
    for block in plan.compute_blocks:
        with servers.server(block, str(block)) as env:
            if not rows and (error := warm_up(env, ["startup"])) is not None:
                log(f"warm-up: {error}")
            for callback in ("silence", "tpad"):
                result = _worker(["stream", callback, "--block", str(block), "--seconds", str(plan.compute_s)],
                                 env, plan.compute_s + 120)
                rows.append({"block": block, "callback": callback, "load_average_1min": os.getloadavg()[0],
                             **result})
                log(f"block {block:3d} {callback:7s}: {_compute_text(result)}")
    return rows


def measure_loads(plan: Plan, gil_threads: int, log: Callable[[str], None], servers: Servers,
                  report: dict[str, Any]) -> list[dict[str, Any]]:
    """Part 2 (and 3): the three callbacks idle, under GIL load, under CPU load, at 64 frames.

    Per load, ``plan.load_runs`` rounds; each round runs every callback once for
    ``plan.run_s`` seconds, in an order rotated from round to round, so that each
    tpad-rt run has a baseline run next to it in time (the machine's other work drifts).
    """
    rows = []
    with servers.server(LOAD_BLOCK, "load") as env:
        report["server_playback_latency_frames"] = playback_latency_frames(env["JACK_DEFAULT_SERVER"])
        names = list(CALLBACKS)
        for load in plan.loads:
            for run in range(plan.load_runs):
                for callback in names[run % len(names):] + names[:run % len(names)]:
                    load_average = os.getloadavg()[0]
                    args = ["stream", callback, "--block", str(LOAD_BLOCK), "--seconds", str(plan.run_s),
                            "--gil-threads", str(gil_threads if load == "gil" else 0)]
                    if load == "cpu":
                        with cpu_hogs(os.cpu_count() or 1):
                            time.sleep(0.5)
                            result = _worker(args, env, plan.run_s + 120)
                    else:
                        result = _worker(args, env, plan.run_s + 120)
                    result["client_gone_after"] = wait_for_no_clients(env)
                    rows.append({"load": load, "callback": callback, "run": run, "load_average_1min": load_average,
                                 **result})
                    log(f"{load:4s} run {run} {callback:7s}: {result.get('callbacks')} of "
                        f"{result.get('expected', float('nan')):.0f} callbacks, {result.get('underflows')} underflows "
                        f"{result.get('error', '')}")
    return rows


def measure_async_latency(plan: Plan, log: Callable[[str], None], servers: Servers) -> dict[str, Any]:
    """Part 3's comparison: the tpad-rt callback idle at 64 frames on a server in JACK's default
    asynchronous mode (every other part runs ``jackd -S``)."""
    with servers.server(LOAD_BLOCK, "async", sync=False) as env:
        frames = playback_latency_frames(env["JACK_DEFAULT_SERVER"])
        result = _worker(["stream", "tpad", "--block", str(LOAD_BLOCK), "--seconds", str(plan.compute_s)], env,
                         plan.compute_s + 120)
    log(f"async server: {_compute_text(result)}")
    return {"server_playback_latency_frames": frames, "load_average_1min": os.getloadavg()[0], **result}


#: The least any process running a cached numba function pays: import numba, then the first call of a
#: trivial ``cache=True`` function (numba loads its lowering registries then, scipy.linalg among them);
#: it prints CLOCK_MONOTONIC (ns) once the call returned.
NUMBA_FLOOR_MODULE = """import time

import numba


@numba.njit(cache=True)
def one_more(x):
    return x + 1.0


one_more(1.0)
print(time.monotonic_ns())
"""


def _numba_floor_s(env: dict[str, str]) -> float:
    """Seconds from spawning a process to its first call of a cached numba function returning."""
    spawned_ns = time.monotonic_ns()
    done = subprocess.run([sys.executable, "-c", "import numba_floor"], env=env, check=True, capture_output=True,
                          text=True, stdin=subprocess.DEVNULL, timeout=120)
    return (int(done.stdout.split()[-1]) - spawned_ns) * 1e-9


def _run_s(command: list[str], env: dict[str, str]) -> float:
    begin = time.monotonic()
    subprocess.run(command, env=env, check=True, capture_output=True, stdin=subprocess.DEVNULL, timeout=120)
    return time.monotonic() - begin


def measure_startup(plan: Plan, log: Callable[[str], None], logs: Path, servers: Servers) -> dict[str, Any]:
    """Part 4: spawn -> first sample at the DAC, through ``tpad-rt play`` and through the Renderer API, next to
    ``import tpad_rt`` and ``import tpad_rt.engine``, alternated."""
    modes = ["startup", "play"]
    runs: dict[str, list[dict[str, float]]] = {mode: [] for mode in modes}
    baseline, engine_import, numba_floor = [], [], []
    (logs / "numba_floor.py").write_text(NUMBA_FLOOR_MODULE)
    with servers.server(LOAD_BLOCK, "startup") as env:
        env = {key: value for key, value in env.items() if key != "DISPLAY"}  # play: scripted input, no mouse
        floor_env = {**env, "PYTHONPATH": str(logs)}
        _run_s([sys.executable, "-c", "import numba_floor"], floor_env)  # compiles its cache; not counted
        if (error := warm_up(env, modes)) is not None:
            return {"error": error}
        for _ in range(plan.startups):
            baseline.append(_run_s([sys.executable, "-c", "import tpad_rt"], env))
            engine_import.append(_run_s([sys.executable, "-c", "import tpad_rt.engine"], env))
            numba_floor.append(_numba_floor_s(floor_env))
            for mode in modes:
                spawned_ns = time.monotonic_ns()
                result = _worker([mode], env, 120)
                if "error" in result:
                    return {"error": f"{mode}: {result['error']}"}
                runs[mode].append({key: (value - spawned_ns) * 1e-9 for key, value in result.items()})
            log("start-up: first sample at " + ", ".join(f"{mode} {runs[mode][-1]['first_dac_ns']:.3f} s"
                                                         for mode in modes)
                + f"; import tpad_rt {baseline[-1]:.3f} s")
        cold: dict[str, list[dict[str, float]]] = {mode: [] for mode in modes}
        for _ in range(plan.cold_startups):  # an empty numba cache each time: the first run on a machine
            for mode in modes:
                with tempfile.TemporaryDirectory(prefix="tpadrt-cold-numba-") as cache:
                    spawned_ns = time.monotonic_ns()
                    result = _worker([mode], {**env, "NUMBA_CACHE_DIR": cache}, 600)
                if "error" in result:
                    return {"error": f"cold {mode}: {result['error']}"}
                cold[mode].append({key: (value - spawned_ns) * 1e-9 for key, value in result.items()})
            log("cold start-up: first sample at " + ", ".join(f"{mode} {cold[mode][-1]['first_dac_ns']:.2f} s"
                                                              for mode in modes))
    return {"runs": runs["startup"], "play_runs": runs["play"], "import_tpad_rt_s": baseline,
            "import_tpad_rt_engine_s": engine_import, "numba_floor_s": numba_floor,
            "cold_runs": cold["startup"], "cold_play_runs": cold["play"]}


def _band(values: list[float], scale: float = 1.0, digits: int = 3) -> str:
    values = np.asarray(values) * scale
    return (f"{np.median(values):.{digits}f} ({np.percentile(values, 10):.{digits}f}-"
            f"{np.percentile(values, 90):.{digits}f})")


def _compute_text(result: dict[str, Any]) -> str:
    if "error" in result:
        return f"error: {result['error']}"
    c = result["compute_us"]
    return f"compute p50 {c['p50']:.2f} us, p99 {c['p99']:.2f}, max {c['max']:.1f} ({c['n']} blocks)"


def _load_runs(report: dict[str, Any], load: str, callback: str) -> list[dict[str, Any]]:
    """Part 2's runs of ``callback`` under ``load`` that gave figures, in run order."""
    return sorted((row for row in report["loads"] if row["load"] == load and row["callback"] == callback
                   and "error" not in row), key=lambda row: row.get("run", 0))


def _sign_test(runs: list[dict[str, Any]], baseline: list[dict[str, Any]]) -> dict[str, Any]:
    """Runs with more / fewer / as many underflows as the baseline run of the same round, and the one-sided
    sign-test p-value of "more" (scipy's exact binomial test over the rounds that differ)."""
    from scipy.stats import binomtest

    base = {row.get("run", 0): row["underflows"] for row in baseline}
    pairs = [(row["underflows"], base[row.get("run", 0)]) for row in runs if row.get("run", 0) in base]
    more = sum(mine > theirs for mine, theirs in pairs)
    fewer = sum(mine < theirs for mine, theirs in pairs)
    p_value = binomtest(more, more + fewer, 0.5, alternative="greater").pvalue if more + fewer else 1.0
    return {"pairs": len(pairs), "more": more, "fewer": fewer, "equal": len(pairs) - more - fewer,
            "p_more": float(p_value),
            "median_difference": float(np.median([mine - theirs for mine, theirs in pairs])) if pairs else None}


def summarise(report: dict[str, Any]) -> dict[str, Any]:
    """Per load and callback: totals over the runs, per-run underflows, the paired comparison with the
    baseline; and the verdicts on issue 4's targets."""
    groups = []
    for load in LOADS:
        baseline = _load_runs(report, load, "silence")
        for callback in CALLBACKS:
            runs = _load_runs(report, load, callback)
            if not runs:
                continue
            callbacks = sum(row["callbacks"] for row in runs)
            expected = sum(row["expected"] for row in runs)
            due_wall = sum(row.get("due_wall", math.nan) for row in runs)
            group = {"load": load, "callback": callback, "runs": len(runs), "callbacks": callbacks,
                     "expected": expected, "delivered_fraction": callbacks / expected, "due_wall": due_wall,
                     "delivered_wall_fraction": callbacks / due_wall,
                     "underflows": sum(row["underflows"] for row in runs),
                     "underflows_per_run": [row["underflows"] for row in runs],
                     "compute_p50_us": float(np.median([row["compute_us"]["p50"] for row in runs])),
                     "compute_p99_us": float(np.median([row["compute_us"]["p99"] for row in runs])),
                     "compute_max_us": max(row["compute_us"]["max"] for row in runs)}
            if callback != "silence" and baseline:
                group["vs_baseline"] = _sign_test(runs, baseline)
            latency = [row["latency_ms"] for row in runs if row.get("latency_ms", {}).get("n")]
            if latency:
                group["latency_p50_ms"] = float(np.median([value["p50"] for value in latency]))
                group["latency_p99_ms"] = float(np.median([value["p99"] for value in latency]))
                group["latency_max_ms"] = max(value["max"] for value in latency)
                group["latency_n"] = sum(value["n"] for value in latency)
                group["wait_p50_ms"] = float(np.median([row["wait_ms"]["p50"] for row in runs]))
                group["wait_p99_ms"] = float(np.median([row["wait_ms"]["p99"] for row in runs]))
                group["dac_delay_ms"] = float(np.median([row["read_dac_delay_ms"]["p50"] for row in runs]))
                group["output_latency_ms"] = float(np.median([row["output_latency_s"] for row in runs])) * 1e3
            groups.append(group)
    by = {(group["load"], group["callback"]): group for group in groups}
    gil_tpad, gil_python = by.get(("gil", "tpad"), {}), by.get(("gil", "python"), {})
    idle_tpad = by.get(("idle", "tpad"), {})
    gil_test = gil_tpad.get("vs_baseline", {})
    python_test = gil_python.get("vs_baseline", {})
    verdict = {
        "significance": SIGNIFICANCE,
        "gil_tpad_vs_baseline": gil_test,
        "gil_tpad_within_margin": bool(gil_test and gil_test["p_more"] >= SIGNIFICANCE),
        "gil_python_vs_baseline": python_test,
        "gil_python_delivered_fraction": gil_python.get("delivered_wall_fraction"),
        "gil_python_collapsed": bool(gil_python and (gil_python["delivered_wall_fraction"] < 0.5
                                                     or python_test.get("p_more", 1.0) < SIGNIFICANCE)),
        "latency_target_ms": TARGET_S * 1e3,
        "latency_p50_ms": idle_tpad.get("latency_p50_ms"),
        "latency_target_met": bool(idle_tpad.get("latency_p50_ms") is not None
                                   and idle_tpad["latency_p50_ms"] <= TARGET_S * 1e3),
        "tpad_part_p50_ms": idle_tpad.get("wait_p50_ms"),
        "server_dac_delay_ms": idle_tpad.get("dac_delay_ms"),
        "async_latency_p50_ms": report.get("async", {}).get("latency_ms", {}).get("p50"),
    }
    return {"groups": groups, "verdict": verdict}


#: The one-sided sign test's level: tpad-rt is "within the baseline's margin" under a load unless its
#: runs had more underflows than their paired baseline runs at p < SIGNIFICANCE.
SIGNIFICANCE = 0.05


def markdown(report: dict[str, Any]) -> str:
    """The report as Markdown tables."""
    plan, machine, verdict = report["plan"], report["machine"], report["summary"]["verdict"]
    smoke = report.get("smoke", False)
    short = report["quick"] or smoke
    lines = [
        "# Real-time latency",
        "",
        f"Generated by `python bench/latency/run.py{' --smoke' if smoke else ' --quick' if report['quick'] else ''}"
        f"{'' if short else ' --seconds ' + format(plan['load_s'], 'g')}`"
        f"{' (a SMOKE run: it checks the bench runs; its figures mean nothing)' if smoke else ''}"
        f"{' (a QUICK run: short windows, rough figures)' if report['quick'] and not smoke else ''}; "
        f"JACK dummy server at {RATE_HZ} Hz in synchronous mode (`jackd -S -p 16 -d dummy -r {RATE_HZ} -p BLOCK`; "
        "part 3 also measures JACK's default asynchronous mode), "
        f"jackd SCHED_FIFO as root: {machine['root']}); {machine['cpu']}, {machine['cores']} cores, "
        f"Python {machine['python']}, numba {machine['numba']}. Every configuration ran in a fresh process; "
        "bench/latency/README.md says how each figure is measured. "
        "1-minute load average before each row (other work on the machine; CPU-load rows include their own hogs): "
        f"{_load_range(report)}.",
        "",
        f"## 1. Compute time per callback ({format(plan['compute_s'], 'g')} s per row, idle, finger moving)",
        "",
        "From the callback's own per-block records (CLOCK_MONOTONIC at entry and exit). "
        "Baseline: the empty `@cfunc` (writes zeros, same bookkeeping) on the same server.",
        "",
        "| block | period us | callback | blocks | p50 us | p99 us | max us | p99 / period | underflows |",
        "| ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for row in report["compute"]:
        period_us = row["block"] / RATE_HZ * 1e6
        if "error" in row:
            lines.append(f"| {row['block']} | {period_us:.0f} | {CALLBACKS[row['callback']]} | error: {row['error']} "
                         "| | | | | |")
            continue
        c = row["compute_us"]
        lines.append(f"| {row['block']} | {period_us:.0f} | {CALLBACKS[row['callback']]} | {c['n']} | {c['p50']:.2f} "
                     f"| {c['p99']:.2f} | {c['max']:.1f} | {c['p99'] / period_us:.1%} | {row['underflows']} |")
    groups = {(group["load"], group["callback"]): group for group in report["summary"]["groups"]}
    lines += [
        "",
        f"## 2. Underflows at {LOAD_BLOCK} frames: {format(plan['load_s'], 'g')} s per load and callback, "
        f"in {plan['load_runs']} runs of {format(plan['load_s'] / plan['load_runs'], 'g')} s",
        "",
        f"GIL load: {report['gil_threads']} Python thread(s) spinning a pure-Python loop in the measured process; "
        f"CPU load: {machine['cores']} processes `python -c 'while True: pass'` (one per core). "
        "Each load runs in rounds; a round runs the three callbacks once each, in a rotated order, so every run "
        "has a baseline run (the empty `@cfunc`) next to it in time: the machine's other work drifts, and the "
        "dummy driver's xruns come in bursts. Due: the callbacks CLOCK_MONOTONIC says were due in the window; "
        "expected: the same from the stream's own clock (`Pa_GetStreamTime`), which a server in synchronous "
        "mode slows down while it waits for a late client (and for a while after it). "
        "*Runs above / below the baseline*: rounds in which the callback had more / fewer "
        "underflows than the baseline run of the same round; *p*: one-sided sign test of \"more\" over the rounds "
        "that differ. Compute time: medians over the runs of each run's p50 and p99, and the largest max.",
        "",
        "| load | callback | delivered / due (wall clock) | delivered / expected (stream clock) | underflows "
        "| per run | runs above / below / equal baseline | p (more than baseline) | compute p50 / p99 / max us |",
        "| --- | --- | ---: | ---: | ---: | --- | ---: | ---: | ---: |",
    ]
    loads = plan.get("loads", LOADS)  # a latency.json from before the plan named them: all three
    for load in loads:
        for callback in CALLBACKS:
            group = groups.get((load, callback))
            if group is None:
                lines.append(f"| {load} | {CALLBACKS[callback]} | error | | | | | | |")
                continue
            test = group.get("vs_baseline")
            lines.append(
                f"| {load} | {CALLBACKS[callback]} | {group['callbacks']} / {group['due_wall']:.0f} "
                f"({group['delivered_wall_fraction']:.1%}) | {group['callbacks']} / {group['expected']:.0f} "
                f"({group['delivered_fraction']:.1%}) | {group['underflows']} "
                f"| {', '.join(str(n) for n in group['underflows_per_run'])} "
                f"| {_pairs_text(test)} | {'-' if test is None else format(test['p_more'], '.3f')} "
                f"| {group['compute_p50_us']:.1f} / {group['compute_p99_us']:.1f} / {group['compute_max_us']:.0f} |")
    lines += [
        "",
        "## 3. Push-to-output latency (tpad-rt `@cfunc`, finger sample pushed every 2 ms)",
        "",
        "From `push_finger` (CLOCK_MONOTONIC just before the call) to the DAC time of the first block whose start "
        "saw the sample (its entry time + `outputBufferDacTime - currentTime` from PortAudio's time info). "
        "wait = push to that callback's entry (tpad-rt's part: at most one period plus scheduling); "
        "DAC delay = what the host API reports between entry and the block's first sample at the DAC: the "
        "playback latency the server declares for its output port. "
        f"Target (issue 4): median <= one block + one period = {TARGET_S * 1e3:.3f} ms at 64 frames "
        "(2 x block / rate at other block sizes). Part 2's rows: medians over the runs of each run's figures.",
        "",
        "| run | jackd mode | block | samples | latency p50 ms | p99 ms | max ms | wait p50 / p99 ms | DAC delay ms "
        "| stream outputLatency ms | target ms | median met |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |",
    ]
    latency_rows = [(f"idle (part 1, {format(plan['compute_s'], 'g')} s)", "sync (-S)", _latency_cells(row))
                    for row in report["compute"] if row["callback"] == "tpad"]
    latency_rows += [(f"{load} (part 2)", "sync (-S)", _group_latency_cells(groups.get((load, "tpad"), {})))
                     for load in loads]
    if "async" in report:
        latency_rows.append((f"idle ({format(plan['compute_s'], 'g')} s)", "async (default)",
                             _latency_cells({**report["async"], "block": LOAD_BLOCK})))
    for name, mode, cells in latency_rows:
        lines.append(f"| {name} | {mode} | {cells} |")
    startup = report["startup"]
    lines += ["", f"## 4. Start-up to the first sample ({len(startup.get('runs', []))} runs each with a warm numba "
              "cache, and with an empty one)",
              ""]
    if "error" in startup:
        lines.append(f"error: {startup['error']}")
    else:
        runs, play_runs = startup["runs"], startup.get("play_runs", [])

        def cell(rows: list[dict[str, float]], key: str) -> str:
            return _band([r[key] for r in rows]) if rows and key in rows[0] else "-"

        lines += [
            "Times from spawning the process (CLOCK_MONOTONIC, shared by both processes): median (p10-p90) in "
            "seconds. *tpad-rt play*: `tpad-rt play textures/grating.yaml --output audio://?rate=192000&block=64 "
            "--duration 0.3` run through `tpad_rt.cli.main` (the console script's function) in the spawned "
            "process, its first sample read from the Renderer's block records. *Renderer API*: the process "
            "imports `tpad_rt.engine`, builds a `Renderer` on the same URL with the same texture, calls `start()` "
            "(warm-up call of the callback, stream open, start). Both wait for the first callback; the first "
            "sample at the DAC is that block's entry time plus its DAC delay.",
            "",
            "| step | tpad-rt play | Renderer API |",
            "| --- | ---: | ---: |",
            f"| interpreter up (worker's first line) | {cell(play_runs, 'process_begin_ns')} "
            f"| {cell(runs, 'process_begin_ns')} |",
            f"| imports done (`tpad_rt.cli` / `tpad_rt.engine`) | {cell(play_runs, 'imported_ns')} "
            f"| {cell(runs, 'imported_ns')} |",
            f"| `Renderer(...)` built (texture compiled) | - | {cell(runs, 'built_ns')} |",
            f"| first callback entered | {cell(play_runs, 'first_entry_ns')} | {cell(runs, 'first_entry_ns')} |",
            f"| `start()` returned | {cell(play_runs, 'started_ns')} | {cell(runs, 'started_ns')} |",
            f"| **first sample at the DAC** | **{cell(play_runs, 'first_dac_ns')}** "
            f"| **{cell(runs, 'first_dac_ns')}** |",
            f"| compile notice printed, empty numba cache | {cell(startup.get('cold_play_runs', []), 'notice_ns')} "
            "| - |",
            f"| **first sample at the DAC, empty numba cache** ({len(startup.get('cold_runs', []))} runs: the "
            f"first run on a machine compiles the kernels) | **{cell(startup.get('cold_play_runs', []), 'first_dac_ns')}** "
            f"| **{cell(startup.get('cold_runs', []), 'first_dac_ns')}** |",
            f"| baseline: `python -c \"import tpad_rt\"` (spawn to exit) | {_band(startup['import_tpad_rt_s'])} | |",
            f"| second baseline: `python -c \"import tpad_rt.engine\"` (spawn to exit: the engine's imports, "
            f"no numba; the interpreter's exit) | {_band(startup['import_tpad_rt_engine_s'])} | |",
            *([f"| numba's floor: `import numba`, then one call of a trivial cached `njit` function (spawn to "
               f"that call's return; every process running cached numba code pays it) "
               f"| {_band(startup['numba_floor_s'])} | |"]
              if startup.get("numba_floor_s") else []),
            "",
            "First sample minus the `import tpad_rt` baseline (medians): "
            + (f"play {np.median([r['first_dac_ns'] for r in play_runs]) - np.median(startup['import_tpad_rt_s']):.3f}"
               " s, " if play_runs else "")
            + f"API {np.median([r['first_dac_ns'] for r in runs]) - np.median(startup['import_tpad_rt_s']):.3f} s. "
            "From imports done to the first sample at the DAC: "
            + (f"play {_band([r['first_dac_ns'] - r['imported_ns'] for r in play_runs])} s, " if play_runs else "")
            + f"API {_band([r['first_dac_ns'] - r['imported_ns'] for r in runs])} s. `import tpad_rt` is lazy; "
            "with the ahead-of-time audio callbacks built (`tpad-rt warm` with a C compiler) neither start imports "
            "numba before its first sample (docs/kernel.md \"Ahead-of-time kernels\"); without them both pay "
            "numba's floor above.",
        ]
    v = verdict
    lines += [
        "",
        "## Issue 4's targets (this run)",
        "",
        f"- Underflows of the tpad-rt `@cfunc` under GIL load within the empty-callback baseline's margin "
        f"(not more than the baseline run of the same round in a way a one-sided sign test finds at "
        f"p < {v['significance']}): {_pairs_text(v['gil_tpad_vs_baseline'] or None)} rounds above / below / equal, "
        f"p = {_fmt(v['gil_tpad_vs_baseline'].get('p_more'))}: "
        f"**{'met' if v['gil_tpad_within_margin'] else 'NOT met'}**. The plain Python callback collapses "
        f"(under half the callbacks delivered, or more underflows than the baseline at p < {v['significance']}): "
        f"{_percent(v['gil_python_delivered_fraction'])} delivered, "
        f"{_pairs_text(v['gil_python_vs_baseline'] or None)} rounds above / below / equal: "
        f"**{'yes' if v['gil_python_collapsed'] else 'NO'}**.",
        f"- Median push-to-output latency at 64 frames (idle, `jackd -S`) {_fmt(v['latency_p50_ms'])} ms against "
        f"{v['latency_target_ms']:.3f} ms: **{'met' if v['latency_target_met'] else 'NOT met'}**. Of it, the wait "
        f"for the callback that reads the sample (tpad-rt's part) is {_fmt(v['tpad_part_p50_ms'])} ms and the DAC "
        f"delay PortAudio reports (`outputBufferDacTime - currentTime`) is {_fmt(v['server_dac_delay_ms'])} ms "
        f"= {_periods(v['server_dac_delay_ms'])} periods (`jack_lsp -l`: "
        f"{report.get('server_playback_latency_frames')} frames of playback latency on the server's output port). "
        "On a server in JACK's default asynchronous mode (no `-S`), which declares and buffers one more period "
        f"(`jack_lsp -l`: {report.get('async', {}).get('server_playback_latency_frames')} frames), the median is "
        f"{_fmt(v['async_latency_p50_ms'])} ms: run jackd with `-S` where latency matters (docs/realtime.md).",
    ]
    return "\n".join(lines) + "\n"


def _pairs_text(test: dict[str, Any] | None) -> str:
    return "-" if test is None else f"{test['more']} / {test['fewer']} / {test['equal']}"


def _latency_cells(row: dict[str, Any]) -> str:
    """Part 3's cells (block .. median met) for one run's figures."""
    latency = row.get("latency_ms", {})
    if "error" in row or not latency.get("n"):
        return f"{row.get('block', '')} | error: {row.get('error', 'no samples')} | | | | | | | |"
    target_ms = 2 * row["block"] / RATE_HZ * 1e3
    return (f"{row['block']} | {latency['n']} | {latency['p50']:.3f} | {latency['p99']:.3f} | {latency['max']:.3f} "
            f"| {row['wait_ms']['p50']:.3f} / {row['wait_ms']['p99']:.3f} | {row['read_dac_delay_ms']['p50']:.3f} "
            f"| {row['output_latency_s'] * 1e3:.3f} | {target_ms:.3f} "
            f"| {'yes' if latency['p50'] <= target_ms else 'no'}")


def _group_latency_cells(group: dict[str, Any]) -> str:
    """Part 3's cells for part 2's runs of one load (medians over the runs)."""
    if "latency_p50_ms" not in group:
        return f"{LOAD_BLOCK} | error: no samples | | | | | | | |"
    return (f"{LOAD_BLOCK} | {group['latency_n']} | {group['latency_p50_ms']:.3f} | {group['latency_p99_ms']:.3f} "
            f"| {group['latency_max_ms']:.3f} | {group['wait_p50_ms']:.3f} / {group['wait_p99_ms']:.3f} "
            f"| {group['dac_delay_ms']:.3f} | {group['output_latency_ms']:.3f} | {TARGET_S * 1e3:.3f} "
            f"| {'yes' if group['latency_p50_ms'] <= TARGET_S * 1e3 else 'no'}")


def _load_range(report: dict[str, Any]) -> str:
    values = [row["load_average_1min"] for row in report["compute"] + report["loads"] if "load_average_1min" in row]
    return f"{min(values):.2f}-{max(values):.2f}" if values else "not recorded"


def _periods(value_ms: float | None) -> str:
    return "n/a" if value_ms is None else f"{value_ms * 1e-3 * RATE_HZ / LOAD_BLOCK:.2f}"


def _percent(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.1%}"


def _fmt(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f}"


def machine() -> dict[str, Any]:
    """Where the figures were measured."""
    import numba
    cpuinfo = Path("/proc/cpuinfo")
    names = [line.split(":", 1)[1].strip() for line in cpuinfo.read_text().splitlines()
             if line.startswith("model name")] if cpuinfo.exists() else []
    jackd = subprocess.run(["jackd", "--version"], capture_output=True, text=True)
    return {"cpu": names[0] if names else platform.processor(), "cores": os.cpu_count(),
            "python": platform.python_version(), "numba": numba.__version__, "numpy": np.__version__,
            "platform": platform.platform(), "root": os.geteuid() == 0,
            "jackd": (jackd.stdout.strip().splitlines() or ["?"])[0],
            "load_average_at_start": os.getloadavg()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true",
                        help="6 s per load and callback in 3 runs, 3 s compute runs, 5 start-ups")
    parser.add_argument("--smoke", action="store_true",
                        help="the test suite's check that the bench runs: every part once at 64 frames, part 2 idle "
                             "only, 0.2 s windows, no start-up with an empty cache, one server for the synchronous parts "
                             "(figures meaningless)")
    parser.add_argument("--seconds", type=float, default=None,
                        help="seconds per load and callback, split into 6 runs (default 30; --quick 6, 3 runs)")
    parser.add_argument("--gil-threads", type=int, default=1, help="Python threads spinning for GIL load (default 1)")
    parser.add_argument("--out", type=results_folder.folder, default=ROOT / "bench" / "results", help="folder for latency.json/.md")
    parser.add_argument("--startup-only", action="store_true",
                        help="measure part 4 (start-up) only; keep the other parts of latency.json as they are")
    parser.add_argument("--rewrite-md", action="store_true",
                        help="measure nothing: rewrite latency.md (and the summary in latency.json) from latency.json")
    args = parser.parse_args(argv)
    results_folder.refuse_smoke_into_results(parser, args.smoke, args.out)
    if (args.startup_only or args.rewrite_md) and not (args.out / "latency.json").is_file():
        parser.error(f"--startup-only and --rewrite-md update {args.out / 'latency.json'}, which does not exist: "
                     "run without them first (or copy a latency.json there)")
    if args.rewrite_md:
        report = json.loads((args.out / "latency.json").read_text())
        report["summary"] = summarise(report)
        (args.out / "latency.json").write_text(json.dumps(report, indent=1) + "\n")
        (args.out / "latency.md").write_text(markdown(report))
        print(markdown(report))
        return 0
    plan = SMOKE if args.smoke else Plan(compute_s=3.0, load_s=6.0, startups=5, load_runs=3, cold_startups=1) \
        if args.quick else Plan(compute_s=10.0, load_s=30.0, startups=15, load_runs=6)
    if args.seconds is not None:
        plan = replace(plan, load_s=args.seconds)
    if args.startup_only:
        report = json.loads((args.out / "latency.json").read_text())
        with tempfile.TemporaryDirectory(prefix="tpadrt-latency-") as logs, \
                Servers(Path(logs), plan.shared_servers) as servers:
            report["startup"] = measure_startup(plan, lambda line: print(line, flush=True), Path(logs), servers)
        report["plan"]["startups"], report["plan"]["cold_startups"] = plan.startups, plan.cold_startups
        report["summary"] = summarise(report)
        (args.out / "latency.json").write_text(json.dumps(report, indent=1) + "\n")
        (args.out / "latency.md").write_text(markdown(report))
        print(markdown(report))
        return 0
    log = lambda line: print(line, flush=True)  # noqa: E731
    report: dict[str, Any] = {"quick": args.quick, "smoke": args.smoke, "rate_hz": RATE_HZ, "plan": asdict(plan),
                              "gil_threads": args.gil_threads, "machine": machine()}
    with tempfile.TemporaryDirectory(prefix="tpadrt-latency-") as logs:
        with Servers(Path(logs), plan.shared_servers) as servers:
            report["compute"] = measure_compute(plan, log, servers)
            report["loads"] = measure_loads(plan, args.gil_threads, log, servers, report)
            report["async"] = measure_async_latency(plan, log, servers)
            report["startup"] = measure_startup(plan, log, Path(logs), servers)
        report["jackd_xrun_lines"] = {path.name: sum("xrun" in line.lower() for line in path.read_text().splitlines())
                                      for path in sorted(Path(logs).glob("jackd-*.log"))}
    report["summary"] = summarise(report)
    text = markdown(report)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "latency.json").write_text(json.dumps(report, indent=1) + "\n")
    (args.out / "latency.md").write_text(text)
    print()
    print(text)
    print(f"wrote {args.out / 'latency.json'} and {args.out / 'latency.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
