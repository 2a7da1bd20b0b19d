"""The measuring process of the serve latency benchmark: one Renderer, pushed in process and through WebSocket.

    python bench/latency/serve_worker.py --seconds S --rounds R [--block FRAMES] [--ping-seconds P --ping-rounds Q]

Run by bench/latency/serve_run.py with ``JACK_DEFAULT_SERVER`` naming a running dummy
server. Starts a :class:`tpad_rt.engine.Renderer` on ``audio://?rate=192000&block=FRAMES``
rendering textures/grating.yaml and, on an asyncio loop in a thread of this process,
``tpad-rt serve``'s :class:`~tpad_rt.serve.server.Server` in front of it (loopback, free
ports, OSC on). Then R rounds, each with two phases of S seconds in an order that
alternates from round to round:

- ``in-process``: the main thread calls ``Renderer.push_finger`` every 2 ms (worker.py's
  application), noting CLOCK_MONOTONIC before each call;
- ``websocket``: a client in its own process (serve_client.py) sends a ``finger``
  message every 2 ms, noting CLOCK_MONOTONIC before each send.

Either way a sample's latency runs from that time to the DAC time of the first block whose
start saw it (worker.py's ``_latency``: the block record's finger count passes the
sample's index, plus the DAC delay PortAudio reports). The finger ring's count at the
start of a WebSocket phase and the client's send order give each message its index
(the phase is refused if the count moved by another number than the messages sent, and
the lift the server pushes when the client leaves).

Then Q ping rounds, each with PING_PHASES of P seconds in an order rotated from round to
round: a WebSocket client in its own process (serve_client.py ``ping``) pings every 10 ms
and notes each round trip, while another process (serve_load.py) loads the server, or
nothing does (``idle``, the baseline).

Prints one line ``RESULT {json}`` last.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from worker import GRATING, RATE_HZ, RecordRing, _app_loop, _finger_x_mm, _latency, _result, read_by  # noqa: E402

CLIENT = HERE / "serve_client.py"
LOAD = HERE / "serve_load.py"
POLL_PERIOD_S = 0.05
#: The ping phases: name -> serve_load.py's arguments after its kind's target (None: no load).
PING_PHASES: dict[str, tuple[str, ...] | None] = {"idle": None, "texture": ("texture",), "osc-20": ("osc", "20"),
                                                  "osc-flood": ("osc", "0")}


class ServerThread:
    """``Server(renderer, settings)`` on an asyncio loop in a thread; ``port`` once started; ``close()``."""

    def __init__(self, renderer: Any):
        from tpad_rt.serve.server import Server, Settings

        self.server = Server(renderer, Settings(port=0, osc_port=0))
        self.loop = asyncio.new_event_loop()
        self.listening = threading.Event()
        self.failure: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="serve", daemon=True)
        self.thread.start()
        if not self.listening.wait(60.0) or self.failure is not None:
            raise SystemExit(f"serve_worker: the server did not start: {self.failure}")

    def _run(self) -> None:
        try:
            self.loop.run_until_complete(self._serve())
        except BaseException as error:  # noqa: BLE001 - reported by the constructor or close()
            self.failure = error
            self.listening.set()

    async def _serve(self) -> None:
        self.stop = asyncio.Event()
        ready = asyncio.Event()
        task = asyncio.create_task(self.server.run(self.stop, ready))
        await ready.wait()
        self.listening.set()
        await task

    @property
    def port(self) -> int:
        return self.server.port

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.stop.set)
        self.thread.join(30.0)


def in_process(renderer: Any, ring: RecordRing, seconds: float) -> list[tuple[int, int]]:
    """The in-process phase: (push time ns, sample index) of each push."""
    from tpad_rt.realtime import monotonic_ns

    counts = renderer.callback_table.arrays.finger_count
    pushes: list[tuple[int, int]] = []

    def push(x_mm: float) -> None:
        index = int(counts[0])
        pushed_ns = monotonic_ns()
        renderer.push_finger(x_mm, 20.0, 0.5)
        pushes.append((pushed_ns, index))

    _app_loop(seconds, push, ring.poll)
    return pushes


def websocket(renderer: Any, ring: RecordRing, port: int, seconds: float) -> list[tuple[int, int]]:
    """The WebSocket phase: (send time ns, sample index) of each message the client sent."""
    counts = renderer.callback_table.arrays.finger_count
    first = int(counts[0])
    client = subprocess.Popen([sys.executable, str(CLIENT), f"ws://127.0.0.1:{port}/ws", str(seconds)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    while client.poll() is None:
        ring.poll()
        time.sleep(POLL_PERIOD_S)
    ring.poll()
    out, err = client.communicate()
    if client.returncode != 0 or not out.strip().splitlines()[-1:][0].startswith("RESULT "):
        raise SystemExit(f"serve_worker: the client failed: {err.strip()}")
    send_ns = json.loads(out.strip().splitlines()[-1][len("RESULT "):])["send_ns"]
    pushed = int(counts[0]) - first
    if pushed not in (len(send_ns), len(send_ns) + 1):  # + the lift the server pushes when the client leaves
        raise SystemExit(f"serve_worker: the client sent {len(send_ns)} samples, the renderer took {pushed}")
    return [(ns, first + k) for k, ns in enumerate(send_ns)]


def _child_result(process: subprocess.Popen[str], what: str, timeout_s: float) -> dict[str, Any]:
    """The ``RESULT`` of a child process once it exits; SystemExit with its stderr when it fails."""
    out, err = process.communicate(timeout=timeout_s)
    lines = out.strip().splitlines()
    if process.returncode != 0 or not lines or not lines[-1].startswith("RESULT "):
        raise SystemExit(f"serve_worker: the {what} failed ({process.returncode}): {err.strip()[-2000:]}")
    result: dict[str, Any] = json.loads(lines[-1][len("RESULT "):])
    return result


def ping_phase(serve: ServerThread, load: tuple[str, ...] | None, seconds: float) -> dict[str, Any]:
    """One ping phase: the round trips (ms) of a client pinging for ``seconds`` while ``load`` runs (its
    RESULT under ``load``), the server's counters it changed, and the renderer's underflows meanwhile."""
    before = dict(serve.server.counters)
    underflows = serve.server.renderer.stats()["underflows"]
    loader = None
    if load is not None:
        target = f"ws://127.0.0.1:{serve.port}/ws" if load[0] == "texture" else str(serve.server.osc_port)
        loader = subprocess.Popen([sys.executable, str(LOAD), load[0], target, str(seconds), *load[1:]],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert loader.stdout is not None
        if loader.stdout.readline().strip() != "READY":
            raise SystemExit(f"serve_worker: the load {load} did not start: {_child_result(loader, 'load', 60)}")
    pinger = subprocess.Popen([sys.executable, str(CLIENT), f"ws://127.0.0.1:{serve.port}/ws", str(seconds), "ping"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    result = _child_result(pinger, "ping client", 300 + seconds)
    if loader is not None:
        result["load"] = _child_result(loader, "load", 600 + seconds)
    result["underflows"] = serve.server.renderer.stats()["underflows"] - underflows
    after = serve.server.counters
    result["server"] = {key: after[key] - before.get(key, 0) for key in after if after[key] != before.get(key, 0)}
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--block", type=int, default=64)
    parser.add_argument("--ping-seconds", type=float, default=3.0)
    parser.add_argument("--ping-rounds", type=int, default=3)
    args = parser.parse_args(argv)

    from tpad_rt.engine import Renderer
    from tpad_rt.kernel import callback as cb

    renderer = Renderer(output=f"audio://?rate={RATE_HZ}&block={args.block}", texture=GRATING)
    renderer.start()
    serve = ServerThread(renderer)
    renderer.push_finger(_finger_x_mm(0.0), 20.0, 0.5)
    time.sleep(0.2)  # past the start
    ring = RecordRing(renderer.callback_table)
    phases: dict[str, list[list[tuple[int, int]]]] = {"in-process": [], "websocket": []}
    order: list[list[str]] = []
    for round_number in range(args.rounds):
        names = ["in-process", "websocket"] if round_number % 2 == 0 else ["websocket", "in-process"]
        order.append(names)
        for name in names:
            if name == "in-process":
                phases[name].append(in_process(renderer, ring, args.seconds))
            else:
                phases[name].append(websocket(renderer, ring, serve.port, args.seconds))
            renderer.lift()
    pings: dict[str, list[dict[str, Any]]] = {name: [] for name in PING_PHASES}
    names = list(PING_PHASES)
    for round_number in range(args.ping_rounds):
        for name in names[round_number % len(names):] + names[:round_number % len(names)]:
            pings[name].append(ping_phase(serve, PING_PHASES[name], args.ping_seconds))
    serve.close()
    rows = ring.rows()
    stats = renderer.stats()
    renderer.stop()
    result: dict[str, Any] = {"rounds": order, "records": int(len(rows)), "records_lost": ring.lost,
                              "underflows": stats["underflows"], "server": dict(serve.server.counters),
                              "ping": pings}
    for name, runs in phases.items():
        per_round = [_latency(rows, pushes, cb) for pushes in runs]
        everything = _latency(rows, [push for pushes in runs for push in pushes], cb)
        result[name] = {"per_round": per_round, "pooled": everything,
                        "latency_ms": _latencies_ms(rows, [push for pushes in runs for push in pushes])}
    _result(result)
    return 0


def _latencies_ms(rows: np.ndarray, pushes: list[tuple[int, int]]) -> list[float]:
    """Every sample's latency (ms), the figure worker._latency takes percentiles of."""
    pushed_ns, entry_ns, dac_ns = read_by(rows, pushes)
    return ((entry_ns + dac_ns - pushed_ns) * 1e-6).round(4).tolist()


if __name__ == "__main__":
    sys.exit(main())
