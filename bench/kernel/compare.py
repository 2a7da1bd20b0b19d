"""The kernel column of two revisions, in alternating runs: ns per sample of each and the paired ratios B / A.

    python bench/kernel/compare.py REV_A REV_B [--blocks 64 1024] [--rounds 8] [--kinds grating ...]

Each revision is checked out in a git worktree of its own (in a temporary folder, removed
at the end). Each round starts one worker process per revision, with its worktree as cwd
and PYTHONPATH and a NUMBA_CACHE_DIR of its own, so each imports its own ``tpad_rt`` and
compiles its own kernel (the ``@cfunc`` driver of that revision's
bench/kernel/realtime_driver.py). The workers measure with that revision's
bench/kernel/run.py (``Case.kernel``, the same textures and finger path), one at a time:
for each texture and block, ``--pairs`` alternations A B / B A per round. A figure is the
median over ``--runs`` fresh streams of ``--seconds`` of audio (default: run.py's full
plan), in ns per output sample at 192 kHz: by default the CPU time of the thread that runs
the ``@cfunc`` (``time.thread_time``: the time slices a shared machine gives other
processes are not counted), with ``--clock wall`` the revision's own ``run.ns_per_sample``
(wall clock); a ratio is B's figure over A's in the same pair (adjacent in time, so the
machine's other work hits both).

Reported per texture and block: median (p10-p90) ns/sample of each revision over all
rounds, and median (p10-p90) of the paired ratios B / A; and whether the two revisions'
DAC samples (the driver's output for ``run.FULL.agreement_s`` of audio, default
RenderOptions) are bit-identical. Writes bench/results/kernel_compare.json and .md
(``--out``). Only ratios mean anything: the machine is shared.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import IO, Any

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))  # results_folder: the --out checks every bench script shares
import results_folder  # noqa: E402
Message = dict[str, Any]


# --- worker: runs in a revision's worktree -------------------------------------------------------


def thread_ns_per_sample(prepare: Any, runs: int) -> float:
    """Median over ``runs`` runs (each prepared untimed by ``prepare``, returning the samples it rendered) of the
    calling thread's CPU time per sample (ns): the @cfunc renders on this thread, and time slices the shared
    machine gives to other processes are not counted."""
    results = []
    for _ in range(runs):
        go = prepare()
        start = time.thread_time()
        samples = go()
        results.append((time.thread_time() - start) * 1e9 / samples)
    return statistics.median(results)


def worker_main() -> int:
    """Serve requests (JSON lines on stdin, answers on the original stdout) with the cwd's bench/kernel/run.py."""
    channel = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)  # anything else printed (numba, C code) goes to stderr, not into the answers
    tree = Path.cwd().resolve()
    sys.path[0] = str(tree / "bench" / "kernel")  # not this script's folder: the worktree's run.py
    start = time.perf_counter()
    import run  # compiles the worktree's @cfunc driver (realtime_driver.RENDER_STREAM)
    import realtime_driver

    import tpad_rt
    from tpad_rt.device import Device
    from tpad_rt.pipeline import RenderOptions

    compile_s = time.perf_counter() - start
    files = {"tpad_rt": tpad_rt.__file__, "run": run.__file__, "realtime_driver": realtime_driver.__file__}
    for name, file in files.items():
        if not Path(str(file)).resolve().is_relative_to(tree):
            raise RuntimeError(f"{name} imported from {file}, not from {tree}")
    cases: dict[str, Any] = {}
    warm: set[tuple[str, int]] = set()

    def case(kind: str) -> Any:
        if kind not in cases:
            cases[kind] = run.Case(Device.default(), run.ROOT / "textures" / run.TEXTURES[kind], RenderOptions())
        return cases[kind]

    def answer(message: Message) -> None:
        channel.write(json.dumps(message) + "\n")
        channel.flush()

    answer({"ready": True, "files": files, "compile_s": compile_s, "textures": run.TEXTURES, "fs_hz": run.FS_HZ,
            "kernel_s": run.FULL.kernel_s, "agreement_s": run.FULL.agreement_s, "machine": run.machine()})
    for line in sys.stdin:
        request: Message = json.loads(line)
        kind, block = request["kind"], int(request["block"])
        if request["op"] == "time":
            seconds = float(request["seconds"])
            if (kind, block) not in warm:  # first stream of this case in this process: untimed
                case(kind).kernel(block, seconds)()
                warm.add((kind, block))
            prepare = lambda: case(kind).kernel(block, seconds)  # noqa: E731
            runs = int(request["runs"])
            figure = run.ns_per_sample(prepare, runs)["median"] if request["clock"] == "wall" else \
                thread_ns_per_sample(prepare, runs)
            answer({"ns_per_sample": figure})
        elif request["op"] == "dump":
            seconds = float(request["seconds"])
            total = round(seconds * run.FS_HZ / block) * block
            out = np.zeros(total, dtype=np.float32)
            case(kind).kernel(block, seconds, out)()
            np.save(request["path"], out)
            answer({"samples": total})
    return 0


