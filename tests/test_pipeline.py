"""Pipeline and RenderOptions: validation, device tables, finger ring, telemetry, warm-up, arrays."""

from __future__ import annotations

import inspect
import math
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from test_render_kernel import FS_HZ, JIT, device, swipe, texture

from tpad_rt.device import Device
from tpad_rt.errors import ConfigError, TpadError
from tpad_rt.kernel import layout
from tpad_rt.kernel.render import render_block
from tpad_rt.pipeline import KernelArrays, Pipeline, RenderOptions, device_tables, force_grid
from tpad_rt.texture import compile_texture

CALIBRATION = Path(__file__).resolve().parents[1] / "tpad_rt" / "devices"


def pipeline(**options: object) -> Pipeline:
    return Pipeline(device(), compile_texture(texture("grating")), fs_hz=FS_HZ, options=RenderOptions(**options))


# --- options --------------------------------------------------------------------


def test_render_options_defaults() -> None:
    options = RenderOptions()
    assert (options.power_budget_w, options.power_avg_w, options.preemphasis) == (None, None, None)
    assert options.power_window_s == 1.0 and options.control_interval == 32
    assert (options.ramp_ms, options.watchdog_ms, options.velocity_window_ms) == (5.0, 50.0, 10.0)
    assert (options.default_force_n, options.mu_floor, options.horizon_ms) == (0.5, 0.01, 0.25)
    assert (options.smoothing_ms, options.braking) == (0.25, True)


def test_bad_options_are_one_config_error_naming_every_field() -> None:
    with pytest.raises(ConfigError) as caught:
        RenderOptions(smoothing_ms=-1.0, control_interval=300, power_avg_w=math.nan, mu_floor=1.5,
                      finger_ring=1, telemetry_ring=2.5, preemphasis="yes", horizon_ms=-2.0,  # type: ignore[arg-type]
                      braking=1, mode_compensation="no")  # type: ignore[arg-type]
    assert caught.value.errors == [
        "RenderOptions.power_avg_w: must be a finite number in [0.001, 1000], got nan",
        "RenderOptions.smoothing_ms: must be in [0.01, 1000], got -1",
        "RenderOptions.horizon_ms: must be in [0, 1000], got -2",
        "RenderOptions.mu_floor: must be in [1e-06, 1], got 1.5",
        "RenderOptions.control_interval: must be in [1, 256], got 300",
        "RenderOptions.finger_ring: must be in [2, 1048576], got 1",
        "RenderOptions.telemetry_ring: must be a whole number in [1, 4194304], got 2.5",
        "RenderOptions.preemphasis: must be true, false or None, got 'yes'",
        "RenderOptions.braking: must be true or false, got 1",
        "RenderOptions.mode_compensation: must be true or false, got 'no'",
    ]


@pytest.mark.parametrize(("option", "value"), [
    ("power_window_s", 1e9), ("power_window_s", 60.5), ("finger_ring", 10**12), ("telemetry_ring", 2**23),
    ("smoothing_ms", 1e-300), ("watchdog_ms", 1e300), ("ramp_ms", 5e-324), ("velocity_window_ms", math.inf),
    ("default_force_n", 1e308), ("power_budget_w", 1e308), ("horizon_ms", 1e308),
])
def test_options_that_would_allocate_without_bound_or_overflow_are_refused(option: str, value: float) -> None:
    with pytest.raises(ConfigError, match=f"^RenderOptions.{option}: must be"):
        RenderOptions(**{option: value})


@pytest.mark.parametrize("name", [f.name for f in fields(RenderOptions)
                                  if f.name not in ("preemphasis", "braking", "track", "mode_compensation")])
def test_every_numeric_option_refuses_text(name: str) -> None:
    with pytest.raises(ConfigError, match=f"RenderOptions.{name}: must be a (finite|whole) number"):
        RenderOptions(**{name: "1"})  # type: ignore[arg-type]


def test_options_override_the_device_defaults() -> None:
    cfg = pipeline(power_budget_w=0.3, power_avg_w=0.1, preemphasis=False, power_window_s=0.5, braking=False).arrays.cfg
    assert (cfg[layout.CFG_POWER_CAP_W], cfg[layout.CFG_POWER_AVG_W], cfg[layout.CFG_PREEMPHASIS]) == (0.3, 0.1, 0.0)
    assert cfg[layout.CFG_BRAKING] == 0.0 and pipeline().arrays.cfg[layout.CFG_BRAKING] == 1.0
    assert cfg[layout.CFG_WINDOW_STEPS] == round(0.5 * FS_HZ / 32)
    defaults = pipeline().arrays.cfg
    assert defaults[layout.CFG_POWER_CAP_W] == defaults[layout.CFG_POWER_AVG_W] == device().power_budget_w
    assert defaults[layout.CFG_PREEMPHASIS] == float(device().preemphasis)
    assert defaults[layout.CFG_CARRIER_HZ] == device().carrier_hz


