"""Device files (format 2): one TPaD's plate, actuator, carrier, amplifier and circuit model.

Values keep the units of their key names; ``tpad_rt.device`` converts to SI. The
circuit (Butterworth-Van Dyke: C0, shunt, and L, C, R per contact force) with one
transduction factor ``gamma_n_per_v`` is the whole device model: amplitude per volt and
power per squared volt follow from it at any force and drive frequency
(docs/formats.md "Device files"). Format 1 files (no ``format_version``, an
``amplitude_um_per_v`` table beside the circuit) are refused by the loader with the
command that converts them (``tpad-rt calibrate convert``).
"""

from __future__ import annotations

import math
from typing import Annotated, ClassVar, Literal

from annotated_types import Ge, Le, Lt, MinLen
from pydantic import Strict, model_validator

from tpad_rt.config.device_ranges import (
    DENSITY_G_CM3,
    FORCE_SLACK_N,
    MAX_CARRIER_HZ,
    MAX_VOLTS,
    MIN_CARRIER_HZ,
    MIN_FORCE_STEP_N,
    MODE_M,
    PLATE_SIDE_MM,
    THICKNESS_MM,
    YOUNGS_MODULUS_GPA,
)
from tpad_rt.config.fields import Flag, StrictModel, Text, rule_error
from tpad_rt.limits import MAX_FORCE_N

#: The motional branch's quality factor sqrt(L / C) / R must lie in (MIN_Q, MAX_Q] at every force:
#: above 0.5 the plate rings (an underdamped resonator, which sim:// models); a MAX_Q plate takes
#: seconds to ring up, far beyond any TPaD.
MIN_Q = 0.5
MAX_Q = 1e6
#: The device file format this tpad-rt reads and writes.
DEVICE_FORMAT_VERSION = 2

ThicknessMm = Annotated[float, Strict(), Ge(THICKNESS_MM[0]), Le(THICKNESS_MM[1])]
DensityGCm3 = Annotated[float, Strict(), Ge(DENSITY_G_CM3[0]), Le(DENSITY_G_CM3[1])]
YoungsModulusGpa = Annotated[float, Strict(), Ge(YOUNGS_MODULUS_GPA[0]), Le(YOUNGS_MODULUS_GPA[1])]
PlateSideMm = Annotated[float, Strict(), Ge(PLATE_SIDE_MM[0]), Le(PLATE_SIDE_MM[1])]
#: m of the plate's m x n mode (nodal lines along its length).
ModeM = Annotated[int, Strict(), Ge(MODE_M[0]), Le(MODE_M[1])]
Volts = Annotated[float, Strict(), Ge(0.1), Le(MAX_VOLTS)]
ForceN = Annotated[float, Strict(), Ge(0), Le(MAX_FORCE_N)]
ForceTable = Annotated[list[ForceN], MinLen(1)]
#: The transduction factor gamma (N/V, the same as C/m): i_g = gamma dX/dt.
GammaNPerV = Annotated[float, Strict(), Ge(1e-6), Le(1e3)]
CarrierHz = Annotated[float, Strict(), Ge(MIN_CARRIER_HZ), Le(MAX_CARRIER_HZ)]
InductanceTable = Annotated[list[Annotated[float, Strict(), Ge(1e-6), Le(1e4)]], MinLen(1)]
CapacitanceTable = Annotated[list[Annotated[float, Strict(), Ge(1e-3), Le(1e6)]], MinLen(1)]
ResistanceTable = Annotated[list[Annotated[float, Strict(), Ge(1e-3), Le(1e7)]], MinLen(1)]


class Plate(StrictModel):
    """The glass plate and the mode it is driven in (``[m, n]`` nodal lines along length, width)."""

    material: Text
    thickness_mm: ThicknessMm
    density_g_cm3: DensityGCm3
    youngs_modulus_gpa: YoungsModulusGpa
    length_mm: PlateSideMm
    width_mm: PlateSideMm
    mode: tuple[ModeM, Annotated[int, Strict(), Ge(0), Le(1000)]]


class Actuator(StrictModel):
    """The piezo actuator bonded to the plate."""

    thickness_mm: ThicknessMm
    density_g_cm3: DensityGCm3
    youngs_modulus_gpa: YoungsModulusGpa


class Amplifier(StrictModel):
    """Drive volts at DAC sample 1.0, and the peak drive never exceeded."""

    volts_per_full_scale: Volts
    max_voltage_v: Volts

    @model_validator(mode="after")
    def _within_full_scale(self) -> Amplifier:
        if self.max_voltage_v > self.volts_per_full_scale:
            raise rule_error(
                f"must be <= volts_per_full_scale ({self.volts_per_full_scale:g}), got {self.max_voltage_v:g}",
                "max_voltage_v",
            )
        return self


