"""How far one sensor's step moves the fused height on the real logs, which have no truth:
each GPS and barometer in turn 2 or 3 m higher from half-way through its span (a fix come back
elsewhere, a reset), every other sensor as logged. The fused height should not move: what it
moves by (RMS and maximum over the flight, m) is what the step cost, and ``steps`` says whose
jump the smoother made it.

Run on demand:  python benchmarks/step_robustness.py [--shared ../shared/logs] [--jobs 2]
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from altfuse.errors import AltfuseError  # noqa: E402
from altfuse.io import read_log  # noqa: E402
from altfuse.pipeline import FuseOptions, prepare, run_method  # noqa: E402
from variants import stepped  # noqa: E402 (tests/variants.py: the tests' step, any size)

SIZES_M = (2.0, 3.0)


def measure(path: Path) -> list[str]:
    """One row per stepped sensor and size of the log at ``path``; none if it does not fuse."""
    try:
        flight = read_log(path)
        prepared = prepare(flight, FuseOptions())
    except AltfuseError:
        return []
    plain = run_method(prepared, FuseOptions()).result.fused
    rows = []
    for sensor in flight.sensors:
        if sensor.kind == "rangefinder":
            continue
        for size in SIZES_M:
            one = tuple(stepped(s, size) if s is sensor else s for s in flight.sensors)
            changed = prepare(replace(flight, sensors=one), FuseOptions())
            run = run_method(changed, FuseOptions())
            # on the ticks of both clocks (a sensor's span can move the clock's start)
            _, mine, theirs = np.intersect1d(
                np.round(changed.referred.t, 6), np.round(prepared.referred.t, 6),
                return_indices=True,
            )  # fmt: skip
            moved = np.abs(run.result.fused[mine] - plain[theirs])
            rows.append(
                f"{path.name[:36]:36s} {sensor.name:5s} {size:3.1f} m  moved RMS "
                f"{np.sqrt(np.nanmean(moved**2)):6.3f} max {np.nanmax(moved):6.2f}  "
                f"steps: {run.result.params.get('steps') or '-'}"
            )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "logs")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    logs = sorted(p for kind in ("ardupilot", "px4") for p in (args.shared / kind).iterdir())
    with ProcessPoolExecutor(args.jobs) as pool:
        for rows in pool.map(measure, logs):
            for row in rows:
                print(row, flush=True)


if __name__ == "__main__":
    main()
