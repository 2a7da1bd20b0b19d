"""Why a run saturated or departed from its texture, and what to change: ``tpad-rt play``'s hint lines.

API map
-------
swipe_url(speed_mm_s, force_n=None) -> str
    endless back-and-forth swipes along the plate at that speed (mm/s) and force (N; the swipe's own without)
FingerTally
    ``.add(rows)`` per telemetry drain: the touching blocks' mean speed and force, the lowest friction the
    texture asked of the plate, the saturated blocks
hint_lines(tally, device, max_voltage_v, power_cap_w, judged, departed, departed_saturated) -> list[str]
    nothing for a run that neither saturated in SATURATION_HINT_SHARE of its touching blocks nor departed in
    DEPARTURE_HINT_SHARE of its judged ones; else one line each, from the run's figures and the device model:
    a slower swipe only where one at least the device's speed floor, and slower than the run's, would help

The figures behind the hints: the friction model (paper Eqs. 2-3) needs a vibration amplitude
proportional to the finger's speed for a given friction, and the drive gives at most the
amplitude of the lower of the voltage limit and the power cap's volts (at the run's force, at
an antinode). So the lowest friction the drive reaches at the run's speed, and the fastest
finger that reaches the texture's lowest level, follow from the device alone. The model takes
a finger slower than the device's speed floor as that fast: where only a finger below it (or
within SPEED_MARGIN of it) would reach the texture's lowest level, no speed is suggested.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from tpad_rt.kernel.layout import FLAG_POWER, FLAG_VOLTAGE, FLAG_WATCHDOG

if TYPE_CHECKING:
    from tpad_rt.device import Device

#: Share of the touching blocks saturated (voltage or power) from which the summary says why.
SATURATION_HINT_SHARE = 0.05
#: Share of the judged blocks departed from which the summary says what to change (the shipped textures' bound).
DEPARTURE_HINT_SHARE = 0.05
#: A suggested finger speed keeps this share of the fastest one that reaches the texture's lowest friction.
SPEED_MARGIN = 0.8


def swipe_url(speed_mm_s: float, force_n: float | None = None) -> str:
    """Endless back-and-forth swipes along the plate at ``speed_mm_s`` (mm/s) pressing ``force_n`` (N; the swipe's
    own force when None)."""
    force = "" if force_n is None else f"&force_n={force_n:g}"
    return f"scripted://swipe?speed_mm_s={speed_mm_s:g}{force}&repeat=0&back_and_forth=1"


@dataclass
class FingerTally:
    """What the touching blocks of a run asked and did, over the telemetry rows added so far."""

    touching: int = 0
    saturated: int = 0
    speed_sum_mm_s: float = 0.0
    force_sum_n: float = 0.0
    lowest_mu: float = 1.0

    def add(self, rows: dict[str, np.ndarray]) -> None:
        """Count the telemetry ``rows`` (TEL_NAMES columns): blocks with the finger down only."""
        flags = rows["saturated"].astype(np.int64)
        down = (flags & FLAG_WATCHDOG) == 0
        self.touching += int(np.count_nonzero(down))
        self.saturated += int(np.count_nonzero(down & ((flags & (FLAG_VOLTAGE | FLAG_POWER)) != 0)))
        self.speed_sum_mm_s += float(rows["speed_mm_s"][down].sum())
        self.force_sum_n += float(rows["force_n"][down].sum())
        if down.any():
            self.lowest_mu = min(self.lowest_mu, float(rows["target_mu"][down].min()))

    @property
    def speed_mm_s(self) -> float:
        """Mean finger speed (mm/s) over the touching blocks (0 without any)."""
        return self.speed_sum_mm_s / max(self.touching, 1)

    @property
    def force_n(self) -> float:
        """Mean contact force (N) over the touching blocks (0 without any)."""
        return self.force_sum_n / max(self.touching, 1)


@dataclass(frozen=True)
class _Reach:
    """The most the drive gives at a speed and force: the limit that binds, the lowest friction."""

    limit: str
    lowest_mu: float
    fastest_mm_s: float  # the fastest finger (mm/s) for which it reaches the texture's lowest friction
    floor_mm_s: float  # the device's speed floor (mm/s): the model takes a slower finger as this fast
    floor_mu: float  # the lowest friction it reaches for a finger at floor_mm_s


def _reach(device: Device, speed_mm_s: float, force_n: float, target_mu: float, max_voltage_v: float,
           power_cap_w: float) -> _Reach:
    """What the drive reaches (at an antinode) for a finger at ``speed_mm_s`` (mm/s) pressing ``force_n`` (N),
    against the texture's lowest friction ``target_mu``."""
    from tpad_rt.physics.friction import amplitude_for, relative_friction  # numba: only once a hint is due
    power_v = math.sqrt(power_cap_w / float(device.power_w_per_v2(force_n)))
    limit = f"{max_voltage_v:g} V limit" if max_voltage_v <= power_v else \
        f"{power_cap_w:g} W power cap ({power_v:.1f} V at {force_n:.2g} N)"
    volts_v = min(max_voltage_v, power_v)
    amplitude_m = float(device.amplitude_m_per_v(force_n)) * volts_v
    model = (device.mu0, device.poisson, device.psi_star)
    speed_m_s = max(speed_mm_s * 1e-3, device.speed_floor_m_s)
    lowest = float(relative_friction(amplitude_m, device.carrier_hz, speed_m_s, *model))
    floor_mu = float(relative_friction(amplitude_m, device.carrier_hz, device.speed_floor_m_s, *model))
    per_m_s = float(amplitude_for(min(max(target_mu, 1e-6), 1.0), device.carrier_hz, 1.0, *model))
    fastest_mm_s = math.inf if per_m_s == 0.0 else amplitude_m / per_m_s * 1e3
    return _Reach(limit, lowest, fastest_mm_s, device.speed_floor_m_s * 1e3, floor_mu)


