"""Plate design: bending resonance and amplification number (paper Section VI, Eqs. 16-21).

A TPaD is a glass plate (index ``p``) with a piezo actuator (index ``a``) bonded
to it. Euler-Bernoulli bending gives the wavenumber and the resonance of the
``m x 0`` mode; the amplification number ``n`` (plate amplitude over actuator
amplitude at their junction) sets how much of the plate's impedance the actuator
sees, hence the relative power of two TPaDs (Eq. 21). SI units: m, kg/m^3, Pa, Hz.

``TABLE1_GLASSES`` and ``ACTUATOR`` hold the paper's eight glasses (Table 1) and
its actuator (Section VI).

The functions validate their inputs and broadcast like NumPy ufuncs. They are plain
NumPy, as in :mod:`tpad_rt.physics.electromech`: no kernel evaluates them, and
``tpad-rt design`` starts without numba.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tpad_rt.physics._validate import FloatOrArray, positive


@dataclass(frozen=True)
class Layer:
    """A glass plate or an actuator: thickness, density and Young's modulus, in file units."""

    label: str
    material: str
    thickness_mm: float
    density_g_cm3: float
    youngs_modulus_gpa: float

    @property
    def thickness_m(self) -> float:
        return self.thickness_mm * 1e-3

    @property
    def density_kg_m3(self) -> float:
        return self.density_g_cm3 * 1e3

    @property
    def youngs_pa(self) -> float:
        return self.youngs_modulus_gpa * 1e9


#: The eight glasses of the paper's Table 1 (thickness mm, density g/cm^3, E GPa), measured.
TABLE1_GLASSES: tuple[Layer, ...] = (
    Layer("SLG_0.4", "soda-lime glass", 0.4, 2.483, 71.0),
    Layer("SLG_0.56", "soda-lime glass", 0.56, 2.483, 71.0),
    Layer("SLG_0.7", "soda-lime glass", 0.7, 2.483, 71.0),
    Layer("D263_0.4", "D263 borosilicate glass", 0.4, 2.51, 72.9),
    Layer("D263_0.56", "D263 borosilicate glass", 0.56, 2.51, 72.9),
    Layer("Gorilla_0.56", "Gorilla aluminosilicate glass", 0.56, 2.42, 71.5),
    Layer("Gorilla_0.8", "Gorilla aluminosilicate glass", 0.8, 2.42, 71.5),
    Layer("BoroFloat_0.7", "BoroFloat borosilicate glass", 0.7, 2.2, 64.0),
)

#: The hard piezo actuator SMPL60W5T03R112 (paper Section VI).
ACTUATOR = Layer("SMPL60W5T03R112", "hard PZT", 0.3, 7.9, 84.0)

#: The paper's plates are 130 x 60 mm (Section II).
PLATE_LENGTH_M = 0.130
PLATE_WIDTH_M = 0.060
#: ... and run in the 20 x 0 mode (Section II).
PLATE_MODE = (20, 0)


def table1_glass(label: str) -> Layer:
    """The Table 1 glass called ``label``; KeyError (listing the labels) if there is none."""
    for glass in TABLE1_GLASSES:
        if glass.label == label:
            return glass
    raise KeyError(f"no Table 1 glass {label!r}; expected one of {', '.join(g.label for g in TABLE1_GLASSES)}")


def _bending_wavenumber(freq_hz: FloatOrArray, mass_per_length_kg_m: FloatOrArray,
                        stiffness_n_m2: FloatOrArray) -> FloatOrArray:
    """Bending wavenumber (rad/m), ``(mu w^2 / D)^(1/4)``: paper Eq. 16. No input checks."""
    omega = 2.0 * np.pi * freq_hz
    wavenumber: FloatOrArray = (mass_per_length_kg_m * omega * omega / stiffness_n_m2) ** 0.25
    return wavenumber


def _mode_resonance_hz(thickness_m: FloatOrArray, density_kg_m3: FloatOrArray, youngs_pa: FloatOrArray,
                       length_m: FloatOrArray, mode_m: FloatOrArray) -> FloatOrArray:
    """Resonance (Hz) of the ``m x 0`` mode of a bare plate (Euler-Bernoulli beam). No input checks."""
    beta = np.pi * (mode_m - 0.5) / length_m  # free-free, m nodal lines: beta length = (m - 1/2) pi
    omega = beta * beta * np.sqrt(youngs_pa * thickness_m * thickness_m / (12.0 * density_kg_m3))
    resonance: FloatOrArray = omega / (2.0 * np.pi)
    return resonance


def _sandwich_stiffness_per_width(h_p: FloatOrArray, e_p: FloatOrArray, h_a: FloatOrArray,
                                  e_a: FloatOrArray) -> FloatOrArray:
    """Flexural stiffness per width D1' (N m) of plate plus actuator: paper Eq. 20. No input checks."""
    stiffness: FloatOrArray = e_p * h_p**3 / 3.0 + e_a * (h_a**3 / 3.0 + h_p * h_a * h_a + h_p * h_p * h_a)
    return stiffness


