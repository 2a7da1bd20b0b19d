"""The concurrent control of the callback-count tests: a second JACK client running the empty native callback.

    python tests/jack_counter.py RATE_HZ BLOCK

Opens an output stream on the default device (the JACK server named by
``JACK_DEFAULT_SERVER``) whose callback is :func:`tpad_rt.kernel.callback.silence_callback`
(compiled, no Python), prints ``ready``, then answers each line read on stdin with
``CALLBACKS UNDERFLOWS`` so far; at the end of its input it stops and closes the stream.

Both clients of one server are called in the same cycles: cycles the server skips (its
xruns on a loaded machine) are missing from both counts, and its stream clock, which
runs behind or ahead of the cycles under load, is not needed. A callback missing
cycles that this control got was late or not called.
"""

from __future__ import annotations

import sys
from pathlib import Path

from tpad_rt.device import Device
from tpad_rt.kernel import callback as cb
from tpad_rt.kernel import table as tab
from tpad_rt.outputs import audio
from tpad_rt.pipeline import Pipeline
from tpad_rt.realtime import CallbackTable
from tpad_rt.texture import load_compiled

GRATING = Path(__file__).resolve().parents[1] / "textures" / "grating.yaml"


def main(rate_hz: int, block: int) -> None:
    pipeline = Pipeline(Device.default(), load_compiled(GRATING), rate_hz)
    target = audio.find_output_device(None)
    table = CallbackTable(pipeline.arrays, pipeline.texture, channels=target.channels)
    stream = audio.AudioStream(target, rate_hz, block, target.channels, cb.silence_callback.address,
                               table.user_data)
    try:
        stream.start()
        print("ready", flush=True)
        for _ in sys.stdin:
            print(int(table.stats[tab.STAT_CALLBACKS]), int(table.stats[tab.STAT_UNDERFLOWS]), flush=True)
        stream.stop()
    finally:
        stream.close()


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]))
