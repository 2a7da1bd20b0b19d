"""The running distribution behind the Renderer's whole-run latency: percentiles within half a bin of the value
of their rank, in fixed memory."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tpad_rt.log_histogram import LogHistogram


def _nearest_rank(values: np.ndarray, q: float) -> float:
    return float(np.sort(values)[max(math.ceil(q / 100 * len(values)), 1) - 1])


@pytest.mark.parametrize("q", [0, 1, 50, 99, 100])
def test_a_percentile_is_within_half_a_bin_of_the_value_of_its_rank(q: float) -> None:
    values = np.random.default_rng(7).lognormal(mean=-1.0, sigma=1.5, size=5000)  # ms, spanning decades
    histogram = LogHistogram(1e-3, 1e4)
    for chunk in np.array_split(values, 7):  # added in pieces, as drains come
        histogram.add(chunk)
    assert histogram.count == len(values)
    assert histogram.percentile(q) == pytest.approx(_nearest_rank(values, q), rel=10 ** (1 / 200) - 1)


def test_values_outside_the_range_count_at_its_ends_and_nan_in_none() -> None:
    histogram = LogHistogram(1.0, 100.0, bins_per_decade=10)
    histogram.add([0.0, -3.0, 1e-9, 5e6, math.inf, math.nan])
    assert histogram.count == 5
    assert histogram.percentile(50) == pytest.approx(10 ** 0.05)  # the first bin's middle
    assert histogram.percentile(100) == pytest.approx(10 ** 1.95)  # the last bin's


def test_empty_is_nan_and_bad_bounds_are_refused() -> None:
    assert math.isnan(LogHistogram(1.0, 2.0).percentile(50))
    for low, high, bins in ((0.0, 1.0, 10), (2.0, 1.0, 10), (1.0, math.inf, 10), (1.0, 2.0, 0)):
        with pytest.raises(ValueError, match="LogHistogram"):
            LogHistogram(low, high, bins)


def test_a_percentile_outside_0_to_100_is_refused() -> None:
    """q = 150 read one bin past the last (an answer above ``high``); q < 0 and NaN are no percentile either, even
    of an empty histogram."""
    histogram = LogHistogram(1e-6, 1.0)
    histogram.add([1e-3])
    for q in (150.0, 100.000001, -1.0, math.nan):
        for tested in (histogram, LogHistogram(1e-6, 1.0)):
            with pytest.raises(ValueError, match=r"q must be in \[0, 100\]"):
                tested.percentile(q)
    assert histogram.percentile(0.0) == histogram.percentile(100.0) == pytest.approx(1e-3, rel=0.012)
