"""The amplifier emulator's timing on a real pty, next to a plain-Python echo on a pty, idle and under CPU load.

    python bench/latency/emulator_pty.py            # 4 rounds per load
    python bench/latency/emulator_pty.py --quick    # 2 rounds, fewer commands and trips
    python bench/latency/emulator_pty.py --smoke --out DIR  # 1 round idle, 20 commands, 1 trip: figures meaningless

Writes bench/results/emulator_pty.json and emulator_pty.md and prints the tables. These
are the timings the emulator's tests once judged on the wall clock (and retried when a
busy machine broke them); the tests now check the behaviour on a virtual clock
(tests/test_amp_emulator.py), and here is how the real process keeps time. Each round
starts ``tpad-rt amp emulate`` and the baseline, bench/latency/emulator_echo.py (a
plain-Python process at the same priority that echoes every byte and writes a STATUS
every 5 ms), each on a new pty, one after the other, and measures both the same way from
this process (the host, at SCHED_FIFO one below them where allowed):

1. command round trip (ms, p50/p99/max): a SET_CARRIER written, until its answer is
   read (the emulator's ACK; the echo's copy);
2. STATUS arrival jitter (ms, p50/p99/max): each STATUS's arrival on the host's clock
   less its ``time_us`` (the writer's own schedule), less the smallest such difference
   of the run: how late, beyond the best case, the periodic frames arrive;
3. the watchdog in real time (emulator only): START and 1024 samples at 8 kHz in one
   write, then silence; from that write to the host reading the first STATUS that counts
   the trip (ms). Its nominal value is 38 ms (A4's 40 ms less the emulator's 2 ms read
   allowance) plus up to one STATUS period (5 ms).

Loads: idle; cpu, one ``while True: pass`` process per core. Nothing here is a pass/fail
test (docs/testing.md).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import select
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "bench"))  # results_folder: the --out checks every bench script shares
import results_folder  # noqa: E402
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

from jack import cpu_hogs  # noqa: E402

from tpad_rt.amp import wire  # noqa: E402
from tpad_rt.amp.wire import Type  # noqa: E402
from tpad_rt.cli.amp import REALTIME_PRIORITY  # noqa: E402

ECHO = HERE / "emulator_echo.py"
LOADS = {"idle": "idle", "cpu": "one spinning process per core"}
WRITERS = {"emulator": "tpad-rt amp emulate", "echo": "plain-Python echo (baseline)"}
#: Longest wait (s) for any answer: a safety net.
WAIT_S = 30.0
#: The carrier the commands ask for (mHz): any the emulator makes.
CARRIER_MHZ = 31_360_000


@contextlib.contextmanager
def started(writer: str, folder: Path) -> Iterator[str]:
    """Start ``writer`` on a new pty; yields the pty's path; SIGTERM (by PID) on the way out."""
    command = ([sys.executable, "-m", "tpad_rt", "amp", "emulate", "--record", str(folder / "amp.npz")]
               if writer == "emulator" else [sys.executable, str(ECHO)])
    process = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stdout is not None
        first = process.stdout.readline()
        if " on /dev/" not in first:
            raise SystemExit(f"{writer} did not start: {first!r}")
        yield first.split()[-1]
    finally:
        process.send_signal(signal.SIGTERM)
        process.communicate(timeout=120)


class Host:
    """This process on the pty ``path``: frames out, frames in with their arrival time (ns)."""

    def __init__(self, path: str):
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
        self.seq = 0
        self.splitter = wire.FrameSplitter()
        #: (arrival ns, time_us) of every STATUS read.
        self.statuses: list[tuple[int, int]] = []

    def write(self, data: bytes) -> int:
        """Write ``data``; CLOCK_MONOTONIC (ns) just before."""
        sent_ns = time.monotonic_ns()
        view = memoryview(data)
        while view:
            view = view[os.write(self.fd, view):]
        return sent_ns

    def frame(self, type_: Type, payload: bytes) -> bytes:
        seq, self.seq = self.seq, (self.seq + 1) & 0xFFFF
        return wire.encode(type_, seq, payload)

    def until(self, wanted: Callable[[wire.Frame], bool], for_s: float = WAIT_S) -> int | None:
        """Read until a ``wanted`` frame arrives (its arrival, ns) or ``for_s`` passes (None)."""
        deadline_ns = time.monotonic_ns() + int(for_s * 1e9)
        while (left_ns := deadline_ns - time.monotonic_ns()) > 0:
            if not select.select([self.fd], [], [], left_ns / 1e9)[0]:
                continue
            data = os.read(self.fd, 65536)
            arrived_ns = time.monotonic_ns()
            found = False
            for encoded in self.splitter.feed(data):
                frame = None if encoded is None else wire.decode(encoded)
                if frame is None:
                    continue
                if frame.type == Type.STATUS:
                    self.statuses.append((arrived_ns, wire.Status.unpack(frame.payload).time_us))
                found = found or wanted(frame)
            if found:
                return arrived_ns
        return None

    def close(self) -> None:
        os.close(self.fd)


