"""The host build of the firmware as a test component: ``firmware/build/host/tpad-amp`` in its own process.

``HostAmp(folder, *flags)`` builds it if needed (tests/firmware_build.py), starts it with
``--device`` (the shipped default device unless the flags name one) and ``--record
FOLDER/amp.csv``, and reads its first line for the port; ``.finish()`` ends it with SIGTERM
(by PID), checks it exited 0 and returns its recording (a numpy structured array, the
columns of ``tpad-amp --help``) and its counters (``.counters``). Used as a context manager
it is killed on the way out whatever happened.
"""

from __future__ import annotations

import re
import signal
from pathlib import Path
from types import TracebackType

import numpy as np

from amp_process import start_amplifier
from firmware_build import build
from tpad_rt.shipped import DEVICES_DIR

#: Seconds the firmware may take to start or to end (it starts in milliseconds; a safety net).
START_TIMEOUT_S = 60.0
#: The summary's counters, in order (as amp emulate's).
COUNTERS = ("frames_ok", "frames_bad", "frames_rejected", "sequence_gaps", "underruns", "watchdog_trips", "faults")
DEFAULT_DEVICE = DEVICES_DIR / "default.yaml"


def tpad_amp() -> Path:
    """The host build's binary, built now if missing or stale."""
    return build("host")


def read_recording(path: Path) -> np.ndarray:
    """A --record CSV as a structured array (one row per applied sample or watchdog trip)."""
    recording: np.ndarray = np.genfromtxt(path, delimiter=",", names=True, ndmin=1)
    return recording


def parse_counters(summary: str) -> dict[str, int]:
    """The ``name=value`` pairs of the summary line, which must hold every counter."""
    pairs = dict(re.findall(r"(\w+)=(\d+)", summary))
    assert tuple(pairs) == COUNTERS, summary
    return {name: int(value) for name, value in pairs.items()}


class HostAmp:
    """``tpad-amp --device DEFAULT --record FOLDER/amp.csv FLAGS``; ``.port`` is the pty to give the host."""

    def __init__(self, folder: Path, *flags: str):
        folder.mkdir(parents=True, exist_ok=True)
        self.record = folder / "amp.csv"
        device = () if "--device" in flags else ("--device", str(DEFAULT_DEVICE))
        self.process, self.port = start_amplifier([str(tpad_amp()), *device, "--record", str(self.record), *flags],
                                                  "amplifier on ", "tpad-amp")
        self.summary = ""
        self.stderr = ""
        self.counters: dict[str, int] = {}

    def finish(self, sig: int | None = signal.SIGTERM) -> np.ndarray:
        """End it with ``sig`` (None: wait for it to end by itself), check it exited 0 with one summary line; its
        recording."""
        if sig is not None and self.process.poll() is None:
            self.process.send_signal(sig)
        out, self.stderr = self.process.communicate(timeout=START_TIMEOUT_S)
        assert self.process.returncode == 0, (self.process.returncode, self.stderr)
        assert out.count("\n") == 1, out
        self.summary = out
        self.counters = parse_counters(out)
        return read_recording(self.record)

    def __enter__(self) -> HostAmp:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.communicate(timeout=START_TIMEOUT_S)
