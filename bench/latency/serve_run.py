"""tpad-rt serve's push-to-output latency through a WebSocket on loopback, next to the in-process push_finger;
and a WebSocket client's ping round trip while another client or sender loads the server, next to an idle one.

    python bench/latency/serve_run.py               # 6 rounds of 3 s per phase, 3 ping rounds of 4 x 3 s (about 2 min)
    python bench/latency/serve_run.py --quick       # 2 rounds of 1 s, 1 ping round of 4 x 2 s
    python bench/latency/serve_run.py --rounds 10 --seconds 5 --ping-rounds 5 --ping-seconds 5 --out DIR

Writes bench/results/latency_serve.json and latency_serve.md and prints the table.
Starts a JACK dummy server (192 kHz, 64-frame periods, synchronous mode: jack.py) and
one measuring process (serve_worker.py) holding a Renderer on it and ``tpad-rt serve``'s
server in front of it; in each round the same renderer takes a finger sample every 2 ms
for S seconds from the process's own thread (``push_finger``, the baseline) and for S
seconds from a WebSocket client in another process, in alternating order. Latency: from
just before the push (or the send) to the DAC time of the first block that read the
sample (bench/latency/README.md, part 3). The table gives both distributions, pooled
over the rounds, and the difference of their medians round by round. Nothing here is a
pass/fail test (docs/testing.md).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
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

from jack import jack_server  # noqa: E402

WORKER = HERE / "serve_worker.py"
RATE_HZ = 192000
PHASES = {"in-process": "Renderer.push_finger in the renderer's process (baseline)",
          "websocket": "a finger message from another process, over a WebSocket on loopback"}
PING_PHASES = {"idle": "nothing else (baseline)",
               "texture": "another client sending ~1 MiB inline textures of unknown keys, one after another",
               "osc-20": "bad OSC bundles, 20 a second",
               "osc-flood": "bad OSC bundles, as fast as one process sends"}


def measure(seconds: float, rounds: int, block: int, ping_seconds: float, ping_rounds: int) -> dict[str, Any]:
    """Run the worker on a fresh dummy server; its RESULT."""
    with tempfile.TemporaryDirectory() as folder, jack_server(RATE_HZ, block, Path(folder) / "jackd.log") as env:
        done = subprocess.run([sys.executable, str(WORKER), "--seconds", str(seconds), "--rounds", str(rounds),
                               "--block", str(block), "--ping-seconds", str(ping_seconds), "--ping-rounds",
                               str(ping_rounds)], cwd=ROOT, env=env, capture_output=True, text=True,
                              timeout=120 + 4 * rounds * seconds + ping_rounds * len(PING_PHASES) * (
                                  ping_seconds + 120))
    lines = done.stdout.strip().splitlines()
    if done.returncode != 0 or not lines or not lines[-1].startswith("RESULT "):
        raise SystemExit(f"serve_worker failed ({done.returncode}): {done.stderr.strip()[-2000:]}")
    return json.loads(lines[-1][len("RESULT "):])


def summarise(result: dict[str, Any]) -> dict[str, Any]:
    """Pooled p50/p99 per phase, and each round's median difference (WebSocket - in-process)."""
    summary: dict[str, Any] = {}
    for name in PHASES:
        latency = np.asarray(result[name]["latency_ms"])
        summary[name] = {"n": int(len(latency)), "p50_ms": float(np.percentile(latency, 50)),
                         "p99_ms": float(np.percentile(latency, 99)), "max_ms": float(latency.max())}
    differences = [ws["latency_ms"]["p50"] - local["latency_ms"]["p50"]
                   for ws, local in zip(result["websocket"]["per_round"], result["in-process"]["per_round"])]
    summary["p50_difference_ms"] = {"per_round": differences, "median": float(np.median(differences))}
    summary["pooled_p50_difference_ms"] = summary["websocket"]["p50_ms"] - summary["in-process"]["p50_ms"]
    summary["ping"] = summarise_pings(result["ping"])
    return summary


