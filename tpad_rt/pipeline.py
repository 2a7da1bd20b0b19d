"""The rendering pipeline: a device, a texture and options turned into the render kernel's arrays.

API map
-------
RenderOptions(power_budget_w=None, power_avg_w=None, power_window_s=1.0, control_interval=32,
              smoothing_ms=0.25, preemphasis=None, braking=True, track=False, mode_compensation=True,
              horizon_ms=0.25, velocity_window_ms=10.0, watchdog_ms=50.0, ramp_ms=5.0, default_force_n=0.5,
              mu_floor=0.01, finger_ring=1024, telemetry_ring=8192)
    the renderer's settings (frozen; ConfigError naming each bad field)
Pipeline(device, texture, fs_hz=192000, options=RenderOptions())
    ``.fs_hz``, ``.sample_index``, ``.time_s``, ``.device``, ``.texture``, ``.options``, ``.running``
    ``.push_finger(t_s, x_mm, y_mm, force_n=None, down=True)``, ``.lift(t_s)``: validated (SampleError)
    ``.stream_time_s``, ``.last_time_s``, ``.position_range_mm``, ``.check_time(t_s, name)``, ``.faults() -> dict``
    ``.set_texture(texture, t_s=None)``, ``.start()``, ``.stop()``
    ``.drive``, ``.set_drive(drive)``, ``.device_drive``: the drive it renders for (:class:`tpad_rt.drive.DriveSpec`)
    ``.recent_fingers()``: the newest samples of the finger ring, decoded; ``.fingers_since(first)``: those from
    sample number ``first`` on
    ``.render(out)``: the next ``len(out)`` float32 samples (1.0 = ``volts_per_full_scale``)
    ``.drain_telemetry() -> dict[str, np.ndarray]``: rows since the last drain, keyed by TEL_NAMES
    ``.last_telemetry_row() -> dict[str, float]``: the newest row, not drained
    ``.warm_up()``, ``.arrays`` (KernelArrays: every array ``render_block`` takes, in its order)
KernelArrays
    NamedTuple ``cfg, dev, state, power_ring, finger, finger_count, prog, params, img, stack,
    telem, telem_count``
force_grid(device) -> (start_n, step_n, intervals), device_tables(device) -> (dev, start_n, step_n)
    the uniform force grid of the device tables, and the tables on it
mode_gain_table(device, x_mm) -> gains
    the mode gain the command divides by at ``x_mm`` (Device.mode_gain, floored at MODE_GAIN_FLOOR)

docs/kernel.md is the design. :meth:`Pipeline.push_finger` validates the sample, then, under
a lock (any number of producer threads), writes the ring row and bumps the count with a
release store; the kernel reads them from another thread without a lock.
"""

from __future__ import annotations

import math
import numbers
import threading
from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np
import numpy.typing as npt

from tpad_rt.device import Device
from tpad_rt.drive import Consumes, DriveSpec
from tpad_rt.errors import ConfigError, SampleError, TpadError
from tpad_rt.inputs.base import FINGER_DTYPE
from tpad_rt.kernel import layout
from tpad_rt.aot.library import publish
from tpad_rt.limits import (
    DEFAULT_FORCE_N, FINGER_TIME_WINDOW_S, MAX_BLOCK_FRAMES, MAX_FORCE_N, MAX_RATE_HZ, position_range_mm,
)
from tpad_rt.texture import CompiledTexture

#: Highest carrier frequency, as a fraction of the sample rate, the pipeline renders (the kernel's own bound).
MAX_CARRIER_FRACTION = layout.MAX_CARRIER_FRACTION
#: Force-grid intervals: at most this many (a grid holding every table knot is sought up
#: to it) and at least this many (amplitude, power and tau are smooth between knots: on
#: 4096 intervals over the shipped 0-2 N, linear interpolation is within 2e-8 of them).
MAX_GRID_INTERVALS = 4096
MIN_GRID_INTERVALS = 4096
#: The least mode gain the command divides by: near a nodal line (a contact patch narrower than the nodal
#: spacing) it asks at most 20x the antinode amplitude, which the volt and power caps then bound.
MODE_GAIN_FLOOR = 0.05
#: How far (a fraction of the device's carrier) a tracking serial amplifier's phase lock may move the carrier
#: from the model's resonance: 0.1 %, 31 Hz on the default device (the model's resonance moves 27 Hz on SLG_0.4
#: from 0 to 2 N); the power tables hold over that band.
LOCK_RANGE = 1e-3

#: Relative tolerance for a force-table knot to count as lying on a grid point.
_KNOT_TOLERANCE = 1e-9


#: Most finger samples and telemetry rows the rings may hold (allocated up front: 40 MiB and 320 MiB).
MAX_FINGER_RING = 2**20
MAX_TELEMETRY_RING = 2**22
#: The accepted range of each number in RenderOptions (closed; units in the names). The budgets go up to the
#: device files' own limit on ``power_budget_w``; the window to a minute (its ring: 360,000 steps at 192 kHz).
_OPTION_RANGES = {
    "power_budget_w": (1e-3, 1000.0),
    "power_avg_w": (1e-3, 1000.0),
    "power_window_s": (1e-3, 60.0),
    "smoothing_ms": (0.01, 1000.0),
    "horizon_ms": (0.0, 1000.0),
    "velocity_window_ms": (0.01, 1000.0),
    "watchdog_ms": (0.01, 10_000.0),
    "ramp_ms": (0.01, 10_000.0),
    "default_force_n": (0.0, MAX_FORCE_N),
    "mu_floor": (1e-6, 1.0),
}


