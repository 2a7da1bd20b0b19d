"""What the finger should have felt: the texture where the finger really was.

API map
-------
texture_at_finger(finger, texture, t_s, texture_t0_s=0.0) -> (mu, valid)
    the texture's relative friction at stream times ``t_s`` (s), at the finger's
    position interpolated between its samples, and where that is known
departures(felt_mu, achieved_mu, judged, tolerance_mu=DEPARTURE_TOLERANCE_MU) -> mask
    the blocks whose achieved friction is further than ``tolerance_mu`` from the felt one

Used to judge a rendering against its texture free of the kernel's own extrapolation
(``horizon_ms``): ``tpad-rt render``'s summary and plots (through
:func:`tpad_rt.offline.texture_under_finger`) and ``tpad-rt play``'s status on ``sim://``.
"""

from __future__ import annotations

import numpy as np

from tpad_rt.texture import CompiledTexture

#: How far (relative friction) the achieved friction may be from the texture under the finger
#: before a block counts as a departure: 0.1, a tenth of the whole range of relative friction.
DEPARTURE_TOLERANCE_MU = 0.1


def departures(felt_mu: np.ndarray, achieved_mu: np.ndarray, judged: np.ndarray,
               tolerance_mu: float = DEPARTURE_TOLERANCE_MU) -> np.ndarray:
    """True for the ``judged`` blocks where ``|felt_mu - achieved_mu| > tolerance_mu`` (NaN counts as departed)."""
    return judged & ~(np.abs(felt_mu - achieved_mu) <= tolerance_mu)


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
