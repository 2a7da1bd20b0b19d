"""Device files: one TPaD's plate, actuator, amplifier, calibration and circuit.

Values keep the units of their key names; ``tpad_rt.device`` converts to SI.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from annotated_types import Ge, Gt, Le, Lt, MinLen
from pydantic import Strict, model_validator

from tpad_rt.config.fields import Flag, NonNegative, Positive, StrictModel, Text, rule_error

PositiveTable = Annotated[list[Positive], MinLen(1)]
ForceTable = Annotated[list[NonNegative], MinLen(1)]


class Plate(StrictModel):
    """The glass plate and the mode it is driven in (``[m, n]`` nodal lines along length, width)."""

    material: Text
    thickness_mm: Positive
    density_g_cm3: Positive
    youngs_modulus_gpa: Positive
    length_mm: Positive
    width_mm: Positive
    mode: tuple[Annotated[int, Strict(), Ge(1)], Annotated[int, Strict(), Ge(0)]]


class Actuator(StrictModel):
    """The piezo actuator bonded to the plate."""

    thickness_mm: Positive
    density_g_cm3: Positive
    youngs_modulus_gpa: Positive


class Amplifier(StrictModel):
    """Drive volts at DAC sample 1.0, and the peak drive never exceeded."""

    volts_per_full_scale: Positive
    max_voltage_v: Positive

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
            if force <= previous:
                message = f"must be > {previous:g} (forces must be strictly increasing), got {force:g}"
                raise rule_error(message, "force_n", index)
        for name in self.tables:
            count = len(getattr(self, name))
            if count != len(self.force_n):
                raise rule_error(f"must have as many items as force_n ({len(self.force_n)}), got {count}", name)
        return self


class Calibration(_ForceTables):
    """Plate vibration amplitude per drive volt (peak) at each contact force."""

    tables = ("amplitude_um_per_v",)
    amplitude_um_per_v: PositiveTable


class Circuit(_ForceTables):
    """Butterworth-Van Dyke model: static capacitance, shunt, and motional branch per force."""

    tables = ("motional_l_h", "motional_c_pf", "motional_r_ohm")
    c0_nf: Positive
    shunt_ohm: Positive
    motional_l_h: PositiveTable
    motional_c_pf: PositiveTable
    motional_r_ohm: PositiveTable


class FrictionModel(StrictModel):
    """Vezzoli/Sednaoui friction model constants (paper Eqs. 2-3)."""

    mu0: Positive = 0.25
    poisson: Annotated[float, Strict(), Gt(-1), Lt(0.5)] = 0.33
    psi_star: Positive = 4.69


class DeviceFile(StrictModel):
    """One TPaD: how it turns volts into vibration, and its limits."""

    label: Text
    description: Text
    plate: Plate
    actuator: Actuator
    resonance_hz: Annotated[float, Strict(), Ge(1000), Le(200_000)]
    amplifier: Amplifier
    calibration: Calibration
    circuit: Circuit
    friction_model: FrictionModel = FrictionModel()
    speed_floor_mm_s: Positive = 5.0
    power_budget_w: Positive
    preemphasis: Flag = True
    source: Annotated[dict[Text, Text], MinLen(1)]
