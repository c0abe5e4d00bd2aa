"""The smoother's noises from the log: each sensor's measurement noise (local, scaled by EM), the
accelerometer's, the offsets' random walks bounded by the sensors' agreement, and a
rangefinder's terrain per metre flown."""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from altfuse.fuse.base import FusionInput, Jump
from altfuse.fuse.smoother.events import VELOCITY, interval_mean, on_every_event
from altfuse.fuse.smoother.model import BARO_SHARED, Events, sharing_air
from altfuse.metrics import (
    hold_nearest,
    mad_sigma,
    running_median,
    running_sum,
    running_white_noise,
    samples_in,
    white_noise_sigma,
)
from altfuse.model import FloatArray, Samples
from altfuse.steps import STEP_SETTLE_S

#: White acceleration noise densities [m^2/s^3]: the default, its floor with the accelerometer,
#: and without it.
Q_ACCEL = 0.05
Q_ACCEL_MIN = 1e-3
Q_ACCEL_NO_IMU = 2.0
#: Offset random walks [m^2/s] for GPS and barometer, and for a rangefinder's ground height when
#: the horizontal speed is unknown.
Q_OFFSET = {"gps": 0.01, "baro": 1e-4, "rangefinder": 0.3}
#: ... and of a GPS as stable as a barometer (an RTK fix; a simulator's GPS, which lags but does
#: not wander): the alternative the log's evidence may choose (:func:`.evidence.gps_evidence`).
Q_OFFSET_STABLE_GPS = {**Q_OFFSET, "gps": Q_OFFSET["baro"]}
#: A step between sensors (:mod:`altfuse.steps`) lets the offset of each sensor that may have
#: jumped jump by this many times the step, one standard deviation, over the events this close
#: to it [s].
JUMP_SIGMAS = 3.0
JUMP_HALF_WIDTH_S = 0.5
#: Ground height under a moving vehicle: random walk per metre flown [m^2/m] when the log cannot
#: tell, and its floor in time [m^2/s] (grass, waves: about 3 cm over 100 s).
Q_TERRAIN_PER_M = 0.05
Q_GROUND_STILL = 1e-5
Q_TERRAIN_MAX = 1.0
MAX_SPEED_M_S = 100.0
#: The spans [s] over which two sensors' agreement is measured, and the least share of the
#: default random walks it may leave (a floor: two simulated sensors can agree exactly; at
#: 1e-3 three long truth logs' bands come into the 0.90-0.99 window and two short ones' fall
#: below it, 0.841 and 0.898, in their climbs: lagging SIM.Alt 8-9 ms there, as the long
#: ones do 2-8 ms, which the offsets' wider band over a long flight covers).
AGREEMENT_LAGS_S = (2.0, 5.0, 10.0, 20.0, 40.0)
#: ... and the blocks [s] the difference is also averaged over first, AGREEMENT_BLOCK_LAGS
#: blocks apart: a noisy sensor's white noise, 2 sigma^2 in every increment of single samples,
#: hid how little it wanders from another (a barometer 0.11 m noisy: no bound under 6e-4 m^2/s;
#: its blocks' means, 2e-5).
AGREEMENT_BLOCKS_S = (2.0, 5.0, 10.0)
AGREEMENT_BLOCK_LAGS = (1, 2, 4)
#: Fewest increments a bound is measured from.
AGREEMENT_MIN_INCREMENTS = 20
Q_AGREEMENT_MIN_SHARE = 1e-2
#: An accelerometer sample departing from its neighbours' median (over SPIKE_WINDOW_S, at
#: least SPIKE_MIN_SAMPLES) by more than SPIKE_SIGMAS of the flight's such departures is a spike
#: (an impact, a clipped or glitched sample); the excess is taken as unknown.
SPIKE_WINDOW_S = 0.1
SPIKE_MIN_SAMPLES = 5
SPIKE_SIGMAS = 5.0
#: The accelerometer against the sensors: each sensor's velocity is its heights' slope over
#: CHECK_SLOPE_S; over each CHECK_SPAN_S both velocities' changes must agree within
#: CHECK_SIGMAS of the slopes' errors plus CHECK_FLOOR_M_S (a sensor's lag, 0.1-0.25 s, turns a
#: change of acceleration into a few tenths of a metre per second).
CHECK_SLOPE_S = 2.0
CHECK_SPAN_S = 1.0
CHECK_SIGMAS = 5.0
CHECK_FLOOR_M_S = 0.5
#: The acceleration noise the smoothed flight asks for, per ACCEL_EM_WINDOW_S [s]: the M-step's
#: mean squared velocity change beyond the accelerometer's, times ACCEL_EM_GAIN for the
#: posterior variance that step omits (measured on the 3.3 plane, whose accelerometer errs by
#: 6-30 m/s^2 at large bank angles: 1, 2 and 4 give 0.121, 0.116 and 0.111 m RMSE against
#: 0.143; 4 costs two simulated flights whose rangefinder drops out 12-20 %, 2 at most 5 %).
ACCEL_EM_WINDOW_S = 1.0
ACCEL_EM_GAIN = 2.0
#: Window [s] of the local measurement-noise estimate.
NOISE_WINDOW_S = 5.0
_MIN_SIGMA_M = 0.01
#: A GPS's vertical velocity noise floor [m/s]: its errors are correlated over a second or so,
#: which the spread between samples does not show. (ArduPilot's EK3_VELD_M_NSE, 0.5, the same
#: on the simulated flights within 10 %, flipped a truth log's temperature test: the quadplane
#: 0.024 -> 0.040 m.)
MIN_SIGMA_VELOCITY_M_S = 0.1


