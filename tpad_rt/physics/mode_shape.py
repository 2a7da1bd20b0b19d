"""The plate's standing wave: the free-free bending mode with ``m`` nodal lines across its length.

A TPaD plate is driven in an ``m x 0`` mode (the paper's plates: 20 x 0, Section II): a
standing bending wave along the length ``L``, the same across the width. Its nodal lines
are about ``L / (m - 1/2)`` apart (6.7 mm on a 130 mm plate at m = 20), and the free ends
swing further than the antinodes between them. The device's amplitude per volt is the
amplitude at an antinode away from the ends, so the shape here is normalised to that.

The Euler-Bernoulli free-free beam (Timoshenko & Young, "Vibration problems in
engineering"): ``beta L`` is the root of ``cos(beta L) cosh(beta L) = 1`` near
``(m - 1/2) pi``, and with ``theta = beta x``

    W(theta) = cosh theta + cos theta - sigma (sinh theta + sin theta),
    sigma = (cosh beta L - cos beta L) / (sinh beta L - sin beta L),

evaluated here without the overflow and cancellation of the hyperbolic terms (beta L is
about 61 at m = 20), and divided by ``sqrt(1 + sigma^2)``, the amplitude of its interior
part ``cos theta - sigma sin theta``.

A fingertip touches a patch ``contact_width`` long along the plate: it feels the mean of
``|W|`` over that patch (the part of it on the plate), a first-order model that treats
the friction reduction as following the mean vibration amplitude under the finger.

API map
-------
free_free_beta_l(nodal_lines) -> float
    ``beta L`` of the free-free mode with ``nodal_lines`` nodal lines (>= 2)
deflection(x_mm, length_mm, nodal_lines) -> array
    the normalised mode shape ``W`` at ``x_mm`` (0 .. ``length_mm``; clamped to the plate)
positions(x_mm, length_mm) -> array
    ``x_mm`` as floats clamped to the plate; ValueError if any is not finite
patch_mean(x_mm, length_mm, nodal_lines, contact_width_mm) -> array
    the mean ``|W|`` over a patch ``contact_width_mm`` long centred at ``x_mm``
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

#: The finest step (in units of the nodal spacing) patch_mean integrates |W| on.
_STEPS_PER_NODE_SPACING = 2000


def free_free_beta_l(nodal_lines: int) -> float:
    """``beta L`` of the free-free beam mode with ``nodal_lines`` nodal lines: the root of
    ``cos x cosh x = 1`` in ``((m - 1) pi, m pi)``, by Newton's method from ``(m - 1/2) pi``.

    Raises ValueError unless ``nodal_lines`` is an int >= 2 (a free-free beam's first
    bending mode has two).
    """
    if isinstance(nodal_lines, bool) or not isinstance(nodal_lines, int) or nodal_lines < 2:
        raise ValueError(f"nodal_lines: must be an integer >= 2, got {nodal_lines!r}")
    x = (nodal_lines - 0.5) * math.pi
    for _ in range(50):  # f = cos x - sech x: the same roots, no overflow
        sech = 1.0 / math.cosh(x) if x < 700.0 else 0.0
        step = (math.cos(x) - sech) / (-math.sin(x) - sech * math.tanh(x))
        x -= step
        if abs(step) <= 1e-15 * x:
            break
    return x


def _shape(theta: np.ndarray, beta_l: float) -> np.ndarray:
    """W(theta) / sqrt(1 + sigma^2) for ``0 <= theta <= beta_l`` (module docstring), overflow-free."""
    e = math.exp(-beta_l)
    d = 1.0 - e * e - 2.0 * e * math.sin(beta_l)  # (sinh b - sin b) 2 e^-b
    sigma = (1.0 + e * e - 2.0 * e * math.cos(beta_l)) / d
    near_far_end = (math.cos(beta_l) - math.sin(beta_l) - e) / d  # (1 - sigma) e^b / 2
    shape = (np.cos(theta) - sigma * np.sin(theta) + 0.5 * (1.0 + sigma) * np.exp(-theta)
             + near_far_end * np.exp(theta - beta_l))
    return shape / math.sqrt(1.0 + sigma * sigma)


def _checked_plate(length_mm: float, nodal_lines: int) -> float:
    """``beta`` (1/mm) of the mode; ValueError for a length that is not finite and > 0, or bad nodal lines."""
    if not (isinstance(length_mm, (int, float)) and 0.0 < length_mm < math.inf):
        raise ValueError(f"length_mm: must be a finite number > 0, got {length_mm!r}")
    return free_free_beta_l(nodal_lines) / float(length_mm)


def positions(x_mm: npt.ArrayLike, length_mm: float) -> np.ndarray:
    """``x_mm`` as floats clamped to ``[0, length_mm]``; ValueError if any is not finite."""
    x = np.asarray(x_mm, dtype=np.float64)
    if not np.all(np.isfinite(x)):
        raise ValueError("x_mm: must be finite numbers")
    return np.clip(x, 0.0, length_mm)


def deflection(x_mm: npt.ArrayLike, length_mm: float, nodal_lines: int) -> np.ndarray:
    """The mode shape at ``x_mm`` (mm from one end; clamped to ``[0, length_mm]``), normalised so its
    interior antinodes are +-1 (the free ends reach about +-1.41).

    Raises ValueError for a non-finite ``x_mm``, a ``length_mm`` that is not finite and
    > 0, or ``nodal_lines`` below 2.
    """
    beta = _checked_plate(length_mm, nodal_lines)
    return _shape(beta * positions(x_mm, float(length_mm)), beta * float(length_mm))


def patch_mean(x_mm: npt.ArrayLike, length_mm: float, nodal_lines: int, contact_width_mm: float) -> np.ndarray:
    """The mean of ``|deflection|`` over ``[x - w/2, x + w/2]`` (``w = contact_width_mm``) clipped to the
    plate, at each ``x_mm`` (clamped to the plate); ``|deflection(x)|`` itself for ``w = 0``.

    Raises ValueError for non-finite positions, a bad plate (see :func:`deflection`) or a
    width that is not finite and >= 0.
    """
    beta = _checked_plate(length_mm, nodal_lines)
    if not (isinstance(contact_width_mm, (int, float)) and 0.0 <= contact_width_mm < math.inf):
        raise ValueError(f"contact_width_mm: must be a finite number >= 0, got {contact_width_mm!r}")
    length = float(length_mm)
    x = positions(x_mm, length)
    if contact_width_mm == 0.0:
        return np.abs(_shape(beta * x, beta * length))
    spacing_mm = math.pi / beta
    points = max(2, math.ceil(length / spacing_mm * _STEPS_PER_NODE_SPACING)) + 1
    grid_mm = np.linspace(0.0, length, points)
    magnitude = np.abs(_shape(beta * grid_mm, beta * length))
    integral = np.concatenate(([0.0], np.cumsum(0.5 * (magnitude[1:] + magnitude[:-1]) * np.diff(grid_mm))))
    low = np.clip(x - 0.5 * contact_width_mm, 0.0, length)
    high = np.clip(x + 0.5 * contact_width_mm, 0.0, length)
    span = high - low
    mean = (np.interp(high, grid_mm, integral) - np.interp(low, grid_mm, integral)) / np.where(span > 0, span, 1.0)
    return np.where(span > 0, mean, np.abs(_shape(beta * x, beta * length)))
