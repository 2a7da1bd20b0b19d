"""Vezzoli/Sednaoui friction model (paper Eqs. 2-3) and its inverse."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tpad_rt.physics import friction
from tpad_rt.physics.friction import amplitude_for, relative_friction

# Hypothesis deadlines are wall-clock limits, and a ufunc's first call compiles it.
NO_DEADLINE = settings(deadline=None)

# Realistic ranges: the paper's plates run at 22-45 kHz with 1.8-6 um amplitude and
# the model is validated for amplitudes > 1 um (Section III); fingers slide at mm/s
# to tens of cm/s.
amplitudes_m = st.floats(1e-6, 10e-6)
freqs_hz = st.floats(20e3, 50e3)
speeds_m_s = st.floats(5e-3, 0.2)


def test_paper_example_30khz_3um_50mm_s():
    assert relative_friction(3e-6, 30e3, 0.05) == pytest.approx(0.2997, abs=1e-4)


def test_hand_computed_value_with_explicit_parameters():
    # Psi = 0.1 / (25e3 * 2e-6 * 0.5 * 1.5) = 2.6667; mu' = 1 - exp(-2.6667 / 2) = 0.73640
    assert relative_friction(2e-6, 25e3, 0.1, mu0=0.5, poisson=0.5, psi_star=2.0) == pytest.approx(
        0.736403, rel=1e-5
    )


def test_defaults_are_the_papers_values():
    assert (friction.MU0, friction.POISSON, friction.PSI_STAR) == (0.25, 0.33, 4.69)


def test_zero_amplitude_is_no_friction_reduction():
    assert relative_friction(0.0, 30e3, 0.05) == 1.0


def test_full_friction_needs_zero_amplitude():
    assert amplitude_for(1.0, 30e3, 0.05) == 0.0


def test_broadcasts_over_arrays():
    amplitudes = np.array([[0.0], [3e-6]])
    result = relative_friction(amplitudes, np.array([25e3, 30e3, 35e3]), 0.05)
    assert result.shape == (2, 3)
    assert np.all(result[0] == 1.0)
    assert result[1, 1] == pytest.approx(0.2997, abs=1e-4)


@NO_DEADLINE
@given(amplitudes_m, freqs_hz, speeds_m_s)
def test_amplitude_for_inverts_relative_friction(amplitude_m, freq_hz, speed_m_s):
    mu_rel = relative_friction(amplitude_m, freq_hz, speed_m_s)
    assert amplitude_for(mu_rel, freq_hz, speed_m_s) == pytest.approx(amplitude_m, rel=1e-9)


@NO_DEADLINE
@given(st.floats(0.01, 0.99), freqs_hz, speeds_m_s)
def test_relative_friction_inverts_amplitude_for(mu_rel, freq_hz, speed_m_s):
    amplitude_m = amplitude_for(mu_rel, freq_hz, speed_m_s)
    assert relative_friction(amplitude_m, freq_hz, speed_m_s) == pytest.approx(mu_rel, abs=1e-12)


@NO_DEADLINE
@given(amplitudes_m, st.floats(1.01, 3.0), freqs_hz, speeds_m_s)
def test_more_vibration_velocity_means_less_friction(amplitude_m, factor, freq_hz, speed_m_s):
    assert relative_friction(amplitude_m * factor, freq_hz, speed_m_s) < relative_friction(
        amplitude_m, freq_hz, speed_m_s
    )
    assert relative_friction(amplitude_m, freq_hz * factor, speed_m_s) < relative_friction(
        amplitude_m, freq_hz, speed_m_s
    )


@pytest.mark.parametrize(
    ("function", "kwargs", "message"),
    [
        (relative_friction, {"amplitude_m": -1e-6}, "amplitude_m must be >= 0, got -1e-06"),
        (relative_friction, {"freq_hz": 0.0}, "freq_hz must be > 0, got 0"),
        (relative_friction, {"speed_m_s": math.nan}, "speed_m_s must be > 0, got nan"),
        (relative_friction, {"mu0": -0.25}, "mu0 must be > 0, got -0.25"),
        (relative_friction, {"poisson": 0.6}, "poisson must be in (-1, 0.5], got 0.6"),
        (relative_friction, {"psi_star": math.inf}, "psi_star must be > 0, got inf"),
        (amplitude_for, {"mu_rel": 0.0}, "mu_rel must be in (0, 1], got 0"),
        (amplitude_for, {"mu_rel": [0.5, 1.5]}, "mu_rel must be in (0, 1], got 1.5"),
        (amplitude_for, {"speed_m_s": -0.05}, "speed_m_s must be > 0, got -0.05"),
    ],
)
def test_out_of_range_inputs_name_argument_range_and_value(function, kwargs, message):
    first = "amplitude_m" if function is relative_friction else "mu_rel"
    arguments = {first: 0.5 if first == "mu_rel" else 1e-6, "freq_hz": 30e3, "speed_m_s": 0.05, **kwargs}
    with pytest.raises(ValueError) as excinfo:
        function(**arguments)
    assert str(excinfo.value) == message


def test_njit_cores_agree_with_wrappers():
    # approx, not ==: under NUMBA_DISABLE_JIT=1 the cores run as Python and may differ in the last bit
    rng = np.random.default_rng(1)
    amplitudes = rng.uniform(0.0, 10e-6, 50)
    freqs = rng.uniform(20e3, 50e3, 50)
    speeds = rng.uniform(5e-3, 0.2, 50)
    model = (friction.MU0, friction.POISSON, friction.PSI_STAR)
    mu = relative_friction(amplitudes, freqs, speeds)
    alpha = amplitude_for(mu, freqs, speeds)
    for i in range(50):
        assert friction.relative_friction_core(amplitudes[i], freqs[i], speeds[i], *model) == pytest.approx(mu[i], rel=1e-12)
        assert friction.amplitude_for_core(mu[i], freqs[i], speeds[i], *model) == pytest.approx(alpha[i], rel=1e-12)