def measurement_sigma(z: FloatArray) -> float:
    """Noise of one sensor [m] from the median absolute second difference of its samples."""
    if z.size < 5:
        return 1.0
    return max(white_noise_sigma(z), _MIN_SIGMA_M)


def accel_psd(t: FloatArray, a: FloatArray) -> float:
    """White-noise density of the vertical acceleration [m^2/s^3]: the spread of its first
    differences (``sigma = 1.4826 MAD(d a) / sqrt(2)``) times the sampling interval, floored at
    ``Q_ACCEL_MIN`` (vibration and attitude errors the spread does not show)."""
    if a.size < 10:
        return Q_ACCEL
    sigma = mad_sigma(np.diff(a)) / math.sqrt(2.0)
    return max(sigma**2 * float(np.median(np.diff(t))), Q_ACCEL_MIN)


def accel_spikes(t: FloatArray, a: FloatArray) -> FloatArray:
    """The white-acceleration density [m^2/s^3] each accelerometer sample adds to the process
    noise: ``max(|e| - k s, 0)^2 dt`` for its departure ``e`` from the median of its neighbours
    (``SPIKE_WINDOW_S``), ``s`` the flight's spread of those departures (from the MAD), ``k``
    ``SPIKE_SIGMAS`` and ``dt`` its sampling interval; 0 for the samples that are no spike.

    Logged IMU samples are point samples of a sensor read at 1 kHz or more: an impact, a bounce
    or a clipped sample integrates to metres per second of velocity in one sample (20 m/s seen),
    which no sensor confirms. Its excess over the normal spread is counted as unknown velocity
    change in that interval, so the sensors' samples that follow are fused, not gated out
    (ArduPilot's EKF3 raises its acceleration noise when the IMU clips).
    """
    if a.size < 2 * SPIKE_MIN_SAMPLES:
        return np.zeros(a.size)
    step = float(np.median(np.diff(t)))
    width = max(SPIKE_MIN_SAMPLES, samples_in(SPIKE_WINDOW_S, step, a.size) if step > 0 else 0) | 1
    e = a - running_median(a, width)
    excess = np.maximum(np.abs(e) - SPIKE_SIGMAS * mad_sigma(e), 0.0)
    dt = np.diff(t, append=t[-1] + step)
    return np.asarray(excess**2 * np.maximum(dt, 0.0))


