"""The measuring process of the serve latency benchmark: one Renderer, pushed in process and through WebSocket.

    python bench/latency/serve_worker.py --seconds S --rounds R [--block FRAMES]

Run by bench/latency/serve_run.py with ``JACK_DEFAULT_SERVER`` naming a running dummy
server. Starts a :class:`tpad_rt.engine.Renderer` on ``audio://?rate=192000&block=FRAMES``
rendering textures/grating.yaml and, on an asyncio loop in a thread of this process,
``tpad-rt serve``'s :class:`~tpad_rt.serve.server.Server` in front of it (loopback, a
free port, no OSC). Then R rounds, each with two phases of S seconds in an order that
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
POLL_PERIOD_S = 0.05


class ServerThread:
    """``Server(renderer, settings)`` on an asyncio loop in a thread; ``port`` once started; ``close()``."""

    def __init__(self, renderer: Any):
        from tpad_rt.serve.server import Server, Settings

        self.server = Server(renderer, Settings(port=0, osc_port=None))
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--block", type=int, default=64)
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
    serve.close()
    rows = ring.rows()
    stats = renderer.stats()
    renderer.stop()
    result: dict[str, Any] = {"rounds": order, "records": int(len(rows)), "records_lost": ring.lost,
                              "underflows": stats["underflows"], "server": dict(serve.server.counters)}
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
