"""Truth logs changed as other logs are (``benchmarks/variant_logs.py``, the tests): a sensor
left out, no IMU records, sensors logged at a low rate, spiked samples, a GPS as noisy as a real
one, a sensor's step. Each variant is made from the read log (``read_log``), before screening
and alignment:

- ``no-<kind>``: every source of that kind left out (``gps``, ``baro``, ``rangefinder``);
- ``no-imu``: the IMU and attitude records left out (the altitude-only model);
- ``rate-<hz>``: each altitude source kept at most once per 1/hz seconds;
- ``gps-<hz>``: the GPS alone so, its heights, vertical velocity and speed (a receiver at 1 or
  2 Hz beside barometers at their own rate);
- ``spikes-<kind>``: 2 % of that kind's samples moved by 2-20 m up or down (seeded);
- ``noisy-gps``: each GPS's heights with 0.3 m of white noise and a random walk of 0.01 m^2/s
  (a real receiver's, where the simulators' is centimetres; seeded; ``noisy-<kind>`` the same
  on another kind);
- ``step-<kind>``: that kind's heights 1 m higher from half-way through each source's span
  (a GPS's jump when its fix changes, a barometer's step);
- ``regain-<kind>``: that kind lost for 10 s from half-way, and 2 m higher once regained (a
  GPS's fix back elsewhere);
- ``airflow-<k>``: a copter's barometers ``k V^2 / 2g`` higher at its ground speed ``V`` (the
  static pressure lowered by ``k`` times the dynamic pressure, as real copters' barometers
  read in forward flight: :data:`altfuse.datum.scale.DYNAMIC_PRIOR`; 1.3 m at 5 m/s where ``k`` is
  1); a plane's as logged (its static port: ``k`` 1 would be 108 m at the 3.3 plane's 46 m/s);
- ``windy-<w>``: the same with ``k`` 1 at the airspeed in a steady wind of ``w`` m/s blowing
  to the east (the ground velocity from the GPS's speed and course, less the wind);
- ``drift-<m>``: each barometer ``m`` metres higher per 10 minutes, from its first sample on (a
  board warming, the weather: "2-3 m over flights of up to 20 minutes", an ArduPilot user's
  foam-covered barometers, discuss.ardupilot.org/t/25952);
- ``scale-<pct>``: each barometer reading every height change ``pct`` % larger (a plane's
  static port, a barometer's error: "ab. 6 % higher than GPS" in all of an ArduPlane user's
  logs, the same thread);
- ``flash-<m>``: each barometer ``m`` metres higher from half-way through its span, settling
  back with a time constant of 5 s (light on the sensor: "an immediate change in altitude and
  around a 15 second correction", a diydrones.com user's barometer under a lamp);
- ``wash-<m>``: a copter's barometers ``m`` metres low in its rotors' wash on the ground:
  from nothing 3 s before the lift-off (the datum's, :func:`altfuse.datum.takeoff.lift_off`) to
  all of it 2 s before, back to nothing as the vehicle passes 1 m (the take-off); ArduPilot's EKF3
  ignores such dips near the ground (``EK3_GND_EFF_DZ``, 4 m by default);
- ``rezero-<s>``: the barometers 2 m high until ``s`` seconds before the take-off (the
  datum's), where the autopilot re-zeroed them (Copter arming without a home), read as altfuse
  reads such a log (``EV`` ``EKF_ALT_RESET`` there: :func:`altfuse.io.dataflash.rejoined`).

Variants join with ``+``: ``noisy-gps+regain-gps``, a real receiver's GPS regained elsewhere.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from altfuse.datum.scale import Track, Wind
from altfuse.inertial import G
from altfuse.io.dataflash import rejoined
from altfuse.model import FlightLog, Samples, Series
from altfuse.pipeline import FuseOptions, prepare
from altfuse.simulate import REZERO_DRIFT_M

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


def _half_way(s: Series) -> float:
    """The time [s] half-way through the source's span."""
    return float(s.t[0] + 0.5 * (s.t[-1] - s.t[0]))


def stepped(s: Series, size_m: float = 1.0) -> Series:
    """``size_m`` higher from half-way through the source's span."""
    return replace(s, value=s.value + np.where(s.t >= _half_way(s), size_m, 0.0))


def _stepped(s: Series, _rng: np.random.Generator, _: str) -> Series:
    return stepped(s)


def _regained(s: Series, _rng: np.random.Generator, _: str) -> Series:
    """Lost for 10 s from half-way through the source's span, and 2 m higher once regained."""
    half = _half_way(s)
    keep = (s.t < half) | (s.t >= half + 10.0)  # its first and last samples: the same half-way
    return stepped(replace(s, t=s.t[keep], value=s.value[keep]), 2.0)


