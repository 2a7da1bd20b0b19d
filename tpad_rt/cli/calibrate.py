"""``tpad-rt calibrate``: device files from a user's own measurements (docs/calibration.md).

Actions:

- ``impedance SWEEP.csv... [--json] [--plot FILE.png]``: fit the Butterworth-Van Dyke
  circuit to impedance sweeps, one fit per contact force, with uncertainties;
- ``amplitude MEAS.csv (--impedance SWEEP.csv... | --device FILE) [--freq-hz F] [--json]
  [--plot FILE.png]``: fit the one transduction factor gamma, check linearity in volts and
  how well one gamma explains every force;
- ``build --impedance SWEEP.csv... --amplitude MEAS.csv --out DEVICE.yaml``: both fits,
  written as a device file that ``tpad-rt check`` accepts and ``play`` renders;
- ``convert OLD.yaml --out NEW.yaml``: a format 1 device file as format 2;
- ``sweep serial://PORT [--device FILE]``: find the resonance through an amplifier that
  measures current and phase (:mod:`tpad_rt.calibrate.sweep`).

Tables go to stdout; warnings (a poorly determined parameter, a force one gamma does not
explain) to stderr as ``warning: ...`` once the action succeeded. Every mistake (a bad
file, a sweep the model does not fit, a bad flag, a device that would not load) ends in
one line on stderr and exit status 1, with nothing written.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import shutil
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from rich import box
from rich.console import Console
from rich.table import Table

from tpad_rt.calibrate import sweep
from tpad_rt.calibrate.impedance import QUANTITIES, BvdFit, fit_sweep
from tpad_rt.calibrate.measurements import ImpedanceSweep, read_amplitudes, read_impedance_sweeps
from tpad_rt.cli.arguments import Subparsers, number
from tpad_rt.config.device_ranges import MAX_CARRIER_HZ, MAX_VOLTS, MIN_CARRIER_HZ
from tpad_rt.errors import ConfigError, printable
from tpad_rt.files import NewFile, check_writable_target
from tpad_rt.json_text import json_text
from tpad_rt.shipped import device_file
from tpad_rt.figures import figure_target, save

# The parser needs none of these (they load pydantic's device model): the functions import them when they run.
if TYPE_CHECKING:
    from tpad_rt.calibrate.amplitude import Circuit, GammaFit
    from tpad_rt.device import Device

_HEADER = "# written by tpad-rt calibrate {action}: its source entries say where each value came from\n"


def add_parser(subparsers: Subparsers) -> None:
    """Register ``calibrate`` and its actions."""
    parser = subparsers.add_parser(
        "calibrate",
        help="fit a device file to your own measurements: impedance sweeps, amplitudes",
        description="Turn a rig's own measurements into a device file (docs/calibration.md).",
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True

    impedance = actions.add_parser(
        "impedance", help="fit the BVD circuit (C0, L, C, R) to impedance sweeps, one per force",
        description="Fit C0 in parallel with L, C, R to impedance sweeps (CSV: freq_hz, z_real_ohm and "
        "z_imag_ohm or z_abs_ohm and z_phase_deg, optional force_n).")
    impedance.add_argument("sweeps", metavar="SWEEP.csv", nargs="+", help="impedance sweep files")
    impedance.add_argument("--json", action="store_true", help="print a JSON list, one object per force")
    impedance.add_argument("--plot", metavar="FILE.png", help="draw |Z|, phase, admittance circle and residuals")
    impedance.set_defaults(func=run_impedance)

    amplitude = actions.add_parser(
        "amplitude", help="fit the transduction factor gamma to amplitude measurements",
        description="Fit one gamma (i_g = gamma dX/dt) to amplitude measurements (CSV: force_n, voltage_v, "
        "amplitude_um, optional freq_hz) through a circuit from impedance sweeps or a device file.")
    amplitude.add_argument("measurements", metavar="MEAS.csv", help="amplitude measurement file")
    source = amplitude.add_mutually_exclusive_group(required=True)
    source.add_argument("--impedance", metavar="SWEEP.csv", nargs="+", help="impedance sweeps giving the circuit")
    source.add_argument("--device", metavar="FILE", help="device file giving the circuit")
    amplitude.add_argument("--freq-hz", type=number(MIN_CARRIER_HZ, True, MAX_CARRIER_HZ, "Hz"),
                           help="drive frequency of rows without freq_hz (default: the carrier: --device's, or the "
                           "sweeps' loaded resonance at their lowest force, as build writes it)")
    amplitude.add_argument("--json", action="store_true", help="print a JSON object")
    amplitude.add_argument("--plot", metavar="FILE.png", help="draw amplitude against volts, and gamma per force")
    amplitude.set_defaults(func=run_amplitude)

    build = actions.add_parser(
        "build", help="write a device file from impedance sweeps and amplitude measurements",
        description="Fit the circuit and gamma, and write a format 2 device file with its sources.")
    build.add_argument("--impedance", metavar="SWEEP.csv", nargs="+", required=True, help="impedance sweeps")
    build.add_argument("--amplitude", metavar="MEAS.csv", required=True, help="amplitude measurements")
    build.add_argument("--out", metavar="DEVICE.yaml", required=True, help="device file to write")
    build.add_argument("--like", metavar="DEVICE", default="default",
                       help="device (file or shipped name) whose plate, actuator, amplifier and friction model to "
                       "copy (default: default)")
    build.add_argument("--label", help="the device's label (default: the output file's name)")
    build.add_argument("--carrier-hz", type=number(MIN_CARRIER_HZ, True, MAX_CARRIER_HZ, "Hz"),
                       help="drive frequency (default: the loaded resonance at the lowest force)")
    build.add_argument("--freq-hz", type=number(MIN_CARRIER_HZ, True, MAX_CARRIER_HZ, "Hz"),
                       help="drive frequency of --amplitude rows without freq_hz (default: the carrier)")
    build.add_argument("--shunt-ohm", type=number(1e-3, True, 1e6, "ohm"), help="shunt resistor (default: --like's)")
    build.add_argument("--max-voltage-v", type=number(0.1, True, MAX_VOLTS, "V"),
                       help="peak drive never exceeded (default: --like's)")
    build.add_argument("--power-budget-w", type=number(0.001, True, 1000, "W"),
                       help="average power budget (default: 1.2 x the power at max volts, no contact)")
    build.set_defaults(func=run_build)

    convert = actions.add_parser(
        "convert", help="convert a format 1 device file to format 2 (one circuit, one gamma)",
        description="Read a format 1 device file (amplitude table beside the circuit) and write it as format 2.")
    convert.add_argument("old", metavar="OLD.yaml", help="format 1 device file")
    convert.add_argument("--out", metavar="NEW.yaml", required=True, help="format 2 device file to write")
    convert.set_defaults(func=run_convert)

    sweeper = actions.add_parser(
        "sweep", help="find the resonance through a serial amplifier that measures current and phase",
        description="Sweep the carrier of a serial amplifier (docs/amp-protocol.md) holding a small drive, read "
        "the current and phase it measures, and fit the circuit around the resonance.")
    sweeper.add_argument("url", metavar="serial://PORT", help="the amplifier (as play's --output takes it)")
    sweeper.add_argument("--device", metavar="FILE", help="device file or shipped name: its carrier centres the "
                         "search, its shunt is taken off the measured impedance (default: default)")
    sweeper.add_argument("--from-hz", type=number(MIN_CARRIER_HZ, True, MAX_CARRIER_HZ, "Hz"),
                         help=f"lowest carrier of the coarse sweep (default: the device's carrier less "
                         f"{100 * sweep.COARSE_SPAN:g} %%)")
    sweeper.add_argument("--to-hz", type=number(MIN_CARRIER_HZ, True, MAX_CARRIER_HZ, "Hz"),
                         help=f"highest carrier of the coarse sweep (default: the device's carrier plus "
                         f"{100 * sweep.COARSE_SPAN:g} %%)")
    sweeper.add_argument("--drive-v", type=number(MIN_DRIVE_V, True, MAX_VOLTS, "V"),
                         help=f"drive held while sweeping, V peak (default: {sweep.DEFAULT_DRIVE_V:g} V, or 1/8 of "
                         "the device's max volts if less)")
    sweeper.add_argument("--dwell-ms", type=number(1, True, sweep.MAX_DWELL_S * 1e3, "ms"),
                         help=f"time each carrier is held before it is read (default: "
                         f"{sweep.DWELL_TIME_CONSTANTS:g} envelope time constants of the device without contact, at "
                         f"least {sweep.MIN_DWELL_S * 1e3:g}, at most {sweep.MAX_DWELL_S * 1e3:g})")
    sweeper.add_argument("--out", metavar="SWEEP.csv", help="write the fine sweep (freq_hz, z_real_ohm, z_imag_ohm)")
    sweeper.add_argument("--json", action="store_true", help="print a JSON object")
    sweeper.add_argument("--plot", metavar="FILE.png", help="draw the fine sweep with its fit")
    sweeper.set_defaults(func=run_sweep)


#: Columns the fit tables need: wider than a default 80-column terminal, so they are printed at least this wide.
_TABLE_WIDTH = 120


#: The least sweep drive (V peak): the amplifier's STATUS reports whole millivolts.
MIN_DRIVE_V = 0.01
#: The longest --label (characters).
MAX_LABEL_CHARS = 200


def _print(table: Table) -> None:
    """Print ``table`` whole: as wide as the terminal, or as its widest row if wider (no number cut short)."""
    natural = Console(width=10_000).measure(table).maximum
    Console(highlight=False, width=max(shutil.get_terminal_size().columns, _TABLE_WIDTH, natural)).print(table)


def _warn(lines: list[str]) -> None:
    for line in lines:
        print(f"warning: {line}", file=sys.stderr)


def _sweeps(paths: list[str]) -> list[ImpedanceSweep]:
    """Every sweep of ``paths``, forces ascending; ConfigError when two files give the same force."""
    sweeps = [one for path in paths for one in read_impedance_sweeps(path)]
    sweeps.sort(key=lambda one: one.force_n)
    for before, after in zip(sweeps, sweeps[1:]):
        if before.force_n == after.force_n:
            raise ConfigError(f"{after.source}: a sweep at {after.force_n:g} N again ({before.source} has one): "
                              "give each force once")
    return sweeps


def _fits(paths: list[str]) -> tuple[list[ImpedanceSweep], list[BvdFit]]:
    sweeps = _sweeps(paths)
    return sweeps, [fit_sweep(sweep) for sweep in sweeps]


def _fit_warnings(sweeps: list[ImpedanceSweep], fits: list[BvdFit]) -> list[str]:
    return [f"{one.label}: {line}" for one, fit in zip(sweeps, fits) for line in fit.warnings]


def concise(value: float, relative: float) -> str:
    """``value`` with its standard uncertainty ``relative`` (a fraction) in concise notation: the uncertainty's
    two leading digits in parentheses, in units of the value's last digit (``1.0395(26)`` is 1.0395 +- 0.0026)."""
    sigma = abs(value) * relative
    if not math.isfinite(sigma) or sigma <= 0.0:
        return f"{value:.6g}"
    decimals = max(0, 1 - math.floor(math.log10(sigma)))
    return f"{value:.{decimals}f}({round(sigma * 10**decimals):d})"


