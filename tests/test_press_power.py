"""A finger that presses harder while the drive sits at the power cap: the plate's vibration, damped more by the
harder press, must not dissipate more than the cap for longer than the physics forces.

The plate is the device's whole circuit solved directly (a naive reference, not the
runtime's plate model): the shunt R0, C0 and the motional L, C, R at the finger's
force, a three-state linear system held over each DAC sample (zero-order hold), its
state carried across force changes. The power is the motional branch's, ``i^2 R``,
averaged over whole carrier periods.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

from tpad_rt.device import Device
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.shipped import DEVICES_DIR
from tpad_rt.texture import load_compiled

FS_HZ = 192_000
BLOCK = 256
DEVICE = Device.from_file(DEVICES_DIR / "SLG_0.56.yaml")
PRESS_AT_S = 0.1


def _held_system(device: Device, force_n: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The circuit over one sample of held source volts: ``x' = A x + B u`` sampled, states (C0's volts, the
    motional current, C's charge); and R at ``force_n``."""
    l_h, c_f, r_ohm = (float(value) for value in device.motional(force_n))
    r0, c0 = device.shunt_ohm, device.c0_f
    a = np.array([[-1 / (r0 * c0), -1 / c0, 0.0], [1 / l_h, -r_ohm / l_h, -1 / (l_h * c_f)], [0.0, 1.0, 0.0]])
    b = np.array([1 / (r0 * c0), 0.0, 0.0])
    augmented = np.zeros((4, 4))
    augmented[:3, :3], augmented[:3, 3] = a, b
    step = expm(augmented / FS_HZ)
    return step[:3, :3], step[:3, 3], r_ohm


def _motional_power_w(texture: Path, cap_w: float, force_n) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The kernel's drive for a swipe at 100 mm/s pressing with ``force_n(t)``, through the circuit: motional
    power (W) per sample, averaged over six carrier periods."""
    pipeline = Pipeline(DEVICE, load_compiled(texture), FS_HZ,
                        options=RenderOptions(power_budget_w=cap_w, power_avg_w=cap_w))
    pipeline.start()
    block = np.empty(BLOCK, dtype=np.float32)
    state, systems = np.zeros(3), {}
    current, resistance = [], []
    for _ in range(int(2 * PRESS_AT_S * FS_HZ / BLOCK)):
        t_s = pipeline.time_s
        force = force_n(t_s)
        pipeline.push_finger(t_s, 5.0 + 100.0 * t_s, 30.0, force)
        pipeline.render(block)
        if force not in systems:
            systems[force] = _held_system(DEVICE, force)
        step, gain, r_ohm = systems[force]
        for volts in block.astype(np.float64) * DEVICE.volts_per_full_scale:
            current.append(state[1])
            state = step @ state + gain * volts
        resistance += [r_ohm] * BLOCK
    instantaneous_w = np.array(current) ** 2 * np.array(resistance)
    window = round(6 * FS_HZ / DEVICE.carrier_hz)
    return np.convolve(instantaneous_w, np.ones(window) / window, "same")


@pytest.fixture(scope="module")
def texture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("press") / "smooth.yaml"
    path.write_text("description: the least friction everywhere\nkind: grating\nperiod_mm: 5\n"
                    "friction: {low: 0.1, high: 0.1}\n")
    return path


def _cap_w() -> float:
    """A cap that binds without contact: the drive sits at it before the press."""
    return 0.35 * float(DEVICE.power_w_per_v2(0.0)) * DEVICE.max_voltage_v**2


def test_a_press_over_10_ms_keeps_the_plate_under_the_cap(texture: Path) -> None:
    """Pressed from 0 to 2 N in 10 ms (R doubles): the shaper brakes the plate down as the cap falls, instead of
    driving on as if the plate held only what the cap allows at the new force."""
    cap_w = _cap_w()

    def force_n(t_s: float) -> float:
        return round(2.0 * min(max((t_s - PRESS_AT_S) / 0.01, 0.0), 1.0), 3)

    power_w = _motional_power_w(texture, cap_w, force_n)
    settled = slice(int(0.05 * FS_HZ), -BLOCK)
    before = power_w[int(0.05 * FS_HZ):int(PRESS_AT_S * FS_HZ)]
    assert before.max() > 0.9 * cap_w  # the drive sits at the cap before the press
    assert power_w[settled].max() <= cap_w * 1.02


def test_a_sudden_press_is_braked_to_the_cap_within_the_plates_time_constant(texture: Path) -> None:
    """Pressed from 0 to 2 N at once: the vibration the plate holds dissipates in the harder press at once (no
    drive can stop that), and the kernel brakes it back to within the guard's 2 % of the cap within one envelope
    time constant (a drive that went on as before took twice that)."""
    cap_w = _cap_w()
    power_w = _motional_power_w(texture, cap_w, lambda t_s: 2.0 if t_s >= PRESS_AT_S else 0.0)
    settled = slice(int(0.05 * FS_HZ), -BLOCK)
    over_s = np.count_nonzero(power_w[settled] > 1.02 * cap_w) / FS_HZ
    held_w = float(np.max(power_w[settled]))
    resistance_ratio = float(DEVICE.motional(2.0)[2] / DEVICE.motional(0.0)[2])
    assert held_w > 1.3 * cap_w  # the press itself takes the plate over: what there is to brake
    assert held_w <= cap_w * resistance_ratio * 1.02  # no more than the same vibration in the harder press
    assert 0 < over_s <= float(DEVICE.envelope_time_constant_s(2.0))
