"""The kernel's fault guard (docs/kernel.md "Faults"): whatever its arrays hold, the drive is finite
and within max_voltage_v, a fault ramps it to 0 and is counted, and the next valid data brings it back.

Bad values are written straight into the kernel's arrays here, past the boundaries that
refuse them (tests/test_push_validation.py): a producer that skips validation, or memory
overwritten by a bug. These tests also run under NUMBA_DISABLE_JIT=1 (tests/run's coverage
run), so their renders are short.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tpad_rt.device import Device
from tpad_rt.kernel import layout
from tpad_rt.pipeline import Pipeline
from tpad_rt.texture import load_compiled

from test_render_kernel import JIT, TEXTURES

BLOCK = 64
#: Blocks rendered before a fault (the drive has ramped up) and after it.
SETTLE_BLOCKS = 24
AFTER_BLOCKS = 24
BAD_VALUES = (math.nan, math.inf, -math.inf, 1e308, -1e308)
#: The default device with its standing wave modelled: the kernel reads its mode gain table.
STANDING_WAVE = Device.from_file(Path(__file__).resolve().parents[1] / "examples" / "devices"
                                 / "SLG_0.56_standing_wave.yaml")


def pipeline(device: Device | None = None) -> Pipeline:
    p = Pipeline(Device.default() if device is None else device, load_compiled(TEXTURES / "grating.yaml"))
    p.start()
    return p


def limit_fs(p: Pipeline) -> float:
    """The largest DAC sample the device allows (full scale)."""
    return p.device.max_voltage_v / p.device.volts_per_full_scale


def render(p: Pipeline, blocks: int, *, push: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Render ``blocks`` blocks, pushing a valid 100 mm/s swipe sample at each block's start when ``push``;
    (the samples, each block's peak envelope volts and flags as rows ``[voltage_v, flags]``)."""
    out = np.zeros(blocks * BLOCK, dtype=np.float32)
    rows = []
    for k in range(blocks):
        if push:
            t_s = p.stream_time_s
            p.push_finger(t_s, 10.0 + 100.0 * t_s, 30.0, 0.5)
        p.render(out[k * BLOCK:(k + 1) * BLOCK])
        row = p.last_telemetry_row()
        rows.append((row["voltage_v"], row["saturated"]))
    return out, np.array(rows)


def assert_safe(p: Pipeline, samples: np.ndarray, rows: np.ndarray) -> None:
    assert np.all(np.isfinite(samples))
    assert np.max(np.abs(samples)) <= limit_fs(p)
    assert np.all(np.isfinite(rows[:, 0])) and np.max(rows[:, 0]) <= p.device.max_voltage_v
    telemetry = p.drain_telemetry()
    for name in ("power_w", "voltage_v", "x_mm", "y_mm", "speed_mm_s", "force_n", "amplitude_um"):
        assert np.all(np.isfinite(telemetry[name])), name
    assert np.max(telemetry["power_w"]) <= p.device.power_budget_w


def write_row(p: Pipeline, values: tuple[float, float, float, float, float]) -> None:
    """Append a finger row without the boundary's checks (as a producer that skipped them would)."""
    finger, count = p.arrays.finger, p.arrays.finger_count
    finger[count[0] % len(finger)] = values
    count[0] += 1


def assert_recovers(p: Pipeline, before_v: float) -> None:
    """The drive comes back to at least half its level before the fault with valid samples."""
    samples, rows = render(p, AFTER_BLOCKS)
    assert_safe(p, samples, rows)
    assert rows[-8:, 0].max() >= 0.5 * before_v
    assert not int(rows[-1, 1]) & layout.FLAG_FAULT


#: (column, value) of a bad finger row: every bad value in each column, and a negative force (-1 mm is a
#: valid position; a NaN force in the ring means 'unknown', the default force applies).
BAD_FINGER_VALUES = [(column, value) for column in (layout.FINGER_X_MM, layout.FINGER_Y_MM, layout.FINGER_FORCE_N)
                     for value in BAD_VALUES if not (column == layout.FINGER_FORCE_N and math.isnan(value))]
BAD_FINGER_VALUES.append((layout.FINGER_FORCE_N, -1.0))