def _impedance_table(fits: list[BvdFit]) -> Table:
    title = "Butterworth-Van Dyke fit (the last digits' standard uncertainty in parentheses)"
    table = Table(box=box.SIMPLE_HEAD, title=title)
    for heading in ("force (N)", "C0 (nF)", "L (H)", "C (pF)", "R (ohm)", "f_s (Hz)", "Q", "points", "residual"):
        table.add_column(heading, justify="right", no_wrap=True)
    for fit in fits:
        values, spread = fit.values(), fit.uncertainty
        cells = [concise(values[key], spread[key]) for key in QUANTITIES]
        force = f"{fit.force_n:g}" if fit.force_given else "0 (none given)"
        table.add_row(force, *cells, f"{fit.points} ({fit.band_points})", f"{100 * fit.rms_residual:.2g} %")
    table.caption = "points: in the sweep (inside the half-power band); residual: RMS of (Z fit - Z) / |Z|"
    return table


def run_impedance(args: argparse.Namespace) -> int:
    """Fit every sweep; print the table or JSON; draw --plot. ConfigError for a bad file or a sweep the
    model does not fit."""
    out = None if args.plot is None else figure_target("--plot", args.plot)
    sweeps, fits = _fits(args.sweeps)
    if args.json:
        print(json_text([fit.as_json() for fit in fits], indent=2))
    else:
        _print(_impedance_table(fits))
    if out is not None:
        from tpad_rt.calibrate.plots import impedance_figure

        save(impedance_figure(sweeps, fits), out)
        print(f"wrote {printable(str(out))}", file=sys.stderr if args.json else sys.stdout)
    _warn(_fit_warnings(sweeps, fits))
    return 0