@dataclass(frozen=True)
class RenderOptions:
    """Settings of the renderer (units in the names). ``None`` means "the device's value".

    - ``power_budget_w``: instantaneous power cap (W); None: ``device.power_budget_w``.
    - ``power_avg_w``: average power budget (W) over every ``power_window_s`` window;
      None: the same as the cap.
    - ``power_window_s``: averaging window (s), rounded to whole control steps.
    - ``control_interval``: samples between control steps (1 to 256). The plate's
      envelope follows the drive with the loaded circuit's ``tau``
      (``Device.envelope_time_constant_s``): 1.96 ms without contact, 0.97 ms at 2 N on
      the default device, a bandwidth of 81-164 Hz; with pre-emphasis the envelope
      follows the 0.25 ms smoothing instead, as far as the volt and power limits let it.
      32 samples at 192 kHz is a 6 kHz control rate: over 35x the plate's bandwidth,
      command steps shorter than the smoothing time constant, a texture edge placed
      within 17 um at 100 mm/s, and the control step's cost (finger, texture, inverse
      model, limits, carrier anchor: about 90 ns for a grating) shared by 32 samples
      (bench/results/kernel.md, grating at block 4096: 9.5 ns per sample; 15.5 at 16, 6.7 at 64).
    - ``smoothing_ms``: one-pole time constant of the commanded envelope (ms).
    - ``preemphasis``: shape the drive so the plate envelope follows the smoothing
      instead of its own ``tau``: the shaper drives a model of the envelope onto the
      smoothed command, as hard as the cap allows; None: ``device.preemphasis``.
    - ``braking``: let the shaper drive in anti-phase (a negative envelope, within the
      same volt and power limits) to take energy out of the plate faster than it rings
      down, when the command falls.
    - ``track``: follow the plate's resonance as the contact force moves it: each control
      step drives at the device circuit's loaded resonance at the step's force
      (:meth:`Device.motional_resonance_hz`) with the amplitude, power and time constant
      there. Carrier samples (a DAC) keep the phase continuous; an amplifier that makes
      the carrier itself (``serial://``) is sent the carrier as it moves, and, if it
      measures phase, corrected towards the plate's real resonance within
      LOCK_RANGE of the carrier (docs/amplifiers.md "Tracking").
    - ``mode_compensation``: on a device with a mode shape (its file's ``mode_shape``),
      ask for the texture's amplitude under the finger, not at an antinode: the command
      divided by :meth:`Device.mode_gain` at the finger (floored at MODE_GAIN_FLOOR),
      within the same volt and power limits. Off, or without a mode shape, the command
      assumes the antinode amplitude everywhere.
    - ``horizon_ms``: extra extrapolation lead of the finger position (ms; latency
      compensation). The default equals the default ``smoothing_ms``: a one-pole filter
      delays a slowly varying envelope by its time constant, so looking that far ahead
      puts texture features back where they are on the plate.
    - ``velocity_window_ms``: span the finger velocity is estimated over (ms).
    - ``watchdog_ms``: no finger sample for longer than this and the drive ramps to 0 (ms).
    - ``ramp_ms``: linear gain ramp on start, stop, lift and watchdog (ms).
    - ``default_force_n``: contact force (N) when a finger sample carries none.
    - ``mu_floor``: lowest relative friction asked of the plate, in (0, 1].
    - ``finger_ring``: finger samples the ring holds (the newest ``finger_ring - 1`` are read).
    - ``telemetry_ring``: telemetry rows (one per rendered block) kept between drains.

    Raises ConfigError, one line per bad field, for a value out of its range: the
    numbers' ranges are _OPTION_RANGES (wide enough for any rig, narrow enough that every
    array the kernel gets stays small and every value finite), the rings' sizes at most
    MAX_FINGER_RING and MAX_TELEMETRY_RING.
    """

    power_budget_w: float | None = None
    power_avg_w: float | None = None
    power_window_s: float = 1.0
    control_interval: int = 32
    smoothing_ms: float = 0.25
    preemphasis: bool | None = None
    braking: bool = True
    track: bool = False
    mode_compensation: bool = True
    horizon_ms: float = 0.25
    velocity_window_ms: float = 10.0
    watchdog_ms: float = 50.0
    ramp_ms: float = 5.0
    default_force_n: float = DEFAULT_FORCE_N
    mu_floor: float = 0.01
    finger_ring: int = 1024
    telemetry_ring: int = 8192

    def __post_init__(self) -> None:
        problems = [f"RenderOptions.{name}: {problem}" for name, problem in self._problems()]
        if problems:
            raise ConfigError(problems)

    def _problems(self) -> list[tuple[str, str]]:
        """``(field, what is wrong)`` for every field out of its range (_OPTION_RANGES)."""
        found = []
        for name, (low, high) in _OPTION_RANGES.items():
            value = getattr(self, name)
            if value is not None:
                found.append((name, _number_problem(value, f"in [{low:g}, {high:g}]", lambda v: low <= v <= high)))
        found += [
            ("control_interval", _count_problem(self.control_interval, 1, layout.MAX_CONTROL_INTERVAL)),
            ("finger_ring", _count_problem(self.finger_ring, 2, MAX_FINGER_RING)),
            ("telemetry_ring", _count_problem(self.telemetry_ring, 1, MAX_TELEMETRY_RING)),
        ]
        if self.preemphasis is not None and not isinstance(self.preemphasis, bool):
            found.append(("preemphasis", f"must be true, false or None, got {self.preemphasis!r}"))
        for name in ("braking", "track", "mode_compensation"):
            if not isinstance(getattr(self, name), bool):
                found.append((name, f"must be true or false, got {getattr(self, name)!r}"))
        return [(name, problem) for name, problem in found if problem]


