"""The smoother against the correlation time of its GPS's bounded error
(``GPS_CORRELATION_S``, ``--gps-correlation``): the measurement behind its default.

Run on demand:  python benchmarks/gps_bound.py [--shared ../shared/logs] [--seeds 0 1 2]
[--jobs 2]

For each value of GRID_S (the last, 1e6 s, a random walk over any flight):

- a long flight, 45 minutes of a real 150 s flight repeated (``tests/repeated.py``, from
  ``beastayyg_log_0036``): the largest gap between the fused height and the nearest sensor
  (the guard's ``max_excursion_m``), the ticks it flags ``diverged`` and the largest
  ``fused_std``; GPS and barometer agree within a metre there, but for the crashes;
- the 13 truth logs in ``../shared/logs/truth``: the smoother's RMSE, maximum error and
  coverage, and how many pass the project's bar (``tests/accuracy.py``'s ``verdict``);
- the simulated flights of ``tests/accuracy.py`` (every scenario and fault, ``--seeds``; their
  GPS wanders as a random walk): the smoother's RMSE against the random walk's, its median and
  worst ratio, and the coverage within 0.90-0.99, above and below.

Each log is read and prepared once; only the smoother runs again per value.
"""

from __future__ import annotations

import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from altfuse.evaluation import choose_truth, evaluate_prepared
from altfuse.fuse.smoother import SmootherParams
from altfuse.io import read_log
from altfuse.pipeline import FuseOptions, Prepared, prepare, run_method

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from accuracy import (  # noqa: E402
    Flight,
    arguments,
    flights,
    prepared_flight,
    verdict,
    window_counts,
)
from altfuse.metrics import coverage  # noqa: E402
from repeated import repeated_log  # noqa: E402

GRID_S = (300.0, 600.0, 1200.0, 3600.0, 1e6)
LONG_SOURCE = "ardupilot/beastayyg_log_0036_mechanical_failure.bin"


def options(tau: float) -> FuseOptions:
    return FuseOptions(params={"smoother": SmootherParams(gps_correlation_s=tau)})


def long_flight(shared: Path) -> list[tuple[float, int, float]]:
    """Per value: the largest gap to the nearest sensor [m], the diverged ticks and the
    largest fused_std [m] on the 45-minute flight."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "long.bin"
        repeated_log(shared / LONG_SOURCE, path, 30)
        prepared = prepare(read_log(path), FuseOptions())
    out = []
    for tau in GRID_S:
        run = run_method(prepared, options(tau))
        guard = run.provenance["guard"]
        std = float(np.nanmax(run.result.tick_traces["fused_std"]))
        out.append((guard["max_excursion_m"], guard["diverged_ticks"], std))
    return out


def truth_log(path: Path) -> tuple[str, list[tuple[float, float, float, bool]]]:
    """Per value: the smoother's RMSE, maximum error, coverage and whether it passes."""
    prepared = prepare(read_log(path), FuseOptions())
    rows = []
    for tau in GRID_S:
        v = verdict(evaluate_prepared(prepared, ["smoother"], options(tau), "sim"), "smoother")
        rows.append((float(v["rmse"]), float(v["max"]), float(v["coverage"]), not v["fails"]))  # type: ignore[arg-type]
    return path.stem, rows


def smoother_rows(prepared: Prepared) -> list[tuple[float, float]]:
    """Per value: the smoother's RMSE against the simulator's truth and its coverage."""
    truth = choose_truth(prepared.log, prepared.referred, "sim").h
    rows = []
    for tau in GRID_S:
        result = run_method(prepared, options(tau)).result
        error = result.fused - truth
        ok = np.isfinite(error)
        rmse = float(np.sqrt(np.mean(error[ok] ** 2)))
        rows.append((rmse, coverage(error, result.tick_traces["fused_std"])))
    return rows


def simulated(flight: Flight) -> list[tuple[float, float]]:
    return smoother_rows(prepared_flight(flight))


def main() -> None:
    args = arguments(__doc__.splitlines()[0]).parse_args()
    with ProcessPoolExecutor(args.jobs) as pool:
        long = pool.submit(long_flight, args.shared)
        truth = list(pool.map(truth_log, sorted((args.shared / "truth").glob("*.BIN"))))
        sims = np.array(list(pool.map(simulated, flights(args.seeds))))  # (flights, values, 2)
        gaps = long.result()
    walk = sims[:, -1, 0]
    for j, tau in enumerate(GRID_S):
        gap, diverged, std = gaps[j]
        ratio = sims[:, j, 0] / walk
        within, above, below = window_counts(sims[:, j, 1])
        passed = sum(rows[j][3] for _, rows in truth)
        print(
            f"{tau:9g} s: long flight gap {gap:.2f} m, diverged {diverged}, fused_std <= "
            f"{std:.2f} m; truth logs pass {passed} of {len(truth)}; simulated flights "
            f"({len(walk)}) RMSE against the random walk's: median {np.median(ratio):.3f}, "
            f"worst {ratio.max():.3f}, coverage within {within}, above {above}, below {below}"
        )
    print("per truth log, RMSE [m] / coverage at " + ", ".join(f"{t:g}" for t in GRID_S) + " s:")
    for name, rows in truth:
        print(f"  {name:56s} " + "  ".join(f"{r[0]:.3f}/{r[2]:.3f}" for r in rows))


if __name__ == "__main__":
    main()
