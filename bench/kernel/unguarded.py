"""The render kernel as it was before its fault guard: the baseline the guard's cost is measured against.

``load_render_block() -> render_block`` reads ``tpad_rt/kernel/render.py`` at
:data:`PRE_GUARD_REVISION` (the last commit before the guard) from the repository's git
history and imports it as a module of its own, compiled without numba's disk cache. It
uses today's ``tpad_rt.kernel.layout`` (the state slots it knows kept their meaning), so
for valid data it renders the same samples as today's kernel: the bench checks that,
then times both in the same run. Raises RuntimeError when git or the revision is missing
(a source tarball has no history).
"""

from __future__ import annotations

import atexit
import importlib.util
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
#: The last commit whose render kernel had no fault guard (issue 8).
PRE_GUARD_REVISION = "1bf5259"


def load_render_block() -> Any:
    """``render_block`` of the kernel at PRE_GUARD_REVISION (see the module docstring)."""
    try:
        source = subprocess.run(["git", "-C", str(ROOT), "show", f"{PRE_GUARD_REVISION}:tpad_rt/kernel/render.py"],
                                capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError) as error:
        raise RuntimeError(f"cannot read the kernel at {PRE_GUARD_REVISION} from git ({error})") from None
    folder = Path(tempfile.mkdtemp(prefix="tpad-rt-unguarded-"))
    atexit.register(shutil.rmtree, folder, True)  # numba may read the source while it compiles: kept until exit
    path = folder / "render_unguarded.py"
    path.write_text(source.replace("cache=True", "cache=False"))
    spec = importlib.util.spec_from_file_location("render_unguarded", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.render_block
