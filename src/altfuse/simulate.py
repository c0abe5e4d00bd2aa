"""Simulated flights with known true altitude, written as genuine DataFlash logs.

A scenario gives the truth (height above take-off, distance flown, attitude) and how noisy each
sensor is when; shared sensor models turn it into the records an ArduPilot log holds, each
sensor behind the truth by a latency drawn per flight from ``LATENCY_S`` (as the ArduPilot
simulators' sensors lag their own), the GPS by a further lag drawn from ``GPS_LAG_S``:

- GPS, 5 Hz, altitude AMSL (home at ``HOME_AMSL_M``), lagging, white noise plus a slow random
  walk; no fix (Status 1, altitude 12 m off) for its first 3 s. Its ground speed (``Spd``), its
  course (``GCrs``: every flight's track runs north, 0, and back, 180), and
  vertical velocity (``VZ``, down) with the same lag (a receiver reports them for one epoch;
  ArduPilot's EKF3 applies one ``EK3_GPS_DELAY`` to all), the velocity with
  ``GPS_VZ_SIGMA_M_S`` of white noise.
- Barometer, 20 Hz, 0.08 m noise, drifting with its temperature (logged in ``BARO.Temp``): the
  board warms from 25 °C towards 35 °C with a 60 s time constant, 0.12 m per °C.
- Rangefinder, 20 Hz, distance along the body's down axis to the ground, 0.25 m mount height;
  ``Stat`` 4 (Good) within range, 2 (OutOfRangeLow) below 0.2 m with ``Dist`` at 0.2 m, 3
  (OutOfRangeHigh) above its maximum with ``Dist`` pinned at the maximum, as many drivers log;
  its ``RNGFND1_MIN_CM``, ``_MAX_CM`` and ``_GNDCLEAR`` (the mount height) in ``PARM`` records.
- IMU, 50 Hz, specific force in FRD with a 0.05 m/s² bias on Z and 0.15 m/s² noise, clipped at
  its ±16 g range; ATT, 10 Hz.
- SIM, 10 Hz: the true altitude AMSL, as ArduPilot's simulator logs it.

Scenarios (``SCENARIOS``): ``paper-a`` (Paper A's experiment: level flight near 15 m, the
barometer departing, then every sensor scattering), ``hover`` (Paper B's hover at 240 m),
``mission`` (take-off, climb, cruise over uneven ground, landing), ``climb`` (a plane's: a
climb to 300 m at up to 18 m/s, banked turns, a descent). Faults (``FAULTS``) can be
added to any: ``baro-drift``, ``gps-glitch``, ``rangefinder-dropout``, ``lose-gps``,
``lose-baro``, ``lose-rangefinder``, and two the real logs showed the accelerometer do:
``imu-impact`` (one IMU sample of 25 g, an impact or a clipped sample: 5 m/s of velocity in one
50 Hz sample), ``attitude-error`` (the logged roll 30 degrees off for 10 s: gravity rotated
into the vertical, 1.3 m/s^2 of false acceleration, as a plane's attitude error at large bank
angles), ``imu-clip`` (a shock: five consecutive IMU samples pinned at the 16 g range, 15 m/s of
false velocity, too long for a median of its neighbours to call a spike), ``imu-25hz`` (the IMU
logged at 25 Hz, as older and busier logs do); and two of the other sensors:
``baro-scale`` (the barometer 7 % high over the flight: a warm sensor), ``baro-airflow`` (the
barometer 1 m higher at the flight's top airspeed, as the square of that speed, in a 2 m/s
wind along the track: the air flowing past lowers the pressure it reads, as on real copters;
not on the hover and Paper A's flight, which do not cruise) and ``rangefinder-low`` (mounted
0.1 m up, below its 0.2 m minimum: OutOfRangeLow on the ground). And four of the flight and
its log: ``roll-flip`` (a full turn about the roll axis in 1 s, as aerobatic and
tumbling logs show: the logged roll, in [-180, 180) degrees as ArduPilot logs it, wraps through
+-180, and the rangefinder, pointing at the sky, reads out of range), ``splice`` (nothing
logged for 20 s from half the flight, the vehicle flying on: a log stopped and resumed, or cut
and joined), ``hard-landing`` (the motors cut 1 m above the ground on the last descent: a
fall, an impact the accelerometer clips at its 16 g range, and a bounce; not on the hover,
which does not land) and ``baro-rezero`` (the barometer 2 m high on the ground until the
vehicle arms, 3 s before take-off, where the autopilot re-zeroes it and logs ``EV``
``EKF_ALT_RESET``, as Copter arming without a home does).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import BinaryIO

import numpy as np

from altfuse import __version__
from altfuse.errors import ParameterError
from altfuse.inertial import G
from altfuse.io.dataflash import EV_EKF_ALT_RESET
from altfuse.model import FloatArray, brief_repr
from altfuse.params import InvalidParameter, is_number
from altfuse.write import atomic_outputs, check_log_path

HOME_AMSL_M = 112.0
HOME_LAT, HOME_LNG = -35.363261, 149.165230  # ArduPilot's simulator home
GPS_WEEK, GPS_MS_OF_WEEK = 2400, 200_000_000
BOOT_S = 30.0  # the log's clock starts at boot; the simulated flight starts this much later
DT_S = 0.01  # truth clock
#: The GPS's lag behind the other sensors [s], of its altitude and its vertical velocity alike,
#: drawn per flight from this range (receivers lag 0.1-0.25 s: EK3_GPS_DELAY's 220 ms)...
GPS_LAG_S = (0.1, 0.25)
#: ... and every sensor's common latency behind the log's timestamps [s] (the time between the
#: air or the ground being sampled and the sample being stamped), drawn likewise: the
#: ArduPilot simulators' sensors lag their own truth (SIM) by 7-12 ms on nine of their ten
#: copter logs shared.
LATENCY_S = (0.005, 0.012)
GPS_VZ_SIGMA_M_S = 0.1  # a receiver's vertical velocity noise (u-blox: 0.05-0.3 m/s)
RANGEFINDER_MIN_M = 0.2
RANGEFINDER_MOUNT_M = 0.25

Records = dict[str, list[tuple[float, tuple[object, ...]]]]


@dataclass(frozen=True)
class Profile:
    """The truth of one flight on the ``DT_S`` clock, and how noisy each sensor is when."""

    __repr__ = brief_repr

    t: FloatArray
    height_m: FloatArray  # above the take-off point
    distance_m: FloatArray  # flown horizontally
    roll: FloatArray  # [rad]
    pitch: FloatArray  # [rad]
    gps_sigma_m: FloatArray
    baro_sigma_m: FloatArray
    baro_error_m: FloatArray  # added to the barometer besides its thermal drift
    rangefinder_sigma_m: FloatArray
    rangefinder_max_m: float
    terrain: Callable[[FloatArray], FloatArray]
    segments: dict[str, tuple[float, float]] = field(default_factory=dict)  # flight time [s]


def _smoothstep(x: FloatArray) -> FloatArray:
    x = np.clip(x, 0.0, 1.0)
    return np.asarray(x * x * (3 - 2 * x))


def _flat(x: FloatArray) -> FloatArray:
    return np.zeros_like(x)


def _hills(x: FloatArray) -> FloatArray:
    """Ground height [m] relative to the take-off point at horizontal distance ``x`` [m]."""
    g = 2.0 * np.sin(2 * np.pi * x / 150.0) + 1.0 * np.sin(2 * np.pi * x / 37.0)
    return np.asarray(g)


def _between(t: FloatArray, up_s: float, rise_s: float, down_s: float, fall_s: float) -> FloatArray:
    """0 before ``up_s``, rising smoothly over ``rise_s`` to 1, falling over ``fall_s`` from
    ``down_s`` back to 0."""
    return np.asarray(_smoothstep((t - up_s) / rise_s) * (1 - _smoothstep((t - down_s) / fall_s)))


def _airborne(t: FloatArray, up_s: float, down_s: float) -> FloatArray:
    return _between(t, up_s, 2.0, down_s, 2.0)


def _phases(
    ground_s: float, cruise_s: float, land_s: float, end_s: float
) -> dict[str, tuple[float, float]]:
    """A flight's segments: on the ground, climbing, cruising, landing."""
    return {
        "ground": (0.0, ground_s),
        "climb": (ground_s, cruise_s),
        "cruise": (cruise_s, land_s),
        "landing": (land_s, end_s),
    }


