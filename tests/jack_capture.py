"""Capture a JACK output port to a .npy file: a second, real JACK client for the audio tests.

    python tests/jack_capture.py SOURCE_PATTERN OUT.npy SECONDS

Runs in its own process (its Python process callback must not share a GIL with the
process under test). Registers one input port, connects the first output port whose
name matches the regular expression SOURCE_PATTERN (ports in number order: PortAudio
numbers a stream's ports on from the previous stream's) to it, prints
``ready`` on stdout, records SECONDS of float32 samples, then writes them to OUT.npy
and prints ``done FRAMES XRUNS``. If the server stops calling it (it shut the client down,
or SECONDS + PATIENCE_S pass), it writes what it has, says so and exits 1.
"""

from __future__ import annotations

import re
import sys
import threading

import jack
import numpy as np

#: How long (s) past SECONDS the capture waits for its samples before it gives up.
PATIENCE_S = 10.0


def main(source: str, out_path: str, seconds: float) -> None:
    client = jack.Client("tpadrt-capture", no_start_server=True)
    port = client.inports.register("in")
    buffer = np.zeros(int(seconds * client.samplerate), dtype=np.float32)
    written = [0]
    xruns = [0]
    full = threading.Event()

    @client.set_process_callback
    def process(frames: int) -> None:
        start = written[0]
        count = min(frames, len(buffer) - start)
        buffer[start:start + count] = port.get_array()[:count]
        written[0] = start + count
        if written[0] == len(buffer):
            full.set()

    @client.set_xrun_callback
    def xrun(delay_us: float) -> None:
        xruns[0] += 1

    shut_down: list[str] = []

    @client.set_shutdown_callback
    def shutdown(status: jack.Status, reason: str) -> None:
        shut_down.append(reason)
        full.set()

    with client:
        sources = client.get_ports(source, is_output=True, is_audio=True)
        if not sources:
            raise SystemExit(f"no output port matches {source!r}")
        client.connect(min(sources, key=lambda found: [int(part) for part in re.findall(r"\d+", found.name)]), port)
        print("ready", flush=True)
        full.wait(seconds + PATIENCE_S)
    np.save(out_path, buffer[:written[0]])
    print(f"done {written[0]} {xruns[0]}", flush=True)
    if written[0] < len(buffer):
        raise SystemExit(f"the server stopped calling the capture client after {written[0]} of {len(buffer)} samples"
                         + (f" (it shut the client down: {shut_down[0]})" if shut_down else ""))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], float(sys.argv[3]))
