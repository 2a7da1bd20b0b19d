"""Butterworth-Van Dyke circuit (paper Section V, Eqs. 2-6)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tpad_rt.physics import electromech as em

# Hypothesis deadlines are wall-clock limits, and a ufunc's first call compiles it.
NO_DEADLINE = settings(deadline=None)

# The paper's circuit: C0 = 9.88 nF, R0 = 100 ohm (Section V); a motional branch
# tuned to 30 kHz with R = 2 kohm and Q = 300.
C0_F = 9.88e-9
R0_OHM = 100.0
F0_HZ = 30e3
R_OHM = 2000.0
L_H = 300 * R_OHM / (2 * math.pi * F0_HZ)
C_F = 1 / ((2 * math.pi * F0_HZ) ** 2 * L_H)

freqs_hz = st.floats(1e3, 200e3)
capacitances_f = st.floats(1e-12, 1e-6)
inductances_h = st.floats(1e-3, 100.0)
resistances_ohm = st.floats(1.0, 1e6)


def _parallel(freq_hz, c0_f, l_h, c_f, r_ohm):
    """C0 in parallel with the series L, C, R, from complex admittances."""
    omega = 2 * math.pi * freq_hz
    z_static = 1 / (1j * omega * c0_f)
    z_motional = r_ohm + 1j * omega * l_h + 1 / (1j * omega * c_f)
    return 1 / (1 / z_static + 1 / z_motional)


@NO_DEADLINE
@given(freqs_hz, capacitances_f, inductances_h, capacitances_f, resistances_ohm)
def test_eq3_closed_form_equals_complex_parallel_combination(freq_hz, c0_f, l_h, c_f, r_ohm):
    assert em.impedance(freq_hz, c0_f, l_h, c_f, r_ohm) == pytest.approx(
        _parallel(freq_hz, c0_f, l_h, c_f, r_ohm), rel=1e-9
    )


@NO_DEADLINE
@given(freqs_hz, capacitances_f, inductances_h, capacitances_f, resistances_ohm)
def test_eq3_equals_eq2_transfer_function_on_the_imaginary_axis(freq_hz, c0_f, l_h, c_f, r_ohm):
    s = 2j * math.pi * freq_hz
    eq2 = (l_h * c_f * s**2 + r_ohm * c_f * s + 1) / (
        c0_f * l_h * c_f * s**3 + c0_f * r_ohm * c_f * s**2 + (c0_f + c_f) * s
    )
    assert em.impedance(freq_hz, c0_f, l_h, c_f, r_ohm) == pytest.approx(eq2, rel=1e-7)


def test_eq6_at_hand_computed_numbers():
    # X0 = -1/(10 nF * 2 pi * 30 kHz) = -530.516 ohm; sqrt(1/X0^2 + 1/R^2) = 2.13379e-3 / ohm;
    # P = 20^2 / (1000 * (1 + 100 * 2.13379e-3)^2) = 0.271686 W
    assert em.real_power_eq6(20.0, 30e3, 10e-9, 1000.0, 100.0) == pytest.approx(0.271686, rel=1e-5)


def test_resonance_and_quality_factor_hand_values():
    # L = 1 H, C = 25.33 pF: f = 1 / (2 pi sqrt(2.533e-11)) = 31623 Hz; Q = sqrt(L/C)/R = 198692/1000
    assert em.resonance_hz(1.0, 2.533e-11) == pytest.approx(31623.0, rel=1e-4)
    assert em.quality_factor(1.0, 2.533e-11, 1000.0) == pytest.approx(198.692, rel=1e-4)
    assert em.resonance_hz(L_H, C_F) == pytest.approx(F0_HZ, rel=1e-12)
    assert em.quality_factor(L_H, C_F, R_OHM) == pytest.approx(300.0, rel=1e-12)


def test_exact_power_without_shunt_is_u_squared_over_r_at_resonance():
    assert em.real_power_exact(20.0, F0_HZ, C0_F, L_H, C_F, R_OHM, 0.0) == pytest.approx(400.0 / R_OHM, rel=1e-9)


@NO_DEADLINE
@given(freqs_hz, st.floats(1e-9, 1e-7), resistances_ohm, st.floats(0.0, 1e4))
def test_exact_power_conserves_energy(freq_hz, c0_f, r_ohm, r0_ohm):
    """Power into the motional branch = power from the source - shunt loss (C0 is lossless)."""
    u_rms = 20.0
    z = em.impedance(freq_hz, c0_f, L_H, C_F, r_ohm)
    current = u_rms / (r0_ohm + z)
    delivered = (u_rms * current.conjugate()).real - abs(current) ** 2 * r0_ohm
    exact = em.real_power_exact(u_rms, freq_hz, c0_f, L_H, C_F, r_ohm, r0_ohm)
    # the subtraction cancels far off resonance: allow rounding on the scale of the apparent power
    assert exact == pytest.approx(delivered, rel=1e-6, abs=1e-12 * abs(u_rms * current))


@NO_DEADLINE
@given(st.floats(20e3, 50e3), st.floats(1e-9, 1e-7), st.floats(50.0, 1e5), st.floats(1.0, 1e3))
def test_exact_power_at_resonance_is_at_least_eq6(freq_hz, c0_f, r_ohm, r0_ohm):
    """Eq. 5 adds |Z| + R0 as magnitudes, |R0 + Z| <= |Z| + R0, so exact >= Eq. 6."""
    l_h = 300 * r_ohm / (2 * math.pi * freq_hz)
    c_f = 1 / ((2 * math.pi * freq_hz) ** 2 * l_h)
    exact = em.real_power_exact(28.28, freq_hz, c0_f, l_h, c_f, r_ohm, r0_ohm)
    assert exact >= em.real_power_eq6(28.28, freq_hz, c0_f, r_ohm, r0_ohm) * (1 - 1e-12)


def test_exact_power_converges_to_eq6_as_shunt_vanishes():
    shunts = np.array([100.0, 10.0, 1.0, 0.1, 0.01])
    exact = em.real_power_exact(28.28, F0_HZ, C0_F, L_H, C_F, R_OHM, shunts)
    eq6 = em.real_power_eq6(28.28, F0_HZ, C0_F, R_OHM, shunts)
    gap = exact / eq6 - 1
    assert gap[0] > 1e-2
    assert np.all(np.diff(gap) < 0)
    assert gap[-1] < 1e-4  # the gap shrinks in proportion to R0
    assert gap[-1] < gap[0] / 1000


@NO_DEADLINE
@given(st.floats(20e3, 50e3), st.floats(1e-9, 1e-7), st.floats(0.0, 1e3), st.floats(1.0, 100.0), st.floats(1.01, 10.0))
def test_both_power_models_fall_as_motional_resistance_rises_above_the_shunt(freq_hz, c0_f, r0_ohm, r_over_r0, step):
    """Paper: power 'is expected to decrease with increasing motional resistance R'.

    That holds for R > R0: Eq. 6 falls for every R > R0, and the exact power at
    resonance, P = U^2 X0^2 R / (R0^2 R^2 + X0^2 (R0 + R)^2), peaks at
    R = R0 |X0| / sqrt(R0^2 + X0^2) < R0. Below R0 (R << R0) both rise with R, so
    the range tested is R in (R0, 100 R0] (R >= 1 ohm), 20-50 kHz, C0 1-100 nF.
    """
    r_low = max(r0_ohm * r_over_r0, 1.0)
    resistances = np.array([r_low, r_low * step])
    l_h = 300 * resistances / (2 * math.pi * freq_hz)
    c_f = 1 / ((2 * math.pi * freq_hz) ** 2 * l_h)
    eq6 = em.real_power_eq6(28.28, freq_hz, c0_f, resistances, r0_ohm)
    exact = em.real_power_exact(28.28, freq_hz, c0_f, l_h, c_f, resistances, r0_ohm)
    assert eq6[1] < eq6[0]
    assert exact[1] < exact[0]


def test_below_the_shunt_power_rises_with_resistance():
    """The other side of the previous test: it is a real limit of the claim, not an artefact."""
    resistances = np.array([5.0, 20.0])
    l_h = 300 * resistances / (2 * math.pi * F0_HZ)
    c_f = 1 / ((2 * math.pi * F0_HZ) ** 2 * l_h)
    assert np.all(np.diff(em.real_power_eq6(28.28, F0_HZ, C0_F, resistances, R0_OHM)) > 0)
    assert np.all(np.diff(em.real_power_exact(28.28, F0_HZ, C0_F, l_h, c_f, resistances, R0_OHM)) > 0)


def test_exact_power_peaks_near_resonance_and_falls_off_it():
    freqs = F0_HZ * np.array([0.95, 0.999, 1.0, 1.001, 1.05])
    power = em.real_power_exact(28.28, freqs, C0_F, L_H, C_F, R_OHM, R0_OHM)
    assert power[2] == power.max()
    assert power[0] < 0.01 * power[2] and power[4] < 0.01 * power[2]
    assert power[1] < power[2] and power[3] < power[2]


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: em.impedance(-1.0, C0_F, L_H, C_F, R_OHM), "freq_hz must be > 0, got -1"),
        (lambda: em.impedance(F0_HZ, 0.0, L_H, C_F, R_OHM), "c0_f must be > 0, got 0"),
        (lambda: em.real_power_eq6(-1.0, F0_HZ, C0_F, R_OHM, R0_OHM), "u_rms must be >= 0, got -1"),
        (lambda: em.real_power_eq6(1.0, F0_HZ, C0_F, R_OHM, -5.0), "r0_ohm must be >= 0, got -5"),
        (lambda: em.real_power_exact(1.0, F0_HZ, C0_F, L_H, C_F, [1.0, math.nan], R0_OHM), "r_ohm must be > 0, got nan"),
        (lambda: em.resonance_hz(L_H, -C_F), f"c_f must be > 0, got {-C_F:g}"),
        (lambda: em.quality_factor(math.inf, C_F, R_OHM), "l_h must be > 0, got inf"),
    ],
)
def test_out_of_range_inputs_name_argument_range_and_value(call, message):
    with pytest.raises(ValueError) as excinfo:
        call()
    assert str(excinfo.value) == message


def _scalar_reference(u_rms, freq_hz, c0_f, l_h, c_f, r_ohm, r0_ohm):
    """Impedance and exact power of one operating point, with Python's complex numbers: the circuit solved as
    written (C0 parallel to R + jX1 behind the shunt), not through Eq. 3's closed form."""
    omega = 2 * math.pi * freq_hz
    branch = complex(r_ohm, l_h * omega - 1 / (c_f * omega))
    c0 = complex(0.0, -1 / (c0_f * omega))
    z = c0 * branch / (c0 + branch)
    i_motional = u_rms * z / (r0_ohm + z) / branch
    return z, abs(i_motional) ** 2 * r_ohm


