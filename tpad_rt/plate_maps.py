"""Maps over the plate: the target friction a texture asks for, and the drive volts and power it takes.

API map
-------
Finger(speed_mm_s, direction_deg, force_n)
    how the finger moves while the maps are made
plate_maps(texture, device, finger, t_s, resolution_mm) -> PlateMaps
    friction, drive volts (asked and clipped), power and saturation at the centres of a grid over
    the plate; ConfigError past MAX_POINTS points, or for ``t_s`` outside [0, MAX_T_S]

``tpad-rt show`` draws them; ``tpad-rt serve`` sends the friction map to its page.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tpad_rt.device import Device
from tpad_rt.errors import ConfigError
from tpad_rt.physics.friction import amplitude_for
from tpad_rt.pipeline import mode_gain_table
from tpad_rt.texture import CompiledTexture

#: Most grid points a figure evaluates (a 130 x 60 mm plate at 0.02 mm).
MAX_POINTS = 20_000_000
#: Latest time (s) a map is drawn at, 11.6 days. A texture's phase is ``t_s * frequency_hz`` cycles in float64: here
#: it still resolves 1.2e-7 of a cycle of the fastest temporal texture (1 kHz); at 1e12 s only an eighth of one, and
#: past 2**52 cycles (4.5e12 s at 1 kHz) the kernel has no phase left and gives NaN. A texture repeats with its
#: period, so a later time draws the same map as that time modulo the period.
MAX_T_S = 1e6


@dataclass(frozen=True)
class Finger:
    """How the finger moves: speed (mm/s, >= 0), direction (degrees, counter-clockwise on screen), force (N, >= 0)."""

    speed_mm_s: float
    direction_deg: float
    force_n: float

    @property
    def unit_direction(self) -> tuple[float, float]:
        """Unit direction of motion in plate coordinates (y down); (0, 0) for a still finger."""
        if self.speed_mm_s == 0.0:
            return 0.0, 0.0
        angle = math.radians(self.direction_deg)
        return math.cos(angle), -math.sin(angle)


@dataclass(frozen=True)
class PlateMaps:
    """Maps over the plate, rows along y: ``x_mm`` (columns) and ``y_mm`` (rows) are the cell centres.

    ``friction`` target relative friction; ``volts_asked`` peak drive volts the target
    needs (unclipped); ``volts`` the same clipped at ``max_voltage_v``; ``power_w`` the
    estimated power of ``volts``; ``saturated`` where ``volts_asked > max_voltage_v``.
    """

    x_mm: np.ndarray
    y_mm: np.ndarray
    friction: np.ndarray
    volts_asked: np.ndarray
    volts: np.ndarray
    power_w: np.ndarray
    saturated: np.ndarray

    @property
    def saturated_percent(self) -> float:
        """Share of the plate (%) where the drive saturates at ``max_voltage_v``."""
        return 100.0 * float(np.mean(self.saturated))


def plate_maps(
    texture: CompiledTexture, device: Device, finger: Finger, t_s: float, resolution_mm: float
) -> PlateMaps:
    """Friction, drive volts and power at the centres of a ``resolution_mm`` grid over the plate.

    Raises ConfigError if the grid would have more than MAX_POINTS points, or ``t_s`` (s) is outside [0, MAX_T_S].
    """
    if not 0.0 <= t_s <= MAX_T_S:
        raise ConfigError(f"--t-s: must be from 0 to {MAX_T_S:g} s (a texture repeats with its period: take the "
                          f"time modulo it), got {t_s:g}")
    length_mm, width_mm = device.plate.length_m * 1e3, device.plate.width_m * 1e3
    spans = (length_mm / resolution_mm, width_mm / resolution_mm)  # inf for a subnormal step
    if spans[0] * spans[1] > 4 * MAX_POINTS or math.ceil(spans[0]) * math.ceil(spans[1]) > MAX_POINTS:
        finest = math.sqrt(length_mm * width_mm / MAX_POINTS)
        shown = " x ".join(str(math.ceil(n)) if n < 1e12 else f"{n:.3g}" for n in spans)  # not 300 digits
        raise ConfigError(f"--resolution-mm: {resolution_mm:g} gives {shown} points; use >= {finest:.3g}")
    columns, rows = math.ceil(spans[0]), math.ceil(spans[1])
    x_mm = (np.arange(columns) + 0.5) * (length_mm / columns)
    y_mm = (np.arange(rows) + 0.5) * (width_mm / rows)
    ux, uy = finger.unit_direction
    friction = texture.evaluate(x_mm[None, :], y_mm[:, None], ux, uy, t_s)
    speed_m_s = max(finger.speed_mm_s * 1e-3, device.speed_floor_m_s)
    amplitude_m = amplitude_for(friction, device.carrier_hz, speed_m_s, device.mu0, device.poisson, device.psi_star)
    volts_asked = amplitude_m / (device.amplitude_m_per_v(finger.force_n) * mode_gain_table(device, x_mm)[None, :])
    volts = np.minimum(volts_asked, device.max_voltage_v)
    return PlateMaps(
        x_mm=x_mm,
        y_mm=y_mm,
        friction=friction,
        volts_asked=np.asarray(volts_asked),
        volts=volts,
        power_w=device.power_w_per_v2(finger.force_n) * volts**2,
        saturated=np.asarray(volts_asked > device.max_voltage_v),
    )
