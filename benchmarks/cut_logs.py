"""The default method on the truth logs cut as real logs are: ended early (a crash, a flat
battery: the file's first part) and begun late (a log rotated or started in flight: its data
from a point of its span on: ``tests/repeated.py``'s ``cut_log``).

Run on demand:  python benchmarks/cut_logs.py [--shared ../shared/logs] [--jobs 2]
[--ended 0.2 0.3 0.4 0.5 0.75] [--begun 0.2 0.4 0.6]

Per log and cut: the smoother's RMSE, maximum error and +-2 sigma coverage against ``SIM.Alt``,
the checks of the project's bar it fails (``tests/accuracy.py``'s ``verdict``) and the best
single sensor's RMSE and maximum; a cut that leaves no fusable log prints why. Last, per check,
on how many cuts it fails. The whole logs are ``benchmarks/truth_accuracy.py``'s.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from accuracy import verdict  # noqa: E402
from altfuse.errors import AltfuseError  # noqa: E402
from altfuse.evaluation import evaluate  # noqa: E402
from altfuse.pipeline import FuseOptions  # noqa: E402
from repeated import cut_log  # noqa: E402


def measure(job: tuple[Path, str, float]) -> tuple[str, list[str]]:
    """One cut of one log: its row, and the checks the smoother fails there."""
    path, how, fraction = job
    label = f"{path.stem[:34]:34s} {how} {fraction:.2f}"
    with tempfile.TemporaryDirectory() as tmp:
        cut = Path(tmp) / path.name
        cut_log(path, cut, how, fraction)
        try:
            result = evaluate(cut, ["smoother"], FuseOptions(), truth="sim")
        except AltfuseError as exc:
            return f"{label}  refused: {exc}", []
    v = verdict(result, "smoother")
    fails = list(v["fails"])  # type: ignore[call-overload]
    sensors = {r.name: r.overall for r in result.rows if r.kind == "sensor"}
    best = min(sensors, key=lambda n: sensors[n].rmse)
    return (
        f"{label}  RMSE {v['rmse']:6.3f}  max {v['max']:6.3f}  coverage {v['coverage']:5.3f}  "
        f"{','.join(fails) or 'PASS':22s} best {best} {sensors[best].rmse:.3f} / "
        f"{sensors[best].max_abs:.3f}",
        fails,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "logs")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--ended", type=float, nargs="*", default=[0.2, 0.3, 0.4, 0.5, 0.75])
    parser.add_argument("--begun", type=float, nargs="*", default=[0.2, 0.4, 0.6])
    args = parser.parse_args()
    logs = sorted((args.shared / "truth").glob("*.BIN"))
    jobs = [(p, "ended", f) for p in logs for f in args.ended]
    jobs += [(p, "begun", f) for p in logs for f in args.begun]
    failed: Counter[str] = Counter()
    print("the smoother against SIM.Alt [m], per log and cut (ended: the file's first part; "
          "begun: its data from that share of its span on)")  # fmt: skip
    with ProcessPoolExecutor(args.jobs) as pool:
        for row, fails in pool.map(measure, jobs):
            print(row, flush=True)
            failed.update(fails)
    print(
        f"{len(jobs)} cuts; failing "
        + (", ".join(f"{check} on {n}" for check, n in failed.most_common()) or "nothing")
    )


if __name__ == "__main__":
    main()