@pytest.mark.parametrize(("column", "value"), BAD_FINGER_VALUES)
def test_a_bad_finger_sample_ramps_the_drive_down_is_counted_and_the_run_recovers(column: int, value: float) -> None:
    p = pipeline()
    samples, rows = render(p, SETTLE_BLOCKS)
    before_v = rows[-4:, 0].max()
    assert before_v > 1.0
    row = [p.stream_time_s, 10.0 + 100.0 * p.stream_time_s, 30.0, 0.5, 1.0]
    row[column] = value
    write_row(p, tuple(row))  # type: ignore[arg-type]
    faulted, fault_rows = render(p, 3, push=False)
    assert_safe(p, np.r_[samples, faulted], np.r_[rows, fault_rows])
    assert int(fault_rows[0, 1]) & layout.FLAG_FAULT
    ramp_blocks = math.ceil(p.options.ramp_ms * 1e-3 * p.fs_hz / BLOCK) + 1
    ramped, ramp_rows = render(p, ramp_blocks, push=False)  # still the bad sample: the ramp runs to 0
    assert np.all(ramped[-BLOCK:] == 0.0)
    assert np.all(np.diff(ramp_rows[:, 0]) <= 1e-9)
    faults = p.faults()
    assert faults["faults"] == 1 and faults["fault_steps"] >= 2 and faults["fault_causes"] == ["finger"]
    assert_recovers(p, before_v)


def test_a_finger_time_that_is_not_finite_is_never_read() -> None:
    p = pipeline()
    _, rows = render(p, SETTLE_BLOCKS)
    for t_s in (math.nan, -math.inf):
        write_row(p, (t_s, 50.0, 30.0, 0.5, 1.0))
    samples, after = render(p, SETTLE_BLOCKS)
    assert_safe(p, samples, after)
    assert after[-8:, 0].max() >= 0.5 * rows[-4:, 0].max()


#: State slots a bug could overwrite, and the values written there.
STATE_SLOTS = (
    layout.STATE_SMOOTH_START_V, layout.STATE_COMMAND_V, layout.STATE_CAP_V, layout.STATE_RAMP_START,
    layout.STATE_RAMP_SAMPLES, layout.STATE_RING_SLOT, layout.STATE_STEP_SAMPLES, layout.STATE_NEXT_PHASE,
    layout.STATE_WINDOW_SUM_W, layout.STATE_FOLLOW_GAIN, layout.STATE_FINGER_SAMPLE,
    layout.STATE_CARRIER_COS, layout.STATE_STEP_FLAGS, layout.STATE_FAULT_CAUSES, layout.STATE_POWER_PER_V2,
    layout.STATE_VX_MM_S, layout.STATE_FIRST_SEGMENT_SAMPLES,
    layout.STATE_MODEL_V, layout.STATE_MODEL_STEP, layout.STATE_DRIVE_LOW_V, layout.STATE_MODEL_ON_REF,
    layout.STATE_MODEL_GAIN_M_PER_V, layout.STATE_MODEL_SLIP_V, layout.STATE_PLATE_W, layout.STATE_PRESS_BRAKING,
    layout.STATE_OVER_CAP_BLOCKS,
)


@pytest.mark.parametrize("slot", STATE_SLOTS)
@pytest.mark.parametrize("value", BAD_VALUES + (-1.0, 5e-324, 1e6))
def test_state_overwritten_with_garbage_never_reaches_the_output(slot: int, value: float) -> None:
    p = pipeline()
    samples, rows = render(p, SETTLE_BLOCKS)
    before_v = rows[-4:, 0].max()
    p.arrays.state[slot] = value
    after, after_rows = render(p, 4)
    assert_safe(p, np.r_[samples, after], np.r_[rows, after_rows])
    assert_recovers(p, before_v)


@pytest.mark.parametrize("value", BAD_VALUES + (0.0, 0.5, 2e6))
def test_a_gain_span_out_of_range_never_reaches_the_output(value: float) -> None:
    """CFG_GAIN_SPAN outside [1, MAX_GAIN_SPAN] counts as MAX_GAIN_SPAN: a finite bound on the plate model."""
    p = pipeline()
    samples, rows = render(p, SETTLE_BLOCKS)
    p.arrays.cfg[layout.CFG_GAIN_SPAN] = value
    p.arrays.state[layout.STATE_MODEL_V] = 1e308  # a model no span may let through
    p.arrays.state[layout.STATE_MODEL_ON_REF] = 0.0
    after, after_rows = render(p, 4)
    assert_safe(p, np.r_[samples, after], np.r_[rows, after_rows])
    assert p.faults()["fault_causes"] == ["state"]
    assert_recovers(p, rows[-4:, 0].max())


def test_a_last_gain_the_device_cannot_have_is_a_state_fault_not_a_press() -> None:
    """A record of the last step's gain far outside the device's span would make a press of nothing (the model
    scaled up to its bound, braking at the full volts): it is a state fault instead, and nothing is braked."""
    p = pipeline()
    samples, rows = render(p, SETTLE_BLOCKS)
    p.arrays.state[layout.STATE_MODEL_GAIN_M_PER_V] *= 1e3
    after, after_rows = render(p, 4)
    assert_safe(p, np.r_[samples, after], np.r_[rows, after_rows])
    assert p.faults()["fault_causes"] == ["state"] and p.over_cap_blocks == 0
    assert_recovers(p, rows[-4:, 0].max())


