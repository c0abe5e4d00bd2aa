"""The smoother's +-2 sigma coverage against the truth for a range of ``timing_sigma_s`` (the
sensors' unknown common latency, ``TIMING_SIGMA_S``): the measurement behind its default.

Run on demand:  python benchmarks/timing_sigma.py [--shared ../shared/logs] [--seeds 0 1 2]
[--jobs 2]

The latency's term changes ``fused_std`` alone (the estimate does not move), so each log is
fused once without it and the term added for every value, at the smoothed vertical velocity.
Logs: the 13
in ``../shared/logs/truth`` (ArduPilot SITL, truth ``SIM.Alt``) and the simulated flights of
``tests/accuracy.py`` (every scenario and fault, ``--seeds``). Per value, for each group: the
coverage's range, how many logs lie within 0.90-0.99, above and below, and the worst distance
out of that window; then each truth log's coverage per value; last, the truth logs' ticks split
by the truth's climb rate (SPEED_BINS_M_S), with the default latency: the errors' RMS over the
band's sigma and the share within +-2 sigma, pooled and per log (where a log has MIN_BIN_TICKS
there).
"""

from __future__ import annotations

import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import NamedTuple

import numpy as np

from altfuse.evaluation import choose_truth
from altfuse.fuse.smoother import TIMING_SIGMA_S, SmootherParams, fused_std
from altfuse.io import read_log
from altfuse.pipeline import FuseOptions, Prepared, prepare, run_method

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from accuracy import (  # noqa: E402
    COVERAGE_WINDOW,
    Flight,
    arguments,
    flights,
    label,
    prepared_flight,
    window_counts,
)
from altfuse.metrics import coverage  # noqa: E402

GRID_S = (0.0, 0.002, 0.003, 0.004, 0.005, 0.006, 0.008, 0.010)
#: The smoothed climb rate [m/s] beyond which a tick is climbing (or descending).
CLIMBING_M_S = 0.5
#: The truth's climb rates [m/s] the ticks are split by (from its changes over a tick: a hover,
#: a slow rise, a climb), and the fewest ticks a log's share of a bin is measured on.
SPEED_BINS_M_S = ((0.0, 0.2), (0.2, 1.0), (1.0, np.inf))
MIN_BIN_TICKS = 20


class Measured(NamedTuple):
    """One log: its coverage for each value of GRID_S, the fused height's latency behind the
    truth where it climbs [s] and those ticks' coverage at the default, and at every tick with
    a truth and a band the truth's climb rate [m/s] and the error over the default band."""

    name: str
    row: list[float]
    latency: float
    climbs: float
    speed: np.ndarray
    z: np.ndarray


def coverages(name: str, prepared: Prepared) -> Measured:
    """The coverage of the truth by the band of one run without the latency's term, that term
    added for every value of GRID_S (:func:`altfuse.fuse.smoother.fused_std`); and over the
    ticks whose smoothed climb rate exceeds CLIMBING_M_S, the fused height's latency behind
    the truth [s] (the least-squares fit of its error to minus that rate, with a constant: the
    truth's own rate, from whole centimetres at 10 Hz, is too noisy a regressor) and their
    coverage with the default term; the errors over the default band, by the truth's rate."""
    truth = choose_truth(prepared.log, prepared.referred, "sim").h
    exact = FuseOptions(params={"smoother": SmootherParams(timing_sigma_s=0.0)})
    result = run_method(prepared, exact).result
    var_h, v = result.tick_traces["fused_std"] ** 2, result.tick_traces["velocity"]
    error = result.fused - truth
    climbing = np.isfinite(error) & np.isfinite(v) & (np.abs(v) > CLIMBING_M_S)
    fit = np.column_stack([np.ones(int(climbing.sum())), -v[climbing]])
    latency = float(np.linalg.lstsq(fit, error[climbing], rcond=None)[0][1])
    band = fused_std(var_h, v, TIMING_SIGMA_S)
    climbs = coverage(error[climbing], band[climbing])
    rate = np.abs(np.gradient(truth, prepared.referred.t))
    both = np.isfinite(error) & np.isfinite(band) & np.isfinite(rate)
    row = [coverage(error, fused_std(var_h, v, s)) for s in GRID_S]
    return Measured(name, row, latency, climbs, rate[both], error[both] / band[both])


def truth_log(path: Path) -> Measured:
    return coverages(path.stem, prepare(read_log(path), FuseOptions()))


def simulated(flight: Flight) -> Measured:
    return coverages(label(flight), prepared_flight(flight))


def by_speed(logs: list[Measured]) -> None:
    """The errors over the default band per bin of the truth's climb rate: RMS and share within
    +-2 sigma, pooled over ``logs`` and their range over the logs with MIN_BIN_TICKS there."""
    print(f"errors over the band at {TIMING_SIGMA_S * 1000:g} ms by the truth's climb rate:")
    for lo, hi in SPEED_BINS_M_S:
        parts = [m.z[(m.speed >= lo) & (m.speed < hi)] for m in logs]
        parts = [z for z in parts if z.size >= MIN_BIN_TICKS]
        if not parts:
            continue
        pooled = np.concatenate(parts)
        rms = [float(np.sqrt(np.mean(z**2))) for z in parts]
        within = [float(np.mean(np.abs(z) <= 2.0)) for z in parts]
        print(
            f"  {lo:g}-{hi:g} m/s: {pooled.size} ticks ({len(parts)} logs), RMS "
            f"{np.sqrt(np.mean(pooled**2)):.2f} ({min(rms):.2f}-{max(rms):.2f}), within +-2 sigma "
            f"{np.mean(np.abs(pooled) <= 2.0):.3f} ({min(within):.3f}-{max(within):.3f})"
        )


def summary(name: str, rows: list[Measured]) -> None:
    c = np.array([r.row for r in rows])
    lo, hi = COVERAGE_WINDOW
    print(f"{name}: {len(rows)} logs")
    for j, s in enumerate(GRID_S):
        col = c[:, j]
        out = np.maximum(lo - col, col - hi).clip(0.0)
        within, above, below = window_counts(col)
        print(
            f"  {s * 1000:4.0f} ms: coverage {col.min():.3f}-{col.max():.3f}, within "
            f"{within}, above {above}, below {below}, worst {out.max():.3f} out of the window"
        )


def main() -> None:
    args = arguments(__doc__.splitlines()[0]).parse_args()
    with ProcessPoolExecutor(args.jobs) as pool:
        truth = list(pool.map(truth_log, sorted((args.shared / "truth").glob("*.BIN"))))
        sims = list(pool.map(simulated, flights(args.seeds)))
    summary("truth logs", truth)
    summary("simulated flights", sims)
    print(
        "per truth log, coverage at " + ", ".join(f"{s * 1000:g}" for s in GRID_S) + " ms; the "
        f"fused height's latency behind SIM.Alt where it climbs faster than {CLIMBING_M_S} m/s, "
        f"and those ticks' coverage at {TIMING_SIGMA_S * 1000:g} ms:"
    )
    for m in truth:
        print(
            f"  {m.name:56s} "
            + " ".join(f"{x:.3f}" for x in m.row)
            + f"  latency {m.latency * 1000:5.1f} ms, climbs {m.climbs:.3f}"
        )
    by_speed(truth)


if __name__ == "__main__":
    main()
