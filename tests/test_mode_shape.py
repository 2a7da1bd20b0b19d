"""The plate's standing wave (issue 11, Deliver 7): the free-free mode shape against the textbook formula and
the beam's frequency equation, the contact patch's mean against numerical integration, the device file's
``mode_shape``, the kernel's compensation, the simulated plate, and ``show``'s panel."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from cli_run import REPO, tpad_rt
from test_track import _even
from tpad_rt.cli.show import draw
from tpad_rt.plate_maps import Finger, plate_maps
from tpad_rt.device import Device
from tpad_rt.kernel import layout
from tpad_rt.physics.mode_shape import deflection, free_free_beta_l, patch_mean
from tpad_rt.pipeline import MODE_GAIN_FLOOR, Pipeline, RenderOptions, mode_gain_table
from tpad_rt.recording import read_recording
from tpad_rt.shipped import DEFAULT_DEVICE
from tpad_rt.texture import load_compiled

EXAMPLE = REPO / "examples" / "devices" / "SLG_0.56_standing_wave.yaml"
SHAPED = Device.from_file(EXAMPLE)
PLAIN = Device.default()
LENGTH_MM = 130.0
FS_HZ = 96_000
BLOCK = 64


def _nodes(values: np.ndarray) -> int:
    return int(np.count_nonzero(np.sign(values[1:]) != np.sign(values[:-1])))


@pytest.mark.parametrize("lines", [2, 3, 5, 8, 20, 41])
def test_beta_l_solves_the_free_free_equation_and_the_shape_has_that_many_nodal_lines(lines: int) -> None:
    beta_l = free_free_beta_l(lines)
    assert (lines - 1) * math.pi < beta_l < lines * math.pi
    assert abs(math.cos(beta_l) - 1.0 / math.cosh(beta_l)) < 1e-12  # cos x cosh x = 1, divided by cosh x
    assert _nodes(deflection(np.linspace(0.0, 100.0, 100_001), 100.0, lines)) == lines


@pytest.mark.parametrize("lines", [2, 3, 4, 5])
def test_the_shape_is_the_textbook_formula_where_that_evaluates_in_floating_point(lines: int) -> None:
    beta_l = free_free_beta_l(lines)
    theta = np.linspace(0.0, beta_l, 2001)
    sigma = (math.cosh(beta_l) - math.cos(beta_l)) / (math.sinh(beta_l) - math.sin(beta_l))
    textbook = np.cosh(theta) + np.cos(theta) - sigma * (np.sinh(theta) + np.sin(theta))
    np.testing.assert_allclose(deflection(theta / beta_l * 80.0, 80.0, lines), textbook / math.hypot(1.0, sigma),
                               rtol=0, atol=1e-9)


def test_the_interior_antinodes_are_one_the_free_ends_swing_further_and_the_even_mode_is_symmetric() -> None:
    x_mm = np.linspace(0.0, LENGTH_MM, 260_001)
    wave = deflection(x_mm, LENGTH_MM, 20)
    interior = (x_mm > 20.0) & (x_mm < LENGTH_MM - 20.0)
    assert abs(np.abs(wave[interior]).max() - 1.0) < 1e-4
    assert abs(abs(wave[0]) - math.sqrt(2.0)) < 1e-9 and abs(abs(wave[-1]) - math.sqrt(2.0)) < 1e-9
    np.testing.assert_allclose(wave, wave[::-1], atol=1e-9)
    spacing_mm = np.diff(x_mm[:-1][np.sign(wave[1:]) != np.sign(wave[:-1])])
    assert np.allclose(spacing_mm[3:-3], LENGTH_MM / 19.5, rtol=2e-3)  # "about 6.5 mm apart" (issue 11)


@settings(max_examples=40, deadline=None)
@given(x_mm=st.floats(-5.0, LENGTH_MM + 5.0), width_mm=st.floats(0.2, 60.0))
def test_the_patch_mean_is_the_integral_of_the_magnitude_over_the_patch(x_mm: float, width_mm: float) -> None:
    low, high = max(min(x_mm, LENGTH_MM) - width_mm / 2, 0.0), min(max(x_mm, 0.0) + width_mm / 2, LENGTH_MM)
    integral, _ = quad(lambda s: abs(float(deflection(s, LENGTH_MM, 20))), low, high, limit=400)
    assert float(patch_mean(x_mm, LENGTH_MM, 20, width_mm)) == pytest.approx(integral / (high - low), abs=2e-5)


def test_a_point_contact_feels_the_point_and_bad_values_are_refused() -> None:
    x_mm = np.linspace(0.0, LENGTH_MM, 999)
    np.testing.assert_allclose(patch_mean(x_mm, LENGTH_MM, 20, 0.0), np.abs(deflection(x_mm, LENGTH_MM, 20)))
    for call in (lambda: deflection(math.nan, LENGTH_MM, 20), lambda: patch_mean(1.0, LENGTH_MM, 20, -1.0),
                 lambda: patch_mean(1.0, LENGTH_MM, 20, math.inf), lambda: free_free_beta_l(1),
                 lambda: deflection(1.0, 0.0, 20), lambda: deflection(1.0, math.inf, 20)):
        with pytest.raises(ValueError):
            call()


def test_the_example_device_is_the_default_plus_its_mode_shape() -> None:
    shipped = DEFAULT_DEVICE.read_text().splitlines()[1:]
    example = [line for line in EXAMPLE.read_text().splitlines() if not line.startswith("#")]
    assert [line for line in example if "(mode shape)" not in line] == [
        line for line in shipped if not line.startswith(("label:", "description:"))]
    assert SHAPED.contact_width_m == pytest.approx(0.010) and PLAIN.contact_width_m is None
    x_mm = np.linspace(-3.0, LENGTH_MM + 3.0, 100_001)
    np.testing.assert_allclose(SHAPED.mode_gain(x_mm), patch_mean(x_mm, LENGTH_MM, 20, 10.0), rtol=0, atol=2e-4)
    np.testing.assert_array_equal(PLAIN.mode_gain(np.array([0.0, 3.3, 65.0])), 1.0)


@pytest.mark.parametrize(("mode", "change", "expected"), [
    ("[20, 0]", "mode_shape:\n  contact_width_mm: 131.0\n", "mode_shape.contact_width_mm: must be <= plate.length_mm"),
    ("[20, 0]", "mode_shape:\n  contact_width_mm: -1.0\n", "mode_shape.contact_width_mm:"),
    ("[20, 0]", "mode_shape:\n  contact_width_mm: '10'\n", "mode_shape.contact_width_mm:"),
    ("[20, 0]", "mode_shape:\n  contact_width_mm: .nan\n", "mode_shape.contact_width_mm:"),
    ("[20, 0]", "mode_shape:\n  contact_width_mm: 10.0\n  nodes: 3\n", "mode_shape.nodes:"),
    ("[20, 1]", "mode_shape:\n  contact_width_mm: 10.0\n", "mode_shape: needs the plate's mode to be [m, 0]"),
    ("[1, 0]", "mode_shape:\n  contact_width_mm: 10.0\n", "mode_shape: needs the plate's mode to be [m, 0]"),
])
def test_a_bad_mode_shape_is_one_line_naming_it(tmp_path: Path, mode: str, change: str, expected: str) -> None:
    text = DEFAULT_DEVICE.read_text().replace("  mode: [20, 0]\n", f"  mode: {mode}\n")
    path = tmp_path / "device.yaml"
    path.write_text(text.replace("source:\n", change + "source:\n", 1))
    done = tpad_rt("check", str(path))
    assert done.returncode == 1 and expected in done.stderr, done.stderr


def _telemetry(device: Device, texture: Path, options: RenderOptions) -> dict[str, np.ndarray]:
    """A 100 mm/s swipe from x = 5 to 125 mm, every block's telemetry."""
    seconds = 1.2
    pipeline = Pipeline(device, load_compiled(texture), FS_HZ, options=replace(options, finger_ring=2048))
    for t_s in np.arange(0.0, seconds, 1e-3):
        pipeline.push_finger(t_s, 5.0 + 100.0 * t_s, 30.0, 0.5)
    pipeline.start()
    out = np.empty(BLOCK, dtype=np.float32)
    for _ in range(int(seconds * FS_HZ / BLOCK)):
        pipeline.render(out)
    return pipeline.drain_telemetry()


