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


#: The flights where the smoother is known not to be the best, and why (issue 15, open).
KNOWN_LOSSES = {
    # a barometer 7 % high on a flight of 15 m: the datum cannot tell its scale against a
    # wandering GPS (1.084 +- 0.030), and the smoother trusts the barometer's stability over
    # the GPS's: 0.892 m against mean's 0.525 (seeds 1 and 2 alike)
    "mission seed 0 baro-scale",
}


def test_the_smoother_has_the_lowest_rmse_on_every_flight_but_the_known_losses(
    rows: dict[Flight, dict[str, float]],
) -> None:
    """Measured (seed 0, 53 flights): smoother 0.013-0.892 m, best other 0.136-1.476 m;
    lowest on 52, the closest of those the hover with its barometer 7 % high, 0.523 against
    support's 0.529."""
    behind = {
        label(f): f"{row['smoother']:.3f} vs {row[best_other(row)]:.3f} {best_other(row)}"
        for f, row in rows.items()
        if row["smoother"] >= row[best_other(row)]
    }
    assert set(behind) == KNOWN_LOSSES, behind


def test_fused_std_is_calibrated(rows: dict[Flight, dict[str, float]]) -> None:
    """90-98 % of the true errors within +-2 sigma over all the flights' ticks (measured 0.930;
    per flight it ranges from 0.18 on the hover with its barometer 7 % high to 1.00)."""
    inside = sum(row["inside"] for row in rows.values())
    ticks = sum(row["ticks"] for row in rows.values())
    assert 0.90 <= inside / ticks <= 0.98
