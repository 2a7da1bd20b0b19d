"""``tpad-rt calibrate``: the worked example's files fitted, built into a device that checks and renders; the
format 1 converter; every mistake one line and exit status 1."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from cli_run import REPO, tpad_rt
from tpad_rt.device import Device

EXAMPLE = REPO / "examples" / "calibration"
KEYS = {"force_n", "c0_nf", "motional_l_h", "motional_c_pf", "motional_r_ohm", "resonance_hz", "q"}
TRUTH = Device.from_file(REPO / "tpad_rt" / "devices" / "SLG_0.56.yaml")


def test_the_shipped_example_files_are_what_the_generator_writes(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, str(EXAMPLE / "make_synthetic.py"), "--out", str(tmp_path)],
                            capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stderr
    for name in ("sweeps.csv", "sweep_0n_polar.csv", "amplitudes.csv"):
        assert (tmp_path / name).read_text() == (EXAMPLE / name).read_text(), name


def test_impedance_json_gives_one_object_per_force_within_2_percent_of_the_device() -> None:
    run = tpad_rt("calibrate", "impedance", str(EXAMPLE / "sweeps.csv"), "--json")
    assert run.returncode == 0, run.stderr
    fits = json.loads(run.stdout)
    assert [fit["force_n"] for fit in fits] == [0.0, 0.5, 1.0, 1.5, 2.0]
    for fit in fits:
        assert KEYS <= set(fit)
        l_h, c_f, r_ohm = (float(value) for value in TRUTH.motional(fit["force_n"]))
        expected = [TRUTH.c0_f * 1e9, l_h, c_f * 1e12, r_ohm]
        got = [fit["c0_nf"], fit["motional_l_h"], fit["motional_c_pf"], fit["motional_r_ohm"]]
        np.testing.assert_allclose(got, expected, rtol=0.02)
        assert fit["q"] == pytest.approx(np.sqrt(fit["motional_l_h"] / (fit["motional_c_pf"] * 1e-12))
                                         / fit["motional_r_ohm"], rel=1e-9)


def test_impedance_table_and_plot(tmp_path: Path) -> None:
    plot = tmp_path / "fit.png"
    run = tpad_rt("calibrate", "impedance", str(EXAMPLE / "sweep_0n_polar.csv"), "--plot", str(plot))
    assert run.returncode == 0, run.stderr
    assert "Butterworth-Van Dyke fit" in run.stdout and "0 (none given)" in run.stdout
    assert f"wrote {plot}" in run.stdout
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and plot.stat().st_size > 50_000


def test_amplitude_recovers_gamma_through_the_sweeps_or_a_device(tmp_path: Path) -> None:
    for source in (("--impedance", str(EXAMPLE / "sweeps.csv")), ("--device", "SLG_0.56")):
        run = tpad_rt("calibrate", "amplitude", str(EXAMPLE / "amplitudes.csv"), *source, "--json",
                      "--plot", str(tmp_path / "gamma.png"))
        assert run.returncode == 0, run.stderr
        fit = json.loads(run.stdout)
        assert fit["gamma_n_per_v"] == pytest.approx(TRUTH.gamma_n_per_v, rel=0.01)
        assert [force["force_n"] for force in fit["forces"]] == [0.0, 0.5, 1.0, 1.5, 2.0]
        assert fit["worst_deviation_percent"] < 2.0 and fit["warnings"] == []
    assert (tmp_path / "gamma.png").stat().st_size > 20_000


def test_build_writes_a_device_that_checks_renders_and_says_where_each_value_came_from(tmp_path: Path) -> None:
    out = tmp_path / "rig.yaml"
    run = tpad_rt("calibrate", "build", "--impedance", str(EXAMPLE / "sweeps.csv"), "--amplitude",
                  str(EXAMPLE / "amplitudes.csv"), "--out", str(out), "--like", "SLG_0.56")
    assert run.returncode == 0, run.stderr
    assert f"wrote {out}: device rig, carrier 313" in run.stdout
    document = yaml.safe_load(out.read_text())
    assert document["format_version"] == 2 and document["label"] == "rig"
    assert "sweeps.csv" in document["source"]["circuit.motional"] and "amplitudes.csv" in \
        document["source"]["circuit.gamma_n_per_v"]
    assert document["source"]["plate"].startswith("from the template device SLG_0.56")
    built = Device.from_file(out)
    assert built.carrier_hz == pytest.approx(TRUTH.carrier_hz, abs=3.0)
    assert built.amplitude_m_per_v(0.0) == pytest.approx(TRUTH.amplitude_m_per_v(0.0), rel=0.02)
    assert built.power_budget_w == TRUTH.power_budget_w
    check = tpad_rt("check", str(out))
    assert check.returncode == 0 and "device: rig" in check.stdout
    recording = tmp_path / "r.npz"
    render = tpad_rt("render", "textures/grating.yaml", "--device", str(out), "--input",
                     "scripted://swipe?speed_mm_s=100", "--output", "sim://", "--out", str(recording))
    assert render.returncode == 0, render.stderr
    with np.load(recording) as data:
        assert float(np.max(data["plate_amplitude_um"])) > 0.5


def test_build_fits_gamma_at_the_carrier_it_is_given(tmp_path: Path) -> None:
    """Amplitudes measured off the resonance (at --carrier-hz, no freq_hz column) give the device's gamma back:
    the fit reads them at that carrier, not at the resonance."""
    carrier_hz = TRUTH.carrier_hz + 50.0
    omega = 2 * np.pi * carrier_hz
    rows = ["force_n,voltage_v,amplitude_um"]
    for force in (0.0, 1.0, 2.0):
        l_h, c_f, r_ohm = (float(value) for value in TRUTH.motional(force))
        branch_ohm = abs(r_ohm + 1j * (omega * l_h - 1 / (omega * c_f)))
        rows += [f"{force},{volts},{volts / branch_ohm / (TRUTH.gamma_n_per_v * omega) * 1e6!r}" for volts in (10, 30)]
    amplitudes = tmp_path / "off_resonance.csv"
    amplitudes.write_text("\n".join(rows) + "\n")
    out = tmp_path / "rig.yaml"
    run = tpad_rt("calibrate", "build", "--impedance", str(EXAMPLE / "sweeps.csv"), "--amplitude", str(amplitudes),
                  "--out", str(out), "--carrier-hz", str(carrier_hz))
    assert run.returncode == 0, run.stderr
    assert "gamma" not in run.stderr  # one gamma explains every force
    built = Device.from_file(out)
    assert built.carrier_hz == carrier_hz
    assert built.gamma_n_per_v == pytest.approx(TRUTH.gamma_n_per_v, rel=0.01)
    assert built.amplitude_m_per_v(1.0) == pytest.approx(TRUTH.amplitude_m_per_v(1.0, carrier_hz), rel=0.02)


def test_convert_turns_a_format_1_file_into_one_that_loads(tmp_path: Path) -> None:
    old = FORMAT_1
    out = tmp_path / "new.yaml"
    run = tpad_rt("calibrate", "convert", str(old), "--out", str(out))
    assert run.returncode == 0, run.stderr
    assert "its amplitude table implied gammas" in run.stdout
    document = yaml.safe_load(out.read_text())
    assert document["format_version"] == 2 and "carrier_hz" in document and "calibration" not in document
    assert "converted from format 1" in document["source"]["circuit.gamma_n_per_v"]
    device = Device.from_file(out)
    # One gamma: the 0.05 um/V at 0 N the old table gave is kept within the spread the message reports
    assert device.amplitude_m_per_v(0.0) * 1e6 == pytest.approx(0.05, rel=0.5)
    again = tpad_rt("calibrate", "convert", str(out), "--out", str(tmp_path / "again.yaml"))
    again.assert_one_line_error("not a format 1 device file")


FORMAT_1 = REPO / "tests" / "bad_files" / "device_format_1.yaml"


@pytest.mark.parametrize(("forces", "amplitudes", "expected"), [
    ("[.nan, 0.5, 1.0, 2.0]", None, "calibration.force_n: every force must be a number in [0, 50] N"),
    ("[0, 0.5, 1.0, .inf]", None, "calibration.force_n: every force must be a number in [0, 50] N"),
    ("[-5, 0.5, 1.0, 2.0]", None, "calibration.force_n: every force must be a number in [0, 50] N"),
    ("[0, 0.5, 1.0, 1.0e+308]", None, "calibration.force_n: every force must be a number in [0, 50] N"),
    ("[0, 0, 0, 0]", None, "calibration.force_n: forces must increase by at least 0.001 N"),
    ("[2.0, 0.5, 1.0, 0]", None, "calibration.force_n: forces must increase by at least 0.001 N"),
    ("['0', '0.5', '1', '2']", None, "calibration.force_n: a format 1 file needs a list of numbers here"),
    (None, "[true, true, true, true]", "calibration.amplitude_um_per_v: a format 1 file needs a list of numbers here"),
    (None, "[1.0e-320, 0.04, 0.03, 0.02]", "calibration.amplitude_um_per_v: every amplitude must be a number in"),
    (None, "[1.0e+308, 0.04, 0.03, 0.02]", "calibration.amplitude_um_per_v: every amplitude must be a number in"),
    (None, "[0.05, 0.04, 0.03]", "calibration: force_n and amplitude_um_per_v must be lists of the same length"),
])
def test_a_bad_format_1_table_is_refused_in_one_line(tmp_path: Path, forces: str | None, amplitudes: str | None,
                                                      expected: str) -> None:
    text = FORMAT_1.read_text()
    if forces is not None:
        text = text.replace("force_n: [0, 0.5, 1.0, 2.0]", f"force_n: {forces}")
    if amplitudes is not None:
        text = text.replace("amplitude_um_per_v: [0.05, 0.04, 0.03, 0.02]", f"amplitude_um_per_v: {amplitudes}")
    old = tmp_path / "old.yaml"
    old.write_text(text)
    tpad_rt("calibrate", "convert", str(old), "--out", str(tmp_path / "new.yaml")).assert_one_line_error(
        f"old.yaml: {expected}")
    assert not (tmp_path / "new.yaml").exists()


def test_an_output_that_is_an_input_is_refused_and_the_input_kept(tmp_path: Path) -> None:
    sweeps, amplitudes, old = (tmp_path / "sweeps.csv", tmp_path / "amplitudes.csv", tmp_path / "old.yaml")
    shutil.copy(EXAMPLE / "sweeps.csv", sweeps)
    shutil.copy(EXAMPLE / "amplitudes.csv", amplitudes)
    shutil.copy(FORMAT_1, old)
    before = {path: path.read_bytes() for path in (sweeps, amplitudes, old)}
    build = ("calibrate", "build", "--impedance", str(sweeps), "--amplitude", str(amplitudes), "--out")
    tpad_rt(*build, str(sweeps)).assert_one_line_error(f"{sweeps}: is also a file this command reads")
    tpad_rt(*build, str(amplitudes)).assert_one_line_error(f"{amplitudes}: is also a file this command reads")
    tpad_rt("calibrate", "convert", str(old), "--out", str(old)).assert_one_line_error(
        f"{old}: is also a file this command reads")
    assert {path: path.read_bytes() for path in before} == before


def _in_khz(tmp_path: Path) -> str:
    """The worked example's amplitudes with freq_hz written in kHz (a unit mistake)."""
    lines = []
    for line in (EXAMPLE / "amplitudes.csv").read_text().splitlines():
        fields = line.split(",")
        if line[:1].isdigit():
            fields[3] = repr(float(fields[3]) / 1000)
        lines.append(",".join(fields))
    path = tmp_path / "khz.csv"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def test_json_has_no_infinity_where_a_value_is_undetermined(tmp_path: Path) -> None:
    """One row gives a gamma but no spread: its uncertainty is null in the JSON (JSON has no Infinity)."""
    rows = (EXAMPLE / "amplitudes.csv").read_text().splitlines()
    header = next(line for line in rows if line.startswith("force_n"))
    first = next(line for line in rows if line[:1].isdigit())
    single = tmp_path / "single.csv"
    single.write_text(f"{header}\n{first}\n")
    run = tpad_rt("calibrate", "amplitude", str(single), "--device", "SLG_0.56", "--json")
    assert run.returncode == 0, run.stderr
    assert "Infinity" not in run.stdout and json.loads(run.stdout)["uncertainty_percent"] is None