def _circuit(args: argparse.Namespace) -> tuple[Circuit, float, list[str]]:
    """The circuit the amplitudes are read through, the carrier (Hz) rows without freq_hz were driven at (the
    device's; for sweeps, the loaded resonance at the lowest force that calibrate build would write with the
    default device's shunt), and the impedance fits' warnings."""
    from tpad_rt.calibrate.amplitude import Circuit
    from tpad_rt.calibrate.device_file import circuit_of, default_carrier_hz
    from tpad_rt.device import Device

    if args.impedance:
        sweeps, fits = _fits(args.impedance)
        return circuit_of(fits), default_carrier_hz(fits, Device.default().shunt_ohm), _fit_warnings(sweeps, fits)
    device = Device.from_file(args.device)
    return Circuit.of_device(device), device.carrier_hz, []


def _gamma_table(fit: GammaFit) -> Table:
    title = f"one gamma: {fit.gamma_n_per_v:.5g} N/V +-{100 * fit.uncertainty:.2g} %"
    table = Table(box=box.SIMPLE_HEAD, title=title)
    for heading in ("force (N)", "rows", "own gamma (N/V)", "vs the one gamma", "linear in volts within"):
        table.add_column(heading, justify="right", no_wrap=True)
    for force in fit.forces:
        linearity = "one voltage" if force.linearity is None else f"{100 * force.linearity:.2g} %"
        table.add_row(f"{force.force_n:g}", f"{force.points}", f"{force.gamma_n_per_v:.5g}",
                      f"{100 * force.deviation:+.1f} %", linearity)
    return table


