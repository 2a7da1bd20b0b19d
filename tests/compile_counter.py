"""Run a ``tpad-rt`` command line, or a Python file, in this process, and say last on stderr which of tpad-rt's
functions numba compiled in it: ``python tests/compile_counter.py play ...`` or ``python tests/compile_counter.py
FILE.py``. The last line is ``COMPILED`` then a JSON list of ``module.qualname``.

numba runs its compiler passes (``numba:run_pass`` events) for every function it compiles, ``@cfunc`` callbacks
too, and for none it loads from its cache: an empty list means no compile work at all.
"""

from __future__ import annotations

import atexit
import json
import runpy
import sys

from numba.core import event

#: How the last stderr line starts.
COMPILED = "compiled in this process:"

_compiled: set[str] = set()


class _Passes(event.Listener):
    def on_start(self, pass_event: event.Event) -> None:
        if str(pass_event.data["module"]).startswith("tpad_rt"):
            _compiled.add(f"{pass_event.data['module']}.{pass_event.data['qualname']}")

    def on_end(self, pass_event: event.Event) -> None:
        pass


def _report() -> None:
    print(COMPILED, json.dumps(sorted(_compiled)), file=sys.stderr, flush=True)


if __name__ == "__main__":
    event.register("numba:run_pass", _Passes())
    atexit.register(_report)
    if sys.argv[1].endswith(".py"):
        sys.argv = sys.argv[1:]
        runpy.run_path(sys.argv[0], run_name="__main__")
    else:
        from tpad_rt.cli import main

        sys.exit(main(sys.argv[1:]))
