"""The WebSocket client of the serve latency benchmark: a finger sample every 2 ms for S seconds.

    python bench/latency/serve_client.py WS_URL SECONDS

Connects (the ``websockets`` sync client), reads the hello, then sends ``finger``
messages (the swipe of worker.py, no client times: each is stamped when it arrives) on
the monotonic clock's 2 ms grid, and records CLOCK_MONOTONIC (ns, the clock every process
on the machine shares) just before each send. Asks for ``stats`` at the end, so that
every finger message has been handled when it exits. Prints one line ``RESULT {json}``
last: ``{"send_ns": [...]}``.
"""

from __future__ import annotations

import json
import math
import sys
import time

from websockets.sync.client import connect

PUSH_PERIOD_S = 0.002


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


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]))
