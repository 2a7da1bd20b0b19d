"""Build the ahead-of-time library: the audio callbacks compiled by numba, linked by the system C compiler.

API map
-------
build_library(progress=None, folders=None) -> Path | None
    compile ``render_callback`` and ``silence_callback`` (:mod:`tpad_rt.kernel.callback`; numba
    loads them from its cache when it can), emit each as a position-independent object for
    this CPU, link them with a small C part (the release store, the stamp, the error count
    and stand-ins for numba's Python error reporting) into one shared library that needs
    only libc and libm, seal it (:func:`tpad_rt.aot.library.seal`), check it loads, and move
    it into place atomically and durably (written, synced, renamed, the folder synced) in
    the first writable of ``folders`` (default :func:`tpad_rt.aot.stamp.library_dirs`),
    replacing whatever file had its name. Its path; None when there is no C compiler
    (``$CC``, a program and its flags, else ``cc``, ``gcc`` or ``clang``). ``progress`` is called with a line per
    step. Raises BuildError when this numba cannot build it, the compiler fails, the
    result does not load or no folder is writable.
``python -m tpad_rt.aot.build``
    the same from the command line: prints the library's path (exit 0), or one line on
    stderr when there is no compiler or the build fails (exit 1) or at Ctrl-C (exit 130)

The objects are emitted from the very LLVM module numba's JIT compiles the callbacks from,
with the JIT's CPU, features and optimisation level; only the relocation model differs
(position-independent code). tests/test_aot.py checks output and state are bit-identical.

The callbacks are compiled with ``error_model="numpy"``: a division or remainder by zero
gives a number, not a raise (so a ring of length 0 would be indexed out of bounds:
:class:`tpad_rt.realtime.CallbackTable` refuses one). A raise is still compiled in where numba
checks one itself (an integer power's negative exponent, ``render.py``'s ``keep ** samples``,
whose exponent is never negative). Where the JIT's callback would report a raise as
"unraisable" on stderr, the library's stand-in for ``PyErr_WriteUnraisable`` counts it in
``tpad_rt_aot_errors`` (:meth:`tpad_rt.aot.library.AotLibrary.errors`), and the other stand-ins do
nothing, so the library needs no Python and no numba.

It reaches numba's code library and llvmlite's pass manager through attributes numba does
not publish (``_library``, ``_get_module_for_linking``, ``_get_host_cpu_name``, ``_tm_features``):
a numba or llvmlite without them ends in BuildError, and the JIT stays.
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from tpad_rt.aot.library import (ERRORS_SYMBOL, PUBLISH_SYMBOL, RENDER_SYMBOL, SILENCE_SYMBOL, STAMP_SYMBOL,
                                 LibraryProblem, open_library, seal)
from tpad_rt.aot.stamp import library_dirs, library_name, library_stamp

#: The callbacks compiled in: (attribute of tpad_rt.kernel.callback, exported symbol).
CALLBACKS = (("render_callback", RENDER_SYMBOL), ("silence_callback", SILENCE_SYMBOL))
#: Symbols numba's error path in a cfunc calls (functions: no-ops, but PyErr_WriteUnraisable, which counts) or
#: reads (data: the addresses of Python's exception types, null pointers here).
_ERROR_PATH_FUNCTIONS = ("numba_gil_ensure", "numba_gil_release", "numba_do_raise", "numba_unpickle",
                         "numba_runtime_build_excinfo_struct", "PyErr_Clear",
                         "PyErr_SetNone", "PyErr_SetString", "PyUnicode_FromString", "PyBytes_FromStringAndSize",
                         "Py_DecRef", "NRT_Free", "NRT_MemInfo_call_dtor")
_ERROR_PATH_DATA = ("PyExc_RuntimeError", "PyExc_StopIteration", "PyExc_SystemError")
#: Seconds the C compiler may take.
COMPILER_TIMEOUT_S = 120.0

Progress = Callable[[str], None]


class BuildError(RuntimeError):
    """The library could not be built (the message says why)."""


def find_compiler() -> list[str] | None:
    """The C compiler's command words: ``$CC`` when set (split as a shell would: a program and its flags, as make
    takes it; its program looked up on PATH), else the first of cc, gcc, clang on PATH; None if there is none."""
    given = os.environ.get("CC", "").strip()
    try:
        candidates = [shlex.split(given)] if given else [["cc"], ["gcc"], ["clang"]]
    except ValueError:  # unbalanced quotes: no program to run
        return None
    for program, *flags in candidates:
        found = shutil.which(program)
        if found:
            return [found, *flags]
    return None


def _c_part(stamp: str) -> str:
    """The C source linked with the callbacks: the stamp, the release store, the error count, the error path's
    stand-ins."""
    stubs = "\n".join(f"void *{name}(void) {{ return 0; }}" for name in _ERROR_PATH_FUNCTIONS)
    data = "\n".join(f"void *{name};" for name in _ERROR_PATH_DATA)
    return f"""#include <stdint.h>