def _slower_speed(speed_mm_s: float, floor_mm_s: float) -> float | None:
    """``speed_mm_s`` (mm/s) rounded down to 1 mm/s (5 from 5, 10 above 50): a swipe's speed to suggest, None
    when that is below ``floor_mm_s`` (mm/s) or 0."""
    step = 10.0 if speed_mm_s > 50 else 5.0 if speed_mm_s >= 5 else 1.0
    rounded = math.floor(speed_mm_s / step) * step
    return rounded if rounded >= floor_mm_s and rounded > 0 else None


def hint_lines(tally: FingerTally, device: Device, max_voltage_v: float, power_cap_w: float, judged: int,
               departed: int, departed_saturated: int) -> list[str]:
    """The summary's hints (module docstring): ``judged`` blocks compared with the texture, ``departed`` of them
    further than the tolerance, ``departed_saturated`` of those saturated (0, 0, 0 where nothing was judged)."""
    saturated_share = tally.saturated / max(tally.touching, 1)
    departed_share = departed / max(judged, 1)
    if saturated_share < SATURATION_HINT_SHARE and departed_share <= DEPARTURE_HINT_SHARE:
        return []
    speed_mm_s, force_n = tally.speed_mm_s, tally.force_n
    reach = _reach(device, speed_mm_s, force_n, tally.lowest_mu, max_voltage_v, power_cap_w)
    finger = f"at {speed_mm_s:.0f} mm/s under {force_n:.2g} N"
    swipe_force_n = force_n if force_n > 0 else None  # a finger at no force: the swipe's own
    shaped = device.contact_width_m is not None
    if reach.lowest_mu > tally.lowest_mu:
        why = (f"the texture asks for friction down to {tally.lowest_mu:.2f}, and {finger} the drive's {reach.limit} "
               f"lowers it to {reach.lowest_mu:.2f} at best (at an antinode"
               + ("; less towards the nodes of the plate's standing wave)" if shaped else ")"))
        change = _change_for_friction(reach, tally.lowest_mu, swipe_force_n)
    else:
        slower = _slower_speed(speed_mm_s / 2, reach.floor_mm_s)
        why = (f"{finger} the drive's {reach.limit} reaches the texture's lowest friction, {tally.lowest_mu:.2f}, at an "
               f"antinode (down to {reach.lowest_mu:.2f}), so it hits the limit while hurrying the plate through the "
               "texture's changes" + (" and towards the nodes of the plate's standing wave" if shaped else ""))
        change = ("gentler changes in the texture leave more headroom" if slower is None else
                  f"a slower finger leaves more headroom (try --input '{swipe_url(slower, swipe_force_n)}'), as do "
                  "gentler changes in the texture")
    lines = []
    said_why = saturated_share >= SATURATION_HINT_SHARE
    if said_why:
        lines.append(f"why saturated ({100 * saturated_share:.1f} % of touching blocks): {why}; {change}")
    if departed_share > DEPARTURE_HINT_SHARE:
        tau_ms = float(device.envelope_time_constant_s(force_n)) * 1e3
        cause = (f"{departed_saturated} of them saturated" + (" (above)" if said_why else "") if departed_saturated
                 else f"none saturated: the plate lags the texture's changes {finger} (its envelope's time constant "
                 f"is {tau_ms:.2f} ms at {force_n:.2g} N)")
        advice = "" if said_why else f"; {change}"
        lines.append(f"departures in {100 * departed_share:.1f} % of judged blocks, more than "
                     f"{100 * DEPARTURE_HINT_SHARE:g} %: {cause}{advice}; --record then `tpad-rt plot` shows where")
    return lines


def _change_for_friction(reach: _Reach, target_mu: float, force_n: float | None) -> str:
    """What to change when the drive does not reach the texture's lowest friction ``target_mu`` at the run's
    speed: a swipe slow enough (pressing ``force_n``, N; the swipe's own when None) when one at least the speed
    floor reaches it with SPEED_MARGIN, and a lowest friction the drive reaches at the run's speed."""
    raise_mu = (f"raise the texture's lowest friction to {math.ceil(reach.lowest_mu * 100) / 100:.2f}, or use a "
                "device with more headroom")
    slower = _slower_speed(SPEED_MARGIN * reach.fastest_mm_s, reach.floor_mm_s)
    if slower is not None:
        return (f"a finger at most {reach.fastest_mm_s:.0f} mm/s reaches {target_mu:.2f}: try "
                f"--input '{swipe_url(slower, force_n)}', {raise_mu}")
    if reach.fastest_mm_s < reach.floor_mm_s:
        return (f"no finger speed reaches {target_mu:.2f} with this drive (the friction model takes a finger slower "
                f"than the device's speed floor, {reach.floor_mm_s:g} mm/s, as that fast, and there the drive lowers "
                f"it to {reach.floor_mu:.2f} at best): {raise_mu}")
    return (f"only a finger between the device's speed floor, {reach.floor_mm_s:g} mm/s, and "
            f"{reach.fastest_mm_s:.1f} mm/s reaches {target_mu:.2f}: {raise_mu}")