def _level_profile(
    t: FloatArray, ground_s: float, climb_s: float, top_m: float, land_at_s: float | None
) -> FloatArray:
    up = _smoothstep((t - ground_s) / climb_s)
    down = 0.0 if land_at_s is None else _smoothstep((t - land_at_s) / climb_s)
    return np.asarray(top_m * up * (1 - down))


def mission(t: FloatArray, duration_s: float) -> Profile:
    """Take-off, a climb to 15 m, a cruise at 5 m/s over hills, out and back, a descent and a
    landing where it took off."""
    ground, climb = 10.0, 15.0
    land = duration_s - ground - climb
    up = _between(t, ground, climb, land, climb)
    h = _level_profile(t, ground, climb, 15.0, land) + 1.5 * np.sin(2 * np.pi * t / 40.0) * up
    flying = _airborne(t, ground + climb / 2, land + climb / 2)
    flown = np.cumsum(flying)
    turn = t[np.searchsorted(flown, flown[-1] / 2)]  # half the way flown: turn back
    ones = np.ones_like(t)
    return Profile(
        t=t,
        height_m=h,
        distance_m=np.cumsum(5.0 * flying * np.where(t < turn, 1.0, -1.0)) * DT_S,
        roll=np.deg2rad(3.0) * np.sin(2 * np.pi * t / 7.0) * flying,
        pitch=np.deg2rad(-5.0) * flying + np.deg2rad(1.0) * np.sin(2 * np.pi * t / 5.0),
        gps_sigma_m=0.35 * ones,
        baro_sigma_m=0.08 * ones,
        baro_error_m=0.0 * ones,
        rangefinder_sigma_m=0.03 * ones,
        rangefinder_max_m=20.0,
        terrain=_hills,
        segments=_phases(ground, ground + climb, land, duration_s),
    )


