"""Writing device files from measurements (``calibrate build``) and from format 1 files (``calibrate convert``).

Both write a format 2 device file (docs/formats.md "Device files") whose ``source``
entries say, key by key, where each value came from: the measurement files and the
date, the template device the geometry was taken from, or a default. A file is written
only once it loads as a :class:`~tpad_rt.device.Device` (what ``tpad-rt check`` and
``play`` do), through a temporary file created exclusively beside it and renamed onto it
(:class:`tpad_rt.files.NewFile`).

API map
-------
build_document(fits, gamma, template, options) -> dict
    a device document from impedance fits, a gamma fit and a template device
convert_document(path) -> (dict, GammaSpread)
    the format 2 document of the format 1 file at ``path``
write_device(document, out, header) -> Device
    write ``document`` to ``out`` once it loads
default_power_budget_w(power_w) -> float
    POWER_BUDGET_MARGIN x ``power_w``, rounded up to POWER_BUDGET_STEP_W
"""

from __future__ import annotations

import datetime
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tpad_rt.calibrate.amplitude import Circuit, GammaFit
from tpad_rt.calibrate.impedance import BvdFit
from tpad_rt.config import DeviceFile
from tpad_rt.config.device_schema import DEVICE_FORMAT_VERSION, FORCE_SLACK_N, MIN_FORCE_STEP_N
from tpad_rt.config.loader import validate_device
from tpad_rt.config.yaml_io import YamlDocument, dump_yaml, load_yaml
from tpad_rt.device import Device
from tpad_rt.errors import ConfigError, printable
from tpad_rt.files import NewFile
from tpad_rt.limits import MAX_FORCE_N
from tpad_rt.physics import electromech

#: The default power budget: this many times the power at max_voltage_v at the lowest force ...
POWER_BUDGET_MARGIN = 1.2
#: ... rounded up to a multiple of this (W).
POWER_BUDGET_STEP_W = 0.05
#: Significant digits the circuit values are written with (the carrier then moves by < 0.01 Hz).
DIGITS = 7
#: C0s fitted at different forces that spread wider than this fraction are reported.
C0_SPREAD_TOLERANCE = 0.02


def default_power_budget_w(power_w: float) -> float:
    """POWER_BUDGET_MARGIN x ``power_w`` (W), rounded up to POWER_BUDGET_STEP_W."""
    steps = math.ceil(round(POWER_BUDGET_MARGIN * power_w / POWER_BUDGET_STEP_W, 9))
    return round(max(steps, 1) * POWER_BUDGET_STEP_W, 2)


def _significant(value: float) -> float:
    return float(f"{value:.{DIGITS}g}")


def circuit_of(fits: list[BvdFit]) -> Circuit:
    """The motional branch of ``fits`` (one per force, forces ascending) as an amplitude-fit Circuit."""
    return Circuit(np.array([fit.force_n for fit in fits]), np.array([fit.l_h for fit in fits]),
                   np.array([fit.c_f for fit in fits]), np.array([fit.r_ohm for fit in fits]))


@dataclass(frozen=True)
class BuildOptions:
    """What ``calibrate build`` takes besides the fits: each None means "derive it" (see build_document)."""

    label: str
    impedance_files: tuple[str, ...]
    amplitude_file: str
    template_name: str
    carrier_hz: float | None = None
    shunt_ohm: float | None = None
    max_voltage_v: float | None = None
    power_budget_w: float | None = None
    date: str = ""


def _template_part(template: DeviceFile, key: str) -> Any:
    return template.model_dump(mode="json")[key]


def default_carrier_hz(fits: list[BvdFit], shunt_ohm: float) -> float:
    """The carrier (Hz, to 0.01) a device built from ``fits`` (one per force, lowest first) drives at unless told:
    the circuit's loaded resonance (shunt ``shunt_ohm`` and the fits' median C0 included) at the lowest force."""
    c0_f = float(np.median([fit.c0_f for fit in fits]))
    lowest = fits[0]
    l_h, c_f = _significant(lowest.l_h), _significant(lowest.c_f * 1e12) * 1e-12
    return round(float(electromech.loaded_resonance_hz(c0_f, l_h, c_f, shunt_ohm)), 2)


