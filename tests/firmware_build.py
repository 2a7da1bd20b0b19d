"""Builds of ``firmware/`` for the tests: ``make -C firmware TARGET``, once per session, under a lock.

``build(target)`` runs make for ``target`` the first time this process asks (later calls
return at once) while holding an fcntl lock on ``firmware/build/.lock``, so that the two
pytest-xdist workers never run make in the same tree at once (the second one finds the
work done: make is a no-op then). It returns the artefact's path. ``make_target(target)``
runs make under the same lock every time and returns the finished process, for targets
whose output is the point (``test``, ``coverage``). Without make or a compiler the test
skips, or fails under ``TPAD_RT_REQUIRE_SYSTEM=1`` (conftest.require_program), naming the
missing program; a failed build fails the test with make's last lines.
"""

from __future__ import annotations

import fcntl
import subprocess
from pathlib import Path

import pytest

from conftest import REPO_ROOT, require_program, require_system

FIRMWARE = REPO_ROOT / "firmware"
BUILD = FIRMWARE / "build"
#: What each target makes (relative to firmware/); targets not listed make nothing to return.
ARTEFACTS = {
    "host": "build/host/tpad-amp",
    "lib": "build/host/libtpadamp.so",
    "microbit": "build/microbit/tpad-amp.elf",
    "nucleo-g474re": "build/nucleo-g474re/tpad-amp.elf",
}
#: The programs each target needs besides make (the host's C compiler for the core's own targets).
_PROGRAMS = {
    "microbit": ("arm-none-eabi-gcc",),
    "nucleo-g474re": ("arm-none-eabi-gcc",),
    "coverage": ("gcc", "gcov"),
}
#: Longest a build may take (s): the whole firmware builds in a few seconds.
MAKE_TIMEOUT_S = 300
#: Lines of make's output a failed build shows.
_FAILED_LINES = 30

_built: dict[str, Path] = {}


def _arm_libc_present() -> bool:
    """True when the ARM compiler finds its C library (libnewlib-arm-none-eabi, only a recommendation of
    gcc-arm-none-eabi): -print-file-name answers the bare name when it does not."""
    done = subprocess.run(["arm-none-eabi-gcc", "-print-file-name=libc.a"], capture_output=True, text=True,
                          check=False)
    path = Path(done.stdout.strip())
    return done.returncode == 0 and path.is_absolute() and path.is_file()


def make_target(target: str) -> subprocess.CompletedProcess[str]:
    """Run ``make -C firmware target`` under the lock; the finished process (stdout and stderr merged)."""
    require_program("make")
    for program in _PROGRAMS.get(target, ("gcc",)):
        require_program(program)
        if program == "arm-none-eabi-gcc":
            require_system(_arm_libc_present(), "the ARM C library (libnewlib-arm-none-eabi)")
    BUILD.mkdir(parents=True, exist_ok=True)
    with open(BUILD / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return subprocess.run(["make", "-C", str(FIRMWARE), target], stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, timeout=MAKE_TIMEOUT_S, check=False)


def build(target: str) -> Path:
    """The artefact of ``target`` (ARTEFACTS), built by make once in this process; fails the test if make fails."""
    if target not in _built:
        done = make_target(target)
        if done.returncode != 0:
            tail = "\n".join(done.stdout.splitlines()[-_FAILED_LINES:])
            pytest.fail(f"make -C firmware {target} failed (exit {done.returncode}):\n{tail}")
        artefact = FIRMWARE / ARTEFACTS[target] if target in ARTEFACTS else FIRMWARE
        if not artefact.exists():
            pytest.fail(f"make -C firmware {target} made no {artefact.relative_to(REPO_ROOT)}")
        _built[target] = artefact
    return _built[target]