#: Paper A's experiment: 40 s of level flight (400 samples at 10 Hz) starting at this flight time.
PAPER_A_LEVEL_S = 20.0


def paper_a(t: FloatArray, duration_s: float) -> Profile:
    """Paper A's experiment (ALGORITHMS.md section 2) as a flight over flat ground.

    After take-off, 40 s of level flight near 15 m: samples 1-136 the sensors agree; 137-255 the
    barometer departs (up to +2.5 m and back); 256-400 all scatter, the sonar least. Then landing.
    """
    start = PAPER_A_LEVEL_S
    agree, departs, scatter = (
        (start, start + 13.6),
        (start + 13.6, start + 25.5),
        (start + 25.5, start + 40.0),
    )
    h = _level_profile(t, 8.0, 10.0, 15.0, duration_s - 18.0)
    # the swell fades in over the last metre of the climb: switched on at a threshold it was
    # a jump of up to 0.3 m, +-620 m/s^2 on the accelerometer, beyond any IMU's range
    h = h + 0.3 * np.sin(2 * np.pi * (t - start) / 16.0) * _smoothstep(h - 14.0)
    in_dep = (t >= departs[0]) & (t < departs[1])
    in_scatter = (t >= scatter[0]) & (t < scatter[1])
    departure = np.where(in_dep, 2.5 * np.sin(np.pi * (t - departs[0]) / 11.9), 0.0)
    return Profile(
        t=t,
        height_m=h,
        distance_m=np.zeros_like(t),  # over flat ground the distance does not matter
        roll=np.zeros_like(t),
        pitch=np.deg2rad(-2.0) * _airborne(t, 13.0, duration_s - 13.0),
        gps_sigma_m=np.where(in_scatter, 0.9, 0.25),
        baro_sigma_m=np.where(in_scatter, 0.6, np.where(in_dep, 0.25, 0.1)),
        baro_error_m=departure,
        rangefinder_sigma_m=np.where(in_scatter, 0.15, 0.05),
        rangefinder_max_m=20.0,
        terrain=_flat,
        segments={"agree": agree, "baro-departs": departs, "scatter": scatter},
    )


def hover(t: FloatArray, duration_s: float) -> Profile:
    """Paper B's experiment: a climb to 240 m at 3 m/s and a hover there (position hold)."""
    ground, climb = 10.0, 80.0
    h = _level_profile(t, ground, climb, 240.0, None)
    swell = 0.3 * np.sin(2 * np.pi * (t - ground - climb) / 20.0)
    h = h + swell * _smoothstep((t - ground - climb) / 5.0)  # no velocity jump at its start
    flying = _airborne(t, ground, duration_s + 10.0)
    ones = np.ones_like(t)
    return Profile(
        t=t,
        height_m=h,
        distance_m=np.zeros_like(t),
        roll=np.deg2rad(1.0) * np.sin(2 * np.pi * t / 9.0) * flying,
        pitch=np.deg2rad(1.0) * np.sin(2 * np.pi * t / 11.0) * flying,
        gps_sigma_m=0.7 * ones,
        baro_sigma_m=0.3 * ones,
        baro_error_m=0.0 * ones,
        rangefinder_sigma_m=0.05 * ones,
        rangefinder_max_m=40.0,
        terrain=_flat,
        segments={
            "ground": (0.0, ground),
            "climb": (ground, ground + climb),
            "hover": (ground + climb, duration_s),
        },
    )