def build_document(fits: list[BvdFit], gamma: GammaFit, template: DeviceFile,
                   options: BuildOptions) -> tuple[dict[str, Any], list[str]]:
    """``(document, notes)``: a format 2 device from ``fits`` (one per force), ``gamma`` and ``template``.

    The circuit is the fits' (C0 their median), gamma the amplitude fit's; the plate,
    actuator, friction model, speed floor, pre-emphasis, mode shape (if any) and volts per
    full scale are the template's. The shunt and max volts are the template's unless given; the carrier is
    the loaded resonance at the lowest force unless given; the power budget
    POWER_BUDGET_MARGIN x the power at max volts at the lowest force, rounded up, unless
    given. ``notes`` are lines for the user (a C0 that varies with force).
    """
    date = options.date or datetime.date.today().isoformat()
    c0s = np.array([fit.c0_f for fit in fits])
    c0_f = float(np.median(c0s))
    notes = []
    spread = float(np.ptp(c0s) / c0_f)
    if spread > C0_SPREAD_TOLERANCE:
        notes.append(f"C0 varies by {100 * spread:.1f} % across the forces' fits; the device uses their median, "
                     f"{c0_f * 1e9:.4g} nF")
    shunt_ohm = template.circuit.shunt_ohm if options.shunt_ohm is None else options.shunt_ohm
    amplifier = _template_part(template, "amplifier")
    if options.max_voltage_v is not None:
        amplifier["max_voltage_v"] = options.max_voltage_v
    l_h = [_significant(fit.l_h) for fit in fits]
    c_pf = [_significant(fit.c_f * 1e12) for fit in fits]
    r_ohm = [_significant(fit.r_ohm) for fit in fits]
    lowest = fits[0]
    if options.carrier_hz is None:
        carrier_hz = default_carrier_hz(fits, shunt_ohm)
        carrier_source = f"derived: the fitted circuit's loaded resonance (shunt and C0 included) at {lowest.force_n:g} N"
    else:
        carrier_hz, carrier_source = options.carrier_hz, "given: calibrate build --carrier-hz"
    if options.power_budget_w is None:
        current = electromech.motional_current(amplifier["max_voltage_v"], carrier_hz, c0_f, l_h[0], c_pf[0] * 1e-12,
                                               r_ohm[0], shunt_ohm)
        power_budget_w = default_power_budget_w(float(np.abs(current) ** 2 * r_ohm[0] / 2))
        budget_source = (f"derived: {POWER_BUDGET_MARGIN:g} x the power at max_voltage_v at {lowest.force_n:g} N, "
                         f"rounded up to {POWER_BUDGET_STEP_W:g} W")
    else:
        power_budget_w, budget_source = options.power_budget_w, "given: calibrate build --power-budget-w"
    sweeps = ", ".join(options.impedance_files)
    template_source = f"from the template device {options.template_name} (not measured by this calibration)"
    document = {
        "format_version": DEVICE_FORMAT_VERSION,
        "label": options.label,
        "description": f"calibrated by tpad-rt calibrate build on {date} from {sweeps} and {options.amplitude_file}",
        "plate": _template_part(template, "plate"),
        "actuator": _template_part(template, "actuator"),
        "carrier_hz": carrier_hz,
        "amplifier": amplifier,
        "circuit": {
            "c0_nf": _significant(c0_f * 1e9),
            "shunt_ohm": shunt_ohm,
            "gamma_n_per_v": _significant(gamma.gamma_n_per_v),
            "force_n": [fit.force_n for fit in fits],
            "motional_l_h": l_h,
            "motional_c_pf": c_pf,
            "motional_r_ohm": r_ohm,
        },
        "friction_model": _template_part(template, "friction_model"),
        "speed_floor_mm_s": template.speed_floor_mm_s,
        "power_budget_w": power_budget_w,
        "preemphasis": template.preemphasis,
        "source": {
            "plate": template_source,
            "actuator": template_source,
            "carrier_hz": carrier_source,
            "amplifier.volts_per_full_scale": template_source,
            "amplifier.max_voltage_v": template_source if options.max_voltage_v is None
            else "given: calibrate build --max-voltage-v",
            "circuit.c0_nf": f"measured: fitted to {sweeps} on {date} (the median over forces)",
            "circuit.shunt_ohm": template_source if options.shunt_ohm is None else "given: calibrate build --shunt-ohm",
            "circuit.gamma_n_per_v": f"measured: fitted to {options.amplitude_file} on {date} (one gamma; the "
            f"forces' own lie within {100 * gamma.worst_deviation:.1f} % of it)",
            "circuit.force_n": f"measured: the forces of {sweeps}",
            "circuit.motional": f"measured: fitted to {sweeps} on {date}",
            "friction_model": template_source,
            "speed_floor_mm_s": template_source,
            "power_budget_w": budget_source,
            "preemphasis": template_source,
        },
    }
    if template.mode_shape is not None:
        document["mode_shape"] = _template_part(template, "mode_shape")
        document["source"]["mode_shape"] = template_source
    return document, notes


@dataclass(frozen=True)
class GammaSpread:
    """How far a format 1 file's amplitude table was from one gamma: the gamma chosen (N/V) and the ratio of
    the largest per-force gamma to the smallest."""

    gamma_n_per_v: float
    ratio: float


