"""Plate design: resonance and amplification number (paper Section VI, Eqs. 16-21)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tpad_rt.physics import plate
from tpad_rt.physics.plate import ACTUATOR, TABLE1_GLASSES, table1_glass

# Hypothesis deadlines are wall-clock limits, and a ufunc's first call compiles it.
NO_DEADLINE = settings(deadline=None)

# Hand-computed for the paper's 130 mm plates in the 20 x 0 mode (glass-only free-free beam, beta L = 19.5 pi),
# n from Eq. 19 with the Section VI actuator, power relative to SLG_0.56 from Eq. 21.
EXPECTED = {
    "SLG_0.4": (21823, 5.561, 0.583),
    "SLG_0.56": (30552, 4.244, 1.0),
    "SLG_0.7": (38190, 3.624, 1.372),
    "D263_0.4": (21994, 5.499, 0.596),
    "D263_0.56": (30791, 4.202, 1.02),
    "Gorilla_0.56": (31056, 4.291, 0.978),
    "Gorilla_0.8": (44366, 3.355, 1.6),
    "BoroFloat_0.7": (38520, 3.895, 1.188),
}


def _n(glass, actuator=ACTUATOR):
    return plate.amplification_number(
        glass.thickness_m, glass.density_kg_m3, glass.youngs_pa,
        actuator.thickness_m, actuator.density_kg_m3, actuator.youngs_pa,
    )


def _resonance_hz(glass):
    return plate.mode_resonance_hz(glass.thickness_m, glass.density_kg_m3, glass.youngs_pa, 0.130, 20)


def test_catalog_is_table1_and_section6():
    assert [g.label for g in TABLE1_GLASSES] == list(EXPECTED)
    slg = table1_glass("SLG_0.56")
    assert (slg.thickness_mm, slg.density_g_cm3, slg.youngs_modulus_gpa) == (0.56, 2.483, 71.0)
    assert (slg.thickness_m, slg.density_kg_m3, slg.youngs_pa) == pytest.approx((0.56e-3, 2483.0, 71e9))
    assert (ACTUATOR.thickness_mm, ACTUATOR.density_g_cm3, ACTUATOR.youngs_modulus_gpa) == (0.3, 7.9, 84.0)
    with pytest.raises(KeyError, match="SLG_0.4, SLG_0.56"):
        table1_glass("SLG_9")


@pytest.mark.parametrize("glass", TABLE1_GLASSES, ids=lambda g: g.label)
def test_20x0_resonance_matches_hand_computation(glass):
    assert _resonance_hz(glass) == pytest.approx(EXPECTED[glass.label][0], abs=1.0)


@pytest.mark.parametrize("glass", TABLE1_GLASSES, ids=lambda g: g.label)
def test_amplification_number_matches_hand_computation(glass):
    assert _n(glass) == pytest.approx(EXPECTED[glass.label][1], abs=6e-4)


@pytest.mark.parametrize("glass", TABLE1_GLASSES, ids=lambda g: g.label)
def test_power_relative_to_slg_056_matches_hand_computation(glass):
    ratio = plate.power_ratio(_n(table1_glass("SLG_0.56")), _n(glass))
    assert ratio == pytest.approx(EXPECTED[glass.label][2], abs=6e-4)


def test_predicted_resonances_are_0_5_to_2_6_percent_below_the_papers_measured_range():
    predicted = [_resonance_hz(g) for g in TABLE1_GLASSES]
    assert min(predicted) / 22.4e3 == pytest.approx(0.974, abs=0.003)
    assert max(predicted) / 44.6e3 == pytest.approx(0.995, abs=0.003)


def test_sandwich_stiffness_eq20_hand_value():
    # 71e9 * 0.56e-3^3 / 3 + 84e9 * (0.3e-3^3 / 3 + 0.56e-3 * 0.3e-3^2 + 0.56e-3^2 * 0.3e-3) = 17.0486 N m
    assert plate.sandwich_stiffness_per_width(0.56e-3, 71e9, 0.3e-3, 84e9) == pytest.approx(17.0486, rel=1e-5)


def test_bending_wavenumber_eq16_hand_value():
    # mu = 1 kg/m, D = 16 N m^2, w = 2 pi 1000: beta = (w^2 / 16)^(1/4) = sqrt(w) / 2 = 39.633 rad/m
    assert plate.bending_wavenumber(1000.0, 1.0, 16.0) == pytest.approx(39.633, rel=1e-4)


@pytest.mark.parametrize("glass", TABLE1_GLASSES, ids=lambda g: g.label)
def test_mode_resonance_puts_a_free_free_beams_20_nodal_lines_on_the_plate(glass):
    mass_per_length = glass.density_kg_m3 * glass.thickness_m  # per unit width
    stiffness = glass.youngs_pa * glass.thickness_m**3 / 12
    beta = plate.bending_wavenumber(_resonance_hz(glass), mass_per_length, stiffness)
    assert 2 * math.pi / beta == pytest.approx(2 * 0.130 / 19.5, rel=1e-12)
    # beta L = 19.5 pi is the free-free beam's 19th root of cos x cosh x = 1 (20 nodal lines), to double
    # precision: there cos x = 1 / cosh x, about 1e-26
    x = float(beta) * 0.130
    assert math.cos(x) == pytest.approx(1 / math.cosh(x), abs=1e-12)
    assert round(x / math.pi - 0.5) == 19


@NO_DEADLINE
@given(
    h_p=st.floats(0.1e-3, 3e-3),
    rho_p=st.floats(1000.0, 9000.0),
    e_p=st.floats(10e9, 200e9),
    omega=st.floats(1e3, 1e6),
    width_m=st.floats(1e-3, 1.0),
)
def test_eq19_equals_eq15_from_the_wavenumbers_at_any_frequency_and_width(h_p, rho_p, e_p, omega, width_m):
    """n = 12 D1 / (E_p h_p^3 l_w) (beta_a / beta_p)^3 with Eqs. 16-18 (sandwich and plate wavenumbers)."""
    h_a, rho_a, e_a = ACTUATOR.thickness_m, ACTUATOR.density_kg_m3, ACTUATOR.youngs_pa
    freq_hz = omega / (2 * math.pi)
    d1 = width_m * plate.sandwich_stiffness_per_width(h_p, e_p, h_a, e_a)  # Eq. 13
    d2 = e_p * width_m * h_p**3 / 12
    beta_a = plate.bending_wavenumber(freq_hz, width_m * (rho_a * h_a + rho_p * h_p), d1)  # Eq. 17
    beta_p = plate.bending_wavenumber(freq_hz, width_m * rho_p * h_p, d2)  # Eq. 18
    eq15 = 12 * d1 / (e_p * h_p**3 * width_m) * (beta_a / beta_p) ** 3
    assert plate.amplification_number(h_p, rho_p, e_p, h_a, rho_a, e_a) == pytest.approx(eq15, rel=1e-9)


@NO_DEADLINE
@given(st.floats(0.2e-3, 2e-3), st.floats(1.01, 2.0))
def test_thinner_glass_amplifies_more(h_p, factor):
    """The trend behind the paper's 'thinner TPaDs yield higher performance'."""
    slg = table1_glass("SLG_0.56")
    args = (slg.density_kg_m3, slg.youngs_pa, ACTUATOR.thickness_m, ACTUATOR.density_kg_m3, ACTUATOR.youngs_pa)
    assert plate.amplification_number(h_p, *args) > plate.amplification_number(h_p * factor, *args)