def climb(t: FloatArray, duration_s: float) -> Profile:
    """A plane's flight as the simulators' climb logs show it: a take-off run, a climb to 300 m
    at up to 18 m/s (the GPS's lag is metres here), a cruise in banked turns with 20 m
    altitude changes, a descent and a landing where it took off."""
    ground, climb_s = 10.0, 25.0
    land = duration_s - ground - climb_s - 10.0
    up = _between(t, ground, climb_s, land, climb_s + 10.0)
    cruising = _between(t, ground + climb_s, 5.0, land, 5.0)
    h = 300.0 * up + 20.0 * np.sin(2 * np.pi * (t - ground - climb_s) / 40.0) * cruising
    flying = _airborne(t, ground, land + climb_s + 10.0)
    rate = np.gradient(h, DT_S)
    ones = np.ones_like(t)
    return Profile(
        t=t,
        height_m=h,
        distance_m=np.cumsum(20.0 * flying) * DT_S,
        roll=np.deg2rad(30.0) * np.sin(2 * np.pi * t / 30.0) * (up > 0.5),
        pitch=np.arctan2(rate, 20.0) * flying,
        gps_sigma_m=0.35 * ones,
        baro_sigma_m=0.1 * ones,
        baro_error_m=0.0 * ones,
        rangefinder_sigma_m=0.03 * ones,
        rangefinder_max_m=40.0,
        terrain=_flat,
        segments=_phases(ground, ground + climb_s, land, duration_s),
    )


def _hard_landing(t: FloatArray, h: FloatArray) -> FloatArray:
    """``h`` with its last descent cut at DROP_M: a fall from there onto the ground (h = 0) and
    bounces, each at RESTITUTION of the impact's speed, until the vehicle rests. The first impact
    reverses 5.5-6 m/s within a few 10 ms steps of the truth's clock: 23-27 g, clipped at the
    IMU's 16 g."""
    k = int(np.flatnonzero(h > DROP_M)[-1]) + 1  # the first tick below DROP_M on the way down
    out: FloatArray = h.copy()
    out[k:] = 0.0
    t0, z0, v0 = t[k - 1], float(h[k - 1]), float(h[k] - h[k - 1]) / DT_S
    while True:
        s_hit = (v0 + math.sqrt(v0 * v0 + 2 * G * z0)) / G  # z0 + v0 s - G s^2 / 2 = 0
        arc = (t >= t0) & (t < t0 + s_hit)
        s = t[arc] - t0
        out[arc] = z0 + v0 * s - 0.5 * G * s * s
        t0, z0, v0 = t0 + s_hit, 0.0, RESTITUTION * (G * s_hit - v0)
        if v0 < SETTLE_M_S:
            return out


#: The longest flight simulated [s]: 12 hours, a long-endurance plane's. A simulated hour
#: holds about 240 MB while it is made and written (10 hours: 2.4 GB, 16 s, a 93 MB log);
#: 11.6 days (1e6 s) took a 24 GB machine's memory and was killed by the system (SIGKILL)
#: after 8 minutes, without a word.
MAX_DURATION_S = 43_200.0


