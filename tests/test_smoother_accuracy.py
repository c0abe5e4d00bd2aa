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
    """Measured (seed 0, 28 flights): smoother 0.014-0.456 m, best other 0.158-1.341 m;
    closest: hover with the barometer lost, 0.456 against 0.665."""
    behind = [
        f"{label(f)}: {row['smoother']:.3f} vs {row[best_other(row)]:.3f} {best_other(row)}"
        for f, row in rows.items()
        if row["smoother"] >= row[best_other(row)]
    ]
    assert not behind, behind


def test_fused_std_is_calibrated(rows: dict[Flight, dict[str, float]]) -> None:
    """90-98 % of the true errors within +-2 sigma over all the flights' ticks (measured 0.975;
    per flight it ranges from 0.53 on paper-a without rangefinder to 1.00 on hover)."""
    inside = sum(row["inside"] for row in rows.values())
    ticks = sum(row["ticks"] for row in rows.values())
    assert 0.90 <= inside / ticks <= 0.98
