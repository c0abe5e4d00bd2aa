"""Each sensor's and each method's error against the simulator's truth on the logs in
``../shared/logs/truth`` (issue 14, acceptance 2) and the PX4 simulator logs in
``../shared/logs/px4`` whose groundtruth passes altfuse's check (issue 18).

Run on demand:  python benchmarks/truth_accuracy.py [--shared ../shared/logs] [--jobs 2]

Per log: each sensor's RMSE and maximum error [m] against ``SIM.Alt`` (referred to take-off as
``altfuse evaluate`` does) with the datum an offset only (``referral="offset"``) and with offset,
scale and lag (``referral="full"``, the default), then every method's RMSE with the default
options, the best single sensor's and the onboard EKF's; then per method its RMSE, maximum
error, +-2 sigma coverage and whether it passes the project's bar (``tests/accuracy.py``'s
``verdict``: the checks it fails). A log that cannot be fused, or whose truth is refused (a PX4
groundtruth moving against the sensors; a ULog without one), prints why.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from altfuse.errors import AltfuseError
from altfuse.evaluation import evaluate
from altfuse.fuse import METHODS
from altfuse.pipeline import FuseOptions

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from accuracy import verdict  # noqa: E402


def measure(path: Path) -> str:
    """The rows of one log, as text."""
    lines = [f"== {path.name}"]
    try:
        offset = evaluate(path, ["mean"], FuseOptions(referral="offset"), truth="sim")
        full = evaluate(path, list(METHODS), FuseOptions(), truth="sim")
    except AltfuseError as exc:
        return "\n".join([*lines, f"   refused: {exc}"])
    before = {r.name: r.overall for r in offset.rows if r.kind == "sensor"}
    for row in full.rows:
        if row.kind != "sensor":
            continue
        b = before.get(row.name)
        was = f"{b.rmse:7.2f} {b.max_abs:7.2f}" if b else f"{'-':>7} {'-':>7}"
        lines.append(
            f"   {row.name:<12} offset only {was}   full {row.overall.rmse:7.2f} "
            f"{row.overall.max_abs:7.2f}"
        )
    methods = {r.name: r.overall for r in full.rows if r.kind == "method"}
    sensors = {r.name: r.overall for r in full.rows if r.kind == "sensor"}
    best = min(sensors, key=lambda n: sensors[n].rmse)
    ekf = next((r.overall for r in full.rows if r.kind == "onboard"), None)
    lines.append(
        "   methods RMSE: "
        + ", ".join(f"{m} {s.rmse:.2f}" for m, s in methods.items())
        + f"; best sensor {best} {sensors[best].rmse:.2f}"
        + (f"; EKF {ekf.rmse:.2f}" if ekf else "")
    )
    lines += [f"   not run: {m}: {why}" for m, why in full.failed.items()]
    for method in full.runs:
        v = verdict(full, method)
        fails = ", ".join(v["fails"]) or "PASS"  # type: ignore[arg-type]
        lines.append(
            f"   {method:<11} RMSE {v['rmse']:8.3f}  max {v['max']:8.3f}  "
            f"coverage {v['coverage']:5.2f}  {fails}"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "logs")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    logs = sorted((args.shared / "truth").glob("*.BIN")) + sorted(
        (args.shared / "px4").glob("*.ulg")
    )
    print("errors [m] against SIM.Alt: RMSE, maximum")
    with ProcessPoolExecutor(args.jobs) as pool:
        for text in pool.map(measure, logs):
            print(text, flush=True)


if __name__ == "__main__":
    main()
