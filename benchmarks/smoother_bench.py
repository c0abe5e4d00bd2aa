"""Time of the smoother against flight length: is it linear? (issue 8, acceptance 3)

Run on demand:  python benchmarks/smoother_bench.py [--minutes 10 30 60]

A synthetic flight (a slow climb-and-hover profile) with GPS at 5 Hz (its heights and its
vertical velocity), barometer and rangefinder at 20 Hz, the IMU at 400 Hz and the report clock
at 10 Hz, fed straight to ``fuse_smoother`` (no log
file: this measures the method, not the reader). Prints the wall time per flight length and per
event.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from altfuse.fuse import FusionInput
from altfuse.fuse.smoother import SmootherParams, fuse_smoother
from altfuse.inertial import VerticalAcceleration
from altfuse.model import Samples, SensorKind


def flight(minutes: float, seed: int = 0) -> FusionInput:
    rng = np.random.default_rng(seed)
    duration = minutes * 60.0

    def truth(t: np.ndarray) -> np.ndarray:
        return np.asarray(20 * (1 - np.cos(2 * np.pi * t / 300)) + 2 * np.sin(t / 7))

    samples: list[Samples] = []
    kinds: tuple[SensorKind, ...] = ("gps", "baro", "rangefinder")
    for rate, sigma in ((5.0, 0.7), (20.0, 0.1), (20.0, 0.03)):
        t = np.arange(0, duration, 1 / rate)
        samples.append(Samples(t, truth(t) + rng.normal(0, sigma, t.size)))
    ti = np.arange(0, duration, 1 / 400)
    accel = np.gradient(np.gradient(truth(ti), ti), ti) + 0.05 + rng.normal(0, 0.2, ti.size)
    ticks = np.arange(0, duration, 0.1)
    z = np.column_stack([np.interp(ticks, t, v) for t, v in samples])
    on_clock = np.interp(ticks, ti, accel)
    vertical = VerticalAcceleration(Samples(ti, accel), on_clock, {})
    gps = samples[0].t
    climb = np.gradient(truth(ti), ti)
    velocity = Samples(gps, np.interp(gps, ti, climb) + rng.normal(0, 0.1, gps.size))
    return FusionInput(
        ticks, z, kinds, kinds, tuple(samples), 0.1, accel=vertical, gps_velocity_up=velocity
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[10.0, 30.0, 60.0])
    args = parser.parse_args()
    for minutes in args.minutes:
        data = flight(minutes)
        velocity = 0 if data.gps_velocity_up is None else data.gps_velocity_up.t.size
        events = sum(s.t.size for s in data.samples) + data.t.size + velocity
        started = time.perf_counter()
        res = fuse_smoother(data, SmootherParams())
        wall = time.perf_counter() - started
        print(
            f"{minutes:5.0f} min: {events:,} events, 400 Hz IMU ({int(minutes * 60 * 400):,} "
            f"samples): {wall:.1f} s, {wall / events * 1e6:.0f} us per event; "
            f"finite {np.isfinite(res.fused).mean():.3f}"
        )


if __name__ == "__main__":
    main()
