"""The simulated plate: kernel vs the resonator's physics and vs slow SciPy references."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal
from scipy.integrate import solve_ivp

from tpad_rt.device import Device
from tpad_rt.kernel.sim import COEF_SIZE, SIM_STATE_SIZE, resonate, resonator_coefficients
from tpad_rt.outputs import open_output
from tpad_rt.outputs.sim import SimOutput
from tpad_rt.physics.friction import relative_friction

DEVICE = Device.default()
F0_HZ = DEVICE.carrier_hz
VOLTS_PER_FS = DEVICE.volts_per_full_scale


def _sine(volts: np.ndarray | float, freq_hz: float, fs_hz: int, samples: int) -> np.ndarray:
    """DAC samples of a sine of peak ``volts`` (per sample or constant) at ``freq_hz``."""
    t_s = np.arange(samples) / fs_hz
    return (np.asarray(volts) / VOLTS_PER_FS * np.sin(2 * np.pi * freq_hz * t_s)).astype(np.float32)


def _envelope(drive: np.ndarray, q: float, gain_m_per_v: float, fs_hz: int, block: int | None = None) -> np.ndarray:
    """The kernel's envelope (m) for ``drive``, rendered in blocks of ``block`` samples (default: one)."""
    coef, state, envelope = np.zeros(COEF_SIZE), np.zeros(SIM_STATE_SIZE), np.zeros(len(drive))
    resonator_coefficients(F0_HZ, q, gain_m_per_v, F0_HZ, fs_hz, coef)
    step = block or len(drive)
    for start in range(0, len(drive), step):
        resonate(drive[start:start + step], VOLTS_PER_FS, coef, state, envelope[start:start + step])
    return envelope


def _fitted_tau_s(envelope: np.ndarray, final: float, fs_hz: int, tau_s: float) -> float:
    """Time constant of ``final * (1 - exp(-t / tau))`` fitted to a step response over 0.2-3 tau."""
    t_s = (np.arange(len(envelope)) + 1) / fs_hz
    window = (t_s > 0.2 * tau_s) & (t_s < 3 * tau_s)
    slope = np.polyfit(t_s[window], np.log(1 - envelope[window] / final), 1)[0]
    return -1 / slope


@pytest.mark.parametrize("fs_hz", [96000, 192000])
@pytest.mark.parametrize("force_n", [0.0, 0.5, 2.0])
def test_step_response_time_constant_and_steady_state(fs_hz: int, force_n: float) -> None:
    q = float(DEVICE.quality_factor(force_n))
    gain = float(DEVICE.amplitude_m_per_v(force_n))
    tau_s = q / (math.pi * F0_HZ)
    volts = 30.0
    envelope = _envelope(_sine(volts, F0_HZ, fs_hz, int(12 * tau_s * fs_hz)), q, gain, fs_hz)
    settled = envelope[-int(fs_hz / F0_HZ) * 10:].mean()
    assert settled == pytest.approx(gain * volts, rel=0.01)
    assert _fitted_tau_s(envelope, gain * volts, fs_hz, tau_s) == pytest.approx(tau_s, rel=0.02)


def test_q_override_sets_the_time_constant() -> None:
    fs_hz, q = 192000, 80.0
    tau_s = q / (math.pi * F0_HZ)
    output = open_output("sim://?q=80", device=DEVICE, fs_hz=fs_hz)
    drive = _sine(20.0, F0_HZ, fs_hz, int(10 * tau_s * fs_hz))
    block = {"force_n": 0.5, "speed_mm_s": 100.0}
    for start in range(0, len(drive), 1):  # one-sample blocks: the per-block mean is the envelope
        output.write(drive[start:start + 1], block)
    envelope_m = output.measurements()["plate_amplitude_um"] * 1e-6
    final = float(DEVICE.amplitude_m_per_v(0.5)) * 20.0
    assert _fitted_tau_s(envelope_m, final, fs_hz, tau_s) == pytest.approx(tau_s, rel=0.02)


