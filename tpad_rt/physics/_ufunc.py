"""``ufunc``: a physics core as a NumPy ufunc for the public wrappers.

Compiled by numba (``@vectorize(cache=True)``), or, when numba's JIT is off
(``NUMBA_DISABLE_JIT=1``, the kernel coverage run of ``tests/run``), NumPy's
``np.vectorize`` of the same core run as Python: a compiled ufunc cannot call a core that
is then a plain Python function (it did only from a disk cache a jitted run had left).
Either returns a NumPy scalar for scalar inputs and an array otherwise.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numba
import numpy as np


def ufunc(core: Callable[..., Any]) -> Callable[..., Any]:
    """``core`` (a function of floats returning a float) broadcast over array arguments."""
    if not numba.config.DISABLE_JIT:  # type: ignore[attr-defined]  # read from the environment; not in its stubs
        return numba.vectorize(cache=True)(core)
    vectorized = np.vectorize(core, otypes=[np.float64])

    @functools.wraps(core)
    def broadcast(*args: Any) -> Any:
        return vectorized(*args)[()]

    return broadcast
