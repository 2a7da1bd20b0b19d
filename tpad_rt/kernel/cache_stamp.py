"""numba disk-cache stamps that cover every source compiled into a module's kernels.

numba keys a function's disk cache on its own source file only. A kernel that has
functions of other modules inlined into it (``render_block`` has the texture
evaluation, the layout constants and the friction model; the audio callback has
``render_block``) would keep a stale compiled copy when one of those files changes.
:func:`stamp_cache` registers a cache locator for one module whose entries are
stamped with the SHA-256 of that module and of every other source named.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

from numba.core import caching


def stamp_cache(module_file: str, *sources: str | Path) -> tuple[Path, ...]:
    """Stamp the disk cache of ``module_file``'s numba functions with it and ``sources``.

    Call it at import time of that module, before its functions compile. Returns the
    stamped paths, ``module_file`` first, so a module inlined elsewhere can pass them on.
    """
    this_file = Path(module_file).resolve()
    paths = (this_file, *(Path(source).resolve() for source in sources))

    def stamped(base: type[Any]) -> type[Any]:
        class Locator(base):
            @classmethod
            def from_function(cls, py_func, py_file):  # type: ignore[no-untyped-def]
                return super().from_function(py_func, py_file) if Path(py_file).resolve() == this_file else None

            def get_source_stamp(self) -> tuple[str, ...]:
                return tuple(hashlib.sha256(path.read_bytes()).hexdigest() for path in paths)

        return Locator

    # numba has no public way to add a cache locator: its own locators are found through this
    # private list, and this function is the only place it is touched.
    caching.CacheImpl._locator_classes[:0] = [
        stamped(base)
        for base in (caching.UserProvidedCacheLocator, caching.InTreeCacheLocator, caching.UserWideCacheLocator)
    ]
    return paths