# --- parent: worktrees, workers, alternation, report ---------------------------------------------


def git(*args: str) -> str:
    """Output of ``git -C ROOT args`` (stripped)."""
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=True).stdout.strip()


class Worker:
    """One worker process (see :func:`worker_main`) in ``tree``, with its own numba cache folder ``cache``."""

    def __init__(self, tree: Path, cache: Path):
        env = {**os.environ, "PYTHONPATH": str(tree), "NUMBA_CACHE_DIR": str(cache)}
        self.process = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--worker"], cwd=tree,
                                        env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.info: Message = {}

    def _pipes(self) -> tuple[IO[str], IO[str]]:
        assert self.process.stdin is not None and self.process.stdout is not None
        return self.process.stdin, self.process.stdout

    def _read(self) -> Message:
        line = self._pipes()[1].readline()
        if not line:
            raise RuntimeError(f"worker exited (code {self.process.wait()})")
        message: Message = json.loads(line)
        return message

    def ready(self) -> Message:
        """Wait until the worker has compiled its kernel; its description (files imported, compile time in s)."""
        self.info = self._read()
        return self.info

    def request(self, **fields: object) -> Message:
        """Send one request, return the answer."""
        stdin = self._pipes()[0]
        stdin.write(json.dumps(fields) + "\n")
        stdin.flush()
        return self._read()

    def close(self) -> None:
        """End the worker (closes its stdin, waits)."""
        if self.process.stdin is not None:
            self.process.stdin.close()
        self.process.wait(timeout=60)


def band(values: list[float]) -> dict[str, float]:
    """Median, p10, p90, min and max of ``values`` (their unit), and their count."""
    return {"median": statistics.median(values), "p10": float(np.percentile(values, 10)),
            "p90": float(np.percentile(values, 90)), "min": min(values), "max": max(values), "n": len(values)}