def _steady(rows: dict[str, np.ndarray]) -> np.ndarray:
    """Touching blocks after the start ramp, the drive not held at a limit."""
    flags = rows["saturated"].astype(np.int64)
    return ((flags & (layout.FLAG_WATCHDOG | layout.FLAG_VOLTAGE | layout.FLAG_POWER)) == 0) & (rows["t"] > 0.02)


def test_the_command_asks_for_the_amplitude_under_the_finger_unless_told_not_to(tmp_path: Path) -> None:
    texture = _even(tmp_path, 0.9)
    plain = _telemetry(PLAIN, texture, RenderOptions())
    shaped = _telemetry(SHAPED, texture, RenderOptions())
    uncompensated = _telemetry(SHAPED, texture, RenderOptions(mode_compensation=False))
    steady = _steady(plain) & _steady(shaped)
    assert np.count_nonzero(steady) > 0.9 * len(steady)
    np.testing.assert_array_equal(shaped["x_mm"], plain["x_mm"])
    gain = mode_gain_table(SHAPED, shaped["x_mm"][steady])
    assert gain.min() < 0.6 < 0.7 < gain.max()  # the patch crosses antinodes and nodes
    np.testing.assert_allclose(shaped["amplitude_um"][steady] * gain, plain["amplitude_um"][steady], rtol=1e-4)
    np.testing.assert_array_equal(uncompensated["amplitude_um"], plain["amplitude_um"])


