"""``tpad-rt design``: the paper's Section VI trends from the command line."""

import json
import math
import subprocess
import sys
from collections import defaultdict

import pytest

from tpad_rt.cli import main

KEYS = {"label", "resonance_hz", "n", "n2", "power_ratio", "thickness_mm", "density_g_cm3", "youngs_modulus_gpa"}


def _design_json(capsys, *args):
    assert main(["design", "--json", *args]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.fixture
def rows(capsys):
    return {row["label"]: row for row in _design_json(capsys)}


def test_json_lists_the_eight_table1_plates_with_the_documented_keys(rows):
    assert list(rows) == ["SLG_0.4", "SLG_0.56", "SLG_0.7", "D263_0.4", "D263_0.56",
                          "Gorilla_0.56", "Gorilla_0.8", "BoroFloat_0.7"]
    assert all(set(row) == KEYS for row in rows.values())
    assert rows["SLG_0.56"]["power_ratio"] == pytest.approx(1.0)
    assert rows["SLG_0.4"]["n"] == pytest.approx(5.561, abs=6e-4)
    assert rows["SLG_0.4"]["n2"] == pytest.approx(rows["SLG_0.4"]["n"] ** 2)


def test_thinner_glass_gives_larger_n_and_lower_power_within_each_material(rows):
    by_material = defaultdict(list)
    for row in rows.values():
        by_material[row["label"].split("_")[0]].append(row)
    assert {m: len(r) for m, r in by_material.items()} == {"SLG": 3, "D263": 2, "Gorilla": 2, "BoroFloat": 1}
    for plates in by_material.values():
        plates.sort(key=lambda row: row["thickness_mm"])
        assert all(a["n"] > b["n"] for a, b in zip(plates, plates[1:]))
        assert all(a["power_ratio"] < b["power_ratio"] for a, b in zip(plates, plates[1:]))


def test_slg_04_needs_the_least_power_and_gorilla_08_the_most(rows):
    ranked = sorted(rows.values(), key=lambda row: row["power_ratio"])
    assert ranked[0]["label"] == "SLG_0.4"
    assert ranked[-1]["label"] == "Gorilla_0.8"


def test_resonances_are_within_the_papers_measured_range_give_or_take_6_percent(rows):
    for row in rows.values():
        assert 22.4e3 / 1.06 <= row["resonance_hz"] <= 44.6e3 * 1.06, row["label"]


def test_extra_plate_and_reference(capsys):
    rows = {row["label"]: row for row in _design_json(capsys, "--plate", "Thin:0.3:2.483:71", "--reference", "SLG_0.4")}
    assert rows["SLG_0.4"]["power_ratio"] == pytest.approx(1.0)
    thin = rows["Thin"]
    assert (thin["thickness_mm"], thin["density_g_cm3"], thin["youngs_modulus_gpa"]) == (0.3, 2.483, 71.0)
    assert thin["n"] > rows["SLG_0.4"]["n"]
    # the beam resonance scales with thickness: 0.3 / 0.4 of SLG_0.4's
    assert thin["resonance_hz"] == pytest.approx(rows["SLG_0.4"]["resonance_hz"] * 0.75, rel=1e-12)


def test_length_and_mode_options_scale_the_resonance(capsys):
    default = _design_json(capsys)[0]["resonance_hz"]
    assert _design_json(capsys, "--length-mm", "65")[0]["resonance_hz"] == pytest.approx(4 * default)
    # beta L = (m - 1/2) pi: the resonance scales as (m - 1/2)^2
    assert _design_json(capsys, "--mode", "10")[0]["resonance_hz"] == pytest.approx(default * (9.5 / 19.5) ** 2)


def test_table_names_the_equations_and_the_models_bias(capsys):
    assert main(["design"]) == 0
    out = capsys.readouterr().out
    assert "Gorilla_0.8" in out and "1.600" in out and "21.82" in out
    for text in ("Euler-Bernoulli", "glass alone", "Eq. 16", "Eqs. 19-20", "Eq. 21", "22.4-44.6 kHz", "2.6 % low"):
        assert text in out


@pytest.mark.parametrize(
    "args",
    [
        ["--plate", "Thin:0.3:2.5"],
        ["--plate", "Thin:0.3:abc:70"],
        ["--plate", "Thin:0.3:2.5:-70"],
        ["--plate", ":0.3:2.5:70"],
        ["--plate", "SLG_0.4:0.3:2.5:70"],
        ["--reference", "SLG_9"],
        ["--length-mm", "0"],
        ["--plate", "X:1e-300:2.5:70"],
        ["--plate", "X:0.5:1e308:1e308", "--reference", "X"],
        ["--plate", "X:0.5:2.5:nan"],
        ["--length-mm", "1e-300"],
        ["--length-mm", "inf"],
        ["--mode", "0"],
        ["--mode", "100000"],
    ],
)
def test_bad_options_exit_1_with_one_line(capsys, args):
    try:
        status = main(["design", *args])
    except SystemExit as exit_:  # argparse's refusals
        status = exit_.code
    assert status == 1
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.count("\n") == 1 and captured.err.startswith("tpad-rt design: ")


def test_malformed_plate_message_shows_the_expected_form(capsys):
    main(["design", "--plate", "Thin:0.3"])
    assert "expected LABEL:THICK_MM:DENSITY_G_CM3:E_GPA" in capsys.readouterr().err


def test_as_a_process():
    ok = subprocess.run([sys.executable, "-m", "tpad_rt", "design", "--json"], capture_output=True, text=True, check=False)
    assert ok.returncode == 0, ok.stderr
    rows = json.loads(ok.stdout)
    assert min(rows, key=lambda row: row["power_ratio"])["label"] == "SLG_0.4"
    assert max(rows, key=lambda row: row["power_ratio"])["label"] == "Gorilla_0.8"

    bad = subprocess.run([sys.executable, "-m", "tpad_rt", "design", "--plate", "x"], capture_output=True, text=True, check=False)
    assert bad.returncode == 1
    assert bad.stderr.count("\n") == 1 and "Traceback" not in bad.stderr
    assert "LABEL:THICK_MM:DENSITY_G_CM3:E_GPA" in bad.stderr


@pytest.mark.parametrize("plate", ["X:0.01:0.1:0.01", "X:100:50:2000", "X:0.01:50:2000", "X:100:0.1:0.01"])
@pytest.mark.parametrize(("length", "mode"), [("1", "1"), ("1000", "1000")])
def test_every_accepted_plate_gives_finite_figures(capsys, plate, length, mode):
    assert main(["design", "--plate", plate, "--length-mm", length, "--mode", mode, "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert all(math.isfinite(value) for row in rows for value in row.values() if isinstance(value, float))


def test_the_papers_measured_power_order_is_shown_beside_eq21_and_where_they_part(capsys) -> None:
    from tpad_rt.cli.design import design_rows, order_rows
    from tpad_rt.physics.plate import TABLE1_GLASSES

    orders = {row["pair"]: row for row in order_rows(design_rows(list(TABLE1_GLASSES), 0.130, 20, "SLG_0.56"))}
    assert len(orders) == 8
    assert [pair for pair, row in orders.items() if not row["agrees"]] == ["SLG_0.7 < BoroFloat_0.7"]
    assert orders["SLG_0.7 < BoroFloat_0.7"]["eq21"] == "1.372 > 1.188"
    assert main(["design"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "Power: the paper's measured order against Eq. 21" in out
    assert "Where they part: SLG_0.7 < BoroFloat_0.7." in out
