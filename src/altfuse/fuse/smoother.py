"""Offline Kalman smoother: a forward filter and a Rauch-Tung-Striebel backward pass.

The papers' methods, like the autopilot's EKF, are causal. Offline, the whole flight is known;
this method uses it. Beyond the papers (issue 8); textbook references: Rauch, Tung & Striebel,
AIAA J. 3(8), 1965, doi:10.2514/3.3166; Bar-Shalom, Li & Kirubarajan, *Estimation with
Applications to Tracking and Navigation*, 2001, ch. 5 and 8.

State (``n = 3 +`` one per sensor ``+`` one per barometer with a logged temperature)::

    x = [h, v, b, c_1 .. c_m, k_1 ..]
    h  height above take-off [m]            v  vertical velocity [m/s]
    b  accelerometer bias [m/s^2]          c_i  for a GPS or barometer: its offset [m];
                                                 for a rangefinder: the ground height under the
                                                 vehicle above take-off [m]
    k_j  a barometer's temperature coefficient [m/degC] (a constant, learnt from the flight)

Process, between consecutive events ``dt`` apart, driven by the mean earth-frame vertical
acceleration ``a`` over the interval (the IMU integrated exactly between events, so the filter
steps at the measurements' rate, not the IMU's)::

    h += v dt + (a - b) dt^2 / 2        v += (a - b) dt
    b, c_i: random walks                noise: white acceleration q_a, and q_b, q_c per state

Measurements, each fused at its own sample time (no resampling before fusion)::

    GPS:  z_i = h + c_i + n_i       barometer:  z_i = h + c_i + k_j (T - T_0) + n_i
    rangefinder:  z_i = h - c_i + n_i

A GPS's lag is not modelled here: the pipeline moves each GPS's samples earlier by the lag it
measures against the barometer (:func:`altfuse.align.estimate_lag`; 0.1-0.4 s on the
simulators' logs, not estimated on altfuse's own simulated flights, whose GPS noise hides it).

On the ground before take-off (the datum's ground window, ending ``STILL_MARGIN_S`` before the
detected take-off) the vehicle stands at the take-off point: ``h = 0`` and ``v = 0`` there. This
pins what the sensors alone leave free (all offsets and ``h`` can shift together) and makes
``fused_std`` an uncertainty about the height above take-off.

Without IMU or ATT records the model falls back to altitude only: ``a = 0``, ``b`` frozen at 0,
and a larger acceleration noise (a constant-velocity random walk); the metadata says so.

From the log itself:

- measurement noise: each sensor's local spread of second differences over ``NOISE_WINDOW_S``
  (``sigma = 1.4826 MAD(d2 z) / sqrt(6)``: white noise survives where a smooth flight cancels;
  sensors get noisier and quieter within a flight), scaled by EM (``EM_PASSES`` smoother passes,
  each followed by the M-step ``s_i = mean((residual^2 + H P H^T) / sigma^2)`` over the sensor's
  accepted samples);
- the acceleration noise, from the accelerometer's own sample-to-sample spread
  (:func:`accel_psd`);
- each barometer's temperature coefficient (a state, above);
- the terrain's roughness under a rangefinder, per metre flown (:func:`terrain_noise`, with the
  horizontal speed from ``GPS.Spd``): over flat ground, or hovering, the rangefinder is an
  absolute reference; over hills it tells only short-term changes. Where the speed ends (a GPS
  lost in flight) the last known speed is held: taking the ground as free instead cost Paper
  A's flight without GPS 0.74 m against 0.03 m;
- whether a barometer drifts: a second forward pass with a drift rate ``r`` on each barometer's
  offset (``c += r dt``, ``r`` a random walk of density ``Q_DRIFT``), kept if it raises the
  log-likelihood of the samples both passes accept by more than ``DRIFT_GAIN`` (a likelihood-ratio
  test at 0.1 %) and rejects no more samples (:func:`_evidence_gain`). A ramp (0.05 m/s) is then
  told from the GPS's wander even with no third sensor (hover RMSE 2.36 m -> 0.23 m), and a
  barometer that does not drift keeps its stable offset (a drift rate it does not need lets the
  height wander where GPS and barometer are alone).

The offsets' random-walk densities are physical defaults (``Q_OFFSET``: a GPS's vertical error
wanders by about 1 m over 100 s; a barometer, once its temperature is modelled, by centimetres),
not estimates: with two drifting sensors the log fixes only the sum of their densities, and
splitting it evenly (the method of moments, and EM, which did not move from there) gave the
barometer the GPS's wander (hover RMSE 0.35 m against 0.07 m with the defaults).
:class:`SmootherParams` overrides (``--sigma``, ``--offset-noise``, ``--accel-noise``, ``--gate``).

Innovation gating: a sample whose innovation exceeds ``gate`` standard deviations (3.5) is
rejected, counted per sensor and traced. When no sample of any sensor has passed for
``LOCKOUT_S`` (2 s), the estimate, not every sensor, has gone astray: the height's and the
velocity's variances grow by what the next sample says, which then passes (ArduPilot's EKF3
resets its height after 5 s). Without it one bad stretch locked every later sample out (a
simulator's log: 47 s and 706 of 706 samples rejected, 415 m below the ground). At 5 sigma,
Paper A's barometer excursion was accepted long enough to bend the barometer's temperature
coefficient (0.24 m/degC against 0.12), and every height after the rangefinder was lost with it
(0.73 m RMSE against 0.17 m at 3.5 sigma).

Outputs: the smoothed height at the clock's ticks, its standard deviation (``fused_std``), the
velocity, bias and each sensor's offset (or ground height), and each sensor's contribution: the
share, per tick, of the total Kalman gain on ``h`` that its accepted samples carried.

Measured (``benchmarks/smoother_accuracy.py``, 66 simulated flights): the lowest RMSE of all
methods on each; 97.3 % of the true errors within +-2 ``fused_std`` over all. Limits: per flight
that coverage ranges from 0.51 to 1.00. Where GPS and barometer are alone through Paper A's
excursion, part of it is followed and ``fused_std`` is too small; where the default offset
random walks overstate a drift (the simulator's barometer has none beyond its temperature),
too large.

Implementation: numpy. filterpy's ``KalmanFilter`` and ``rts_smoother`` expect one measurement
vector of fixed size per step; here each step carries one scalar measurement of any sensor, or
none (a clock tick), and the gains per sensor are needed for the contributions — an explicit loop
over events with the arrays the backward pass needs is shorter than adapting it. Cost is linear
in the number of events: one forward and one backward step each.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from altfuse.fuse.base import FUSED, NONE, SINGLE, FusionInput, FusionResult
from altfuse.metrics import MAD_TO_SIGMA, mad_sigma, white_noise_sigma
from altfuse.model import FloatArray, Samples
from altfuse.params import InvalidParameter, Params, param

#: Process noise defaults (power spectral densities): white acceleration [m^2/s^3] with and
#: without the accelerometer, bias random walk [m^2/s^5], offset random walks [m^2/s] for GPS and
#: barometer, and for a rangefinder's ground height when the horizontal speed is unknown.
Q_ACCEL = 0.05
Q_ACCEL_MIN = 1e-3
Q_ACCEL_NO_IMU = 2.0
Q_BIAS = 1e-5
Q_OFFSET = {"gps": 0.01, "baro": 1e-4, "rangefinder": 0.3}
#: Ground height under a moving vehicle: random walk per metre flown [m^2/m] when the log cannot
#: tell, and its floor in time [m^2/s] (grass, waves: about 3 cm over 100 s).
Q_TERRAIN_PER_M = 0.05
Q_GROUND_STILL = 1e-5
#: Prior on a barometer's temperature coefficient [m/degC] (a constant, learnt from the flight).
THERMAL_PRIOR = 0.5
#: A barometer's drift rate [m/s]: its prior at the start, and its random-walk density
#: [m^2/s^3] (the rate may change by about 0.03 m/s in 100 s).
DRIFT_PRIOR = 0.01
Q_DRIFT = 1e-5
#: Log-likelihood gain that adds the drift rates (or the temperature coefficients): half the
#: chi-square (1 dof) 0.1 % point.
DRIFT_GAIN = 10.83 / 2
#: The richer model may reject this share more of the samples (the temperature model of the
#: sample mission rejects 2 of 5,371 more, and explains the rest by 25 in log-likelihood).
EVIDENCE_SLACK = 1e-3
#: How well "standing still at the take-off point" holds on the ground [m, m/s].
STILL_SIGMA = 0.02
#: The spans [s] over which two sensors' agreement is measured, and the least share of the
#: default random walks it may leave (a floor: two simulated sensors can agree exactly).
AGREEMENT_LAGS_S = (2.0, 5.0, 10.0, 20.0, 40.0)
Q_AGREEMENT_MIN_SHARE = 1e-2
#: Longest time [s] every sensor's samples may be rejected before the estimate is let loose.
LOCKOUT_S = 2.0
#: EM iterations (each a forward and a backward pass) after the first pass.
EM_PASSES = 4
#: Window [s] of the local measurement-noise estimate.
NOISE_WINDOW_S = 5.0
Q_TERRAIN_MAX = 1.0
MAX_SPEED_M_S = 100.0
_MIN_SIGMA_M = 0.01


@dataclass(frozen=True, kw_only=True)
class SmootherParams(Params):
    """What the smoother takes from the user; everything else it learns from the log."""

    gate_sigma: float = param(3.5, help="innovation gate", unit="sigma", check="positive")
    accel_noise_m2_s3: float | None = param(
        None,
        help="white acceleration noise density",
        unit="m^2/s^3",
        check="positive",
        default_text=f"from the accelerometer's noise, {Q_ACCEL_NO_IMU:g} without IMU",
    )
    sigma_m: Mapping[str, float] = param(
        {},
        help="a sensor's measurement noise",
        unit="m",
        check="positive",
        default_text="from the log",
    )
    offset_noise_m2_s: Mapping[str, float] = param(
        {},
        help="random-walk density of a sensor's offset (a rangefinder's ground height)",
        unit="m^2/s",
        check="positive",
        default_text=f"gps {Q_OFFSET['gps']:g}, baro {Q_OFFSET['baro']:g}; rangefinder from the "
        "terrain and the speed",
    )


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


def local_sigma(t: FloatArray, z: FloatArray, window_s: float = NOISE_WINDOW_S) -> FloatArray:
    """Noise of one sensor at each of its samples [m]: :func:`measurement_sigma` over a running
    window of ``window_s`` (sensors get noisier and quieter within a flight)."""
    if z.size < 5:
        return np.full(z.size, measurement_sigma(z))
    d2 = np.abs(np.diff(z, 2))
    d2 = np.concatenate(([d2[0]], d2, [d2[-1]]))
    width = max(5, round(window_s / float(np.median(np.diff(t)) or 1.0)))
    med = pd.Series(d2).rolling(width, center=True, min_periods=3).median().to_numpy()
    return np.asarray(np.maximum(MAD_TO_SIGMA * med / math.sqrt(6.0), _MIN_SIGMA_M))


def terrain_noise(d: FloatArray, flown: FloatArray, lag: int) -> float:
    """Ground-height random walk per metre flown [m^2/m], by method of moments; NaN if unknown.

    ``d`` is another sensor minus a rangefinder on the clock (the ground height plus both
    sensors' errors), ``flown`` the distance flown [m] on the clock. Over ``lag`` ticks the
    squared change of ``d`` is ``q dx + const`` (``const``: the noise, and drift too slow to
    matter over the lag): regressed on the distance ``dx`` flown meanwhile.
    """
    if d.size <= lag:
        return math.nan
    dd, dx = d[lag:] - d[:-lag], flown[lag:] - flown[:-lag]
    ok = np.isfinite(dd) & np.isfinite(dx)
    if (ok & (dx > 1.0)).sum() < 10 or (ok & (dx <= 1.0)).sum() < 10:
        return math.nan
    design = np.column_stack([dx[ok], np.ones(ok.sum())])
    slope = float(np.linalg.lstsq(design, dd[ok] ** 2, rcond=None)[0][0])
    return max(slope, 0.0)


def _merge_events(
    samples: Sequence[Samples], ticks: FloatArray
) -> tuple[FloatArray, np.ndarray, FloatArray, np.ndarray]:
    """All sample and tick times in order: (time, sensor index or -1 for a tick, value, and
    each event's position in its sensor's samples)."""
    times = [ticks] + [s[0] for s in samples]
    which = [np.full(ticks.size, -1)] + [np.full(s[0].size, i) for i, s in enumerate(samples)]
    values = [np.full(ticks.size, np.nan)] + [s[1] for s in samples]
    position = [np.arange(ticks.size)] + [np.arange(s[0].size) for s in samples]
    t = np.concatenate(times)
    who = np.concatenate(which)
    # at equal times the tick comes last: it reports the state after its instant's samples
    order = np.lexsort((who == -1, t))
    return t[order], who[order], np.concatenate(values)[order], np.concatenate(position)[order]


def _interval_mean(series: Samples, t: FloatArray) -> FloatArray:
    """The mean of a sampled signal over each interval between consecutive times ``t`` (the
    samples integrated exactly, trapezoids); NaN where ``t`` leaves the samples' span."""
    ts, v = series
    order = np.argsort(ts, kind="stable")
    ts, v = ts[order], v[order]
    integral = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(ts))))
    at_events = np.interp(t, ts, integral)
    dt = np.diff(t, prepend=t[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.diff(at_events, prepend=at_events[0]) / dt
    mean[~np.isfinite(mean) | (t < ts[0]) | (t > ts[-1])] = np.nan
    return np.asarray(mean)


def _thermal(
    temperatures: Sequence[Samples | None],
    samples: Sequence[Samples],
    who: np.ndarray,
    position: np.ndarray,
    m: int,
) -> tuple[np.ndarray, FloatArray]:
    """Each sensor's temperature-coefficient state index (-1: none) and each event's temperature
    less the sensor's first one [degC] (0 for the others)."""
    tstate = np.full(m, -1)
    dtemp = np.zeros(who.size)
    for i, temp in enumerate(temperatures):
        if temp is None or temp[0].size < 2 or not samples[i][0].size:
            continue
        order = np.argsort(temp[0], kind="stable")
        at_samples = np.interp(samples[i][0], temp[0][order], temp[1][order])
        tstate[i] = 3 + m + int((tstate >= 0).sum())
        mine = who == i
        dtemp[mine] = (at_samples - at_samples[0])[position[mine]]
    return tstate, dtemp


@dataclass(frozen=True)
class _Layout:
    """The sensors' states in ``x`` and what their measurement rows need."""

    sign: FloatArray  # +1: the sensor measures h + c_i; -1: h - c_i (a rangefinder)
    thermal: np.ndarray  # each sensor's temperature-coefficient state; -1: none
    dtemp: FloatArray  # each event's temperature change of its sensor [degC]
    drift: np.ndarray  # each sensor's drift-rate state; -1: none

    @property
    def n(self) -> int:
        return 3 + self.sign.size + int((self.thermal >= 0).sum() + (self.drift >= 0).sum())

    @property
    def drift_pairs(self) -> np.ndarray:
        """(offset state, its drift-rate state) per drifting sensor, shape (k, 2)."""
        drifting = np.flatnonzero(self.drift >= 0)
        return np.column_stack([3 + drifting, self.drift[drifting]])

    def without_thermal(self) -> _Layout:
        """The same without the temperature-coefficient states."""
        return _Layout(self.sign, np.full(self.sign.size, -1), self.dtemp, self.drift)

    def with_drift(self, kinds: Sequence[str]) -> _Layout:
        """The same with a drift-rate state for each barometer."""
        drift = np.full(self.sign.size, -1)
        baros = [i for i, k in enumerate(kinds) if k == "baro"]
        drift[baros] = self.n + np.arange(len(baros))
        return _Layout(self.sign, self.thermal, self.dtemp, drift)


def _transition(dt: float, n: int, use_bias: bool, drifts: np.ndarray) -> FloatArray:
    """F over ``dt``: h += v dt - b dt^2/2, v += -b dt, c_i += r_i dt for a sensor with a drift
    rate ``r_i`` (``drifts``: (offset, rate) state pairs); the rest random walks (identity)."""
    f = np.eye(n)
    f[0, 1] = dt
    if use_bias:
        f[0, 2], f[1, 2] = -0.5 * dt * dt, -dt
    if drifts.size:
        f[drifts[:, 0], drifts[:, 1]] = dt
    return f


@dataclass(frozen=True)
class _Events:
    """What the forward pass steps through, one entry per event (a sample or a clock tick).

    ``who``: the sensor of a sample, -1 for a tick; ``z``: the sample's value; ``a``: the mean
    vertical acceleration over the interval ending at the event; ``q_state`` (events, m): the
    sensor states' random-walk densities over that interval; ``still``: the events at which the
    vehicle is known to stand at the take-off point; ``h0``: the first height guess.
    """

    t: FloatArray
    who: np.ndarray
    z: FloatArray
    a: FloatArray
    q_state: FloatArray
    still: np.ndarray
    q_accel: float
    use_bias: bool
    gate: float
    h0: float


def _process_noise(ev: _Events, k: int, dt: float, n: int, drifts: np.ndarray) -> FloatArray:
    """Q over the interval ``dt`` ending at event ``k``: white acceleration on (h, v), the bias's
    and the sensor states' random walks, and each drifting offset's integrated random walk."""
    m = ev.q_state.shape[1]
    q = np.zeros((n, n))
    q_accel = ev.q_accel
    q[0, 0], q[0, 1], q[1, 1] = q_accel * dt**3 / 3, q_accel * dt**2 / 2, q_accel * dt
    q[1, 0] = q[0, 1]
    q[2, 2] = Q_BIAS * dt if ev.use_bias else 0.0
    q[3 : 3 + m, 3 : 3 + m] = np.diag(ev.q_state[k] * dt)
    for c, rate in drifts:  # a drifting offset: an integrated random walk
        q[c, c] += Q_DRIFT * dt**3 / 3
        q[c, rate] = q[rate, c] = Q_DRIFT * dt**2 / 2
        q[rate, rate] = Q_DRIFT * dt
    return q


def _hold_still(x: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
    """On the ground before take-off: h = 0 and v = 0 (the datum's definition)."""
    for j in (0, 1):
        s = p[j, j] + STILL_SIGMA**2
        kg = p[:, j] / s
        x = x - kg * x[j]
        p = p - np.outer(kg, p[j])
    return x, p


def _rts(
    ev: _Events, layout: _Layout, filtered: tuple[FloatArray, FloatArray, FloatArray, FloatArray]
) -> tuple[FloatArray, FloatArray]:
    """Rauch-Tung-Striebel: x_s(k) = x_f(k) + C (x_s(k+1) - x_p(k+1)), C = P_f F^T P_p(k+1)^-1."""
    xp, pp, xf, pf = filtered
    xs, ps = xf.copy(), pf.copy()
    for k in range(ev.t.size - 2, -1, -1):
        f = _transition(ev.t[k + 1] - ev.t[k], layout.n, ev.use_bias, layout.drift_pairs)
        c = np.linalg.solve(pp[k + 1].T, (pf[k] @ f.T).T).T
        xs[k] = xf[k] + c @ (xs[k + 1] - xp[k + 1])
        ps[k] = pf[k] + c @ (ps[k + 1] - pp[k + 1]) @ c.T
    return xs, ps


def _measurement_row(layout: _Layout, i: int, k: int) -> FloatArray:
    """H of sensor ``i``'s sample at event ``k``: h plus the sensor's offset (GPS, baro) or
    minus its ground height (rangefinder), plus its temperature term."""
    hrow = np.zeros(layout.n)
    hrow[0], hrow[3 + i] = 1.0, layout.sign[i]
    if layout.thermal[i] >= 0:
        hrow[layout.thermal[i]] = layout.dtemp[k]
    return hrow


def _run(ev: _Events, r: FloatArray, layout: _Layout, smooth: bool = True) -> dict[str, np.ndarray]:
    """Forward filter and (if ``smooth``) RTS pass over the events: the states and diagnostics.

    ``r`` is each event's measurement variance. Also each accepted sample's log-likelihood (its
    innovation's density; NaN elsewhere): the evidence by which :func:`_evidence_gain` compares two
    models.
    """
    sign, tstate, drifts = layout.sign, layout.thermal, layout.drift_pairs
    m, n = sign.size, layout.n
    n_thermal = int((tstate >= 0).sum())
    count = ev.t.size
    loglik = np.full(count, np.nan)
    xp = np.zeros((count, n))
    pp = np.zeros((count, n, n))
    xf = np.zeros((count, n))
    pf = np.zeros((count, n, n))
    gain_h = np.zeros(count)
    accepted = np.zeros(count, dtype=bool)
    x = np.zeros(n)
    x[0] = ev.h0
    # without the accelerometer the bias is inert: a tiny fixed variance keeps P invertible
    p = np.diag(
        [10.0**2, 3.0**2, 0.1**2 if ev.use_bias else 1e-9]
        + [1.0**2] * m
        + [THERMAL_PRIOR**2] * n_thermal
        + [DRIFT_PRIOR**2] * (n - 3 - m - n_thermal)
    )
    previous = last_accepted = ev.t[0]
    for k in range(count):
        dt = ev.t[k] - previous
        previous = ev.t[k]
        if dt > 0:
            f = _transition(dt, n, ev.use_bias, drifts)
            x = f @ x
            x[0] += 0.5 * ev.a[k] * dt * dt
            x[1] += ev.a[k] * dt
            p = f @ p @ f.T + _process_noise(ev, k, dt, n, drifts)
        i = ev.who[k]
        if i >= 0:
            hrow = _measurement_row(layout, i, k)
            y = ev.z[k] - hrow @ x
            locked_out = ev.t[k] - last_accepted > LOCKOUT_S
            if locked_out and y * y > ev.gate * ev.gate * (hrow @ p @ hrow + r[k]):
                # no sample of any sensor passed the gate for LOCKOUT_S: the estimate, not
                # every sensor, has gone astray (ArduPilot's EKF3 resets its height after
                # 5 s); its height and velocity become as uncertain as this sample says
                p = p.copy()
                p[0, 0] += y * y
                p[1, 1] += (y / LOCKOUT_S) ** 2
            ph = p @ hrow
            s = hrow @ ph + r[k]
        xp[k], pp[k] = x, p
        if i >= 0 and y * y <= ev.gate * ev.gate * s:  # innovation gate
            kg = ph / s
            x = x + kg * y
            p = p - np.outer(kg, ph)
            gain_h[k] = abs(kg[0])
            accepted[k] = True
            last_accepted = ev.t[k]
            loglik[k] = -0.5 * (math.log(2 * math.pi * s) + y * y / s)
        if ev.still[k]:
            x, p = _hold_still(x, p)
        xf[k], pf[k] = x, p
    if smooth:
        xf, pf = _rts(ev, layout, (xp, pp, xf, pf))
    return {"x": xf, "p": pf, "gain_h": gain_h, "accepted": accepted, "loglik": loglik}


def _evidence_gain(without: dict[str, np.ndarray], richer: dict[str, np.ndarray]) -> float:
    """Log-likelihood gain of the richer model (barometer drift rates, temperature
    coefficients) over the one without, over the samples both accept; ``-inf`` if it accepts
    fewer samples in all, beyond ``EVIDENCE_SLACK`` of them.

    The comparison is over the same samples: counting a rejected sample at the gate's value
    would credit whichever model explains away a departure (Paper A's barometer excursion), and
    one whose offset drifts then lets ``h`` wander once no third sensor holds it. A model that
    explains the data better has no need to reject more of it: the drift model did, by up to
    94 samples of a rangefinder returning from a dropout, on flights where it had gone astray.
    """
    slack = EVIDENCE_SLACK * without["accepted"].sum()
    if richer["accepted"].sum() < without["accepted"].sum() - slack:
        return -math.inf
    both = without["accepted"] & richer["accepted"]
    return float(np.sum(richer["loglik"][both]) - np.sum(without["loglik"][both]))


def _thermal_evidence(
    physical: _Events, r: FloatArray, layout: _Layout
) -> tuple[_Layout, float, dict[str, np.ndarray] | None]:
    """``layout`` with the barometers' temperature coefficients where the log's evidence asks
    for them, that evidence (the log-likelihood gain, NaN without a temperature), and the
    forward pass of the layout chosen (None without a temperature).

    In a simulator's standard atmosphere the temperature follows the height, and a coefficient
    on it is a second, wrong scale (three climbs: 0.09-0.29 m RMSE with it, 0.01-0.04 m
    without). The test is made with the offsets' physical random walks (``physical``), not
    with a looser one a user gave: a barometer let wander absorbs the drift the temperature
    explains, and the test would drop a model the flight needs (the sample hover with
    ``--offset-noise baro=0.001``: 0.40 m RMSE without it, 0.06 m with).
    """
    if not (layout.thermal >= 0).any():
        return layout, math.nan, None
    plain = layout.without_thermal()
    without, richer = _run(physical, r, plain, False), _run(physical, r, layout, False)
    gain = _evidence_gain(without, richer)
    return (layout, gain, richer) if gain > DRIFT_GAIN else (plain, gain, without)


def _drift_evidence(
    ev: _Events,
    r: FloatArray,
    layout: _Layout,
    kinds: Sequence[str],
    stable: dict[str, np.ndarray] | None,
) -> tuple[_Layout, float]:
    """``layout`` with a drift rate on each barometer's offset where the log's evidence asks
    for it, and that evidence (NaN without a barometer); ``stable`` is ``layout``'s forward pass
    if one was already run with these events."""
    if "baro" not in kinds:
        return layout, math.nan
    drifting = layout.with_drift(kinds)
    gain = _evidence_gain(
        stable if stable is not None else _run(ev, r, layout, False),
        _run(ev, r, drifting, False),
    )
    return (drifting if gain > DRIFT_GAIN else layout), gain


def _drift_record(layout: _Layout, gain: float) -> dict[str, float | int | str]:
    """The drift test's outcome for the metadata (none without a barometer)."""
    if math.isnan(gain):
        return {}
    if not math.isfinite(gain):
        return {"baro_drift": "not modelled (it rejected more samples than the stable model)"}
    verdict = "modelled" if (layout.drift >= 0).any() else "not modelled"
    return {"baro_drift": verdict, "baro_drift_loglik_gain": gain}


def _known_names(values: Mapping[str, float], names: Sequence[str], field: str) -> None:
    """Per-sensor overrides must name sensors of this log."""
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise InvalidParameter(field, f"names no sensor of this log: {', '.join(unknown)}")


def wander_bound(d: FloatArray, dt: float) -> float:
    """An upper bound [m^2/s] on the random-walk density of ``d`` on a clock of step ``dt``:
    ``Var(d(t + L) - d(t)) = q L + 2 sigma^2 >= q L``, so ``q <= Var_L / L`` at every span
    ``L`` of AGREEMENT_LAGS_S (each variance robust, from the MAD); the least of them. Noise
    only loosens it: beyond its sampling error it never claims that two sensors agree better
    than they do. NaN when the difference is too short."""
    bounds = []
    for lag in AGREEMENT_LAGS_S:
        k = max(1, round(lag / dt))
        inc = d[k:] - d[:-k] if d.size > k else np.zeros(0)
        inc = inc[np.isfinite(inc)]
        if inc.size >= 20:
            bounds.append(mad_sigma(inc) ** 2 / (k * dt))
    return min(bounds) if bounds else math.nan


def _bounded_by_agreement(
    inputs: FusionInput, q_time: FloatArray, given: Sequence[bool]
) -> FloatArray:
    """GPS and barometer offsets' random walks no looser than the sensors' agreement allows.

    Two sensors' offsets wander apart at the sum of their densities, which their difference
    bounds from above (:func:`wander_bound`); each one's can be no larger. A pair that agrees better
    than the defaults' sum scales both defaults down in their ratio (the prior's preference of a
    stable barometer over a wandering GPS stays); never up. In the simulators' logs a GPS and a
    scaled barometer agree to a centimetre over minutes, where the defaults allow a metre and
    gave a fused_std five to twenty times the true error.
    """
    out: FloatArray = q_time.copy()
    kinds = inputs.kinds
    steady = [i for i, k in enumerate(kinds) if k != "rangefinder"]
    bound = {
        (i, j): wander_bound(inputs.z[:, i] - inputs.z[:, j], inputs.dt_s)
        for i, j in itertools.combinations(steady, 2)
    }
    for i in (i for i in steady if not given[i]):
        for j in (j for j in steady if j != i):
            observed = bound[min(i, j), max(i, j)]
            prior = q_time[i] + q_time[j]
            if math.isfinite(observed) and prior > 0:
                share = max(observed / prior, Q_AGREEMENT_MIN_SHARE)
                out[i] = min(out[i], q_time[i] * min(1.0, share))
    return out


def _state_noise(
    inputs: FusionInput, times: FloatArray, given: Mapping[str, float]
) -> tuple[FloatArray, dict[str, float]]:
    """Random-walk densities of the sensor states over each event interval (events, m), and each
    rangefinder's terrain roughness [m^2/m] by name, for the record.

    ``given`` (by sensor name) overrides. GPS and barometer offsets: ``Q_OFFSET``, constant. A
    rangefinder's ground height changes as the vehicle flies over the ground: ``q dx`` per
    distance ``dx`` flown (``q`` by :func:`terrain_noise` against the quietest other sensor) plus
    ``Q_GROUND_STILL`` in time; without a speed, ``Q_OFFSET["rangefinder"]`` in time.
    """
    z, t, kinds, names, speed = inputs.z, inputs.t, inputs.kinds, inputs.names, inputs.speed
    q_time = np.array([given.get(n, Q_OFFSET[k]) for n, k in zip(names, kinds, strict=True)])
    q_time = _bounded_by_agreement(inputs, q_time, [n in given for n in names])
    q_events = np.tile(q_time, (times.size, 1))
    terrain: dict[str, float] = {}
    ranges = [i for i, k in enumerate(kinds) if k == "rangefinder" and names[i] not in given]
    if speed is None or speed.t.size < 2 or not ranges:
        return q_events, terrain
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.1
    v = Samples(speed.t, np.clip(speed.value, 0.0, MAX_SPEED_M_S))
    flown_speed = _interval_mean(v, t)
    flown = np.cumsum(np.nan_to_num(flown_speed) * np.diff(t, prepend=t[0]))
    flown[np.isnan(flown_speed)] = np.nan
    # outside the speed's span (a GPS lost in flight) the last known speed is held
    speed_events = pd.Series(_interval_mean(v, times)).ffill().bfill().to_numpy()
    noise = [measurement_sigma(col[np.isfinite(col)]) for col in z.T]
    others = [j for j, k in enumerate(kinds) if k != "rangefinder"]
    for i in ranges:
        q_m = math.nan
        if others:
            j = min(others, key=lambda j: noise[j])
            q_m = terrain_noise(z[:, j] - z[:, i], flown, max(1, round(1.0 / dt)))
        q_m = Q_TERRAIN_PER_M if not math.isfinite(q_m) else min(q_m, Q_TERRAIN_MAX)
        terrain[names[i]] = q_m
        moving = q_m * speed_events + Q_GROUND_STILL
        q_events[:, i] = np.where(np.isfinite(speed_events), moving, q_time[i])
    return q_events, terrain


@dataclass(frozen=True)
class _Noise:
    """Each event's measurement variance as ``base * scale[sensor]``: ``base`` the local noise
    of its sensor squared, ``scale`` refined by EM except for the sensors in ``fixed``."""

    base: FloatArray
    scale: FloatArray
    fixed: np.ndarray

    def r(self, who: np.ndarray) -> FloatArray:
        r: FloatArray = self.base * self.scale[np.maximum(who, 0)]
        return r


def _measurement_noise(
    inputs: FusionInput, given: Mapping[str, float], who: np.ndarray, position: np.ndarray
) -> _Noise:
    """Each sample's variance: the local noise of its sensor (or ``given``), scale 1."""
    local = [
        np.full(s.value.size, given[name]) if name in given else local_sigma(*s)
        for name, s in zip(inputs.names, inputs.samples, strict=True)
    ]
    base = np.ones(who.size)
    for i in range(len(inputs.samples)):
        mine = who == i
        base[mine] = local[i][position[mine]] ** 2
    fixed = np.array([name in given for name in inputs.names])
    return _Noise(base, np.ones(len(inputs.samples)), fixed)


def _em_scale(ev: _Events, layout: _Layout, noise: _Noise, out: dict[str, np.ndarray]) -> None:
    """EM, M-step: each sensor's noise scale from the smoothed residuals (in place)."""
    xs, ps = out["x"], out["p"]
    tstate, sign, dtemp = layout.thermal, layout.sign, layout.dtemp
    for i in range(sign.size):
        mine = (ev.who == i) & out["accepted"]
        if noise.fixed[i] or not mine.any():
            continue
        # the measurement model's rows at these events: coefficients on (h, c_i, k_i)
        cols = [0, 3 + i] + ([int(tstate[i])] if tstate[i] >= 0 else [])
        coef = np.column_stack(
            [np.ones(mine.sum()), np.full(mine.sum(), sign[i])]
            + ([dtemp[mine]] if tstate[i] >= 0 else [])
        )
        resid = ev.z[mine] - np.einsum("ka,ka->k", coef, xs[mine][:, cols])
        var_h = np.einsum("ka,kab,kb->k", coef, ps[mine][:, cols][:, :, cols], coef)
        noise.scale[i] = max(float(np.mean((resid**2 + var_h) / noise.base[mine])), 1e-4)


def _contributions(
    who: np.ndarray, gain_h: FloatArray, z: FloatArray
) -> tuple[FloatArray, np.ndarray]:
    """Each sensor's share per tick of the gain on h its samples carried since the previous tick
    (summing to 1 over the sensors present at the tick), and which ticks have a sensor."""
    m = z.shape[1]
    tick = who == -1
    idx_tick = np.flatnonzero(tick)
    cum = np.zeros((who.size + 1, m))
    for i in range(m):
        cum[1:, i] = np.cumsum(np.where(who == i, gain_h, 0.0))
    bounds = np.concatenate(([0], idx_tick[:-1] + 1))
    share = cum[idx_tick + 1] - cum[bounds]
    valid = np.asarray(np.isfinite(z).any(axis=1))
    total = share.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        weights = np.where(total > 0, share / total, np.nan)
    # a tick with no update since the previous one keeps the previous contributions
    for k in range(1, z.shape[0]):
        if not np.isfinite(weights[k]).all():
            weights[k] = weights[k - 1]
    # a sensor absent from the clock at a tick (a gap longer than --max-gap) gets no weight there,
    # though its samples near the gap still informed the smoother
    present = np.isfinite(z)
    weights = np.where(present, np.nan_to_num(weights), 0.0)
    total = weights.sum(axis=1, keepdims=True)
    even = present / np.maximum(present.sum(axis=1, keepdims=True), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        weights = np.where(total > 0, weights / total, even)
    return np.asarray(np.where(valid[:, None], weights, np.nan)), valid


def fuse_smoother(inputs: FusionInput, params: SmootherParams) -> FusionResult:
    """Kalman filter + RTS smoother over the whole flight (see the module doc).

    From ``inputs``: each sensor's own referred ``samples`` (fused at their own times), its
    ``kinds`` and ``names``; ``z`` on the clock marks the ticks where no sensor is valid and gives
    the noise densities of the sensors' states; the clock ``t`` at which the result is reported;
    ``accel`` (None: the altitude-only random-walk model), ``speed``, ``temperatures`` (a
    barometer with them gets a temperature coefficient) and ``on_ground_s`` (there ``h = 0`` and
    ``v = 0``) when the log has them.
    """
    names, kinds, samples = inputs.names, inputs.kinds, inputs.samples
    _known_names(params.sigma_m, names, "sigma_m")
    _known_names(params.offset_noise_m2_s, names, "offset_noise_m2_s")
    m = len(samples)
    accel = None if inputs.accel is None else inputs.accel.samples
    use_imu = accel is not None and accel.t.size >= 2
    q_accel = Q_ACCEL_NO_IMU
    if params.accel_noise_m2_s3 is not None:
        q_accel = params.accel_noise_m2_s3
    elif use_imu and accel is not None:
        q_accel = accel_psd(*accel)
    times, who, values, position = _merge_events(samples, inputs.t)
    # each sample's variance: the local noise of its sensor times a scale refined by EM
    noise = _measurement_noise(inputs, params.sigma_m, who, position)
    still = np.zeros(times.size, dtype=bool)
    if inputs.on_ground_s is not None:
        lo, hi = inputs.on_ground_s
        still = (who == -1) & (times >= lo) & (times <= hi)
    a = np.zeros(times.size)
    if use_imu and accel is not None:
        a = np.nan_to_num(_interval_mean(accel, times))
    first = [s.value[0] for s in samples if s.value.size]
    h0 = float(np.median(first)) if first else 0.0
    tstate, dtemp = _thermal(inputs.temperatures, samples, who, position, m)
    sign = np.array([-1.0 if k == "rangefinder" else 1.0 for k in kinds])
    layout = _Layout(sign, tstate, dtemp, np.full(m, -1))
    q_events, terrain = _state_noise(inputs, times, params.offset_noise_m2_s)
    ev = _Events(times, who, values, a, q_events, still, q_accel, use_imu, params.gate_sigma, h0)
    physical = ev
    if params.offset_noise_m2_s:
        physical = replace(ev, q_state=_state_noise(inputs, times, {})[0])
    layout, thermal_gain, chosen = _thermal_evidence(physical, noise.r(who), layout)
    # the thermal test's pass of the layout chosen, where it was made with these noises
    layout, drift_gain = _drift_evidence(
        ev, noise.r(who), layout, kinds, chosen if physical is ev else None
    )
    for npass in range(EM_PASSES + 1):
        out = _run(ev, noise.r(who), layout)
        if npass == EM_PASSES:
            break
        _em_scale(ev, layout, noise, out)

    tick = who == -1
    xs, ps = out["x"][tick], out["p"][tick]
    weights, valid = _contributions(who, out["gain_h"], inputs.z)
    n_valid = np.isfinite(inputs.z).sum(axis=1)
    status = np.where(n_valid == 1, SINGLE, np.where(valid, FUSED, NONE))
    return FusionResult(
        method="smoother",
        fused=np.where(valid, xs[:, 0], np.nan),
        weights=weights,
        status=status,
        traces={"offset": xs[:, 3 : 3 + m]},
        tick_traces={
            "fused_std": np.where(valid, np.sqrt(np.maximum(ps[:, 0, 0], 0.0)), np.nan),
            "velocity": xs[:, 1],
            "accel_bias": xs[:, 2],
        },
        params={
            "model": "accelerometer-driven" if use_imu else "altitude-only random walk (no IMU)",
            "accel_noise_m2_s3": q_accel,
            "gate_sigma": params.gate_sigma,
            **_drift_record(layout, drift_gain),
            **(
                {}
                if math.isnan(thermal_gain)
                else {
                    "baro_thermal": "modelled"
                    if (layout.thermal >= 0).any()
                    else "not modelled (the log's evidence does not ask for it)",
                    "baro_thermal_loglik_gain": thermal_gain,
                }
            ),
            **_fitted(names, ev, noise, layout, xs[-1]),
            **{f"q_terrain_{name}_m2_m": value for name, value in terrain.items()},
            **{
                f"rejected_{name}": int(((who == i) & ~out["accepted"]).sum())
                for i, name in enumerate(names)
            },
        },
    )


def _fitted(
    names: Sequence[str], ev: _Events, noise: _Noise, layout: _Layout, last: FloatArray
) -> dict[str, float]:
    """What the smoother learnt of each sensor, for the record: its noise (the median over its
    samples), its offset's random walk (the median over the flight) and a barometer's
    temperature coefficient."""
    sensor_q = np.median(ev.q_state, axis=0)
    who, tstate = ev.who, layout.thermal
    return {
        **{
            f"sigma_{name}_m": float(np.median(np.sqrt(noise.base[who == i] * noise.scale[i])))
            for i, name in enumerate(names)
            if (who == i).any()
        },
        **{f"q_offset_{name}_m2_s": float(sensor_q[i]) for i, name in enumerate(names)},
        **{
            f"thermal_{name}_m_per_degC": float(last[tstate[i]])
            for i, name in enumerate(names)
            if tstate[i] >= 0
        },
    }
