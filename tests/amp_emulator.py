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
from types import TracebackType

import numpy as np
from amp_process import START_TIMEOUT_S, start_amplifier

REPO = Path(__file__).resolve().parents[1]


class Emulator:
    """``tpad-rt amp emulate --record DIR/amp.npz FLAGS``; ``.port`` is the pty to give the host."""

    def __init__(self, folder: Path, *flags: str):
        folder.mkdir(parents=True, exist_ok=True)
        self.record = folder / "amp.npz"
        self.process, self.port = start_amplifier(
            [sys.executable, "-m", "tpad_rt", "amp", "emulate", "--record", str(self.record), *flags],
            "amplifier emulator on ", "the emulator", cwd=REPO)
        self.summary = ""

    def finish(self, sig: int | None = signal.SIGTERM) -> dict[str, np.ndarray]:
        """End it with ``sig`` (None: wait for it to end by itself), check it exited 0, return its recording."""
        if sig is not None and self.process.poll() is None:
            self.process.send_signal(sig)
        out, err = self.process.communicate(timeout=START_TIMEOUT_S)
        assert self.process.returncode == 0, (self.process.returncode, err)
        self.summary = out
        with np.load(self.record) as recording:
            return {name: recording[name] for name in recording.files}

    def __enter__(self) -> Emulator:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.communicate(timeout=START_TIMEOUT_S)