def run_amplitude(args: argparse.Namespace) -> int:
    """Fit gamma; print the table or JSON; draw --plot. ConfigError for a bad file."""
    from tpad_rt.calibrate.amplitude import fit_gamma

    out = None if args.plot is None else figure_target("--plot", args.plot)
    circuit, carrier_hz, warnings = _circuit(args)
    measurements = read_amplitudes(args.measurements)
    fit = fit_gamma(measurements, circuit, carrier_hz if args.freq_hz is None else args.freq_hz)
    if args.json:
        print(json_text(fit.as_json(), indent=2))
    else:
        _print(_gamma_table(fit))
    if out is not None:
        from tpad_rt.calibrate.plots import amplitude_figure

        save(amplitude_figure(measurements, circuit, fit), out)
        print(f"wrote {printable(str(out))}", file=sys.stderr if args.json else sys.stdout)
    _warn(warnings + [f"{measurements.source}: {line}" for line in fit.warnings])
    return 0


def _summary(device: Device, out: Path) -> str:
    return (f"wrote {printable(str(out))}: device {printable(device.label)}, carrier {device.carrier_hz:.2f} Hz, "
            f"gamma {device.gamma_n_per_v:.4g} N/V, {len(device.force_table_n)} forces "
            f"({device.force_table_n[0]:g}-{device.force_table_n[-1]:g} N), "
            f"{device.amplitude_m_per_v(device.force_table_n[0]) * device.max_voltage_v * 1e6:.3g} um at "
            f"{device.max_voltage_v:g} V without contact, power budget {device.power_budget_w:g} W")


