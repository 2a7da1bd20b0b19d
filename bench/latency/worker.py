"""One measured configuration of the latency benchmark, in a fresh process.

    python bench/latency/worker.py stream CALLBACK --block FRAMES --seconds S [--gil-threads N]
    python bench/latency/worker.py startup --block FRAMES
    python bench/latency/worker.py play --block FRAMES

Run by bench/latency/run.py with ``JACK_DEFAULT_SERVER`` naming a running dummy server
(PortAudio sees it because it initialises in this process while the server runs).
Prints one line ``RESULT {json}`` last.

``stream``: opens a 192 kHz output stream of ``FRAMES``-frame blocks on the default
device with CALLBACK, one of

- ``silence``: tpad_rt.kernel.callback.silence_callback (a ``@cfunc`` writing zeros,
  the empty-callback baseline of the tests) on a CallbackTable;
- ``tpad``: a :class:`tpad_rt.engine.Renderer` on ``audio://`` rendering
  textures/grating.yaml (its ``render_callback``);
- ``python``: an ordinary sounddevice Python callback calling ``Pipeline.render``
  (the same kernel, the same texture);

then, like an application, pushes a finger sample every 2 ms from the main thread
(a slow back-and-forth swipe) and every 50 ms copies the new per-block records out of
the callback's record ring, for ``S`` seconds, while ``N`` other Python threads spin a
pure-Python loop (GIL load). Reports callbacks and underflows in that window, the
callbacks the stream's own clock (``Pa_GetStreamTime``) expects in it, every block's
compute time, the callbacks CLOCK_MONOTONIC says were due in it (a server in synchronous
mode slows its own clock while it waits for a late client), and (``tpad``) each finger
sample's push-to-output latency. The
``python`` configuration exits without closing its stream (a JACK client starved of
the GIL can hang in deactivation; the server cleans up after a client that exits).

``startup``: the start-up path with a warm numba cache: imports tpad_rt, builds a
Renderer on ``audio://`` with the grating, ``start()``s it and waits for the first
callback; reports CLOCK_MONOTONIC stamps (ns, the clock of the parent process too)
of each step and of the first sample at the DAC (the first block's entry time plus
its DAC delay). ``play``: the same stamps for ``tpad-rt play textures/grating.yaml
--output audio://?rate=192000&block=FRAMES --duration 0.3`` run through
``tpad_rt.cli.main`` in this process.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import threading
import time
from typing import Any
from pathlib import Path

RATE_HZ = 192000
ROOT = Path(__file__).resolve().parents[2]
GRATING = ROOT / "textures" / "grating.yaml"
#: Seconds between two finger samples pushed by the "application".
PUSH_PERIOD_S = 0.002
#: Seconds between two copies of the record ring (4096 rows: 0.34 s of 16-frame blocks).
POLL_PERIOD_S = 0.05
#: Blocks of Python-callback compute times kept (a preallocated ring).
PY_RECORDS = 2**20


def _result(payload: dict) -> None:
    print("RESULT " + json.dumps(payload), flush=True)


def _finger_x_mm(t_s: float) -> float:
    """A slow back-and-forth swipe: 10..50 mm, up to 63 mm/s."""
    return 30.0 + 20.0 * math.sin(2 * math.pi * t_s / 2.0)


def _gil_hogs(count: int) -> None:
    def spin() -> None:
        n = 0
        while True:
            n += 1

    for _ in range(count):
        threading.Thread(target=spin, daemon=True).start()


class RecordRing:
    """Copies the new rows of a CallbackTable's per-block record ring (call ``poll`` often enough)."""

    def __init__(self, table: object):
        from tpad_rt.kernel import table as tab
        self.tab = tab
        self.table = table
        self.next = int(table.stats[tab.STAT_CALLBACKS])
        self.chunks: list = []
        self.lost = 0

    def poll(self) -> None:
        import numpy as np
        tab = self.tab
        done = int(self.table.stats[tab.STAT_CALLBACKS])
        rows = self.table.blocks.shape[0]
        first = max(self.next, done - rows + 1)  # row (done % rows) may be being rewritten
        self.lost += first - self.next
        if done > first:
            self.chunks.append(self.table.blocks[np.arange(first, done) % rows].copy())
        self.next = done

    def rows(self):
        import numpy as np
        return np.concatenate(self.chunks) if self.chunks else np.zeros((0, self.tab.BLOCK_COLS), dtype=np.int64)


