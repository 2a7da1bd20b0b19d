"""A Renderer app on ``serial://PORT`` in its own process, for the tests that freeze or orphan the host.

    python tests/serial_host.py PORT

Starts a Renderer with the grating on PORT and pushes a slow swipe every 2 ms. Prints
``streaming`` once the amplifier reports RUNNING, ``resumed`` once it plays again (over
1 V RMS) after a START sent again after its watchdog, and runs until its stdin closes; then
stops (STOP and all) and prints ``restarts N start_index I`` (STARTs sent again after the
amplifier's watchdog, and the stream index the last START named). An error ends it with one line on stderr and exit status 1, as tpad-rt's
commands do.
"""

from __future__ import annotations

import itertools
import sys
import threading
import time
from pathlib import Path

from tpad_rt.engine import Renderer
from tpad_rt.errors import TpadError

GRATING = Path(__file__).resolve().parents[1] / "textures" / "grating.yaml"


def main(port: str) -> int:
    closed = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), closed.set()), daemon=True).start()
    try:
        with Renderer(output=f"serial://{port}", texture=GRATING) as renderer:
            started = time.monotonic()
            announced = resumed = False
            for step in itertools.count():
                if closed.is_set():
                    break
                renderer.check()
                renderer.push_finger(20.0 + 10.0 * ((time.monotonic() - started) % 5.0), 20.0, 0.5)
                if not resumed and step % 10 == 0:
                    amplifier = renderer.stats()["amplifier"]
                    if not announced and amplifier["amp_state"] == "RUNNING":
                        print("streaming", flush=True)
                        announced = True
                    elif announced and amplifier["restarts"] >= 1 and amplifier["amp_state"] == "RUNNING" \
                            and amplifier["amp_voltage_v_rms"] > 1.0:
                        print("resumed", flush=True)
                        resumed = True
                time.sleep(0.002)
        amplifier = renderer.stats()["amplifier"]
        print(f"restarts {amplifier['restarts']} start_index {amplifier['start_index']}", flush=True)
    except TpadError as error:
        print(f"serial_host: {error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
