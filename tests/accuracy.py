"""Every method's error on simulated flights with truth: the measure behind issue 8's claims.

A flight (scenario, seed, faults) is simulated, written as a DataFlash log, read back and fused
by every method as ``altfuse fuse`` would; each method's RMSE [m] is against the SIM truth,
referred to take-off as ``altfuse evaluate`` does. For the smoother also how many ticks' true
errors lie within its +-2 ``fused_std``. Used by ``tests/test_smoother_accuracy.py`` and
``benchmarks/smoother_accuracy.py``: a measurement, not part of the package.
"""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from altfuse.evaluation import Evaluation, choose_truth
from altfuse.fuse import METHODS
from altfuse.fuse.base import DIVERGED
from altfuse.io import read_log
from altfuse.pipeline import FuseOptions, Prepared, prepare, run_method
from altfuse.simulate import (
    SCENARIOS,
    applicable_faults,
    simulate_flight,
    write_simulated_log,
)

Flight = tuple[str, int, tuple[str, ...]]
ROOT = Path(__file__).resolve().parents[1]
#: The project's bar on a +-2 sigma band: the share of the true errors it covers.
COVERAGE_WINDOW = (0.90, 0.99)


def flights(seeds: Sequence[int]) -> list[Flight]:
    """Every scenario with each seed: without fault, with each fault, and the mission with a
    GPS glitch and a rangefinder dropout together."""
    out: list[Flight] = []
    for seed in seeds:
        out += [(s, seed, ()) for s in SCENARIOS]
        out += [(s, seed, (f,)) for s in SCENARIOS for f in applicable_faults(s)]
        out.append(("mission", seed, ("gps-glitch", "rangefinder-dropout")))
    return out


def prepared_flight(flight: Flight) -> Prepared:
    """One simulated flight written as a DataFlash log, read back and prepared as
    ``altfuse fuse`` would."""
    scenario, seed, faults = flight
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "flight.bin"
        write_simulated_log(simulate_flight(scenario, seed, faults=faults), path)
        return prepare(read_log(path), FuseOptions())


def arguments(description: str) -> argparse.ArgumentParser:
    """The options of a benchmark over the truth logs and the simulated flights: where the
    shared logs are, the flights' seeds, the processes."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "logs")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--jobs", type=int, default=2)
    return parser


def measure(flight: Flight) -> dict[str, float]:
    """Each method's RMSE on one simulated flight, and the smoother's ``inside`` (ticks within
    +-2 sigma) of ``ticks``, its ``diverged`` ticks (the guard's flags) and its largest true
    error among them (``diverged_error``, 0 without)."""
    prepared = prepared_flight(flight)
    truth = choose_truth(prepared.log, prepared.referred).h
    row: dict[str, float] = {}
    for method in METHODS:
        result = run_method(prepared, FuseOptions(method=method)).result
        error = result.fused - truth
        ok = np.isfinite(error)
        row[method] = float(np.sqrt(np.mean(error[ok] ** 2)))
        if method == "smoother":
            std = result.tick_traces["fused_std"][ok]
            row["inside"] = float(np.sum(np.abs(error[ok]) <= 2 * std))
            row["ticks"] = float(ok.sum())
            flagged = ok & (result.status == DIVERGED)
            row["diverged"] = float(flagged.sum())
            row["diverged_error"] = float(np.max(np.abs(error[flagged]), initial=0.0))
    return row


def best_other(row: dict[str, float]) -> str:
    """The method other than the smoother with the lowest RMSE in a :func:`measure` row."""
    return min((m for m in METHODS if m != "smoother"), key=lambda m: row[m])


def label(flight: Flight) -> str:
    scenario, seed, faults = flight
    return f"{scenario} seed {seed}" + (f" {'+'.join(faults)}" if faults else "")


def window_counts(covers: np.ndarray) -> tuple[int, int, int]:
    """How many of the coverages ``covers`` lie within COVERAGE_WINDOW, above it, below it."""
    lo, hi = COVERAGE_WINDOW
    within = int(np.sum((covers >= lo) & (covers <= hi)))
    return within, int(np.sum(covers > hi)), int(np.sum(covers < lo))


def verdict(evaluation: Evaluation, method: str) -> dict[str, object]:
    """Whether ``method`` passes on the log of ``evaluation`` (the project's bar, per log):
    RMSE <= the best single sensor's + max(3 cm, 10 %), maximum error <= max(2x, +0.10 m)
    that sensor's, +-2 sigma coverage of the true errors in [0.90, 0.99], and an RMSE below
    the onboard EKF's (where the log has one); ``share_of_bar``: the larger of RMSE and maximum
    error as a share of its bar."""
    rows = {r.name: r for r in evaluation.rows}
    sensors = [r for r in evaluation.rows if r.kind == "sensor"]
    best = min(sensors, key=lambda r: r.overall.rmse)
    mine = rows[method].overall
    cover = mine.within_2std
    ekf = rows["ekf"].overall.rmse if "ekf" in rows and rows["ekf"].kind == "onboard" else None
    rmse_bar = best.overall.rmse + max(0.03, 0.1 * best.overall.rmse)
    max_bar = max(2 * best.overall.max_abs, best.overall.max_abs + 0.10)
    checks = {
        "rmse": mine.rmse <= rmse_bar,
        "max": mine.max_abs <= max_bar,
        "coverage": COVERAGE_WINDOW[0] <= cover <= COVERAGE_WINDOW[1],
        "ekf": ekf is None or mine.rmse < ekf,
    }
    return {
        "rmse": mine.rmse,
        "max": mine.max_abs,
        "coverage": cover,
        "best": best.name,
        "best_rmse": best.overall.rmse,
        # the larger of RMSE and maximum error as a share of its bar (above 1: over it)
        "share_of_bar": max(mine.rmse / rmse_bar, mine.max_abs / max_bar),
        "ekf_rmse": ekf,
        "fails": [k for k, ok in checks.items() if not ok],
    }