def test_vectorised_functions_equal_a_scalar_reference_point_by_point():
    rng = np.random.default_rng(2)
    freqs = rng.uniform(0.9 * F0_HZ, 1.1 * F0_HZ, 30)
    resistances = rng.uniform(100.0, 5000.0, 30)
    shunts = rng.uniform(0.0, 200.0, 30)
    z = em.impedance(freqs, C0_F, L_H, C_F, resistances)
    exact = em.real_power_exact(28.28, freqs, C0_F, L_H, C_F, resistances, shunts)
    q = em.quality_factor(L_H, C_F, resistances)
    for i in range(30):
        z_ref, power_ref = _scalar_reference(28.28, freqs[i], C0_F, L_H, C_F, resistances[i], shunts[i])
        assert z[i] == pytest.approx(z_ref, rel=1e-9)
        assert exact[i] == pytest.approx(power_ref, rel=1e-9)
        assert q[i] == pytest.approx(math.sqrt(L_H / C_F) / resistances[i], rel=1e-12)
        assert em.impedance(freqs[i], C0_F, L_H, C_F, resistances[i]) == z[i]  # scalars broadcast the same
    assert em.resonance_hz(L_H, C_F) == pytest.approx(1 / (2 * math.pi * math.sqrt(L_H * C_F)), rel=1e-12)
    assert isinstance(em.quality_factor(L_H, C_F, R_OHM), np.float64)  # a NumPy scalar for scalar inputs



