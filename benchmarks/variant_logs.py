"""The default method on the truth logs changed as other logs are: a sensor left out (a flight
without GPS, a failed barometer), no IMU records, sensors logged at a low rate, spiked samples,
and a GPS as noisy as a real one.

Run on demand:  python benchmarks/variant_logs.py [--shared ../shared/logs] [--jobs 2]
[--variants no-gps no-baro no-imu rate-5 spikes-baro spikes-gps noisy-gps step-gps]

Each variant is made from the read log (``read_log``), before screening and alignment:

- ``no-<kind>``: every source of that kind left out (``gps``, ``baro``, ``rangefinder``);
- ``no-imu``: the IMU and attitude records left out (the altitude-only model);
- ``rate-<hz>``: each altitude source kept at most once per 1/hz seconds;
- ``spikes-<kind>``: 2 % of that kind's samples moved by 2-20 m up or down (seeded);
- ``noisy-gps``: each GPS's heights with 0.3 m of white noise and a random walk of 0.01 m^2/s
  (a real receiver's, where the simulators' is centimetres; seeded; ``noisy-<kind>`` the same
  on another kind);
- ``step-<kind>``: that kind's heights 1 m higher from half-way through each source's span
  (a GPS's jump when its fix changes, a barometer's step; not in the default set).

Per log and variant: the smoother's RMSE, maximum error and +-2 sigma coverage against
``SIM.Alt``, the checks of the project's bar it fails (``tests/accuracy.py``'s ``verdict``;
the EKF's check left out: the onboard EKF had every sensor) and the best single sensor's
RMSE. Last, per variant, on how many logs RMSE and maximum are within the bar.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from accuracy import verdict  # noqa: E402
from altfuse.errors import AltfuseError  # noqa: E402
from altfuse.evaluation import evaluate_prepared  # noqa: E402
from altfuse.io import read_log  # noqa: E402
from altfuse.model import FlightLog, Series  # noqa: E402
from altfuse.pipeline import FuseOptions, prepare  # noqa: E402

VARIANTS = ["no-gps", "no-baro", "no-imu", "rate-5", "spikes-baro", "spikes-gps", "noisy-gps"]
ALTITUDE = ("gps", "baro", "rangefinder")


def _each(flight: FlightLog, kind: str, change: Callable[[Series], Series]) -> FlightLog:
    """``flight`` with ``change`` applied to each source of ``kind``."""
    sensors = tuple(change(s) if s.kind == kind else s for s in flight.sensors)
    return replace(flight, sensors=sensors)


def _thinned(s: Series, _rng: np.random.Generator, hz: str) -> Series:
    """At most one sample per ``1 / hz`` seconds."""
    keep = np.r_[True, np.diff(np.floor(s.t / (1.0 / float(hz)))) > 0]
    return replace(s, t=s.t[keep], value=s.value[keep])


def _spiked(s: Series, rng: np.random.Generator, _: str) -> Series:
    """2 % of the samples moved by 2-20 m up or down."""
    hit = rng.random(s.t.size) < 0.02
    jump = rng.choice([-1.0, 1.0], s.t.size) * rng.uniform(2.0, 20.0, s.t.size)
    return replace(s, value=s.value + hit * jump)


def _stepped(s: Series, _rng: np.random.Generator, _: str) -> Series:
    """1 m higher from half-way through the source's span."""
    half = s.t[0] + 0.5 * (s.t[-1] - s.t[0])
    return replace(s, value=s.value + np.where(s.t >= half, 1.0, 0.0))


def _noisy(s: Series, rng: np.random.Generator, _: str) -> Series:
    """0.3 m of white noise and a random walk of 0.01 m^2/s (a real receiver's)."""
    dt = np.maximum(np.diff(s.t, prepend=s.t[0]), 0.0)
    walk = np.cumsum(rng.normal(0.0, 1.0, s.t.size) * np.sqrt(0.01 * dt))
    return replace(s, value=s.value + rng.normal(0.0, 0.3, s.t.size) + walk)


#: Each variant that changes samples: the kinds it changes (None: the one its name ends with,
#: ``spikes-baro``) and how (each source, the generator, the name's end).
CHANGES: dict[str, tuple[tuple[str, ...] | None, Callable[..., Series]]] = {
    "rate": (ALTITUDE, _thinned),
    "spikes": (None, _spiked),
    "step": (None, _stepped),
    "noisy": (None, _noisy),
}


def variant(flight: FlightLog, how: str, seed: int = 1) -> FlightLog:
    """``flight`` changed as the variant ``how`` says (see the module doc)."""
    rng = np.random.default_rng(seed)
    what, _, arg = how.partition("-")
    if what == "no" and arg == "imu":
        return replace(flight, imu=None, attitude=None)
    if what == "no":
        return replace(flight, sensors=tuple(s for s in flight.sensors if s.kind != arg))
    if what not in CHANGES or not arg:
        raise ValueError(f"unknown variant {how!r}")
    kinds, change = CHANGES[what]
    for kind in kinds or (arg,):
        flight = _each(flight, kind, lambda s: change(s, rng, arg))
    return flight


def measure(job: tuple[Path, str]) -> tuple[str, str, bool]:
    """One variant of one log: its row, and whether RMSE and maximum are within the bar."""
    path, how = job
    label = f"{path.stem[:34]:34s} {how:12s}"
    try:
        prepared = prepare(variant(read_log(path), how), FuseOptions())
        result = evaluate_prepared(prepared, ["smoother"], truth="sim")
    except AltfuseError as exc:
        return f"{label} refused: {exc}", how, False
    v = verdict(result, "smoother")
    fails = [f for f in v["fails"] if f != "ekf"]  # type: ignore[attr-defined]
    row = (
        f"{label} RMSE {v['rmse']:6.3f}  max {v['max']:6.3f}  coverage {v['coverage']:5.3f}  "
        f"{','.join(fails) or 'PASS':20s} best {v['best']} {v['best_rmse']:.3f}"
    )
    return row, how, not {"rmse", "max"} & set(fails)


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
    print("the smoother against SIM.Alt [m], per log and variant")
    with ProcessPoolExecutor(args.jobs) as pool:
        for row, how, ok in pool.map(measure, jobs):
            print(row, flush=True)
            made[how] += "refused" not in row
            within[how] += ok
    print("RMSE and maximum within the bar: " + ", ".join(
        f"{how} {within[how]} of {made[how]}" for how in args.variants
    ))  # fmt: skip


if __name__ == "__main__":
    main()