def measure(trees: dict[str, Path], folder: Path, kinds: list[str] | None, blocks: list[int], rounds: int,
            pairs: int, runs: int, seconds: float | None, log: Any, clock: str = "cpu") -> Message:
    """Every figure of the comparison (module docstring); ``trees``: worktree of revision "a" and "b"."""
    times: dict[tuple[str, int], dict[str, list[float]]] = {}
    infos: dict[str, list[Message]] = {"a": [], "b": []}
    identity: dict[tuple[str, int], Message] = {}
    plan: Message = {}
    for round_index in range(rounds):
        workers: dict[str, Worker] = {}
        try:
            for name, tree in trees.items():
                workers[name] = Worker(tree, folder / f"numba-{name}")
            for name, worker in workers.items():
                infos[name].append(worker.ready())
            first = infos["a"][0]
            if round_index == 0:
                chosen = kinds or list(first["textures"])
                plan = {"kinds": chosen, "blocks": blocks, "rounds": rounds, "pairs": pairs, "runs": runs, "clock": clock,
                        "seconds": seconds or first["kernel_s"], "dump_seconds": first["agreement_s"]}
                for kind in chosen:
                    for block in blocks:
                        paths = {name: folder / f"{name}-{kind}-{block}.npy" for name in workers}
                        for name, worker in workers.items():
                            worker.request(op="dump", kind=kind, block=block, path=str(paths[name]),
                                           seconds=plan["dump_seconds"])
                        a, b = np.load(paths["a"]), np.load(paths["b"])
                        same_shape = a.shape == b.shape
                        identity[kind, block] = {
                            "identical": bool(np.array_equal(a, b)), "samples": int(a.size),
                            "max_abs_difference": float(np.abs(a.astype(np.float64) - b).max()) if same_shape else None}
            log(f"round {round_index + 1}/{rounds}: kernels compiled in "
                + ", ".join(f"{name} {infos[name][-1]['compile_s']:.0f} s" for name in workers))
            for case_index, (kind, block) in enumerate((k, b) for k in plan["kinds"] for b in blocks):
                series = times.setdefault((kind, block), {"a": [], "b": []})
                for pair in range(pairs):
                    order = ("a", "b") if (round_index + case_index + pair) % 2 == 0 else ("b", "a")
                    for name in order:
                        answer = workers[name].request(op="time", kind=kind, block=block, runs=runs,
                                                       seconds=plan["seconds"], clock=clock)
                        series[name].append(answer["ns_per_sample"])
        finally:
            for worker in workers.values():
                worker.close()
    rows = []
    for (kind, block), series in times.items():
        ratios = [b / a for a, b in zip(series["a"], series["b"])]
        rows.append({"kind": kind, "texture": infos["a"][0]["textures"][kind], "block": block,
                     "a_ns_per_sample": band(series["a"]), "b_ns_per_sample": band(series["b"]),
                     "b_over_a": band(ratios), **identity[kind, block],
                     "a_values": series["a"], "b_values": series["b"]})
        log(f"{kind:9s} block {block:5d}: A {rows[-1]['a_ns_per_sample']['median']:6.2f}, "
            f"B {rows[-1]['b_ns_per_sample']['median']:6.2f} ns/sample, B/A {rows[-1]['b_over_a']['median']:.3f} "
            f"({rows[-1]['b_over_a']['p10']:.3f}-{rows[-1]['b_over_a']['p90']:.3f}), "
            f"samples {'identical' if rows[-1]['identical'] else 'DIFFER'}")
    all_ratios = [b / a for row in rows for a, b in zip(row["a_values"], row["b_values"])]
    return {"plan": plan, "fs_hz": infos["a"][0]["fs_hz"], "machine": infos["a"][0]["machine"],
            "files": {name: infos[name][0]["files"] for name in infos},
            "compile_s": {name: [info["compile_s"] for info in infos[name]] for name in infos},
            "rows": rows, "all_b_over_a": band(all_ratios)}


