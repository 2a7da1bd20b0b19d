"""One run of tpad-rt's serial streamer for bench/latency/serial_run.py, in a fresh process.

    python bench/latency/serial_worker.py SERIAL_URL SECONDS [--gil-threads N] --pushes FILE.npz

Runs a Renderer on SERIAL_URL with the grating and, like an application, pushes a
finger sample every 2 ms (a slow back-and-forth swipe) and copies the new per-frame
records out of the streamer's record ring every 50 ms, for SECONDS, while N other
Python threads spin a pure-Python loop. Writes each push's CLOCK_MONOTONIC time and the
stream index of the first sample of the first frame rendered after it to FILE.npz, and
prints one JSON line last: the envelope rate achieved, the samples the amplifier missed
(its underruns, and the samples of frames it refused), its other counters, the host's
own latency estimate, the target fill.
"""

from __future__ import annotations

import argparse
import faulthandler
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from worker import PUSH_PERIOD_S, RecordRing, _finger_x_mm, _gil_hogs  # noqa: E402

from tpad_rt.engine import Renderer  # noqa: E402
from tpad_rt.kernel import table as tab  # noqa: E402

GRATING = HERE.parents[1] / "textures" / "grating.yaml"
#: Seconds past its run after which the worker prints every thread's stack and exits (a hang shows where it hung).
HANG_S = 120.0


def main(url: str, seconds: float, gil_threads: int, pushes_path: Path) -> None:
    faulthandler.dump_traceback_later(seconds + HANG_S, exit=True)
    with Renderer(output=url, texture=GRATING) as renderer:
        table = renderer.callback_table
        assert table is not None
        ring = RecordRing(table)
        _gil_hogs(gil_threads)
        pushed: list[tuple[int, int]] = []  # (push time ns, finger count after it)
        first_frame = int(table.stats[tab.STAT_CALLBACKS])
        started = time.monotonic()
        next_poll = started
        while (now := time.monotonic()) - started < seconds:
            renderer.push_finger(_finger_x_mm(now - started), 20.0, 0.5)
            pushed.append((time.monotonic_ns(), int(renderer._pipeline.arrays.finger_count[0])))
            if now >= next_poll:
                ring.poll()
                next_poll = now + 0.05
            time.sleep(PUSH_PERIOD_S)
        ring.poll()
        frames = int(table.stats[tab.STAT_CALLBACKS]) - first_frame
        stats = renderer.stats()
    amp = stats["amplifier"]
    rows = ring.rows()
    counts = rows[:, tab.BLOCK_FINGER_COUNT]
    firsts = np.searchsorted(counts, [count for _, count in pushed], side="left")
    kept = firsts < len(rows)
    np.savez(pushes_path, push_ns=np.array([ns for ns, _ in pushed])[kept],
             first_index=rows[firsts[kept], tab.BLOCK_SAMPLE_INDEX])
    print(json.dumps({
        "rate_fraction": frames * amp["frame_samples"] / (seconds * amp["envelope_hz"]),
        "missed": amp["amp_underruns"] + amp["amp_frames_rejected"] * amp["frame_samples"], "late": amp["late"],
        "frames_bad": amp["amp_frames_bad"],
        "frames_rejected": amp["amp_frames_rejected"], "host_latency_ms_p50": stats["latency_ms_p50"],
        "target_fill_ms": amp["target_fill"] / amp["envelope_hz"] * 1e3,
    }), flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("url")
    parser.add_argument("seconds", type=float)
    parser.add_argument("--gil-threads", type=int, default=0)
    parser.add_argument("--pushes", type=Path, required=True)
    arguments = parser.parse_args()
    main(arguments.url, arguments.seconds, arguments.gil_threads, arguments.pushes)