# --- the device model's quantities: naive references from complex circuit algebra ---------------------------

def _naive_branch_current(u_peak, freq_hz, c0_f, l_h, c_f, r_ohm, r0_ohm):
    """Source -> R0 -> (C0 parallel to the branch): the branch current from the actuator voltage."""
    omega = 2 * math.pi * freq_hz
    z_branch = r_ohm + 1j * omega * l_h + 1 / (1j * omega * c_f)
    z_actuator = 1 / (1j * omega * c0_f + 1 / z_branch)
    v_actuator = u_peak * z_actuator / (r0_ohm + z_actuator)
    return v_actuator / z_branch


def _naive_thevenin(freq_hz, c0_f, r0_ohm):
    """The source seen from the branch: R0 then C0 to ground, as a voltage ratio and an impedance."""
    z_c0 = 1 / (1j * 2 * math.pi * freq_hz * c0_f)
    return z_c0 / (r0_ohm + z_c0), r0_ohm * z_c0 / (r0_ohm + z_c0)


branches = st.tuples(st.floats(5e3, 100e3), st.floats(1e-9, 1e-7), st.floats(20.0, 3000.0), st.floats(10.0, 1e5),
                     st.floats(0.0, 1e3))


@NO_DEADLINE
@given(branches, st.floats(-0.01, 0.01), st.floats(0.1, 100.0))
def test_motional_current_and_amplitude_are_the_circuits(branch, detuning, u_peak):
    f0_hz, c0_f, q, r_ohm, r0_ohm = branch
    l_h = q * r_ohm / (2 * math.pi * f0_hz)
    c_f = 1 / ((2 * math.pi * f0_hz) ** 2 * l_h)
    freq = f0_hz * (1 + detuning)
    naive = _naive_branch_current(u_peak, freq, c0_f, l_h, c_f, r_ohm, r0_ohm)
    assert em.motional_current(u_peak, freq, c0_f, l_h, c_f, r_ohm, r0_ohm) == pytest.approx(naive, rel=1e-9)
    gamma = 0.05
    assert em.plate_amplitude_m(u_peak, freq, c0_f, l_h, c_f, r_ohm, r0_ohm, gamma) == pytest.approx(
        abs(naive) / (gamma * 2 * math.pi * freq), rel=1e-9)
    # |I|^2 R / 2 at peak volts is the exact circuit's power at RMS volts
    assert abs(naive) ** 2 * r_ohm / 2 == pytest.approx(
        em.real_power_exact(u_peak / math.sqrt(2), freq, c0_f, l_h, c_f, r_ohm, r0_ohm), rel=1e-9)