@dataclass(frozen=True)
class Scenario:
    name: str
    make: Callable[[FloatArray, float], Profile]
    default_duration_s: float
    min_duration_s: float
    lands: bool = True  # its last descent reaches the ground
    cruises: bool = True  # it flies horizontally (a ground speed)


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario("paper-a", paper_a, 75.0, 75.0, cruises=False),
        Scenario("hover", hover, 180.0, 120.0, lands=False, cruises=False),
        Scenario("mission", mission, 120.0, 60.0),
        Scenario("climb", climb, 150.0, 120.0),
    )
}
FAULTS = (
    "baro-drift",
    "gps-glitch",
    "rangefinder-dropout",
    "lose-gps",
    "lose-baro",
    "lose-rangefinder",
    "imu-impact",
    "attitude-error",
    "imu-clip",
    "imu-25hz",
    "baro-scale",
    "baro-airflow",
    "rangefinder-low",
    "roll-flip",
    "splice",
    "hard-landing",
    "baro-rezero",
)
#: The faults that need a scenario that lands, and one that cruises.
LANDING_FAULTS = ("hard-landing",)
CRUISING_FAULTS = ("baro-airflow",)
#: The accelerometer's range [m/s^2]: ArduPilot's IMUs clip at 16 g.
IMU_CLIP_M_S2 = 16.0 * G
#: A barometer's scale error with ``baro-scale``: 7 % high, as the simulators' climbs show.
BARO_SCALE = 1.07
#: How much higher the barometer reads at the flight's top airspeed with ``baro-airflow``
#: [m]: ``k V^2 / 2g`` (the static pressure lowered by ``k`` times the dynamic pressure), ``k``
#: 0.40 at the mission's 7 m/s (two real copters' barometers read 0.8 and 1.2), 0.06 at the
#: plane's 18 m/s.
BARO_AIRFLOW_M = 1.0
#: ... at the airspeed in a steady wind of this [m/s] blowing along the track (from the south,
#: the way the flights set out): the mission's legs out and back fly through the air at 3 and
#: 7 m/s at one ground speed, 5 m/s, the plane's at 18 and 22 m/s.
BARO_AIRFLOW_WIND_M_S = 2.0
#: The rangefinder's mount height with ``rangefinder-low``: below its minimum range, so that
#: on the ground it reads OutOfRangeLow.
RANGEFINDER_LOW_MOUNT_M = 0.1
#: How long the turn of ``roll-flip`` takes [s] (540 deg/s at its fastest).
FLIP_S = 1.0
#: How long nothing is logged with ``splice`` [s], from half the flight.
SPLICE_S = 20.0
#: ``baro-rezero``: how much higher the barometer reads on the ground before the vehicle arms
#: [m] (it drifted so since boot, a warming sensor: one real copter's rose 2.5 m in 72 s), and
#: how long before take-off it arms [s]; there the autopilot re-zeroes it and logs ``EV``
#: ``EKF_ALT_RESET`` (:data:`altfuse.io.dataflash.EV_EKF_ALT_RESET`), as Copter arming without
#: a home does.
REZERO_DRIFT_M = 2.0
ARMING_LEAD_S = 3.0
#: ``hard-landing``: the height [m] at which the motors cut on the last descent, and the share of
#: its speed the vehicle keeps, upwards, at each impact (its legs' restitution); it rests once
#: it bounces slower than SETTLE_M_S.
DROP_M = 1.0
RESTITUTION = 0.3
SETTLE_M_S = 0.1


@dataclass(frozen=True)
class SimulatedFlight:
    """The truth on the ``DT_S`` clock, the records to log by type, and how far the sensors lag
    the truth [s]: every one (``latency_s``), the GPS (``gps_lag_s``, the latency included)."""

    __repr__ = brief_repr

    scenario: str
    seed: int
    duration_s: float
    faults: tuple[str, ...]
    profile: Profile
    records: Records
    latency_s: float
    gps_lag_s: float


def applicable_faults(scenario: str) -> tuple[str, ...]:
    """The faults ``scenario`` can take: all but LANDING_FAULTS where it does not land, and
    CRUISING_FAULTS where it does not cruise."""
    spec = SCENARIOS[scenario]
    return tuple(
        f
        for f in FAULTS
        if (spec.lands or f not in LANDING_FAULTS) and (spec.cruises or f not in CRUISING_FAULTS)
    )


def _fault_window(duration_s: float, start: float, length_s: float) -> tuple[float, float]:
    return start * duration_s, start * duration_s + length_s


