"""Where numba caches tpad-rt's kernels, whether the whole compile plan is in it, and a clean-up after a stop.

API map
-------
COMPILED_PACKAGES
    the packages whose numba functions the compile plan compiles (``kernel``, ``physics``)
cache_dir(package_dir) -> Path
    the folder numba caches ``package_dir``'s functions in, found as numba finds it without importing numba:
    ``NUMBA_CACHE_DIR`` when set, else the package's writable ``__pycache__``, else the user-wide cache
plan_stamp() -> str
    the SHA-256 of everything a compiled kernel depends on: the sources of :data:`COMPILED_PACKAGES` and
    the compile plan, numba's and Python's versions and the machine
package_version(name) -> bytes
    the installed version of package ``name`` (numba's and llvmlite's ``_version.py``), read without importing
    it or scanning every installed distribution; shared with the ahead-of-time library's stamp
plan_complete() -> bool
    whether a whole compile plan finished for :func:`plan_stamp` (its mark is in the kernels' cache folder,
    so clearing the cache clears it)
marked_before() -> bool
    whether a plan finished before for other sources (its mark is still there)
mark_plan_complete()
    write that mark (atomically), after the whole plan finished
compile_lock(on_wait) -> context manager
    an exclusive lock on the kernels' cache folder, across processes, held while a plan compiles
discard_unfinished(since_ns) -> int
    after compile workers were killed: remove what a later run could trust though it was half written since
    ``since_ns`` (``time.time_ns()``); returns how many files it removed
discard_functions(names)
    remove the cache index of each function named ``module.qualname`` (``tpad_rt.kernel.render.render_block``)

numba writes a new cache entry's index before its data file, each by an atomic rename: a worker killed
between the two leaves an index naming a data file that is missing (numba recompiles) or, after a source
changed, one left from the old source (numba would load it). :func:`discard_unfinished` removes the index of
every function whose index changed after ``since_ns`` and whose newest data file is older than that index,
and the temporary files of writes cut short.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import importlib.metadata
import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
COMPILED_PACKAGES = (PACKAGE_DIR / "kernel", PACKAGE_DIR / "physics")
_PLAN_SOURCE = PACKAGE_DIR / "compile_plan.py"
_MARK = "tpad-rt-plan.{stamp}.done"
_LOCK = "tpad-rt-compile.lock"


def _subpath(package_dir: Path) -> str:
    """numba's folder name for a source folder inside a shared cache (``_CacheLocator.get_suitable_cache_subpath``)."""
    return f"{package_dir.name}_{hashlib.sha1(str(package_dir).encode()).hexdigest()}"


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def cache_dir(package_dir: Path) -> Path:
    """The folder numba caches the functions of the sources in ``package_dir`` in (module docstring)."""
    custom = os.environ.get("NUMBA_CACHE_DIR", "")
    if custom:
        return Path(custom) / _subpath(package_dir)
    in_tree = package_dir / "__pycache__"
    if _writable(in_tree):
        return in_tree
    user = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return user / "numba" / _subpath(package_dir)


def plan_stamp() -> str:
    """The SHA-256 (hex) of what the compiled kernels depend on (module docstring)."""
    digest = hashlib.sha256()
    for source in sorted([*(path for folder in COMPILED_PACKAGES for path in folder.glob("*.py")), _PLAN_SOURCE]):
        digest.update(source.name.encode() + b"\0" + source.read_bytes())
    for version in (package_version("numba"), sys.version.encode(), os.uname().machine.encode()):
        digest.update(version + b"\0")
    return digest.hexdigest()


def package_version(name: str) -> bytes:
    """The installed version of package ``name`` without importing it (nor asking the import system for it): the
    ``_version.py`` (numba's and llvmlite's name the release and the revision) of the first ``name`` folder on
    ``sys.path``, without the slow scan of every installed distribution that ``importlib.metadata`` makes; the
    distribution's version where there is no such file."""
    for entry in sys.path:
        try:
            return (Path(entry or ".") / name / "_version.py").read_bytes()
        except OSError:
            continue
    return importlib.metadata.version(name).encode()


def _mark() -> Path:
    return cache_dir(COMPILED_PACKAGES[0]) / _MARK.format(stamp=plan_stamp()[:16])


def plan_complete() -> bool:
    """Whether the whole compile plan finished for these sources (module docstring)."""
    return _mark().is_file()


def marked_before() -> bool:
    """Whether the cache folder has the mark of a plan that finished for other sources."""
    mark = _mark()
    return any(old != mark for old in mark.parent.glob(_MARK.format(stamp="*")))


def mark_plan_complete() -> None:
    """Record that the whole compile plan finished for these sources; marks for other sources go."""
    mark = _mark()
    for old in mark.parent.glob(_MARK.format(stamp="*")):
        old.unlink(missing_ok=True)
    partial = mark.with_suffix(".tmp")
    partial.write_text("every step of tpad_rt.compile_plan finished for these sources\n")
    os.replace(partial, mark)


@contextlib.contextmanager
def compile_lock(on_wait: Callable[[], None]) -> Iterator[None]:
    """Hold the kernels' compile lock (exclusive, across processes) in the block; ``on_wait()`` first when
    another process holds it (this one then waits for it)."""
    folder = cache_dir(COMPILED_PACKAGES[0])
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / _LOCK, "a") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            on_wait()
            fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _function_files(folder: Path) -> dict[str, tuple[Path, list[Path]]]:
    """numba's cache files in ``folder`` by function: ``{base: (index, data files)}`` (``base.nbi``,
    ``base.N.nbc``)."""
    functions: dict[str, tuple[Path, list[Path]]] = {}
    for index in folder.glob("*.nbi"):
        base = index.name[:-len(".nbi")]
        functions[base] = (index, [data for data in folder.glob(f"{_glob_escape(base)}.*.nbc")])
    return functions


def _glob_escape(text: str) -> str:
    """``text`` with glob's special characters matched literally."""
    return "".join(f"[{char}]" if char in "*?[" else char for char in text)


def discard_unfinished(since_ns: int) -> int:
    """Remove the cache files a killed write may have left untrustworthy since ``since_ns`` (module docstring)."""
    removed = 0
    for folder in {cache_dir(package) for package in COMPILED_PACKAGES}:
        if not folder.is_dir():
            continue
        for partial in folder.glob("*.tmp.*"):
            partial.unlink(missing_ok=True)
            removed += 1
        for index, data in _function_files(folder).values():
            written_ns = index.stat().st_mtime_ns
            if written_ns >= since_ns and max((file.stat().st_mtime_ns for file in data), default=0) < written_ns:
                index.unlink(missing_ok=True)
                removed += 1
    return removed


def discard_functions(names: set[str]) -> None:
    """Remove the cache index of each function named ``tpad_rt.PACKAGE.MODULE.QUALNAME`` in the compiled
    packages: numba compiles them again."""
    for folder in COMPILED_PACKAGES:
        prefix = f"tpad_rt.{folder.name}."
        for name in names:
            if name.startswith(prefix):
                module, qualname = name[len(prefix):].split(".", 1)
                for index in cache_dir(folder).glob(f"{_glob_escape(module)}.{_glob_escape(qualname)}-*.nbi"):
                    index.unlink(missing_ok=True)
