"""The running statistics of :mod:`altfuse.metrics` against pandas' rolling windows, which they
replace on the fuse path (pandas' import alone is 0.3 s of a 1.3 s run)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from altfuse.metrics import hold_nearest, running_median, running_sum, samples_in

WINDOWS = [(w, m) for w in (1, 2, 3, 4, 5, 8, 51, 250) for m in (1, 3) if m <= w]


@pytest.mark.parametrize("n", [0, 1, 3, 7, 200])
@pytest.mark.parametrize(("window", "min_periods"), WINDOWS)
def test_running_median_is_pandas_centred_rolling_median(
    n: int, window: int, min_periods: int
) -> None:
    rng = np.random.default_rng(n * 1000 + window)
    x = rng.normal(size=n)
    x[rng.random(n) < 0.2] = np.nan
    expected = pd.Series(x, dtype=float).rolling(window, center=True, min_periods=min_periods)
    np.testing.assert_array_equal(running_median(x, window, min_periods), expected.median())


@pytest.mark.parametrize("window", [1, 2, 5, 20, 51])
def test_running_sum_is_pandas_centred_rolling_sum_without_drift(window: int) -> None:
    rng = np.random.default_rng(window)
    x = rng.normal(size=500)
    expected = pd.Series(x).rolling(window, center=True, min_periods=1).sum().to_numpy()
    np.testing.assert_allclose(running_sum(x, window), expected, rtol=1e-12, atol=1e-12)
    # a flight's times squared: each window summed afresh, no running total's rounding
    t = np.arange(300_000) * 0.1 + 1e3
    got = running_sum(t * t, 20)[150_000]
    assert got == pytest.approx(np.sum((t[149_990:150_010]) ** 2), rel=1e-14)


def test_hold_nearest_fills_forward_then_backward() -> None:
    x = np.array([np.nan, np.nan, 1.0, np.nan, 3.0, np.nan])
    np.testing.assert_array_equal(hold_nearest(x), [1.0, 1.0, 1.0, 1.0, 3.0, 3.0])
    np.testing.assert_array_equal(hold_nearest(np.full(3, np.nan)), np.full(3, np.nan))
    rng = np.random.default_rng(0)
    y = rng.normal(size=100)
    y[rng.random(100) < 0.4] = np.nan
    np.testing.assert_array_equal(hold_nearest(y), pd.Series(y).ffill().bfill().to_numpy())


@pytest.mark.parametrize(
    ("span_s", "step", "most", "expected"),
    [
        (5.0, 0.1, 1000, 50),
        (5.0, 0.1, 20, 20),  # more than there are
        (5.0, 5e-324, 1000, 1000),  # stamps a denormal apart: 5 / step is infinite
        (5.0, 0.0, 1000, 1000),  # none apart
        (5.0, -0.1, 1000, 1000),  # stamps going back
    ],
)
def test_samples_in_a_span_never_overflow_nor_exceed_the_samples(
    span_s: float, step: float, most: int, expected: int
) -> None:
    """A damaged log's stamps, a denormal apart, made ``round(5 / step)`` raise an
    OverflowError in the smoother's noise window (the long fuzz run: exit 3)."""
    assert samples_in(span_s, step, most) == expected
