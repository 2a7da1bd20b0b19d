"""``tpad-rt show``: the figure, the maps behind it, and one clear line for every bad input."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml
import pytest
from PIL import Image

from tpad_rt.cli import main
from tpad_rt.config.texture_schema import MAX_FREQUENCY_HZ
from tpad_rt.errors import ConfigError
from tpad_rt.plate_maps import MAX_T_S, Finger, plate_maps
from tpad_rt.device import Device
from tpad_rt.physics.friction import relative_friction
from tpad_rt.texture import load_compiled

REPO = Path(__file__).resolve().parents[1]
TEXTURES = REPO / "textures"
GOOD = REPO / "tests" / "good_files"
#: figsize (8.6, 11.0) inches at 150 dpi.
FIGURE_PX = (1290, 1650)


@pytest.mark.parametrize(
    ("texture", "extra"),
    [
        (TEXTURES / "layers_window.yaml", []),
        (GOOD / "gradient_image.yaml", ["--device", str(GOOD / "device.yaml"), "--direction-deg", "135"]),
        (TEXTURES / "temporal_pulse.yaml", ["--speed-mm-s", "0", "--t-s", "0.02"]),
    ],
    ids=["layers", "gradient-other-device", "still-finger"],
)
def test_show_writes_a_png(texture: Path, extra: list[str], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "figure.png"
    assert main(["show", str(texture), "--resolution-mm", "2", "--out", str(out), *extra]) == 0
    with Image.open(out) as image:
        image.load()
        assert image.format == "PNG" and image.size == FIGURE_PX
    stdout = capsys.readouterr().out
    assert stdout.startswith(f"wrote {out}: ") and "% of the plate saturated" in stdout
    assert stdout.count("\n") == (2 if "temporal" in texture.name else 1)  # a flat map in time: a second line


def test_a_flat_map_of_a_texture_that_changes_in_time_says_which_t_s_draws_another_level(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """temporal_pulse is 1.0 (vibration off) everywhere at t = 0: show says it changes in time and names a --t-s
    that draws another level; at that time the map is that level. A texture that varies over the plate says
    nothing more."""
    out = tmp_path / "pulse.png"
    assert main(["show", str(TEXTURES / "temporal_pulse.yaml"), "--resolution-mm", "5", "--out", str(out)]) == 0
    hint = capsys.readouterr().out.splitlines()[1]
    low = yaml.safe_load((TEXTURES / "temporal_pulse.yaml").read_text())["friction"]["low"]
    assert hint.startswith("the map is flat at t = 0 s (1 everywhere): this texture changes in time, not over the "
                           f"plate (friction {low:g} to 1 over 2 s from there); --t-s "), hint
    t_s, level = hint.split("--t-s ")[1].split(" draws it at ")
    assert float(level) == low
    _, maps = _maps("temporal_pulse.yaml", t_s=float(t_s))
    assert np.all(maps.friction == low)
    assert main(["show", str(TEXTURES / "grating.yaml"), "--resolution-mm", "5", "--out", str(out)]) == 0
    assert capsys.readouterr().out.count("\n") == 1


def _maps(texture: str, speed_mm_s: float = 100.0, force_n: float = 0.5, t_s: float = 0.0):  # type: ignore[no-untyped-def]
    device = Device.default()
    return device, plate_maps(load_compiled(TEXTURES / texture), device, Finger(speed_mm_s, 0.0, force_n), t_s, 1.0)


def test_maps_cover_the_plate_and_invert_the_friction_model() -> None:
    device, maps = _maps("grating.yaml", force_n=2.0)  # 2 N: the low level needs ~49 V
    assert maps.friction.shape == (60, 130) == maps.volts.shape == maps.power_w.shape
    assert maps.x_mm[0] == 0.5 and maps.y_mm[-1] == 59.5
    amplitude_m = maps.volts_asked * device.amplitude_m_per_v(2.0)
    achieved = relative_friction(amplitude_m, device.carrier_hz, 0.1, device.mu0, device.poisson, device.psi_star)
    assert np.allclose(achieved, maps.friction, atol=1e-12)
    assert np.array_equal(maps.saturated, maps.volts_asked > device.max_voltage_v)
    assert maps.volts.max() == device.max_voltage_v and maps.saturated.any()
    assert np.allclose(maps.power_w, device.power_w_per_v2(2.0) * maps.volts**2)


def test_a_slow_finger_is_inverted_at_the_speed_floor() -> None:
    _, still = _maps("grating.yaml", speed_mm_s=0.0)
    _, crawling = _maps("grating.yaml", speed_mm_s=1.0)
    assert np.array_equal(still.volts_asked, crawling.volts_asked)
    assert still.saturated_percent == 0.0


def test_maps_at_the_latest_time_are_finite_and_keep_the_phase_of_the_fastest_pulse(tmp_path: Path) -> None:
    """At MAX_T_S every shipped texture maps to finite values, and a sine pulse at the fastest frequency a texture
    may have is still where its period says (a quarter cycle before MAX_T_S: its low level); past MAX_T_S the time
    is refused (1e20 s gave a NaN phase and a traceback)."""
    device, finger = Device.default(), Finger(100.0, 0.0, 0.5)
    for path in sorted(TEXTURES.glob("*.yaml")):
        maps = plate_maps(load_compiled(path), device, finger, MAX_T_S, 5.0)
        assert all(np.isfinite(values).all() for values in (maps.friction, maps.volts_asked, maps.power_w)), path
    fast = tmp_path / "fast.yaml"
    fast.write_text(f"description: fastest sine pulse\nkind: temporal\nwaveform: sine\nfrequency_hz: "
                    f"{MAX_FREQUENCY_HZ}\nfriction: {{low: 0.5, high: 1.0}}\n")
    pulse = load_compiled(fast)
    quarter_s = 0.25 / MAX_FREQUENCY_HZ
    assert plate_maps(pulse, device, finger, MAX_T_S - quarter_s, 5.0).friction == pytest.approx(0.5, abs=1e-9)
    assert plate_maps(pulse, device, finger, MAX_T_S, 5.0).friction == pytest.approx(0.75, abs=1e-9)
    for late_s in (math.nextafter(MAX_T_S, math.inf), 1e20):
        with pytest.raises(ConfigError, match=r"--t-s: must be from 0 to 1e\+06 s"):
            plate_maps(pulse, device, finger, late_s, 5.0)


def test_show_runs_as_a_program_and_prints_one_line(tmp_path: Path) -> None:
    out = tmp_path / "grating.png"
    done = subprocess.run(
        [sys.executable, "-m", "tpad_rt", "show", str(TEXTURES / "grating.yaml"), "--resolution-mm", "2",
         "--out", str(out)],
        capture_output=True, text=True, check=False,
    )
    assert done.returncode == 0, done.stderr
    assert out.is_file() and done.stdout.startswith("wrote ")


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["missing.yaml"], "missing.yaml"),
        ([str(GOOD / "device.yaml")], "device.yaml"),
        ([str(GOOD / "grating.yaml"), "--device", str(GOOD / "grating.yaml")], "grating.yaml"),
        ([str(GOOD / "grating.yaml"), "--speed-mm-s", "-1"], "--speed-mm-s: must be a finite number >= 0, got -1"),
        ([str(GOOD / "grating.yaml"), "--force-n", "-0.5"], "--force-n: must be a finite number >= 0, got -0.5"),
        ([str(GOOD / "grating.yaml"), "--t-s", "-0.5"], "--t-s: must be a finite number >= 0, got -0.5"),
        ([str(GOOD / "grating.yaml"), "--t-s", "1e20"], "--t-s: must be from 0 to 1e+06 s (a texture repeats with "),
        ([str(GOOD / "grating.yaml"), "--resolution-mm", "0"], "--resolution-mm: must be a finite number > 0, got 0"),
        ([str(GOOD / "grating.yaml"), "--resolution-mm", "0.001"], "--resolution-mm: 0.001 gives 130000 x 60000"),
    ],
    ids=["missing", "device-as-texture", "texture-as-device", "speed", "force", "time", "too-late", "resolution",
         "too-fine"],
)
def test_bad_input_is_one_line_and_exit_1(
    arguments: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["show", *arguments, "--out", str(tmp_path / "x.png")]) == 1
    stderr = capsys.readouterr().err
    assert message in stderr and "Traceback" not in stderr
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize(
    ("out", "message"),
    [("figure.jpg", "--out: must end in .png, .pdf, .svg"), ("no/such/folder/figure.png", "figure.png: cannot write figures there: no folder ")],
)
def test_bad_output_path_is_one_line_and_exit_1(
    out: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["show", str(GOOD / "grating.yaml"), "--resolution-mm", "5", "--out", str(tmp_path / out)]) == 1
    stderr = capsys.readouterr().err
    assert message in stderr and "Traceback" not in stderr and stderr.count("\n") == 1


@pytest.mark.parametrize(("option", "value"), [("--speed-mm-s", "fast"), ("--force-n", "nan"),
                                               ("--direction-deg", "inf"), ("--t-s", "1_000")])
def test_a_value_that_is_not_a_number_is_a_usage_error(capsys: pytest.CaptureFixture, option: str, value: str) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["show", str(GOOD / "grating.yaml"), option, value, "--out", "x.png"])
    assert exit_info.value.code == 1
    assert f"argument {option}: must be a finite number, got '{value}'" in capsys.readouterr().err