def slope(t: FloatArray, z: FloatArray, width: int) -> tuple[FloatArray, FloatArray]:
    """The least-squares slope of ``z`` over a centred window of ``width`` ticks at each tick,
    and the window's ``sum (t - mean t)^2`` (the slope's error is ``sigma / sqrt`` of it); NaN
    where fewer than 4 samples are valid."""
    ok = np.isfinite(z)
    tt, zz = np.where(ok, t - t[0], 0.0), np.where(ok, z, 0.0)

    n, st, sz, stt, stz = (
        running_sum(v, width) for v in (ok.astype(float), tt, zz, tt * tt, tt * zz)
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        sxx = stt - st * st / n
        slope = (stz - st * sz / n) / sxx
    bad = (n < 4) | ~(sxx > 0)
    return np.where(bad, np.nan, slope), np.where(bad, np.nan, sxx)


def accel_refused(inputs: FusionInput, a: FloatArray) -> FloatArray:
    """The acceleration noise density [m^2/s^3] at each tick where every GPS and barometer
    refuses the accelerometer ``a`` (on the clock); 0 elsewhere.

    Over each span of ``CHECK_SPAN_S`` the change of the slope (over ``CHECK_SLOPE_S``) of each
    sensor's heights less the accelerometer's double integral, ``r``, is 0 within the slopes'
    errors; where it is not for any sensor that has samples there, on one side for all, the
    accelerometer, not the sensors, is taken as wrong there: the span gets the density
    ``r^2 / T``, ``r`` the sensors' least. A plane's log whose vertical acceleration errs by
    6-30 m/s^2 at large bank angles (gravity rotated into the vertical by an attitude error)
    integrated to 90 m away between the gate's lockouts.

    One sensor kind alone refuses it too (a barometer while the GPS is out): with no second
    opinion, trusting a wrong sensor costs that sensor's error, trusting a wrong accelerometer
    grows without bound. The same plane with its GPS frozen for 70 s (dropped as stuck) was
    100 m off on its barometer alone (RMSE 6.9 m, 0.97 m since); a simulated GPS alone, noisier
    than the accelerometer, costs 0-0.07 m (13 of 159 flights moved, the smoother still the
    lowest on each).

    Without an accelerometer ``a`` is 0: the altitude-only model's constant velocity is what
    the sensors refuse (a plane pulled into a dive at 36 m/s^2 without IMU records: 16 m for a
    second, 0.6 m since).
    """
    t, z, dt = inputs.t, inputs.z, inputs.dt_s
    steady = [i for i, k in enumerate(inputs.kinds) if k != "rangefinder"]
    extra = np.zeros(t.size)
    span = max(1, round(CHECK_SPAN_S / dt))
    if not steady or t.size <= span:
        return extra
    width = max(5, round(CHECK_SLOPE_S / dt))
    # the height the accelerometer alone gives: its slope goes through the same window as the
    # sensors' (a change of acceleration inside it must not count)
    step = np.diff(t, prepend=t[0])
    h_accel = np.cumsum(np.cumsum(a * step) * step)
    changes = []
    for i in steady:
        valid = np.isfinite(z[:, i])
        if valid.sum() < 10:
            continue
        sigma = white_noise_sigma(z[valid, i])
        d, sxx = slope(t, z[:, i] - h_accel, width)
        r = d[span:] - d[:-span]
        bound = CHECK_SIGMAS * sigma * np.sqrt(1 / sxx[span:] + 1 / sxx[:-span]) + CHECK_FLOOR_M_S
        # NaN: the sensor has no vote there (too few samples around either end)
        changes.append(np.where(np.abs(r) > bound, r, np.where(np.isfinite(r), 0.0, np.nan)))
    if not changes:
        return extra
    r = np.array(changes)
    voting = np.isfinite(r)
    side = np.where(voting, np.sign(r), np.nan)
    agreed = voting.any(axis=0) & (
        np.nanmin(side, axis=0, initial=np.inf) == np.nanmax(side, axis=0, initial=-np.inf)
    )
    agreed &= np.nanmin(np.where(voting, np.abs(side), np.inf), axis=0) > 0
    least = np.where(agreed, np.min(np.where(voting, np.abs(r), np.inf), axis=0), 0.0)
    density = least**2 / (span * dt)
    for j in range(span + 1):  # every tick of a refused span
        extra[j : j + density.size] = np.maximum(extra[j : j + density.size], density)
    return extra


def local_sigma(t: FloatArray, z: FloatArray, window_s: float = NOISE_WINDOW_S) -> FloatArray:
    """Noise of one sensor at each of its samples [m]: :func:`measurement_sigma` over a running
    window of ``window_s`` (sensors get noisier and quieter within a flight)."""
    if z.size < 5:
        return np.full(z.size, measurement_sigma(z))
    step = float(np.median(np.diff(t)))
    # stamps microseconds apart (damaged) must not ask for a window longer than the samples
    width = min(z.size, max(5, samples_in(window_s, step, z.size)))
    local = running_white_noise(z, width, min_periods=3)
    sigma = np.where(np.isfinite(local), local, measurement_sigma(z))
    return np.asarray(np.maximum(sigma, _MIN_SIGMA_M))


def terrain_noise(
    d: FloatArray,
    flown: FloatArray,
    lag: int,
    noise_m2: float,
    steps: Sequence[tuple[int, int]] = (),
) -> float:
    """Ground-height random walk per metre flown [m^2/m], by method of moments; NaN if unknown.

    ``d`` is another sensor minus a rangefinder on the clock (the ground height plus both
    sensors' errors), ``flown`` the distance flown [m] on the clock. Over ``lag`` ticks the
    squared change of ``d`` is ``q dx + const`` (``const``: the noise, and drift too slow to
    matter over the lag): regressed on the distance ``dx`` flown meanwhile. Where the
    rangefinder never reads while the vehicle is (nearly) still (below its minimum on the
    ground, then flown fast) ``const`` is taken as ``noise_m2``, the two sensors' white noise
    over the change (twice the sum of their variances), and only ``q`` is fitted.

    ``steps``: the ticks (first, last) within which either sensor may have jumped (a step
    between sensors, :attr:`FusionInput.steps`); a change across one is no ground's. A GPS
    stepped 2 m half-way through a real log (beastayyg_log_0039) made its ground 150 times as
    rough (6.4e-4 -> 0.096 m^2/m): the rangefinder let loose, its evidence for the
    barometer's temperature and drift turned, and the whole flight's height moved 0.39 m RMS.
    """
    if d.size <= lag:
        return math.nan
    dd, dx = d[lag:] - d[:-lag], flown[lag:] - flown[:-lag]
    for first, last in steps:  # the change from k to k + lag spans ticks first..last
        dd[max(first - lag, 0) : max(last, 0)] = np.nan
    ok = np.isfinite(dd) & np.isfinite(dx)
    moving = ok & (dx > 1.0)
    if moving.sum() < 10:
        return math.nan
    if (ok & (dx <= 1.0)).sum() < 10:
        slope = float(
            np.dot(dx[moving], dd[moving] ** 2 - noise_m2) / np.dot(dx[moving], dx[moving])
        )
        return max(slope, 0.0)
    design = np.column_stack([dx[ok], np.ones(ok.sum())])
    slope = float(np.linalg.lstsq(design, dd[ok] ** 2, rcond=None)[0][0])
    return max(slope, 0.0)


def wander_bound(d: FloatArray, dt: float) -> float:
    """An upper bound [m^2/s] on the random-walk density of ``d`` on a clock of step ``dt``:
    ``Var(d(t + L) - d(t)) = q L + 2 sigma^2 >= q L``, so ``q <= Var_L / L`` at every span
    ``L`` of AGREEMENT_LAGS_S; and of the means of ``d`` over blocks of ``W``
    (AGREEMENT_BLOCKS_S) ``k W`` apart (AGREEMENT_BLOCK_LAGS), whose increments' variance is
    ``q W (k - 1/3) + 2 sigma^2 / N``, the noise averaged over the block's ``N`` samples (each
    variance robust, from the MAD); the least of them. Noise only loosens it: beyond its
    sampling error it never claims that two sensors agree better than they do. NaN when the
    difference is too short."""
    lags = [max(1, round(lag / dt)) for lag in AGREEMENT_LAGS_S]
    bounds = [_bound(d, k, k * dt) for k in lags]
    for width_s in AGREEMENT_BLOCKS_S:
        width = max(1, round(width_s / dt))
        blocks = d[: d.size // width * width].reshape(-1, width)
        finite = np.isfinite(blocks).sum(axis=1)
        # a block's mean where at least half of it is there
        means = np.where(
            finite >= width / 2, np.nansum(blocks, axis=1) / np.maximum(finite, 1), np.nan
        )
        bounds += [_bound(means, k, width * dt * (k - 1 / 3)) for k in AGREEMENT_BLOCK_LAGS]
    found = [b for b in bounds if math.isfinite(b)]
    return min(found) if found else math.nan


def _bound(d: FloatArray, k: int, span_s: float) -> float:
    """``Var(d(i + k) - d(i)) / span_s`` (robust: from the MAD), NaN with fewer than
    AGREEMENT_MIN_INCREMENTS finite increments."""
    inc = d[k:] - d[:-k] if d.size > k else np.zeros(0)
    inc = inc[np.isfinite(inc)]
    return mad_sigma(inc) ** 2 / span_s if inc.size >= AGREEMENT_MIN_INCREMENTS else math.nan


def bounded_by_agreement(
    inputs: FusionInput, q_time: FloatArray, given: Sequence[bool]
) -> FloatArray:
    """GPS and barometer offsets' random walks no looser than the sensors' agreement allows.

    Two sensors' offsets wander apart at the sum of their densities (two barometers' less what
    they share: :func:`.model.sharing_air`), which their difference bounds from above
    (:func:`wander_bound`); each one's can be no larger. A pair that agrees better than the
    defaults' sum scales both defaults down in their ratio (the prior's preference of a
    stable barometer over a wandering GPS stays); never up. In the simulators' logs a GPS and a
    scaled barometer agree to a centimetre over minutes, where the defaults allow a metre and
    gave a fused_std five to twenty times the true error.
    """
    out: FloatArray = q_time.copy()
    kinds = inputs.kinds
    steady = [i for i, k in enumerate(kinds) if k != "rangefinder"]
    shared = sharing_air(kinds)
    bound = {
        (i, j): wander_bound(inputs.z[:, i] - inputs.z[:, j], inputs.dt_s)
        for i, j in itertools.combinations(steady, 2)
    }
    for i in (i for i in steady if not given[i]):
        for j in (j for j in steady if j != i):
            observed = bound[min(i, j), max(i, j)]
            prior = q_time[i] + q_time[j]
            if i in shared and j in shared:  # less what they share (BARO_SHARED)
                prior -= 2 * BARO_SHARED * min(q_time[i], q_time[j])
            if math.isfinite(observed) and prior > 0:
                share = max(observed / prior, Q_AGREEMENT_MIN_SHARE)
                out[i] = min(out[i], q_time[i] * min(1.0, share))
    return out


def offset_noise(
    inputs: FusionInput, given: Mapping[str, float], defaults: Mapping[str, float] = Q_OFFSET
) -> FloatArray:
    """Each sensor's offset random walk in time [m^2/s]: ``given`` (by sensor name), else its
    kind's in ``defaults``, bounded by the sensors' agreement (:func:`bounded_by_agreement`)."""
    names, kinds = inputs.names, inputs.kinds
    q_time = np.array([given.get(n, defaults[k]) for n, k in zip(names, kinds, strict=True)])
    return bounded_by_agreement(inputs, q_time, [n in given for n in names])


def state_noise(
    inputs: FusionInput, times: FloatArray, given: Mapping[str, float]
) -> tuple[FloatArray, dict[str, float]]:
    """Random-walk densities of the sensor states over each event interval (events, m; one row
    where they are the same at every event), and each rangefinder's terrain roughness [m^2/m] by
    name, for the record.

    ``given`` (by sensor name) overrides. GPS and barometer offsets: :func:`offset_noise`,
    constant. A rangefinder's ground height changes as the vehicle flies over the ground:
    ``q dx`` per distance ``dx`` flown (``q`` by :func:`terrain_noise` against the quietest other
    sensor) plus ``Q_GROUND_STILL`` in time; without a speed, ``Q_OFFSET["rangefinder"]`` in time.
    """
    z, t, kinds, names, speed = inputs.z, inputs.t, inputs.kinds, inputs.names, inputs.speed
    q_time = offset_noise(inputs, given)
    terrain: dict[str, float] = {}
    ranges = [i for i, k in enumerate(kinds) if k == "rangefinder" and names[i] not in given]
    if speed is None or speed.t.size < 2 or not ranges:
        # the same at every event: one row (an event's worth is 12 MB on a 7.4-hour log)
        return q_time[np.newaxis, :].copy(), terrain
    q_events = np.tile(q_time, (times.size, 1))
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.1
    v = Samples(speed.t, np.clip(speed.value, 0.0, MAX_SPEED_M_S))
    flown_speed = interval_mean(v, t)
    flown = np.cumsum(np.nan_to_num(flown_speed) * np.diff(t, prepend=t[0]))
    flown[np.isnan(flown_speed)] = np.nan
    # outside the speed's span (a GPS lost in flight) the last known speed is held
    speed_events = hold_nearest(interval_mean(v, times))
    noise = [measurement_sigma(col[np.isfinite(col)]) for col in z.T]
    others = [j for j, k in enumerate(kinds) if k != "rangefinder"]
    for i in ranges:
        q_m = math.nan
        if others:
            j = min(others, key=lambda j: noise[j])
            lag = max(1, round(1.0 / dt))
            steps = [
                (int(np.searchsorted(t, at - half)), int(np.searchsorted(t, at + half)) + 1)
                for at, jumped, _, half, *_ in (*inputs.steps, *inputs.tentative)
                if i in jumped or j in jumped
            ]
            q_m = terrain_noise(
                z[:, j] - z[:, i], flown, lag, 2 * (noise[j] ** 2 + noise[i] ** 2), steps
            )
        q_m = Q_TERRAIN_PER_M if not math.isfinite(q_m) else min(q_m, Q_TERRAIN_MAX)
        terrain[names[i]] = q_m
        moving = q_m * speed_events + Q_GROUND_STILL
        q_events[:, i] = np.where(np.isfinite(speed_events), moving, q_time[i])
    return q_events, terrain


def with_jumps(
    q_state: FloatArray, steps: Sequence[Jump], times: FloatArray, *, settling: bool = True
) -> FloatArray:
    """The sensor states' random-walk densities ``q_state`` (one row, or one per event at
    ``times``) with, at each of the ``steps`` between sensors, a jump of each sensor that may
    have jumped of JUMP_SIGMAS times the step (one standard deviation), spread over the events
    within the step's window of it (its last entry, a half-width [s]: JUMP_HALF_WIDTH_S, or a
    clock tick where the sensor's own heights tell the instant), and with ``settling`` its
    settling over the next STEP_SETTLE_S (as far as the two sensors' difference moved back, its
    last entry, one standard deviation: :attr:`altfuse.steps.Step.settle_m`). Which sensor
    jumped is tried without it (:func:`.evidence.jump_evidence`): settling on either reading,
    the two explain the samples after a step alike.

    Measured on the truth logs with their barometers flashed 1, 3, -3 and 10 m half-way
    (settling back over 15 s, ``tests/variants.py``), each jump told by its sensors' own
    heights, before the datum's scale fit left the settling out (since, 12, 11, 13 and 11:
    :func:`altfuse.datum.scale.baro_scales`): within the bar on RMSE and maximum on 10, 9, 10 and 4
    of 13, where 8, 7, 7 and 6 without the settling; the worst RMSE over the bar's 9.1 times
    where 101 times (the agricultural copter's 10 m flash: its barometers, moved back by their
    jump, read 9 m low once settled, and were followed where its GPS, one value to the log's
    end, had been dropped as stuck). Settling by the whole step after every jump did as well
    on those, and let a barometer stepped 1 m beside a wandering GPS follow the GPS's wander
    for 20 s."""
    if not steps:
        same: FloatArray = q_state.copy()
        return same
    out: FloatArray = np.array(np.broadcast_to(q_state, (times.size, q_state.shape[1])))
    for time, sensors, size, width, settle in steps:
        near = np.abs(times - time) <= width
        after = (times > time + width) & (times <= time + width + STEP_SETTLE_S)
        for i in sensors:
            out[near, i] += (JUMP_SIGMAS * size) ** 2 / (2.0 * width)
            if settling:
                out[after, i] += settle**2 / STEP_SETTLE_S
    return out


@dataclass(frozen=True)
class Noise:
    """Each event's measurement variance as ``base * scale[series]``, at least ``floor``:
    ``base`` the local noise of its series squared, ``scale`` refined by EM except for the
    sensors in ``fixed``, one entry per sensor, then the vertical velocity's; ``floor`` per
    event."""

    base: FloatArray
    scale: FloatArray
    fixed: np.ndarray
    floor: FloatArray

    def series(self, who: np.ndarray) -> np.ndarray:
        """Each event's entry in ``scale``: its sensor's, the velocity's last (a tick: 0)."""
        return np.where(who == VELOCITY, self.scale.size - 1, np.maximum(who, 0))

    def r(self, who: np.ndarray) -> FloatArray:
        r: FloatArray = np.maximum(self.base * self.scale[self.series(who)], self.floor)
        return r


def measurement_noise(
    inputs: FusionInput,
    given: Mapping[str, float],
    events: tuple[np.ndarray, np.ndarray],
    velocity: Samples | None,
) -> Noise:
    """Each sample's variance: the local noise of its sensor (or ``given``), or of the vertical
    velocity ``velocity`` (at least MIN_SIGMA_VELOCITY_M_S, whatever EM finds); scale 1.
    ``events``: each event's series and its position in it (:func:`.events.merge_events`)."""
    who, position = events
    local = [
        np.full(s.value.size, given[name]) if name in given else local_sigma(*s)
        for name, s in zip(inputs.names, inputs.samples, strict=True)
    ]
    series = list(enumerate(local))
    if velocity is not None:
        series.append((VELOCITY, local_sigma(*velocity)))
    base = np.ones(who.size)
    for i, sigma in series:
        mine = who == i
        base[mine] = sigma[position[mine]] ** 2
    fixed = np.array([name in given for name in inputs.names] + [False])
    floor = np.where(who == VELOCITY, MIN_SIGMA_VELOCITY_M_S**2, 0.0)
    return Noise(base, np.ones(len(inputs.samples) + 1), fixed, floor)


def em_accel(ev: Events, x: FloatArray, floor: FloatArray) -> Events:
    """EM, M-step for the white acceleration noise, per window of ``ACCEL_EM_WINDOW_S``: the
    events with each window's density ``q = ACCEL_EM_GAIN sum(w^2) / sum(dt)``, where the
    smoothed flight needs it (``x``: its states h, v and b at every event), never below
    ``floor`` (the log's own, with its spikes and the sensors' refusals).
    ``w = v(k) - v(k-1) - (a_k - b) dt``: the velocity's change the sensors asked for beyond
    the accelerometer's. An accelerometer wrong for seconds (an
    attitude error turning gravity into the vertical) shows here where its own sample spread
    says nothing: on the 3.3 plane 0.143 -> 0.116 m RMSE, maximum 0.85 -> 0.67 m. Without an
    accelerometer (``a = 0``, ``b = 0``) the density of the velocity's random walk, where the
    flight asks for more than ``floor``: the 4.5 plane with its IMU left out 0.189 -> 0.040 m
    RMSE, maximum 2.53 -> 0.15 m (one random walk for its launch, its turns and its cruise)."""
    model = ev.model
    if model is None:
        density = _em_density(ev.t, ev.a, x)
    else:  # over the model's intervals, each other event taking its own's
        density = on_every_event(_em_density(ev.t[model], ev.a[model], x[model]), model)
    return replace(ev, q_accel=np.maximum(floor, ACCEL_EM_GAIN * density))


def _em_density(t: FloatArray, a: FloatArray, x: FloatArray) -> FloatArray:
    """Per event, its window's ``sum(w^2) / sum(dt)`` (:func:`em_accel`)."""
    dt = np.diff(t, prepend=t[0])
    w = np.zeros(t.size)
    # v(k) = v(k-1) + (a_k - b) dt + w_k  (the transition of model.transition with the input)
    w[1:] = x[1:, 1] - x[:-1, 1] - (a[1:] - x[:-1, 2]) * dt[1:]
    window = np.floor((t - t[0]) / ACCEL_EM_WINDOW_S).astype(np.int64)
    squares, span = np.bincount(window, w * w), np.bincount(window, dt)
    density = np.divide(squares, span, out=np.zeros(span.size), where=span > 0)
    return np.asarray(density[window])


def em_scale(ev: Events, noise: Noise, out: dict[str, np.ndarray]) -> None:
    """EM, M-step: each series' noise scale from the smoothed residuals (in place): ``out``'s
    rows (each sample's smoothed ``H x`` and its variance) and verdicts."""
    m = noise.scale.size - 1
    for i, entry in [*((i, i) for i in range(m)), (VELOCITY, m)]:
        mine = np.flatnonzero((ev.who == i) & out["accepted"])
        if noise.fixed[entry] or not mine.size:
            continue
        resid = ev.z[mine] - out["hx"][mine]
        ratio = (resid**2 + out["var_row"][mine]) / noise.base[mine]
        ratio = ratio[np.isfinite(ratio)]  # a state the filter lost (damaged stamps) says nothing
        if ratio.size:
            noise.scale[entry] = max(float(np.mean(ratio)), 1e-4)
