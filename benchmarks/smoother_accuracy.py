"""Every method's error on simulated flights with truth (issue 8, acceptances 1 and 2).

Run on demand:  python benchmarks/smoother_accuracy.py [--seeds 0 1 2] [--jobs 2]

Flights (``tests/accuracy.py``'s ``flights``): every ``altfuse simulate`` scenario with each seed,
without fault, with each fault, and the mission with a GPS glitch and a rangefinder dropout
together. Prints one row per flight (the smoother's RMSE [m], the share of its ticks whose true
error lies within +-2 sigma, the best other method), then: on how many flights the smoother
has the lowest RMSE, and its pooled coverage; the worst case per flight (its largest RMSE
against the best other method's, its lowest and highest coverage, and on how many flights the
coverage lies within 0.90-0.99, above, below); and the flights where the guard flagged it
``diverged``, with its true error at those ticks (where that is small, a false alarm: the guard
compares with the sensors' raw readings).
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from accuracy import best_other, flights, label, measure, window_counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    todo = flights(args.seeds)
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(measure, todo))
    print(f"{'flight':46s} {'smoother':>8s} {'cover':>6s}  best other")
    wins, inside, ticks = 0, 0.0, 0.0
    for flight, row in zip(todo, rows, strict=True):
        best = best_other(row)
        wins += row["smoother"] < row[best]
        inside, ticks = inside + row["inside"], ticks + row["ticks"]
        print(
            f"{label(flight):46s} {row['smoother']:8.3f} {row['inside'] / row['ticks']:6.3f}  "
            f"{row[best]:.3f} {best}"
        )
    print(
        f"smoother lowest on {wins} of {len(todo)} flights; within +-2 sigma {inside / ticks:.3f}"
    )
    # the worst case per flight: the smoother's RMSE against the best other method's, and
    # its band's coverage against 0.90-0.99
    by_label = {label(f): row for f, row in zip(todo, rows, strict=True)}
    ratio = {name: row["smoother"] / row[best_other(row)] for name, row in by_label.items()}
    cover = {name: row["inside"] / row["ticks"] for name, row in by_label.items()}
    worst = max(ratio, key=ratio.__getitem__)
    low, high = min(cover, key=cover.__getitem__), max(cover, key=cover.__getitem__)
    within, above, below = window_counts(np.array(list(cover.values())))
    print(
        f"worst RMSE ratio to the best other: {ratio[worst]:.2f} ({worst}); coverage "
        f"{cover[low]:.3f} ({low}) to {cover[high]:.3f} ({high}): within 0.90-0.99 on "
        f"{within}, above on {above}, below on {below}"
    )
    # the guard's flags where the truth is known: a flag where the error is small is a false alarm
    flagged = {name: row for name, row in by_label.items() if row["diverged"]}
    errors = [row["diverged_error"] for row in flagged.values()]
    print(
        f"flagged diverged on {len(flagged)} flights"
        + (
            f", the true error at the flagged ticks {min(errors):.2f}-{max(errors):.2f} m"
            if errors
            else ""
        )
        + "".join(
            f"\n  {name}: {row['diverged']:.0f} ticks, true error up to "
            f"{row['diverged_error']:.2f} m"
            for name, row in flagged.items()
        )
    )


if __name__ == "__main__":
    main()
