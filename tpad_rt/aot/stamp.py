"""The stamp of an ahead-of-time library and where it lives; imports neither numba nor llvmlite.

API map
-------
SOURCES
    the files whose code goes into the library (every kernel source, the friction model,
    the builder): a change to one makes a new stamp
library_stamp() -> str
    SHA-256 (hex) of those sources, the numba and llvmlite versions, numba's code
    generation settings (CODEGEN_SETTINGS), the platform and the CPU (its /proc/cpuinfo
    identity: vendor, family, model, and the instruction sets a compiler may use:
    ISA_FLAGS of the x86 flags, every aarch64 feature)
cpu_identity(cpuinfo) -> str
    the lines of /proc/cpuinfo's text that go into the stamp
library_dirs() -> list[Path]
    the folders a library may live in, in the order they are searched (and tried for writing),
    beside numba's cache: ``$NUMBA_CACHE_DIR/tpad_rt_aot`` alone when that is set (numba then
    caches only there), else ``tpad_rt/kernel/__pycache__`` (numba's in-tree cache) and the user
    cache ``$XDG_CACHE_HOME/tpad-rt/aot`` (default ``~/.cache``) when that is read-only
library_name(stamp) -> str
    the library's file name for a stamp

The library's machine code is specialised for the CPU it was built on (as numba's JIT is),
so the CPU is part of the stamp: a library never loads on another CPU model or after a
source, numba or llvmlite change. The x86 flags that say nothing of the instructions LLVM may
emit (mitigations a microcode or kernel update adds, such as ``md_clear``; TSX, which one may
take away and LLVM never emits unasked; the kernel's own features) are left out, so such an
update keeps the library.
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
from pathlib import Path

from tpad_rt.kernel_cache import package_version

_PACKAGE = Path(__file__).resolve().parents[1]
#: The sources compiled into the library (tests/test_aot.py checks these cover the callbacks' cache stamp).
SOURCES: tuple[Path, ...] = (*sorted((_PACKAGE / "kernel").glob("*.py")), _PACKAGE / "physics" / "friction.py",
                             _PACKAGE / "aot" / "build.py")
#: numba settings (environment variables) that change the code it generates.
CODEGEN_SETTINGS = ("NUMBA_OPT", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES", "NUMBA_BOUNDSCHECK", "NUMBA_LOOP_VECTORIZE",
                    "NUMBA_SLP_VECTORIZE", "NUMBA_ENABLE_AVX", "NUMBA_DISABLE_INTEL_SVML")
#: /proc/cpuinfo keys that identify a CPU model (x86-64, then aarch64).
_CPU_KEYS = ("vendor_id", "cpu family", "model", "model name",
             "CPU implementer", "CPU architecture", "CPU variant", "CPU part")
#: /proc/cpuinfo keys listing instruction sets: x86's flags (only ISA_FLAGS of them count), aarch64's features.
_FLAG_KEYS = ("flags", "Features")
#: The x86 flags (Linux's names) of instruction sets LLVM's host detection reports and may emit code for.
ISA_FLAGS = frozenset("""
    lm cx8 cmov mmx fxsr sse sse2 pni pclmulqdq ssse3 fma cx16 sse4_1 sse4_2 movbe popcnt aes xsave avx f16c rdrand
    lahf_lm abm 3dnowprefetch fsgsbase bmi1 avx2 bmi2 invpcid avx512f avx512dq rdseed adx avx512ifma clflushopt
    clwb avx512cd sha_ni avx512bw avx512vl xsaveopt xsavec xsaves avx_vnni avx512_bf16 avx512vbmi avx512_vbmi2
    gfni vaes vpclmulqdq avx512_vnni avx512_bitalg avx512_vpopcntdq rdpid cldemote movdiri movdir64b serialize
    amx_bf16 avx512_fp16 amx_tile amx_int8 sse4a xop fma4 tbm lwp clzero mwaitx wbnoinvd waitpkg
    enqcmd ptwrite avx_ifma avx_vnni_int8 avx_ne_convert cmpccxadd prefetchi user_shstk
""".split())


def library_stamp() -> str:
    """The stamp (SHA-256 hex) the library built from the current sources for this machine carries."""
    digest = hashlib.sha256()
    for source in SOURCES:
        digest.update(source.name.encode() + b"\0" + hashlib.sha256(source.read_bytes()).digest())
    for name in ("numba", "llvmlite"):
        digest.update(f"{name}=".encode() + package_version(name) + b"\0")
    for setting in CODEGEN_SETTINGS:
        digest.update(f"{setting}={os.environ.get(setting, '')}\0".encode())
    system = os.uname()  # platform.system() and .machine() say the same, after about 4 ms the first time
    digest.update(f"{system.sysname} {system.machine}\0{_cpu_identity()}".encode())
    return digest.hexdigest()


@functools.cache
def _cpu_identity() -> str:
    """:func:`cpu_identity` of this machine's /proc/cpuinfo (``platform.processor()`` without one)."""
    try:
        return cpu_identity(Path("/proc/cpuinfo").read_text(errors="replace"))
    except OSError:
        return platform.processor()


def cpu_identity(cpuinfo: str) -> str:
    """The identifying lines of the first processor in ``cpuinfo`` (the text of /proc/cpuinfo): its model, and
    its instruction sets (x86 flags cut to ISA_FLAGS, every aarch64 feature), each list sorted."""
    lines = []
    for line in cpuinfo.splitlines():
        if not line.strip():
            break  # the first processor only
        key, _, value = line.partition(":")
        key = key.strip()
        if key in _CPU_KEYS:
            lines.append(f"{key}={value.strip()}")
        elif key in _FLAG_KEYS:
            flags = set(value.split())
            lines.append(f"{key}={' '.join(sorted(flags & ISA_FLAGS if key == 'flags' else flags))}")
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