def _format1_table(name: str, calibration: Any) -> tuple[np.ndarray, np.ndarray]:
    """Format 1's ``calibration`` table: ``(force_n, amplitude in m per volt)``. ConfigError unless both are lists
    of the same length of real numbers (not booleans or text), forces finite in ``[0, MAX_FORCE_N]`` and rising
    by at least MIN_FORCE_STEP_N, amplitudes in ``[1e-6, 1000]`` um per volt."""
    lists = {}
    for key in ("force_n", "amplitude_um_per_v"):
        values = calibration.get(key) if isinstance(calibration, dict) else None
        if not (isinstance(values, list) and values and all(
                isinstance(value, (int, float)) and not isinstance(value, bool) for value in values)):
            raise ConfigError(f"{name}: calibration.{key}: a format 1 file needs a list of numbers here")
        try:
            lists[key] = np.array(values, dtype=np.float64)
        except OverflowError:  # an integer beyond float64
            raise ConfigError(f"{name}: calibration.{key}: a number here is beyond any force or amplitude") from None
    forces, amplitudes = lists["force_n"], lists["amplitude_um_per_v"]
    if forces.shape != amplitudes.shape:
        raise ConfigError(f"{name}: calibration: force_n and amplitude_um_per_v must be lists of the same length")
    if not np.all((forces >= 0.0) & (forces <= MAX_FORCE_N)):
        raise ConfigError(f"{name}: calibration.force_n: every force must be a number in [0, {MAX_FORCE_N:g}] N")
    if np.any(np.diff(forces) < MIN_FORCE_STEP_N - FORCE_SLACK_N):
        raise ConfigError(f"{name}: calibration.force_n: forces must increase by at least {MIN_FORCE_STEP_N:g} N")
    if not np.all((amplitudes >= 1e-6) & (amplitudes <= 1000.0)):
        raise ConfigError(f"{name}: calibration.amplitude_um_per_v: every amplitude must be a number in [1e-06, 1000] "
                          "um per volt")
    return forces + 0.0, amplitudes * 1e-6  # + 0.0: a force of -0.0 is 0


def convert_document(path: str | Path) -> tuple[dict[str, Any], GammaSpread]:
    """The format 2 document of the format 1 device file at ``path``, and how far its table was from one gamma.

    Format 1 kept an amplitude table (um per drive volt, by force) beside the circuit.
    Format 2 keeps the circuit and one gamma: for each of the table's forces, the
    circuit's motional current per drive volt at the carrier (through the shunt and C0)
    over ``omega`` times the table's amplitude gives that force's gamma; the file gets
    their geometric mean. ``resonance_hz`` becomes ``carrier_hz``. Raises ConfigError
    for a file that is not format 1, or whose circuit or table is unusable.
    """
    name = printable(str(path))
    original = load_yaml(Path(path), name)
    data = dict(original.data)
    if "format_version" in data or "resonance_hz" not in data:
        raise ConfigError(f"{name}: not a format 1 device file (it has format_version, or no resonance_hz): nothing to "
                          "convert")
    forces, amplitudes_m = _format1_table(name, data.pop("calibration", None))
    document: dict[str, Any] = {"format_version": DEVICE_FORMAT_VERSION}
    for key, value in data.items():
        document["carrier_hz" if key == "resonance_hz" else key] = value
    circuit = document.get("circuit")
    if not isinstance(circuit, dict):
        raise ConfigError(f"{name}: circuit: a format 1 file needs a circuit mapping")
    circuit["gamma_n_per_v"] = 1.0  # validated below with the rest, then replaced
    source = document.get("source")
    device = Device.from_spec(validate_device(name, YamlDocument(document, original.root)), name)
    currents = np.abs(device.motional_current_a_per_v(forces))
    gammas = currents / (2.0 * math.pi * device.carrier_hz * amplitudes_m)
    if not np.all(np.isfinite(gammas) & (gammas > 0.0)):
        raise ConfigError(f"{name}: calibration.amplitude_um_per_v: every amplitude must be a finite number > 0")
    gamma = float(np.exp(np.log(gammas).mean()))
    circuit["gamma_n_per_v"] = _significant(gamma)
    ratio = float(gammas.max() / gammas.min())
    if isinstance(source, dict):
        source.pop("calibration", None)
        source.pop("calibration.amplitude_um_per_v", None)
        source.pop("calibration.force_n", None)
        if "resonance_hz" in source:
            source["carrier_hz"] = source.pop("resonance_hz")
        source["circuit.gamma_n_per_v"] = (
            f"derived: converted from format 1 by tpad-rt calibrate convert on {datetime.date.today().isoformat()}: "
            f"the geometric mean of the gammas its amplitude table implied at each force, which spread "
            f"{ratio:.2f}x from least to most")
    return document, GammaSpread(gamma, ratio)


def write_device(document: dict[str, Any], out: str | Path, header: str = "") -> Device:
    """Write ``document`` as YAML to ``out`` once it loads as a Device; the Device.

    Written through :class:`tpad_rt.files.NewFile` (a temporary file created exclusively
    beside ``out``, loaded, then renamed onto it). Raises ConfigError, writing nothing, when
    ``out`` is no place to write (no folder, a directory, a FIFO) or the document is not a
    valid device (its problems, as ``tpad-rt check`` gives them); BackendError, writing
    nothing, when the file cannot be written (a full disk).
    """
    shown = printable(str(out))
    with NewFile(out, "device files") as new:
        new.file.write(dump_yaml(document, header).encode("utf-8"))
        new.file.flush()
        try:
            device = Device.from_file(new.temporary)
        except ConfigError as error:
            # The lines name the temporary file and its line numbers: the user sees neither.
            raise ConfigError([re.sub(r" \(line \d+\)$", "", line.replace(printable(new.temporary), f"{shown} (not written)"))
                               for line in error.errors]) from None
    return device
