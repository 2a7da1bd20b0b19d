"""A finger that presses harder while the drive sits at the power cap: the plate's vibration, damped more by the
harder press, must not dissipate more than the cap for longer than the physics forces.

The plate is the device's whole circuit solved directly (a naive reference, not the
runtime's plate model): the shunt R0, C0 and the motional L, C, R at the finger's
force, a three-state linear system held over each DAC sample (zero-order hold), its
state carried across force changes. The power is the motional branch's, ``R |i|^2 / 2``
with the current's amplitude taken sample by sample (from the current and the charge).

The floor a sudden press is judged against is full reverse braking: the same run up to
the first control step that sees the new force, then the drive at ``-max_voltage_v`` on
the kernel's own carrier in anti-phase, through the same circuit; the time from that step
until its power is back under 1.02 times the cap before the plate comes to rest. No drive
within the volts brings it back sooner.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from tpad_rt.config import check_file
from tpad_rt.device import Device
from tpad_rt.kernel import layout
from tpad_rt.outputs.sim import SimOutput
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.shipped import DEVICES_DIR
from tpad_rt.texture import load_compiled

FS_HZ = 192_000
STEP = 32  # the default control interval: one block a control step, so each step sees its block's finger sample
PRESS_AT_S = 0.1
OVER = 1.02  # "back under the cap": within 2 % of it (the press guard's threshold)
FLOOR_FACTOR = 1.2  # the drive must be back within this many times the full-reverse floor
SHIFT = 0.005  # the most the property test's devices move their resonance from 0 to 2 N (a fraction)
REVERSE_S = 0.02  # how long a full-reverse floor is simulated for: the plate is at rest well before


def _held_system(device: Device, force_n: float) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The circuit over one sample of held source volts: ``x' = A x + B u`` sampled, states (C0's volts, the
    motional current, C's charge); and R and the motional branch's own resonance (rad/s) at ``force_n``."""
    l_h, c_f, r_ohm = (float(value) for value in device.motional(force_n))
    r0, c0 = device.shunt_ohm, device.c0_f
    a = np.array([[-1 / (r0 * c0), -1 / c0, 0.0], [1 / l_h, -r_ohm / l_h, -1 / (l_h * c_f)], [0.0, 1.0, 0.0]])
    b = np.array([1 / (r0 * c0), 0.0, 0.0])
    augmented = np.zeros((4, 4))
    augmented[:3, :3], augmented[:3, 3] = a, b
    step = expm(augmented / FS_HZ)
    return step[:3, :3], step[:3, 3], r_ohm, 1 / np.sqrt(l_h * c_f)


