"""Property (issue 8): every texture and device file `tpad-rt check` accepts renders finite, in-limit output.

Random valid files (every texture kind, layers nested with regions; devices drawn across
the whole accepted ranges, their ends included) are written as YAML, checked, loaded
with the real loaders and rendered by the Pipeline for a swipe across the plate, then
played into the simulated plate. Every sample must be finite and within the voltage
limit, the telemetry's power within the budget, nothing may trip the kernel's fault
guard, and the simulated plate's measurements must be finite.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from tpad_rt.config import check_file
from tpad_rt.config.device_schema import MAX_Q, MIN_FORCE_STEP_N, MIN_Q
from tpad_rt.config.fields import MAX_ANGLE_DEG, MAX_COORDINATE_MM, MAX_LENGTH_MM, MIN_LENGTH_MM
from tpad_rt.config.texture_schema import MAX_FREQUENCY_HZ, MAX_GAIN, MAX_HEIGHT_MM, MIN_FREQUENCY_HZ
from tpad_rt.device import Device
from tpad_rt.physics import electromech
from tpad_rt.kernel import layout
from tpad_rt.limits import MAX_FORCE_N, MAX_RATE_HZ
from tpad_rt.outputs.sim import SimOutput
from tpad_rt.pipeline import MAX_CARRIER_FRACTION, Pipeline, RenderOptions, device_tables
from tpad_rt.texture import load_compiled

BLOCKS = 20
BLOCK = 64
WAVEFORMS = ["sine", "square", "triangle", "sawtooth"]


def _number(low: float, high: float, log: bool = False) -> st.SearchStrategy[float]:
    """A float in [low, high]: often one of the ends, else uniform (log-uniform with ``log``)."""
    ends = st.sampled_from([low, high])
    if log:
        inside = st.floats(math.log10(low), math.log10(high)).map(lambda e: min(max(10.0**e, low), high))
    else:
        inside = st.floats(low, high)
    return st.one_of(ends, inside)


_LENGTH = _number(MIN_LENGTH_MM, MAX_LENGTH_MM, log=True)
_COORDINATE = _number(-MAX_COORDINATE_MM, MAX_COORDINATE_MM) | st.floats(-200.0, 300.0)
_POINT = st.tuples(_COORDINATE, _COORDINATE).map(list)
_ANGLE = _number(-MAX_ANGLE_DEG, MAX_ANGLE_DEG)
_LEVEL = st.sampled_from([1e-300, 0.01, 1.0]) | st.floats(1e-300, 1.0)
_FRACTION = st.sampled_from([5e-324, 0.5, 1.0 - 2**-53]) | st.floats(0.0, 1.0, exclude_min=True, exclude_max=True)


@st.composite
def _levels(draw: st.DrawFn, *names: str) -> dict[str, float]:
    """Friction levels, increasing in the order of ``names``."""
    return dict(zip(names, sorted(draw(_LEVEL) for _ in names)))


@st.composite
def _periodic(draw: st.DrawFn) -> dict[str, Any]:
    waveform = draw(st.sampled_from(WAVEFORMS))
    spec: dict[str, Any] = {"waveform": waveform, "friction": draw(_levels("low", "high"))}
    if waveform in ("square", "triangle"):
        spec["duty"] = draw(_FRACTION)
    return spec


@st.composite
def _image(draw: st.DrawFn, folder: Path) -> dict[str, Any]:
    """An image map: a small random ``.npy`` array written to ``folder``."""
    rows, cols = draw(st.integers(1, 8)), draw(st.integers(1, 8))
    pixels = np.random.default_rng(draw(st.integers(0, 2**32 - 1))).uniform(0.0, 1.0, (rows, cols))
    name = f"image{len(list(folder.glob('*.npy')))}.npy"
    np.save(folder / name, pixels)
    return {"image": name, "size_mm": [draw(_LENGTH), draw(_LENGTH)], "origin_mm": draw(_POINT),
            "wrap": draw(st.sampled_from(["tile", "clamp"]))}


@st.composite
def _shape(draw: st.DrawFn, outline: bool) -> dict[str, Any]:
    name = draw(st.sampled_from(["rect", "circle", "line"] if outline else ["rect", "circle"]))
    if name == "rect":
        return {"rect": {"x_mm": draw(_COORDINATE), "y_mm": draw(_COORDINATE), "w_mm": draw(_LENGTH),
                         "h_mm": draw(_LENGTH)}}
    if name == "circle":
        return {"circle": {"center_mm": draw(_POINT), "radius_mm": draw(_LENGTH)}}
    start = draw(_POINT)
    end = draw(st.just(start) | _POINT)
    assume(end == start or math.dist(start, end) >= MIN_LENGTH_MM)
    return {"line": {"from_mm": start, "to_mm": end}}


@st.composite
def _leaf(draw: st.DrawFn, folder: Path) -> dict[str, Any]:
    """A texture of any kind but layers."""
    kind = draw(st.sampled_from(["grating", "temporal", "bitmap", "gradient", "bumps", "edges"]))
    if kind == "grating":
        return {"kind": kind, **draw(_periodic()), "period_mm": draw(_LENGTH), "angle_deg": draw(_ANGLE),
                "phase_deg": draw(_ANGLE)}
    if kind == "temporal":
        return {"kind": kind, **draw(_periodic()), "frequency_hz": draw(_number(MIN_FREQUENCY_HZ, MAX_FREQUENCY_HZ))}
    if kind == "bitmap":
        return {"kind": kind, **draw(_image(folder)), "invert": draw(st.booleans()),
                "friction": draw(_levels("low", "high"))}
    if kind == "gradient":
        shape = draw(st.sampled_from(["bump", "ridge", "sine", "image"]))
        height: dict[str, Any] = {"shape": shape, "height_mm": draw(_number(-MAX_HEIGHT_MM, MAX_HEIGHT_MM))}
        if shape == "bump":
            height |= {"center_mm": draw(_POINT), "radius_mm": draw(_LENGTH)}
        elif shape == "ridge":
            height |= {"center_mm": draw(_POINT), "angle_deg": draw(_ANGLE), "width_mm": draw(_LENGTH)}
        elif shape == "sine":
            height |= {"period_mm": draw(_LENGTH), "angle_deg": draw(_ANGLE)}
        else:
            height |= draw(_image(folder))
        return {"kind": kind, "height": height, "gain": draw(_number(-MAX_GAIN, MAX_GAIN)),
                "friction": draw(_levels("low", "base", "high"))}
    if kind == "bumps":
        placement: dict[str, Any] = (
            {"centers_mm": draw(st.lists(_POINT, min_size=1, max_size=5))} if draw(st.booleans())
            else {"grid": {"spacing_mm": [draw(_LENGTH), draw(_LENGTH)], "offset_mm": draw(_POINT)}}
        )
        return {"kind": kind, **placement, "radius_mm": draw(_LENGTH),
                "profile": draw(st.sampled_from(["cosine", "gaussian", "disk"])),
                "friction": {"inside": draw(_LEVEL), "outside": draw(_LEVEL)}}
    return {"kind": kind, "shapes": draw(st.lists(_shape(outline=True), min_size=1, max_size=4)),
            "width_mm": draw(_LENGTH), "profile": draw(st.sampled_from(["step", "cosine"])),
            "friction": {"edge": draw(_LEVEL), "background": draw(_LEVEL)}}


@st.composite
def _texture(draw: st.DrawFn, folder: Path, depth: int = 1) -> dict[str, Any]:
    """Any texture kind; layers nest up to three levels, each layer maybe with an op and a region."""
    if depth > 3 or not draw(st.integers(0, 3)) == 0:
        return draw(_leaf(folder))
    layers = []
    for _ in range(draw(st.integers(1, 3))):
        layer = draw(_texture(folder, depth + 1))
        layer["op"] = draw(st.sampled_from(["multiply", "min", "max", "add"]))
        if draw(st.booleans()):
            layer["region"] = draw(_shape(outline=False))
        layers.append(layer)
    return {"kind": "layers", "layers": layers}


@st.composite
def _forces(draw: st.DrawFn) -> list[float]:
    """A force table: 1 to 4 knots in [0, MAX_FORCE_N], at least MIN_FORCE_STEP_N apart."""
    forces = [draw(st.sampled_from([0.0, MAX_FORCE_N - MIN_FORCE_STEP_N]) | st.floats(0.0, 10.0))]
    for _ in range(draw(st.integers(0, 3))):
        step = draw(st.sampled_from([MIN_FORCE_STEP_N]) | st.floats(MIN_FORCE_STEP_N, 20.0))
        if forces[-1] + step > MAX_FORCE_N:
            break
        forces.append(forces[-1] + step)
    return forces


@st.composite
def _circuit(draw: st.DrawFn, forces: list[float], carrier_hz: float) -> dict[str, Any]:
    """A circuit across the ranges whose Q stays in (MIN_Q, MAX_Q] between every two knots, which resonates,
    loaded, within a factor 2 of ``carrier_hz`` and rings there (Device.derived_problems).

    C is drawn over its whole range, L so that the branch resonates near the carrier (both
    varying by at most 1.4x across the knots); R is then drawn where the schema's bounds on
    Q hold between every two knots; C0 and the shunt over their whole ranges.
    """
    n = len(forces)
    omega = 2 * math.pi * carrier_hz
    c_base_pf = draw(_number(1e-3, 1e6, log=True))
    l0 = 1 / (omega**2 * c_base_pf * 1e-12) * draw(st.floats(0.6, 1.6))
    assume(1e-6 <= l0 <= 1e4)
    l_h = [min(max(l0 * draw(st.floats(0.85, 1.2)), 1e-6), 1e4) for _ in range(n)]
    c_pf = [min(max(c_base_pf * draw(st.floats(0.85, 1.2)), 1e-3), 1e6) for _ in range(n)]
    # The schema bounds Q between knots by the smallest L with the largest C and R, and the reverse.
    lowest, highest = math.sqrt(min(l_h) / (max(c_pf) * 1e-12)), math.sqrt(max(l_h) / (min(c_pf) * 1e-12))
    r_low = max(1e-3, highest / MAX_Q * (1 + 1e-9))
    r_high = min(1e7, lowest / MIN_Q * (1 - 1e-9))
    assume(r_low < r_high)
    r_ohm = [draw(_number(r_low, r_high, log=True)) for _ in range(n)]
    circuit = {"c0_nf": draw(_number(1e-3, 1e5, log=True)), "shunt_ohm": draw(_number(1e-3, 1e6, log=True)),
               "gamma_n_per_v": draw(_number(1e-6, 1e3, log=True)),
               "force_n": forces, "motional_l_h": l_h, "motional_c_pf": c_pf, "motional_r_ohm": r_ohm}
    # The shunt seen through C0 must neither damp the branch below ringing nor pull its resonance away.
    c0_f = circuit["c0_nf"] * 1e-9
    for l_value, c_value, r_value in zip(l_h, c_pf, r_ohm):
        resonance = float(electromech.loaded_resonance_hz(c0_f, l_value, c_value * 1e-12, circuit["shunt_ohm"]))
        tau = float(electromech.loaded_time_constant_s(carrier_hz, c0_f, l_value, r_value, circuit["shunt_ohm"]))
        assume(0.55 * carrier_hz <= resonance <= 1.8 * carrier_hz and math.pi * resonance * tau > 0.55)
    return circuit


@st.composite
def _device(draw: st.DrawFn) -> dict[str, Any]:
    """A device file across the whole accepted ranges."""
    full_scale_v = draw(_number(0.1, 10_000.0, log=True))
    carrier_hz = draw(_number(1000.0, 200_000.0))
    material = {"thickness_mm": draw(_number(0.01, 100.0, log=True)), "density_g_cm3": draw(_number(0.1, 50.0)),
                "youngs_modulus_gpa": draw(_number(0.01, 2000.0, log=True))}
    length_mm = draw(_number(1.0, 1000.0))
    shaped = draw(st.booleans())  # a mode shape needs an [m >= 2, 0] mode
    mode = [draw(st.integers(2, 1000)), 0] if shaped else [draw(st.integers(1, 1000)), draw(st.integers(0, 1000))]
    return {
        "format_version": 2, "label": "random", "description": "a random device across the accepted ranges",
        "plate": {"material": "glass", **material, "length_mm": length_mm, "width_mm": draw(_number(1.0, 1000.0)),
                  "mode": mode},
        "actuator": material,
        "carrier_hz": carrier_hz,
        "amplifier": {"volts_per_full_scale": full_scale_v,
                      "max_voltage_v": draw(_number(0.1, full_scale_v) if full_scale_v > 0.1 else st.just(0.1))},
        "circuit": draw(_circuit(draw(_forces()), carrier_hz)),
        "friction_model": {"mu0": draw(_number(0.01, 10.0, log=True)),
                           "poisson": draw(st.sampled_from([0.0, 0.5 - 2**-53])
                                           | st.floats(0.0, 0.5, exclude_max=True)),
                           "psi_star": draw(_number(0.01, 1000.0, log=True))},
        "speed_floor_mm_s": draw(_number(0.1, 1000.0, log=True)),
        "power_budget_w": draw(_number(0.001, 1000.0, log=True)),
        "preemphasis": draw(st.booleans()),
        **({"mode_shape": {"contact_width_mm": draw(_number(0.0, length_mm))}} if shaped else {}),
        "source": {"everything": "random"},
    }


def _written(folder: Path, name: str, tree: dict[str, Any]) -> Path:
    path = folder / name
    path.write_text(yaml.safe_dump(tree))
    assert check_file(path) == [], f"{name} should be valid:\n{path.read_text()}"
    return path


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large])
@given(data=st.data())
def test_every_valid_file_renders_finite_in_limit_output(tmp_path_factory: pytest.TempPathFactory, data: Any) -> None:
    folder = tmp_path_factory.mktemp("files")
    texture = load_compiled(_written(folder, "texture.yaml",
                                     {"description": "random", **data.draw(_texture(folder), "texture")}))
    device = Device.from_file(_written(folder, "device.yaml", data.draw(_device(), "device")))
    track = data.draw(st.booleans(), "track")
    highest_hz = float(device_tables(device, track)[0][layout.DEV_CARRIER_HZ].max())
    fs_hz = max(192_000, math.ceil(highest_hz / MAX_CARRIER_FRACTION))
    assume(fs_hz <= MAX_RATE_HZ)
    options = RenderOptions(track=track, mode_compensation=data.draw(st.booleans(), "mode_compensation"))
    pipeline = Pipeline(device, texture, fs_hz, options=options)
    sim = SimOutput(device, fs_hz)
    length_mm, width_mm = device.plate.length_m * 1e3, device.plate.width_m * 1e3
    y_mm = data.draw(st.floats(0.0, width_mm), "y_mm")
    force_n = data.draw(st.none() | st.floats(0.0, 5.0), "force_n")
    pipeline.start()
    out = np.empty(BLOCK, dtype=np.float32)
    for block in range(BLOCKS):
        pipeline.push_finger(pipeline.time_s, length_mm * block / (BLOCKS - 1), y_mm, force_n)
        pipeline.render(out)
        assert np.all(np.isfinite(out))
        assert np.max(np.abs(out).astype(np.float64) * device.volts_per_full_scale) <= device.max_voltage_v
        sim.write(out, pipeline.last_telemetry_row())
    telemetry = pipeline.drain_telemetry()
    assert np.all(np.isfinite(telemetry["power_w"])) and np.all(telemetry["power_w"] <= device.power_budget_w)
    assert np.all(telemetry["voltage_v"] <= device.max_voltage_v)
    assert not np.any(telemetry["saturated"] & layout.FLAG_FAULT), "a valid file tripped the kernel's fault guard"
    for name, values in sim.measurements().items():
        assert values.shape == (BLOCKS,) and np.all(np.isfinite(values)), name
