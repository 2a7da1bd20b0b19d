"""Input checks shared by the public physics wrappers (the njit cores check nothing)."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

#: What a public wrapper returns: a NumPy scalar for scalar inputs, else an array.
FloatOrArray = np.float64 | npt.NDArray[np.float64]
#: The same for complex results.
ComplexOrArray = np.complex128 | npt.NDArray[np.complex128]


def _range_text(low: float, high: float, low_closed: bool, high_closed: bool) -> str:
    if math.isinf(high):
        return f"must be {'>=' if low_closed else '>'} {low:g}"
    return f"must be in {'[' if low_closed else '('}{low:g}, {high:g}{']' if high_closed else ')'}"


def checked(
    name: str,
    value: npt.ArrayLike,
    low: float,
    high: float = math.inf,
    *,
    low_closed: bool = False,
    high_closed: bool = False,
) -> npt.NDArray[np.float64]:
    """``value`` as a float64 array, or ValueError naming ``name``, the range and the bad value.

    Every value must be finite and lie between ``low`` and ``high`` (each end open
    unless ``low_closed`` / ``high_closed``).
    """
    array = np.asarray(value, dtype=np.float64)
    above = array >= low if low_closed else array > low
    below = array <= high if high_closed else array < high
    bad = ~(np.isfinite(array) & above & below)
    if bad.any():
        got = array[bad].flat[0]
        raise ValueError(f"{name} {_range_text(low, high, low_closed, high_closed)}, got {got:g}")
    return array


def positive(**values: npt.ArrayLike) -> list[npt.NDArray[np.float64]]:
    """Each keyword value as a float64 array checked finite and > 0, in order."""
    return [checked(name, value, 0.0) for name, value in values.items()]


def non_negative(name: str, value: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """``value`` as a float64 array checked finite and >= 0."""
    return checked(name, value, 0.0, low_closed=True)


def finite(name: str, value: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """``value`` as a float64 array, or ValueError naming ``name`` and the first value that is not finite, or
    saying that ``value`` holds something other than real numbers (text, booleans, complex numbers)."""
    raw = np.asarray(value)
    if raw.dtype.kind not in "iuf":
        raise ValueError(f"{name} must hold real numbers, got {raw.dtype} values")
    array = raw.astype(np.float64)
    bad = ~np.isfinite(array)
    if bad.any():
        raise ValueError(f"{name} must be finite, got {array[bad].flat[0]:g}")
    return array
