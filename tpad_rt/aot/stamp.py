"""The stamp of an ahead-of-time library and where it lives; imports neither numba nor llvmlite.

API map
-------
SOURCES
    the files whose code goes into the library (every kernel source, the friction model,
    the builder): a change to one makes a new stamp
library_stamp() -> str
    SHA-256 (hex) of those sources, the numba and llvmlite versions, numba's code
    generation settings (NUMBA_OPT, NUMBA_CPU_NAME, NUMBA_CPU_FEATURES), the platform and
    the CPU (its /proc/cpuinfo identity: model and instruction-set flags)
library_dirs() -> list[Path]
    the folders a library may live in, in the order they are searched (and tried for writing),
    beside numba's cache: ``$NUMBA_CACHE_DIR/tpad_rt_aot`` alone when that is set (numba then
    caches only there), else ``tpad_rt/kernel/__pycache__`` (numba's in-tree cache) and the user
    cache ``$XDG_CACHE_HOME/tpad-rt/aot`` (default ``~/.cache``) when that is read-only
library_name(stamp) -> str
    the library's file name for a stamp

The library's machine code is specialised for the CPU it was built on (as numba's JIT is),
so the CPU is part of the stamp: a library never loads on another CPU model or after a
source, numba or llvmlite change.
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
from importlib import metadata
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parents[1]
#: The sources compiled into the library (tests/test_aot.py checks these cover the callbacks' cache stamp).
SOURCES: tuple[Path, ...] = (*sorted((_PACKAGE / "kernel").glob("*.py")), _PACKAGE / "physics" / "friction.py",
                             _PACKAGE / "aot" / "build.py")
#: numba settings that change the code it generates.
_CODEGEN_SETTINGS = ("NUMBA_OPT", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")
#: /proc/cpuinfo keys that identify a CPU model and its instruction sets (x86-64, then aarch64).
_CPU_KEYS = ("vendor_id", "cpu family", "model", "model name", "flags",
             "CPU implementer", "CPU architecture", "CPU variant", "CPU part", "Features")


def library_stamp() -> str:
    """The stamp (SHA-256 hex) the library built from the current sources for this machine carries."""
    digest = hashlib.sha256()
    for source in SOURCES:
        digest.update(source.name.encode() + b"\0" + hashlib.sha256(source.read_bytes()).digest())
    for name in ("numba", "llvmlite"):
        digest.update(f"{name}={metadata.version(name)}\0".encode())
    for setting in _CODEGEN_SETTINGS:
        digest.update(f"{setting}={os.environ.get(setting, '')}\0".encode())
    digest.update(f"{platform.system()} {platform.machine()}\0{_cpu_identity()}".encode())
    return digest.hexdigest()


@functools.cache
def _cpu_identity() -> str:
    """The first processor's identifying lines of /proc/cpuinfo (``platform.processor()`` without one)."""
    try:
        text = Path("/proc/cpuinfo").read_text(errors="replace")
    except OSError:
        return platform.processor()
    lines = []
    for line in text.splitlines():
        if not line.strip():
            break  # the first processor only
        key, _, value = line.partition(":")
        if key.strip() in _CPU_KEYS:
            lines.append(f"{key.strip()}={value.strip()}")
    return "\n".join(lines)


def library_dirs() -> list[Path]:
    """The folders an ahead-of-time library is looked for in, first match wins (module docstring)."""
    numba_cache = os.environ.get("NUMBA_CACHE_DIR")
    if numba_cache:
        return [Path(numba_cache) / "tpad_rt_aot"]
    user_cache = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return [_PACKAGE / "kernel" / "__pycache__", Path(user_cache) / "tpad-rt" / "aot"]


def library_name(stamp: str) -> str:
    """The file name of the library with ``stamp``."""
    return f"tpad_rt_aot-{stamp[:32]}.so"
