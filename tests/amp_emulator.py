"""The amplifier emulator as a test component: ``tpad-rt amp emulate`` in its own process, on a new pty.

``Emulator(folder, *flags)`` starts it (recording into ``folder``, made if missing),
reads its first line for the port, and ``.finish()`` ends it with SIGTERM (by PID) and
returns its recording (a dict of arrays). Used as a context manager it is killed on the
way out whatever happened.
"""

from __future__ import annotations

import signal
import sys
from pathlib import Path

import numpy as np
from amp_process import AmplifierProcess

REPO = Path(__file__).resolve().parents[1]


class Emulator(AmplifierProcess):
    """``tpad-rt amp emulate --record DIR/amp.npz FLAGS``; ``.port`` is the pty to give the host."""

    def __init__(self, folder: Path, *flags: str):
        folder.mkdir(parents=True, exist_ok=True)
        self.record = folder / "amp.npz"
        super().__init__([sys.executable, "-m", "tpad_rt", "amp", "emulate", "--record", str(self.record), *flags],
                         "amplifier emulator on ", "the emulator", cwd=REPO)
        self.summary = ""

    def finish(self, sig: int | None = signal.SIGTERM) -> dict[str, np.ndarray]:
        """End it with ``sig`` (None: wait for it to end by itself), check it exited 0, return its recording."""
        self.summary = self.end(sig)
        with np.load(self.record) as recording:
            return {name: recording[name] for name in recording.files}