def simulate_flight(  # noqa: C901, PLR0915 (one flight's sensor models in turn, top to bottom)
    scenario: str = "mission",
    seed: int = 0,
    duration_s: float | None = None,
    faults: str | Sequence[str] = (),
) -> SimulatedFlight:
    """Simulate ``scenario`` and its sensors (see the module doc), with ``faults`` (one fault's
    name, or several)."""
    faults = (faults,) if isinstance(faults, str) else tuple(faults)
    if scenario not in SCENARIOS:
        raise ParameterError(f"unknown scenario {scenario!r}; choose one of {', '.join(SCENARIOS)}")
    spec = SCENARIOS[scenario]
    if not (is_number(seed) and float(seed).is_integer() and seed >= 0):
        raise InvalidParameter("seed", f"must be a whole number >= 0, got {seed!r}")
    if duration_s is not None and not is_number(duration_s):
        raise InvalidParameter("duration_s", f"must be a number of seconds, got {duration_s!r}")
    duration = spec.default_duration_s if duration_s is None else float(duration_s)
    if not spec.min_duration_s <= duration <= MAX_DURATION_S:  # and not NaN
        raise InvalidParameter(
            "duration_s",
            f"must be from {spec.min_duration_s:g} s (for {scenario}) to {MAX_DURATION_S:g} s"
            f" (12 hours), got {duration:g}",
        )
    unknown = [f for f in faults if f not in FAULTS]
    if unknown:
        raise ParameterError(f"unknown fault {unknown[0]!r}; choose from {', '.join(FAULTS)}")
    if refused := [f for f in faults if f not in applicable_faults(scenario)]:
        able = ", ".join(n for n in SCENARIOS if refused[0] in applicable_faults(n))
        need = "land" if refused[0] in LANDING_FAULTS else "cruise"
        raise ParameterError(f"{scenario} does not {need}: {refused[0]} needs one of {able}")
    rng = np.random.default_rng(int(seed))
    t = np.arange(0.0, duration, DT_S)
    p = spec.make(t, duration)
    records: Records = {}

    def at(rate_hz: float) -> FloatArray:
        return np.arange(0.0, duration, 1.0 / rate_hz)

    def truth(ts: FloatArray, values: FloatArray, lag_s: float = 0.0) -> FloatArray:
        return np.interp(ts - lag_s, t, values)

    # with splice, nothing is logged for SPLICE_S while the vehicle flies on
    paused = _fault_window(duration, 0.5, SPLICE_S) if "splice" in faults else (np.inf, np.inf)

    def log(name: str, times: FloatArray, *columns: FloatArray | float) -> None:
        logged = (times < paused[0]) | (times >= paused[1])
        cols = [np.broadcast_to(np.asarray(c), times.shape)[logged] for c in columns]
        records[name] = [
            (float(ti), tuple(c[k] for c in cols)) for k, ti in enumerate(times[logged])
        ]

    def keep(name: str, times: FloatArray) -> FloatArray:
        return times[times < 0.5 * duration] if f"lose-{name}" in faults else times

    if "roll-flip" in faults:  # one turn: the attitude after it is the one before
        lo, _ = _fault_window(duration, 0.35, FLIP_S)
        p = replace(p, roll=p.roll + 2 * np.pi * _smoothstep((t - lo) / FLIP_S))
    if "hard-landing" in faults:
        p = replace(p, height_m=_hard_landing(t, p.height_m))

    # every sensor's common latency behind the log's timestamps, and the GPS's own lag: from
    # their own stream, every other draw stays as it was
    timing = np.random.default_rng((seed, 2))
    latency = timing.uniform(*LATENCY_S)
    gps_lag = latency + timing.uniform(*GPS_LAG_S)

    def sensed(ts: FloatArray, values: FloatArray, lag_s: float = latency) -> FloatArray:
        """What a sensor stamps ``ts`` saw: the truth ``lag_s`` earlier."""
        return truth(ts, values, lag_s)

    # GPS: 5 Hz, lagging, AMSL, white noise + random walk, no fix for the first 3 s
    ts = keep("gps", at(5.0))
    fix = ts >= 3.0
    alt = HOME_AMSL_M + sensed(ts, p.height_m, gps_lag)
    alt = (
        alt
        + np.cumsum(rng.normal(0.0, 0.05, ts.size))
        + truth(ts, p.gps_sigma_m) * rng.normal(0.0, 1.0, ts.size)
    )
    alt = alt + np.where(fix, 0.0, 12.0)
    if "gps-glitch" in faults:
        lo, hi = _fault_window(duration, 0.6, 5.0)
        alt = alt + np.where((ts >= lo) & (ts < hi), 15.0, 0.0)
    # GPS time (week and ms of week) once fixed, 0 before, as receivers report it
    gms = np.where(fix, GPS_MS_OF_WEEK + np.round((BOOT_S + ts) * 1000), 0)
    climb = np.gradient(p.height_m, DT_S)
    along = np.gradient(p.distance_m, DT_S)  # the ground velocity along the track, north
    speed = np.abs(along)  # over the ground, horizontal
    # the velocity's noise from its own stream: every other sensor's draw stays as it was
    climb_noise = np.random.default_rng((seed, 1)).normal(0.0, GPS_VZ_SIGMA_M_S, ts.size)
    log(
        "GPS",
        ts,
        0,
        np.where(fix, 3, 1),
        gms,
        np.where(fix, GPS_WEEK, 0),
        np.where(fix, 14, 4),
        np.where(fix, 0.8, 9.99),
        HOME_LAT,
        HOME_LNG,
        alt,
        sensed(ts, speed, gps_lag),
        np.where(sensed(ts, along, gps_lag) < 0.0, 180.0, 0.0),  # the course, deg from north
        -(sensed(ts, climb, gps_lag) + climb_noise),
        0.0,
        1,
    )

    # barometer: 20 Hz, thermal drift, scenario error, noise
    ts = keep("baro", at(20.0))
    temp = 25.0 + 10.0 * (1 - np.exp(-ts / 60.0))
    scale = BARO_SCALE if "baro-scale" in faults else 1.0
    alt = scale * sensed(ts, p.height_m) + 0.12 * (temp - 25.0) + truth(ts, p.baro_error_m)
    alt = alt + truth(ts, p.baro_sigma_m) * rng.normal(0.0, 1.0, ts.size)
    if "baro-drift" in faults:
        alt = alt + 0.05 * np.clip(ts - 0.4 * duration, 0.0, None)
    if "baro-airflow" in faults:
        air = np.abs(along - BARO_AIRFLOW_WIND_M_S)  # through the air, the wind from the south
        alt = alt + BARO_AIRFLOW_M * (sensed(ts, air) / air.max()) ** 2
    if "baro-rezero" in faults:
        armed = float(t[np.argmax(p.height_m > 0.0)]) - ARMING_LEAD_S
        alt = alt + np.where(ts < armed, REZERO_DRIFT_M, 0.0)
        records["EV"] = [(armed, (EV_EKF_ALT_RESET,))]
    log("BARO", ts, 0, alt, temp, 1)

    # rangefinder: 20 Hz along the body axis, out-of-range codes as drivers log them
    ts = keep("rangefinder", at(20.0))
    ground = p.terrain(sensed(ts, p.distance_m))
    tilt = np.cos(sensed(ts, p.roll)) * np.cos(sensed(ts, p.pitch))
    mount = RANGEFINDER_LOW_MOUNT_M if "rangefinder-low" in faults else RANGEFINDER_MOUNT_M
    # pointing above the horizon it sees no ground: beyond its maximum
    dist = np.full(ts.size, np.inf)
    np.divide(sensed(ts, p.height_m) - ground + mount, tilt, out=dist, where=tilt > 0)
    dist = dist + truth(ts, p.rangefinder_sigma_m) * rng.normal(0.0, 1.0, ts.size)
    stat = np.where(dist > p.rangefinder_max_m, 3, np.where(dist < RANGEFINDER_MIN_M, 2, 4))
    dist = np.clip(dist, RANGEFINDER_MIN_M, p.rangefinder_max_m)
    if "rangefinder-dropout" in faults:
        lo, hi = _fault_window(duration, 0.5, 10.0)
        out = (ts >= lo) & (ts < hi)
        stat, dist = np.where(out, 1, stat), np.where(out, 0.0, dist)  # 1 = NoData
    # logged as newer ArduPilot does: centimetres in an int16, multiplier B (0.01) in FMTU
    log("RFND", ts, 0, np.round(100 * dist), stat, 25)
    # and configured as ArduPilot logs it at boot: range limits, and what it reads when landed
    params = {
        "RNGFND1_MIN_CM": 100 * RANGEFINDER_MIN_M,
        "RNGFND1_MAX_CM": 100 * p.rangefinder_max_m,
        "RNGFND1_GNDCLEAR": 100 * mount,
    }
    records["PARM"] = [(0.0, (key, round(value))) for key, value in params.items()]

    # IMU: 50 Hz (or 25) specific force in FRD, with bias and noise
    ts = at(25.0 if "imu-25hz" in faults else 50.0)
    r, pitch = sensed(ts, p.roll), sensed(ts, p.pitch)
    acc_up = np.gradient(np.gradient(p.height_m, DT_S), DT_S)
    f_down = -(G + sensed(ts, acc_up))
    # f_body = R_ned_to_body @ (0, 0, f_down), yaw 0
    f_body = np.stack(
        [
            -np.sin(pitch) * f_down,
            np.sin(r) * np.cos(pitch) * f_down,
            np.cos(r) * np.cos(pitch) * f_down,
        ]
    )
    f_body = f_body + rng.normal(0.0, 0.15, (3, ts.size)) + np.array([[0.0], [0.0], [0.05]])
    f_body = np.clip(f_body, -IMU_CLIP_M_S2, IMU_CLIP_M_S2)  # the sensor's range
    if "imu-impact" in faults:  # up is -Z in FRD
        f_body[2, np.searchsorted(ts, 0.45 * duration)] -= 25.0 * G
    if "imu-clip" in faults:  # a shock up, five samples pinned at the sensor's range
        first = np.searchsorted(ts, 0.65 * duration)
        f_body[2, first : first + 5] = -IMU_CLIP_M_S2
    log("IMU", ts, 0, *f_body)

    ts = at(10.0)
    roll_logged = np.rad2deg(sensed(ts, p.roll))
    if "attitude-error" in faults:
        lo, hi = _fault_window(duration, 0.55, 10.0)
        roll_logged = roll_logged + np.where((ts >= lo) & (ts < hi), 30.0, 0.0)
    wrapped = (roll_logged + 180.0) % 360.0 - 180.0  # as logged: in [-180, 180)
    roll_logged = np.where(np.abs(roll_logged) > 180.0, wrapped, roll_logged)
    log("ATT", ts, roll_logged, np.rad2deg(sensed(ts, p.pitch)), 0.0)
    log("SIM", ts, HOME_AMSL_M + truth(ts, p.height_m))
    return SimulatedFlight(scenario, int(seed), duration, faults, p, records, latency, gps_lag)


