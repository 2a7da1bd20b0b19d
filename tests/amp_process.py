"""Starting an amplifier process (``tpad-rt amp emulate``, ``tpad-amp``, ``firmware/run-qemu``) that names its pty
on its first line, for the tests that talk to it."""

from __future__ import annotations

import select
import subprocess
from pathlib import Path

from conftest import REPO_ROOT

#: How long (s) an amplifier may take to name its pty (the emulator imports numpy and compiles on a cold cache).
START_TIMEOUT_S = 120.0


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