def markdown(report: Message) -> str:
    """The report as a Markdown table."""
    def fmt(figure: dict[str, float], digits: int) -> str:
        return f"{figure['median']:.{digits}f} ({figure['p10']:.{digits}f}-{figure['p90']:.{digits}f})"

    a, b, plan = report["revisions"]["a"], report["revisions"]["b"], report["plan"]
    lines = [
        "# Kernel column: two revisions in alternating runs",
        "",
        f"Generated by `{report['command']}`; A = {a['name']} ({a['commit'][:10]}), B = {b['name']} "
        f"({b['commit'][:10]}); {report['machine']['cpu']}, {report['machine']['cores']} cores, "
        f"numba {report['machine']['numba']}; load average at start {report['load_average'][0]:.2f}.",
        f"ns per output sample of `render_block` from the `@cfunc` driver (bench/kernel/realtime_driver.py) at "
        f"{report['fs_hz']} Hz, default RenderOptions: median (p10-p90) over {plan['rounds']} rounds x "
        f"{plan['pairs']} pairs, each figure the median of {plan['runs']} fresh streams of {plan['seconds']:g} s "
        f"({'CPU time of the rendering thread' if plan.get('clock', 'wall') == 'cpu' else 'wall-clock time'}); "
        "each round a fresh process per revision (its own worktree, tpad_rt and compiled kernel), the two run one "
        "at a time, alternating A B / B A. B / A: median (p10-p90) of the ratios within each pair. identical: "
        f"the two revisions' DAC samples ({plan['dump_seconds']:g} s) equal bit for bit.",
        "",
        "| kind | block | A ns/sample | B ns/sample | B / A | identical |",
        "| --- | ---: | ---: | ---: | ---: | --- |",
    ]
    for row in report["rows"]:
        lines.append(f"| {row['kind']} | {row['block']} | {fmt(row['a_ns_per_sample'], 2)} "
                     f"| {fmt(row['b_ns_per_sample'], 2)} | {fmt(row['b_over_a'], 3)} "
                     f"| {'yes' if row['identical'] else 'NO'} |")
    lines += ["", f"All pairs: B / A {fmt(report['all_b_over_a'], 3)} over {report['all_b_over_a']['n']} pairs."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("rev_a", help="revision A (the baseline)")
    parser.add_argument("rev_b", help="revision B (ratios are B / A)")
    parser.add_argument("--blocks", type=int, nargs="+", default=[64, 1024], help="block sizes (samples)")
    parser.add_argument("--kinds", nargs="+", help="texture kinds of run.TEXTURES (default: all)")
    parser.add_argument("--rounds", type=int, default=8, help="rounds (a fresh process per revision each)")
    parser.add_argument("--pairs", type=int, default=3, help="A/B pairs per texture and block per round")
    parser.add_argument("--runs", type=int, default=3, help="fresh streams per figure (its median)")
    parser.add_argument("--seconds", type=float, help="seconds of audio per stream (default: run.py's full plan)")
    parser.add_argument("--clock", choices=("cpu", "wall"), default="cpu",
                        help="time each stream by the worker thread's CPU time (default) or by the wall clock")
    parser.add_argument("--out", type=results_folder.folder, default=ROOT / "bench" / "results", help="folder for kernel_compare.*")
    args = parser.parse_args(argv)
    revisions = {name: {"name": rev, "commit": git("rev-parse", "--verify", f"{rev}^{{commit}}")}
                 for name, rev in (("a", args.rev_a), ("b", args.rev_b))}
    load = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="tpad-rt-compare-") as temp:
        folder = Path(temp)
        trees = {name: folder / f"tree-{name}" for name in revisions}
        try:
            for name, tree in trees.items():
                git("worktree", "add", "--detach", str(tree), revisions[name]["commit"])
            report = measure(trees, folder, args.kinds, args.blocks, args.rounds, args.pairs, args.runs,
                             args.seconds, lambda line: print(line, flush=True), args.clock)
        finally:
            for tree in trees.values():
                if tree.exists():
                    git("worktree", "remove", "--force", str(tree))
            git("worktree", "prune")
    command = "python bench/kernel/compare.py " + shlex.join(sys.argv[1:] if argv is None else argv)
    report = {"command": command, "revisions": revisions, "load_average": load,
              "load_average_at_end": os.getloadavg(), **report}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "kernel_compare.json").write_text(json.dumps(report, indent=1) + "\n")
    (args.out / "kernel_compare.md").write_text(markdown(report))
    print(markdown(report))
    print(f"wrote {args.out / 'kernel_compare.json'} and {args.out / 'kernel_compare.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(worker_main() if sys.argv[1:] == ["--worker"] else main())
