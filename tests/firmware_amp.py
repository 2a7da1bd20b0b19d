"""The host build of the firmware as a test component: ``firmware/build/host/tpad-amp`` in its own process.

``HostAmp(folder, *flags)`` builds it if needed (tests/firmware_build.py), starts it with
``--device`` (the shipped default device unless the flags name one) and ``--record
FOLDER/amp.csv``, and reads its first line for the port; ``.finish()`` ends it with SIGTERM
(by PID), checks it exited 0 and returns its recording (a numpy structured array, the
columns of ``tpad-amp --help``) and its counters (``.counters``). Used as a context manager
it is killed on the way out whatever happened.
"""

from __future__ import annotations

import signal
from pathlib import Path

import numpy as np

from amp_process import COUNTERS, AmplifierProcess, parse_counters
from firmware_build import build
from tpad_rt.shipped import DEVICES_DIR

DEFAULT_DEVICE = DEVICES_DIR / "default.yaml"


def tpad_amp() -> Path:
    """The host build's binary, built now if missing or stale."""
    return build("host")


def read_recording(path: Path) -> np.ndarray:
    """A --record CSV as a structured array (one row per applied sample or watchdog trip)."""
    recording: np.ndarray = np.genfromtxt(path, delimiter=",", names=True, ndmin=1)
    return recording


class HostAmp(AmplifierProcess):
    """``tpad-amp --device DEFAULT --record FOLDER/amp.csv FLAGS``; ``.port`` is the pty to give the host."""

    def __init__(self, folder: Path, *flags: str):
        folder.mkdir(parents=True, exist_ok=True)
        self.record = folder / "amp.csv"
        device = () if "--device" in flags else ("--device", str(DEFAULT_DEVICE))
        super().__init__([str(tpad_amp()), *device, "--record", str(self.record), *flags], "amplifier on ",
                         "tpad-amp")
        self.summary = ""
        self.counters: dict[str, int] = {}

    def finish(self, sig: int | None = signal.SIGTERM) -> np.ndarray:
        """End it with ``sig`` (None: wait for it to end by itself), check it exited 0 with one summary line, which
        holds every counter; its recording."""
        out = self.end(sig)
        assert out.count("\n") == 1, out
        self.summary = out
        self.counters = parse_counters(out)
        assert tuple(self.counters) == COUNTERS, out
        return read_recording(self.record)
