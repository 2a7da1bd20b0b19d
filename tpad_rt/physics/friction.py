"""Vezzoli/Sednaoui ultrasonic friction model (paper Eqs. 2-3) and its inverse.

``mu' = 1 - exp(-Psi / Psi*)`` with ``Psi = U / (f * alpha * mu0 * (1 + nu))``:
relative friction ``mu'`` of a finger sliding at speed ``U`` (m/s) on a plate
vibrating at ``f`` (Hz) with amplitude ``alpha`` (m). SI units throughout.

The ``*_core`` functions are numba-compiled scalar kernels without input checks;
the public functions validate their inputs and broadcast like NumPy ufuncs.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

from tpad_rt.physics._ufunc import ufunc
from tpad_rt.physics._validate import FloatOrArray, checked

# The paper (model: Section III; values: start of Section IV, with U = 50 mm/s) takes
# these from Vezzoli et al. and Sednaoui et al.
#: Friction coefficient with the vibration off.
MU0 = 0.25
#: Poisson's ratio of the finger skin.
POISSON = 0.33
#: Characteristic value of the dimensionless group Psi.
PSI_STAR = 4.69


@numba.njit(cache=True, nogil=True)
def relative_friction_core(
    amplitude_m: float, freq_hz: float, speed_m_s: float, mu0: float, poisson: float, psi_star: float
) -> float:
    """Relative friction mu' (paper Eqs. 2-3); amplitude 0 gives 1.0. No input checks."""
    if amplitude_m == 0.0:
        return 1.0
    psi = speed_m_s / (freq_hz * amplitude_m * mu0 * (1.0 + poisson))
    return 1.0 - math.exp(-psi / psi_star)


@numba.njit(cache=True, nogil=True)
def amplitude_for_core(
    mu_rel: float, freq_hz: float, speed_m_s: float, mu0: float, poisson: float, psi_star: float
) -> float:
    """Vibration amplitude (m) giving relative friction ``mu_rel``; 1 gives 0. No input checks."""
    if mu_rel >= 1.0:
        return 0.0
    return speed_m_s / (freq_hz * mu0 * (1.0 + poisson) * psi_star * -math.log1p(-mu_rel))


@ufunc
def _relative_friction_ufunc(amplitude_m, freq_hz, speed_m_s, mu0, poisson, psi_star):  # type: ignore[no-untyped-def]
    return relative_friction_core(amplitude_m, freq_hz, speed_m_s, mu0, poisson, psi_star)


@ufunc
def _amplitude_for_ufunc(mu_rel, freq_hz, speed_m_s, mu0, poisson, psi_star):  # type: ignore[no-untyped-def]
    return amplitude_for_core(mu_rel, freq_hz, speed_m_s, mu0, poisson, psi_star)


def _checked_model(
    freq_hz: npt.ArrayLike, speed_m_s: npt.ArrayLike, mu0: float, poisson: float, psi_star: float
) -> tuple[npt.NDArray[np.float64], ...]:
    """The inputs both directions of the model share, validated."""
    return (
        checked("freq_hz", freq_hz, 0.0),
        checked("speed_m_s", speed_m_s, 0.0),
        checked("mu0", mu0, 0.0),
        checked("poisson", poisson, -1.0, 0.5, high_closed=True),
        checked("psi_star", psi_star, 0.0),
    )


def relative_friction(
    amplitude_m: npt.ArrayLike,
    freq_hz: npt.ArrayLike,
    speed_m_s: npt.ArrayLike,
    mu0: float = MU0,
    poisson: float = POISSON,
    psi_star: float = PSI_STAR,
) -> FloatOrArray:
    """Relative friction mu' in (0, 1] (paper Eqs. 2-3); broadcasts over its arguments.

    ``amplitude_m`` (m, >= 0; 0 gives 1.0), ``freq_hz`` (Hz, > 0), ``speed_m_s``
    (finger speed, m/s, > 0), ``mu0`` (> 0), ``poisson`` (in (-1, 0.5]),
    ``psi_star`` (> 0). Raises ValueError for a value outside its range or not finite.
    """
    amplitude = checked("amplitude_m", amplitude_m, 0.0, low_closed=True)
    return _relative_friction_ufunc(amplitude, *_checked_model(freq_hz, speed_m_s, mu0, poisson, psi_star))


def amplitude_for(
    mu_rel: npt.ArrayLike,
    freq_hz: npt.ArrayLike,
    speed_m_s: npt.ArrayLike,
    mu0: float = MU0,
    poisson: float = POISSON,
    psi_star: float = PSI_STAR,
) -> FloatOrArray:
    """Vibration amplitude (m) that gives relative friction ``mu_rel`` (inverse of Eqs. 2-3).

    ``alpha = U / (f * mu0 * (1 + nu) * Psi* * (-ln(1 - mu')))``; ``mu_rel`` must be
    in (0, 1] (1 gives 0 m); the other arguments as for :func:`relative_friction`.
    Raises ValueError for a value outside its range or not finite.
    """
    target = checked("mu_rel", mu_rel, 0.0, 1.0, high_closed=True)
    return _amplitude_for_ufunc(target, *_checked_model(freq_hz, speed_m_s, mu0, poisson, psi_star))