@pytest.mark.parametrize("offset_bandwidths", [-1.0, 1.0, 3.0])
def test_off_resonance_drop_matches_the_resonator(offset_bandwidths: float) -> None:
    """A drive ``k f0 / Q`` off resonance settles at the continuous resonator's |H(f)| / |H(f0)|."""
    fs_hz, force_n = 192000, 0.5
    q, gain = float(DEVICE.quality_factor(force_n)), float(DEVICE.amplitude_m_per_v(force_n))
    freq_hz = F0_HZ + offset_bandwidths * F0_HZ / q
    tau_s = q / (math.pi * F0_HZ)
    envelope = _envelope(_sine(10.0, freq_hz, fs_hz, int(14 * tau_s * fs_hz)), q, gain, fs_hz)
    settled = envelope[-int(fs_hz / F0_HZ * 50):].mean()  # averages the beat's last traces
    omega0, omega = 2 * np.pi * F0_HZ, 2 * np.pi * freq_hz
    ratio = (omega0**2 / q) / abs(omega0**2 - omega**2 + 1j * omega * omega0 / q)
    assert settled / (gain * 10.0) == pytest.approx(ratio, rel=0.01)
    if offset_bandwidths == 1.0:
        assert ratio == pytest.approx(1 / math.sqrt(5), rel=0.01)


def _modulated_drive(fs_hz: int, seconds: float) -> np.ndarray:
    """A carrier at f0 whose peak volts step, ramp and wobble (as a texture would ask)."""
    t_s = np.arange(int(seconds * fs_hz)) / fs_hz
    volts = np.where(t_s < seconds / 3, 25.0, 10.0) + 5.0 * np.sin(2 * np.pi * 150 * t_s) * (t_s > seconds / 2)
    return _sine(volts, F0_HZ, fs_hz, len(t_s))


def test_kernel_equals_scipy_zero_order_hold_discretisation() -> None:
    """Same resonator discretised by scipy.signal.cont2discrete, normalised by a linear solve, run by dlsim."""
    fs_hz, force_n = 192000, 0.8
    q, gain = float(DEVICE.quality_factor(force_n)), float(DEVICE.amplitude_m_per_v(force_n))
    omega0 = 2 * np.pi * F0_HZ
    a = np.array([[0.0, 1.0], [-omega0**2, -omega0 / q]])
    b = np.array([[0.0], [1.0]])
    ad, bd, cd, dd, _ = signal.cont2discrete((a, b, np.eye(2), np.zeros((2, 1))), 1 / fs_hz, method="zoh")
    z = np.exp(2j * np.pi * F0_HZ / fs_hz)
    response = np.linalg.solve(z * np.eye(2) - ad, bd[:, 0])[0]  # steady x per unit input at f0
    bd = bd * gain / abs(response)
    drive = _modulated_drive(fs_hz, 0.01)
    volts = drive.astype(np.float64) * VOLTS_PER_FS
    _, _, states = signal.dlsim((ad, bd, np.eye(2), np.zeros((2, 1)), 1 / fs_hz), volts)
    after = np.vstack([states[1:], (ad @ states[-1] + bd[:, 0] * volts[-1])[None, :]])  # state after each sample
    reference = np.hypot(after[:, 0], after[:, 1] / omega0)
    kernel = _envelope(drive, q, gain, fs_hz, block=64)
    assert np.max(np.abs(kernel - reference)) < 1e-9 * np.max(reference)


def test_kernel_follows_the_continuous_resonator_solved_by_solve_ivp() -> None:
    """Continuous ODE driven by the band-limited drive (its envelope times sin), solved by DOP853."""
    fs_hz, force_n, seconds = 192000, 0.5, 0.006
    q, gain = float(DEVICE.quality_factor(force_n)), float(DEVICE.amplitude_m_per_v(force_n))
    omega0 = 2 * np.pi * F0_HZ
    b = gain * omega0**2 / q  # steady amplitude at resonance: b Q / w0^2 = gain per volt

    def peak_volts(t_s: float) -> float:
        return 25.0 if t_s < seconds / 2 else 10.0

    def rhs(t_s: float, state: np.ndarray) -> list[float]:
        x_m, v_m_s = state
        u = peak_volts(t_s) * math.sin(omega0 * t_s)
        return [v_m_s, b * u - omega0 / q * v_m_s - omega0**2 * x_m]

    t_eval = (np.arange(int(seconds * fs_hz)) + 1) / fs_hz
    solution = solve_ivp(rhs, (0.0, t_eval[-1]), [0.0, 0.0], method="DOP853", t_eval=t_eval,
                         rtol=1e-9, atol=1e-15, max_step=1 / fs_hz)
    reference = np.hypot(solution.y[0], solution.y[1] / omega0)
    drive = _sine(np.array([peak_volts(t) for t in t_eval - 1 / fs_hz]), F0_HZ, fs_hz, len(t_eval))
    kernel = _envelope(drive, q, gain, fs_hz, block=64)
    assert np.max(np.abs(kernel - reference)) < 0.005 * gain * 25.0