def test_tables_and_power_ring_overwritten_are_rebuilt() -> None:
    p = pipeline()
    _, rows = render(p, SETTLE_BLOCKS)
    state = p.arrays.state
    state[layout.STATE_COS_TABLE:layout.STATE_SIZE] = 1e308
    p.arrays.power_ring[:] = math.nan
    samples, after = render(p, 4)
    assert_safe(p, samples, after)
    assert int(after[0, 1]) & layout.FLAG_FAULT
    assert p.faults()["fault_causes"] == ["state"]  # the smoothing left out of range: tables rebuilt
    assert np.all(np.isfinite(p.arrays.power_ring))
    assert_recovers(p, rows[-4:, 0].max())


@pytest.mark.parametrize(("row", "value"), [
    (row, value) for row in (layout.DEV_AMP_M_PER_V, layout.DEV_POWER_W_PER_V2, layout.DEV_TAU_S, layout.DEV_MODE_GAIN)
    for value in (math.nan, math.inf, -1.0, 0.0) if not (row == layout.DEV_TAU_S and value == 0.0)  # tau 0: valid
])
def test_a_bad_device_table_is_a_device_fault(row: int, value: float) -> None:
    p = pipeline(STANDING_WAVE if row == layout.DEV_MODE_GAIN else None)
    _, rows = render(p, SETTLE_BLOCKS)
    kept = p.arrays.dev[row].copy()
    p.arrays.dev[row] = value
    samples, after = render(p, SETTLE_BLOCKS)
    assert_safe(p, samples, after)
    assert all(int(flags) & layout.FLAG_FAULT for flags in after[:, 1])
    assert np.all(samples[-BLOCK:] == 0.0)
    assert p.faults()["fault_causes"] == ["device"]
    p.arrays.dev[row] = kept
    assert_recovers(p, rows[-4:, 0].max())


def test_a_texture_value_that_is_not_finite_is_a_texture_fault() -> None:
    p = pipeline()
    _, rows = render(p, SETTLE_BLOCKS)
    params = p.arrays.params
    kept = params.copy()
    params[:] = math.nan
    samples, after = render(p, SETTLE_BLOCKS)
    assert_safe(p, samples, after)
    assert np.all(samples[-BLOCK:] == 0.0)
    assert p.faults() == {"faults": 1, "fault_steps": p.faults()["fault_steps"], "fault_samples": 0,
                          "fault_causes": ["texture"]}
    params[:] = kept
    assert_recovers(p, rows[-4:, 0].max())


def test_a_drive_past_the_voltage_limit_is_zeroed_by_the_output_guard() -> None:
    p = pipeline()
    render(p, SETTLE_BLOCKS)
    half = p.options.control_interval // 2
    out = np.zeros(2 * half, dtype=np.float32)
    p.render(out[:half])  # into the middle of a control step
    for slot in (layout.STATE_CAP_V, layout.STATE_COMMAND_V):  # the open step's values, overwritten
        p.arrays.state[slot] = 10 * p.device.max_voltage_v
    p.render(out[half:])
    assert np.max(np.abs(out)) <= limit_fs(p)
    faults = p.faults()
    rejected = faults.pop("fault_samples")
    assert faults == {"faults": 1, "fault_steps": 1, "fault_causes": ["output"]}
    assert half // 2 <= rejected <= half  # 10x the limit: all but the samples near a carrier zero crossing
    assert rejected == np.count_nonzero(out[half:] == 0.0)
    assert int(p.last_telemetry_row()["saturated"]) & layout.FLAG_FAULT
    samples, rows = render(p, 4)
    assert_safe(p, np.r_[out, samples], rows)


@settings(max_examples=60 if JIT else 8, deadline=None)
@given(
    garbage=st.dictionaries(st.integers(0, layout.STATE_SIZE - 1),
                            st.floats(allow_nan=True, allow_infinity=True), max_size=12),
    finger=st.lists(st.tuples(*[st.floats(allow_nan=True, allow_infinity=True)] * 4, st.sampled_from([0.0, 1.0])),
                    max_size=6),
)
def test_no_state_and_no_finger_rows_make_the_drive_unsafe(
    garbage: dict[int, float], finger: list[tuple[float, ...]]
) -> None:
    p = pipeline()
    render(p, 4)
    for index, value in garbage.items():
        p.arrays.state[index] = value
    for row in finger:
        write_row(p, row)  # type: ignore[arg-type]
    samples, rows = render(p, 6, push=False)
    assert_safe(p, samples, rows)
