"""The WebSocket clients of the serve latency benchmark: a finger sample every 2 ms, or a ping every 10 ms,
for S seconds.

    python bench/latency/serve_client.py WS_URL SECONDS          # finger samples
    python bench/latency/serve_client.py WS_URL SECONDS ping     # pings

Connects (the ``websockets`` sync client), reads the hello, then sends ``finger``
messages (the swipe of worker.py, no client times: each is stamped when it arrives) on
the monotonic clock's 2 ms grid, and records CLOCK_MONOTONIC (ns, the clock every process
on the machine shares) just before each send. Asks for ``stats`` at the end, so that
every finger message has been handled when it exits. Prints one line ``RESULT {json}``
last: ``{"send_ns": [...]}``. With ``ping``, sends a ``ping`` on the 10 ms grid once the
previous one is answered, and prints ``{"rtt_ms": [...]}``: each ping's round trip, from
just before its send to its ``pong`` read (ms).
"""

from __future__ import annotations

import json
import math
import sys
import time

from websockets.sync.client import connect

PUSH_PERIOD_S = 0.002
PING_PERIOD_S = 0.01
#: Longest wait for one pong (s): a server that takes longer has failed.
PONG_TIMEOUT_S = 120.0


def main(url: str, seconds: float) -> None:
    send_ns: list[int] = []
    with connect(url, max_size=None) as ws:
        json.loads(ws.recv())  # hello
        start = time.monotonic()
        step = 0
        while (elapsed := time.monotonic() - start) < seconds:
            x_mm = 30.0 + 20.0 * math.sin(2 * math.pi * elapsed / 2.0)
            message = json.dumps({"type": "finger", "x_mm": x_mm, "y_mm": 20.0, "force_n": 0.5})
            send_ns.append(time.monotonic_ns())
            ws.send(message)
            step += 1
            time.sleep(max(0.0, start + step * PUSH_PERIOD_S - time.monotonic()))
        ws.send(json.dumps({"type": "stats", "id": "end"}))
        while json.loads(ws.recv()).get("id") != "end":
            pass
    print("RESULT " + json.dumps({"send_ns": send_ns}), flush=True)


def ping(url: str, seconds: float) -> None:
    rtt_ms: list[float] = []
    with connect(url, max_size=None) as ws:
        json.loads(ws.recv())  # hello
        start = time.monotonic()
        while time.monotonic() - start < seconds:
            sent_ns = time.monotonic_ns()
            ws.send(json.dumps({"type": "ping", "id": len(rtt_ms)}))
            while json.loads(ws.recv(timeout=PONG_TIMEOUT_S)).get("id") != len(rtt_ms):
                pass
            rtt_ms.append((time.monotonic_ns() - sent_ns) * 1e-6)
            time.sleep(max(0.0, start + len(rtt_ms) * PING_PERIOD_S - time.monotonic()))
    print("RESULT " + json.dumps({"rtt_ms": rtt_ms}), flush=True)


if __name__ == "__main__":
    (ping if sys.argv[3:] == ["ping"] else main)(sys.argv[1], float(sys.argv[2]))
