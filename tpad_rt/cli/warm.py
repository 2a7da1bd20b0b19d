"""``tpad-rt warm``: compile every kernel now, once, so that no command compiles later.

Compiles the whole compile plan into numba's cache (``tpad_rt.compiling.ensure_compiled``: the steps in
worker processes, progress as steps done of the total), or says that it is all compiled already; either way
it names the cache folder. Ctrl-C stops it (exit 130). Nothing here imports numba until it runs.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tpad_rt.cli.arguments import whole

#: The most workers --jobs takes.
MAX_JOBS = 64


def add_parser(subparsers: Any) -> None:
    """Register ``warm``."""
    parser = subparsers.add_parser(
        "warm",
        help="compile every kernel now, once, into numba's cache (run it after installing)",
        description="Compile every kernel tpad-rt runs (play on every output, render, serve, the Pipeline and "
                    "Renderer APIs, the serial streamer) into numba's cache, so that no command compiles "
                    "later; or say that they are all compiled already. Ctrl-C stops.",
    )
    parser.add_argument("--jobs", metavar="N", type=whole(MAX_JOBS, "workers"),
                        help=f"worker processes, 1 to {MAX_JOBS} (default: the CPUs, at most 2)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Warm (module docstring); 0 once everything is compiled."""
    from tpad_rt import compiling, kernel_cache

    report = compiling.ensure_compiled(args.jobs)
    if report is None:
        where = kernel_cache.cache_dir(kernel_cache.COMPILED_PACKAGES[0])
        print(f"tpad-rt warm: every kernel is compiled already, cached in {where}")
    _build_ahead_of_time()
    return 0


def _build_ahead_of_time(folders: Sequence[Path] | None = None) -> None:
    """Build the audio callbacks' ahead-of-time library (docs/kernel.md "Ahead-of-time kernels") in the first writable
    of ``folders`` (default: beside numba's cache) unless a sound one for the current sources is there. A file there
    that the loader refuses (cut short, damaged, another stamp) is named in one line with what was wrong and rebuilt
    in its place, never loaded. Without a C compiler, or when the build fails, one line says so: the renderer then
    runs numba's callbacks, which start about half a second later."""
    from tpad_rt.aot import build, library

    found = library.find(folders)
    if found.library is not None:
        print(f"tpad-rt warm: the ahead-of-time audio callbacks are built already: {found.path}")
        return
    if found.problem is not None:
        print(f"tpad-rt warm: the ahead-of-time library {found.path} {found.problem}: building it again")
    try:
        path = build.build_library(folders=folders)
    except build.BuildError as err:
        print(f"tpad-rt warm: the ahead-of-time audio callbacks were not built ({err}); the renderer uses numba's",
              file=sys.stderr)
        return
    if path is None:
        which = f"$CC ({os.environ['CC']}) names no program" if os.environ.get("CC") else "no cc, gcc or clang"
        print(f"tpad-rt warm: no C compiler ({which}): the ahead-of-time audio callbacks are not "
              "built; the renderer uses numba's, which start about half a second later")
    else:
        print(f"tpad-rt warm: built the ahead-of-time audio callbacks: {path}")
