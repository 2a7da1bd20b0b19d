"""A tpad-rt serve client in Python (the ``websockets`` package): set a texture, swipe a finger, watch it.

    tpad-rt serve                                  # in another terminal (any output)
    python examples/clients/python_client.py [--url ws://127.0.0.1:8765/ws] [--texture grating]

It checks the server's protocol version, sets a shipped texture by name, subscribes to
telemetry at 20 Hz, swipes the finger from x = 20 mm to 110 mm and back at 100 mm/s
(samples every 5 ms, stamped with this process's clock, sent in batches of four), lifts,
and prints what the renderer did: a line per telemetry message, then its latency figures.
The same messages as the JavaScript and C# clients beside it (docs/serve.md).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from typing import Any

from websockets.sync.client import connect

PROTOCOL_VERSION = 1
SPEED_MM_S = 100.0
SAMPLE_PERIOD_S = 0.005
BATCH = 4


def swipe_positions(from_mm: float, to_mm: float) -> list[float]:
    """x (mm) every SAMPLE_PERIOD_S from ``from_mm`` to ``to_mm`` and back at SPEED_MM_S."""
    steps = int(abs(to_mm - from_mm) / SPEED_MM_S / SAMPLE_PERIOD_S)
    forth = [from_mm + (to_mm - from_mm) * i / steps for i in range(steps + 1)]
    return forth + forth[::-1]


def main(url: str, texture: str) -> int:
    with connect(url) as ws:
        hello = json.loads(ws.recv())
        if hello.get("type") != "hello" or hello.get("protocol") != PROTOCOL_VERSION:
            print(f"this client speaks protocol {PROTOCOL_VERSION}; the server said {hello}", file=sys.stderr)
            return 1
        plate = hello["device"]["plate"]
        print(f"{hello['server']}: {hello['device']['label']}, plate {plate['length_mm']:g} x {plate['width_mm']:g} mm, "
              f"at most {hello['device']['max_voltage_v']:g} V; texture now: {hello['texture']['description']}")

        ws.send(json.dumps({"type": "texture", "name": texture, "id": "texture"}))
        ws.send(json.dumps({"type": "subscribe", "rate_hz": 20}))
        replies: list[dict[str, Any]] = []
        done = threading.Event()

        def read() -> None:  # the server's messages, printed as they come, until the stats reply
            for raw in ws:
                message = json.loads(raw)
                replies.append(message)
                if message["type"] == "telemetry" and message["touching"]:
                    print(f"  x {message['x_mm']:6.1f} mm  target {message['target_mu']:.3f}  achieved "
                          f"{message['achieved_mu']:.3f}  drive {message['voltage_peak_v']:5.1f} V  power "
                          f"{message['power_peak_w']:.3f} W")
                elif message["type"] == "error":
                    print(f"  error {message['code']}: {message['message']}")
                elif message["type"] == "texture" and message.get("id") == "texture":
                    print(f"texture set: {message['description']}")
                if message["type"] == "stats":
                    done.set()
                    return

        reader = threading.Thread(target=read, daemon=True)
        reader.start()

        positions = swipe_positions(20.0, 0.85 * plate["length_mm"])
        start = time.monotonic()
        for first in range(0, len(positions), BATCH):
            due = start + (first + BATCH - 1) * SAMPLE_PERIOD_S  # send a batch when its last sample is due
            time.sleep(max(0.0, due - time.monotonic()))
            samples = [{"x_mm": x, "y_mm": plate["width_mm"] / 2, "t": start + (first + i) * SAMPLE_PERIOD_S}
                       for i, x in enumerate(positions[first:first + BATCH])]
            ws.send(json.dumps({"type": "fingers", "samples": samples}))
        ws.send(json.dumps({"type": "lift", "t": time.monotonic()}))
        time.sleep(0.2)  # telemetry of the lift
        ws.send(json.dumps({"type": "stats"}))
        if not done.wait(10.0):
            print("no stats reply within 10 s", file=sys.stderr)
            return 1
        stats = replies[-1]["renderer"]
        errors = [reply for reply in replies if reply["type"] == "error"]
        print(f"push-to-output latency p50 {milliseconds(stats['latency_ms_p50'])}, "
              f"p99 {milliseconds(stats['latency_ms_p99'])}; {len(errors)} errors")
        return 1 if errors else 0


def milliseconds(value: float | None) -> str:
    """A figure in ms to 0.01 ms, or "n/a" for none (the server sends null where nothing was measured)."""
    return "n/a" if value is None else f"{value:.2f} ms"


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="ws://127.0.0.1:8765/ws")
    parser.add_argument("--texture", default="grating", help="a shipped texture's name (default grating)")
    arguments = parser.parse_args()
    try:
        sys.exit(main(arguments.url, arguments.texture))
    except OSError as error:
        sys.exit(f"cannot reach {arguments.url}: {error} (is tpad-rt serve running?)")
