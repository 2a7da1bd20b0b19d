"""One TPaD's calibration in SI units: resonance, gains, circuit and limits.

A :class:`Device` is built from a device file (docs/formats.md "Device files") by
:meth:`Device.from_file`, from an already validated :class:`tpad_rt.config.DeviceFile`
by :meth:`Device.from_spec`, or from the shipped ``devices/default.yaml`` by
:meth:`Device.default`. Its methods evaluate the force-dependent tables (linear
interpolation, clamped at the table ends; vectorised over ``force_n``): these are
what the real-time kernel tabulates. :meth:`Device.plate_amplitude_m` runs a drive
envelope through them: the amplitude it gives the plate (a pre-emphasised drive maps
back to the level it was shaped for).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from tpad_rt import shipped
from tpad_rt.config import DeviceFile, load_device
from tpad_rt.config.breadcrumb import breadcrumb
from tpad_rt.errors import ConfigError
from tpad_rt.physics import electromech
from tpad_rt.physics._validate import FloatOrArray, checked, finite, non_negative

#: Where the device files of the paper's TPaDs live (in the source tree).

#: Forces spread evenly over the tables at which :meth:`Device.derived_problems` checks (besides the knots).
DERIVED_CHECK_POINTS = 4097

_Table = npt.NDArray[np.float64]
_TABLE_FIELDS = (
    "force_table_n",
    "amplitude_m_per_v_table",
    "motional_force_table_n",
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
    """A TPaD's calibration, SI units; the ``*_table`` fields are read-only float64 arrays.

    ``amplitude_m_per_v_table`` (m per peak volt) is indexed by ``force_table_n``;
    the motional branch tables by their own ``motional_force_table_n``.
    """

    label: str
    description: str
    plate: Plate
    actuator: Actuator
    resonance_hz: float
    volts_per_full_scale: float
    max_voltage_v: float
    force_table_n: _Table
    amplitude_m_per_v_table: _Table
    c0_f: float
    shunt_ohm: float
    motional_force_table_n: _Table
    motional_l_h_table: _Table
    motional_c_f_table: _Table
    motional_r_ohm_table: _Table
    mu0: float
    poisson: float
    psi_star: float
    speed_floor_m_s: float
    power_budget_w: float
    preemphasis: bool

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
            resonance_hz=spec.resonance_hz,
            volts_per_full_scale=spec.amplifier.volts_per_full_scale,
            max_voltage_v=spec.amplifier.max_voltage_v,
            force_table_n=np.asarray(spec.calibration.force_n, dtype=np.float64),
            amplitude_m_per_v_table=np.multiply(spec.calibration.amplitude_um_per_v, 1e-6),
            c0_f=circuit.c0_nf * 1e-9,
            shunt_ohm=circuit.shunt_ohm,
            motional_force_table_n=np.asarray(circuit.force_n, dtype=np.float64),
            motional_l_h_table=np.asarray(circuit.motional_l_h, dtype=np.float64),
            motional_c_f_table=np.multiply(circuit.motional_c_pf, 1e-12),
            motional_r_ohm_table=np.asarray(circuit.motional_r_ohm, dtype=np.float64),
            mu0=spec.friction_model.mu0,
            poisson=spec.friction_model.poisson,
            psi_star=spec.friction_model.psi_star,
            speed_floor_m_s=spec.speed_floor_mm_s * 1e-3,
            power_budget_w=spec.power_budget_w,
            preemphasis=spec.preemphasis,
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

    def amplitude_m_per_v(self, force_n: npt.ArrayLike) -> FloatOrArray:
        """Plate vibration amplitude (m) per peak drive volt at contact force ``force_n`` (N, >= 0)."""
        return np.interp(non_negative("force_n", force_n), self.force_table_n, self.amplitude_m_per_v_table)

    def motional(self, force_n: npt.ArrayLike) -> tuple[FloatOrArray, FloatOrArray, FloatOrArray]:
        """Motional branch ``(L in H, C in F, R in ohm)`` at contact force ``force_n`` (N, >= 0)."""
        forces = non_negative("force_n", force_n)
        return tuple(  # type: ignore[return-value]
            np.interp(forces, self.motional_force_table_n, table)
            for table in (self.motional_l_h_table, self.motional_c_f_table, self.motional_r_ohm_table)
        )

    def power_w_per_v2(self, force_n: npt.ArrayLike) -> FloatOrArray:
        """Real power (W) per squared peak drive volt at the carrier, exact circuit (paper Eqs. 2-6).

        Drive of 1 V peak (``u_rms = 1/sqrt(2)``) at ``resonance_hz``, the frequency the
        runtime drives at, through the shunt into the motional branch at contact force
        ``force_n``. Multiply by ``V**2`` for a peak drive of ``V`` volts.
        """
        l_h, c_f, r_ohm = self.motional(force_n)
        return electromech.real_power_exact(
            1 / math.sqrt(2), self.resonance_hz, self.c0_f, l_h, c_f, r_ohm, self.shunt_ohm
        )

    def quality_factor(self, force_n: npt.ArrayLike) -> FloatOrArray:
        """Quality factor ``sqrt(L / C) / R`` of the motional branch at contact force ``force_n``."""
        return electromech.quality_factor(*self.motional(force_n))

    def envelope_time_constant_s(self, force_n: npt.ArrayLike) -> FloatOrArray:
        """Time constant (s) of the vibration envelope, ``Q / (pi f0)`` with ``f0 = resonance_hz``."""
        return self.quality_factor(force_n) / (math.pi * self.resonance_hz)

    def plate_amplitude_m(
        self, drive_v: npt.ArrayLike, rate_hz: float, force_n: float, initial_m: float = 0.0
    ) -> npt.NDArray[np.float64]:
        """Plate vibration amplitude (m) that the drive envelope ``drive_v`` gives: the calibrated amplitude model.

        The model the kernel's pre-emphasis assumes (docs/kernel.md "Per sample"): at
        contact force ``force_n`` the plate's envelope ``p`` follows the drive envelope
        ``u`` (peak volts at the carrier, the resonance) as ``tau dp/dt = G u - p``, with
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
        """One ``key: what is wrong`` line per derived table not finite and > 0 at some force; empty if fine.

        Checked at every knot of the force tables and at DERIVED_CHECK_POINTS forces spread
        evenly over them (the kernel's force grid is at most 4096 intervals): amplitude per
        volt, power per squared volt at the carrier, envelope time constant.
        """
        knots = np.union1d(self.force_table_n, self.motional_force_table_n)
        forces = np.union1d(knots, np.linspace(knots[0], knots[-1], DERIVED_CHECK_POINTS))
        tables = (
            ("calibration.amplitude_um_per_v", "plate amplitude per volt (m/V)", self.amplitude_m_per_v),
            ("circuit", "power per squared volt at the carrier (W/V^2)", self.power_w_per_v2),
            ("circuit", "envelope time constant Q / (pi f0) (s)", self.envelope_time_constant_s),
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
        return problems
