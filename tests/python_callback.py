"""The control of the GIL-load test: an ordinary sounddevice Python callback under GIL load.

    python tests/python_callback.py SECONDS

Opens a 192 kHz, 64-frame output stream on the default device (the JACK server named
by ``JACK_DEFAULT_SERVER``) whose Python callback renders the grating through
``Pipeline.render``, while another thread runs a pure-Python loop. Prints
``CALLBACKS UNDERFLOWS EXPECTED`` (EXPECTED from the stream's own clock), then exits at
once without closing the stream: a JACK client starved of the GIL can hang in
deactivation, and the server cleans up after a client that exits.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path

import numpy as np
import sounddevice

from tpad_rt.device import Device
from tpad_rt.pipeline import Pipeline
from tpad_rt.texture import load_compiled

RATE_HZ = 192000
BLOCK = 64
GRATING = Path(__file__).resolve().parents[1] / "textures" / "grating.yaml"


def main(seconds: float) -> None:
    pipeline = Pipeline(Device.default(), load_compiled(GRATING), RATE_HZ)
    pipeline.warm_up()
    pipeline.start()
    block = np.zeros(BLOCK, dtype=np.float32)
    counts = [0, 0]

    def render(outdata: np.ndarray, frames: int, time_info: object, status: sounddevice.CallbackFlags) -> None:
        counts[0] += 1
        counts[1] += bool(status.output_underflow)
        outdata.fill(0.0)
        if frames == BLOCK:
            pipeline.render(block)
            outdata[:, 0] = block

    def hog() -> None:
        count = 0
        while True:
            count += 1

    stream = sounddevice.OutputStream(samplerate=RATE_HZ, blocksize=BLOCK, channels=1, dtype="float32",
                                      latency="low", callback=render)
    stream.start()
    threading.Thread(target=hog, daemon=True).start()
    begin_s = stream.time
    time.sleep(seconds)
    end_s = stream.time
    print(counts[0], counts[1], (end_s - begin_s) * RATE_HZ / BLOCK, flush=True)
    os._exit(0)


if __name__ == "__main__":
    main(float(sys.argv[1]))
