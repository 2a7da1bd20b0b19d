"""The numba decorators of the kernels, typed for mypy.

numba's own stubs type ``njit(...)`` as returning a Dispatcher, which mypy cannot call with
a kernel's Python signature, and do not know numba's ``_nrt`` option; an ``@intrinsic``
is typed with its code generator's signature ``(typingctx, ...)``, not the one compiled
code calls. These wrappers change nothing at run time: they return numba's own objects.

API map
-------
njit(**options) -> decorator
    ``numba.njit(**options)``, typed as returning the function it decorates
intrinsic(generator) -> callable
    ``numba.extending.intrinsic(generator)``, typed as any callable
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba
import numba.extending

Function = TypeVar("Function", bound=Callable[..., Any])


def njit(**options: Any) -> Callable[[Function], Function]:
    """``numba.njit(**options)``: a decorator mypy checks calls of against the decorated Python function."""
    return cast(Callable[[Function], Function], numba.njit(**options))


def intrinsic(generator: Callable[..., Any]) -> Callable[..., Any]:
    """``numba.extending.intrinsic(generator)``: callable from compiled code with the intrinsic's own arguments."""
    return cast(Callable[..., Any], numba.extending.intrinsic(generator))
