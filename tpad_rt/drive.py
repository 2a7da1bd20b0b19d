"""What a run drives: the one description of the drive (:class:`DriveSpec`) that everything reads.

API map
-------
Consumes
    what an output takes from the render kernel: DAC samples or the envelope
DriveSpec(consumes, rate_hz, carrier_hz, volts_per_full_scale, max_voltage_v, source)
    the drive a run uses; ``DriveSpec.from_device(device, consumes, rate_hz)`` (what the device file
    says), ``spec.from_hardware(...)`` (what an output's hardware reported, e.g. a serial amplifier's
    INFO and carrier echo), ``spec.metadata()`` (its recording keys)

The output makes it (its driver, from the device file and what the hardware reported); the
kernel's ``cfg`` (:meth:`tpad_rt.pipeline.Pipeline.set_drive`), recordings' metadata, ``play``'s
summary and ``serve``'s ``device`` message all read it, so they cannot disagree.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, replace
from enum import Enum
from typing import TYPE_CHECKING, Any

from tpad_rt.errors import ConfigError

if TYPE_CHECKING:
    from tpad_rt.device import Device  # annotations only: the device model loads pydantic


class Consumes(Enum):
    """What an output takes from the render kernel."""

    #: float32 DAC samples in [-1, 1] (1.0 = the drive's volts_per_full_scale) at the output's sample rate,
    #: which must exceed 2.2x the carrier: the kernel's modulation stage makes the carrier
    DAC = "DAC samples"
    #: the envelope, drive volts (signed: negative drives the carrier in anti-phase) at the output's envelope
    #: rate, with the carrier's frequency given once: the output makes the carrier itself
    ENVELOPE = "envelope"


@dataclass(frozen=True)
class DriveSpec:
    """The drive a run uses.

    ``consumes`` what the kernel renders for the output; ``rate_hz`` its samples per second (the DAC's rate,
    or the amplifier's envelope rate); ``carrier_hz`` the carrier made (Hz); ``volts_per_full_scale`` the
    volts a sample of 1.0 stands for; ``max_voltage_v`` the clamp (V: the lower of the device's and the
    hardware's); ``source`` who said so (``"device file"``, or the hardware that reported it).

    Raises ConfigError for a rate, carrier, scale or clamp that is not a finite number > 0.
    """

    consumes: Consumes
    rate_hz: float
    carrier_hz: float
    volts_per_full_scale: float
    max_voltage_v: float
    source: str = "device file"

    def __post_init__(self) -> None:
        if not isinstance(self.consumes, Consumes):
            raise ConfigError(f"drive: consumes: must be a Consumes, got {self.consumes!r}")
        for name in ("rate_hz", "carrier_hz", "volts_per_full_scale", "max_voltage_v"):
            value = getattr(self, name)
            number = float(value) if isinstance(value, numbers.Real) and not isinstance(value, bool) else math.nan
            if not (math.isfinite(number) and number > 0):
                raise ConfigError(f"drive: {name}: must be a finite number > 0, got {value!r}")
            object.__setattr__(self, name, number)  # a NumPy number is kept as a plain float
        if not isinstance(self.source, str):
            raise ConfigError(f"drive: source: must be text, got {self.source!r}")

    @classmethod
    def from_device(cls, device: Device, consumes: Consumes, rate_hz: float) -> DriveSpec:
        """The drive the device file describes, rendered as ``consumes`` at ``rate_hz`` (Hz)."""
        return cls(consumes, rate_hz, device.carrier_hz, device.volts_per_full_scale, device.max_voltage_v)

    def from_hardware(self, *, volts_per_full_scale: float, max_voltage_v: float, carrier_hz: float,
                      source: str) -> DriveSpec:
        """This drive as the output's hardware reported it: its full scale (V per 1.0), its clamp (V; the
        lower of it and this one's is kept: call it on the device file's drive,
        :attr:`tpad_rt.pipeline.Pipeline.device_drive`), the carrier it makes (Hz); ``source`` names the
        hardware. Raises ConfigError as the class does."""
        return replace(self, volts_per_full_scale=volts_per_full_scale,
                       max_voltage_v=min(max_voltage_v, self.max_voltage_v), carrier_hz=carrier_hz, source=source)

    def metadata(self) -> dict[str, Any]:
        """Its keys in a recording's metadata (:mod:`tpad_rt.recording`)."""
        return {"carrier_hz": float(self.carrier_hz), "volts_per_full_scale": float(self.volts_per_full_scale),
                "max_voltage_v": float(self.max_voltage_v), "output_consumes": self.consumes.value,
                "drive_rate_hz": float(self.rate_hz), "drive_source": self.source}


__all__ = ["Consumes", "DriveSpec"]
