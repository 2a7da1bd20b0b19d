"""The last check before drive samples are stored: finite and within full scale.

The renderer never produces anything else; a sample that is not is a bug in tpad-rt,
and the writers (``wav://``, recordings) refuse it instead of storing it.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def first_bad_sample(samples: npt.NDArray[np.floating]) -> int | None:
    """Index of the first sample of 1-D ``samples`` that is NaN, infinite or beyond full scale (|x| > 1), else None."""
    within = np.abs(samples) <= 1.0  # False for NaN
    return None if within.all() else int(np.argmin(within))


def bad_sample_message(index: int, value: float) -> str:
    """Why drive sample ``index`` (holding ``value``) is refused, and that it is a bug to report."""
    problem = "not finite" if not np.isfinite(value) else "beyond full scale (|sample| > 1)"
    return (
        f"drive sample {index} is {value!r}, {problem}: the drive held a value no output may carry; "
        "this is a bug in tpad-rt, please report it"
    )