def summarise_pings(pings: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    """Per ping phase: its round trips pooled over the rounds (n, p50, p99, max in ms), their ratios to the idle
    phase's, and what the load sent and the server counted."""
    summary: dict[str, Any] = {}
    for name in PING_PHASES:
        rtt = np.concatenate([run["rtt_ms"] for run in pings[name]])
        summary[name] = {"n": int(len(rtt)), "p50_ms": float(np.percentile(rtt, 50)),
                         "p99_ms": float(np.percentile(rtt, 99)), "max_ms": float(rtt.max()),
                         "underflows": sum(run["underflows"] for run in pings[name]),
                         "load": [run.get("load") for run in pings[name]],
                         "server": [run["server"] for run in pings[name]]}
    idle = summary["idle"]
    for name in PING_PHASES:
        summary[name]["ratio_to_idle"] = {key: summary[name][f"{key}_ms"] / idle[f"{key}_ms"]
                                          for key in ("p50", "p99", "max")}
    return summary


def markdown(report: dict[str, Any]) -> str:
    """The results as a Markdown table and a line on the difference."""
    s, p = report["summary"], report["parameters"]
    lines = [f"JACK dummy server, {RATE_HZ} Hz, {p['block']}-frame periods, synchronous mode; {p['rounds']} rounds, "
             f"{p['seconds']:g} s per phase, a sample every 2 ms (machine: {report['machine']['cpus']} CPUs, "
             f"{report['machine']['python']}).", "",
             "| pushed by | samples | push-to-output p50 | p99 | max |", "|---|---:|---:|---:|---:|"]
    for name, title in PHASES.items():
        row = s[name]
        lines.append(f"| {title} | {row['n']} | {row['p50_ms']:.3f} ms | {row['p99_ms']:.3f} ms | "
                     f"{row['max_ms']:.3f} ms |")
    rounds = ", ".join(f"{d:+.3f}" for d in s["p50_difference_ms"]["per_round"])
    lines += ["", f"WebSocket p50 - in-process p50: {s['pooled_p50_difference_ms']:+.3f} ms pooled; per round "
              f"{rounds} ms (median {s['p50_difference_ms']['median']:+.3f} ms). Underflows in the run: "
              f"{report['result']['underflows']}; server counters: {report['result']['server']}."]
    pings = s["ping"]
    lines += ["", f"A WebSocket client's ping round trip (a ping every 10 ms, each after the last pong) on the same server, "
              f"{p['ping_rounds']} rounds of {p['ping_seconds']:g} s per phase, phases rotated:", "",
              "| while the server also takes | pings | p50 | p99 | max | p50 / idle | p99 / idle | max / idle | "
              "underflows |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, title in PING_PHASES.items():
        row, ratio = pings[name], pings[name]["ratio_to_idle"]
        lines.append(f"| {title} | {row['n']} | {row['p50_ms']:.2f} ms | {row['p99_ms']:.2f} ms | "
                     f"{row['max_ms']:.2f} ms | {ratio['p50']:.2f} | {ratio['p99']:.2f} | {ratio['max']:.2f} | "
                     f"{row['underflows']} |")
    texture = [load for load in pings["texture"]["load"] if load]
    replies = [reply for load in texture for reply in load["reply_s"]]
    flood = [load["rate_per_s"] for load in pings["osc-flood"]["load"] if load]
    dropped = sum(server.get("osc_dropped", 0) for server in pings["osc-flood"]["server"])
    lines += ["", f"Texture messages of {texture[0]['message_bytes']:,} bytes: {len(replies)} refused, each answered "
              f"{min(replies):.2f}-{max(replies):.2f} s after its send (read in a parser process). OSC flood: "
              f"{np.mean(flood):,.0f} datagrams a second sent, {dropped:,} dropped unread by the server-wide budget."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 rounds of 1 s per phase")
    parser.add_argument("--seconds", type=float, default=3.0, help="seconds per phase (default 3)")
    parser.add_argument("--rounds", type=int, default=6, help="rounds (default 6)")
    parser.add_argument("--block", type=int, default=64, help="frames per period (default 64)")
    parser.add_argument("--ping-seconds", type=float, default=3.0, help="seconds per ping phase (default 3)")
    parser.add_argument("--ping-rounds", type=int, default=3, help="ping rounds (default 3)")
    parser.add_argument("--out", type=results_folder.folder, default=ROOT / "bench" / "results", help="folder for the results")
    args = parser.parse_args(argv)
    seconds, rounds = (1.0, 2) if args.quick else (args.seconds, args.rounds)
    ping_seconds, ping_rounds = (2.0, 1) if args.quick else (args.ping_seconds, args.ping_rounds)
    result = measure(seconds, rounds, args.block, ping_seconds, ping_rounds)
    report = {
        "parameters": {"seconds": seconds, "rounds": rounds, "block": args.block, "ping_seconds": ping_seconds,
                       "ping_rounds": ping_rounds},
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
        "summary": summarise(result),
        "result": {key: value for key, value in result.items() if key not in PHASES and key != "ping"},
        "ping": result["ping"],
        "phases": {name: {"per_round": result[name]["per_round"], "pooled": result[name]["pooled"]}
                   for name in PHASES},
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "latency_serve.json").write_text(json.dumps(report, indent=1) + "\n")
    text = markdown(report)
    (args.out / "latency_serve.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
