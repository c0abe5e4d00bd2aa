"""The smoother's state-space model: the state's layout, its transition ``F``, process noise
``Q``, measurement rows ``H``, prior, and the ground constraint (the module doc of
:mod:`altfuse.fuse.smoother` gives the equations)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from altfuse.datum import GROUND_MAX_SPEED_M_S
from altfuse.datum.scale import DYNAMIC_PRIOR, dynamic_head
from altfuse.fuse.smoother.compiled import compiled_step
from altfuse.fuse.smoother.events import TICK, VELOCITY
from altfuse.fuse.smoother.kalman import assign, innovation, update
from altfuse.metrics import mad_sigma, running_median, runs
from altfuse.model import FloatArray, Samples

#: Accelerometer bias random walk [m^2/s^5].
Q_BIAS = 1e-5
#: Prior on a barometer's temperature coefficient [m/degC] (a constant, learnt from the flight).
THERMAL_PRIOR = 0.5
#: Prior on the scale error of a barometer whose scale the datum could not tell [-]: barometers
#: read 3-8 % high (:mod:`altfuse.datum`). Measured 0.03, 0.05 and 0.1: the truth logs within
#: 0.2 mm of each other, the simulated flights within 10 %. The smoother learns the scale only
#: where the datum's estimate is at least this good (a standard error of at most SCALE_PRIOR)
#: and agrees with it within SCALE_AGREE_SIGMAS of that error: where the datum's estimate
#: says nothing (+-0.09 to +-0.33 on the real logs shared), the smoother's likelihood, whose
#: GPS wander is a random walk, found 8-28 % scales that took its fused height 0.2-0.7 m
#: further from the autopilot's EKF on 3 of 5 logs.
SCALE_PRIOR = 0.05
SCALE_AGREE_SIGMAS = 2.0
#: A scale the datum applied with a standard error above this [-] (it applies up to
#: ``altfuse.datum.scale.MAX_SCALE_STD``) the smoother learns again from the barometer's readings
#: referred by their offset only, and keeps where the log's evidence takes it
#: (:func:`.evidence.relearnt_scales`): the datum's fit sees the GPS alone, the smoother the
#: accelerometer too. Measured: altfuse's hovers 240 m high with the barometer 7 % high (the
#: datum's 1.074-1.075 +- 0.013-0.014) 0.483 / 0.218 / 0.714 -> 0.040 / 0.195 / 0.403 m RMSE,
#: +-2 sigma coverage 0.17 / 0.61 / 0.12 -> 1.00 / 0.95 / 0.65, no other simulated flight
#: changed; the quadplane's truth log (1.053 +- 0.010) 0.024 -> 0.014 m, its maximum 0.052 ->
#: 0.039 m, coverage 0.980 -> 0.997; begun at 40 and 60 % of its span 0.421 / 0.373 -> 0.012 /
#: 0.015 m; the 104 cut truth logs over the bar on RMSE 6 -> 4, on the maximum 6 -> 4. The real
#: logs' outputs are unchanged (a real 45-minute flight's 1.17 +- 0.016: the evidence does not
#: take it, the datum's stays). Every barometer's scale is learnt again where one's is
#: (:func:`scales_to_relearn`). At 0.005 the truth logs' 92 m climb 0.027 -> 0.035 m, the 4.5
#: plane 0.024 -> 0.029, the 305 m climb with a real receiver's GPS 0.367 -> 0.491 (its
#: barometer 0.445): not taken.
LEARN_SCALE_STD = 0.01
#: A barometer's drift rate [m/s]: its prior at the start, and its random-walk density
#: [m^2/s^3] (the rate may change by about 0.03 m/s in 100 s). Tried: 1e-6 mended three more
#: of ``benchmarks/variant_logs.py``'s drifting barometers and cost the noisy ones (10 -> 7 of
#: 13 logs within the bar), the 20 % scales (9 -> 7) and the 3.3 plane's coverage (0.99 ->
#: 1.00): not taken.
DRIFT_PRIOR = 0.01
Q_DRIFT = 1e-5
#: The share of a barometer's offset wander, and of its drift rate's, that every barometer of
#: the vehicle shares (the correlation of their random walks' increments): they read one air,
#: its weather, the airflow past the airframe and the warmth of one board. Taken as
#: independent, two barometers outvote a GPS on what they share: the 4.4.4 hop's two in a 3
#: m/s wind (``benchmarks/variant_logs.py``, ``windy-3``) each needed a drift rate of its own
#: where one drift of the GPS explained both (gains 49 and 62), and the height followed them
#: 0.168 m RMSE from the truth, where either barometer alone with the GPS gave 0.044 and 0.019;
#: at 0.9, 0.045. The autopilots' own estimators fuse one barometer at a time (ArduPilot's
#: primary, PX4's ``vehicle_air_data``). Measured on the five truth logs with two barometers
#: (the rest have one and do not move): their RMSE within 0.3 mm, the hop's coverage 0.911 ->
#: 0.901; the worst case per log over the variants the hop 4.88 -> 1.29, the 4.5 copter's
#: rangefinder flight 0.69 -> 0.53, the quadplane 5.24 -> 5.00, the others within 0.05; with
#: one barometer of the two drifting, flashed, noisy, stepped or 10 % off alone, within the
#: bar as before (the quadplane's second one 10 % off: 0.018 -> 0.030 m, its best sensor's
#: 0.008). At 0.5 the hop in a wind stays at 4.87; at 0.99 as at 0.9 within 0.06.
BARO_SHARED = 0.9
#: How well "standing still at the take-off point" holds on the ground [m, m/s], per tick: a
#: vehicle on its gear moves its IMU by millimetres (the gear giving as the motors spin up).
#: At 0.02 the ground span pinned the offsets only to 2 cm over the root of its ticks: a 0.6 s
#: span (the hexa's) left fused_std 7.6 mm for a flight whose errors are 3-5 mm, and a PX4 log
#: that starts on the ground, with a prior of 2 cm on every offset, 1.6 cm for errors of 5 mm.
#: Measured at 0.005 on the truth logs: the quadplane 0.030 -> 0.025 m RMSE, coverage 0.81 ->
#: 0.91; a static PX4 log 0.0083 -> 0.0066 m; the rest within 0.6 mm; the simulated flights'
#: coverage 95.2 -> 95.0 %, within 10 % of the best on the same 158 of 159.
STILL_SIGMA = 0.005
#: The barometers' error in the rotors' wash (``w``, one for every barometer: they read one
#: air), in each span the datum says the vehicle may be in it: a random walk from 0 at the
#: span's start, held to 0 again at its end, whose spread at the span's middle is this [m].
#: Measured on the truth logs' variants (``benchmarks/variant_logs.py``, the 14 default and
#: ``wash-1``, ``wash-2``): the logs as logged never take it, and barometers 0.5 m low in the
#: wash are within the bar on 10 of 13 at 0.2, 0.3, 0.5 and 1 m alike (8 without the wash);
#: at 0.2 the 92 m climb 0.038 -> 0.041 m RMSE, at 0.5 and 1 the rangefinder flight 0.034 ->
#: 0.037, at 1 the 10 m sonar 0.088 -> 0.104. A Gaussian spread wide enough for a dip pays for
#: it in every sample of the span (the filter's likelihood integrates over it): at 1 m the
#: test lost the wash on logs that had one, until the samples only the wash lets in counted.
WASH_SIGMA = 0.3
#: The autopilot's landed verdict is trusted this long [s] inside each of its landed spans
#: from each of their turns (a detector says "landed" after the touch-down, "flying" after the
#: lift-off; a span's end that is the log's own is no turn), while the GPS says the vehicle
#: moves slower than GROUND_MAX_SPEED_M_S, and where the height sensors do not agree it climbs
#: or sinks faster than that (:func:`landed_events`).
LANDED_MARGIN_S = 2.0
#: What a splice resets (the rows of :func:`reset_states`): nothing, where the vehicle is (a
#: log resumed in flight, its sensors' offsets the main segment's), and where the vehicle is
#: with every sensor's offset and drift (a segment referred to its own ground).
RESET_NONE, RESET_MOTION, RESET_DATUM = 0, 1, 2
#: A GPS's vertical error is bounded: its offset is a first-order Gauss-Markov process of this
#: correlation time [s] (``dc = -c dt / tau + dw``: stationary receivers' errors fit an
#: Ornstein-Uhlenbeck process, not a random walk, Schumayer et al., Sensors 20(21) 6050,
#: 2020, doi:10.3390/s20216050), of its random-walk density ``q`` at spans short against
#: ``tau``, its standard deviation never above ``sqrt(q tau / 2)`` (1.7 m for the default
#: 0.01 m^2/s, 0.17 m for a stable GPS's 1e-4). The barometer's offset stays a random walk (the
#: weather moves it for hours). With both random walks nothing held the height's common mode:
#: a real 150 s flight repeated for 45 minutes had its fused height 4.2 m from GPS and
#: barometer, which agreed within a metre, fused_std 2.6 m; over 7.4 hours 42.8 m, 160,983 of
#: 265,476 ticks diverged. Measured at 300 / 600 / 1200 / 3600 s (``benchmarks/gps_bound.py``):
#: that flight's largest gap from a sensor 0.95 / 0.85 / 1.94 / 3.16 m; on the 192 simulated
#: flights, whose GPS is a random walk, the worst RMSE against the random walk's 1.30 / 1.14 /
#: 1.07 / 1.02 (the smoother still the lowest of all methods on every one at 600 s); the truth
#: logs within 1 mm and 0.003 of coverage, 9 of 13 passing at each (measured again since the
#: agreement is also measured on blocks' means). ``--gps-correlation``.
GPS_CORRELATION_S = 600.0
#: Prior on a sensor's offset from the datum [m], where the flight says nothing better; and the
#: fewest samples on the ground that say better.
OFFSET_PRIOR = 1.0
MIN_DATUM_SAMPLES = 3


@dataclass(frozen=True)
class Regressor:
    """A constant state that enters one sensor's measurement as ``coef * state``, with a
    zero-mean prior of standard deviation ``prior``: a barometer's temperature coefficient
    (``coef``: its temperature change [degC]), its scale error (``coef``: the height, as
    smoothed without it; :func:`scale_regressors`), or its dynamic-pressure coefficient
    (``coef``: the dynamic head ``V^2 / 2g`` [m]; :func:`dynamic_regressors`); the GPS's
    vertical velocity's lag (:mod:`.velocity`). (Tried and dropped, measured: the scale
    error of every barometer, ``coef`` its own reading, which a GPS's wander confounds on a
    climb, 92 m climb 0.047 -> 0.100 m RMSE, and which a barometer explains away with a
    scale error of 1, a PX4 log 0.006 -> 1.03 m; a sensor's lag, ``coef`` minus the velocity,
    quadplane 0.026 -> 0.195 m.)"""

    name: Literal["thermal", "scale", "lag", "dynamic"]
    sensor: int
    coef: FloatArray  # per event; read at the sensor's own samples only
    prior: float


def datum_priors(
    samples: Sequence[Samples], windows: Sequence[tuple[float, float] | None]
) -> FloatArray:
    """Each offset's prior sigma [m] for a flight with no span known to stand still (a log that
    starts moments before take-off, or with no take-off found): where a sensor's offset was
    measured on the datum window (``windows``, :attr:`altfuse.datum.Referred.datum_windows`:
    before take-off, or the log's first seconds, where the datum is defined), the standard error
    of that measurement (its samples' robust spread there over the root of their count) with
    STILL_SIGMA, how well the vehicle held there; OFFSET_PRIOR elsewhere. With OFFSET_PRIOR on
    the first seconds too, a PX4 simulator log standing on the ground had fused_std 0.70 m for
    errors of 1 cm (now 0.017 m)."""
    out = np.full(len(samples), OFFSET_PRIOR)
    for i, (s, window) in enumerate(zip(samples, windows, strict=True)):
        if window is None:
            continue
        there = s.value[(s.t >= window[0]) & (s.t <= window[1])]
        if there.size < MIN_DATUM_SAMPLES:
            continue
        out[i] = math.hypot(mad_sigma(there) / math.sqrt(there.size), STILL_SIGMA)
    return out


def still_events(
    times: FloatArray,
    who: np.ndarray,
    spans: Sequence[tuple[float, float]],
    model: np.ndarray | None = None,
) -> np.ndarray:
    """The clock ticks at which the vehicle stands at its take-off point (``spans``: the
    datum's ground windows, one per segment of a spliced log with its own ground); of the
    ``model`` events alone where given (:attr:`Events.model`: as many holds at every output
    rate)."""
    out = np.zeros(times.size, dtype=bool)
    for lo, hi in spans:
        out |= (times >= lo) & (times <= hi)
    out &= who == TICK
    return out if model is None else out & model


def wash_depths(
    times: FloatArray, wash: FloatArray, spans: Sequence[tuple[float, float]]
) -> tuple[float, float]:
    """How far the barometers' wash ``wash`` (smoothed, at ``times``) dips below the lower of
    its ends in any of ``spans``, and how far it rises above the higher [m] (where the log
    begins in a span, its first value there is that end)."""
    dip = rise = 0.0
    for lo, hi in spans:
        inside = wash[(times >= lo) & (times <= hi)]
        if inside.size:
            ends = (inside[0], inside[-1])
            dip = max(dip, float(min(ends) - inside.min()))
            rise = max(rise, float(inside.max() - max(ends)))
    return dip, rise


def wash_density(span: tuple[float, float]) -> float:
    """The density [m^2/s] of the wash's random walk over ``span``: WASH_SIGMA at its middle,
    where a walk from 0 held to 0 again at the end has a quarter of its whole variance."""
    return 4.0 * WASH_SIGMA**2 / max(span[1] - span[0], 1e-3)


def cleared_events(
    times: FloatArray,
    who: np.ndarray,
    spans: Sequence[tuple[float, float]],
    model: np.ndarray | None = None,
) -> np.ndarray:
    """The clock ticks at which the barometers have left the rotors' wash (``w = 0``): the
    first of each span's end (``spans``: the datum's, :attr:`FusionInput.ground_effect_s`);
    of the ``model`` events alone where given (:func:`still_events`)."""
    out = np.zeros(times.size, dtype=bool)
    ticks = np.flatnonzero((who == TICK) & (True if model is None else model))
    for _, hi in spans:
        k = int(np.searchsorted(times[ticks], hi))
        if k < ticks.size:
            out[ticks[k]] = True
    return out


def reset_events(times: FloatArray, splices: Sequence[tuple[float, bool]]) -> np.ndarray:
    """Per event, what a splice resets there (RESET_*): at the first event of each segment
    after the first (``splices``: its start and whether it was referred to a ground)."""
    out = np.zeros(times.size, dtype=np.int8)
    for start, grounded in splices:
        k = int(np.searchsorted(times, start))
        if k < times.size:
            out[k] = RESET_DATUM if grounded else RESET_MOTION
    return out


def first_height(who: np.ndarray, z: FloatArray, start: int = 0, default: float = 0.0) -> float:
    """A height guess from event ``start`` on: the median of each sensor's first sample there
    (``who``, ``z``: the events' series and values), ``default`` where none has one. Where the
    log starts, and where a segment of a spliced log does: nothing says where the vehicle went
    meanwhile, and a guess from before the splice (300 m off after a plane's pause in its
    cruise) shuts the gate on every sensor."""
    series = who[start:]
    sensors = np.unique(series[series >= 0])
    if sensors.size == 0:
        return default
    return float(np.median([z[start + int(np.argmax(series == i))] for i in sensors]))


def landed_events(
    times: FloatArray,
    who: np.ndarray,
    landed: Samples | None,
    speed: Samples | None,
    climb: Samples | None = None,
    model: np.ndarray | None = None,
) -> np.ndarray:
    """The clock ticks at which the vehicle stands on the ground by the autopilot's own land
    detector (``landed``: PX4's ``vehicle_land_detected``, ArduPilot's ``STAT.isFlying``), each
    landed span less ``LANDED_MARGIN_S`` at either end where the verdict turns there (a
    detector decides with a delay; the verdict's first and last samples are no turn: the
    vehicle stood there before the log began and after it ended as far as it tells), and not
    where the GPS says it rolls faster than ``GROUND_MAX_SPEED_M_S`` (a plane taxiing on a
    sloping field climbs with it). There the smoother holds v = 0. A span in which the
    sensors climb or sink that fast (``climb``: :func:`sensed_climb`) is no landing at all: a
    detector can say landed in the air (Copter 3.4's did in a 10 m/s descent, its motors at
    their lower limit), and a descent held at v = 0 ends metres off every sensor. Of the
    ``model`` events alone where given (:func:`still_events`).

    With the margin at the log's own ends too, two PX4 simulator logs standing on the ground
    throughout had their first and last 2 s free: the height sloped 4 cm there in an 11 s log
    (0.013 m RMSE against the groundtruth where the EKF's is 0.011; 0.007 since), and the
    6ba1abc7 log 0.007 m (0.002 since). The quadplane's truth log, its verdict landed from its
    first sample, 0.018 -> 0.021 m (a temperature coefficient its evidence now asks for); the
    other truth logs and the simulated flights unchanged."""
    out = np.zeros(times.size, dtype=bool)
    if landed is None or landed.t.size == 0:
        return out
    order = np.argsort(landed.t, kind="stable")
    t, on = landed.t[order], landed.value[order] > 0.5
    for a, b in runs(on):  # the spans [start, end) over which the verdict is "landed"
        lo = t[a] + LANDED_MARGIN_S if a > 0 else t[a]
        hi = t[b] - LANDED_MARGIN_S if b < t.size else t[-1]
        if climb is not None:
            inside = (climb.t >= lo) & (climb.t <= hi)
            if np.any(np.abs(climb.value[inside]) > GROUND_MAX_SPEED_M_S):
                continue
        out |= (times >= lo) & (times <= hi)
    out &= who == -1
    if speed is not None and speed.t.size:
        order = np.argsort(speed.t, kind="stable")
        rolling = np.interp(times, speed.t[order], speed.value[order]) > GROUND_MAX_SPEED_M_S
        out &= ~rolling
    return out if model is None else out & model


def sensed_climb(t: FloatArray, z: FloatArray, dt_s: float) -> Samples:
    """The vertical speed [m/s] the height sensors agree on at the ticks ``t`` (``z``: one
    column each): each one's change over the last second of its 1 s running median, the
    slowest of them where all go one way (one sensor's step is no climb), else 0; NaN where
    fewer than two tell one."""
    n = max(1, round(1.0 / dt_s))
    rates = np.full(z.shape, np.nan)
    for i in range(z.shape[1]):
        smooth = running_median(z[:, i], n)
        rates[n:, i] = (smooth[n:] - smooth[:-n]) / (t[n:] - t[:-n])
    told = np.isfinite(rates).sum(axis=1) >= 2
    up = np.where(np.isfinite(rates), rates, np.inf).min(axis=1)
    down = np.where(np.isfinite(rates), rates, -np.inf).max(axis=1)
    agreed = np.where(up > 0.0, up, np.where(down < 0.0, down, 0.0))
    return Samples(t, np.where(told, agreed, np.nan))


def thermal_regressors(
    temperatures: Sequence[Samples | None],
    samples: Sequence[Samples],
    who: np.ndarray,
    position: np.ndarray,
) -> list[Regressor]:
    """A temperature coefficient for each sensor with a logged temperature: ``coef`` its
    temperature less its first one [degC]."""
    out = []
    for i, temp in enumerate(temperatures):
        if temp is None or temp[0].size < 2 or not samples[i][0].size:
            continue
        order = np.argsort(temp[0], kind="stable")
        at_samples = np.interp(samples[i][0], temp[0][order], temp[1][order])
        dtemp = np.zeros(who.size)
        mine = who == i
        dtemp[mine] = (at_samples - at_samples[0])[position[mine]]
        out.append(Regressor("thermal", i, dtemp, THERMAL_PRIOR))
    return out


def dynamic_regressors(
    speed: Samples, kinds: Sequence[str], events: tuple[FloatArray, np.ndarray]
) -> list[Regressor]:
    """A dynamic-pressure coefficient for each barometer (prior DYNAMIC_PRIOR): ``coef`` its
    dynamic head ``V^2 / 2g`` [m] at its samples (:func:`altfuse.datum.scale.dynamic_head`, ``V``
    the ``speed``: an airspeed, or the ground speed). ``events``: their times and series."""
    times, who = events
    out = []
    for i, kind in enumerate(kinds):
        mine = who == i
        head = dynamic_head(speed, times[mine]) if kind == "baro" else None
        if head is None:
            continue
        coef = np.zeros(who.size)
        coef[mine] = head
        out.append(Regressor("dynamic", i, coef, DYNAMIC_PRIOR))
    return out


def scale_regressors(
    who: np.ndarray, h: FloatArray, unknown: Sequence[tuple[float, float] | None]
) -> list[Regressor]:
    """A scale error for each barometer whose scale the datum estimated to within SCALE_PRIOR
    and did not apply (``unknown``, per sensor: the estimate and its error, or None):
    ``z = h + c + s h``, ``coef`` the height ``h`` at its samples (an estimate made without
    the scale: the measurement is linear in ``s`` given it), prior ``SCALE_PRIOR``."""
    return [
        Regressor("scale", i, np.where(who == i, h, 0.0), SCALE_PRIOR)
        for i in scales_to_learn(unknown)
    ]


def scales_to_relearn(
    known: Sequence[tuple[float, float] | None],
) -> dict[int, tuple[float, float]]:
    """Where the datum applied a barometer's scale with a standard error above LEARN_SCALE_STD,
    every barometer whose scale it applied (``known``, per sensor: that scale and its error, or
    None): that scale and error by sensor; else none.

    A vehicle's barometers share the air whose temperature sets their scale, and their datum's
    fits the same GPS: learning one again and holding the other at the datum's scale leaves
    the held one's error (beside the learnt one's) to the GPS's wander. The quadplane's truth
    log with its sensors at 2 Hz (``rate-2``), its barometers 1.052 +- 0.011 and 1.048 +- 0.008
    (both 5.1 % high when learnt): the first learnt, the second followed 0.26 % low over 65 m,
    0.125 m RMSE against its GPS's 0.038; both learnt, 0.032 (with one stepped 1 m, 0.162 ->
    0.042; at 1 Hz 0.040 -> 0.072 beside its GPS's 0.217)."""
    if not any(k is not None and k[1] > LEARN_SCALE_STD for k in known):
        return {}
    return {i: k for i, k in enumerate(known) if k is not None}


def unpinned_scales(
    kinds: Sequence[str],
    known: Sequence[tuple[float, float] | None],
    unknown: Sequence[tuple[float, float] | None],
    layout: Layout,
) -> FloatArray:
    """Per sensor, the standard error of a barometer's scale that nothing pins and the smoother
    does not learn (0 elsewhere). Without a GPS: the datum's error of its estimate (``known``:
    applied, ``unknown``: not), at most SCALE_PRIOR, or SCALE_PRIOR where it has none. With a
    GPS: SCALE_PRIOR where the datum's fit against it could not tell the scale to within that
    (and so applied none and offered none to learn).

    Barometers alone share the error of their scale, which the smoother cannot see: its band
    held the height of barometers 5-8 % high to centimetres (the simulators' planes with their
    GPS left out: 2.6 and 1.7 m RMSE, +-2 sigma coverage 0.03 and 0.32). A GPS pins it only as
    well as the datum's fit says: beside a real receiver's GPS (0.3 m noisy, wandering), the
    simulators' 10 m hexacopter's barometer 5 % high (0.989 +- 0.074 against the GPS) was
    followed 0.43 m off with a band of 2-5 cm (coverage 0.05; 1.00 since)."""
    out = np.zeros(len(kinds))
    if "gps" in kinds:
        for i, kind in enumerate(kinds):
            told = unknown[i]
            if kind == "baro" and told is not None and told[1] > SCALE_PRIOR:
                out[i] = SCALE_PRIOR
        return out
    learnt = {r.sensor for r in layout.regressors if r.name == "scale"}
    for i, kind in enumerate(kinds):
        if kind == "baro" and i not in learnt:
            told = known[i] or unknown[i]
            out[i] = SCALE_PRIOR if told is None else min(told[1], SCALE_PRIOR)
    return out


def scales_to_learn(unknown: Sequence[tuple[float, float] | None]) -> list[int]:
    """The barometers whose scale the datum estimated to within SCALE_PRIOR and did not apply
    (``unknown``, per sensor: the estimate and its error, or None)."""
    return [i for i, known in enumerate(unknown) if known is not None and known[1] <= SCALE_PRIOR]


def scales_agree(
    layout: Layout, last: FloatArray, unknown: Sequence[tuple[float, float] | None]
) -> bool:
    """Whether each scale error in ``layout`` (its estimate in the state ``last``) lies within
    SCALE_AGREE_SIGMAS of the datum's standard error of the datum's estimate."""
    for j, reg in enumerate(layout.regressors):
        known = unknown[reg.sensor]
        if reg.name == "scale" and known is not None:
            scale, std = known
            if abs(last[layout.index(j)] - (scale - 1.0)) > SCALE_AGREE_SIGMAS * std:
                return False
    return True


@dataclass(frozen=True)
class Layout:
    """The sensors' states in ``x`` and what their measurement rows need.

    ``x = [h, v, b, c_1 .. c_m, regressors .., drift rates ..]``.
    """

    sign: FloatArray  # +1: the sensor measures h + c_i; -1: h - c_i (a rangefinder)
    regressors: tuple[Regressor, ...]
    drifting: tuple[int, ...] = ()  # the sensors whose offset has a drift rate
    offset_prior: FloatArray | None = None  # each offset's prior sigma [m]; None: OFFSET_PRIOR
    bounded: tuple[int, ...] = ()  # the sensors whose offset is bounded (a GPS's)
    correlation_s: float = GPS_CORRELATION_S  # ... by a Gauss-Markov process of this time [s]
    shared: tuple[int, ...] = ()  # the sensors whose offsets wander together (BARO_SHARED)
    # the spans [s] in which the sensors that share their air are read in the rotors' wash
    # (one state w, the last); empty: no such state
    wash_spans: tuple[tuple[float, float], ...] = ()
    wash_prior: float = STILL_SIGMA  # w's prior sigma [m] (a log begun in the wash: wider)

    @property
    def n(self) -> int:
        return 3 + self.sign.size + len(self.regressors) + len(self.drifting) + bool(self.washed)

    @property
    def washed(self) -> tuple[int, ...]:
        """The sensors read in the rotors' wash: those that share their air, where it has a
        span."""
        return self.shared if self.wash_spans else ()

    @property
    def wash(self) -> int:
        """The state of the barometers' error in the rotors' wash, ``w``; -1: none."""
        return self.n - 1 if self.washed else -1

    def index(self, j: int) -> int:
        """The state of regressor ``j``."""
        return 3 + self.sign.size + j

    def has(self, name: str) -> bool:
        return any(r.name == name for r in self.regressors)

    @property
    def drift_pairs(self) -> np.ndarray:
        """(offset state, its drift-rate state) per drifting sensor, shape (k, 2)."""
        first = 3 + self.sign.size + len(self.regressors)
        pairs = [(3 + i, first + d) for d, i in enumerate(self.drifting)]
        return np.array(pairs, dtype=int).reshape(-1, 2)

    def structure(self, use_bias: bool) -> Structure:
        """F's structure (:data:`Structure`), as the kernels take it."""
        bounded = np.array([3 + i for i in self.bounded], dtype=np.int64)
        shared = (
            np.array([3 + i for i in self.shared], dtype=np.int64),
            np.array([d for d, i in enumerate(self.drifting) if i in self.shared], dtype=np.int64),
        )
        drifts = self.drift_pairs.astype(np.int64)
        spans = np.array([(lo, hi, wash_density((lo, hi))) for lo, hi in self.wash_spans])
        wash = (self.wash, spans.reshape(-1, 3))
        return use_bias, drifts, bounded, self.correlation_s, shared, wash

    def adding(self, regressors: Sequence[Regressor]) -> Layout:
        """The same with these regressors too."""
        return replace(self, regressors=self.regressors + tuple(regressors))

    def without(self, name: str) -> Layout:
        """The same without the regressors called ``name``."""
        kept = tuple(r for r in self.regressors if r.name != name)
        return replace(self, regressors=kept)

    def with_drift(self, kinds: Sequence[str]) -> Layout:
        """The same with a drift-rate state for each barometer."""
        return replace(self, drifting=tuple(i for i, k in enumerate(kinds) if k == "baro"))


def couplings(use_bias: bool, drifts: np.ndarray) -> np.ndarray:
    """The entries (row, column) of ``F`` off its diagonal that :func:`transition` sets,
    shape (k, 2): the kernels take ``F`` as the identity plus these."""
    pairs = [(0, 1)] + ([(0, 2), (1, 2)] if use_bias else [])
    pairs += [(int(c), int(rate)) for c, rate in drifts]
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


#: F's structure, as the kernels take it: whether the accelerometer's bias is a state, the
#: drifting offsets' (offset, rate) state pairs, the bounded offsets' states and their
#: correlation time [s], the offsets that wander together (BARO_SHARED): their states, and
#: their rows among the drifting pairs; and the state of the rotors' wash (-1: none) and the
#: spans it walks in, each (start [s], end [s], density [m^2/s]).
Structure = tuple[
    bool, np.ndarray, np.ndarray, float, tuple[np.ndarray, np.ndarray], tuple[int, np.ndarray]
]


@compiled_step
def transition(f: FloatArray, dt: float, structure: Structure) -> None:
    """F over ``dt``, into ``f`` (an identity but for the entries :func:`couplings` lists and
    the diagonal's at the bounded offsets): h += v dt - b dt^2/2, v += -b dt, c_i += r_i dt
    for a sensor with a drift rate ``r_i``, a bounded offset decays, c *= exp(-dt / tau); the
    rest random walks."""
    use_bias, drifts, bounded, tau, _, _ = structure
    f[0, 1] = dt
    if use_bias:
        f[0, 2], f[1, 2] = -0.5 * dt * dt, -dt
    for j in range(drifts.shape[0]):
        f[drifts[j, 0], drifts[j, 1]] = dt
    for c in bounded:
        f[c, c] = math.exp(-dt / tau)


@dataclass(frozen=True)
class Events:
    """What the forward pass steps through, one entry per event (a sample or a clock tick).

    ``who``: the sensor of a sample, -1 for a tick; ``z``: the sample's value; ``a``: the mean
    vertical acceleration over the interval ending at the event, ``q_accel`` the white
    acceleration noise density there [m^2/s^3] (the flight's, and what spikes and the sensors'
    refusals add); ``q_state`` (events, m): the sensor states' random-walk densities over that
    interval (one row: the same at every event); ``still``: the events at which the vehicle is
    known to stand at the take-off point; ``h0``: the first height guess;
    ``landed``: the events at which it stands still elsewhere on the ground, none of
    ``still`` (v = 0 alone; None: none); ``reset``: the first event of each segment of a
    spliced log, the row of :func:`reset_states` that returns to the prior there (0 elsewhere;
    None: none); ``early``: the samples at which the height is let loose where they fail the
    gate (the first rejection of an episode a pass before let loose later; None: none);
    ``model``: the events the model is decided on, the samples and the ticks of the clock it
    is decided on, where the output's clock is another (None: every event); each other event
    is a tick of the output's that splits an interval and reads the state there; ``cleared``:
    the events at which the barometers have left the rotors' wash, ``w = 0`` (None: none).
    """

    t: FloatArray
    who: np.ndarray
    z: FloatArray
    a: FloatArray
    q_state: FloatArray
    still: np.ndarray
    q_accel: FloatArray
    use_bias: bool
    gate: float
    h0: float
    landed: np.ndarray | None = None
    reset: np.ndarray | None = None
    early: np.ndarray | None = None
    model: np.ndarray | None = None
    cleared: np.ndarray | None = None


@compiled_step
def wash_noise(t: float, structure: Structure) -> float:
    """The density [m^2/s] of the rotors' wash's random walk over the interval that ends at
    ``t`` [s]: its span's where ``t`` lies in one (after its start, up to its end), else 0."""
    for j in range(structure[5][1].shape[0]):
        lo, hi, density = structure[5][1][j]
        if lo < t <= hi:
            return float(density)
    return 0.0


@compiled_step
def process_noise(
    q: FloatArray,
    dt: float,
    q_accel: float,
    q_state: FloatArray,
    structure: Structure,
    q_wash: float,
) -> None:
    """Q over an interval ``dt``, into ``q``: white acceleration of density ``q_accel`` on
    (h, v), the bias's and the sensor states' random walks (``q_state``, one density per
    sensor; a bounded offset's Gauss-Markov increment of the same density at short spans), and
    each drifting offset's integrated random walk; the barometers' increments correlated by
    BARO_SHARED (of the smaller density: ``min(q_i, q_j)`` is a covariance, and ``Q`` stays
    positive semi-definite where one's offset is let loose at a step); the rotors' wash's random
    walk of density ``q_wash`` (:func:`wash_noise`)."""
    use_bias, drifts, bounded, tau, (shared, shared_drifts), (wash, _) = structure
    q[:] = 0.0
    # white acceleration: [[dt^3/3, dt^2/2], [dt^2/2, dt]] q_a on (h, v)
    q[0, 0], q[0, 1], q[1, 1] = q_accel * dt**3 / 3, q_accel * dt**2 / 2, q_accel * dt
    q[1, 0] = q[0, 1]
    q[2, 2] = Q_BIAS * dt if use_bias else 0.0
    for i in range(q_state.size):
        q[3 + i, 3 + i] = q_state[i] * dt
    if wash >= 0:  # the wash's random walk, of its own density (0 out of its spans)
        q[wash, wash] = q_wash * dt
    for c in bounded:
        # q tau / 2 (1 - exp(-2 dt / tau)): the stationary variance q tau / 2, less what the
        # decay carries over of it
        q[c, c] = -q_state[c - 3] * tau / 2 * math.expm1(-2 * dt / tau)
    for j in range(drifts.shape[0]):  # a drifting offset: an integrated random walk
        c, rate = drifts[j, 0], drifts[j, 1]
        q[c, c] += Q_DRIFT * dt**3 / 3
        q[c, rate] = Q_DRIFT * dt**2 / 2
        q[rate, c] = q[c, rate]
        q[rate, rate] = Q_DRIFT * dt
    for one in range(shared.size):
        for other in range(one):
            c, d = shared[one], shared[other]
            q[c, d] = BARO_SHARED * min(q_state[c - 3], q_state[d - 3]) * dt
            q[d, c] = q[c, d]
    for one in range(shared_drifts.size):
        for other in range(one):
            c, rate = drifts[shared_drifts[one], 0], drifts[shared_drifts[one], 1]
            d, rate_d = drifts[shared_drifts[other], 0], drifts[shared_drifts[other], 1]
            q[c, d] += BARO_SHARED * Q_DRIFT * dt**3 / 3
            q[c, rate_d] = q[rate, d] = BARO_SHARED * Q_DRIFT * dt**2 / 2
            q[rate, rate_d] = BARO_SHARED * Q_DRIFT * dt
            for i, j in ((c, d), (c, rate_d), (rate, d), (rate, rate_d)):
                q[j, i] = q[i, j]


def sharing_air(kinds: Sequence[str]) -> tuple[int, ...]:
    """The sensors whose offsets wander together by BARO_SHARED: the barometers."""
    return tuple(i for i, k in enumerate(kinds) if k == "baro")


#: H of every event, compactly (:func:`measurement_rows`): per series its row without the
#: regressors' terms, per regressor its state and its sensor, and per regressor its coefficient
#: at every event.
Rows = tuple[FloatArray, np.ndarray, FloatArray]


def measurement_rows(layout: Layout, who: np.ndarray, coef: FloatArray | None = None) -> Rows:
    """H of every event (:data:`Rows`; :func:`measurement_row` makes an event's row): for a
    sample of sensor ``i``, h plus the sensor's offset (GPS, baro) or minus its ground height
    (rangefinder), plus its regressors' terms and a barometer's wash (``layout.washed``); v for
    a vertical-velocity sample; 0 for a tick. Kept as the rows of each series and the
    regressors' coefficients (``coef``, where :func:`regressor_coefficients` made them
    already): the rows of every event cost 44 MB on a 7.4-hour log (seven states)."""
    m = layout.sign.size
    base = np.zeros((m + 2, layout.n))  # by series: VELOCITY (-2), TICK (-1), then the sensors
    base[VELOCITY + 2, 1] = 1.0
    base[2:, 0] = 1.0
    base[2 + np.arange(m), 3 + np.arange(m)] = layout.sign
    base[2 + np.array(layout.washed, dtype=np.int64), layout.wash] = 1.0
    regs = np.array(
        [(layout.index(j), r.sensor) for j, r in enumerate(layout.regressors)], dtype=np.int64
    ).reshape(-1, 2)
    if coef is None:
        coef = regressor_coefficients(layout.regressors, who.size)
    elif coef.shape != (len(layout.regressors), who.size):
        # the kernels index it without a check: another layout's would be read silently
        raise ValueError(f"coefficients {coef.shape} for {len(layout.regressors)} regressors")
    return base, regs, coef


def regressor_coefficients(regressors: Sequence[Regressor], events: int) -> FloatArray:
    """The regressors' coefficients at every event, one row each (:func:`measurement_rows`)."""
    coef = np.zeros((len(regressors), events))
    for j, r in enumerate(regressors):
        coef[j] = r.coef
    return coef


@compiled_step
def measurement_row(rows: Rows, series: int, k: int, out: FloatArray) -> None:
    """Event ``k``'s row of H (a sample of ``series``) into ``out`` (:func:`measurement_rows`)."""
    base, regs, coef = rows
    assign(out, base[series + 2])
    for j in range(regs.shape[0]):
        if regs[j, 1] == series:
            out[regs[j, 0]] = coef[j, k]


@compiled_step
def hold(
    x: FloatArray,
    p: FloatArray,
    record: FloatArray,
    held: tuple[bool, bool, bool],
    unit: FloatArray,
) -> None:
    """The states known to be 0 at an event, as measurements of variance ``STILL_SIGMA^2``,
    those ``held`` says: h at the datum (before take-off: the datum's definition), v standing on
    the ground, and the rotors' wash ``w`` once the vehicle has left it. Each one's ``P H'``,
    ``S`` and innovation go into a row of ``record`` (3, n + 2), for the smoother's backward
    pass; ``S`` 0 where there was none. ``unit``: the rows of H of h, v and w (3, n)."""
    n = x.size
    for j in range(3):
        record[j, n] = 0.0
        if held[j]:
            ph = record[j, :n]
            y, s = innovation(x, p, 0.0, unit[j], STILL_SIGMA**2, ph)
            record[j, n], record[j, n + 1] = s, y
            update(x, p, y, s, ph)


def reset_states(layout: Layout) -> np.ndarray:
    """Per row of RESET_*, the states that return to the prior (3, n): at a splice nothing says
    where the vehicle went meanwhile (h, v); in a segment with its own datum each sensor's
    offset is 0 at its ground, and a drift rate is not carried across. The accelerometer's bias
    and the regressors (a barometer's temperature coefficient, its scale, the velocity's lag)
    are the sensors' own, and are kept."""
    rows = np.zeros((3, layout.n), dtype=np.bool_)
    rows[RESET_MOTION, :2] = True
    rows[RESET_DATUM, :2] = True
    rows[RESET_DATUM, 3 : 3 + layout.sign.size] = True
    if layout.drifting:
        rows[RESET_DATUM, layout.drift_pairs[:, 1]] = True
    return rows


def prior(ev: Events, layout: Layout) -> tuple[FloatArray, FloatArray]:
    """The state and covariance before the first event: ``h`` at the first height guess, every
    other state at 0; a loose height and velocity, the offsets' priors (``layout``'s; a bounded
    offset's no wider than its stationary spread), the regressors', the drift rates' and the
    wash's (``layout.wash_prior``)."""
    m = layout.sign.size
    x = np.zeros(layout.n)
    x[0] = ev.h0
    offsets = np.full(m, OFFSET_PRIOR) if layout.offset_prior is None else layout.offset_prior
    offsets = offsets**2
    for i in layout.bounded:
        # wider, a decay from an unknown start is a trend that sensor noise fits: the height's
        # level then followed a noisy barometer's trend (5-10 cm on a 2-minute flight with no
        # ground to hold it)
        offsets[i] = min(offsets[i], float(ev.q_state[0, i]) * layout.correlation_s / 2)
    # without the accelerometer the bias is inert: a tiny fixed variance keeps P invertible
    p = np.diag(
        [10.0**2, 3.0**2, 0.1**2 if ev.use_bias else 1e-9]
        + list(offsets)
        + [r.prior**2 for r in layout.regressors]
        + [DRIFT_PRIOR**2] * len(layout.drifting)
        + [layout.wash_prior**2] * bool(layout.washed)
    )
    return x, p