const char {STAMP_SYMBOL}[] = "{stamp}";
int64_t {ERRORS_SYMBOL};
void {PUBLISH_SYMBOL}(int64_t *array, int64_t index, int64_t value) {{
    __atomic_store_n(&array[index], value, __ATOMIC_RELEASE);
}}
/* numba's Python error reporting, reached only on a raise: each raise counted, nothing else done */
void PyErr_WriteUnraisable(void *object) {{
    (void)object;
    __atomic_fetch_add(&{ERRORS_SYMBOL}, 1, __ATOMIC_RELAXED);
}}
{stubs}
{data}
"""


def _version_script() -> str:
    """The linker's version script: the library exports its five symbols, nothing else."""
    exported = "; ".join((RENDER_SYMBOL, SILENCE_SYMBOL, PUBLISH_SYMBOL, STAMP_SYMBOL, ERRORS_SYMBOL))
    return f"{{ global: {exported}; local: *; }};\n"


def _callback_objects(folder: Path, progress: Progress) -> list[Path]:
    """Emit each callback, compiled by numba, as a position-independent object in ``folder``; BuildError when
    this numba or llvmlite lacks what the emission reaches (module docstring)."""
    import llvmlite
    import numba

    from tpad_rt.kernel import callback

    objects = []
    for name, symbol in CALLBACKS:
        progress(f"compiling {name} (numba; from its cache when it has it)")
        path = folder / f"{symbol}.o"
        try:
            path.write_bytes(_emit_object(getattr(callback, name), symbol))
        except (AttributeError, TypeError, NameError, RuntimeError) as error:
            raise BuildError(f"aot: numba {numba.__version__} with llvmlite {llvmlite.__version__} cannot build it "
                             f"({type(error).__name__}: {error}); the JIT stays") from error
        objects.append(path)
    return objects


def _emit_object(cfunc: Any, symbol: str) -> bytes:
    """The object code of numba ``cfunc``, exported as ``symbol``: position-independent, for the JIT's CPU."""
    import llvmlite.binding as ll
    from numba.core import config

    library = cfunc._library  # numba has no public way to reach a cfunc's code library
    module = library._get_module_for_linking().clone()  # what the JIT compiled, exports linkonce_odr
    entry = module.get_function(cfunc.native_name)
    entry.linkage = "external"
    entry.name = symbol
    codegen = library.codegen
    machine = ll.Target.from_triple(ll.get_process_triple()).create_target_machine(
        cpu=codegen._get_host_cpu_name(), features=codegen._tm_features,
        opt=config.OPT,  # type: ignore[attr-defined]  # read from the environment; not in its stubs
        reloc="pic", codemodel="default")
    passes = ll.create_new_module_pass_manager()
    passes.add_global_dead_code_eliminate_pass()  # drops the unused linkonce_odr helpers, nothing else
    passes.run(module, ll.create_pass_builder(machine, ll.create_pipeline_tuning_options()))
    return bytes(machine.emit_object(module))


