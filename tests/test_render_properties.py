"""Properties of the render kernel over random textures, paths, forces, budgets, options and block splits."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_render_kernel import (
    FS_HZ,
    JIT,
    Scenario,
    assert_power_budgets,
    device,
    render_kernel,
    texture,
)

from tpad_rt.kernel.render import PHASE_BITS, carrier_phase_units
from tpad_rt.pipeline import RenderOptions

#: Examples per property, and seconds of audio each (fewer and shorter when the kernel is plain Python).
EXAMPLES = 30 if JIT else 4
SECONDS = (0.03, 0.12) if JIT else (0.02, 0.04)
SHIPPED = ["grating", "square_grating", "sawtooth_ramp", "temporal_pulse", "bitmap_noise", "gradient_ridges",
           "bumps_grid", "edges_buttons", "layers_window", "layers_modulated"]
WAVEFORMS = ["sine", "square", "triangle", "sawtooth"]


@st.composite
def textures(draw: st.DrawFn) -> Any:
    """A shipped texture, or a random grating or temporal texture."""
    kind = draw(st.sampled_from(["shipped", "grating", "temporal"]))
    if kind == "shipped":
        return texture(draw(st.sampled_from(SHIPPED)))
    low = draw(st.floats(0.01, 1.0))
    friction = {"low": low, "high": draw(st.floats(low, 1.0))}
    waveform = draw(st.sampled_from(WAVEFORMS))
    shape = {"waveform": waveform, "friction": friction}
    if waveform in ("square", "triangle"):
        shape["duty"] = draw(st.floats(0.05, 0.95))
    if kind == "grating":
        return texture({"kind": "grating", "period_mm": draw(st.floats(0.3, 30.0)),
                        "angle_deg": draw(st.floats(-180, 180)), **shape})
    return texture({"kind": "temporal", "frequency_hz": draw(st.floats(0.5, 500.0)), **shape})


@st.composite
def paths(draw: st.DrawFn, duration_s: float) -> np.ndarray:
    """Finger rows through random waypoints at a random rate, random (or unknown) force, maybe a lift."""
    rate_hz = draw(st.floats(100.0, 3000.0))
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    waypoints = draw(st.lists(st.tuples(st.floats(-10, 140), st.floats(-10, 70)), min_size=2, max_size=6))
    knots = np.linspace(0.0, duration_s, len(waypoints))
    x = np.interp(t, knots, [p[0] for p in waypoints])
    y = np.interp(t, knots, [p[1] for p in waypoints])
    force = draw(st.sampled_from(["unknown", "constant", "varying"]))
    if force == "unknown":
        forces = np.full_like(t, np.nan)
    elif force == "constant":
        forces = np.full_like(t, draw(st.floats(0.0, 3.0)))
    else:
        # push_finger refuses a negative force (SampleError); the kernel's own defence against one that reaches
        # the ring anyway is tests/test_render_guard.py's
        forces = np.interp(t, [0.0, duration_s], [draw(st.floats(0.0, 3.0)), draw(st.floats(0.0, 3.0))])
    down = np.ones_like(t)
    if draw(st.booleans()):
        first = draw(st.integers(0, t.size - 1))
        down[first : first + draw(st.integers(1, 20))] = 0.0
    return np.column_stack([t, x, y, forces, down])


@st.composite
def options(draw: st.DrawFn) -> RenderOptions:
    """Random budgets (often binding) and settings."""
    cap_w = draw(st.floats(0.005, 1.0))
    return RenderOptions(
        power_budget_w=cap_w,
        power_avg_w=draw(st.none() | st.floats(0.002, 1.5 * cap_w)),
        power_window_s=draw(st.floats(0.001, 0.1)),
        control_interval=draw(st.sampled_from([1, 7, 16, 32, 64, 100, 256])),
        smoothing_ms=draw(st.floats(0.1, 5.0)),
        preemphasis=draw(st.booleans()),
        horizon_ms=draw(st.floats(0.0, 20.0)),
        velocity_window_ms=draw(st.floats(0.5, 30.0)),
        watchdog_ms=draw(st.floats(1.0, 60.0)),
        ramp_ms=draw(st.floats(0.01, 10.0)),
        default_force_n=draw(st.floats(0.0, 2.5)),
        mu_floor=draw(st.floats(0.01, 1.0)),
    )


@st.composite
def scenarios(draw: st.DrawFn) -> Scenario:
    """A random stream, followed by a silent tail long enough for the watchdog and ramp."""
    duration_s = draw(st.floats(*SECONDS))
    chosen = draw(options())
    tail_s = (chosen.watchdog_ms + chosen.ramp_ms) / 1000 + 2 * chosen.control_interval / FS_HZ
    n = int((duration_s + tail_s) * FS_HZ)
    swaps = [(0, draw(textures()), 0.0)]
    if draw(st.booleans()):
        swaps.append((draw(st.integers(1, n - 1)), draw(textures()), draw(st.floats(-1.0, 1.0))))
    run: list[tuple[int, bool]] = [(0, True)]
    if draw(st.booleans()):
        stop = draw(st.integers(1, n - 1))
        run += [(stop, False), (draw(st.integers(stop, n)), True)]
    return Scenario(draw(paths(duration_s)), n, swaps, chosen, run=run)


def step_powers(telemetry: dict[str, np.ndarray], n_samples: int, interval: int) -> np.ndarray:
    """Per-control-step power (W) from a render in blocks that never cross a step (some cut by events)."""
    starts = np.round(telemetry["t"] * FS_HZ).astype(np.int64)
    lengths = np.diff(np.append(starts, n_samples))
    steps = starts // interval
    return np.bincount(steps, telemetry["power_w"] * lengths) / np.bincount(steps, lengths)


PROPERTY = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@PROPERTY
@given(scenarios(), st.lists(st.integers(1, 5000), min_size=1, max_size=5))
def test_limits_hold_and_any_block_split_gives_the_same_samples(scenario: Scenario, blocks: list[int]) -> None:
    interval = scenario.options.control_interval
    by_step = render_kernel(scenario, blocks=(interval,))
    split = render_kernel(scenario, blocks=blocks)
    assert np.array_equal(by_step.samples, split.samples)

    peak_v = np.abs(by_step.samples.astype(np.float64)).max() * device().volts_per_full_scale
    assert peak_v <= device().max_voltage_v
    assert by_step.telemetry["voltage_v"].max() <= device().max_voltage_v
    cap_w = scenario.options.power_budget_w
    avg_w = cap_w if scenario.options.power_avg_w is None else scenario.options.power_avg_w
    window_steps = max(1, round(scenario.options.power_window_s * FS_HZ / interval))
    assert_power_budgets(step_powers(by_step.telemetry, scenario.n_samples, interval), cap_w, avg_w, window_steps)

    last_touch_s = scenario.fingers[-1, 0]
    silent_s = last_touch_s + (scenario.options.watchdog_ms + scenario.options.ramp_ms) / 1000
    silent_from = math.ceil(silent_s * FS_HZ) + interval + 1
    assert np.all(by_step.samples[silent_from:] == 0.0)


@settings(max_examples=200 if JIT else 20, deadline=None)
@given(st.integers(0, 2**62), st.integers(0, 2**PHASE_BITS - 1))
def test_carrier_phase_is_the_exact_product_modulo_2_60(n: int, step_units: int) -> None:
    assert carrier_phase_units(n, step_units) == (n * step_units) % 2**PHASE_BITS