def _app_loop(seconds: float, push, poll) -> None:
    """Push a finger sample every PUSH_PERIOD_S and poll every POLL_PERIOD_S, for ``seconds``."""
    start = time.monotonic()
    next_poll = start
    while (elapsed := time.monotonic() - start) < seconds:
        push(_finger_x_mm(elapsed))
        if time.monotonic() >= next_poll:
            poll()
            next_poll += POLL_PERIOD_S
        time.sleep(PUSH_PERIOD_S)
    poll()


def _percentiles(values, scale: float = 1.0) -> dict:
    import numpy as np
    values = np.asarray(values, dtype=np.float64) * scale
    if len(values) == 0:
        return {"n": 0}
    return {"n": int(len(values)), "p50": float(np.percentile(values, 50)), "p99": float(np.percentile(values, 99)),
            "max": float(values.max()), "mean": float(values.mean())}


def stream_native(callback: str, block: int, seconds: float, gil_threads: int) -> dict:
    from tpad_rt.device import Device
    from tpad_rt.engine import Renderer
    from tpad_rt.kernel import callback as cb
    from tpad_rt.kernel import table_layout as tab  # the layout only: no numba
    from tpad_rt.outputs import audio
    from tpad_rt.pipeline import Pipeline
    from tpad_rt.realtime import CallbackTable, monotonic_ns
    from tpad_rt.texture import load_compiled

    renderer = stream = None
    pushes: list[tuple[int, int]] = []
    if callback == "tpad":
        renderer = Renderer(output=f"audio://?rate={RATE_HZ}&block={block}", texture=GRATING)
        renderer.start()
        table = renderer.callback_table
        clock = renderer.stream_time_s
        counts = table.arrays.finger_count

        def push(x_mm: float) -> None:
            index = int(counts[0])
            pushed_ns = monotonic_ns()
            renderer.push_finger(x_mm, 20.0, 0.5)
            pushes.append((pushed_ns, index))
    else:
        pipeline = Pipeline(Device.default(), load_compiled(GRATING), RATE_HZ)
        target = audio.find_output_device(None)
        table = CallbackTable(pipeline.arrays, pipeline.texture, channels=target.channels)
        stream = audio.AudioStream(target, RATE_HZ, block, target.channels, cb.silence_callback.address,
                                   table.user_data)
        stream.start()
        clock = stream.time_s

        def push(x_mm: float) -> None:  # the same application work; the silent callback ignores it
            pipeline.push_finger(pipeline.time_s, x_mm, 20.0, 0.5)

    time.sleep(0.2)  # past the start
    _gil_hogs(gil_threads)
    ring = RecordRing(table)
    begin_s, begin, begin_wall_s = clock(), table.stats.copy(), time.monotonic()
    _app_loop(seconds, push, ring.poll)
    end_s, end, end_wall_s = clock(), table.stats.copy(), time.monotonic()
    rows = ring.rows()
    result = {
        "callbacks": int(end[tab.STAT_CALLBACKS] - begin[tab.STAT_CALLBACKS]),
        "underflows": int(end[tab.STAT_UNDERFLOWS] - begin[tab.STAT_UNDERFLOWS]),
        "expected": (end_s - begin_s) * RATE_HZ / block, "due_wall": (end_wall_s - begin_wall_s) * RATE_HZ / block,
        "records": int(len(rows)), "records_lost": ring.lost,
        "compute_us": _percentiles(rows[:, tab.BLOCK_COMPUTE_NS], 1e-3),
        "dac_delay_ms": _percentiles(rows[:, tab.BLOCK_DAC_DELAY_NS], 1e-6),
    }
    if renderer is not None:
        result.update(_latency(rows, pushes, cb))
        result["output_latency_s"] = renderer.driver.stream.output_latency_s  # PortAudio's, read while it runs
        renderer.stop()
        stats = renderer.stats()
        result["renderer_stats"] = {key: stats[key] for key in (
            "latency_ms_p50", "latency_ms_p99", "compute_us_p50", "compute_us_p99", "compute_us_max", "underflows",
            "callbacks")}
    else:
        result["output_latency_s"] = stream.output_latency_s
        stream.stop()
        stream.close()
    return result


