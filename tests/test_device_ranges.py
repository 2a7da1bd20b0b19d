"""Device ranges (docs/formats.md "Ranges, and why"): bounds, the Q rule, the force spacing, derived tables."""

from __future__ import annotations

import copy
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from tpad_rt.config import check_file, load_device
from tpad_rt.device import Device
from tpad_rt.shipped import DEVICES_DIR
from tpad_rt.errors import ConfigError
from tpad_rt.outputs import open_output
from tpad_rt.outputs.sim import SimOutput

GOOD = Path(__file__).parent / "good_files" / "device.yaml"
BASE: dict[str, Any] = yaml.safe_load(GOOD.read_text())

#: (path to the key, accepted limit, refused value just past it, the refusal's message)
BOUNDS = [
    (("plate", "thickness_mm"), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    (("plate", "thickness_mm"), 100.0, 100.5, "must be <= 100, got 100.5"),
    (("plate", "density_g_cm3"), 0.1, 0.099, "must be >= 0.1, got 0.099"),
    (("plate", "youngs_modulus_gpa"), 2000.0, 2000.5, "must be <= 2000, got 2000.5"),
    (("plate", "length_mm"), 1000.0, 1000.5, "must be <= 1000, got 1000.5"),
    (("plate", "width_mm"), 1.0, 0.99, "must be >= 1, got 0.99"),
    (("plate", "mode", 0), 1000, 1001, "must be <= 1000, got 1001"),
    (("actuator", "density_g_cm3"), 50.0, 50.5, "must be <= 50, got 50.5"),
    (("actuator", "youngs_modulus_gpa"), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    (("carrier_hz",), 200000.0, 200000.5, "must be <= 200000, got 200000.5"),
    (("carrier_hz",), 1000.0, 999.5, "must be >= 1000, got 999.5"),
    (("amplifier", "volts_per_full_scale"), 10000.0, 10000.5, "must be <= 10000, got 10000.5"),
    (("amplifier", "max_voltage_v"), 0.1, 0.099, "must be >= 0.1, got 0.099"),
    (("circuit", "force_n", 1), 0.001, 0.0009,
     "must be >= 0.001 (forces must increase by at least 0.001 N), got 0.0009"),
    (("circuit", "gamma_n_per_v"), 1e-6, 9.9e-7, "must be >= 1e-06, got 9.9e-07"),
    (("circuit", "gamma_n_per_v"), 1e3, 1000.5, "must be <= 1000, got 1000.5"),
    (("circuit", "c0_nf"), 0.001, 0.00099, "must be >= 0.001, got 0.00099"),
    (("circuit", "c0_nf"), 1e5, 100000.5, "must be <= 100000, got 100000.5"),
    (("circuit", "shunt_ohm"), 0.001, 0.00099, "must be >= 0.001, got 0.00099"),
    (("circuit", "shunt_ohm"), 1e6, 1000000.5, "must be <= 1e+06, got 1000000.5"),
    (("circuit", "motional_l_h", 1), 1e-6, 9.9e-7, "must be >= 1e-06, got 9.9e-07"),
    (("circuit", "motional_c_pf", 1), 1e6, 1000000.5, "must be <= 1e+06, got 1000000.5"),
    (("circuit", "motional_r_ohm", 0), 1e-3, 9.9e-4, "must be >= 0.001, got 0.00099"),
    (("circuit", "force_n", 2), 50.0, 50.5, "must be <= 50, got 50.5"),
    (("friction_model", "mu0"), 0.01, 0.0099, "must be >= 0.01, got 0.0099"),
    (("friction_model", "mu0"), 10.0, 10.5, "must be <= 10, got 10.5"),
    (("friction_model", "poisson"), 0.0, -0.01, "must be >= 0, got -0.01"),
    (("friction_model", "poisson"), 0.4999, 0.5, "must be < 0.5, got 0.5"),
    (("friction_model", "psi_star"), 1000.0, 1000.5, "must be <= 1000, got 1000.5"),
    (("speed_floor_mm_s",), 0.1, 0.099, "must be >= 0.1, got 0.099"),
    (("speed_floor_mm_s",), 1000.0, 1000.5, "must be <= 1000, got 1000.5"),
    (("power_budget_w",), 0.001, 0.00099, "must be >= 0.001, got 0.00099"),
    (("power_budget_w",), 1000.0, 1000.5, "must be <= 1000, got 1000.5"),
]


def _with(changes: dict[tuple[str | int, ...], Any]) -> dict[str, Any]:
    tree = copy.deepcopy(BASE)
    tree.setdefault("friction_model", {"mu0": 0.25, "poisson": 0.33, "psi_star": 4.69})
    for path, value in changes.items():
        node = tree
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = copy.deepcopy(value)
    return tree


def _write(tmp_path: Path, tree: dict[str, Any]) -> Path:
    path = tmp_path / "device.yaml"
    path.write_text(yaml.safe_dump(tree))
    return path


def _breadcrumb(path: Path, location: str, message: str) -> str:
    return re.escape(f"{path}: {location}: {message}") + r" \(line \d+\)"


def _location(path: tuple[str | int, ...]) -> str:
    return "".join(f"[{key}]" if isinstance(key, int) else f".{key}" for key in path).lstrip(".")


# L = 1e-6 H and C = 1e6 pF: sqrt(L / C) = 1 ohm, so Q = 1 / R at every force; it resonates at 1 / (2 pi 1e-6 s),
# so the carrier goes there, and the shunt goes to its least, so that it hardly damps the branch.
_UNIT_BRANCH = {("circuit", "motional_l_h"): [1e-6] * 3, ("circuit", "motional_c_pf"): [1e6] * 3,
                ("carrier_hz",): 1 / (2 * math.pi * 1e-6), ("circuit", "shunt_ohm"): 1e-3}


def _tuned_to(carrier_hz: float) -> dict[tuple[str | int, ...], Any]:
    """The good device's branch retuned (C) to resonate at ``carrier_hz``, with R low enough to ring there."""
    l_h = BASE["circuit"]["motional_l_h"]
    return {("circuit", "motional_c_pf"): [1e12 / ((2 * math.pi * carrier_hz) ** 2 * inductance) for inductance in l_h],
            ("circuit", "motional_r_ohm"): [200.0] * len(l_h)}


def _context(path: tuple[str | int, ...], value: float) -> dict[tuple[str | int, ...], Any]:
    """Other values that keep the file valid with the key at its limit (a motional value alone would move Q, a
    carrier alone would leave the resonance)."""
    if path[:2] in (("circuit", "motional_l_h"), ("circuit", "motional_c_pf"), ("circuit", "motional_r_ohm")):
        return {**_UNIT_BRANCH, ("circuit", "motional_r_ohm"): [1.0] * 3}
    if path == ("carrier_hz",):
        return _tuned_to(min(max(value, 1000.0), 200_000.0))
    return {}


@pytest.mark.parametrize(("path", "inside", "outside", "message"), BOUNDS,
                         ids=[f"{'.'.join(map(str, case[0]))}-{case[1]:g}" for case in BOUNDS])
def test_the_limit_is_accepted_and_just_past_it_refused(
    tmp_path: Path, path: tuple[str | int, ...], inside: float, outside: float, message: str
) -> None:
    accepted = _write(tmp_path, _with({**_context(path, inside), path: inside}))
    assert check_file(accepted) == []
    assert Device.from_file(accepted).derived_problems() == []
    refused = _write(tmp_path, _with({**_context(path, outside), path: outside}))
    [error] = check_file(refused)
    assert re.fullmatch(_breadcrumb(refused, _location(path), message), error), error


def test_q_just_above_one_half_is_accepted(tmp_path: Path) -> None:
    path = _write(tmp_path, _with({**_UNIT_BRANCH, ("circuit", "motional_r_ohm"): [1.0, 1.5, 1.99]}))
    assert check_file(path) == []
    device = Device.from_file(path)
    assert float(device.quality_factor(2.0)) == pytest.approx(1 / 1.99)
    assert device.derived_problems() == []


def test_q_of_one_half_is_refused(tmp_path: Path) -> None:
    path = _write(tmp_path, _with({**_UNIT_BRANCH, ("circuit", "motional_r_ohm"): [1.0, 1.5, 2.0]}))
    message = ("the quality factor sqrt(L / C) / R must stay above 0.5 at every force; "
               "it can reach 0.5 between force_n 1 and 2 N")
    assert re.fullmatch(_breadcrumb(path, "circuit.motional_r_ohm[1]", message), check_file(path)[0])


def test_q_is_bounded_between_knots_not_only_at_them(tmp_path: Path) -> None:
    # Q = 1 at both knots (sqrt(L / C) = 1 and 100 ohm, R = 1 and 100 ohm), but L, C, R are
    # interpolated separately: halfway sqrt(L / C) = 10 ohm and R = 50.5 ohm, Q = 0.198.
    l_h, c_f, r_ohm = [1e-6, 1e-4], [1e-6, 1e-8], [1.0, 100.0]
    assert [math.sqrt(ind / cap) / r for ind, cap, r in zip(l_h, c_f, r_ohm)] == pytest.approx([1.0, 1.0])
    halfway = [float(np.mean(values)) for values in (l_h, c_f, r_ohm)]
    assert math.sqrt(halfway[0] / halfway[1]) / halfway[2] == pytest.approx(0.198, abs=1e-3)
    path = _write(tmp_path, _with({("circuit", "force_n"): [0.0, 1.0], ("circuit", "motional_l_h"): l_h,
                                   ("circuit", "motional_c_pf"): [c * 1e12 for c in c_f],
                                   ("circuit", "motional_r_ohm"): r_ohm}))
    message = ("the quality factor sqrt(L / C) / R must stay above 0.5 at every force; "
               "it can reach 0.01 between force_n 0 and 1 N")
    assert re.fullmatch(_breadcrumb(path, "circuit.motional_r_ohm[0]", message), check_file(path)[0])


def test_q_above_a_million_is_refused(tmp_path: Path) -> None:
    # sqrt(1e4 H / 1e-15 F) = 3.162e9 ohm: R = 3163 ohm gives Q just under 1e6, 3162 just over.
    high = {("circuit", "motional_l_h"): [1e4] * 3, ("circuit", "motional_c_pf"): [1e-3] * 3}
    assert check_file(_write(tmp_path, _with({**high, ("circuit", "motional_r_ohm"): [3163.0] * 3}))) == []
    path = _write(tmp_path, _with({**high, ("circuit", "motional_r_ohm"): [3162.0] * 3}))
    message = ("the quality factor sqrt(L / C) / R must stay at most 1e+06 at every force; "
               "it can reach 1e+06 between force_n 0 and 1 N")
    assert re.fullmatch(_breadcrumb(path, "circuit.motional_r_ohm[0]", message), check_file(path)[0])


def test_a_single_knot_circuit_is_checked_at_its_force(tmp_path: Path) -> None:
    single = {("circuit", "force_n"): [0.5], ("circuit", "motional_l_h"): [1e-6], ("circuit", "motional_c_pf"): [1e6],
              ("circuit", "motional_r_ohm"): [4.0]}
    path = _write(tmp_path, _with(single))
    message = ("the quality factor sqrt(L / C) / R must stay above 0.5 at every force; "
               "it can reach 0.25 at its one force")
    assert re.fullmatch(_breadcrumb(path, "circuit.motional_r_ohm[0]", message), check_file(path)[0])


@pytest.mark.parametrize("path", sorted(DEVICES_DIR.glob("*.yaml")), ids=lambda path: path.stem)
def test_shipped_devices_have_sound_derived_tables(path: Path) -> None:
    assert Device.from_file(path).derived_problems() == []


def _bypassing_the_schema(**circuit: Any) -> Any:
    """The good device's model with circuit values set without validation (as a range combination might slip)."""
    spec = load_device(GOOD)
    return spec.model_copy(update={"circuit": spec.circuit.model_copy(update=circuit)})


def test_a_nan_power_estimate_refuses_the_device() -> None:
    with pytest.raises(ConfigError) as caught:
        # |I| underflows to 0 while the detuning factor (X / R)^2 overflows: 0 x inf
        Device.from_spec(_bypassing_the_schema(motional_l_h=[1e300] * 3, motional_c_pf=[1e-300] * 3), "dev.yaml")
    assert caught.value.errors == [
        "dev.yaml: circuit: power per squared volt at the carrier (W/V^2) must be finite and > 0 at every force, "
        "got nan at 0 N: these values are outside what tpad-rt can render (docs/formats.md \"Ranges, and why\")"
    ]


def test_an_infinite_time_constant_and_an_overflowing_reactance_refuse_the_device() -> None:
    spec = _bypassing_the_schema(motional_l_h=[1e308] * 3, motional_c_pf=[1e-300] * 3, motional_r_ohm=[1e-3] * 3)
    with pytest.raises(ConfigError) as caught:
        Device.from_spec(spec)
    assert [error.split(" must be")[0] for error in caught.value.errors] == [
        "circuit: plate amplitude per volt at the carrier (m/V)",
        "circuit: power per squared volt at the carrier (W/V^2)",
        "circuit: envelope time constant 2 L / (R + Re Z_th) (s)",
    ]
    assert "got nan at 0 N" in caught.value.errors[0] and "got inf at 0 N" in caught.value.errors[2]


def test_a_huge_gamma_that_rounds_the_amplitude_to_zero_refuses_the_device() -> None:
    with pytest.raises(ConfigError) as caught:
        Device.from_spec(_bypassing_the_schema(gamma_n_per_v=1e308), "dev.yaml")
    assert [error.split(" must be")[0] for error in caught.value.errors] == [
        "dev.yaml: circuit: plate amplitude per volt at the carrier (m/V)"]


def test_sim_q_url_is_bounded_as_device_files_are() -> None:
    device = Device.from_file(GOOD)
    assert open_output("sim://?q=1000000", device=device, fs_hz=192000).q == 1e6
    with pytest.raises(ConfigError, match=r"option q: must be device or a number in \(0\.5, 1e\+06\], got '1e20'"):
        open_output("sim://?q=1e20", device=device, fs_hz=192000)


def test_sim_treats_a_negative_or_nan_force_as_zero() -> None:
    device = Device.from_file(GOOD)
    drive = np.sin(2 * np.pi * device.carrier_hz * np.arange(64) / 192000).astype(np.float32) * 0.5
    for force_n in (-1.0, math.nan):
        output = SimOutput(device, 192000)
        output.write(drive, {"force_n": force_n, "speed_mm_s": 100.0})
        reference = SimOutput(device, 192000)
        reference.write(drive, {"force_n": 0.0, "speed_mm_s": 100.0})
        assert output.latest() == reference.latest()


def test_a_circuit_that_resonates_far_from_the_carrier_is_refused(tmp_path: Path) -> None:
    # The good device resonates near 28 kHz: a carrier of 60 kHz is more than twice that
    path = _write(tmp_path, _with({("carrier_hz",): 60_000.0}))
    assert check_file(path) == []  # the schema's ranges hold; the device built from them does not
    with pytest.raises(ConfigError) as caught:
        Device.from_file(path)
    [error] = caught.value.errors
    assert ("circuit: the loaded motional resonance 1 / (2 pi sqrt(L C)), shunt and C0 included, must lie within a "
            "factor 2 of carrier_hz (60000 Hz): a TPaD is driven near its resonance; got 28148.4 Hz at 0 N") in error
    assert Device.from_file(_write(tmp_path, _with({("carrier_hz",): 50_000.0}))).derived_problems() == []


def test_a_shunt_that_damps_the_branch_below_ringing_is_refused(tmp_path: Path) -> None:
    # Unloaded Q = 2 (sqrt(L / C) = 1 ohm, R = 0.5 ohm); a 100 ohm shunt seen through C0 (a 1 ohm reactance at
    # 159 kHz) adds ~5 ohm of damping, and its reactance moves the resonance up ninefold
    loaded = {**_UNIT_BRANCH, ("circuit", "motional_r_ohm"): [0.5] * 3, ("circuit", "shunt_ohm"): 100.0}
    with pytest.raises(ConfigError) as caught:
        Device.from_file(_write(tmp_path, _with(loaded)))
    moved, damped = caught.value.errors
    assert "must lie within a factor 2 of carrier_hz (159155 Hz)" in moved
    assert re.search(r"circuit: the loaded quality factor \(the shunt seen through C0 damps the branch\) must stay "
                     r"above 0\.5, got 0\.18 at 0 N: the plate would not ring", damped), damped