def _link(compiler: list[str], objects: list[Path], folder: Path, stamp: str) -> Path:
    """Link ``objects`` and the C part into ``folder``/library.so; BuildError when the compiler fails."""
    c_part = folder / "tpad_rt_aot.c"
    c_part.write_text(_c_part(stamp))
    script = folder / "exports.map"
    script.write_text(_version_script())
    output = folder / "library.so"
    command = [*compiler, "-shared", "-fPIC", "-O2", "-o", str(output), *map(str, objects), str(c_part),
               f"-Wl,--version-script={script}", "-lm"]
    try:
        result = subprocess.run(command, capture_output=True, text=True, timeout=COMPILER_TIMEOUT_S)
    except (OSError, subprocess.TimeoutExpired) as error:
        raise BuildError(f"aot: the C compiler {shlex.join(compiler)} did not run: {error}") from error
    if result.returncode != 0:
        last = (result.stderr.strip().splitlines() or ["no message"])[-1]
        raise BuildError(f"aot: linking with {shlex.join(compiler)} failed (exit {result.returncode}): {last}")
    return output


def _install(built: Path, stamp: str, folders: Sequence[Path]) -> Path:
    """Move ``built`` to the first writable of ``folders`` under the stamp's name, atomically and durably: copied
    to a temporary file there, synced, renamed over the name, the folder synced. BuildError when none is
    writable; no temporary file is left behind, whatever stops it."""
    reasons = []
    for folder in folders:
        target = folder / library_name(stamp)
        try:
            folder.mkdir(parents=True, exist_ok=True)
            fd, temporary = tempfile.mkstemp(dir=folder, prefix=".tpad_rt_aot-", suffix=".tmp")
        except OSError as error:
            reasons.append(f"{folder}: {error.strerror or error}")
            continue
        try:
            with os.fdopen(fd, "wb") as written:
                written.write(built.read_bytes())
                written.flush()
                os.fchmod(written.fileno(), 0o755)
                os.fsync(written.fileno())
            os.replace(temporary, target)
            _sync_folder(folder)
            return target
        except OSError as error:
            reasons.append(f"{folder}: {error.strerror or error}")
        finally:
            Path(temporary).unlink(missing_ok=True)  # gone after the rename; else the half-written copy
    raise BuildError("aot: no folder to write the library to (" + "; ".join(reasons) + ")")


def _sync_folder(folder: Path) -> None:
    """Flush ``folder``'s entries (a rename into it) to disk."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def build_library(progress: Progress | None = None, folders: Sequence[Path] | None = None) -> Path | None:
    """Build and install the library for the current stamp (module docstring); its path, None without a
    C compiler. Raises BuildError when the build fails or the result does not load."""
    say = progress or (lambda line: None)
    compiler = find_compiler()
    if compiler is None:
        return None
    stamp = library_stamp()
    with tempfile.TemporaryDirectory(prefix="tpad_rt_aot-") as scratch:
        folder = Path(scratch)
        objects = _callback_objects(folder, say)
        say(f"linking with {shlex.join(compiler)}")
        built = _link(compiler, objects, folder, stamp)
        built.write_bytes(seal(built.read_bytes()))
        try:
            open_library(built, stamp)
        except LibraryProblem as problem:
            raise BuildError(f"aot: the library built with {shlex.join(compiler)} {problem}") from None
        path = _install(built, stamp, library_dirs() if folders is None else folders)
    say(f"wrote {path}")
    return path


def main() -> int:
    """``python -m tpad_rt.aot.build``: build, print the path; one line on stderr and 1 on failure, 130 at
    Ctrl-C."""
    try:
        path = build_library(lambda line: print(f"aot: {line}", file=sys.stderr))
    except BuildError as error:
        print(error, file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("aot: interrupted", file=sys.stderr)
        return 130
    if path is None:
        given = os.environ.get("CC", "").strip()
        where = f"CC={given} names no program on PATH" if given else "set CC, or install cc, gcc or clang"
        print(f"aot: no C compiler ({where}): the kernels stay on numba's JIT", file=sys.stderr)
        return 1
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