def shown(value: object) -> str:
    """``repr(value)`` for a message, cut to 40 characters."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _as_float(value: object) -> float:
    """``value`` as a float if it is a real number (not a bool) a float can hold; NaN otherwise (10**400 too)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return math.nan
    try:
        return float(value)
    except OverflowError:
        return math.nan


def _checked(name: str, value: object, low: float, high: float, unit: str) -> float:
    """``value`` as a float if it is a real number (not a bool) in ``[low, high]``; else SampleError
    ``name: must be a finite number in [low, high] unit, got value``."""
    number = _as_float(value)
    if not low <= number <= high:
        raise SampleError(f"{name}: must be a finite number in [{low:g}, {high:g}] {unit}, got {shown(value)}")
    return number


def _number_problem(value: object, rule: str, holds: Callable[[float], bool]) -> str:
    """'' if ``value`` is a finite real number satisfying ``holds``, else what is wrong."""
    number = _as_float(value)
    if not math.isfinite(number):
        return f"must be a finite number {rule}, got {shown(value)}"
    return "" if holds(number) else f"must be {rule}, got {number:g}"


def _count_problem(value: object, low: int, high: int | None) -> str:
    """'' if ``value`` is a whole number in ``[low, high]`` (no upper bound when None), else what is wrong."""
    rule = f">= {low}" if high is None else f"in [{low}, {high}]"
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        return f"must be a whole number {rule}, got {shown(value)}"
    count = int(value)
    return "" if low <= count and (high is None or count <= high) else f"must be {rule}, got {shown(value)}"


class KernelArrays(NamedTuple):
    """Every array :func:`tpad_rt.kernel.render.render_block` takes, in its argument order."""

    cfg: np.ndarray
    dev: np.ndarray
    state: np.ndarray
    power_ring: np.ndarray
    finger: np.ndarray
    finger_count: np.ndarray
    prog: np.ndarray
    params: np.ndarray
    img: np.ndarray
    stack: np.ndarray
    telem: np.ndarray
    telem_count: np.ndarray


def force_grid(device: Device) -> tuple[float, float, int]:
    """``(start_n, step_n, intervals)``: the uniform force grid the device tables are sampled on.

    It spans every knot of the circuit's force table. When all knots lie on a common
    grid of at most ``MAX_GRID_INTERVALS`` intervals (true of every shipped device:
    multiples of 0.1 N), the grid is that one, so every knot is a grid point. That grid
    is then halved until it has at least ``MIN_GRID_INTERVALS`` intervals, because
    amplitude, power and envelope time constant, smooth functions of the interpolated
    circuit, are sampled on it. Without a common grid: ``MAX_GRID_INTERVALS`` intervals.
    """
    knots = device.force_table_n
    start_n = float(knots[0])
    span_n = float(knots[-1]) - start_n
    if span_n == 0.0:
        return start_n, 1.0, 1
    offsets = (knots - start_n) / span_n
    intervals = next(
        (
            count
            for count in range(1, MAX_GRID_INTERVALS + 1)
            if np.all(np.abs(offsets * count - np.round(offsets * count)) <= _KNOT_TOLERANCE * count)
        ),
        MAX_GRID_INTERVALS,
    )
    while intervals < MIN_GRID_INTERVALS:
        intervals *= 2
    return start_n, span_n / intervals, intervals


def device_tables(device: Device, track: bool = False, band_hz: float = 0.0) -> tuple[np.ndarray, float, float]:
    """``(dev, start_n, step_n)``: the kernel's device tables on :func:`force_grid`'s grid.

    ``dev[DEV_CARRIER_HZ]`` the carrier driven at each force: the device's ``carrier_hz``, or
    with ``track`` the motional branch's loaded resonance there
    (:meth:`Device.motional_resonance_hz`). At that carrier: ``dev[DEV_AMP_M_PER_V]`` plate
    amplitude per peak volt (m/V), ``dev[DEV_POWER_W_PER_V2]`` the most power a drive of 1 V
    peak can draw (W, :meth:`Device.power_w_per_v2`: the exact circuit, detuning included),
    ``dev[DEV_TAU_S]`` the loaded envelope time constant (s); forces ``start_n + k * step_n``.
    ``dev[DEV_MODE_GAIN]`` is on a grid in x, not force: :func:`mode_gain_table` at ``x = k *
    mode_step_mm(device, dev)`` (1 without a mode shape). ``dev[DEV_REACTANCE_OHM]`` and
    ``dev[DEV_REACTANCE_SLOPE_OHM_PER_HZ]``: the motional branch's reactance at the carrier and
    its slope in frequency, for a serial amplifier's lock. With ``band_hz`` > 0 (an amplifier whose carrier may sit up to that far from
    the table's) the power per squared volt is the most over the carrier, and the carrier
    +- ``band_hz``.
    """
    start_n, step_n, intervals = force_grid(device)
    forces_n = start_n + step_n * np.arange(intervals + 1)
    carrier_hz = (np.asarray(device.motional_resonance_hz(forces_n), dtype=np.float64) if track
                  else np.full(len(forces_n), device.carrier_hz))
    dev = np.empty((layout.DEV_ROWS, intervals + 1))
    dev[layout.DEV_AMP_M_PER_V] = device.amplitude_m_per_v(forces_n, carrier_hz)
    dev[layout.DEV_POWER_W_PER_V2] = np.max([device.power_w_per_v2(forces_n, carrier_hz + shift_hz)
                                            for shift_hz in {0.0, -band_hz, band_hz}], axis=0)
    dev[layout.DEV_TAU_S] = device.envelope_time_constant_s(forces_n, carrier_hz)
    dev[layout.DEV_CARRIER_HZ] = carrier_hz
    dev[layout.DEV_MODE_GAIN] = mode_gain_table(device, np.arange(intervals + 1) * mode_step_mm(device, dev))
    dev[layout.DEV_REACTANCE_OHM] = device.motional_reactance_ohm(forces_n, carrier_hz)
    dev[layout.DEV_REACTANCE_SLOPE_OHM_PER_HZ] = device.motional_reactance_slope_ohm_per_hz(forces_n, carrier_hz)
    return dev, start_n, step_n