def test_the_gain_table_is_floored_so_a_point_contact_at_a_node_asks_a_bounded_drive(tmp_path: Path) -> None:
    point = replace(SHAPED, contact_width_m=0.0)
    nodes_mm = np.linspace(0.0, LENGTH_MM, 130_001)
    gains = mode_gain_table(point, nodes_mm)
    assert gains.min() == MODE_GAIN_FLOOR and np.all(np.isfinite(gains))
    rows = _telemetry(point, _even(tmp_path, 0.9), RenderOptions())
    touching = (rows["saturated"].astype(np.int64) & layout.FLAG_WATCHDOG) == 0
    assert np.all(rows["voltage_v"] <= point.max_voltage_v) and not np.any(rows["saturated"].astype(np.int64)
                                                                              & layout.FLAG_FAULT)
    assert np.any(rows["saturated"][touching].astype(np.int64) & layout.FLAG_VOLTAGE)  # near the nodes: at the limit


def _render(tmp_path: Path, name: str, *extra: str) -> dict[str, np.ndarray]:
    out = tmp_path / f"{name}.npz"
    done = tpad_rt("render", str(_even(tmp_path, 0.8)), "--device", str(EXAMPLE), "--input",
                   "scripted://swipe?speed_mm_s=100&from_mm=10&to_mm=120&repeat=1", "--out", str(out), *extra)
    assert done.returncode == 0, done.stderr
    return read_recording(out).blocks


def test_the_simulated_plate_feels_the_standing_wave_and_the_compensation_restores_the_texture(tmp_path: Path) -> None:
    compensated = _render(tmp_path, "compensated")
    uncompensated = _render(tmp_path, "uncompensated", "--no-mode-compensation")
    steady = _steady(compensated) & _steady(uncompensated)
    error = np.abs(compensated["achieved_mu"] - 0.8)[steady]
    shown = np.abs(uncompensated["achieved_mu"] - 0.8)[steady]
    assert error.mean() < 0.01 and error.max() < 0.05  # where there is headroom the plate follows the texture
    assert shown.mean() > 5 * error.mean() and shown.max() > 0.1  # without, the finger feels the nodes
    # The friction the uncompensated finger feels rises and falls with the patch mean: once per nodal spacing.
    felt = uncompensated["achieved_mu"][steady]
    gain = SHAPED.mode_gain(uncompensated["x_mm"][steady])
    assert np.corrcoef(felt, gain)[0, 1] < -0.9


def test_show_draws_the_standing_wave_and_divides_the_drive_by_it(tmp_path: Path) -> None:
    texture = load_compiled(_even(tmp_path, 0.9))
    finger = Finger(100.0, 0.0, 0.5)
    shaped, plain = plate_maps(texture, SHAPED, finger, 0.0, 0.5), plate_maps(texture, PLAIN, finger, 0.0, 0.5)
    np.testing.assert_allclose(shaped.volts_asked * mode_gain_table(SHAPED, shaped.x_mm)[None, :], plain.volts_asked)
    figure = draw(shaped, texture, SHAPED, finger, 0.0, "even.yaml")
    titles = [axes.get_title(loc="left") for axes in figure.axes if axes.get_visible() and axes.get_title(loc="left")]
    assert len(titles) == 4 and titles[3].startswith("20 x 0 mode, nodal lines 6.7 mm apart: a 10 mm contact patch "
                                                     "feels 0.55 to 0.73 of the antinode amplitude")
    assert len([t for t in (axes.get_title(loc="left") for axes in draw(plain, texture, PLAIN, finger, 0.0,
                                                                         "even.yaml").axes) if t]) == 3
    done = tpad_rt("show", "textures/grating.yaml", "--device", str(EXAMPLE), "--out", str(tmp_path / "s.png"))
    assert done.returncode == 0 and (tmp_path / "s.png").stat().st_size > 10_000, done.stderr
