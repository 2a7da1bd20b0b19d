"""What the finger should have felt: the texture where the finger really was.

API map
-------
texture_at_finger(finger, texture, t_s, texture_t0_s=0.0) -> (mu, valid)
    the texture's relative friction at stream times ``t_s`` (s), at the finger's
    position interpolated between its samples, and where that is known
departures(felt_mu, achieved_mu, judged, tolerance_mu=DEPARTURE_TOLERANCE_MU) -> mask
    the blocks whose achieved friction is further than ``tolerance_mu`` from the felt one
judge_blocks(blocks, finger, texture, *, block_s, mu_floor, texture_t0_s=0.0) -> Judged
    both, for telemetry rows: what ``render``, ``play`` and a Renderer's recording judge
start_ramps(t_s, touching, window_s, touch_start_s=-inf, was_touching=False) -> (mask, touch_start_s)
    the touching blocks within ``window_s`` of their touch's start, where the drive fades in

Used to judge a rendering against its texture free of the kernel's own extrapolation
(``horizon_ms``): ``tpad-rt render``'s summary and plots (through
:func:`tpad_rt.offline.texture_under_finger`), ``tpad-rt play``'s status on ``sim://`` and the
``departed`` column of recordings (``render``'s and a Renderer's), all by :func:`judge_blocks`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from tpad_rt.kernel.layout import FLAG_WATCHDOG

if TYPE_CHECKING:  # annotations only: the texture loads the kernels, which judging a run does not need
    from tpad_rt.texture import CompiledTexture

#: How far (relative friction) the achieved friction may be from the texture under the finger
#: before a block counts as a departure: 0.1, a tenth of the whole range of relative friction.
DEPARTURE_TOLERANCE_MU = 0.1


def departures(felt_mu: np.ndarray, achieved_mu: np.ndarray, judged: np.ndarray,
               tolerance_mu: float = DEPARTURE_TOLERANCE_MU) -> np.ndarray:
    """True for the ``judged`` blocks where ``|felt_mu - achieved_mu| > tolerance_mu`` (NaN counts as departed)."""
    return judged & ~(np.abs(felt_mu - achieved_mu) <= tolerance_mu)


@dataclass(frozen=True)
class Judged:
    """Blocks judged against the texture under the finger: ``felt_mu`` (the texture at each block's middle,
    clamped to ``[mu_floor, 1]`` as the kernel renders it; 1 where not known), ``known`` (where it is known),
    ``judged`` (touching blocks where it is known and the plate's friction was measured) and ``departed`` (judged blocks further than
    DEPARTURE_TOLERANCE_MU from it)."""

    felt_mu: np.ndarray
    known: np.ndarray
    judged: np.ndarray
    departed: np.ndarray


def judge_blocks(blocks: Mapping[str, np.ndarray], finger: np.ndarray, texture: CompiledTexture, *, block_s: float,
                 mu_floor: float, texture_t0_s: float = 0.0) -> Judged:
    """Judge telemetry ``blocks`` (``t``, ``saturated`` and the plate's ``achieved_mu``, NaN where not measured;
    blocks of ``block_s`` s) against ``texture`` (started at stream time ``texture_t0_s``, s) under ``finger``
    (FINGER_DTYPE samples in time order, :func:`texture_at_finger`), with the kernel's floor ``mu_floor``."""
    felt_mu, known = texture_at_finger(finger, texture, blocks["t"] + 0.5 * block_s, texture_t0_s)
    felt_mu = np.clip(felt_mu, mu_floor, 1.0)
    achieved_mu = blocks["achieved_mu"]
    touching = (blocks["saturated"].astype(np.int64) & FLAG_WATCHDOG) == 0
    judged = known & touching & np.isfinite(achieved_mu)
    return Judged(felt_mu, known, judged, departures(felt_mu, achieved_mu, judged))


def start_ramps(t_s: np.ndarray, touching: np.ndarray, window_s: float, touch_start_s: float = -math.inf,
                was_touching: bool = False) -> tuple[np.ndarray, float]:
    """True for the ``touching`` blocks (stream times ``t_s``, s, in order) less than ``window_s`` (s) after
    the start of their touch, and the start (s) of the touch the last block belongs to.

    A touch starts at a touching block after a block that was not touching (the watchdog
    gate was closed: no finger, a lift, a stalled input); the renderer fades the drive in
    there by design, over ``ramp_ms``. Blocks judged in chunks carry the state on:
    ``touch_start_s`` and ``was_touching`` describe the blocks before ``t_s``.
    """
    touching = np.asarray(touching, dtype=bool)
    t_s = np.asarray(t_s, dtype=np.float64)
    previous = np.r_[was_touching, touching[:-1]]
    starts_s = np.maximum.accumulate(np.where(touching & ~previous, t_s, touch_start_s))
    last_start_s = float(starts_s[-1]) if len(starts_s) else touch_start_s
    return touching & (t_s - starts_s < window_s), last_start_s


def texture_at_finger(finger: np.ndarray, texture: CompiledTexture, t_s: np.ndarray,
                      texture_t0_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The texture's relative friction under the finger at stream times ``t_s`` (s), and where it is known.

    ``finger``: FINGER_DTYPE samples in time order. The position is interpolated
    linearly between the samples around each time; the direction of motion is that
    segment's; the texture's time is ``t_s - texture_t0_s``. ``valid`` is False where
    the finger was lifted or the time lies outside the samples (``mu`` is 1 there).
    """
    t_s = np.asarray(t_s, dtype=np.float64)
    after = np.searchsorted(finger["t_s"], t_s, side="right")
    valid = (after > 0) & (after < len(finger))
    before = np.clip(after - 1, 0, max(len(finger) - 1, 0))
    after = np.clip(after, 0, max(len(finger) - 1, 0))
    if len(finger):
        valid &= finger["down"][before] & finger["down"][after]
    mu = np.ones(t_s.shape)
    if not valid.any():
        return mu, valid
    b, a = before[valid], after[valid]
    span_s = finger["t_s"][a] - finger["t_s"][b]
    share = (t_s[valid] - finger["t_s"][b]) / span_s
    dx, dy = finger["x_mm"][a] - finger["x_mm"][b], finger["y_mm"][a] - finger["y_mm"][b]
    length = np.hypot(dx, dy)
    moving = length > 0
    ux = np.divide(dx, length, out=np.zeros_like(dx), where=moving)
    uy = np.divide(dy, length, out=np.zeros_like(dy), where=moving)
    mu[valid] = texture.evaluate(finger["x_mm"][b] + share * dx, finger["y_mm"][b] + share * dy, ux, uy,
                                 t_s[valid] - texture_t0_s)
    return mu, valid
