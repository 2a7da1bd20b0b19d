"""The drive a run uses (tpad_rt.drive.DriveSpec), how the pipeline takes it, and the stop ramp a driver waits
out (Driver.wait_silent) on a virtual clock."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from tpad_rt.clock import VirtualClock
from tpad_rt.device import Device
from tpad_rt.drive import Consumes, DriveSpec
from tpad_rt.drivers.base import Driver
from tpad_rt.errors import ConfigError
from tpad_rt.kernel.layout import CFG_CARRIER_HZ, CFG_MAX_VOLTAGE_V, CFG_VOLTS_PER_FS, STATE_GATE, STATE_RAMP_START
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.realtime import CallbackTable
from tpad_rt.texture import load_compiled
from tpad_rt.urls import parse_url

DEVICE = Device.default()
GRATING = load_compiled("textures/grating.yaml")


@pytest.mark.parametrize("field", ["rate_hz", "carrier_hz", "volts_per_full_scale", "max_voltage_v"])
@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf, True, "40", None])
def test_every_figure_must_be_a_finite_number_above_zero(field: str, bad: object) -> None:
    figures = {"rate_hz": 8000, "carrier_hz": 30000.0, "volts_per_full_scale": 50.0, "max_voltage_v": 40.0}
    with pytest.raises(ConfigError, match=f"drive: {field}: must be a finite number > 0"):
        DriveSpec(Consumes.ENVELOPE, **{**figures, field: bad})  # type: ignore[arg-type]


def test_numpy_figures_are_kept_as_floats_and_the_kind_must_be_a_consumes() -> None:
    spec = DriveSpec(Consumes.DAC, np.int64(96000), np.float32(31360.0), 50.0, 40.0)  # type: ignore[arg-type]
    assert type(spec.rate_hz) is float and spec.rate_hz == 96000.0
    with pytest.raises(ConfigError, match="consumes: must be a Consumes"):
        DriveSpec("DAC", 96000, 31360.0, 50.0, 40.0)  # type: ignore[arg-type]


def test_a_hardware_report_keeps_the_lower_clamp_and_names_its_source() -> None:
    device_drive = DriveSpec.from_device(DEVICE, Consumes.ENVELOPE, 8000)
    assert (device_drive.carrier_hz, device_drive.max_voltage_v, device_drive.source) == (
        DEVICE.carrier_hz, DEVICE.max_voltage_v, "device file")
    low = device_drive.from_hardware(volts_per_full_scale=60.0, max_voltage_v=20.0, carrier_hz=30001.5, source="amp A")
    high = device_drive.from_hardware(volts_per_full_scale=60.0, max_voltage_v=100.0, carrier_hz=30001.5,
                                      source="amp B")
    assert (low.max_voltage_v, high.max_voltage_v) == (20.0, DEVICE.max_voltage_v)
    assert high.metadata() == {"carrier_hz": 30001.5, "volts_per_full_scale": 60.0,
                               "max_voltage_v": DEVICE.max_voltage_v, "output_consumes": "envelope",
                               "drive_rate_hz": 8000.0, "drive_source": "amp B"}


def test_the_pipeline_renders_for_the_drive_it_is_given_and_a_second_report_is_not_held_to_the_first() -> None:
    pipeline = Pipeline(DEVICE, GRATING, fs_hz=8000, envelope_output=True)
    assert pipeline.drive == pipeline.device_drive == DriveSpec.from_device(DEVICE, Consumes.ENVELOPE, 8000)
    first = pipeline.device_drive.from_hardware(volts_per_full_scale=60.0, max_voltage_v=20.0, carrier_hz=30500.0,
                                                source="amp A")
    pipeline.set_drive(first)
    cfg = pipeline.arrays.cfg
    assert (cfg[CFG_VOLTS_PER_FS], cfg[CFG_MAX_VOLTAGE_V], cfg[CFG_CARRIER_HZ]) == (60.0, 20.0, 30500.0)
    pipeline.set_drive(pipeline.device_drive.from_hardware(volts_per_full_scale=60.0, max_voltage_v=100.0,
                                                           carrier_hz=30500.0, source="amp B"))
    assert cfg[CFG_MAX_VOLTAGE_V] == DEVICE.max_voltage_v and pipeline.drive.source == "amp B"


def test_the_pipeline_refuses_a_drive_it_cannot_render() -> None:
    pipeline = Pipeline(DEVICE, GRATING, fs_hz=96000)
    with pytest.raises(ConfigError, match="envelope at 96000 Hz, but the pipeline renders DAC samples"):
        pipeline.set_drive(DriveSpec(Consumes.ENVELOPE, 96000, DEVICE.carrier_hz, 50.0, 40.0))
    with pytest.raises(ConfigError, match="at 48000 Hz, but the pipeline renders DAC samples at 96000 Hz"):
        pipeline.set_drive(DriveSpec(Consumes.DAC, 48000, DEVICE.carrier_hz, 50.0, 40.0))
    with pytest.raises(ConfigError, match="above the device's"):
        pipeline.set_drive(DriveSpec(Consumes.DAC, 96000, DEVICE.carrier_hz, 50.0, DEVICE.max_voltage_v * 2))
    with pytest.raises(ConfigError, match="needs a sample rate of at least"):
        pipeline.set_drive(DriveSpec(Consumes.DAC, 96000, 60000.0, 50.0, 40.0))
    with pytest.raises(ConfigError, match="must be a DriveSpec"):
        pipeline.set_drive({"carrier_hz": 1.0})  # type: ignore[arg-type]
    pipeline.start()
    with pytest.raises(RuntimeError, match="stop the pipeline first"):
        pipeline.set_drive(pipeline.device_drive)
    assert pipeline.drive == pipeline.device_drive


class ClockedDriver(Driver):
    """A driver whose hardware is the virtual clock: every block period, an event renders one block."""

    def start(self, table: CallbackTable) -> None:
        block = np.zeros(self.block_frames, dtype=np.float32)
        period_ns = round(self.block_frames * 1e9 / self.rate_hz)
        clock = self.clock
        assert isinstance(clock, VirtualClock)

        def render() -> None:
            table.call(block)
            self.rendered.append(block.copy())
            clock.at(clock.now_ns() + period_ns, render)

        self.rendered: list[np.ndarray] = []
        clock.at(clock.now_ns() + period_ns, render)

    def poll(self, table: CallbackTable) -> BaseException | None:
        return None

    def close(self, ramp_ms: float) -> BaseException | None:
        return None


def _driver_and_table(clock: VirtualClock) -> tuple[ClockedDriver, Pipeline, CallbackTable]:
    options = RenderOptions(ramp_ms=5.0, control_interval=32)
    driver = ClockedDriver(parse_url("sim://", "output", {"sim": ["sim://"]}), device=DEVICE, rate_hz=96000,
                           block_frames=64, options=options, clock=clock)
    pipeline = Pipeline(DEVICE, GRATING, fs_hz=96000, options=options)
    table = CallbackTable(pipeline.arrays, GRATING)
    return driver, pipeline, table


def test_the_stop_waits_on_the_drivers_clock_until_the_ramp_and_one_block_more_were_rendered() -> None:
    clock = VirtualClock()
    driver, pipeline, table = _driver_and_table(clock)
    pipeline.start()
    driver.start(table)
    for k in range(40):  # a finger sliding for 40 ms of virtual time
        pipeline.push_finger(k * 1e-3, 20.0 + k * 0.5, 20.0)
        clock.advance_by(1_000_000)
    drive = np.concatenate(driver.rendered)
    assert np.abs(drive).max() > 0.05  # it drove
    stopped_at = table.next_sample
    pipeline.stop()
    silent_by = driver.wait_silent(table, threading.Event())
    ramp_samples = round(5e-3 * 96000)
    assert silent_by == stopped_at + 32 + ramp_samples + 64
    assert table.next_sample >= silent_by  # it waited until then, on the virtual clock (no real time passed)
    state = table.arrays.state
    assert not (state[STATE_GATE] or state[STATE_RAMP_START])
    rendered = np.concatenate(driver.rendered)  # sample n of the stream is rendered[n]
    assert np.all(rendered[silent_by - 64:] == 0.0)  # the block before it was already silent
    assert np.abs(rendered[stopped_at:stopped_at + 32]).max() > 0  # and the ramp began from a drive
    waited_ns = clock.now_ns() - 40_000_000
    assert waited_ns <= (silent_by - stopped_at + 64) * 1e9 / 96000 + 1_000_000  # no longer than needed


def test_the_stop_gives_up_at_its_bound_when_the_output_renders_nothing() -> None:
    clock = VirtualClock()
    driver, pipeline, table = _driver_and_table(clock)  # never started: nothing renders
    pipeline.start()
    pipeline.stop()
    silent_by = driver.wait_silent(table, threading.Event())
    assert table.next_sample < silent_by
    bound_s = 20 * silent_by / 96000 + 1.0  # STOP_TIMEOUT_FACTOR x the samples to silence, plus a second
    assert clock.now_ns() == pytest.approx(bound_s * 1e9, abs=2_000_000)


def test_an_ended_run_stops_the_wait_at_once() -> None:
    clock = VirtualClock()
    driver, pipeline, table = _driver_and_table(clock)
    ended = threading.Event()
    ended.set()
    driver.wait_silent(table, ended)
    assert clock.now_ns() == 0
