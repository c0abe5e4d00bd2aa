"""Each GPS's lag as altfuse finds it, against the barometer and against the accelerometer, and
against the simulators' truth where the log has one: the measurement behind
``altfuse.align.inertial_lag`` and ``LAG_AGREE_SIGMAS``.

Run on demand:  python benchmarks/gps_lags.py [--shared ../shared/logs] [--jobs 2]

Per log (``../shared/logs``: truth, ardupilot, px4), and per truth log with each barometer as
noisy as a GPS (``tests/variants.py``'s ``noisy-baro``): the first GPS's lag behind the first
barometer (:func:`altfuse.align.gps_lags`), its vertical velocity's behind the integrated
vertical acceleration (:func:`altfuse.align.estimate_lag` on
:func:`altfuse.inertial.velocity_integral`), each with its standard error or the share of the
changes it explains; their disagreement in combined standard errors; the lag the pipeline takes
(``Prepared.lags``); and the GPS's lag behind ``SIM.Alt`` by the same estimator.
"""

from __future__ import annotations

import argparse
import math
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from altfuse.align import Lag, estimate_lag, gps_lags  # noqa: E402
from altfuse.errors import AltfuseError  # noqa: E402
from altfuse.inertial import velocity_integral  # noqa: E402
from altfuse.io import read_log  # noqa: E402
from altfuse.pipeline import FuseOptions, prepare  # noqa: E402
from variants import variant  # noqa: E402


def shown(lag: Lag | None) -> str:
    if lag is None:
        return f"{'-':>17}"
    if lag.std_s is None:
        return f"{'not (' + format(lag.explained or 0.0, '.0%') + ')':>17}"
    return f"{lag.lag_s:+.2f} +-{lag.std_s:.3f} {lag.explained or 0.0:4.0%}"


def measure(job: tuple[Path, str]) -> str:
    """One row: the log at ``path``, changed by the variant ``how`` ("" for none)."""
    path, how = job
    label = f"{path.stem[:40]:40s} {how or '-':10s}"
    try:
        flight = read_log(path)
        flight = variant(flight, how) if how else flight
        prepared = prepare(flight, FuseOptions())
    except AltfuseError as exc:
        return f"{label} refused: {str(exc)[:60]}"
    taken, screened = prepared.lags.get("gps"), prepared.log  # the log as screened
    baro = gps_lags(list(screened.sensors)).get("gps")
    inertial = None
    imu, attitude = screened.imu, screened.attitude
    if screened.vertical_velocity is not None and imu is not None and attitude is not None:
        integral = velocity_integral(imu, attitude)
        if integral is not None:
            inertial = estimate_lag(screened.vertical_velocity, integral)
    apart = "-"
    if baro is not None and inertial is not None and baro.std_s and inertial.std_s:
        error = math.hypot(baro.std_s, inertial.std_s)
        apart = f"{abs(baro.lag_s - inertial.lag_s) / error:.1f}"
    gps = next((s for s in screened.sensors if s.name == "gps"), None)
    sim = next((r for r in screened.references if r.name == "sim"), None)
    truth = f"{estimate_lag(gps, sim).lag_s:+.2f}" if gps is not None and sim is not None else "-"
    took = f"{taken.lag_s:+.2f} ({taken.reference})" if taken is not None else "-"
    return f"{label} {shown(baro)}  {shown(inertial)}  {apart:>5}  {took:22s} {truth:>6}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "logs")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    truth = sorted((args.shared / "truth").glob("*.BIN"))
    others = sorted((args.shared / "ardupilot").iterdir()) + sorted(
        (args.shared / "px4").glob("*.ulg")
    )
    jobs = [(p, "") for p in truth] + [(p, "noisy-baro") for p in truth] + [(p, "") for p in others]
    print(
        f"{'log':40s} {'variant':10s} {'against baro':>17}  {'against accel':>17}  "
        f"{'apart':>5}  {'taken':22s} {'vs SIM':>6}"
    )
    with ProcessPoolExecutor(args.jobs) as pool:
        for row in pool.map(measure, jobs):
            print(row, flush=True)


if __name__ == "__main__":
    main()