def test_many_forces_are_told_apart_by_a_colour_bar_without_warnings(tmp_path: Path) -> None:
    lines = ["freq_hz,z_real_ohm,z_imag_ohm,force_n"]
    sweep = (EXAMPLE / "sweep_0n_polar.csv").read_text().splitlines()
    polar = [line.split(",") for line in sweep if line[:1].isdigit()][::8]
    for force in np.linspace(0.0, 2.0, 20):
        for freq, magnitude, phase in polar:
            z = float(magnitude) * np.exp(1j * np.radians(float(phase)))
            lines.append(f"{freq},{float(z.real)!r},{float(z.imag)!r},{force:.3f}")
    many = tmp_path / "many.csv"
    many.write_text("\n".join(lines) + "\n")
    run = tpad_rt("calibrate", "impedance", str(many), "--plot", str(tmp_path / "many.png"))
    assert run.returncode == 0, run.stderr
    assert run.stderr == "" and (tmp_path / "many.png").stat().st_size > 50_000


def _fifo(tmp_path: Path) -> str:
    path = tmp_path / "fifo.csv"
    os.mkfifo(path)
    return str(path)


@pytest.mark.parametrize(("args", "expected"), [
    (("calibrate",), "the following arguments are required: ACTION"),
    (("calibrate", "impedance"), "the following arguments are required: SWEEP.csv"),
    (("calibrate", "impedance", "missing.csv"), "missing.csv: cannot read: no such file or directory"),
    (("calibrate", "impedance", "{fifo}"), "not a regular file (a FIFO); tpad-rt reads impedance sweeps"),
    (("calibrate", "impedance", "{sweeps}", "--plot", "fit.txt"), "--plot: must end in .png, .pdf, .svg"),
    (("calibrate", "impedance", "{sweeps}", "{sweeps}"), "a sweep at 0 N again"),
    (("calibrate", "impedance", "{amplitudes}"), "header: unknown column 'voltage_v'"),
    (("calibrate", "amplitude", "{amplitudes}"), "one of the arguments --impedance --device is required"),
    (("calibrate", "amplitude", "{amplitudes}", "--device", "SLG_0.56", "--freq-hz", "nan"),
     "argument --freq-hz: must be a number in [1000, 200000] (Hz), got 'nan'"),
    (("calibrate", "amplitude", "{amplitudes}", "--device", "SLG_0.56", "--freq-hz", "3_1000"),
     "argument --freq-hz: must be a number in [1000, 200000] (Hz), got '3_1000'"),
    (("calibrate", "amplitude", "{khz}", "--device", "SLG_0.56"),
     "khz.csv: row 1's freq_hz, 31.3586 Hz, is far from the circuit's resonance (31358.6 Hz): amplitudes are "
     "measured near it (in Hz, not kHz)"),
    (("calibrate", "build", "--impedance", "{sweeps}", "--amplitude", "{amplitudes}", "--out", "x.yaml",
      "--like", str(REPO / "textures" / "grating.yaml")),
     "grating.yaml: a texture file (it has 'kind'), not a device file (which has format_version and a circuit)"),
    (("calibrate", "build", "--impedance", "{sweeps}", "--amplitude", "{amplitudes}", "--out", "x.yaml",
      "--label", "two\nlines"), "--label: must be 1 to 200 printable characters, got 'two\\x0alines'"),
    (("calibrate", "sweep", "serial:///nonexistent", "--drive-v", "1e-320"),
     "argument --drive-v: must be a number in [0.01, 10000] (V), got '1e-320'"),
    (("calibrate", "build", "--impedance", "{sweeps}", "--amplitude", "{amplitudes}", "--out", "/dev/null"),
     "/dev/null: exists and is not a regular file"),
    (("calibrate", "build", "--impedance", "{sweeps}", "--amplitude", "{amplitudes}", "--out", "x.yaml",
      "--like", "nonesuch"), "nonesuch"),
    (("calibrate", "build", "--impedance", "{sweeps}", "--amplitude", "{amplitudes}", "--out", "x.yaml",
      "--max-voltage-v", "1e308"), "argument --max-voltage-v: must be a number in [0.1, 10000] (V), got '1e308'"),
    (("calibrate", "build", "--impedance", "{sweeps}", "--amplitude", "{amplitudes}", "--out", "x.yaml",
      "--max-voltage-v", "60"), "--max-voltage-v: must be <= the volts_per_full_scale of --like default (50 V), got 60"),
    (("calibrate", "convert", "{old}", "--out", "/dev/zero"), "/dev/zero: exists and is not a regular file"),
])
def test_every_mistake_is_one_line(tmp_path: Path, args: tuple[str, ...], expected: str) -> None:
    names = {"{sweeps}": str(EXAMPLE / "sweeps.csv"), "{amplitudes}": str(EXAMPLE / "amplitudes.csv"),
             "{old}": str(REPO / "tests" / "bad_files" / "device_format_1.yaml"), "{khz}": _in_khz(tmp_path)}
    filled = [names.get(arg, _fifo(tmp_path) if arg == "{fifo}" else arg) for arg in args]
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        run = tpad_rt(*filled)
    finally:
        os.chdir(cwd)
    run.assert_one_line_error(expected)
    assert not (tmp_path / "x.yaml").exists()


