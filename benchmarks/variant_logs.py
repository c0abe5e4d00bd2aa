"""The default method on the truth logs changed as other logs are: a sensor left out (a flight
without GPS, a failed barometer), no IMU records, sensors logged at a low rate, spiked samples,
a GPS as noisy as a real one, barometers as noisy, copters' barometers reading high in the
airflow of forward flight as real copters' do, in still air and in a 3 m/s wind, and
barometers that drift, read every change too large, flash (light on the sensor) or dip in a
copter's rotors' wash on the ground.

Run on demand:  python benchmarks/variant_logs.py [--shared ../shared/logs] [--jobs 2]
[--variants no-gps no-baro no-imu rate-5 spikes-baro spikes-gps noisy-gps noisy-baro airflow-1
windy-3 drift-3 scale-5 flash-3 wash-0.5]

The variants (``tests/variants.py``, which the tests use too): ``no-<kind>``, ``no-imu``,
``rate-<hz>``, ``gps-<hz>``, ``spikes-<kind>``, ``noisy-<kind>``, ``step-<kind>``,
``regain-<kind>``, ``airflow-<k>``, ``windy-<w>``, ``rezero-<s>``, ``wash-<m>``, ``drift-<m>``,
``scale-<pct>``, ``flash-<m>``, joined by ``+`` (``gps-<hz>``, ``step-<kind>``,
``regain-<kind>``, ``rezero-<s>``, ``drift-<m>``, ``scale-<pct>``, ``flash-<m>``, ``windy-<w>``
and ``wash-<m>`` but ``windy-3``, ``drift-3``, ``scale-5``, ``flash-3`` and ``wash-0.5`` not in
the default set).

Per log and variant: the smoother's RMSE, maximum error and +-2 sigma coverage against
``SIM.Alt``, the checks of the project's bar it fails (``tests/accuracy.py``'s ``verdict``;
the EKF's check left out: the onboard EKF had every sensor) and the best single sensor's
RMSE. Last, per variant, on how many logs RMSE and maximum are within the bar, and per log its
worst case: the largest over the variants of its RMSE's or maximum error's share of the bar,
whichever is larger (the project decides by the worst case per log, not by counting wins).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from accuracy import verdict  # noqa: E402
from altfuse.errors import AltfuseError  # noqa: E402
from altfuse.evaluation import evaluate_prepared  # noqa: E402
from altfuse.io import read_log  # noqa: E402
from altfuse.pipeline import FuseOptions, prepare  # noqa: E402
from variants import variant  # noqa: E402

VARIANTS = [
    "no-gps", "no-baro", "no-imu", "rate-5", "spikes-baro", "spikes-gps", "noisy-gps", "noisy-baro",
    "airflow-1", "windy-3", "drift-3", "scale-5", "flash-3", "wash-0.5",
]  # fmt: skip


def measure(job: tuple[Path, str]) -> tuple[str, str, float]:
    """One variant of one log: its row, and the larger of its RMSE and maximum error as a share
    of its bar (NaN: refused)."""
    path, how = job
    label = f"{path.stem[:34]:34s} {how:12s}"
    try:
        prepared = prepare(variant(read_log(path), how), FuseOptions())
        result = evaluate_prepared(prepared, ["smoother"], truth="sim")
    except AltfuseError as exc:
        return f"{label} refused: {exc}", how, math.nan
    v = verdict(result, "smoother")
    fails = [f for f in v["fails"] if f != "ekf"]  # type: ignore[attr-defined]
    row = (
        f"{label} RMSE {v['rmse']:6.3f}  max {v['max']:6.3f}  coverage {v['coverage']:5.3f}  "
        f"{','.join(fails) or 'PASS':20s} best {v['best']} {v['best_rmse']:.3f}"
    )
    return row, how, float(v["share_of_bar"])  # type: ignore[arg-type]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "logs")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--variants", nargs="*", default=VARIANTS)
    args = parser.parse_args()
    logs = sorted((args.shared / "truth").glob("*.BIN"))
    jobs = [(p, how) for p in logs for how in args.variants]
    within: Counter[str] = Counter()
    made: Counter[str] = Counter()
    worst: dict[str, tuple[float, str]] = {}
    print("the smoother against SIM.Alt [m], per log and variant")
    with ProcessPoolExecutor(args.jobs) as pool:
        for (path, _), (row, how, share) in zip(jobs, pool.map(measure, jobs), strict=True):
            print(row, flush=True)
            if math.isnan(share):
                continue
            made[how] += 1
            within[how] += share <= 1.0
            worst[path.stem] = max(worst.get(path.stem, (-math.inf, "")), (share, how))
    print("RMSE and maximum within the bar: " + ", ".join(
        f"{how} {within[how]} of {made[how]}" for how in args.variants
    ))  # fmt: skip
    print("worst case per log: the larger of RMSE and maximum as a share of its bar (above 1:")
    print("over it), the largest over the variants")
    for name, (share, how) in worst.items():
        print(f"  {name[:48]:48s} {share:5.2f}  {how}")


if __name__ == "__main__":
    main()