def _circuit(device: Device, volts: np.ndarray, forces_n: np.ndarray, state: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """The circuit from ``state`` (C0's volts, the motional current, C's charge) driven by ``volts`` at
    ``forces_n``: the motional power (W) before each sample, ``R |i|^2 / 2`` with the current's amplitude from the
    current and the charge in quadrature, ``|i|^2 = i^2 + (w q)^2`` (exact for a sinusoid at ``w``, the branch's
    resonance: no averaging window, so no time smeared), and the state before each sample."""
    systems: dict[float, tuple[np.ndarray, np.ndarray, float, float]] = {}
    power_w, states = np.empty(len(volts)), np.empty((len(volts), 3))
    for k, (source_v, force_n) in enumerate(zip(volts, forces_n)):
        if force_n not in systems:
            systems[force_n] = _held_system(device, force_n)
        step, gain, r_ohm, w_rad_s = systems[force_n]
        power_w[k], states[k] = r_ohm * (state[1] ** 2 + (w_rad_s * state[2]) ** 2) / 2, state
        state = step @ state + gain * source_v
    return power_w, states


@pytest.fixture(scope="module")
def texture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("press") / "smooth.yaml"
    path.write_text("description: the least friction everywhere\nkind: grating\nperiod_mm: 5\n"
                    "friction: {low: 0.1, high: 0.1}\n")
    return path


def _cap_w(device: Device) -> float:
    """A cap that binds without contact: the drive sits at it before the press."""
    return 0.35 * float(device.power_w_per_v2(0.0)) * device.max_voltage_v**2


class Run:
    """A swipe at 100 mm/s pressing with ``force_n(t)``, rendered in blocks of ``block`` frames (one finger
    sample a block, pushed before it renders, as a DAC's callback or ``sim://``'s paced driver take them), with
    the simulated plate of ``sim://`` fed the same blocks; the sample of the block at ``bad_finger_at_s``, if
    given, written into the ring with an absurd position (as a producer that skipped the checks would)."""

    def __init__(self, device: Device, texture: Path, force_n: Callable[[float], float], track: bool = False,
                 block: int = STEP, preemphasis: bool | None = None, bad_finger_at_s: float | None = None):
        self.device, self.cap_w, self.block = device, _cap_w(device), block
        options = RenderOptions(power_budget_w=self.cap_w, power_avg_w=self.cap_w, track=track,
                                preemphasis=preemphasis)
        pipeline = Pipeline(device, load_compiled(texture), FS_HZ, options=options)
        self.sim = SimOutput(device, FS_HZ)
        pipeline.start()
        samples = np.empty(block, dtype=np.float32)
        blocks, forces, carriers = [], [], []
        for _ in range(int(2 * PRESS_AT_S * FS_HZ / block)):
            t_s = pipeline.time_s
            if bad_finger_at_s is not None and abs(t_s - bad_finger_at_s) < 0.5 * block / FS_HZ:
                finger, count = pipeline.arrays.finger, pipeline.arrays.finger_count
                finger[count[0] % len(finger)] = (t_s, 1e12, 30.0, force_n(t_s), 1.0)
                count[0] += 1
            else:
                pipeline.push_finger(t_s, 5.0 + 100.0 * t_s, 30.0, force_n(t_s))
            pipeline.render(samples)
            self.sim.write(samples, pipeline.last_telemetry_row())
            blocks.append(samples.astype(np.float64) * device.volts_per_full_scale)
            forces.append(force_n(t_s))
            carriers.append(pipeline.arrays.state[layout.STATE_STEP_CARRIER_HZ])
        self.volts = np.concatenate(blocks)
        self.forces_n = np.repeat(forces, block)
        # The carrier the kernel rendered each sample at (fixed, or tracked at the block's force), and its phase.
        carrier_hz = np.repeat(carriers, block)
        self.phase = np.r_[0.0, np.cumsum(carrier_hz[:-1] / FS_HZ)]
        self.telemetry = pipeline.drain_telemetry()
        self.over_cap_blocks = pipeline.over_cap_blocks
        self.fault_causes = pipeline.faults()["fault_causes"]
        self.power_w, self.states = _circuit(device, self.volts, self.forces_n, np.zeros(3))
        self.pressed = int(np.argmax(self.forces_n != self.forces_n[0]))  # the first step that sees the new force

    def seconds_over(self, power_w: np.ndarray) -> float:
        """From the press's first step to the last sample over the cap (s), the last block left out."""
        over = np.nonzero(power_w[self.pressed:-self.block] > OVER * self.cap_w)[0]
        return (over[-1] + 1) / FS_HZ if len(over) else 0.0

    def reverse_floor_s(self, start: int | None = None) -> float:
        """Full reverse braking from sample ``start`` (the press's first step by default): the kernel's drive
        before it, then ``-max_voltage_v`` on the kernel's own carrier (in anti-phase to it), for REVERSE_S or
        until the plate is still. The time from ``start`` until the circuit's power is back under the cap before
        the plate stops (s); 0 if it is not over (braking on would ring the plate up in anti-phase)."""
        start = self.pressed if start is None else start
        stop = start + round(REVERSE_S * FS_HZ)
        volts = -self.device.max_voltage_v * np.sin(2 * np.pi * self.phase[start:stop])
        power_w, _ = _circuit(self.device, volts, self.forces_n[start:stop], self.states[start])
        still = int(np.argmin(power_w))
        assert still < len(power_w) - 1, "full reverse does not bring the plate to rest within REVERSE_S"
        over = np.flatnonzero(power_w[:still] > OVER * self.cap_w)
        return (over[-1] + 1) / FS_HZ if len(over) else 0.0

    def excursions_beyond_floors(self) -> list[tuple[float, float]]:
        """For each force change (a sudden press of its own), ``(s, floor_s)``: the time from its first step until
        the plate is back under the cap (0 if it does not go over before the next change), and that change's
        full-reverse floor."""
        changes = np.r_[np.flatnonzero(np.diff(self.forces_n)) + 1, len(self.forces_n) - self.block]
        result = []
        for start, stop in zip(changes[:-1], changes[1:]):
            over = np.flatnonzero(self.power_w[start:stop] > OVER * self.cap_w)
            result.append(((over[-1] + 1) / FS_HZ if len(over) else 0.0, self.reverse_floor_s(int(start))))
        return result


def _sudden(force_n: float) -> Callable[[float], float]:
    return lambda t_s: force_n if t_s >= PRESS_AT_S else 0.0


@pytest.mark.parametrize(("block", "preemphasis"), [(STEP, None), (64, None), (256, None), (64, False)],
                         ids=["step-blocks", "64-frames", "256-frames", "no-preemphasis"])
@pytest.mark.parametrize("track", [False, True], ids=["fixed", "track"])
@pytest.mark.parametrize("name", ["SLG_0.56", "SLG_0.4"])
def test_a_sudden_press_is_braked_back_under_the_cap_near_the_full_reverse_floor(
        texture: Path, name: str, track: bool, block: int, preemphasis: bool | None) -> None:
    """Pressed from 0 to 2 N at once: the vibration the plate holds dissipates in the harder press at once (no
    drive can stop that); the kernel brakes it back under the cap within 1.2 times the time full reverse braking
    takes, and its telemetry shows the excursion (a drive that braked at the cap's volts and drove on took 4.6-12
    times the floor). Blocks of 64 frames are the default of ``audio://`` and ``sim://`` alike; the kernel's
    samples do not depend on how a stream is cut into blocks (test_render_properties), only on when the finger
    sample arrives: here before the block it is due in."""
    device = Device.from_file(DEVICES_DIR / f"{name}.yaml")
    run = Run(device, texture, _sudden(2.0), track, block, preemphasis)
    floor_s = run.reverse_floor_s()
    assert np.max(run.power_w[run.pressed:]) > 1.3 * run.cap_w  # the press itself takes the plate over
    assert run.seconds_over(run.power_w) <= FLOOR_FACTOR * floor_s, (run.seconds_over(run.power_w), floor_s)
    # The telemetry: the drive's estimate stays within the cap, the plate's shows the excursion, and it is counted.
    plate_w, power_w = run.telemetry["plate_w"], run.telemetry["power_w"]
    assert np.max(power_w) <= run.cap_w
    pressed_block = run.pressed // block
    assert np.max(plate_w[:pressed_block]) <= run.cap_w < plate_w[pressed_block]
    assert run.over_cap_blocks == np.count_nonzero(plate_w > run.cap_w) >= 1
    # sim:// was fed the same drive: its plate, a resonator of its own, is back down with the circuit's.
    amplitude_um = run.sim.measurements()["plate_amplitude_um"]
    settled_block = pressed_block + math.ceil(2 * floor_s * FS_HZ / block)
    assert amplitude_um[settled_block] < amplitude_um[pressed_block - 1]


@pytest.mark.parametrize("steps_from_press", [-1, 0, 1])
@pytest.mark.parametrize("name", ["SLG_0.56", "SLG_0.4"])
def test_a_bad_finger_sample_at_the_press_does_not_blind_the_guard(texture: Path, name: str,
                                                                    steps_from_press: int) -> None:
    """A finger sample with an absurd position a step before, at or after the press: that step is a fault (the
    gate closes for it), but the plate's model follows the plate through it, so the press is still seen, counted
    and braked: back under the cap within the floor's bound plus the two steps the fault takes (its own, and the
    ramp back)."""
    device = Device.from_file(DEVICES_DIR / f"{name}.yaml")
    floor_s = Run(device, texture, _sudden(2.0)).reverse_floor_s()
    run = Run(device, texture, _sudden(2.0), bad_finger_at_s=PRESS_AT_S + steps_from_press * STEP / FS_HZ)
    assert run.fault_causes == ["finger"]
    assert run.over_cap_blocks >= 1 and np.max(run.telemetry["plate_w"]) > 1.3 * run.cap_w
    assert run.seconds_over(run.power_w) <= FLOOR_FACTOR * floor_s + 2 * STEP / FS_HZ, \
        (run.seconds_over(run.power_w), floor_s)


@pytest.mark.parametrize("preemphasis", [None, False], ids=["preemphasis", "no-preemphasis"])
@pytest.mark.parametrize("name", ["SLG_0.56", "SLG_0.4"])
def test_a_finger_wobbling_at_the_cap_is_no_press(texture: Path, name: str, preemphasis: bool | None) -> None:
    """A force wobbling by 1.5 % around 1 N while the drive sits at the cap: nothing is counted over the cap, the
    plate's modelled power stays within the guard's 2 %, and so does the circuit's."""
    device = Device.from_file(DEVICES_DIR / f"{name}.yaml")

    def force_n(t_s: float) -> float:
        return round(1.0 + 0.01 * math.sin(2 * math.pi * 37 * t_s) + 0.005 * math.sin(2 * math.pi * 211 * t_s), 4)

    run = Run(device, texture, force_n, preemphasis=preemphasis)
    settled = slice(int(0.05 * FS_HZ), -STEP)
    assert run.power_w[settled].max() <= OVER * run.cap_w
    assert np.max(run.telemetry["power_w"]) > 0.99 * run.cap_w  # the drive sits at the cap
    assert run.over_cap_blocks == 0 and np.max(run.telemetry["plate_w"]) <= OVER * run.cap_w


def test_a_press_over_10_ms_keeps_the_plate_under_the_cap(texture: Path) -> None:
    """Pressed from 0 to 2 N in 10 ms (R doubles): the shaper brakes the plate down as the cap falls, instead of
    driving on as if the plate held only what the cap allows at the new force."""
    device = Device.from_file(DEVICES_DIR / "SLG_0.56.yaml")

    def force_n(t_s: float) -> float:
        return round(2.0 * min(max((t_s - PRESS_AT_S) / 0.01, 0.0), 1.0), 3)

    run = Run(device, texture, force_n)
    before = run.power_w[int(0.05 * FS_HZ):int(PRESS_AT_S * FS_HZ)]
    assert before.max() > 0.9 * run.cap_w  # the drive sits at the cap before the press
    assert run.power_w[int(0.05 * FS_HZ):-STEP].max() <= run.cap_w * OVER


def _scaled_device(folder: Path, rise: float, l_change: float, shift: float, preemphasis: bool) -> Device:
    """SLG_0.56 with its motional R rising ``rise`` times from 0 to 2 N, L changing by the fraction ``l_change``
    and C so that the branch's resonance moves by the fraction ``shift`` (their values at 0 N as shipped), checked
    as a file."""
    tree: dict[str, Any] = yaml.safe_load((DEVICES_DIR / "SLG_0.56.yaml").read_text())
    tree["preemphasis"] = preemphasis
    circuit = tree["circuit"]
    share = np.array(circuit["force_n"]) / circuit["force_n"][-1]
    c_change = 1 / ((1 + shift) ** 2 * (1 + l_change)) - 1  # resonance 1 / sqrt(L C)
    for key, change in (("motional_r_ohm", rise - 1), ("motional_l_h", l_change), ("motional_c_pf", c_change)):
        circuit[key] = [float(circuit[key][0] * (1 + change * x)) for x in share]
    path = folder / f"{rise:.4f}_{l_change:.4f}_{shift:.5f}_{preemphasis}.yaml"
    path.write_text(yaml.safe_dump(tree))
    assert check_file(path) == [], path.read_text()
    return Device.from_file(path)


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                HealthCheck.function_scoped_fixture])
@given(rise=st.floats(1.5, 10.0), l_change=st.floats(-0.1, 0.1), shift=st.floats(-SHIFT, SHIFT),
       press_ms=st.sampled_from([0.0, 1.0, 2.0, 10.0]), preemphasis=st.booleans())
