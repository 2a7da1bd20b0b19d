"""Build the ahead-of-time library: the audio callbacks compiled by numba, linked by the system C compiler.

API map
-------
build_library(progress=None) -> Path | None
    compile ``render_callback`` and ``silence_callback`` (:mod:`tpad_rt.kernel.callback`; numba
    loads them from its cache when it can), emit each as a position-independent object for
    this CPU, link them with a small C part (the release store, the stamp, and no-op stand-ins
    for numba's Python error reporting) into one shared library that needs only libc and
    libm, and move it into place atomically (the first writable of
    :func:`tpad_rt.aot.stamp.library_dirs`). Its path; None when there is no C compiler
    (``$CC``, else ``cc``, ``gcc`` or ``clang``). ``progress`` is called with a line per
    step. Raises BuildError when the compiler fails or no folder is writable.
``python -m tpad_rt.aot.build``
    the same from the command line: prints the library's path (exit 0), or one line on
    stderr (exit 1) when there is no compiler or the build fails

The objects are emitted from the very LLVM module numba's JIT compiles the callbacks from,
with the JIT's CPU, features and optimisation level; only the relocation model differs
(position-independent code). tests/test_aot.py checks output and state are bit-identical.

The only raise the callbacks can reach is numba's ZeroDivisionError for an integer
division by zero (a ring of length 0, which the Python side never makes). The JIT's
callback then prints an "unraisable" message; the library's stand-ins make that path
silent, so the library needs no Python and no numba.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

from tpad_rt.aot.library import PUBLISH_SYMBOL, RENDER_SYMBOL, SILENCE_SYMBOL, STAMP_SYMBOL, open_library
from tpad_rt.aot.stamp import library_dirs, library_name, library_stamp

#: The callbacks compiled in: (attribute of tpad_rt.kernel.callback, exported symbol).
CALLBACKS = (("render_callback", RENDER_SYMBOL), ("silence_callback", SILENCE_SYMBOL))
#: Symbols numba's error path in a cfunc calls (functions) or reads (data): no-ops in the library.
_ERROR_PATH_FUNCTIONS = ("numba_gil_ensure", "numba_gil_release", "numba_do_raise", "numba_unpickle",
                         "numba_runtime_build_excinfo_struct", "PyErr_WriteUnraisable", "PyErr_Clear",
                         "PyErr_SetNone", "PyErr_SetString", "PyUnicode_FromString", "PyBytes_FromStringAndSize",
                         "Py_DecRef", "NRT_Free", "NRT_MemInfo_call_dtor")
_ERROR_PATH_DATA = ("PyExc_RuntimeError", "PyExc_StopIteration", "PyExc_SystemError")
#: Seconds the C compiler may take.
COMPILER_TIMEOUT_S = 120.0

Progress = Callable[[str], None]


class BuildError(RuntimeError):
    """The library could not be built (the message says why)."""


def find_compiler() -> str | None:
    """The C compiler: ``$CC`` when set, else the first of cc, gcc, clang on PATH; None if there is none."""
    names = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for name in names:
        found = shutil.which(name)
        if found:
            return found
    return None


def _c_part(stamp: str) -> str:
    """The C source linked with the callbacks: the stamp, the release store, the error path's stand-ins."""
    stubs = "\n".join(f"void *{name}(void) {{ return 0; }}" for name in _ERROR_PATH_FUNCTIONS)
    data = "\n".join(f"char {name};" for name in _ERROR_PATH_DATA)
    return f"""#include <stdint.h>
const char {STAMP_SYMBOL}[] = "{stamp}";
void {PUBLISH_SYMBOL}(int64_t *array, int64_t index, int64_t value) {{
    __atomic_store_n(&array[index], value, __ATOMIC_RELEASE);
}}
/* numba's Python error reporting, reached only on a raise: silent here */
{stubs}
{data}
"""


def _version_script() -> str:
    """The linker's version script: the library exports its four symbols, nothing else."""
    exported = "; ".join((RENDER_SYMBOL, SILENCE_SYMBOL, PUBLISH_SYMBOL, STAMP_SYMBOL))
    return f"{{ global: {exported}; local: *; }};\n"


def _callback_objects(folder: Path, progress: Progress) -> list[Path]:
    """Emit each callback, compiled by numba, as a position-independent object in ``folder``."""
    import llvmlite.binding as ll
    from numba.core import config

    from tpad_rt.kernel import callback

    objects = []
    for name, symbol in CALLBACKS:
        progress(f"compiling {name} (numba; from its cache when it has it)")
        cfunc = getattr(callback, name)
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
        path = folder / f"{symbol}.o"
        path.write_bytes(machine.emit_object(module))
        objects.append(path)
    return objects


def _link(compiler: str, objects: list[Path], folder: Path, stamp: str) -> Path:
    """Link ``objects`` and the C part into ``folder``/library.so; BuildError when the compiler fails."""
    c_part = folder / "tpad_rt_aot.c"
    c_part.write_text(_c_part(stamp))
    script = folder / "exports.map"
    script.write_text(_version_script())
    output = folder / "library.so"
    command = [compiler, "-shared", "-fPIC", "-O2", "-o", str(output), *map(str, objects), str(c_part),
               f"-Wl,--version-script={script}", "-lm"]
    try:
        result = subprocess.run(command, capture_output=True, text=True, timeout=COMPILER_TIMEOUT_S)
    except (OSError, subprocess.TimeoutExpired) as error:
        raise BuildError(f"aot: the C compiler {compiler} did not run: {error}") from error
    if result.returncode != 0:
        last = (result.stderr.strip().splitlines() or ["no message"])[-1]
        raise BuildError(f"aot: linking with {compiler} failed (exit {result.returncode}): {last}")
    return output


def _install(built: Path, stamp: str) -> Path:
    """Move ``built`` to the first writable library folder, atomically; BuildError when none is writable."""
    reasons = []
    for folder in library_dirs():
        try:
            folder.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=folder, prefix=".tpad_rt_aot-", suffix=".tmp",
                                             delete=False) as temporary:
                temporary.write(built.read_bytes())
            os.chmod(temporary.name, 0o755)
            target = folder / library_name(stamp)
            os.replace(temporary.name, target)
            return target
        except OSError as error:
            reasons.append(f"{folder}: {error.strerror or error}")
            if "temporary" in locals() and Path(temporary.name).exists():
                Path(temporary.name).unlink()
    raise BuildError("aot: no folder to write the library to (" + "; ".join(reasons) + ")")


def build_library(progress: Progress | None = None) -> Path | None:
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
        say(f"linking with {compiler}")
        built = _link(compiler, objects, folder, stamp)
        if open_library(built, stamp) is None:
            raise BuildError(f"aot: the library built with {compiler} does not load or lacks a symbol")
        path = _install(built, stamp)
    say(f"wrote {path}")
    return path


def main() -> int:
    """``python -m tpad_rt.aot.build``: build, print the path; one line on stderr and 1 on failure."""
    try:
        path = build_library(lambda line: print(f"aot: {line}", file=sys.stderr))
    except BuildError as error:
        print(error, file=sys.stderr)
        return 1
    if path is None:
        print("aot: no C compiler (set CC, or install cc, gcc or clang): the kernels stay on numba's JIT",
              file=sys.stderr)
        return 1
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
