"""altfuse's not-a-knot cubic spline against scipy's ``CubicSpline`` (its default ends), which it
replaces on the fuse path (scipy.interpolate's import alone is 0.2-0.36 s)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from altfuse.spline import cubic_spline


@pytest.mark.parametrize("n", [2, 3, 4, 5, 12, 500])
@pytest.mark.parametrize("spacing", ["uniform", "irregular", "clustered"])
def test_it_is_scipys_cubic_spline(n: int, spacing: str) -> None:
    rng = np.random.default_rng(n)
    steps = {
        "uniform": np.full(n - 1, 0.1),
        "irregular": rng.uniform(0.01, 0.5, n - 1),
        "clustered": rng.choice([1e-3, 1.0], n - 1),  # samples 1 ms apart beside 1 s gaps
    }[spacing]
    x = 1000.0 + np.concatenate(([0.0], np.cumsum(steps)))
    y = 50 * np.sin(x / 3) + rng.normal(0, 0.5, n)
    # between the knots, on them, and a tick's width beyond the ends (extrapolated)
    at = np.concatenate((np.linspace(x[0] - 0.05, x[-1] + 0.05, 3 * n), x))
    expected = CubicSpline(x, y)(at)
    np.testing.assert_allclose(cubic_spline(x, y, at), expected, rtol=0, atol=1e-9 * np.ptp(y))


def test_it_needs_two_knots() -> None:
    with pytest.raises(ValueError, match="two knots"):
        cubic_spline(np.array([1.0]), np.array([2.0]), np.array([1.0]))
