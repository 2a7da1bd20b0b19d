"""The simulated plate is the loaded circuit, detuning included, and no drive within the power cap's volts can
make it draw more than the cap (the kernel's power table is the detuning bound, not the steady power)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tpad_rt.device import Device
from tpad_rt.kernel.sim import COEF_SIZE, SIM_STATE_SIZE, resonate
from tpad_rt.outputs.sim import SimOutput, plate_resonator
from tpad_rt.shipped import DEVICES_DIR

FS_HZ = 192_000
#: SLG_0.4 rings longest (Q about 1080): at 2 N its carrier sits 28 Hz below the loaded resonance, a detuning of
#: about 1.3 envelope bandwidths, where a transient overshoots its steady level by several per cent.
SLG04 = Device.from_file(DEVICES_DIR / "SLG_0.4.yaml")
FORCE_N = 2.0


def _envelope_m(device: Device, drive_v: np.ndarray, force_n: float) -> np.ndarray:
    """The plate's amplitude envelope (m) for the carrier modulated by ``drive_v`` (V peak, one per sample)."""
    coef, state = np.zeros(COEF_SIZE), np.zeros(SIM_STATE_SIZE)
    plate_resonator(device, force_n, FS_HZ, coef)
    n = np.arange(len(drive_v))
    samples = (drive_v / device.volts_per_full_scale * np.sin(2 * np.pi * device.carrier_hz * n / FS_HZ))
    envelope = np.zeros(len(drive_v))
    resonate(samples.astype(np.float32), device.volts_per_full_scale, coef, state, envelope)
    return envelope


def _power_w(device: Device, envelope_m: np.ndarray, force_n: float) -> np.ndarray:
    """Power into the motional branch (W) at plate amplitude ``envelope_m``: ``|I_g|^2 R / 2``, ``|I_g| = gamma w X``."""
    r_ohm = float(device.motional(force_n)[2])
    current_a = device.gamma_n_per_v * 2 * np.pi * device.carrier_hz * envelope_m
    return current_a**2 * r_ohm / 2