class _ForceTables(StrictModel):
    """Tables indexed by a strictly increasing ``force_n``; ``tables`` name the others."""

    tables: ClassVar[tuple[str, ...]]
    force_n: ForceTable

    @model_validator(mode="after")
    def _consistent(self) -> _ForceTables:
        for index in range(1, len(self.force_n)):
            previous, force = self.force_n[index - 1], self.force_n[index]
            if force - previous < MIN_FORCE_STEP_N - FORCE_SLACK_N:
                message = (f"must be >= {previous + MIN_FORCE_STEP_N:g} (forces must increase by at least "
                           f"{MIN_FORCE_STEP_N:g} N), got {force:g}")
                raise rule_error(message, "force_n", index)
        for name in self.tables:
            count = len(getattr(self, name))
            if count != len(self.force_n):
                raise rule_error(f"must have as many items as force_n ({len(self.force_n)}), got {count}", name)
        return self


class Circuit(_ForceTables):
    """Butterworth-Van Dyke model: static capacitance, shunt, transduction factor, motional branch per force."""

    tables = ("motional_l_h", "motional_c_pf", "motional_r_ohm")
    c0_nf: Annotated[float, Strict(), Ge(1e-3), Le(1e5)]
    shunt_ohm: Annotated[float, Strict(), Ge(1e-3), Le(1e6)]
    gamma_n_per_v: GammaNPerV
    motional_l_h: InductanceTable
    motional_c_pf: CapacitanceTable
    motional_r_ohm: ResistanceTable

    @model_validator(mode="after")
    def _rings(self) -> Circuit:
        """Q = sqrt(L / C) / R in (MIN_Q, MAX_Q] wherever the tables interpolate (checked after _consistent)."""
        last = len(self.force_n) - 1
        for index in range(max(last, 1)):
            pair = slice(index, min(index + 1, last) + 1)
            l_h, c_pf, r_ohm = self.motional_l_h[pair], self.motional_c_pf[pair], self.motional_r_ohm[pair]
            # Linear interpolation keeps each of L, C, R between its knots: bounds on Q over the interval.
            lowest = math.sqrt(min(l_h) / (max(c_pf) * 1e-12)) / max(r_ohm)
            highest = math.sqrt(max(l_h) / (min(c_pf) * 1e-12)) / min(r_ohm)
            if lowest > MIN_Q and highest <= MAX_Q:
                continue
            limit, value = (f"above {MIN_Q:g}", lowest) if lowest <= MIN_Q else (f"at most {MAX_Q:g}", highest)
            forces = self.force_n[pair]
            where = f"between force_n {forces[0]:g} and {forces[-1]:g} N" if len(forces) > 1 else "at its one force"
            message = f"the quality factor sqrt(L / C) / R must stay {limit} at every force; it can reach {value:.3g}"
            raise rule_error(f"{message} {where}", "motional_r_ohm", index)
        return self


class FrictionModel(StrictModel):
    """Vezzoli/Sednaoui friction model constants (paper Eqs. 2-3)."""

    mu0: Annotated[float, Strict(), Ge(0.01), Le(10)] = 0.25
    poisson: Annotated[float, Strict(), Ge(0), Lt(0.5)] = 0.33
    psi_star: Annotated[float, Strict(), Ge(0.01), Le(1000)] = 4.69


class ModeShape(StrictModel):
    """The standing wave across the plate: the free-free ``m x 0`` bending mode (``m = plate.mode[0]``), and
    the length (mm) of the fingertip's contact patch along the plate, over which the finger feels its mean."""

    contact_width_mm: Annotated[float, Strict(), Ge(0), Le(1000)]


class DeviceFile(StrictModel):
    """One TPaD: how it turns volts into vibration, and its limits."""

    format_version: Literal[2]
    label: Text
    description: Text
    plate: Plate
    actuator: Actuator
    carrier_hz: CarrierHz
    amplifier: Amplifier
    circuit: Circuit
    friction_model: FrictionModel = FrictionModel()
    speed_floor_mm_s: Annotated[float, Strict(), Ge(0.1), Le(1000)] = 5.0
    power_budget_w: Annotated[float, Strict(), Ge(0.001), Le(1000)]
    preemphasis: Flag = True
    mode_shape: ModeShape | None = None
    source: Annotated[dict[Text, Text], MinLen(1)]

    @model_validator(mode="after")
    def _mode_shape_fits(self) -> DeviceFile:
        """A mode shape needs an m x 0 mode with m >= 2 and a contact patch no longer than the plate."""
        if self.mode_shape is None:
            return self
        lines, across = self.plate.mode
        if lines < 2 or across != 0:
            raise rule_error(f"needs the plate's mode to be [m, 0] with m >= 2 (a free-free bending wave along the "
                             f"length), got [{lines}, {across}]", "mode_shape")
        if self.mode_shape.contact_width_mm > self.plate.length_mm:
            raise rule_error(f"must be <= plate.length_mm ({self.plate.length_mm:g}), got "
                             f"{self.mode_shape.contact_width_mm:g}", "mode_shape", "contact_width_mm")
        return self
