"""One TPaD's model in SI units: carrier, circuit, transduction factor and limits.

A :class:`Device` is built from a device file (docs/formats.md "Device files") by
:meth:`Device.from_file`, from an already validated :class:`tpad_rt.config.DeviceFile`
by :meth:`Device.from_spec`, or from the shipped ``devices/default.yaml`` by
:meth:`Device.default`.

One model: the Butterworth-Van Dyke circuit (C0, shunt R0, and L, C, R against
contact force, interpolated linearly and clamped at the table ends) with one
transduction factor ``gamma`` (``i_g = gamma dX/dt``). Amplitude per volt, power per
squared volt, the envelope's time constant and the motional resonance all follow from
it at the carrier driven (:mod:`tpad_rt.physics.electromech`); these are what the
real-time kernel tabulates. :meth:`Device.plate_amplitude_m` runs a drive envelope
through the first-order envelope model the kernel's shaper assumes.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from tpad_rt import shipped
from tpad_rt.config import DeviceFile, load_device
from tpad_rt.config.breadcrumb import breadcrumb
from tpad_rt.config.device_schema import MIN_Q
from tpad_rt.errors import ConfigError
from tpad_rt.kernel import layout
from tpad_rt.physics import electromech, mode_shape
from tpad_rt.physics._validate import ComplexOrArray, FloatOrArray, checked, finite, non_negative

#: Positions over the plate at which :meth:`Device.mode_gain` is evaluated once and then interpolated
#: (0.0065 mm apart on a 130 mm plate: within 5e-7 of the exact patch mean, 1e-4 where the patch's edge
#: meets the plate's end and the mean has a kink).
MODE_GAIN_POINTS = 20_001
#: Forces spread evenly over the tables at which :meth:`Device.derived_problems` checks (besides the knots).
DERIVED_CHECK_POINTS = 4097
#: The loaded motional resonance must lie within this factor of the carrier at every force: a TPaD is driven
#: near its resonance (the shipped plates: within 0.13 %), and the simulated plate resonates there.
RESONANCE_CARRIER_FACTOR = layout.TRACKED_CARRIER_FACTOR

_Table = npt.NDArray[np.float64]
_TABLE_FIELDS = (
    "force_table_n",
    "motional_l_h_table",
    "motional_c_f_table",
    "motional_r_ohm_table",
)


@dataclass(frozen=True)
class Plate:
    """The glass plate (SI) and its ``(m, n)`` mode."""

    material: str
    thickness_m: float
    density_kg_m3: float
    youngs_pa: float
    length_m: float
    width_m: float
    mode: tuple[int, int]


@dataclass(frozen=True)
class Actuator:
    """The piezo actuator bonded to the plate (SI)."""

    thickness_m: float
    density_kg_m3: float
    youngs_pa: float


@dataclass(frozen=True, eq=False)
class Device:
    """A TPaD's model, SI units; the ``*_table`` fields are read-only float64 arrays indexed by ``force_table_n``.

    ``carrier_hz`` is the frequency the runtime drives at; ``gamma_n_per_v`` the
    transduction factor (N/V, the same as C/m); ``contact_width_m`` the finger's contact
    patch along the plate when the device models the plate's standing wave (the file's
    ``mode_shape``), else None: the antinode amplitude everywhere.
    """

    label: str
    description: str
    plate: Plate
    actuator: Actuator
    carrier_hz: float
    volts_per_full_scale: float
    max_voltage_v: float
    c0_f: float
    shunt_ohm: float
    gamma_n_per_v: float
    force_table_n: _Table
    motional_l_h_table: _Table
    motional_c_f_table: _Table
    motional_r_ohm_table: _Table
    mu0: float
    poisson: float
    psi_star: float
    speed_floor_m_s: float
    power_budget_w: float
    preemphasis: bool
    contact_width_m: float | None = None

    def __post_init__(self) -> None:
        for name in _TABLE_FIELDS:
            table = np.array(getattr(self, name), dtype=np.float64)
            table.setflags(write=False)
            object.__setattr__(self, name, table)

    @classmethod
    def from_spec(cls, spec: DeviceFile, path: str | Path | None = None) -> Device:
        """The Device described by a validated device file model (file units converted to SI).

        Raises ConfigError (each line naming ``path``, the file, when given) if a table the
        kernel is built from is not finite and > 0 at some force (:meth:`derived_problems`).
        """
        plate, actuator, circuit = spec.plate, spec.actuator, spec.circuit
        device = cls(
            label=spec.label,
            description=spec.description,
            plate=Plate(
                material=plate.material,
                thickness_m=plate.thickness_mm * 1e-3,
                density_kg_m3=plate.density_g_cm3 * 1e3,
                youngs_pa=plate.youngs_modulus_gpa * 1e9,
                length_m=plate.length_mm * 1e-3,
                width_m=plate.width_mm * 1e-3,
                mode=(plate.mode[0], plate.mode[1]),
            ),
            actuator=Actuator(
                thickness_m=actuator.thickness_mm * 1e-3,
                density_kg_m3=actuator.density_g_cm3 * 1e3,
                youngs_pa=actuator.youngs_modulus_gpa * 1e9,
            ),
            carrier_hz=spec.carrier_hz,
            volts_per_full_scale=spec.amplifier.volts_per_full_scale,
            max_voltage_v=spec.amplifier.max_voltage_v,
            c0_f=circuit.c0_nf * 1e-9,
            shunt_ohm=circuit.shunt_ohm,
            gamma_n_per_v=circuit.gamma_n_per_v,
            force_table_n=np.asarray(circuit.force_n, dtype=np.float64),
            motional_l_h_table=np.asarray(circuit.motional_l_h, dtype=np.float64),
            motional_c_f_table=np.multiply(circuit.motional_c_pf, 1e-12),
            motional_r_ohm_table=np.asarray(circuit.motional_r_ohm, dtype=np.float64),
            mu0=spec.friction_model.mu0,
            poisson=spec.friction_model.poisson,
            psi_star=spec.friction_model.psi_star,
            speed_floor_m_s=spec.speed_floor_mm_s * 1e-3,
            power_budget_w=spec.power_budget_w,
            preemphasis=spec.preemphasis,
            contact_width_m=None if spec.mode_shape is None else spec.mode_shape.contact_width_mm * 1e-3,
        )
        problems = device.derived_problems()
        if problems:
            raise ConfigError([breadcrumb(None if path is None else str(path), (), problem) for problem in problems])
        return device

    @classmethod
    def from_file(cls, path: str | Path) -> Device:
        """The Device in the device file at ``path``; ConfigError listing every problem in it."""
        return cls.from_spec(load_device(path), path)

    @classmethod
    def default(cls) -> Device:
        """The default device, the package's ``devices/default.yaml`` (SLG_0.56); ConfigError if it is missing
        (a broken installation)."""
        path = shipped.DEFAULT_DEVICE
        if not path.is_file():
            raise ConfigError(f"{path}: the default device file is missing from the installed package "
                              "(reinstall tpad-rt); pass a device file instead")
        return cls.from_file(path)

    def mode_deflection(self, x_mm: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The plate's standing wave at ``x_mm`` (mm along its length, clamped to the plate), in units of the
        antinode amplitude (:func:`tpad_rt.physics.mode_shape.deflection`).

        Raises ValueError for a non-finite position or a plate mode with fewer than two nodal lines.
        """
        return mode_shape.deflection(x_mm, self.plate.length_m * 1e3, self.plate.mode[0])

    def mode_gain(self, x_mm: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The vibration amplitude a finger centred at ``x_mm`` (mm along the plate) feels, over the antinode
        amplitude: the mean ``|mode_deflection|`` over its contact patch, or 1 without a mode shape.

        Raises ValueError for a non-finite position.
        """
        x = mode_shape.positions(x_mm, self.plate.length_m * 1e3)
        if self.contact_width_m is None:
            return np.ones_like(x)
        grid_mm, gains = self._mode_gain_table
        return np.interp(x, grid_mm, gains)

    @functools.cached_property
    def _mode_gain_table(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """:meth:`mode_gain` on MODE_GAIN_POINTS positions over the plate, evaluated once (it integrates the
        shape on a fine grid), interpolated linearly between them after."""
        length_mm = self.plate.length_m * 1e3
        grid_mm = np.linspace(0.0, length_mm, MODE_GAIN_POINTS)
        width_mm = 0.0 if self.contact_width_m is None else self.contact_width_m * 1e3
        return grid_mm, mode_shape.patch_mean(grid_mm, length_mm, self.plate.mode[0], width_mm)

    def motional(self, force_n: npt.ArrayLike) -> tuple[FloatOrArray, FloatOrArray, FloatOrArray]:
        """Motional branch ``(L in H, C in F, R in ohm)`` at contact force ``force_n`` (N, >= 0)."""
        forces = non_negative("force_n", force_n)
        return tuple(  # type: ignore[return-value]
            np.interp(forces, self.force_table_n, table)
            for table in (self.motional_l_h_table, self.motional_c_f_table, self.motional_r_ohm_table)
        )

    def _driven(self, freq_hz: npt.ArrayLike | None) -> npt.ArrayLike:
        """``freq_hz``, or the carrier when None: the frequency a method evaluates the circuit at."""
        return self.carrier_hz if freq_hz is None else freq_hz

    def motional_current_a_per_v(self, force_n: npt.ArrayLike, freq_hz: npt.ArrayLike | None = None) -> ComplexOrArray:
        """Steady complex motional current (A peak) per peak drive volt at ``freq_hz`` (Hz, default: the carrier;
        an array broadcasts against ``force_n``)."""
        l_h, c_f, r_ohm = self.motional(force_n)
        freq = self._driven(freq_hz)
        return electromech.motional_current(1.0, freq, self.c0_f, l_h, c_f, r_ohm, self.shunt_ohm)

    def motional_reactance_ohm(self, force_n: npt.ArrayLike, freq_hz: npt.ArrayLike | None = None) -> FloatOrArray:
        """The motional branch's reactance ``w L - 1 / (w C)`` (ohm) at contact force ``force_n`` (N, >= 0) and
        ``freq_hz`` (Hz, default: the carrier): what a serial amplifier's phase lock compares with the one its
        measured voltage, current and phase imply."""
        l_h, c_f, _ = self.motional(force_n)
        omega = 2.0 * np.pi * np.asarray(self._driven(freq_hz), dtype=np.float64)
        return omega * l_h - 1.0 / (omega * c_f)

    def motional_reactance_slope_ohm_per_hz(self, force_n: npt.ArrayLike,
                                            freq_hz: npt.ArrayLike | None = None) -> FloatOrArray:
        """d/df of :meth:`motional_reactance_ohm` (ohm/Hz): ``2 pi (L + 1 / (w^2 C))``."""
        l_h, c_f, _ = self.motional(force_n)
        omega = 2.0 * np.pi * np.asarray(self._driven(freq_hz), dtype=np.float64)
        return 2.0 * np.pi * (l_h + 1.0 / (omega * omega * c_f))

    def amplitude_m_per_v(self, force_n: npt.ArrayLike, freq_hz: npt.ArrayLike | None = None) -> FloatOrArray:
        """Steady plate vibration amplitude (m) per peak drive volt at contact force ``force_n`` (N, >= 0).

        ``|I_g| / (gamma omega)`` at ``freq_hz`` (default: the carrier), the exact circuit,
        detuning included.
        """
        l_h, c_f, r_ohm = self.motional(force_n)
        freq = self._driven(freq_hz)
        return electromech.plate_amplitude_m(1.0, freq, self.c0_f, l_h, c_f, r_ohm, self.shunt_ohm, self.gamma_n_per_v)

    def steady_power_w_per_v2(self, force_n: npt.ArrayLike, freq_hz: npt.ArrayLike | None = None) -> FloatOrArray:
        """Steady real power (W) into the motional branch per squared peak drive volt, ``|I_g|^2 R / 2``.

        At ``freq_hz`` (default: the carrier), through the shunt and C0 (paper Eqs. 2-6,
        solved exactly). Multiply by ``V**2`` for a peak drive of ``V`` volts.
        """
        r_ohm = self.motional(force_n)[2]
        power: FloatOrArray = np.abs(self.motional_current_a_per_v(force_n, freq_hz)) ** 2 * r_ohm / 2.0
        return power

    def detuning_factor(self, force_n: npt.ArrayLike, freq_hz: npt.ArrayLike | None = None) -> FloatOrArray:
        """How far a transient's motional power can exceed the steady power at ``freq_hz`` (default: the carrier;
        >= 1).

        :func:`tpad_rt.physics.electromech.detuning_factor`: 1 where the drive sits on the
        loaded resonance, ``1 + (detuning x tau)^2`` off it.
        """
        l_h, c_f, r_ohm = self.motional(force_n)
        freq = self._driven(freq_hz)
        return electromech.detuning_factor(freq, self.c0_f, l_h, c_f, r_ohm, self.shunt_ohm)

    def power_w_per_v2(self, force_n: npt.ArrayLike, freq_hz: npt.ArrayLike | None = None) -> FloatOrArray:
        """The most real power (W) per squared peak drive volt that a drive at ``freq_hz`` (default: the carrier)
        can draw.

        :meth:`steady_power_w_per_v2` times :meth:`detuning_factor`: a drive whose envelope
        stays within ``V`` volts never draws more than ``V**2`` times this, through any
        transient. It is what the kernel's power caps and its power telemetry use (equal to
        the steady power where the carrier is on the motional resonance).
        """
        bound: FloatOrArray = self.steady_power_w_per_v2(force_n, freq_hz) * self.detuning_factor(force_n, freq_hz)
        return bound

    def quality_factor(self, force_n: npt.ArrayLike) -> FloatOrArray:
        """Unloaded quality factor ``sqrt(L / C) / R`` of the motional branch at contact force ``force_n``."""
        return electromech.quality_factor(*self.motional(force_n))

    def envelope_time_constant_s(self, force_n: npt.ArrayLike, freq_hz: npt.ArrayLike | None = None) -> FloatOrArray:
        """Time constant (s) of the vibration envelope: ``2 L / (R + Re Z_th)``, the branch loaded by the
        shunt and C0 at ``freq_hz`` (default: the carrier;
        :func:`tpad_rt.physics.electromech.loaded_time_constant_s`)."""
        l_h, _, r_ohm = self.motional(force_n)
        freq = self._driven(freq_hz)
        return electromech.loaded_time_constant_s(freq, self.c0_f, l_h, r_ohm, self.shunt_ohm)

    def motional_resonance_hz(self, force_n: npt.ArrayLike) -> FloatOrArray:
        """Resonance (Hz) of the motional branch loaded by the shunt and C0 at contact force ``force_n``: the
        frequency a drive should follow to stay on resonance (``--track``)."""
        l_h, c_f, _ = self.motional(force_n)
        return electromech.loaded_resonance_hz(self.c0_f, l_h, c_f, self.shunt_ohm)

    def loaded_quality_factor(self, force_n: npt.ArrayLike) -> FloatOrArray:
        """Quality factor of the loaded branch, ``pi f_r tau``, with ``f_r`` :meth:`motional_resonance_hz` and
        ``tau`` :meth:`envelope_time_constant_s`: the resonator the simulated plate is."""
        q: FloatOrArray = math.pi * self.motional_resonance_hz(force_n) * self.envelope_time_constant_s(force_n)
        return q

    def plate_amplitude_m(
        self, drive_v: npt.ArrayLike, rate_hz: float, force_n: float, initial_m: float = 0.0
    ) -> npt.NDArray[np.float64]:
        """Plate vibration amplitude (m) that the drive envelope ``drive_v`` gives: the calibrated amplitude model.

        The model the kernel's pre-emphasis assumes (docs/kernel.md "Per sample"): at
        contact force ``force_n`` the plate's envelope ``p`` follows the drive envelope
        ``u`` (peak volts at the carrier) as ``tau dp/dt = G u - p``, with
        ``G = amplitude_m_per_v(force_n)`` and ``tau = envelope_time_constant_s(force_n)``.
        So the steady amplitude is ``G u``, and a pre-emphasised drive, which overshoots at
        every change, maps back to the level it was shaped for. Sample ``k`` of
        ``drive_v`` is held for ``1 / rate_hz`` s (zero-order hold, as an amplifier
        applies its envelope samples; docs/amplifiers.md); element ``k`` of the result is
        the amplitude at the end of that hold (exact discretisation,
        ``p_k = b p_(k-1) + (1 - b) G u_k``, ``b = exp(-1 / (rate_hz tau))``), starting
        from ``initial_m`` (m; 0: the plate at rest). A negative drive is the carrier in
        anti-phase: the result is signed the same way, and the vibration amplitude a
        finger feels is its magnitude (the input of
        :func:`tpad_rt.physics.friction.relative_friction`).

        ``drive_v`` (V) is one-dimensional, every value finite; ``rate_hz`` (Hz) finite
        and > 0; ``force_n`` (N) a finite scalar >= 0 (one force for the whole span: the
        model is time-invariant only at a fixed force); ``initial_m`` finite. Raises
        ValueError, naming the argument, otherwise.
        """
        drive = finite("drive_v", drive_v)
        if drive.ndim != 1:
            raise ValueError(f"drive_v must be one-dimensional, got shape {drive.shape}")
        for name, value in (("rate_hz", rate_hz), ("force_n", force_n), ("initial_m", initial_m)):
            if np.ndim(value) != 0:
                raise ValueError(f"{name} must be a scalar, got shape {np.shape(value)}")
        rate = float(checked("rate_hz", finite("rate_hz", rate_hz), 0.0))
        force = float(non_negative("force_n", finite("force_n", force_n)))
        initial = float(finite("initial_m", initial_m))
        gain_m_per_v = float(self.amplitude_m_per_v(force))
        step = 1.0 / (rate * float(self.envelope_time_constant_s(force)))  # one sample, in time constants
        decay = math.exp(-step)
        if drive.size == 0:
            return drive.copy()
        # Imported here: importing scipy.signal at the top would cost every command a few hundred ms.
        from scipy.signal import lfilter  # type: ignore[import-untyped]

        amplitude, _ = lfilter([-math.expm1(-step) * gain_m_per_v], [1.0, -decay], drive, zi=[decay * initial])
        return np.asarray(amplitude, dtype=np.float64)

    def derived_problems(self) -> list[str]:
        """One ``key: what is wrong`` line per derived quantity out of bounds at some force; empty if fine.

        Checked at every knot of the force table and at DERIVED_CHECK_POINTS forces spread
        evenly over it (the kernel's force grid is at most 4096 intervals): amplitude per
        volt, power per squared volt at the carrier and envelope time constant must be
        finite and > 0; the loaded resonance must lie within RESONANCE_CARRIER_FACTOR of the
        carrier, and the loaded quality factor above MIN_Q (the plate must ring, as
        ``sim://`` simulates it).
        """
        knots = self.force_table_n
        forces = np.union1d(knots, np.linspace(knots[0], knots[-1], DERIVED_CHECK_POINTS))
        tables = (
            ("circuit", "plate amplitude per volt at the carrier (m/V)", self.amplitude_m_per_v),
            ("circuit", "power per squared volt at the carrier (W/V^2)", self.power_w_per_v2),
            ("circuit", "envelope time constant 2 L / (R + Re Z_th) (s)", self.envelope_time_constant_s),
        )
        problems = []
        for key, what, table in tables:
            with np.errstate(all="ignore"):
                values = np.asarray(table(forces), dtype=np.float64)
            bad = np.flatnonzero(~(np.isfinite(values) & (values > 0.0)))
            if bad.size:
                problems.append(
                    f"{key}: {what} must be finite and > 0 at every force, got {values[bad[0]]:g} at "
                    f"{forces[bad[0]]:g} N: these values are outside what tpad-rt can render "
                    "(docs/formats.md \"Ranges, and why\")"
                )
        if problems:
            return problems
        with np.errstate(all="ignore"):
            ratio = np.asarray(self.motional_resonance_hz(forces), dtype=np.float64) / self.carrier_hz
            loaded_q = np.asarray(self.loaded_quality_factor(forces), dtype=np.float64)
        off = np.flatnonzero(~((ratio >= 1 / RESONANCE_CARRIER_FACTOR) & (ratio <= RESONANCE_CARRIER_FACTOR)))
        if off.size:
            problems.append(
                f"circuit: the loaded motional resonance 1 / (2 pi sqrt(L C)), shunt and C0 included, must lie within "
                f"a factor {RESONANCE_CARRIER_FACTOR:g} of carrier_hz ({self.carrier_hz:g} Hz): a TPaD is driven near "
                f"its resonance; got {ratio[off[0]] * self.carrier_hz:.6g} Hz at {forces[off[0]]:g} N"
            )
        damped = np.flatnonzero(~(loaded_q > MIN_Q))
        if damped.size:
            problems.append(
                f"circuit: the loaded quality factor (the shunt seen through C0 damps the branch) must stay above "
                f"{MIN_Q:g}, got {loaded_q[damped[0]]:.3g} at {forces[damped[0]]:g} N: the plate would not ring"
            )
        return problems
