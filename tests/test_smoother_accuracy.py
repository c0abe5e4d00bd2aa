"""Issue 8's acceptances 1 and 2 on simulated flights with truth: every scenario, with and
without each fault (seed 0; ``benchmarks/smoother_accuracy.py`` runs more seeds)."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

import pytest

from accuracy import Flight, best_other, flights, label, measure

FLIGHTS = flights([0])


@pytest.fixture(scope="module")
def rows() -> dict[Flight, dict[str, float]]:
    with ProcessPoolExecutor(2) as pool:
        return dict(zip(FLIGHTS, pool.map(measure, FLIGHTS), strict=True))


def test_the_smoother_has_the_lowest_rmse_on_every_flight(
    rows: dict[Flight, dict[str, float]],
) -> None:
    """Measured (seed 0, 64 flights): smoother 0.015-0.472 m, best other 0.135-1.469 m; lowest on
    all 64, the closest the hover with its barometer 7 % high, 0.472 against support's 0.505.
    The mission with that barometer was the one loss until the smoother learnt the scale the
    datum cannot tell over 15 m (0.892 m against mean's 0.525; now 0.038)."""
    behind = {
        label(f): f"{row['smoother']:.3f} vs {row[best_other(row)]:.3f} {best_other(row)}"
        for f, row in rows.items()
        if row["smoother"] >= row[best_other(row)]
    }
    assert not behind, behind


def test_fused_std_is_calibrated(rows: dict[Flight, dict[str, float]]) -> None:
    """90-98 % of the true errors within +-2 sigma over all the flights' ticks (measured 0.949;
    per flight it ranges from 0.17 on the hover with its barometer 7 % high to 1.00)."""
    inside = sum(row["inside"] for row in rows.values())
    ticks = sum(row["ticks"] for row in rows.values())
    assert 0.90 <= inside / ticks <= 0.98