def _amplification_number(h_p: FloatOrArray, rho_p: FloatOrArray, e_p: FloatOrArray, h_a: FloatOrArray,
                          rho_a: FloatOrArray, e_a: FloatOrArray) -> FloatOrArray:
    """Amplification number n: paper Eq. 19 as written. No input checks."""
    d1_per_width = _sandwich_stiffness_per_width(h_p, e_p, h_a, e_a)
    bracket = (d1_per_width / e_p) ** (1.0 / 3.0) * (rho_a * h_a / (h_p * h_p * rho_p) + 1.0 / h_p) / 12.0
    n: FloatOrArray = 12.0 * bracket**0.75
    return n


def bending_wavenumber(
    freq_hz: npt.ArrayLike, mass_per_length_kg_m: npt.ArrayLike, stiffness_n_m2: npt.ArrayLike
) -> FloatOrArray:
    """Bending wavenumber (rad/m) of a beam, ``beta = (mu w^2 / D)^(1/4)``: paper Eq. 16.

    ``mass_per_length_kg_m`` is mu (kg/m), ``stiffness_n_m2`` the flexural
    stiffness D (N m^2). All must be finite and > 0 (ValueError otherwise).
    """
    return _bending_wavenumber(
        *positive(freq_hz=freq_hz, mass_per_length_kg_m=mass_per_length_kg_m, stiffness_n_m2=stiffness_n_m2)
    )


def mode_resonance_hz(
    thickness_m: npt.ArrayLike,
    density_kg_m3: npt.ArrayLike,
    youngs_pa: npt.ArrayLike,
    length_m: npt.ArrayLike,
    mode_m: npt.ArrayLike,
) -> FloatOrArray:
    """Resonance (Hz) of the ``m x 0`` mode of the glass alone (Euler-Bernoulli beam, Eq. 16).

    A free-free beam whose bending mode has ``m >= 2`` nodal lines has ``beta length`` at
    the ``(m - 1)``-th root of ``cos(x) cosh(x) = 1``: ``(m - 1/2) pi`` to within 0.4 % at
    ``m = 2``, 1e-4 at ``m = 3`` and 3e-6 from ``m = 4`` on (wavelength
    ``2 length / (m - 1/2)``; ``2 length / m`` would be a mode of ``m + 1/2`` nodal lines;
    ``m = 1`` has no bending mode, and gives ``pi / 2``). Then
    ``w = beta^2 sqrt(E h^2 / (12 rho))``. The actuator, the glue and the width are
    ignored; for the paper's eight plates it gives 21.83-44.37 kHz against the measured
    22.4-44.6 kHz, 2.6 % low at the low end and 0.5 % at the top.
    All arguments must be finite and > 0 (ValueError otherwise).
    """
    return _mode_resonance_hz(
        *positive(
            thickness_m=thickness_m,
            density_kg_m3=density_kg_m3,
            youngs_pa=youngs_pa,
            length_m=length_m,
            mode_m=mode_m,
        )
    )


def sandwich_stiffness_per_width(
    h_p: npt.ArrayLike, e_p: npt.ArrayLike, h_a: npt.ArrayLike, e_a: npt.ArrayLike
) -> FloatOrArray:
    """Flexural stiffness per unit width D1' (N m) of the plate-actuator sandwich: paper Eq. 20.

    ``D1' = E_p h_p^3 / 3 + E_a (h_a^3 / 3 + h_p h_a^2 + h_p^2 h_a)``; thicknesses
    (m) and Young's moduli (Pa) must be finite and > 0 (ValueError otherwise).
    """
    return _sandwich_stiffness_per_width(*positive(h_p=h_p, e_p=e_p, h_a=h_a, e_a=e_a))


def amplification_number(
    h_p: npt.ArrayLike,
    rho_p: npt.ArrayLike,
    e_p: npt.ArrayLike,
    h_a: npt.ArrayLike,
    rho_a: npt.ArrayLike,
    e_a: npt.ArrayLike,
) -> FloatOrArray:
    """Amplification number n of plate ``p`` driven by actuator ``a``: paper Eq. 19 as written.

    ``n = 12 [ (D1'/E_p)^(1/3) (rho_a h_a / (h_p^2 rho_p) + 1/h_p) / 12 ]^(3/4)``
    (D1' from Eq. 20), which equals Eq. 15 with Eqs. 17-18 substituted; it does not
    depend on frequency or width. Thicknesses (m), densities (kg/m^3) and Young's
    moduli (Pa) must be finite and > 0 (ValueError otherwise).
    """
    return _amplification_number(
        *positive(h_p=h_p, rho_p=rho_p, e_p=e_p, h_a=h_a, rho_a=rho_a, e_a=e_a)
    )


def power_ratio(n_1: npt.ArrayLike, n_2: npt.ArrayLike) -> FloatOrArray:
    """Real power of TPaD 2 over TPaD 1 at the same drive voltage, ``n1^2 / n2^2``: paper Eq. 21.

    Assumes the reflected glass impedance dominates and is alike for both.
    ``n_1`` and ``n_2`` must be finite and > 0 (ValueError otherwise).
    """
    n_1_checked, n_2_checked = positive(n_1=n_1, n_2=n_2)
    ratio: FloatOrArray = (n_1_checked / n_2_checked) ** 2
    return ratio