def read_by(rows, pushes: list[tuple[int, int]]):
    """For each push ``(time ns, sample index)`` whose reading block was recorded: ``(push time ns, that
    block's entry time ns, its DAC delay ns)``, arrays. The reading block is the first whose start saw the
    sample (its BLOCK_FINGER_COUNT passes the index); the first record is left out (it may have been read
    earlier)."""
    import numpy as np

    from tpad_rt.kernel import table_layout as tab  # the layout only: no numba
    pushed_ns, index = np.array(pushes, dtype=np.int64).reshape(-1, 2).T
    counts = rows[:, tab.BLOCK_FINGER_COUNT]
    first = np.searchsorted(counts, index, side="right")
    kept = (first > 0) & (first < len(rows))
    first = first[kept]
    return pushed_ns[kept], rows[first, tab.BLOCK_ENTRY_NS], rows[first, tab.BLOCK_DAC_DELAY_NS]


def _latency(rows, pushes: list[tuple[int, int]], cb) -> dict:
    """Each push's latency to the DAC time of the first block that read it, and its two parts."""
    if not pushes or len(rows) < 2:
        return {"latency_ms": {"n": 0}}
    pushed_ns, entry_ns, dac_ns = read_by(rows, pushes)
    return {
        "latency_ms": _percentiles(entry_ns + dac_ns - pushed_ns, 1e-6),
        "wait_ms": _percentiles(entry_ns - pushed_ns, 1e-6),
        "read_dac_delay_ms": _percentiles(dac_ns, 1e-6),
    }


def stream_python(block: int, seconds: float, gil_threads: int) -> None:
    """The control: a sounddevice Python callback running Pipeline.render; exits without closing."""
    import numpy as np
    import sounddevice

    from tpad_rt.device import Device
    from tpad_rt.pipeline import Pipeline
    from tpad_rt.texture import load_compiled

    pipeline = Pipeline(Device.default(), load_compiled(GRATING), RATE_HZ)
    pipeline.warm_up()
    pipeline.start()
    scratch = np.zeros(block, dtype=np.float32)
    counts = [0, 0]
    compute_ns = np.zeros(PY_RECORDS, dtype=np.int64)

    def render(outdata: np.ndarray, frames: int, time_info: object, status: sounddevice.CallbackFlags) -> None:
        entry = time.perf_counter_ns()
        outdata.fill(0.0)
        if frames == block:
            pipeline.render(scratch)
            outdata[:, 0] = scratch
        compute_ns[counts[0] % PY_RECORDS] = time.perf_counter_ns() - entry
        counts[1] += bool(status.output_underflow)
        counts[0] += 1

    stream = sounddevice.OutputStream(samplerate=RATE_HZ, blocksize=block, channels=1, dtype="float32",
                                      latency="low", callback=render)
    stream.start()
    time.sleep(0.2)
    _gil_hogs(gil_threads)
    begin_s, begin, begin_wall_s = stream.time, list(counts), time.monotonic()

    def push(x_mm: float) -> None:
        pipeline.push_finger(pipeline.time_s, x_mm, 20.0, 0.5)

    _app_loop(seconds, push, lambda: None)
    end_s, end, end_wall_s = stream.time, list(counts), time.monotonic()
    kept = compute_ns[begin[0]:min(end[0], PY_RECORDS)]
    _result({
        "callbacks": end[0] - begin[0], "underflows": end[1] - begin[1],
        "expected": (end_s - begin_s) * RATE_HZ / block, "due_wall": (end_wall_s - begin_wall_s) * RATE_HZ / block,
        "records": int(len(kept)), "records_lost": 0,
        "compute_us": _percentiles(kept, 1e-3), "output_latency_s": float(stream.latency),
    })
    sys.stdout.flush()
    os._exit(0)


