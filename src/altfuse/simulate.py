"""A simulated flight with known true altitude, written as a genuine DataFlash log.

The flight: ``GROUND_S`` seconds on the ground, a climb to ``CRUISE_M`` metres, a cruise at
5 m/s over ground that rises and falls (so the rangefinder sees the terrain), a descent and
``GROUND_S`` seconds on the ground after landing. The sensors, each with its own rate and error:

- GPS, 5 Hz, AMSL (home at ``HOME_AMSL_M``), 0.2 s lag, 0.35 m white noise plus a slow
  random walk; no fix (Status 1, altitude 12 m off) for its first 3 s.
- Barometer, 20 Hz, 0.08 m noise, drifting 1 cm/s while the air warms (a common baro error).
- Rangefinder, 20 Hz, distance along the body axis to the ground, 0.25 m mount height, 0.03 m
  noise, Stat 4 (Good) from 0.2 to 20 m, Stat 3 (OutOfRangeHigh) with Dist = 20 m above that.
- IMU, 50 Hz, specific force in FRD with a 0.05 m/s² bias on Z and 0.15 m/s² noise.
- ATT, 10 Hz, small roll and pitch; SIM, 10 Hz, the true altitude AMSL as ArduPilot's simulator
  logs it.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from altfuse import __version__
from altfuse.errors import ParameterError
from altfuse.io.dataflash_writer import DataFlashWriter
from altfuse.model import FloatArray

G = 9.80665
HOME_AMSL_M = 112.0
CRUISE_M = 15.0
GROUND_S = 10.0
CLIMB_S = 15.0
BOOT_S = 30.0  # the log's clock starts at boot; the flight data start this much later
RANGEFINDER_MAX_M = 20.0
RANGEFINDER_MIN_M = 0.2
RANGEFINDER_MOUNT_M = 0.25
MIN_DURATION_S = 60.0


@dataclass(frozen=True)
class SimulatedFlight:
    """Truth on a 100 Hz clock and the records to log, by type, as (time [s], values) rows."""

    seed: int
    duration_s: float
    t: FloatArray
    height_m: FloatArray
    terrain_m: FloatArray
    records: dict[str, list[tuple[float, tuple[object, ...]]]]


def _smoothstep(x: FloatArray) -> FloatArray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def true_height(t: FloatArray, duration_s: float) -> FloatArray:
    """Height above the take-off point [m] at flight time ``t`` [s]."""
    up = _smoothstep((t - GROUND_S) / CLIMB_S)
    down = _smoothstep((t - (duration_s - GROUND_S - CLIMB_S)) / CLIMB_S)
    wander = 1.5 * np.sin(2 * np.pi * t / 40.0) * up * (1 - down)
    return np.asarray(CRUISE_M * up * (1 - down) + wander)


def terrain(x: FloatArray) -> FloatArray:
    """Ground height [m] relative to the take-off point at horizontal distance ``x`` [m]."""
    return np.asarray(2.0 * np.sin(2 * np.pi * x / 150.0) + 1.0 * np.sin(2 * np.pi * x / 37.0))


def simulate_flight(seed: int = 0, duration_s: float = 120.0) -> SimulatedFlight:
    """Simulate the flight and its sensors (see the module doc)."""
    if not (np.isfinite(duration_s) and duration_s >= MIN_DURATION_S):
        raise ParameterError(f"--duration must be at least {MIN_DURATION_S:g} s, got {duration_s}")
    rng = np.random.default_rng(seed)
    dt = 0.01
    t = np.arange(0.0, duration_s, dt)
    h = true_height(t, duration_s)
    airborne = _smoothstep((t - GROUND_S - CLIMB_S / 2) / 2.0) * (
        1 - _smoothstep((t - (duration_s - GROUND_S - CLIMB_S / 2)) / 2.0)
    )
    x = np.cumsum(5.0 * airborne) * dt
    ground = terrain(x) - terrain(np.zeros(1))[0]
    roll = np.deg2rad(3.0) * np.sin(2 * np.pi * t / 7.0) * airborne
    pitch = np.deg2rad(-5.0) * airborne + np.deg2rad(1.0) * np.sin(2 * np.pi * t / 5.0)
    acc_up = np.gradient(np.gradient(h, dt), dt)

    def at(rate_hz: float, lag_s: float = 0.0) -> tuple[FloatArray, FloatArray]:
        ts = np.arange(0.0, duration_s, 1.0 / rate_hz)
        return ts, np.interp(ts - lag_s, t, h)

    records: dict[str, list[tuple[float, tuple[object, ...]]]] = {}

    def log(name: str, times: FloatArray, *columns: FloatArray | int) -> None:
        cols = [np.broadcast_to(c, times.shape) for c in columns]
        records[name] = [(float(ti), tuple(c[k] for c in cols)) for k, ti in enumerate(times)]

    ts, hg = at(5.0, lag_s=0.2)
    walk = np.cumsum(rng.normal(0.0, 0.05, ts.size))
    fix = ts >= 3.0
    gps_alt = HOME_AMSL_M + hg + walk + rng.normal(0.0, 0.35, ts.size) + np.where(fix, 0.0, 12.0)
    log("GPS", ts, 0, np.where(fix, 3, 1), gps_alt)

    ts, hb = at(20.0)
    drift = 0.01 * np.clip(ts - GROUND_S, 0.0, None)
    log("BARO", ts, 0, hb + drift + rng.normal(0.0, 0.08, ts.size), 1)

    ts, hr = at(20.0)
    tilt = np.cos(np.interp(ts, t, roll)) * np.cos(np.interp(ts, t, pitch))
    dist = (hr - np.interp(ts, t, ground) + RANGEFINDER_MOUNT_M) / tilt
    dist = dist + rng.normal(0.0, 0.03, ts.size)
    stat = np.where(dist > RANGEFINDER_MAX_M, 3, np.where(dist < RANGEFINDER_MIN_M, 2, 4))
    # logged as newer ArduPilot does: centimetres in an int16, multiplier B (0.01) in FMTU
    dist_cm = np.round(100 * np.clip(dist, RANGEFINDER_MIN_M, RANGEFINDER_MAX_M))
    log("RFND", ts, 0, dist_cm, stat, 25)

    ts = np.arange(0.0, duration_s, 1.0 / 50.0)
    r, p, a = (np.interp(ts, t, v) for v in (roll, pitch, acc_up))
    f_ned = np.stack([np.zeros_like(ts), np.zeros_like(ts), -(G + a)])
    # specific force in the body frame: R_ned_to_body @ f_ned, yaw 0
    f_body = np.stack(
        [
            -np.sin(p) * f_ned[2],
            np.sin(r) * np.cos(p) * f_ned[2],
            np.cos(r) * np.cos(p) * f_ned[2],
        ]
    )
    noise = rng.normal(0.0, 0.15, (3, ts.size))
    log("IMU", ts, 0, *(f_body + noise + np.array([[0.0], [0.0], [0.05]])))

    ts = np.arange(0.0, duration_s, 0.1)
    log("ATT", ts, *(np.rad2deg(np.interp(ts, t, v)) for v in (roll, pitch)), 0)
    log("SIM", ts, HOME_AMSL_M + np.interp(ts, t, h))
    return SimulatedFlight(seed, float(duration_s), t, h, ground, records)


_TYPES = {
    # name: (format, columns, units, multipliers), ArduPilot 4.x layouts (subsets)
    "GPS": ("QBBf", "TimeUS,I,Status,Alt", "s#-m", "F--0"),
    "BARO": ("QBfB", "TimeUS,I,Alt,Health", "s#m-", "F-0-"),
    "RFND": ("QBhBB", "TimeUS,Instance,Dist,Stat,Orient", "s#m--", "F-B--"),
    "IMU": ("QBfff", "TimeUS,I,AccX,AccY,AccZ", "s#ooo", "F-000"),
    "ATT": ("Qfff", "TimeUS,Roll,Pitch,Yaw", "sddh", "F000"),
    "SIM": ("Qf", "TimeUS,Alt", "sm", "F0"),
    "MSG": ("QZ", "TimeUS,Message", "s-", "F-"),
}


def write_simulated_log(flight: SimulatedFlight, path: str | Path) -> int:
    """Write ``flight`` as a DataFlash log at ``path`` (atomically); return the record count."""
    path = Path(path)
    rows: list[tuple[float, str, tuple[object, ...]]] = [
        (BOOT_S + ti, name, values) for name, recs in flight.records.items() for ti, values in recs
    ]
    rows.sort(key=lambda row: row[0])
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            writer = DataFlashWriter(handle)
            for name, (fmt, columns, units, mults) in _TYPES.items():
                writer.define(name, fmt, columns, units, mults)
            message = f"ArduCopter V4.0.0 (simulated by altfuse {__version__}, seed {flight.seed})"
            writer.write("MSG", int(BOOT_S * 1e6), message)
            for time_s, name, values in rows:
                writer.write(name, round(time_s * 1e6), *values)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return writer.records