def round_trips_ms(host: Host, writer: str, count: int) -> list[float]:
    """``count`` SET_CARRIER commands, one at a time: from each write to its answer (ms)."""
    times_ms = []
    for _ in range(count):
        seq = host.seq
        sent_ns = host.write(host.frame(Type.SET_CARRIER, wire.SetCarrier(CARRIER_MHZ).pack()))
        if writer == "emulator":
            arrived = host.until(lambda frame: frame.type == Type.ACK and wire.Ack.unpack(frame.payload).acked_seq == seq)
        else:
            arrived = host.until(lambda frame: frame.type == Type.SET_CARRIER and frame.seq == seq)
        if arrived is None:
            raise SystemExit(f"{writer}: no answer to seq {seq}")
        times_ms.append((arrived - sent_ns) / 1e6)
    return times_ms


def watchdog_ms(host: Host, trips: int) -> list[float]:
    """``trips`` times: HELLO, then START and 1024 samples in one write, then silence; from that write to the first
    STATUS counting the trip (ms)."""
    seen_ms = []
    for trip in range(trips):
        host.seq = 0
        host.write(host.frame(Type.HELLO, wire.Hello("bench", trip).pack()))
        host.until(lambda frame: frame.type == Type.INFO and wire.Info.unpack(frame.payload).hello_nonce == trip)
        samples = np.full(64, 8000, np.int16)
        burst = (host.frame(Type.SET_CARRIER, wire.SetCarrier(CARRIER_MHZ).pack())
                 + host.frame(Type.START, wire.Start(8000, 0, 1024).pack())
                 + b"".join(host.frame(Type.ENVELOPE, wire.Envelope(64 * k, samples).pack()) for k in range(16)))
        sent_ns = host.write(burst)
        arrived = host.until(lambda frame: frame.type == Type.STATUS
                             and wire.Status.unpack(frame.payload).watchdog_trips > 0)
        if arrived is None:
            raise SystemExit("the emulator's watchdog did not trip")
        seen_ms.append((arrived - sent_ns) / 1e6)
    return seen_ms


def jitter_ms(statuses: list[tuple[int, int]]) -> list[float]:
    """Each STATUS's arrival less its own time_us, less the smallest of those (ms)."""
    if not statuses:
        return []
    arrived_ns = np.array([arrived for arrived, _ in statuses], dtype=np.int64)
    due_ns = np.unwrap(np.array([time_us for _, time_us in statuses], dtype=np.float64), period=2**32) * 1000
    late = arrived_ns - due_ns
    return ((late - late.min()) / 1e6).tolist()


def run_once(writer: str, commands: int, trips: int) -> dict[str, list[float]]:
    with tempfile.TemporaryDirectory() as folder, started(writer, Path(folder)) as port:
        host = Host(port)
        try:
            host.write(host.frame(Type.HELLO, wire.Hello("bench", 0xBE).pack()))  # STATUS from now on
            host.until(lambda frame: False, for_s=0.2)
            result = {"round_trip_ms": round_trips_ms(host, writer, commands)}
            result["watchdog_ms"] = watchdog_ms(host, trips) if writer == "emulator" else []
            result["jitter_ms"] = jitter_ms(host.statuses)
        finally:
            host.close()
    return result


def spread(values: list[float]) -> dict[str, float]:
    array = np.asarray(values)
    return {"p50": float(np.percentile(array, 50)), "p99": float(np.percentile(array, 99)),
            "max": float(array.max()), "count": int(array.size)}


