"""The calibration fits (tpad_rt.calibrate): BVD circuit from impedance sweeps, gamma from amplitudes.

Synthetic measurements come from known parameters through the circuit solved directly
(complex admittances, not the fit's own model code), with 1 % relative noise: the fits
must give the parameters back within 2 %, and say when the model does not fit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tpad_rt.calibrate import measurements
from tpad_rt.calibrate.amplitude import Circuit, fit_gamma
from tpad_rt.calibrate.impedance import fit_sweep, model_impedance
from tpad_rt.calibrate.measurements import (
    AmplitudeMeasurements, ImpedanceSweep, read_amplitudes, read_impedance_sweeps,
)
from tpad_rt.device import Device
from tpad_rt.errors import ConfigError

NOISE = 0.01
#: An analyser's sweep: 801 points (the paper's HP35665A sweeps 401 or 801 lines).
POINTS = 801
HALF_SPAN_BANDWIDTHS = 5.0


def _admittance_circuit(freq_hz, c0_f, l_h, c_f, r_ohm):
    """C0 parallel to the series L, C, R, from complex admittances (the naive reference)."""
    omega = 2 * np.pi * freq_hz
    return 1 / (1j * omega * c0_f + 1 / (r_ohm + 1j * omega * l_h + 1 / (1j * omega * c_f)))


def _branch(fs_hz, q, r_ohm):
    omega = 2 * math.pi * fs_hz
    return q * r_ohm / omega, 1 / (omega * q * r_ohm)


def _sweep(c0_f, fs_hz, q, r_ohm, seed, noise=NOISE, points=POINTS, span=HALF_SPAN_BANDWIDTHS, center_hz=None,
           extra=None):
    """A synthetic sweep: ``points`` frequencies over +-``span`` half-power bandwidths, complex noise of ``noise``
    x |Z| (standard deviation, split evenly over real and imaginary parts); ``extra`` adds a branch in parallel."""
    l_h, c_f = _branch(fs_hz, q, r_ohm)
    center = fs_hz if center_hz is None else center_hz
    freq = np.linspace(center - span * fs_hz / q, center + span * fs_hz / q, points)
    z = _admittance_circuit(freq, c0_f, l_h, c_f, r_ohm)
    if extra is not None:
        l2, c2 = _branch(extra[0], extra[1], extra[2])
        z = 1 / (1 / z + 1 / (extra[2] + 1j * 2 * np.pi * freq * l2 + 1 / (2j * np.pi * freq * c2)))
    rng = np.random.default_rng(seed)
    z = z + noise * np.abs(z) * (rng.standard_normal(points) + 1j * rng.standard_normal(points)) / math.sqrt(2)
    return ImpedanceSweep("synthetic.csv", 0.0, True, freq, z), (c0_f, l_h, c_f, r_ohm)


# The motional feature must stand out of 1 % noise: its conductance peak 1 / R at least 15 % of w C0 (the
# shipped plates: 8-60 %). Weaker features fit with larger uncertainties, which the fit reports (and warns
# about above UNCERTAIN_FRACTION); 2 % then needs more points or less noise.
circuits = st.tuples(
    st.floats(1e-9, 50e-9), st.floats(15e3, 60e3), st.floats(50.0, 2000.0), st.floats(100.0, 20_000.0),
    st.integers(0, 2**32 - 1),
).filter(lambda p: 1 / p[3] >= 0.15 * 2 * math.pi * p[1] * p[0])


@settings(deadline=None, max_examples=60, suppress_health_check=[HealthCheck.filter_too_much])
@given(circuits)
def test_the_fit_recovers_c0_l_c_r_within_2_percent_at_1_percent_noise(params):
    c0_f, fs_hz, q, r_ohm, seed = params
    sweep, (_, l_h, c_f, _) = _sweep(c0_f, fs_hz, q, r_ohm, seed)
    fit = fit_sweep(sweep)
    got = np.array([fit.c0_f, fit.l_h, fit.c_f, fit.r_ohm])
    np.testing.assert_allclose(got, [c0_f, l_h, c_f, r_ohm], rtol=0.02)
    assert fit.resonance_hz == pytest.approx(fs_hz, rel=1e-3)


def test_without_noise_the_fit_is_exact_and_the_model_is_the_naive_circuit():
    sweep, truth = _sweep(9.88e-9, 31360.0, 212.0, 965.5, seed=0, noise=0.0)
    fit = fit_sweep(sweep)
    np.testing.assert_allclose([fit.c0_f, fit.l_h, fit.c_f, fit.r_ohm], truth, rtol=1e-7)
    np.testing.assert_allclose(model_impedance(sweep.freq_hz, fit), _admittance_circuit(sweep.freq_hz, *truth),
                               rtol=1e-6)
    assert fit.warnings == ()


def test_the_reported_uncertainties_match_the_scatter_of_repeated_fits():
    """Over 40 noise draws the R fitted scatters by about the uncertainty each fit reports."""
    errors, sigmas = [], []
    for seed in range(40):
        sweep, truth = _sweep(9.88e-9, 31360.0, 150.0, 1500.0, seed)
        fit = fit_sweep(sweep)
        errors.append(fit.r_ohm / truth[3] - 1)
        sigmas.append(fit.uncertainty["motional_r_ohm"])
    ratio = float(np.std(errors) / np.mean(sigmas))
    assert 0.6 < ratio < 1.6, ratio


@pytest.mark.parametrize(("c0_over_c", "q", "seed"), [(10.0, 1e5, 1), (40.0, 1e5, 1), (3.0, 1e4, 3), (10.0, 1e3, 4)])
def test_a_parameter_the_sweep_barely_determines_is_reported_so(c0_over_c, q, seed):
    """C0 large against C and Q high (the motional branch dominates): C0 is poorly determined, and the fit must say
    so, with an uncertainty that covers its error (a pseudo-inverse's cutoff reported it to 1e-10 %)."""
    c_f, fs_hz = 24.76e-12, 31363.76
    r_ohm = 1 / (2 * math.pi * fs_hz * q * c_f)
    sweep, truth = _sweep(c0_over_c * c_f, fs_hz, q, r_ohm, seed, noise=0.005)
    fit = fit_sweep(sweep)
    for key, got, expected in zip(("c0_nf", "motional_l_h", "motional_c_pf", "motional_r_ohm"),
                                  (fit.c0_f, fit.l_h, fit.c_f, fit.r_ohm), truth):
        error = abs(got / expected - 1)
        assert error <= 4 * fit.uncertainty[key], (key, error, fit.uncertainty[key])
        if error > 0.02:
            assert any(line.startswith(f"{key} is poorly determined") for line in fit.warnings), fit.warnings


def test_a_second_mode_in_the_band_is_refused():
    sweep, _ = _sweep(9.88e-9, 31360.0, 200.0, 1000.0, seed=1, span=25.0, extra=(31360.0 * 1.05, 200.0, 1200.0))
    with pytest.raises(ConfigError, match=r"synthetic.csv, 0 N: the model does not fit: a second mode in the band at "
                                          r"3\d{4}(\.\d+)? Hz .*trim the sweep to one mode"):
        fit_sweep(sweep)


def test_too_few_points_near_the_resonance_is_refused():
    sweep, _ = _sweep(9.88e-9, 31360.0, 200.0, 1000.0, seed=2, points=41, span=20.0)  # a point per bandwidth
    with pytest.raises(ConfigError, match=r"too few points near the resonance: [0-4] inside the half-power band .*at "
                                          r"least 5 needed: sweep in steps of .* Hz or finer there"):
        fit_sweep(sweep)


def test_a_sweep_beside_the_resonance_is_refused():
    sweep, _ = _sweep(9.88e-9, 31360.0, 200.0, 1000.0, seed=3, center_hz=31360.0 * (1 + 5.5 / 200))
    with pytest.raises(ConfigError, match="the conductance peaks at the sweep's edge .* the resonance is outside the "
                                          "sweep; widen it"):
        fit_sweep(sweep)


def test_a_resonance_buried_in_noise_is_refused():
    sweep, _ = _sweep(9.88e-9, 31360.0, 200.0, 20_000.0, seed=4, noise=0.05)
    with pytest.raises(ConfigError, match="the resonance is buried in noise"):
        fit_sweep(sweep)


def test_a_phase_of_the_wrong_sign_is_refused_with_a_hint():
    sweep, _ = _sweep(9.88e-9, 31360.0, 200.0, 1000.0, seed=5)
    flipped = ImpedanceSweep(sweep.source, 0.0, True, sweep.freq_hz, np.conj(sweep.impedance_ohm))
    with pytest.raises(ConfigError, match=r"is not a capacitor's .*about -90 degrees for a piezo"):
        fit_sweep(flipped)


def test_dielectric_loss_the_model_lacks_is_flagged():
    sweep, truth = _sweep(9.88e-9, 31360.0, 200.0, 1000.0, seed=6, noise=0.002)
    loss_s = 2 * np.pi * sweep.freq_hz * truth[0] * 0.03  # tan(delta) = 3 %
    lossy = ImpedanceSweep(sweep.source, 0.0, True, sweep.freq_hz, 1 / (1 / sweep.impedance_ohm + loss_s))
    fit = fit_sweep(lossy)
    assert any("times the point-to-point noise: the circuit does not explain the sweep" in w for w in fit.warnings)


# --- amplitude -------------------------------------------------------------------------------------------------

def _amplitude_rows(device, gamma_scale=lambda force: 1.0, exponent=1.0, noise=NOISE, seed=0):
    rng = np.random.default_rng(seed)
    forces, volts, amplitudes = [], [], []
    for force in (0.0, 0.5, 1.0, 2.0):
        l_h, c_f, r_ohm = (float(value) for value in device.motional(force))
        omega = 2 * math.pi * device.carrier_hz
        branch = abs(r_ohm + 1j * (omega * l_h - 1 / (omega * c_f)))
        for v in (10.0, 20.0, 30.0, 40.0):
            current = (v ** exponent * 40 ** (1 - exponent)) / branch
            amplitude = current / (device.gamma_n_per_v * gamma_scale(force) * omega) * 1e6
            forces.append(force)
            volts.append(v)
            amplitudes.append(amplitude * (1 + noise * rng.standard_normal()))
    return AmplitudeMeasurements("amp.csv", np.array(forces), np.array(volts), np.array(amplitudes), None)


@pytest.fixture(scope="module")
def device():
    return Device.default()


@pytest.fixture(scope="module")
def circuit(device):
    return Circuit(device.force_table_n, device.motional_l_h_table, device.motional_c_f_table,
                   device.motional_r_ohm_table)


def test_gamma_is_recovered_within_1_percent_and_one_gamma_explains_every_force(device, circuit):
    fit = fit_gamma(_amplitude_rows(device), circuit, device.carrier_hz)
    assert fit.gamma_n_per_v == pytest.approx(device.gamma_n_per_v, rel=0.01)
    assert fit.worst_deviation < 0.02 and fit.warnings == ()
    assert all(force.linearity is not None and force.linearity < 0.05 for force in fit.forces)
    assert 0 < fit.uncertainty < 0.01


def test_a_gamma_that_grows_with_force_is_reported(device, circuit):
    fit = fit_gamma(_amplitude_rows(device, gamma_scale=lambda force: 1 + 0.4 * force), circuit, device.carrier_hz)
    [warning] = fit.warnings
    assert "one gamma does not explain every force: at 2 N" in warning


def test_an_amplitude_that_saturates_with_volts_is_reported(device, circuit):
    fit = fit_gamma(_amplitude_rows(device, exponent=0.7, noise=0.0), circuit, device.carrier_hz)
    assert any("departs from proportional to volts" in warning for warning in fit.warnings)


def test_the_drive_frequency_defaults_to_the_circuits_lowest_force_resonance(device, circuit):
    rows = _amplitude_rows(device, noise=0.0)
    assert fit_gamma(rows, circuit).freq_hz == pytest.approx(circuit.resonance_hz)
    with_column = AmplitudeMeasurements(rows.source, rows.force_n, rows.voltage_v, rows.amplitude_um,
                                        np.full(len(rows.force_n), device.carrier_hz))
    fit = fit_gamma(with_column, circuit)
    assert fit.freq_hz is None and fit.gamma_n_per_v == pytest.approx(device.gamma_n_per_v, rel=1e-9)


# --- reading -----------------------------------------------------------------------------------------------------

def _write(tmp_path, text, name="m.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_polar_and_cartesian_sweeps_read_the_same(tmp_path):
    sweep, _ = _sweep(9.88e-9, 31360.0, 200.0, 1000.0, seed=7, points=30)
    z = sweep.impedance_ohm
    rows = "".join(f"{float(f)!r},{float(zi.real)!r},{float(zi.imag)!r},0.5\n" for f, zi in zip(sweep.freq_hz[::-1], z[::-1]))
    cartesian = read_impedance_sweeps(_write(tmp_path, "# a comment\nfreq_hz,z_real_ohm,z_imag_ohm,force_n\n" + rows))
    polar_rows = "".join(f"{float(abs(zi))!r},{float(f)!r},{math.degrees(np.angle(zi))!r}\n"
                         for f, zi in zip(sweep.freq_hz, z))
    polar = read_impedance_sweeps(_write(tmp_path, "z_abs_ohm,freq_hz,z_phase_deg\n" + polar_rows, "p.csv"))
    [one], [other] = cartesian, polar
    assert one.force_n == 0.5 and one.force_given and other.force_n == 0.0 and not other.force_given
    np.testing.assert_array_equal(one.freq_hz, sweep.freq_hz)  # sorted ascending
    np.testing.assert_allclose(one.impedance_ohm, other.impedance_ohm, rtol=1e-12)


def test_a_negative_zero_force_is_zero(tmp_path):
    lines = ["freq_hz,z_real_ohm,z_imag_ohm,force_n"] + [f"{30000 + k},1,-500,-0.0" for k in range(20)]
    [sweep] = read_impedance_sweeps(_write(tmp_path, "\n".join(lines) + "\n"))
    assert sweep.force_n == 0.0 and math.copysign(1.0, sweep.force_n) == 1.0


def test_forces_split_a_file_into_sweeps(tmp_path):
    lines = ["freq_hz,z_real_ohm,z_imag_ohm,force_n"]
    for force in (1.0, 0.0):
        lines += [f"{30000 + k},{10 + k},{-500 - k},{force}" for k in range(measurements.MIN_SWEEP_POINTS)]
    sweeps = read_impedance_sweeps(_write(tmp_path, "\n".join(lines) + "\n"))
    assert [sweep.force_n for sweep in sweeps] == [0.0, 1.0]
    assert sweeps[0].label.endswith("m.csv, 0 N") and len(sweeps[1].freq_hz) == measurements.MIN_SWEEP_POINTS


@pytest.mark.parametrize(("text", "message"), [
    ("", "m.csv: empty; expected a header line freq_hz,z_real_ohm,z_imag_ohm[,force_n] or"),
    ("freq_hz,z_real_ohm\n1,2\n", "m.csv: header: the impedance needs z_real_ohm and z_imag_ohm, or z_abs_ohm and "
                                  "z_phase_deg (got z_real_ohm)"),
    ("freq_hz,z_real_ohm,z_imag_ohm,z_abs_ohm\n", "got z_real_ohm, z_imag_ohm, z_abs_ohm"),
    ("freq_hz,z_rea_ohm,z_imag_ohm\n", "m.csv:1: header: unknown column 'z_rea_ohm'; did you mean 'z_real_ohm'?"),
    ("freq_hz,freq_hz\n", "m.csv:1: header: column 'freq_hz' appears twice"),
    ("z_real_ohm,z_imag_ohm\n", "m.csv:1: header: missing column freq_hz"),
    ("freq_hz,z_real_ohm,z_imag_ohm\n1e308,1,1\n", "m.csv:2: column freq_hz: must be a finite number in [1, 1e+07] "
                                                   "Hz, got '1e308'"),
    ("freq_hz,z_real_ohm,z_imag_ohm\n-0.0,1,1\n", "column freq_hz: must be a finite number in [1, 1e+07] Hz, "
                                                  "got '-0.0'"),
    ("freq_hz,z_real_ohm,z_imag_ohm\n1,nan,1\n", "m.csv:2: column z_real_ohm: must be a finite number"),
    ("freq_hz,z_abs_ohm,z_phase_deg\n1,1,200\n", "column z_phase_deg: must be a finite number in [-180, 180]"),
    ("freq_hz,z_abs_ohm,z_phase_deg\n1,5e-324,20\n", "column z_abs_ohm: must be a finite number in [1e-06, 1e+12]"),
    ("freq_hz,z_real_ohm,z_imag_ohm\n1,0,-1e-300\n" + "".join(f"{k},1,1\n" for k in range(2, 30)),
     "m.csv:2: |Z| is below 1e-06 ohm: a short circuit, not a sweep"),
    ("freq_hz,z_real_ohm,z_imag_ohm\n1,1,1\n1,2,2\n", "m.csv:3: freq_hz 1 Hz appears twice in the sweep at 0 N "
                                                     "(also line 2)"),
    ("freq_hz,z_real_ohm,z_imag_ohm\n1,1,1\n", "m.csv: 1 points; a sweep needs at least 20"),
    ("freq_hz,z_real_ohm,z_imag_ohm\n1,1\n", "m.csv:2: 2 fields, expected 3 (freq_hz,z_real_ohm,z_imag_ohm)"),
    ("freq_hz,z_real_ohm,z_imag_ohm,force_n\n1,1,1,51\n", "column force_n: must be a finite number in [0, 50] N"),
    ("freq_hz,z_real_ohm,z_imag_ohm\n", "m.csv: no rows after the header"),
    ("freq_hz\tz_real_ohm\tz_imag_ohm\n", "header: unknown column 'freq_hz\\x09z_real_ohm\\x09z_imag_ohm': columns are "
                                           "separated by commas, not tabs"),
    ("freq_hz;z_real_ohm;z_imag_ohm\n", "columns are separated by commas, not semicolons"),
    ("30620.5,1,-500\n30621.5,1,-500\n", "m.csv:1: header: unknown column '30620.5': the file starts with data; its "
                                        "first line must name the columns"),
    ("freq_hz,z_real_ohm,z_imag_ohm\n31_000,1,1\n", "m.csv:2: column freq_hz: must be a finite number in [1, 1e+07] "
                                                    "Hz, got '31_000'"),
    ("freq_hz,z_real_ohm,z_imag_ohm\n\u0663\u0661\u0660\u0660\u0660,1,1\n", "m.csv:2: column freq_hz: must be a finite number"),
    ("freq_hz,z_real_ohm,z_imag_ohm\n\uff13\uff11\uff10\uff10\uff10,1,1\n", "m.csv:2: column freq_hz: must be a finite number"),
    ("freq_hz,z_real_ohm,z_imag_ohm\n1,infinity,1\n", "m.csv:2: column z_real_ohm: must be a finite number"),
    ("freq_hz,z_abs_ohm,z_phase_deg\n" + "".join(f"{30000 + k},500,{-1.57 + k / 100}\n" for k in range(30)),
     "m.csv: z_phase_deg: every phase lies within +-pi, as radians would: the column is in degrees"),
    ("freq_hz,z_real_ohm,z_imag_ohm,force_n\n" + "".join(f"{30000 + k},1,-500,{k % 2 * 1e-320}\n" for k in range(40)),
     "m.csv: force_n: sweeps at 0 and 9.99989e-321 N are less than 0.001 N apart: one sweep per force"),
])
def test_bad_impedance_files_are_refused_in_one_message(tmp_path, text, message):
    with pytest.raises(ConfigError) as caught:
        read_impedance_sweeps(_write(tmp_path, text))
    assert message in str(caught.value)


@pytest.mark.parametrize(("text", "message"), [
    ("force_n,voltage_v\n", "m.csv:1: header: missing column amplitude_um; expected "
                            "force_n,voltage_v,amplitude_um[,freq_hz]"),
    ("force_n,voltage_v,amplitude_um\n0,0,1\n", "m.csv:2: column voltage_v: must be a finite number in [1e-06, "
                                                 "10000] V"),
    ("force_n,voltage_v,amplitude_um\n0,1,inf\n", "column amplitude_um: must be a finite number in [1e-06, 1000] um"),
    ("force_n,voltage_v,amplitude_um,freq_hz\n0,1,1,5e-324\n", "column freq_hz: must be a finite number in [1, "
                                                               "1e+07] Hz, got '5e-324'"),
])
def test_bad_amplitude_files_are_refused_in_one_message(tmp_path, text, message):
    with pytest.raises(ConfigError) as caught:
        read_amplitudes(_write(tmp_path, text))
    assert message in str(caught.value)


def test_a_file_with_too_many_rows_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(measurements, "MAX_MEASUREMENT_ROWS", 3)
    path = _write(tmp_path, "force_n,voltage_v,amplitude_um\n" + "0,1,1\n" * 4)
    with pytest.raises(ConfigError, match=r"m.csv:5: more than 3 rows, the most a measurement file may hold"):
        read_amplitudes(path)


def test_a_fifo_is_refused_before_it_is_read(tmp_path):
    import os

    fifo = tmp_path / "sweep.csv"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match="not a regular file \\(a FIFO\\); tpad-rt reads impedance sweeps from"):
        read_impedance_sweeps(fifo)


def test_a_file_of_too_many_forces_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(measurements, "MAX_SWEEPS", 2)
    rows = "".join(f"{30000 + k},1,-500,{force}\n" for force in (0, 1, 2) for k in range(20))
    with pytest.raises(ConfigError, match="m.csv: 3 forces; a file may hold at most 2 sweeps"):
        read_impedance_sweeps(_write(tmp_path, "freq_hz,z_real_ohm,z_imag_ohm,force_n\n" + rows))