def gain_span(dev: np.ndarray) -> float:
    """The largest over the smallest plate amplitude per volt in ``dev``, in ``[1, layout.MAX_GAIN_SPAN]``: how many
    times its volts at the lightest-loaded force the amplitude a plate holds is worth at the heaviest (the plate
    model's bound)."""
    gains = dev[layout.DEV_AMP_M_PER_V]
    return float(min(gains.max() / gains.min(), layout.MAX_GAIN_SPAN))


def mode_step_mm(device: Device, dev: np.ndarray) -> float:
    """The x step (mm) of ``dev[DEV_MODE_GAIN]``'s grid: the plate's length over the table's intervals."""
    return device.plate.length_m * 1e3 / (dev.shape[1] - 1)


def mode_gain_table(device: Device, x_mm: npt.ArrayLike) -> np.ndarray:
    """:meth:`Device.mode_gain` at ``x_mm``, at least MODE_GAIN_FLOOR: what the command divides by.

    Raises ValueError for a non-finite position.
    """
    return np.maximum(device.mode_gain(x_mm), MODE_GAIN_FLOOR)


def _check_rate(device: Device, fs_hz: float, envelope_output: bool, highest_carrier_hz: float) -> None:
    """ConfigError unless ``fs_hz`` is a finite rate (Hz) in (0, MAX_RATE_HZ], and (for carrier samples,
    not ``envelope_output``) at least ``highest_carrier_hz / 0.45``."""
    problem = _number_problem(fs_hz, f"in (0, {MAX_RATE_HZ}]", lambda v: 0 < v <= MAX_RATE_HZ)
    if problem:
        raise ConfigError(f"fs_hz: {problem}")
    needed_hz = highest_carrier_hz / MAX_CARRIER_FRACTION
    if fs_hz < needed_hz and not envelope_output:
        raise ConfigError(
            f"fs_hz: device {device.label}'s carrier ({device.carrier_hz:g} Hz) needs a sample rate of at "
            f"least {math.ceil(needed_hz)} Hz (carrier <= {MAX_CARRIER_FRACTION} x fs), got {fs_hz:g}"
        )


def _writable(array: np.ndarray, dtype: type) -> np.ndarray:
    """A C-contiguous writable copy of ``array`` (the kernel is compiled for writable arrays)."""
    return np.array(array, dtype=dtype, order="C", copy=True)