def test_the_simulated_plate_resonates_at_the_loaded_resonance_with_the_loaded_time_constant() -> None:
    device = Device.default()
    coef = np.zeros(COEF_SIZE)
    plate_resonator(device, 0.0, FS_HZ, coef)
    # The resonator's free ring-down: zero drive from a displaced state decays with the loaded tau
    state, envelope = np.array([1e-6, 0.0]), np.zeros(FS_HZ // 50)
    resonate(np.zeros(len(envelope), np.float32), 1.0, coef, state, envelope)
    tau_s = float(device.envelope_time_constant_s(0.0))
    n = round(tau_s * FS_HZ)
    assert envelope[n - 1] / 1e-6 == pytest.approx(math.exp(-1.0), rel=2e-3)
    assert tau_s < float(device.quality_factor(0.0)) / (math.pi * device.carrier_hz)  # the shunt damps it


def test_a_detuned_step_settles_at_the_carriers_amplitude_after_the_detuned_overshoot() -> None:
    volts = 20.0
    tau_s = float(SLG04.envelope_time_constant_s(FORCE_N))
    envelope = _envelope_m(SLG04, np.full(int(15 * tau_s * FS_HZ), volts), FORCE_N)
    steady = float(SLG04.amplitude_m_per_v(FORCE_N)) * volts
    assert envelope[-200:].mean() == pytest.approx(steady, rel=2e-3)
    # The complex envelope a' = -(1/tau - j D) a + b u rises as |1 - exp(-(1/tau - j D) t)| times its steady
    # level: it overshoots, by more than exp(-pi / (D tau)), the value at D t = pi
    detuning_rad_s = 2 * math.pi * abs(float(SLG04.motional_resonance_hz(FORCE_N)) - SLG04.carrier_hz)
    t_s = np.linspace(0.0, 15 * tau_s, 100_001)
    overshoot = float(np.max(np.abs(1 - np.exp(-(1 / tau_s - 1j * detuning_rad_s) * t_s)))) - 1
    assert overshoot > math.exp(-math.pi / (detuning_rad_s * tau_s)) > 0.05
    assert envelope.max() / steady - 1 == pytest.approx(overshoot, rel=0.02)


def _worst_drive_v(device: Device, volts: float, force_n: float, seconds: float) -> np.ndarray:
    """The drive that pumps a detuned plate hardest within +-``volts``: full volts, its sign flipped every half
    beat period (it follows the phase the detuning turns the envelope through)."""
    detuning_hz = abs(float(device.motional_resonance_hz(force_n)) - device.carrier_hz)
    t_s = np.arange(int(seconds * FS_HZ)) / FS_HZ
    return volts * np.sign(np.cos(2 * np.pi * detuning_hz * t_s) + 1e-12)


@pytest.mark.parametrize("label", ["SLG_0.4", "SLG_0.56", "Gorilla_0.8"])
def test_no_drive_within_the_caps_volts_draws_more_than_the_cap(label: str) -> None:
    device = Device.from_file(DEVICES_DIR / f"{label}.yaml")
    cap_w = device.power_budget_w
    for force_n in (0.0, 1.0, FORCE_N):
        volts = min(device.max_voltage_v, math.sqrt(cap_w / float(device.power_w_per_v2(force_n))))
        tau_s = float(device.envelope_time_constant_s(force_n))
        for drive in (np.full(int(20 * tau_s * FS_HZ), volts), _worst_drive_v(device, volts, force_n, 20 * tau_s)):
            power_w = _power_w(device, _envelope_m(device, drive, force_n), force_n)
            assert power_w.max() <= cap_w * (1 + 2e-3), (force_n, power_w.max() / cap_w)


def test_the_steady_power_alone_would_let_a_detuned_plate_exceed_the_cap() -> None:
    """The reason the kernel's table is the bound: capped by the steady power, the worst drive overshoots."""
    cap_w = SLG04.power_budget_w
    volts = math.sqrt(cap_w / float(SLG04.steady_power_w_per_v2(FORCE_N)))
    tau_s = float(SLG04.envelope_time_constant_s(FORCE_N))
    power_w = _power_w(SLG04, _envelope_m(SLG04, _worst_drive_v(SLG04, volts, FORCE_N, 20 * tau_s), FORCE_N),
                       FORCE_N)
    assert power_w.max() > 1.5 * cap_w


def test_sim_output_records_the_detuned_plate() -> None:
    output = SimOutput(SLG04, FS_HZ)
    volts = 20.0
    n = np.arange(int(0.1 * FS_HZ))
    drive = (volts / SLG04.volts_per_full_scale * np.sin(2 * np.pi * SLG04.carrier_hz * n / FS_HZ)).astype(np.float32)
    for start in range(0, len(drive), 256):
        output.write(drive[start:start + 256], {"force_n": FORCE_N, "speed_mm_s": 100.0})
    amplitude_um = output.measurements()["plate_amplitude_um"]
    steady_um = float(SLG04.amplitude_m_per_v(FORCE_N)) * volts * 1e6
    assert amplitude_um[-1] == pytest.approx(steady_um, rel=3e-3)
    assert amplitude_um.max() > 1.05 * steady_um


def test_the_kernels_drive_keeps_the_detuned_plate_under_its_power_cap(tmp_path) -> None:
    """End to end: the render kernel, capped at a power budget it must hit, drives SLG_0.4 pressed at 2 N (its
    resonance 28 Hz off the carrier) through a texture that switches at that beat, the worst case for a detuned
    plate; the circuit's motional power, from the simulated plate's envelope sample by sample, stays under the
    cap, where a cap on the steady power would let it through by half as much again."""
    from tpad_rt.pipeline import Pipeline, RenderOptions
    from tpad_rt.texture import load_compiled

    cap_w = 0.01  # binds: SLG_0.4 at 2 N would take 0.09 W at 40 V
    assert float(SLG04.power_w_per_v2(FORCE_N)) * SLG04.max_voltage_v**2 > 5 * cap_w
    beat_hz = abs(float(SLG04.motional_resonance_hz(FORCE_N)) - SLG04.carrier_hz)
    speed_mm_s = 100.0
    texture = tmp_path / "beat.yaml"
    texture.write_text(f"kind: grating\nwaveform: square\nperiod_mm: {speed_mm_s / beat_hz!r}\n"
                       "friction: {low: 0.2, high: 1.0}\ndescription: switches at the detuned plate's beat\n")
    options = RenderOptions(power_budget_w=cap_w, power_avg_w=cap_w, default_force_n=FORCE_N)
    pipeline = Pipeline(SLG04, load_compiled(texture), FS_HZ, options=options)
    pipeline.start()
    block = np.empty(256, dtype=np.float32)
    drive = []
    for _ in range(int(0.6 * FS_HZ / len(block))):
        t_s = pipeline.time_s
        pipeline.push_finger(t_s, 5.0 + speed_mm_s * t_s, 30.0, FORCE_N)
        pipeline.render(block)
        drive.append(block.copy())
    samples = np.concatenate(drive)
    coef, state, envelope = np.zeros(COEF_SIZE), np.zeros(SIM_STATE_SIZE), np.zeros(len(samples))
    plate_resonator(SLG04, FORCE_N, FS_HZ, coef)
    resonate(samples, SLG04.volts_per_full_scale, coef, state, envelope)
    power_w = _power_w(SLG04, envelope, FORCE_N)
    # The capped volts hold the steady power to cap / detuning factor (0.41 of it here); the beat's transients
    # take the plate above that, and never above the cap
    assert power_w.max() > 1.1 * cap_w / float(SLG04.detuning_factor(FORCE_N))
    assert power_w.max() <= cap_w * (1 + 2e-3), power_w.max() / cap_w