@pytest.mark.parametrize("rows", [3, 300])
def test_old_mac_line_ends_are_told_so_short_or_over_4_kib(tmp_path: Path, rows: int) -> None:
    """A measurement file whose lines end in CR alone reads as one line: refused by the csv module when short, by
    its length over 4 KiB; both messages say what is wrong with the line ends."""
    lines = ["freq_hz,z_real_ohm,z_imag_ohm"] + [f"{30000 + 10 * k},{1.0},{-500.0}" for k in range(rows)]
    mac = tmp_path / "mac.csv"
    mac.write_bytes(("\r".join(lines) + "\r").encode())
    assert (mac.stat().st_size > 4096) == (rows == 300)
    run = tpad_rt("calibrate", "impedance", str(mac))
    run.assert_one_line_error(f"{mac}:1: ")
    assert run.stderr.endswith("; it holds a carriage return (CR): lines must end in LF or CR LF, not CR alone "
                               "(old Mac line ends)\n")
    assert ("line longer than 4,096 bytes" in run.stderr) == (rows == 300)


def test_a_sweep_the_model_does_not_fit_is_one_line(tmp_path: Path) -> None:
    lines = ["freq_hz,z_real_ohm,z_imag_ohm"] + [f"{30000 + 10 * k},{1.0},{-500.0}" for k in range(100)]
    flat = tmp_path / "flat.csv"
    flat.write_text("\n".join(lines) + "\n")
    tpad_rt("calibrate", "impedance", str(flat)).assert_one_line_error(
        "flat.csv, 0 N (no force_n column): the model does not fit")


def test_an_existing_device_file_is_replaced_only_once_the_new_one_loads(tmp_path: Path) -> None:
    out = tmp_path / "rig.yaml"
    shutil.copy(REPO / "tpad_rt" / "devices" / "SLG_0.4.yaml", out)
    before = out.read_text()
    run = tpad_rt("calibrate", "build", "--impedance", str(EXAMPLE / "sweeps.csv"), "--amplitude",
                  str(EXAMPLE / "amplitudes.csv"), "--out", str(out), "--power-budget-w", "0.001")
    assert run.returncode == 0, run.stderr  # a tiny budget is valid
    assert out.read_text() != before
    failed = tpad_rt("calibrate", "build", "--impedance", str(EXAMPLE / "sweeps.csv"), "--amplitude",
                     str(EXAMPLE / "amplitudes.csv"), "--out", str(out), "--max-voltage-v", "60")
    failed.assert_one_line_error("--max-voltage-v: must be <=")
    assert "power_budget_w: 0.001" in out.read_text()
    assert [path.name for path in tmp_path.iterdir()] == ["rig.yaml"]