_TYPES = {
    # name: (format, columns, units, multipliers), ArduPilot 4.x layouts (subsets)
    "GPS": (
        "QBBIHBcLLeffffB",
        "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U",
        "s#-s-S-DUmnhnh-",
        "F--C--BGGB000--",
    ),
    "BARO": ("QBffB", "TimeUS,I,Alt,Temp,Health", "s#mO-", "F-00-"),
    "RFND": ("QBhBB", "TimeUS,Instance,Dist,Stat,Orient", "s#m--", "F-B--"),
    "IMU": ("QBfff", "TimeUS,I,AccX,AccY,AccZ", "s#ooo", "F-000"),
    "ATT": ("Qfff", "TimeUS,Roll,Pitch,Yaw", "sddh", "F000"),
    "SIM": ("Qf", "TimeUS,Alt", "sm", "F0"),
    "MSG": ("QZ", "TimeUS,Message", "s-", "F-"),
    "PARM": ("QNf", "TimeUS,Name,Value", "s--", "F--"),
    "EV": ("QB", "TimeUS,Id", "s-", "F-"),
}


def write_simulated_log(flight: SimulatedFlight, path: str | Path) -> int:
    """Write ``flight`` as a DataFlash log at ``path`` (atomically); return the record count.
    A name of another format (``hover.csv``, ``hover.ulg``) is refused
    (:func:`altfuse.write.check_log_path`)."""
    path = Path(path)
    check_log_path(path)
    rows: list[tuple[float, str, tuple[object, ...]]] = [
        (BOOT_S + ti, name, values) for name, recs in flight.records.items() for ti, values in recs
    ]
    rows.sort(key=lambda row: row[0])
    records = 0

    def write(handle: BinaryIO) -> None:
        nonlocal records
        from altfuse.io.dataflash_writer import DataFlashWriter  # pymavlink's tables: 50 ms

        writer = DataFlashWriter(handle)
        for name, (fmt, columns, units, mults) in _TYPES.items():
            if name in flight.records or name == "MSG":  # written below
                writer.define(name, fmt, columns, units, mults)
        faults = ", faults " + "+".join(flight.faults) if flight.faults else ""
        message = (
            f"ArduCopter V4.0.0 (simulated by altfuse {__version__}: {flight.scenario}, "
            f"seed {flight.seed}{faults})"
        )
        writer.write("MSG", int(BOOT_S * 1e6), message[:64])
        for time_s, name, values in rows:
            writer.write(name, round(time_s * 1e6), *values)
        records = writer.records

    with atomic_outputs() as stage:
        stage(path, write, binary=True)
    return records