def test_presses_on_devices_whose_damping_rises_up_to_tenfold_are_braked_near_the_floor(
        tmp_path: Path, texture: Path, rise: float, l_change: float, shift: float, press_ms: float,
        preemphasis: bool) -> None:
    """Devices `check` accepts whose motional R rises up to ten times from 0 to 2 N (L moving by up to 10 %, the
    shipped plates' 5 % and more, and C with it so that the resonance moves by up to SHIFT, 0.5 %: about four times
    SLG_0.4's 28 Hz, at a fixed carrier; a plate the finger detunes further is one to `track`), pressed at once or
    over up to 10 ms (R rising 90 % between two 1 kHz finger samples), with pre-emphasis or without: the kernel
    handles any such change, whatever its rate. A gradual press is a run of smaller sudden ones (one a finger
    sample): after each, the plate is back under the cap within 1.2 times that change's own full-reverse floor."""
    device = _scaled_device(tmp_path, rise, l_change, shift, preemphasis)

    def force_n(t_s: float) -> float:
        if press_ms == 0.0:
            return 2.0 if t_s >= PRESS_AT_S else 0.0
        t_ms = np.floor(t_s * 1000)  # finger samples at 1 kHz
        return round(2.0 * min(max((t_ms - PRESS_AT_S * 1000) / press_ms, 0.0), 1.0), 3)

    run = Run(device, texture, force_n)
    excursions = run.excursions_beyond_floors()
    assert press_ms > 0.0 or excursions[0][1] > 0.0  # a sudden press takes the plate over
    for seconds, floor_s in excursions:
        assert seconds <= FLOOR_FACTOR * floor_s, excursions