def run_build(args: argparse.Namespace) -> int:
    """Fit, build and write the device file; print what it holds. ConfigError for a bad input or a device
    that would not load."""
    from tpad_rt.calibrate.amplitude import fit_gamma
    from tpad_rt.calibrate.device_file import (
        BuildOptions, build_document, circuit_of, default_carrier_hz, write_device,
    )
    from tpad_rt.config import load_device

    out = Path(args.out)
    if args.label is not None and not (0 < len(args.label) <= MAX_LABEL_CHARS and args.label.isprintable()):
        raise ConfigError(f"--label: must be 1 to {MAX_LABEL_CHARS} printable characters, got "
                          f"'{printable(args.label[:MAX_LABEL_CHARS])}'")
    check_writable_target(out, "device files", [*args.impedance, args.amplitude, device_file(args.like)])
    template = load_device(args.like)
    full_scale_v = template.amplifier.volts_per_full_scale
    if args.max_voltage_v is not None and args.max_voltage_v > full_scale_v:
        raise ConfigError(f"--max-voltage-v: must be <= the volts_per_full_scale of --like {printable(args.like)} "
                          f"({full_scale_v:g} V), got {args.max_voltage_v:g}")
    sweeps, fits = _fits(args.impedance)
    measurements = read_amplitudes(args.amplitude)
    shunt_ohm = template.circuit.shunt_ohm if args.shunt_ohm is None else args.shunt_ohm
    carrier_hz = default_carrier_hz(fits, shunt_ohm) if args.carrier_hz is None else args.carrier_hz
    # Amplitude rows without a freq_hz column were measured at the carrier the device will drive at
    gamma = fit_gamma(measurements, circuit_of(fits), carrier_hz if args.freq_hz is None else args.freq_hz)
    options = BuildOptions(
        label=args.label or out.stem, impedance_files=tuple(Path(path).name for path in args.impedance),
        amplitude_file=Path(args.amplitude).name, template_name=str(args.like), carrier_hz=args.carrier_hz,
        shunt_ohm=args.shunt_ohm, max_voltage_v=args.max_voltage_v, power_budget_w=args.power_budget_w,
    )
    document, notes = build_document(fits, gamma, template, options)
    device = write_device(document, out, _HEADER.format(action="build"))
    print(_summary(device, out))
    _warn(_fit_warnings(sweeps, fits) + [f"{measurements.source}: {line}" for line in gamma.warnings] + notes)
    return 0


def _write_sweep(out: Path, found: sweep.SweepResult) -> None:
    """Write the fine sweep to ``out`` as an impedance CSV (docs/calibration.md "CSV formats"), through
    :class:`tpad_rt.files.NewFile` (its errors)."""
    fine = found.fine
    lines = [f"# tpad-rt calibrate sweep: {fine.source}, the device's shunt taken off", "freq_hz,z_real_ohm,z_imag_ohm"]
    lines += [f"{freq!r},{z.real!r},{z.imag!r}" for freq, z in zip(fine.freq_hz.tolist(), fine.impedance_ohm.tolist())]
    with NewFile(out, "impedance sweeps") as new:
        new.file.write(("\n".join(lines) + "\n").encode("utf-8"))