def test_a_sample_rate_too_low_for_the_carrier_names_the_rate_needed() -> None:
    with pytest.raises(ConfigError, match=r"needs a sample rate of at least 69689 Hz .* got 48000"):
        Pipeline(device(), compile_texture(texture("grating")), fs_hz=48000)
    Pipeline(device(), compile_texture(texture("grating")), fs_hz=69689)
    for rate in (math.inf, 10**400):
        with pytest.raises(ConfigError, match=r"fs_hz: must be a finite number in \(0, 768000\]"):
            Pipeline(device(), compile_texture(texture("grating")), fs_hz=rate)
    with pytest.raises(ConfigError, match=r"fs_hz: must be in \(0, 768000\], got 2e\+09"):
        Pipeline(device(), compile_texture(texture("grating")), fs_hz=2_000_000_000)  # would allocate a 500 MB ring


# --- device tables --------------------------------------------------------------


def _interpolate(dev: np.ndarray, start_n: float, step_n: float, force_n: np.ndarray) -> np.ndarray:
    """The kernel's lookup, in NumPy: linear on the uniform grid, clamped at the ends."""
    position = np.clip((force_n - start_n) / step_n, 0, dev.shape[1] - 1)
    i = np.minimum(position.astype(int), dev.shape[1] - 2)
    return dev[:, i] + (position - i) * (dev[:, i + 1] - dev[:, i])


@pytest.mark.parametrize("path", sorted(CALIBRATION.glob("*.yaml")), ids=lambda p: p.stem)
def test_device_tables_reproduce_the_device(path: Path) -> None:
    """Knots on the grid; amplitude, power and tau, smooth in force between knots, within 1e-6 of the model."""
    dev_model = Device.from_file(path)
    dev, start_n, step_n = device_tables(dev_model)
    knots = dev_model.force_table_n
    on_grid = (knots - start_n) / step_n
    assert np.allclose(on_grid, np.round(on_grid), rtol=0, atol=1e-9)
    forces_n = np.concatenate([knots, np.random.default_rng(0).uniform(-0.5, knots[-1] + 0.5, 5000)])
    table = _interpolate(dev, start_n, step_n, forces_n)
    clamped = np.maximum(forces_n, 0.0)
    np.testing.assert_allclose(table[layout.DEV_AMP_M_PER_V], dev_model.amplitude_m_per_v(clamped), rtol=1e-6)
    np.testing.assert_allclose(table[layout.DEV_POWER_W_PER_V2], dev_model.power_w_per_v2(clamped), rtol=1e-6)
    np.testing.assert_allclose(table[layout.DEV_TAU_S], dev_model.envelope_time_constant_s(clamped), rtol=1e-6)
    on_knots = _interpolate(dev, start_n, step_n, knots)
    np.testing.assert_allclose(on_knots[layout.DEV_AMP_M_PER_V], dev_model.amplitude_m_per_v(knots), rtol=1e-12)


def test_force_grid_without_a_common_grid_uses_the_finest_one() -> None:
    base = device()
    odd = np.array([0.0, 0.2137, 1.0, 1.913])
    l_h, c_f, r_ohm = base.motional(odd)
    oddity = Device(**{**{f.name: getattr(base, f.name) for f in fields(Device)}, "force_table_n": odd,
                       "motional_l_h_table": l_h, "motional_c_f_table": c_f, "motional_r_ohm_table": r_ohm})
    assert force_grid(oddity)[2] == 4096
    constant = Device(**{**{f.name: getattr(base, f.name) for f in fields(Device)}, "force_table_n": [0.5],
                         "motional_l_h_table": [2.3], "motional_c_f_table": [1.1e-11], "motional_r_ohm_table": [1600.0]})
    assert force_grid(constant) == (0.5, 1.0, 1)
    dev, _, _ = device_tables(constant)
    assert np.all(dev[layout.DEV_AMP_M_PER_V] == constant.amplitude_m_per_v(0.5))


# --- finger, texture, run -------------------------------------------------------


def test_push_finger_writes_the_row_then_counts_it_and_lift_keeps_the_position() -> None:
    p = pipeline(finger_ring=4)
    for k in range(6):
        p.push_finger(k * 0.001, 10.0 + k, 20.0, force_n=0.1 * k, down=True)
    p.lift(0.006)
    finger, count = p.arrays.finger, p.arrays.finger_count
    assert count[0] == 7
    assert list(finger[5 % 4]) == pytest.approx([0.005, 15.0, 20.0, 0.5, 1.0])
    assert list(finger[6 % 4, :3]) == [0.006, 15.0, 20.0]
    assert finger[6 % 4, layout.FINGER_DOWN] == 0.0 and math.isnan(finger[6 % 4, layout.FINGER_FORCE_N])


def test_start_stop_and_time() -> None:
    p = pipeline()
    assert not p.running and p.sample_index == 0 and p.time_s == 0.0
    p.start()
    assert p.running
    p.render(np.zeros(960, dtype=np.float32))
    assert p.sample_index == 960 and p.time_s == pytest.approx(0.01)
    p.stop()
    assert not p.running


