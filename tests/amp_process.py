"""An amplifier process (``tpad-rt amp emulate``, ``tpad-amp``, ``firmware/run-qemu``) that names its pty on its
first line and prints its counters as ``name=value`` pairs when it ends, for the tests that talk to it."""

from __future__ import annotations

import re
import select
import subprocess
from pathlib import Path
from types import TracebackType
from typing import TypeVar

from conftest import REPO_ROOT

#: How long (s) an amplifier may take to name its pty (the emulator imports numpy and compiles on a cold cache)
#: or to end.
START_TIMEOUT_S = 120.0
#: The counters every amplifier prints when it ends (``amp emulate``'s, ``tpad-amp``'s, ``run-qemu``'s).
COUNTERS = ("frames_ok", "frames_bad", "frames_rejected", "sequence_gaps", "underruns", "watchdog_trips", "faults")

_Process = TypeVar("_Process", bound="AmplifierProcess")


def start_amplifier(command: list[str], prefix: str, what: str,
                    cwd: Path = REPO_ROOT) -> tuple[subprocess.Popen[str], str]:
    """Start ``command`` (stdout and stderr piped, text) and read its first line, ``prefix`` then the pty's path;
    ``(process, path)``. AssertionError naming ``what``, with what it printed, when the line does not come
    within START_TIMEOUT_S or is another (the process is killed first)."""
    process = subprocess.Popen(command, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    assert process.stdout is not None
    ready, _, _ = select.select([process.stdout], [], [], START_TIMEOUT_S)
    first = process.stdout.readline() if ready else ""
    if not first.startswith(prefix):
        process.kill()
        _, err = process.communicate(timeout=START_TIMEOUT_S)
        raise AssertionError(f"{what} did not start: {first!r} {err!r}")
    return process, first[len(prefix):].strip()


def parse_counters(line: str) -> dict[str, int]:
    """The ``name=value`` pairs (whole numbers) of an amplifier's counters line, in their order."""
    return {name: int(value) for name, value in re.findall(r"(\w+)=(\d+)", line)}


class AmplifierProcess:
    """An amplifier in its own process, started by :func:`start_amplifier`; ``.port`` is the pty to give the host.
    Used as a context manager it is killed on the way out, whatever happened."""

    def __init__(self, command: list[str], prefix: str, what: str, cwd: Path = REPO_ROOT):
        self.what = what
        self.process, self.port = start_amplifier(command, prefix, what, cwd)
        self.stderr = ""

    def end(self, sig: int | None) -> str:
        """End it with ``sig`` (by PID; None: wait for it to end by itself), check it exited 0; what it printed
        after its first line. AssertionError when it does not end within START_TIMEOUT_S (it is killed)."""
        if sig is not None and self.process.poll() is None:
            self.process.send_signal(sig)
        try:
            out, self.stderr = self.process.communicate(timeout=START_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.communicate()
            raise AssertionError(f"{self.what} did not end") from None
        assert self.process.returncode == 0, (self.what, self.process.returncode, self.stderr)
        return out

    def __enter__(self: _Process) -> _Process:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.communicate(timeout=START_TIMEOUT_S)