class Pipeline:
    """One stream of drive samples for ``device`` rendering ``texture`` at ``fs_hz``; owns every array.

    The samples are the carrier (DAC samples), or with ``envelope_output`` its envelope,
    for an amplifier that makes the carrier itself; :attr:`drive` describes them (from the
    device file; :meth:`set_drive` replaces it with what the output's hardware reported). Created stopped (silent): :meth:`start` ramps
    the drive up once a finger slides. Raises ConfigError for a sample rate not in
    ``(0, MAX_RATE_HZ]``, or (carrier samples) below ``resonance_hz / 0.45``.
    """

    def __init__(
        self,
        device: Device,
        texture: CompiledTexture,
        fs_hz: float = 192000,
        options: RenderOptions = RenderOptions(),
        *,
        envelope_output: bool = False,
    ):
        band_hz = LOCK_RANGE * device.carrier_hz if options.track and envelope_output else 0.0
        dev, start_n, step_n = device_tables(device, options.track, band_hz)
        _check_rate(device, fs_hz, envelope_output, float(dev[layout.DEV_CARRIER_HZ].max()))
        self.envelope_output = envelope_output
        self._device_drive = DriveSpec.from_device(device, Consumes.ENVELOPE if envelope_output else Consumes.DAC,
                                                   fs_hz)
        self._drive = self._device_drive
        self.device = device
        self.options = options
        self.fs_hz = fs_hz
        self.sample_index = 0
        self._drained = 0
        self._producer = threading.Lock()  # push_finger may be called from several threads
        self._last_t_s = -math.inf  # the newest sample's time (s): finger times never decrease
        self.position_range_mm = position_range_mm(device.plate.length_m * 1e3, device.plate.width_m * 1e3)
        window_steps = max(1, round(options.power_window_s * fs_hz / options.control_interval))
        self._arrays = KernelArrays(
            cfg=self._config(start_n, step_n, window_steps, mode_step_mm(device, dev), gain_span(dev)),
            dev=dev,
            state=np.zeros(layout.STATE_SIZE),
            power_ring=np.zeros(window_steps),
            finger=np.zeros((options.finger_ring, layout.FINGER_COLS)),
            finger_count=np.zeros(1, dtype=np.int64),
            prog=np.zeros((0, layout.TEX_PROG_COLS), dtype=np.int64),
            params=np.zeros(0),
            img=np.zeros(0),
            stack=np.zeros(1),
            telem=np.zeros((options.telemetry_ring, layout.TEL_COLS)),
            telem_count=np.zeros(1, dtype=np.int64),
        )
        self.set_texture(texture, 0.0)

    def _config(self, grid_start_n: float, grid_step_n: float, window_steps: int, gain_step_mm: float,
                span: float) -> np.ndarray:
        """The ``cfg`` array (layout.CFG_*), RUN off; ``gain_step_mm`` the x step of the mode gain table, ``span``
        the dev tables' :func:`gain_span`."""
        device, options = self.device, self.options
        cap_w = device.power_budget_w if options.power_budget_w is None else options.power_budget_w
        preemphasis = device.preemphasis if options.preemphasis is None else options.preemphasis
        cfg = np.zeros(layout.CFG_SIZE)
        for index, value in {
            layout.CFG_FS_HZ: self.fs_hz,
            layout.CFG_CARRIER_HZ: self._drive.carrier_hz,
            layout.CFG_VOLTS_PER_FS: self._drive.volts_per_full_scale,
            layout.CFG_MAX_VOLTAGE_V: self._drive.max_voltage_v,
            layout.CFG_POWER_CAP_W: cap_w,
            layout.CFG_POWER_AVG_W: cap_w if options.power_avg_w is None else options.power_avg_w,
            layout.CFG_WINDOW_STEPS: window_steps,
            layout.CFG_SPEED_FLOOR_M_S: device.speed_floor_m_s,
            layout.CFG_MU0: device.mu0,
            layout.CFG_POISSON: device.poisson,
            layout.CFG_PSI_STAR: device.psi_star,
            layout.CFG_MU_FLOOR: options.mu_floor,
            layout.CFG_CONTROL_INTERVAL: options.control_interval,
            layout.CFG_SMOOTHING_S: options.smoothing_ms * 1e-3,
            layout.CFG_PREEMPHASIS: 1.0 if preemphasis else 0.0,
            layout.CFG_HORIZON_S: options.horizon_ms * 1e-3,
            layout.CFG_VELOCITY_WINDOW_S: options.velocity_window_ms * 1e-3,
            layout.CFG_WATCHDOG_S: options.watchdog_ms * 1e-3,
            layout.CFG_RAMP_S: options.ramp_ms * 1e-3,
            layout.CFG_DEFAULT_FORCE_N: options.default_force_n,
            layout.CFG_FORCE_GRID_START_N: grid_start_n,
            layout.CFG_FORCE_GRID_STEP_N: grid_step_n,
            layout.CFG_OUTPUT_ENVELOPE: 1.0 if self.envelope_output else 0.0,
            layout.CFG_BRAKING: 1.0 if options.braking else 0.0,
            layout.CFG_TRACK: 1.0 if options.track else 0.0,
            layout.CFG_MODE_STEP_MM: (gain_step_mm if options.mode_compensation and device.contact_width_m is not None
                                      else 0.0),
            layout.CFG_C0_F: device.c0_f,
            layout.CFG_SHUNT_OHM: device.shunt_ohm,
            layout.CFG_GAIN_SPAN: span,
        }.items():
            cfg[index] = value
        return cfg

    @property
    def arrays(self) -> KernelArrays:
        """Every array ``render_block`` takes after ``(out, start_index)``, in its order."""
        return self._arrays

    @property
    def texture(self) -> CompiledTexture:
        """The texture being rendered."""
        return self._texture

    @property
    def time_s(self) -> float:
        """Stream time (s) of the next sample :meth:`render` produces."""
        return self.sample_index / self.fs_hz

    @property
    def running(self) -> bool:
        """True between :meth:`start` and :meth:`stop`."""
        return self._arrays.cfg[layout.CFG_RUN] != 0.0

    @property
    def drive(self) -> DriveSpec:
        """The drive the kernel renders for (carrier, full scale, clamp, rate)."""
        return self._drive

    @property
    def device_drive(self) -> DriveSpec:
        """The drive the device file describes, at this pipeline's rate: what an output's hardware report
        replaces (:meth:`DriveSpec.from_hardware`)."""
        return self._device_drive

    def set_drive(self, drive: DriveSpec) -> None:
        """Render for ``drive`` from now on: the drive the output's hardware reported at start (its full scale,
        clamp and carrier). Raises ConfigError for a drive of another kind or rate, or a clamp above the
        device's maximum, or a carrier the rate cannot make (DAC samples); RuntimeError while running."""
        if self.running:
            raise RuntimeError("Pipeline.set_drive: stop the pipeline first")
        if not isinstance(drive, DriveSpec):
            raise ConfigError(f"drive: must be a DriveSpec, got {type(drive).__name__}")
        if drive.consumes is not self._drive.consumes or drive.rate_hz != self._drive.rate_hz:
            raise ConfigError(f"drive: it is {drive.consumes.value} at {drive.rate_hz:g} Hz, but the pipeline renders "
                              f"{self._drive.consumes.value} at {self._drive.rate_hz:g} Hz")
        if drive.max_voltage_v > self.device.max_voltage_v:
            raise ConfigError(f"drive: max_voltage_v: {drive.max_voltage_v:g} V is above the device's "
                              f"{self.device.max_voltage_v:g} V")
        _check_rate(self.device, self.fs_hz, self.envelope_output, drive.carrier_hz)
        cfg = self._arrays.cfg
        cfg[layout.CFG_VOLTS_PER_FS] = drive.volts_per_full_scale
        cfg[layout.CFG_MAX_VOLTAGE_V] = drive.max_voltage_v
        cfg[layout.CFG_CARRIER_HZ] = drive.carrier_hz
        self._drive = drive

    def start(self) -> None:
        """Let the drive ramp up (from the next control step) while a finger slides."""
        self._arrays.cfg[layout.CFG_RUN] = 1.0

    def stop(self) -> None:
        """Ramp the drive down to 0 (from the next control step) and keep it silent."""
        self._arrays.cfg[layout.CFG_RUN] = 0.0

    @property
    def stream_time_s(self) -> float:
        """Stream time (s) of the next sample the kernel renders, whoever calls it (this pipeline's
        :meth:`render`, or a real-time callback on its arrays)."""
        return float(self._arrays.state[layout.STATE_NEXT_INDEX]) / self.fs_hz

    def check_time(self, t_s: float, name: str = "t_s") -> float:
        """``t_s`` as a float if it is a finite time (s) within FINGER_TIME_WINDOW_S of :attr:`stream_time_s`;
        SampleError naming ``name``, the accepted range and the value otherwise."""
        now_s = self.stream_time_s
        low, high = now_s - FINGER_TIME_WINDOW_S, now_s + FINGER_TIME_WINDOW_S
        return _checked(name, t_s, low, high, f"s (within {FINGER_TIME_WINDOW_S:g} s of the stream clock, now {now_s:.3f} s)")

    def _checked_sample(
        self, t_s: float, x_mm: float, y_mm: float, force_n: float | None
    ) -> tuple[float, float, float, float]:
        """``(t_s, x_mm, y_mm, force_n)`` as floats (force NaN when None), each checked; SampleError otherwise."""
        (x_low, x_high), (y_low, y_high) = self.position_range_mm
        plate = f"mm (one plate length beyond each edge of the {x_high / 2:g} x {y_high / 2:g} mm plate)"
        return (
            self.check_time(t_s),
            _checked("x_mm", x_mm, x_low, x_high, plate),
            _checked("y_mm", y_mm, y_low, y_high, plate.replace("length", "width")),
            math.nan if force_n is None else _checked("force_n", force_n, 0.0, MAX_FORCE_N, "N (None: the default force)"),
        )

    def push_finger(
        self, t_s: float, x_mm: float, y_mm: float, force_n: float | None = None, down: bool = True
    ) -> None:
        """Append a finger sample: stream time (s), plate position (mm), contact force (N; None: the
        default), touching or not.

        Raises SampleError (a ValueError) naming the argument and its range for a value that is
        not a finite number, a time further than FINGER_TIME_WINDOW_S from :attr:`stream_time_s`
        or before the previous sample's, a position beyond :attr:`position_range_mm` (one plate
        length or width past each edge), a force outside ``[0, MAX_FORCE_N]``. Safe from several
        threads (a lock orders them); writes the ring row, then bumps the count the kernel reads
        with a release store (:func:`tpad_rt.aot.library.publish`).
        """
        row = (*self._checked_sample(t_s, x_mm, y_mm, force_n), 1.0 if down else 0.0)
        with self._producer:
            self._append(row)

    def lift(self, t_s: float) -> None:
        """The finger leaves the plate at stream time ``t_s`` (s), where it last was: the drive ramps to 0.
        Raises SampleError as :meth:`push_finger` for a bad time."""
        time_s = self.check_time(t_s)
        with self._producer:  # the position and the row under one lock: no other producer in between
            self._append((time_s, *self.last_position_mm(), math.nan, 0.0))

    @property
    def last_time_s(self) -> float:
        """Stream time (s) of the newest finger sample pushed (``-inf`` before the first)."""
        return self._last_t_s

    def _append(self, row: tuple[float, float, float, float, float]) -> None:
        """Write a checked ``row`` into the ring, then bump the count (release store); the producer lock held.
        SampleError if its time is before the previous sample's."""
        if row[0] < self._last_t_s:
            raise SampleError(f"t_s: must be >= the previous sample's time {self._last_t_s:.6f} s "
                              f"(finger times never decrease), got {row[0]:.6f}")
        self._last_t_s = row[0]
        finger, count = self._arrays.finger, self._arrays.finger_count
        finger[count[0] % finger.shape[0]] = row
        publish(count, 0, int(count[0]) + 1)  # after the row: a release store

    def last_position_mm(self) -> tuple[float, float]:
        """The plate position (mm) of the newest finger sample, ``(0, 0)`` before the first."""
        finger, count = self._arrays.finger, self._arrays.finger_count
        last = finger[(count[0] - 1) % finger.shape[0]]
        return float(last[layout.FINGER_X_MM]), float(last[layout.FINGER_Y_MM])

    def recent_fingers(self) -> np.ndarray:
        """The newest finger samples pushed (at most ``finger_ring - 2``), oldest first, as
        :data:`tpad_rt.inputs.base.FINGER_DTYPE`.

        Read without a lock while a producer may push: the ring's oldest row is left out.
        """
        return self.fingers_since(0)[0]

    def fingers_since(self, first: int) -> tuple[np.ndarray, int]:
        """The finger samples from number ``first`` (0: the first ever pushed) on that the ring still holds (at most
        ``finger_ring - 2``, oldest first, as :data:`tpad_rt.inputs.base.FINGER_DTYPE`), and the number after the
        last of them (the count they were read at). Read without a lock, as :meth:`recent_fingers`."""
        count = int(self._arrays.finger_count[0])
        ring = self._arrays.finger
        rows = ring[np.arange(max(first, count - len(ring) + 2), count) % len(ring)]
        samples = np.zeros(len(rows), dtype=FINGER_DTYPE)
        for name, column in (("t_s", layout.FINGER_T_S), ("x_mm", layout.FINGER_X_MM), ("y_mm", layout.FINGER_Y_MM),
                             ("force_n", layout.FINGER_FORCE_N)):
            samples[name] = rows[:, column]
        samples["down"] = rows[:, layout.FINGER_DOWN] > 0.5
        return samples, count

    @property
    def over_cap_blocks(self) -> int:
        """Rendered blocks in which the plate held more than the power cap as the model has it (telemetry
        ``plate_w``): a press takes the vibration the plate holds into a finger that damps more, and the kernel
        brakes it back (docs/kernel.md "A harder press")."""
        count = self._arrays.state[layout.STATE_OVER_CAP_BLOCKS]
        return int(count) if 0.0 <= count < 2**62 else 0

    def faults(self) -> dict[str, object]:
        """The kernel's fault counters (docs/kernel.md "Faults"): ``faults`` (faults that began),
        ``fault_steps`` (control steps), ``fault_samples`` (samples the output guard zeroed) and
        ``fault_causes`` (names of every FAULT_* cause met, in layout.FAULT_NAMES order)."""
        state = np.nan_to_num(self._arrays.state[[layout.STATE_FAULT_CAUSES, layout.STATE_FAULT_EVENTS,
                                                  layout.STATE_FAULT_STEPS, layout.STATE_FAULT_SAMPLES]],
                              nan=0.0, posinf=2**62, neginf=0.0).clip(0, 2**62).astype(np.int64)  # never raises
        causes, events, steps, samples = (int(value) for value in state)
        return {
            "faults": events,
            "fault_steps": steps,
            "fault_samples": samples,
            "fault_causes": [name for bit, name in enumerate(layout.FAULT_NAMES) if causes & (1 << bit)],
        }

    def set_texture(self, texture: CompiledTexture, t_s: float | None = None) -> None:
        """Render ``texture`` from the next block; temporal textures start at ``t_s`` (s; None: now).

        The carrier is unaffected (its phase follows the sample index). Raises SampleError for a
        ``t_s`` as :meth:`check_time` refuses it.
        """
        t0_s = self.stream_time_s if t_s is None else self.check_time(t_s)
        self._texture = texture
        self._arrays = self._arrays._replace(
            prog=_writable(texture.prog, np.int64),
            params=_writable(texture.params, np.float64),
            img=_writable(texture.img, np.float64),
            stack=np.zeros(max(texture.stack_depth, 1)),
        )
        self._arrays.cfg[layout.CFG_TEXTURE_T0_S] = t0_s

    def render(self, out: np.ndarray) -> None:
        """Fill ``out`` with the next ``len(out)`` drive samples (float32, 1.0 = ``volts_per_full_scale``).

        Raises TypeError unless ``out`` is a writable C-contiguous 1-D float32 array,
        ValueError unless it holds 1 to 65536 samples.
        """
        if not (
            isinstance(out, np.ndarray) and out.dtype == np.float32 and out.ndim == 1
            and out.flags.c_contiguous and out.flags.writeable
        ):
            raise TypeError("out: must be a writable C-contiguous 1-D float32 NumPy array")
        if not 1 <= out.size <= MAX_BLOCK_FRAMES:
            raise ValueError(f"out: must hold 1 to {MAX_BLOCK_FRAMES} samples, got {out.size}")
        from tpad_rt.kernel.render import render_block  # numba: imported by what renders here, not at import

        render_block(out, self.sample_index, *self._arrays)
        self.sample_index += out.size

    def finger_rows_pass(self, rows: np.ndarray, due: np.ndarray, block_frames: int) -> bool:
        """Whether :meth:`push_finger` would take every finger sample of ``rows`` when
        :meth:`render_blocks` pushes them (the same rules, checked at once).

        ``rows``: float64 ``[N, FINGER_COLS]`` (force NaN: the default); sample ``i`` is pushed
        before block ``k``, the first with ``i < due[k]``, when the stream clock stands at that
        block's first sample.
        """
        rows = rows[:int(due[-1])] if len(due) else rows[:0]  # the samples pushed
        if len(rows) == 0:
            return True
        t_s = rows[:, layout.FINGER_T_S]
        block = np.searchsorted(due, np.arange(len(rows)), side="right")
        now_s = (self._arrays.state[layout.STATE_NEXT_INDEX] + block * block_frames) / self.fs_hz
        (x_low, x_high), (y_low, y_high) = self.position_range_mm
        x_mm, y_mm = rows[:, layout.FINGER_X_MM], rows[:, layout.FINGER_Y_MM]
        force_n, down = rows[:, layout.FINGER_FORCE_N], rows[:, layout.FINGER_DOWN]
        with np.errstate(invalid="ignore"):
            fine = ((now_s - FINGER_TIME_WINDOW_S <= t_s) & (t_s <= now_s + FINGER_TIME_WINDOW_S)
                    & (x_low <= x_mm) & (x_mm <= x_high) & (y_low <= y_mm) & (y_mm <= y_high)
                    & (np.isnan(force_n) | ((0.0 <= force_n) & (force_n <= MAX_FORCE_N)))
                    & ((down == 0.0) | (down == 1.0)))
        ordered = bool(t_s[0] >= self._last_t_s) and bool(np.all(np.diff(t_s) >= 0.0))
        return bool(fine.all()) and ordered

    def render_blocks(self, out: np.ndarray, block_frames: int, rows: np.ndarray, due: np.ndarray) -> None:
        """Render ``len(due)`` blocks of ``block_frames`` samples into ``out``, pushing ``rows[due[k - 1]:due[k]]``
        before block ``k``: :meth:`push_finger` and :meth:`render` block by block, in one native call.

        ``rows``: float64 ``[N, FINGER_COLS]`` finger samples ``(t_s, x_mm, y_mm, force_n or NaN,
        down 1.0/0.0)``; ``due``: int64, non-decreasing, each in ``[0, N]``. Raises ValueError
        when the shapes do not fit, SampleError (a ValueError; nothing rendered) unless
        :meth:`finger_rows_pass` holds (push them one by one to learn which sample is bad),
        TypeError for an ``out`` :meth:`render` refuses.
        """
        frames = len(due) * block_frames
        if not (isinstance(out, np.ndarray) and out.dtype == np.float32 and out.ndim == 1
                and out.flags.c_contiguous and out.flags.writeable):
            raise TypeError("out: must be a writable C-contiguous 1-D float32 NumPy array")
        rows = np.ascontiguousarray(rows, dtype=np.float64)
        due = np.ascontiguousarray(due, dtype=np.int64)
        if not (1 <= block_frames <= MAX_BLOCK_FRAMES and out.size >= frames and rows.ndim == 2
                and rows.shape[1] == layout.FINGER_COLS and due.ndim == 1
                and (len(due) == 0 or (due[0] >= 0 and due[-1] <= len(rows) and bool(np.all(np.diff(due) >= 0))))):
            raise ValueError("render_blocks: out, rows or due do not fit (module docstring)")
        with self._producer:
            if not self.finger_rows_pass(rows, due, block_frames):
                raise SampleError("render_blocks: a finger sample push_finger refuses; push them one by one to "
                                  "learn which")
            from tpad_rt.kernel.batch import render_blocks  # numba: imported by what renders here

            render_blocks(out, block_frames, self.sample_index, rows, due, *self._arrays)
            if len(rows) and len(due) and due[-1] > 0:
                self._last_t_s = float(rows[int(due[-1]) - 1, layout.FINGER_T_S])
        self.sample_index += frames

    def last_telemetry_row(self) -> dict[str, float]:
        """The newest telemetry row (the last rendered block's), by ``layout.TEL_NAMES``; not drained."""
        telem, count = self._arrays.telem, self._arrays.telem_count
        return dict(zip(layout.TEL_NAMES, telem[(count[0] - 1) % telem.shape[0]].tolist()))

    def drain_telemetry(self) -> dict[str, np.ndarray]:
        """The telemetry rows written since the last drain, one array per ``layout.TEL_NAMES`` column.

        ``saturated`` holds the FLAG_* bits as int64; the others are float64. Raises
        TpadError if more rows were written than the ring holds (they are lost; the
        next drain starts afresh): drain more often or raise ``telemetry_ring``.
        """
        telem, count = self._arrays.telem, self._arrays.telem_count
        first, end = self._drained, int(count[0])
        rows = telem[np.arange(first, end) % telem.shape[0]]
        written = int(count[0]) - first  # re-read: rows copied while the kernel wrote must not be overwritten
        if written > telem.shape[0]:
            self._drained = int(count[0])
            raise TpadError(
                f"telemetry ring overflowed: {written} rows since the last drain, it holds {telem.shape[0]}; "
                "drain more often or raise RenderOptions.telemetry_ring"
            )
        self._drained = end
        drained = {name: rows[:, column].copy() for column, name in enumerate(layout.TEL_NAMES)}
        drained[layout.TEL_NAMES[layout.TEL_FLAGS]] = rows[:, layout.TEL_FLAGS].astype(np.int64)
        return drained

    def warm_up(self, batch: bool = False) -> None:
        """Compile (or load from cache) and run the kernel once on copies of the arrays; with ``batch``,
        :meth:`render_blocks`' kernel too (the offline render's).

        The pipeline's own state is untouched; the first real :meth:`render` is then fast.
        """
        from tpad_rt.kernel.batch import render_blocks
        from tpad_rt.kernel.render import render_block

        frames = self.options.control_interval + 1
        scratch = KernelArrays(*(array.copy() for array in self._arrays))
        render_block(np.zeros(frames, dtype=np.float32), self.sample_index, *scratch)
        if batch:
            scratch = KernelArrays(*(array.copy() for array in self._arrays))
            render_blocks(np.zeros(frames, dtype=np.float32), frames, self.sample_index,
                          np.zeros((0, layout.FINGER_COLS)), np.zeros(1, dtype=np.int64), *scratch)
