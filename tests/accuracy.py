"""Every method's error on simulated flights with truth: the measure behind issue 8's claims.

A flight (scenario, seed, faults) is simulated, written as a DataFlash log, read back and fused
by every method as ``altfuse fuse`` would; each method's RMSE [m] is against the SIM truth,
referred to take-off as ``altfuse evaluate`` does. For the smoother also how many ticks' true
errors lie within its +-2 ``fused_std``. Used by ``tests/test_smoother_accuracy.py`` and
``benchmarks/smoother_accuracy.py``: a measurement, not part of the package.
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from altfuse.evaluation import choose_truth
from altfuse.fuse import METHODS
from altfuse.io import read_log
from altfuse.pipeline import FuseOptions, prepare, run_method
from altfuse.simulate import FAULTS, SCENARIOS, simulate_flight, write_simulated_log

Flight = tuple[str, int, tuple[str, ...]]


def flights(seeds: Sequence[int]) -> list[Flight]:
    """Every scenario with each seed: without fault, with each fault, and the mission with a
    GPS glitch and a rangefinder dropout together."""
    out: list[Flight] = []
    for seed in seeds:
        out += [(s, seed, ()) for s in SCENARIOS]
        out += [(s, seed, (f,)) for s in SCENARIOS for f in FAULTS]
        out.append(("mission", seed, ("gps-glitch", "rangefinder-dropout")))
    return out


def measure(flight: Flight) -> dict[str, float]:
    """Each method's RMSE on one simulated flight, and the smoother's ``inside`` (ticks within
    +-2 sigma) of ``ticks``."""
    scenario, seed, faults = flight
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "flight.bin"
        write_simulated_log(simulate_flight(scenario, seed, faults=faults), path)
        prepared = prepare(read_log(path), FuseOptions())
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
    return row


def best_other(row: dict[str, float]) -> str:
    """The method other than the smoother with the lowest RMSE in a :func:`measure` row."""
    return min((m for m in METHODS if m != "smoother"), key=lambda m: row[m])


def label(flight: Flight) -> str:
    scenario, seed, faults = flight
    return f"{scenario} seed {seed}" + (f" {'+'.join(faults)}" if faults else "")
