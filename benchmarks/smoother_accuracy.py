"""Every method's error on simulated flights with truth (issue 8, acceptances 1 and 2).

Run on demand:  python benchmarks/smoother_accuracy.py [--seeds 0 1 2] [--jobs 2]

Flights: every ``altfuse simulate`` scenario with each seed and no fault, and each scenario with
each fault (and the mission with a GPS glitch and a rangefinder dropout together) at the first
seed. Each is written as a log, read back and fused by every method as ``altfuse fuse`` would;
the RMSE [m] is against the SIM truth, referred to take-off as ``altfuse evaluate`` does. For the
smoother also the share of ticks whose true error lies within its +-2 sigma (``cover``).
Prints one row per flight, and a last line: on how many flights the smoother has the lowest RMSE,
and its pooled coverage.
"""

from __future__ import annotations

import argparse
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from altfuse.evaluate import choose_truth
from altfuse.fuse import FUSERS
from altfuse.io import read_log
from altfuse.pipeline import FuseOptions, prepare, run_method
from altfuse.simulate import FAULTS, SCENARIOS, simulate_flight, write_simulated_log

Case = tuple[str, int, tuple[str, ...]]


def cases(seeds: list[int]) -> list[Case]:
    out: list[Case] = [(s, seed, ()) for s in SCENARIOS for seed in seeds]
    out += [(s, seeds[0], (f,)) for s in SCENARIOS for f in FAULTS]
    out.append(("mission", seeds[0], ("gps-glitch", "rangefinder-dropout")))
    return out


def measure(case: Case) -> dict[str, float]:
    """RMSE of every method on one simulated flight; the smoother's +-2 sigma coverage."""
    scenario, seed, faults = case
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "flight.bin"
        write_simulated_log(simulate_flight(scenario, seed, faults=faults), path)
        prepared = prepare(read_log(path), FuseOptions())
    truth = choose_truth(prepared.log, prepared.referred).h
    row: dict[str, float] = {}
    for method in FUSERS:
        result = run_method(prepared, FuseOptions(method=method)).result
        error = result.fused - truth
        ok = np.isfinite(error)
        row[method] = float(np.sqrt(np.mean(error[ok] ** 2)))
        if method == "smoother":
            std = result.tick_traces["fused_std"][ok]
            row["inside"] = float(np.sum(np.abs(error[ok]) <= 2 * std))
            row["ticks"] = float(ok.sum())
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    todo = cases(args.seeds)
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(measure, todo))
    others = [m for m in FUSERS if m != "smoother"]
    print(f"{'flight':44s} {'smoother':>8s} {'cover':>6s}  best other")
    wins, inside, ticks = 0, 0.0, 0.0
    for (scenario, seed, faults), row in zip(todo, rows, strict=True):
        best = min(others, key=lambda m: row[m])
        wins += row["smoother"] < row[best]
        inside, ticks = inside + row["inside"], ticks + row["ticks"]
        label = f"{scenario} seed {seed}" + (f" {'+'.join(faults)}" if faults else "")
        print(
            f"{label:44s} {row['smoother']:8.3f} {row['inside'] / row['ticks']:6.3f}  "
            f"{row[best]:.3f} {best}"
        )
    print(
        f"smoother lowest on {wins} of {len(todo)} flights; within +-2 sigma {inside / ticks:.3f}"
    )


if __name__ == "__main__":
    main()