def markdown(report: dict[str, Any]) -> str:
    s, p = report["summary"], report["parameters"]
    lines = [f"Amplifier emulator on a pty, next to a plain-Python echo at the same priority; {p['rounds']} rounds "
             f"per load, {p['commands']} commands and {p['trips']} watchdog trips a round (machine: "
             f"{report['machine']['cpus']} CPUs, Python {report['machine']['python']}, load average before "
             f"{report['machine']['loadavg_before']}; the host at {report['machine']['host_priority']}, the writers "
             f"one above).", "",
             "Loads: " + "; ".join(f"{name}: {LOADS[name]}" for name in p["loads"]) + ".", "",
             "| figure | load | emulator p50 / p99 / max | echo p50 / p99 / max | p50 ratio |", "|---|---|---|---|---:|"]
    for figure, title in (("round_trip_ms", "command round trip"), ("jitter_ms", "STATUS arrival jitter")):
        for load in p["loads"]:
            mine, base = s[f"emulator/{load}"][figure], s[f"echo/{load}"][figure]
            lines.append(f"| {title} | {load} | {mine['p50']:.3f} / {mine['p99']:.3f} / {mine['max']:.3f} ms | "
                         f"{base['p50']:.3f} / {base['p99']:.3f} / {base['max']:.3f} ms | "
                         f"{mine['p50'] / base['p50']:.2f} |")
    lines += ["", "| load | silence to the watchdog's trip seen, p50 / p99 / max | nominal |", "|---|---|---|"]
    for load in p["loads"]:
        row = s[f"emulator/{load}"]["watchdog_ms"]
        lines.append(f"| {load} | {row['p50']:.1f} / {row['p99']:.1f} / {row['max']:.1f} ms | 38-43 ms, plus the "
                     "pty's delivery (the echo's round trip) |")
    return "\n".join(lines) + "\n"


def host_priority() -> str:
    """Run this process (the host) at SCHED_FIFO one below the writers' priority where allowed, so that its own
    scheduling does not stand in the figures: what it got. Its children (the writers, the load) do not inherit it
    (SCHED_RESET_ON_FORK): a spinning load at SCHED_FIFO would take the machine."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(REALTIME_PRIORITY - 1))
    except OSError:
        return "ordinary (SCHED_FIFO refused)"
    return f"SCHED_FIFO {REALTIME_PRIORITY - 1}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 rounds, 100 commands and 5 trips a round")
    parser.add_argument("--smoke", action="store_true",
                        help="the test suite's check that the bench runs: 1 round idle, 20 commands, 1 trip "
                             "(figures meaningless)")
    parser.add_argument("--rounds", type=int, default=4, help="rounds per load (default 4)")
    parser.add_argument("--out", type=results_folder.folder, default=ROOT / "bench" / "results", help="folder for the results")
    args = parser.parse_args(argv)
    results_folder.refuse_smoke_into_results(parser, args.smoke, args.out)
    rounds, commands, trips = (1, 20, 1) if args.smoke else (2, 100, 5) if args.quick else (args.rounds, 300, 10)
    loads = ["idle"] if args.smoke else list(LOADS)
    loadavg_before = " ".join(Path("/proc/loadavg").read_text().split()[:3])
    priority = host_priority()
    runs: dict[str, dict[str, list[dict[str, list[float]]]]] = {w: {load: [] for load in loads} for w in WRITERS}
    for round_number in range(rounds):
        for load in loads:
            with contextlib.ExitStack() as load_on:
                if load == "cpu":
                    load_on.enter_context(cpu_hogs(os.cpu_count() or 2))
                for writer in (WRITERS if round_number % 2 == 0 else reversed(list(WRITERS))):
                    runs[writer][load].append(run_once(writer, commands, trips))
                    print(f"round {round_number + 1}/{rounds} {load:4s} {writer}", flush=True)
    summary = {f"{writer}/{load}": {figure: spread([v for result in results for v in result[figure]])
                                    if any(result[figure] for result in results) else {}
                                    for figure in ("round_trip_ms", "jitter_ms", "watchdog_ms")}
               for writer, by_load in runs.items() for load, results in by_load.items()}
    report = {"parameters": {"rounds": rounds, "commands": commands, "trips": trips, "loads": loads},
              "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform(),
                          "loadavg_before": loadavg_before, "host_priority": priority},
              "summary": summary}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "emulator_pty.json").write_text(json.dumps(report, indent=1) + "\n")
    text = markdown(report)
    (args.out / "emulator_pty.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
