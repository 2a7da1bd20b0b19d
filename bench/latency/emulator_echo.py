"""The baseline of emulator_pty.py: the least a Python amplifier on a pty does, nothing more.

    python bench/latency/emulator_echo.py     # prints "echo on /dev/pts/N", runs until SIGTERM

A plain-Python process on a new pty, at the emulator's SCHED_FIFO priority where allowed,
waiting in ``poll`` as the emulator does: it writes back every byte it reads at once,
and writes a STATUS frame (only ``time_us`` set, on its own microsecond clock) every
5 ms. emulator_pty.py measures it exactly as it measures ``tpad-rt amp emulate``, so
what the emulator adds to the pty's and the scheduler's share is the difference.
"""

from __future__ import annotations

import os
import select
import signal
import sys
import time
import tty
from pathlib import Path
from types import FrameType

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from tpad_rt.amp import wire  # noqa: E402
from tpad_rt.cli.amp import REALTIME_PRIORITY  # noqa: E402

#: STATUS period (ns): the emulator's.
PERIOD_NS = 5_000_000


def main() -> int:
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
    except OSError:
        print("emulator_echo: no SCHED_FIFO here", file=sys.stderr, flush=True)
    stopping: list[int] = []

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stopping.append(signum)

    signal.signal(signal.SIGTERM, on_signal)
    poller = select.poll()
    poller.register(master, select.POLLIN)
    print(f"echo on {os.ttyname(slave)}", flush=True)
    origin_ns = time.monotonic_ns()
    next_ns, seq = origin_ns + PERIOD_NS, 0
    while not stopping:
        if poller.poll(max(0.0, (next_ns - time.monotonic_ns()) / 1e6)):
            try:
                data = os.read(master, 65536)
            except BlockingIOError:
                data = b""
            if data:
                os.write(master, data)
        if time.monotonic_ns() >= next_ns:
            status = wire.Status(((next_ns - origin_ns) // 1000) & 0xFFFFFFFF, *([0] * 16))
            os.write(master, wire.encode(wire.Type.STATUS, seq, status.pack()))
            next_ns, seq = next_ns + PERIOD_NS, seq + 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