def startup(block: int) -> dict:
    from time import monotonic_ns
    begin_ns = monotonic_ns()
    from tpad_rt.engine import Renderer
    from tpad_rt.kernel import table_layout as tab  # the layout only: no numba
    imported_ns = monotonic_ns()
    renderer = Renderer(output=f"audio://?rate={RATE_HZ}&block={block}", texture=GRATING)
    built_ns = monotonic_ns()
    renderer.start()
    started_ns = monotonic_ns()
    table = renderer.callback_table
    deadline = time.monotonic() + 10
    while table.stats[tab.STAT_CALLBACKS] == 0 and time.monotonic() < deadline:
        time.sleep(0.0001)
    first = table.blocks[0].copy()
    renderer.stop()
    return {"process_begin_ns": begin_ns, "imported_ns": imported_ns, "built_ns": built_ns,
            "started_ns": started_ns, "first_entry_ns": int(first[tab.BLOCK_ENTRY_NS]),
            "first_dac_ns": int(first[tab.BLOCK_ENTRY_NS] + first[tab.BLOCK_DAC_DELAY_NS])}


def startup_play(block: int) -> dict:
    """``tpad-rt play textures/grating.yaml --output audio://...`` run through ``tpad_rt.cli.main`` (the
    console script's function), its first sample read from the Renderer's block records: ``Renderer.start``
    is wrapped to note the first block once it arrives (after the stream started: it moves nothing)."""
    from time import monotonic_ns
    begin_ns = monotonic_ns()
    from tpad_rt import cli, compiling
    from tpad_rt.engine import Renderer
    from tpad_rt.kernel import table_layout as tab  # the layout only: no numba
    imported_ns = monotonic_ns()
    original = Renderer.start
    noted: dict = {}
    compile_plan = compiling._compile_plan

    def compile_first(jobs: int, console: Any) -> Any:  # the compile notice's first line is printed (first run only)
        noted.setdefault("notice_ns", monotonic_ns())
        return compile_plan(jobs, console)

    compiling._compile_plan = compile_first  # type: ignore[assignment]

    def start(self: Renderer) -> None:
        original(self)
        noted["started_ns"] = monotonic_ns()
        table = self.callback_table
        deadline = time.monotonic() + 10
        while table.stats[tab.STAT_CALLBACKS] == 0 and time.monotonic() < deadline:
            time.sleep(0.0001)
        first = table.blocks[0].copy()
        noted["first_entry_ns"] = int(first[tab.BLOCK_ENTRY_NS])
        noted["first_dac_ns"] = int(first[tab.BLOCK_ENTRY_NS] + first[tab.BLOCK_DAC_DELAY_NS])

    Renderer.start = start  # type: ignore[method-assign]
    status = cli.main(["play", str(GRATING), "--output", f"audio://?rate={RATE_HZ}&block={block}",
                       "--duration", "0.3"])
    if status != 0 or "first_dac_ns" not in noted:
        raise SystemExit(f"tpad-rt play exited with {status} before a first sample")
    return {"process_begin_ns": begin_ns, "imported_ns": imported_ns, **noted}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("mode", choices=("stream", "startup", "play"))
    parser.add_argument("callback", nargs="?", choices=("silence", "tpad", "python"))
    parser.add_argument("--block", type=int, default=64)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--gil-threads", type=int, default=0)
    args = parser.parse_args(argv)
    if args.mode == "startup":
        _result(startup(args.block))
    elif args.mode == "play":
        _result(startup_play(args.block))
    elif args.callback == "python":
        stream_python(args.block, args.seconds, args.gil_threads)
    else:
        _result(stream_native(args.callback, args.block, args.seconds, args.gil_threads))
    return 0


if __name__ == "__main__":
    sys.exit(main())