def _airflow(s: Series, track: Track, k: float, east_m_s: float = 0.0) -> Series:
    """``k V^2 / 2g`` higher, ``V`` the airspeed at its samples: the ground velocity (the
    ``track``'s speed and course) less a wind of ``east_m_s`` blowing to the east."""
    air = track.airspeed(Wind(0.0, east_m_s, 0.0, 0.0))
    v = np.interp(s.t, air.t, air.value)
    return replace(s, value=s.value + k * v**2 / (2.0 * G))


def _rezeroed(flight: FlightLog, lead_s: float) -> FlightLog:
    """``rezero-<s>`` (the module doc): unchanged where no take-off is found."""
    takeoff = prepare(flight, FuseOptions()).referred.takeoff_s
    if takeoff is None:
        return flight
    at = takeoff - lead_s

    def read(s: Series) -> Series:
        high = replace(s, value=s.value + np.where(s.t < at, REZERO_DRIFT_M, 0.0))
        return rejoined(high, (at,), flight.takeoffs)[0]

    return _each(flight, "baro", read)


def _washed(flight: FlightLog, metres: float) -> FlightLog:
    """``wash-<m>`` (the module doc): unchanged but for a copter with a lift-off found."""
    referred = prepare(flight, FuseOptions()).referred
    lift, takeoff = referred.liftoff_s, referred.takeoff_s
    if flight.vehicle != "copter" or lift is None or takeoff is None:
        return flight
    times = [lift - 3.0, lift - 2.0, lift, max(takeoff, lift + 0.1)]

    def read(s: Series) -> Series:
        return replace(s, value=s.value - metres * np.interp(s.t, times, [0.0, 1.0, 1.0, 0.0]))

    return _each(flight, "baro", read)


def _drifted(s: Series, _rng: np.random.Generator, per_10_min: str) -> Series:
    """``per_10_min`` metres higher per 10 minutes since the first sample."""
    return replace(s, value=s.value + float(per_10_min) * (s.t - s.t[0]) / 600.0)


def _scaled(s: Series, _rng: np.random.Generator, percent: str) -> Series:
    """Every change from the first sample ``percent`` % larger."""
    first = s.value[0]
    return replace(s, value=first + (s.value - first) * (1.0 + float(percent) / 100.0))


def _flashed(s: Series, _rng: np.random.Generator, metres: str) -> Series:
    """``metres`` higher from half-way through the span, settling back (a 5 s time constant)."""
    since = s.t - _half_way(s)
    settling = float(metres) * np.exp(-np.maximum(since, 0.0) / 5.0)
    return replace(s, value=s.value + np.where(since >= 0.0, settling, 0.0))


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
    "regain": (None, _regained),
    "drift": (("baro",), _drifted),
    "scale": (("baro",), _scaled),
    "flash": (("baro",), _flashed),
}


#: The variants that change the barometers around the datum's take-off (the flight, the figure).
AROUND_TAKEOFF: dict[str, Callable[[FlightLog, float], FlightLog]] = {
    "rezero": _rezeroed,
    "wash": _washed,
}


def variant(flight: FlightLog, how: str, seed: int = 1) -> FlightLog:
    """``flight`` changed as the variant ``how`` says (see the module doc); variants joined by
    ``+`` one after the other, the next with the next seed (``noisy-gps+regain-gps``)."""
    if "+" in how:
        first, _, rest = how.partition("+")
        return variant(variant(flight, first, seed), rest, seed + 1)
    rng = np.random.default_rng(seed)
    what, _, arg = how.partition("-")
    if what == "no" and arg == "imu":
        return replace(flight, imu=None, attitude=None)
    if what == "no":
        return replace(flight, sensors=tuple(s for s in flight.sensors if s.kind != arg))
    if what == "gps" and arg:
        speeds = {
            field: _thinned(series, rng, arg)
            for field in ("vertical_velocity", "ground_speed", "ground_course")
            if (series := getattr(flight, field)) is not None
        }
        return replace(_each(flight, "gps", lambda s: _thinned(s, rng, arg)), **speeds)
    if what in AROUND_TAKEOFF:
        return AROUND_TAKEOFF[what](flight, float(arg))
    if what in ("airflow", "windy"):
        speed, course = flight.ground_speed, flight.ground_course
        if flight.vehicle != "copter" or speed is None or course is None:
            return flight
        track = Track(Samples(speed.t, speed.value), Samples(course.t, course.value))
        k, wind = (float(arg), 0.0) if what == "airflow" else (1.0, float(arg))
        return _each(flight, "baro", lambda s: _airflow(s, track, k, wind))
    if what not in CHANGES or not arg:
        raise ValueError(f"unknown variant {how!r}")
    kinds, change = CHANGES[what]
    for kind in kinds or (arg,):
        flight = _each(flight, kind, lambda s: change(s, rng, arg))
    return flight
