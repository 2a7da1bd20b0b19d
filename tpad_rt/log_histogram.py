"""A running distribution of positive values in fixed memory: a histogram of log-spaced bins.

API map
-------
LogHistogram(low, high, bins_per_decade=BINS_PER_DECADE)
    ``add(values)``, ``percentile(q) -> float`` (q in [0, 100], else ValueError; NaN while empty), ``count``

Percentiles of a whole run (push-to-output latency over every block: tpad_rt.telemetry) without keeping
its values: a value lands in the bin ``[low * 10**(k / bins_per_decade), low * 10**((k + 1) / bins_per_decade))``,
and a percentile is the geometric middle of the bin the value of that rank lies in, so it is within half a
bin's ratio of the value (1.2 % at 100 bins a decade). Values below ``low`` count in the first bin, above
``high`` in the last, NaN in none.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

#: Bins per decade by default: a percentile within 10 ** (1 / 200) - 1 = 1.2 % of the value of its rank.
BINS_PER_DECADE = 100


class LogHistogram:
    """Counts of values in log-spaced bins from ``low`` to ``high`` (same unit, ``0 < low < high``), at
    ``bins_per_decade`` (>= 1) bins per decade. Raises ValueError for other bounds. Not thread-safe."""

    def __init__(self, low: float, high: float, bins_per_decade: int = BINS_PER_DECADE):
        if not (0 < low < high < math.inf) or bins_per_decade < 1:
            raise ValueError(f"LogHistogram: need 0 < low < high and bins_per_decade >= 1, got {low}, {high}, "
                             f"{bins_per_decade}")
        self._low_log10 = math.log10(low)
        self._bins_per_decade = bins_per_decade
        self._counts = np.zeros(math.ceil((math.log10(high) - self._low_log10) * bins_per_decade), dtype=np.int64)

    @property
    def count(self) -> int:
        """Values added so far (NaN not counted)."""
        return int(self._counts.sum())

    def add(self, values: npt.ArrayLike) -> None:
        """Count ``values`` (any shape; NaN is skipped, values outside ``[low, high]`` go to the end bins)."""
        values = np.asarray(values, dtype=np.float64).ravel()
        values = values[~np.isnan(values)]
        if not len(values):
            return
        with np.errstate(divide="ignore", invalid="ignore"):  # 0 and negative values: -inf or NaN, the first bin
            position = (np.log10(values) - self._low_log10) * self._bins_per_decade
        bins = np.clip(np.nan_to_num(position, nan=0.0, neginf=0.0, posinf=len(self._counts)), 0,
                       len(self._counts) - 1).astype(np.int64)
        self._counts += np.bincount(bins, minlength=len(self._counts))

    def percentile(self, q: float) -> float:
        """The ``q``-th percentile (0 to 100) of the values added: the geometric middle of the bin holding the
        value of rank ``ceil(q / 100 * count)`` (the smallest for q = 0); NaN when none was added.
        Raises ValueError for a ``q`` outside [0, 100] (or NaN)."""
        if not 0.0 <= q <= 100.0:
            raise ValueError(f"LogHistogram.percentile: q must be in [0, 100], got {q}")
        total = self.count
        if total == 0:
            return math.nan
        rank = max(math.ceil(q / 100 * total), 1)
        index = int(np.searchsorted(np.cumsum(self._counts), rank))
        return float(10 ** (self._low_log10 + (index + 0.5) / self._bins_per_decade))