def test_set_texture_starts_temporal_textures_at_the_given_time() -> None:
    p = pipeline()
    pulse = texture({"kind": "temporal", "waveform": "square", "frequency_hz": 10.0, "duty": 0.5,
                     "friction": {"low": 0.4, "high": 1.0}})
    for row in swipe(0.2):
        p.push_finger(*row[:3], None if np.isnan(row[3]) else row[3], down=True)
    p.start()
    p.render(np.zeros(FS_HZ // 100, dtype=np.float32))
    p.set_texture(compile_texture(pulse))  # t0 = now (0.01 s): high for 50 ms, then low
    assert p.texture.kind == "temporal" and p.arrays.cfg[layout.CFG_TEXTURE_T0_S] == pytest.approx(0.01)
    block = np.zeros(32, dtype=np.float32)
    targets = []
    for _ in range(FS_HZ // 10 // 32):
        p.render(block)
        targets.append(p.drain_telemetry()["target_mu"][-1])
    switch = np.flatnonzero(np.array(targets) == 0.4)[0]
    assert switch * 32 / FS_HZ == pytest.approx(0.05, abs=64 / FS_HZ)
    p.set_texture(compile_texture(pulse), t_s=-0.05)
    assert p.arrays.cfg[layout.CFG_TEXTURE_T0_S] == -0.05


def test_render_refuses_bad_buffers() -> None:
    p = pipeline()
    with pytest.raises(TypeError, match="float32"):
        p.render(np.zeros(64))
    with pytest.raises(TypeError, match="C-contiguous"):
        p.render(np.zeros(128, dtype=np.float32)[::2])
    with pytest.raises(ValueError, match="1 to 65536 samples, got 0"):
        p.render(np.zeros(0, dtype=np.float32))
    with pytest.raises(ValueError, match="got 65537"):
        p.render(np.zeros(65537, dtype=np.float32))
    p.render(np.zeros(65536, dtype=np.float32))


# --- telemetry ------------------------------------------------------------------


def test_drain_telemetry_returns_the_rows_since_the_last_drain() -> None:
    p = pipeline(telemetry_ring=8)
    for row in swipe(0.1):
        p.push_finger(*row[:3], None if np.isnan(row[3]) else row[3], down=True)
    p.start()
    for _ in range(5):
        p.render(np.zeros(100, dtype=np.float32))
    rows = p.drain_telemetry()
    assert list(rows) == list(layout.TEL_NAMES)
    assert rows["saturated"].dtype == np.int64 and rows["t"].dtype == np.float64
    assert rows["t"] == pytest.approx(np.arange(5) * 100 / FS_HZ)
    assert len(p.drain_telemetry()["t"]) == 0
    for _ in range(8):
        p.render(np.zeros(100, dtype=np.float32))
    assert p.drain_telemetry()["t"] == pytest.approx(np.arange(5, 13) * 100 / FS_HZ)


def test_telemetry_overflow_is_an_error_and_the_next_drain_starts_afresh() -> None:
    p = pipeline(telemetry_ring=4)
    for _ in range(6):
        p.render(np.zeros(16, dtype=np.float32))
    with pytest.raises(TpadError, match="telemetry ring overflowed: 6 rows since the last drain, it holds 4"):
        p.drain_telemetry()
    assert len(p.drain_telemetry()["t"]) == 0
    p.render(np.zeros(16, dtype=np.float32))
    assert p.drain_telemetry()["t"] == pytest.approx([6 * 16 / FS_HZ])


# --- arrays and warm-up ---------------------------------------------------------


def test_arrays_follow_render_block_argument_order_with_the_layout_shapes() -> None:
    parameters = list(inspect.signature(render_block.py_func if JIT else render_block).parameters)
    assert parameters == ["out", "start_index", *KernelArrays._fields]
    arrays = pipeline(finger_ring=16, telemetry_ring=5).arrays
    assert arrays.cfg.shape == (layout.CFG_SIZE,) and arrays.state.shape == (layout.STATE_SIZE,)
    assert arrays.dev.shape[0] == layout.DEV_ROWS and arrays.finger.shape == (16, layout.FINGER_COLS)
    assert arrays.telem.shape == (5, layout.TEL_COLS) and arrays.power_ring.shape == (round(FS_HZ / 32),)
    assert arrays.finger_count.dtype == arrays.telem_count.dtype == arrays.prog.dtype == np.int64
    for array in arrays:
        assert array.flags.c_contiguous and array.flags.writeable


def test_warm_up_leaves_the_pipeline_untouched() -> None:
    p = pipeline()
    for row in swipe(0.05):
        p.push_finger(*row[:3], None if np.isnan(row[3]) else row[3], down=True)
    p.start()
    p.render(np.zeros(1000, dtype=np.float32))
    before = [array.copy() for array in p.arrays]
    p.warm_up()
    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(before, p.arrays))
    assert p.sample_index == 1000