@NO_DEADLINE
@given(branches)
def test_the_loaded_resonance_zeroes_the_loops_reactance(branch):
    f0_hz, c0_f, q, r_ohm, r0_ohm = branch
    l_h = q * r_ohm / (2 * math.pi * f0_hz)
    c_f = 1 / ((2 * math.pi * f0_hz) ** 2 * l_h)
    resonance = float(em.loaded_resonance_hz(c0_f, l_h, c_f, r0_ohm))
    omega = 2 * math.pi * resonance
    _, z_th = _naive_thevenin(resonance, c0_f, r0_ohm)
    loop_x = omega * l_h - 1 / (omega * c_f) + z_th.imag
    assert abs(loop_x) <= 1e-9 * omega * l_h
    assert resonance >= f0_hz * (1 - 1e-12)  # the shunt through C0 is capacitive: it raises the resonance


@NO_DEADLINE
@given(branches, st.floats(-0.01, 0.01))
def test_time_constant_and_detuning_factor_are_the_loaded_loops(branch, detuning):
    f0_hz, c0_f, q, r_ohm, r0_ohm = branch
    l_h = q * r_ohm / (2 * math.pi * f0_hz)
    c_f = 1 / ((2 * math.pi * f0_hz) ** 2 * l_h)
    freq = f0_hz * (1 + detuning)
    ratio, z_th = _naive_thevenin(freq, c0_f, r0_ohm)
    r_loop = r_ohm + z_th.real
    assert em.loaded_time_constant_s(freq, c0_f, l_h, r_ohm, r0_ohm) == pytest.approx(2 * l_h / r_loop, rel=1e-9)
    steady = abs(_naive_branch_current(1.0, freq, c0_f, l_h, c_f, r_ohm, r0_ohm)) ** 2
    worst = abs(ratio / r_loop) ** 2  # the L1 bound of the envelope's impulse response: |V_th| / R_loop
    assert em.detuning_factor(freq, c0_f, l_h, c_f, r_ohm, r0_ohm) == pytest.approx(worst / steady, rel=1e-9)