@NO_DEADLINE
@given(st.floats(1.0, 10.0), st.floats(1.0, 10.0))
def test_power_ratio_eq21(n_1, n_2):
    assert plate.power_ratio(n_1, n_2) == pytest.approx(n_1**2 / n_2**2, rel=1e-12)
    assert plate.power_ratio(n_1, n_2) * plate.power_ratio(n_2, n_1) == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: plate.bending_wavenumber(3e4, 0.0, 1.0), "mass_per_length_kg_m must be > 0, got 0"),
        (lambda: plate.mode_resonance_hz(0.5e-3, 2500.0, 70e9, 0.13, [20, -1]), "mode_m must be > 0, got -1"),
        (lambda: plate.mode_resonance_hz(-0.5e-3, 2500.0, 70e9, 0.13, 20), "thickness_m must be > 0, got -0.0005"),
        (lambda: plate.sandwich_stiffness_per_width(0.5e-3, math.nan, 0.3e-3, 84e9), "e_p must be > 0, got nan"),
        (lambda: plate.amplification_number(0.5e-3, 2500.0, 70e9, 0.3e-3, -7900.0, 84e9), "rho_a must be > 0, got -7900"),
        (lambda: plate.power_ratio(4.0, 0.0), "n_2 must be > 0, got 0"),
    ],
)
def test_out_of_range_inputs_name_argument_range_and_value(call, message):
    with pytest.raises(ValueError) as excinfo:
        call()
    assert str(excinfo.value) == message


def test_wrappers_broadcast_over_the_catalog():
    thickness = np.array([g.thickness_m for g in TABLE1_GLASSES])
    density = np.array([g.density_kg_m3 for g in TABLE1_GLASSES])
    youngs = np.array([g.youngs_pa for g in TABLE1_GLASSES])
    resonances = plate.mode_resonance_hz(thickness, density, youngs, 0.130, 20)
    assert resonances.shape == (8,)
    assert resonances == pytest.approx([EXPECTED[g.label][0] for g in TABLE1_GLASSES], abs=1.0)