def run_sweep(args: argparse.Namespace) -> int:
    """Find the resonance through the amplifier; print it. ConfigError for a bad option or a sweep the model does
    not fit, BackendError for the amplifier."""
    from tpad_rt.device import Device
    from tpad_rt.outputs.serial_amp import AmpLink, parse_serial_url

    plot = None if args.plot is None else figure_target("--plot", args.plot)
    out = None if args.out is None else Path(args.out)
    if out is not None:
        check_writable_target(out, "impedance sweeps", [device_file("default" if args.device is None else args.device)])
    device = Device.default() if args.device is None else Device.from_file(args.device)
    drive_v = args.drive_v if args.drive_v is not None else min(sweep.DEFAULT_DRIVE_V, device.max_voltage_v / 8)
    if drive_v > device.max_voltage_v:
        raise ConfigError(f"--drive-v: must be <= the device's max_voltage_v ({device.max_voltage_v:g} V), "
                          f"got {drive_v:g}")
    low = args.from_hz if args.from_hz is not None else device.carrier_hz * (1 - sweep.COARSE_SPAN)
    high = args.to_hz if args.to_hz is not None else device.carrier_hz * (1 + sweep.COARSE_SPAN)
    if not low < high:
        raise ConfigError(f"--from-hz ({low:g}) must be below --to-hz ({high:g})")
    dwell_s = sweep.default_dwell_s(device) if args.dwell_ms is None else args.dwell_ms * 1e-3
    target = parse_serial_url(args.url)
    link = AmpLink.open(target, carrier_hz=low, max_voltage_v=device.max_voltage_v)  # the tone within both caps
    started = time.monotonic()
    try:
        assert link.info is not None
        if drive_v > link.info.max_v:
            raise ConfigError(f"--drive-v: must be <= the amplifier's clamp ({link.info.max_v:g} V), got {drive_v:g}")
        with _progress("sweeping the carrier") as advance:
            found = sweep.find_resonance(link, device, drive_v, dwell_s, low, high, advance)
    finally:
        link.stop(ramp_ms=5.0)
    seconds = time.monotonic() - started
    if out is not None:
        _write_sweep(out, found)
    if args.json:
        print(json_text(found.as_json(), indent=2))
    else:
        fit = found.fit
        zero = "none within 5 degrees (the piezo stays capacitive)" if found.zero_phase_hz is None \
            else f"{found.zero_phase_hz:.2f} Hz"
        print(f"resonance: {found.loaded_resonance_hz:.2f} Hz loaded by the shunt (the carrier to drive at); "
              f"series {fit.resonance_hz:.2f} Hz")
        print(f"circuit: C0 {fit.c0_f * 1e9:.4g} nF, L {fit.l_h:.5g} H, C {fit.c_f * 1e12:.5g} pF, "
              f"R {fit.r_ohm:.5g} ohm, Q {fit.q:.4g}; zero phase: {zero}")
        print(f"measured {len(found.coarse.freq_hz) + len(found.fine.freq_hz)} carriers at {drive_v:g} V in "
              f"{seconds:.1f} s")
    if plot is not None:
        from tpad_rt.calibrate.plots import impedance_figure

        save(impedance_figure([found.fine], [found.fit]), plot)
        print(f"wrote {printable(str(plot))}", file=sys.stderr if args.json else sys.stdout)
    if out is not None:
        print(f"wrote {printable(str(out))}", file=sys.stderr if args.json else sys.stdout)
    _warn([f"{found.fine.label}: {line}" for line in found.fit.warnings])
    return 0


@contextlib.contextmanager
def _progress(what: str) -> Iterator[Callable[[int, int], None]]:
    """A progress bar on stderr while the block runs (none when stderr is not a terminal); yields advance(done,
    total)."""
    if not sys.stderr.isatty():
        yield lambda done, total: None
        return
    from rich.progress import Progress

    with Progress(console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task(what, total=None)

        def advance(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield advance


def run_convert(args: argparse.Namespace) -> int:
    """Convert the format 1 file; say how far its amplitude table was from one gamma."""
    from tpad_rt.calibrate.device_file import convert_document, write_device

    out = Path(args.out)
    check_writable_target(out, "device files", [args.old])
    document, spread = convert_document(args.old)
    device = write_device(document, out, _HEADER.format(action="convert"))
    print(_summary(device, out))
    print(f"its amplitude table implied gammas {spread.ratio:.2f}x apart across force; the file now has one, their "
          f"geometric mean {spread.gamma_n_per_v:.4g} N/V: amplitude per volt follows the circuit")
    return 0
