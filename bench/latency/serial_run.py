"""Serial amplifier benchmark: envelope rate, push-to-amplifier latency and underruns under load, over a pty.

    python bench/latency/serial_run.py              # 5 runs of 4 s per load and writer
    python bench/latency/serial_run.py --quick      # 2 runs of 2 s
    python bench/latency/serial_run.py --buffer-ms 1 --envelope-hz 16000
    python bench/latency/serial_run.py --smoke --out DIR  # one run of 0.3 s, tpad-rt's streamer, idle: figures meaningless

Writes bench/results/latency_serial.json and latency_serial.md and prints the table.
Every run starts the amplifier emulator (``tpad-rt amp emulate``) on a new pty in a
process of its own, then a host in another process: either tpad-rt's Renderer on
``serial://`` (its GIL-free streamer, bench/latency/serial_worker.py) or the control, a
plain-Python writer (tests/python_serial_writer.py), for the same time, idle, under GIL
load (one Python thread spinning in the host's process), under the same CPU load without
the GIL (one spinning process: the baseline of GIL load, since the GIL thread also takes a
core) or under CPU load (one spinning process per core). Figures, each next to its baseline of the same run:

1. envelope rate achieved: samples the host sent per second of its run, against the
   rate START agreed;
2. push-to-amplifier latency (p50, p99): from ``push_finger`` to the time the emulator
   applied the first sample of the first frame rendered after the push, both on
   CLOCK_MONOTONIC (the emulator records each sample's time), next to the part the host
   planned (the target fill) and the host's own estimate;
3. samples the amplifier missed (played with nothing buffered: its underruns, and the
   samples of frames it refused, late or after its watchdog tripped), idle, under GIL
   load and under CPU load, for the streamer and for the Python writer.

Nothing here is a pass/fail test (docs/testing.md).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "bench"))  # results_folder: the --out checks every bench script shares
import results_folder  # noqa: E402
sys.path.insert(0, str(HERE))

from jack import cpu_hogs  # noqa: E402

WORKER = HERE / "serial_worker.py"
WRITER = ROOT / "tests" / "python_serial_writer.py"
#: Load -> what it is. "cpu1" is the GIL thread's CPU load without the GIL: what GIL load costs beyond it is the GIL's.
LOADS = {"idle": "idle", "gil": "one Python thread holding the GIL in the host's process",
         "cpu1": "one spinning process (the GIL thread's CPU load, no GIL)", "cpu": "one spinning process per core"}
WRITERS = {"tpad": "tpad-rt streamer (numba, no GIL)", "python": "plain-Python writer (control)"}


def _emulator(folder: Path) -> tuple[subprocess.Popen[str], str, Path]:
    """Start ``tpad-rt amp emulate`` recording to FOLDER/amp.npz; (process, port, recording path)."""
    record = folder / "amp.npz"
    process = subprocess.Popen([sys.executable, "-m", "tpad_rt", "amp", "emulate", "--record", str(record)],
                               cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert process.stdout is not None
    first = process.stdout.readline()
    if not first.startswith("amplifier emulator on "):
        raise SystemExit(f"the emulator did not start: {first!r} {process.stderr.read() if process.stderr else ''}")
    return process, first.split()[-1], record


def _finish(process: subprocess.Popen[str], record: Path) -> dict[str, np.ndarray]:
    """SIGTERM the emulator, wait, and load its recording."""
    process.send_signal(signal.SIGTERM)
    process.communicate(timeout=120)
    with np.load(record) as recording:
        return {name: recording[name] for name in recording.files}


def run_once(writer: str, load: str, seconds: float, buffer_ms: float, envelope_hz: int) -> dict[str, Any]:
    """One run of ``writer`` under ``load``: its figures."""
    with tempfile.TemporaryDirectory() as folder:
        emulator, port, record = _emulator(Path(folder))
        try:
            with contextlib.ExitStack() as load_on:
                if load in ("cpu", "cpu1"):
                    load_on.enter_context(cpu_hogs(1 if load == "cpu1" else os.cpu_count() or 2))
                gil = "1" if load == "gil" else "0"
                url = f"serial://{port}?buffer_ms={buffer_ms:g}&envelope_hz={envelope_hz}"
                if writer == "tpad":
                    command = [str(WORKER), url, str(seconds), "--gil-threads", gil, "--pushes", f"{folder}/pushes.npz"]
                else:
                    command = [str(WRITER), url, str(seconds), "--gil-threads", gil]
                done = subprocess.run([sys.executable, *command], cwd=ROOT, capture_output=True, text=True,
                                      timeout=seconds + 300)
        finally:
            recording = _finish(emulator, record)
        if done.returncode != 0:
            raise SystemExit(f"{writer} under {load} failed: {done.stderr.strip()}")
        if writer == "python":
            frames, expected, missed = map(int, done.stdout.split()[-3:])
            return {"rate_fraction": frames / expected, "missed": missed}
        result = json.loads(done.stdout.splitlines()[-1])
        result.update(_applied_latency(Path(folder) / "pushes.npz", recording))
        return result


def _applied_latency(pushes_path: Path, recording: dict[str, np.ndarray]) -> dict[str, Any]:
    """Push-to-amplifier latency (ms) of each push: the emulator's time for the first sample of the first frame
    that read it, minus the push time (both CLOCK_MONOTONIC)."""
    with np.load(pushes_path) as pushes:
        push_ns, frame_index = pushes["push_ns"], pushes["first_index"]
    playing = recording["index"] >= 0
    applied_s = dict(zip(recording["index"][playing].tolist(), recording["t_s"][playing].tolist()))
    latency_ms = np.array([(applied_s[index] - ns * 1e-9) * 1e3 for ns, index in zip(push_ns, frame_index)
                           if index in applied_s])
    return {"latency_ms": latency_ms.tolist(), "pushes_applied": len(latency_ms), "pushes": len(push_ns)}


def summarise(runs: dict[str, dict[str, list[dict[str, Any]]]]) -> dict[str, Any]:
    """Medians and spreads over the runs of each writer and load."""
    summary: dict[str, Any] = {}
    for writer, by_load in runs.items():
        for load, results in by_load.items():
            row: dict[str, Any] = {
                "missed": [r["missed"] for r in results],
                "rate_fraction": [r["rate_fraction"] for r in results],
            }
            if writer == "tpad":
                latency = np.concatenate([np.asarray(r["latency_ms"]) for r in results])
                row.update(latency_ms_p50=float(np.percentile(latency, 50)),
                           latency_ms_p99=float(np.percentile(latency, 99)),
                           host_estimate_ms_p50=float(np.median([r["host_latency_ms_p50"] for r in results])),
                           target_fill_ms=results[0]["target_fill_ms"], late=[r["late"] for r in results],
                           frames_bad=[r["frames_bad"] for r in results])
            summary[f"{writer}/{load}"] = row
    return summary


def markdown(report: dict[str, Any]) -> str:
    """The results as Markdown tables."""
    s, p = report["summary"], report["parameters"]
    lines = [f"Serial amplifier over a pty, emulator in its own process; envelope {p['envelope_hz']} Hz, "
             f"target fill {p['buffer_ms']:g} ms; {p['runs']} runs of {p['seconds']:g} s per row "
             f"(machine: {report['machine']['cpus']} CPUs, {report['machine']['python']}).", "",
             "Loads: " + "; ".join(f"{name}: {LOADS[name]}" for name in p["loads"]) + ".", "",
             "| writer | load | envelope rate achieved (min of runs) | samples the amplifier missed, per run | in all |",
             "|---|---|---|---|---:|"]
    for writer in p["writers"]:
        for load in p["loads"]:
            row = s[f"{writer}/{load}"]
            lines.append(f"| {WRITERS[writer]} | {load} | {min(row['rate_fraction']) * 100:.1f} % | "
                         f"{', '.join(str(u) for u in row['missed'])} | {sum(row['missed'])} |")
    lines += ["", "| load | push-to-amplifier p50 | p99 | host's estimate p50 | target fill |", "|---|---|---|---|---|"]
    for load in p["loads"]:
        row = s[f"tpad/{load}"]
        lines.append(f"| {load} | {row['latency_ms_p50']:.2f} ms | {row['latency_ms_p99']:.2f} ms | "
                     f"{row['host_estimate_ms_p50']:.2f} ms | {row['target_fill_ms']:.2f} ms |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 runs of 2 s per row")
    parser.add_argument("--smoke", action="store_true",
                        help="the test suite's check that the bench runs: one run of 0.3 s of tpad-rt's streamer, "
                             "idle only (figures meaningless)")
    parser.add_argument("--seconds", type=float, default=4.0, help="seconds per run (default 4)")
    parser.add_argument("--runs", type=int, default=5, help="runs per row (default 5)")
    parser.add_argument("--buffer-ms", type=float, default=1.0, help="the host's target fill (default 1 ms)")
    parser.add_argument("--envelope-hz", type=int, default=16000, help="envelope rate (default 16000 Hz)")
    parser.add_argument("--out", type=results_folder.folder, default=ROOT / "bench" / "results", help="folder for the results")
    args = parser.parse_args(argv)
    results_folder.refuse_smoke_into_results(parser, args.smoke, args.out)
    seconds, rounds = (0.3, 1) if args.smoke else (2.0, 2) if args.quick else (args.seconds, args.runs)
    loads = ["idle"] if args.smoke else list(LOADS)
    writers = ["tpad"] if args.smoke else list(WRITERS)
    runs: dict[str, dict[str, list[dict[str, Any]]]] = {w: {load: [] for load in loads} for w in writers}
    for round_number in range(rounds):
        for load in loads:
            for writer in (writers if round_number % 2 == 0 else reversed(writers)):
                result = run_once(writer, load, seconds, args.buffer_ms, args.envelope_hz)
                runs[writer][load].append(result)
                print(f"round {round_number + 1}/{rounds} {writer:6s} {load:4s}: missed {result['missed']}, "
                      f"rate {result['rate_fraction'] * 100:.1f} %", flush=True)
    report = {
        "parameters": {"seconds": seconds, "runs": rounds, "buffer_ms": args.buffer_ms,
                       "envelope_hz": args.envelope_hz, "loads": loads, "writers": writers},
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
        "summary": summarise(runs),
        "runs": {w: {load: [{k: v for k, v in r.items() if k != "latency_ms"} for r in rs] for load, rs in by.items()}
                 for w, by in runs.items()},
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "latency_serial.json").write_text(json.dumps(report, indent=1) + "\n")
    text = markdown(report)
    (args.out / "latency_serial.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
