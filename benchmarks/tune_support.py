"""Measure Paper A's support weighting over a grid of (alpha scale, beta, k).

Run on demand, not in the tests:  python benchmarks/tune_support.py [--shared ../shared/logs]

Error measures, all RMSE [m] of the fused height:
- ``paperA``: the synthetic Paper A experiment (tests/conftest.py), seeds 0-9, against its truth;
  over the whole flight and in the baro-departure regime.
- ``sim``: sample_logs/mission.bin against its SIM truth.
- real logs with three or more sources (0038, 0039: GPS, BARO, CTUN.SAlt; diaven: GPS, GPS2,
  CTUN.BAlt, RFND) against the autopilot's own estimate (EKF -PD, or CTUN.Alt where the log has
  no EKF records), referred to take-off the same way. That estimate is a reference, not truth:
  a method can be right and still differ from it.

``alpha`` is given as a factor on the data-driven value (1 = auto).
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from altfuse.align import align  # noqa: E402
from altfuse.datum import refer_to_takeoff  # noqa: E402
from altfuse.fuse import FusionInput, FusionResult  # noqa: E402
from altfuse.fuse.support import SupportParams, auto_alpha, fuse_support  # noqa: E402
from altfuse.io import read_log  # noqa: E402
from altfuse.screen import screen  # noqa: E402
from altfuse.simulate import HOME_AMSL_M  # noqa: E402
from conftest import paper_a_flight  # noqa: E402

SHORT = {
    "beastayyg_log_0038_mechanical_failure.bin": "log0038",
    "beastayyg_log_0039_mechanical_failure.bin": "log0039",
    "diaven_sample01.bin": "diaven",
}


def rmse(x: np.ndarray, truth: np.ndarray) -> float:
    e = x - truth
    return float(np.sqrt(np.nanmean(e**2)))


def support(z: np.ndarray, alpha: float, beta: float, k: int) -> FusionResult:
    """Paper A on heights on a 10 Hz clock, with a window of ``k`` ticks."""
    params = SupportParams(alpha_per_m2=alpha, beta=beta, window_s=k * 0.1)
    return fuse_support(FusionInput.from_heights(z, 0.1), params)


def referred_case(path: Path) -> tuple[np.ndarray, np.ndarray]:
    flight = screen(read_log(path))
    ref = refer_to_takeoff(align(flight.sensors))
    refs = {r.name: r for r in flight.references}
    truth_series = refs.get("sim") or refs.get("ekf") or refs["ctun"]
    truth = np.interp(ref.t, truth_series.t, truth_series.value)
    if truth_series.name == "sim":
        truth = truth - HOME_AMSL_M
    else:  # refer the autopilot's estimate to take-off like the sensors
        lo, hi = ref.ground_window_s
        truth = truth - np.median(truth[(ref.t >= lo) & (ref.t <= hi)])
    return ref.h, truth


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "logs")
    args = parser.parse_args()
    cases = {"sim": referred_case(ROOT / "sample_logs" / "mission.bin")}
    for name in SHORT:
        path = args.shared / "ardupilot" / name
        if path.exists():
            cases[SHORT[name]] = referred_case(path)
    flights = [paper_a_flight(seed) for seed in range(10)]
    header = ["a_x", "beta", "k", "paperA", "paperA_dep", *cases]
    print(" ".join(f"{h:>10}" for h in header))
    for scale, beta, k in itertools.product(
        (0.25, 1.0, 4.0), (0.0, 1.0, 10.0, 100.0), (0, 5, 10, 20, 40)
    ):
        whole, dep = [], []
        for f in flights:
            res = support(f.z, scale * auto_alpha(f.z), beta, k)
            whole.append(rmse(res.fused, f.truth))
            dep.append(rmse(res.fused[f.baro_departs], f.truth[f.baro_departs]))
        row = [scale, beta, k, np.mean(whole), np.mean(dep)]
        for h, truth in cases.values():
            res = support(h, scale * auto_alpha(h), beta, k)
            row.append(rmse(res.fused, truth))
        print(" ".join(f"{v:>10.4g}" for v in row))
    base = []
    for h, truth in cases.values():
        base.append(rmse(np.nanmean(h, axis=1), truth))
    print(
        "mean baseline:",
        " ".join(f"{v:.4g}" for v in base),
        "paperA",
        np.mean([rmse(f.z.mean(axis=1), f.truth) for f in flights]).round(4),
    )


if __name__ == "__main__":
    main()