def test_blocks_of_any_size_give_identical_results() -> None:
    drive = _modulated_drive(192000, 0.005)
    one = _envelope(drive, 275.0, 4e-8, 192000)
    assert np.array_equal(one, _envelope(drive, 275.0, 4e-8, 192000, block=16))
    assert np.array_equal(one, _envelope(drive, 275.0, 4e-8, 192000, block=4096))


@pytest.mark.parametrize(("speed_mm_s", "used_mm_s"), [(100.0, 100.0), (1.0, 5.0), (math.nan, 5.0)])
def test_achieved_friction_is_the_forward_model_at_the_plate_amplitude(speed_mm_s: float, used_mm_s: float) -> None:
    fs_hz, force_n, volts = 192000, 0.5, 20.0
    output = SimOutput(DEVICE, fs_hz)
    drive = _sine(volts, F0_HZ, fs_hz, int(0.04 * fs_hz))  # 14 time constants
    for start in range(0, len(drive), 64):
        output.write(drive[start:start + 64], {"force_n": force_n, "speed_mm_s": speed_mm_s})
    measured = output.measurements()
    amplitude_m = float(DEVICE.amplitude_m_per_v(force_n)) * volts
    assert measured["plate_amplitude_um"][-1] == pytest.approx(amplitude_m * 1e6, rel=1e-3)
    expected = relative_friction(amplitude_m, F0_HZ, used_mm_s * 1e-3, DEVICE.mu0, DEVICE.poisson, DEVICE.psi_star)
    assert measured["achieved_mu"][-1] == pytest.approx(float(expected), rel=1e-3)
    assert len(measured["achieved_mu"]) == len(drive) // 64


def test_measurements_are_kept_until_taken() -> None:
    """A SimOutput keeps what it measured until taken (the paced driver takes after every step): the names are
    there with no block, a take hands over and forgets."""
    output = SimOutput(DEVICE, 192000)
    assert {name: len(values) for name, values in output.measurements().items()} == {
        "plate_amplitude_um": 0, "achieved_mu": 0}
    block = {"force_n": 0.5, "speed_mm_s": 100.0, "x_mm": 30.0}
    for _ in range(3):
        output.write(np.full(64, 0.5, dtype=np.float32), block)
    taken = output.take_measurements()
    assert len(taken["achieved_mu"]) == len(taken["plate_amplitude_um"]) == 3
    assert output.latest() == {"plate_amplitude_um": taken["plate_amplitude_um"][-1],
                               "achieved_mu": taken["achieved_mu"][-1]}
    assert [len(values) for values in output.measurements().values()] == [0, 0]


def test_a_plate_rung_down_rests_at_zero_not_in_subnormal_floats() -> None:
    """After the drive stops, the ring-down ends with the state at exactly 0 (NEGLIGIBLE_M), never in subnormal
    floats (every operation on one costs up to 100x more), and a drive afterwards rings it up as from rest."""
    q = float(DEVICE.quality_factor(0.5))
    coef, state = np.zeros(COEF_SIZE), np.zeros(SIM_STATE_SIZE)
    resonator_coefficients(F0_HZ, q, float(DEVICE.amplitude_m_per_v(0.5)), F0_HZ, 192000, coef)
    drive = _sine(30.0, F0_HZ, 192000, 4096)
    envelope = np.zeros(len(drive))
    resonate(drive, VOLTS_PER_FS, coef, state, envelope)
    silence = np.zeros(4096, dtype=np.float32)
    for _ in range(400):  # 8.5 s of silence in blocks, long enough to decay through every float
        resonate(silence, VOLTS_PER_FS, coef, state, envelope)
        assert np.all((state == 0.0) | (np.abs(state) >= np.finfo(np.float64).tiny)), state
    assert np.all(state == 0.0)
    again = np.zeros(len(drive))
    resonate(drive, VOLTS_PER_FS, coef, state, again)
    assert np.array_equal(again, _envelope(drive, q, float(DEVICE.amplitude_m_per_v(0.5)), 192000))
