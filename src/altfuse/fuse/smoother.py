"""Offline Kalman smoother: a forward filter and a Rauch-Tung-Striebel backward pass.

The papers' methods, like the autopilot's EKF, are causal. Offline, the whole flight is known;
this method uses it. Beyond the papers (issue 8); textbook references: Rauch, Tung & Striebel,
AIAA J. 3(8), 1965, doi:10.2514/3.3166; Bar-Shalom, Li & Kirubarajan, *Estimation with
Applications to Tracking and Navigation*, 2001, ch. 5 and 8.

State (``n = 3 +`` one per sensor)::

    x = [h, v, b, c_1 .. c_m]
    h  height above take-off [m]            v  vertical velocity [m/s]
    b  accelerometer bias [m/s^2]          c_i  for a GPS or barometer: its offset [m];
                                                 for a rangefinder: the ground height under the
                                                 vehicle above take-off [m]

Process, between consecutive events ``dt`` apart, driven by the mean earth-frame vertical
acceleration ``a`` over the interval (the IMU integrated exactly between events, so the filter
steps at the measurements' rate, not the IMU's)::

    h += v dt + (a - b) dt^2 / 2        v += (a - b) dt
    b, c_i: random walks                noise: white acceleration q_a, and q_b, q_c per state

Measurements, each fused at its own sample time (no resampling before fusion)::

    GPS, barometer:  z_i = h + c_i + n_i          rangefinder:  z_i = h - c_i + n_i

Without IMU or ATT records the model falls back to altitude only: ``a = 0``, ``b`` frozen at 0,
and a larger acceleration noise (a constant-velocity random walk); the metadata says so.

Noise, from the log itself: each sensor's measurement noise starts from the spread of its second
differences (``sigma = 1.4826 MAD(d2 z) / sqrt(6)``, white noise surviving where a smooth flight
cancels) and is refined by EM (``EM_PASSES`` smoother passes, each followed by the M-step
``r_i = mean(residual^2 + H P H^T)`` over the sensor's accepted samples). The offsets' (and ground
heights') random-walk densities come from the data by method of moments (:func:`offset_noise`):
two sensors' difference drifts as the sum of their offsets' random walks. The acceleration noise
is a constant. ``--sigma``, ``--accel-noise`` and ``--gate`` override.

Innovation gating: a sample whose innovation exceeds ``gate`` standard deviations is rejected,
counted per sensor and traced.

Outputs: the smoothed height at the clock's ticks, its standard deviation (``fused_std``), the
velocity, bias and each sensor's offset (or ground height), and each sensor's contribution: the
share, per tick, of the total Kalman gain on ``h`` that its accepted samples carried.

Implementation: numpy. filterpy's ``KalmanFilter`` and ``rts_smoother`` expect one measurement
vector of fixed size per step; here each step carries one scalar measurement of any sensor, or
none (a clock tick), and the gains per sensor are needed for the contributions — an explicit loop
over events with the arrays the backward pass needs is shorter than adapting it. Cost is linear
in the number of events: one forward and one backward step each.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np

from altfuse.errors import ParameterError
from altfuse.fuse.base import FUSED, NONE, SINGLE, FusionResult
from altfuse.model import FloatArray

#: Process noise defaults (power spectral densities): white acceleration [m^2/s^3] with and
#: without the accelerometer, bias random walk [m^2/s^5], offset random walks [m^2/s] for GPS and
#: barometer, ground-height random walk under a moving vehicle [m^2/s].
Q_ACCEL = 0.05
Q_ACCEL_NO_IMU = 2.0
Q_BIAS = 1e-5
Q_OFFSET = {"gps": 0.02, "baro": 0.002, "rangefinder": 0.3}
DEFAULT_GATE = 5.0
#: EM iterations (each a forward and a backward pass) after the first pass.
EM_PASSES = 4
Q_STATE_MIN, Q_STATE_MAX = 1e-5, 1.0
_MIN_SIGMA_M = 0.01


def measurement_sigma(z: FloatArray) -> float:
    """Noise of one sensor [m] from the median absolute second difference of its samples."""
    if z.size < 5:
        return 1.0
    d2 = np.diff(z, 2)
    return max(1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0), _MIN_SIGMA_M)


def offset_noise(z: FloatArray, dt: float, lags_s: tuple[float, float] = (5.0, 30.0)) -> FloatArray:
    """Random-walk densities of the sensors' offsets [m^2/s], by method of moments.

    Two sensors' difference is ``c_i - c_j`` plus white noise: the variance of its increments
    over a lag ``L`` is ``(q_i + q_j) L + const``, so two lags give ``q_i + q_j`` free of the
    noise; the pairs give each ``q_i`` (non-negative least squares; equal halves for two sensors).
    """
    m = z.shape[1]
    default = np.full(m, np.nan)
    if m < 2:
        return default
    l1, l2 = (max(1, round(lag / dt)) for lag in lags_s)
    rows, rhs = [], []
    for i in range(m):
        for j in range(i + 1, m):
            d = z[:, i] - z[:, j]
            with np.errstate(invalid="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # no overlap: NaN, handled
                v1 = np.nanmean((d[l1:] - d[:-l1]) ** 2) if d.size > l1 else np.nan
                v2 = np.nanmean((d[l2:] - d[:-l2]) ** 2) if d.size > l2 else np.nan
            if np.isfinite(v1) and np.isfinite(v2):
                row = np.zeros(m)
                row[[i, j]] = 1.0
                rows.append(row)
                rhs.append(max((v2 - v1) / ((l2 - l1) * dt), 0.0))
    if not rows:
        return default
    a, b = np.array(rows), np.array(rhs)
    if m == 2:
        return np.full(2, b[0] / 2)
    q = np.linalg.lstsq(a, b, rcond=None)[0]
    return np.asarray(np.maximum(q, 0.0))


def _events(
    samples: Sequence[tuple[FloatArray, FloatArray]], ticks: FloatArray
) -> tuple[FloatArray, np.ndarray, FloatArray]:
    """All sample and tick times in order: (time, sensor index or -1 for a tick, value)."""
    times = [ticks] + [s[0] for s in samples]
    which = [np.full(ticks.size, -1)] + [np.full(s[0].size, i) for i, s in enumerate(samples)]
    values = [np.full(ticks.size, np.nan)] + [s[1] for s in samples]
    t = np.concatenate(times)
    who = np.concatenate(which)
    # at equal times the tick comes last: it reports the state after its instant's samples
    order = np.lexsort((who == -1, t))
    return t[order], who[order], np.concatenate(values)[order]


def _mean_accel(accel: tuple[FloatArray, FloatArray] | None, t: FloatArray) -> FloatArray:
    """The mean of ``a`` over each interval between consecutive event times (0 without IMU)."""
    if accel is None or accel[0].size < 2:
        return np.zeros(t.size)
    ta, a = accel
    order = np.argsort(ta, kind="stable")
    ta, a = ta[order], a[order]
    # cumulative trapezoid integral of a, evaluated at the event times (flat outside the IMU span)
    integral = np.concatenate(([0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * np.diff(ta))))
    at_events = np.interp(t, ta, integral)
    dt = np.diff(t, prepend=t[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.diff(at_events, prepend=at_events[0]) / dt
    mean[~np.isfinite(mean)] = 0.0
    outside = (t < ta[0]) | (t > ta[-1])
    mean[outside] = 0.0
    return np.asarray(mean)


def _transition(dt: float, n: int, use_bias: bool) -> FloatArray:
    """F over ``dt``: h += v dt - b dt^2/2, v += -b dt; the rest random walks (identity)."""
    f = np.eye(n)
    f[0, 1] = dt
    if use_bias:
        f[0, 2], f[1, 2] = -0.5 * dt * dt, -dt
    return f


def _run(
    t: FloatArray,
    who: np.ndarray,
    z: FloatArray,
    a: FloatArray,
    sign: FloatArray,
    r: FloatArray,
    q_accel: float,
    q_state: FloatArray,
    use_bias: bool,
    gate: float,
    x0: FloatArray,
) -> dict[str, np.ndarray]:
    """Forward filter and RTS pass over the events; the smoothed states and their diagnostics.

    ``sign`` is +1 for a sensor measuring ``h + c_i``, -1 for one measuring ``h - c_i``.
    """
    m = sign.size
    n = 3 + m
    count = t.size
    xp = np.zeros((count, n))
    pp = np.zeros((count, n, n))
    xf = np.zeros((count, n))
    pf = np.zeros((count, n, n))
    gain_h = np.zeros(count)
    accepted = np.zeros(count, dtype=bool)
    x = x0.copy()
    # without the accelerometer the bias is inert: a tiny fixed variance keeps P invertible
    p = np.diag([10.0**2, 3.0**2, 0.1**2 if use_bias else 1e-9] + [1.0**2] * m)
    previous = t[0]
    for k in range(count):
        dt = t[k] - previous
        previous = t[k]
        if dt > 0:
            f = _transition(dt, n, use_bias)
            x = f @ x
            x[0] += 0.5 * a[k] * dt * dt
            x[1] += a[k] * dt
            q = np.zeros((n, n))
            q[0, 0], q[0, 1], q[1, 1] = q_accel * dt**3 / 3, q_accel * dt**2 / 2, q_accel * dt
            q[1, 0] = q[0, 1]
            q[2, 2] = Q_BIAS * dt if use_bias else 0.0
            q[3:, 3:] = np.diag(q_state * dt)
            p = f @ p @ f.T + q
        xp[k], pp[k] = x, p
        i = who[k]
        if i >= 0:
            # H: h plus the sensor's offset (GPS, baro) or minus its ground height (rangefinder)
            hrow = np.zeros(n)
            hrow[0], hrow[3 + i] = 1.0, sign[i]
            y = z[k] - hrow @ x
            ph = p @ hrow
            s = hrow @ ph + r[i]
            if y * y <= gate * gate * s:  # innovation gate
                kg = ph / s
                x = x + kg * y
                p = p - np.outer(kg, ph)
                gain_h[k] = abs(kg[0])
                accepted[k] = True
        xf[k], pf[k] = x, p
    # Rauch-Tung-Striebel: x_s(k) = x_f(k) + C (x_s(k+1) - x_p(k+1)), C = P_f F^T P_p(k+1)^-1
    xs, ps = xf.copy(), pf.copy()
    for k in range(count - 2, -1, -1):
        f = _transition(t[k + 1] - t[k], n, use_bias)
        c = np.linalg.solve(pp[k + 1].T, (pf[k] @ f.T).T).T
        xs[k] = xf[k] + c @ (xs[k + 1] - xp[k + 1])
        ps[k] = pf[k] + c @ (ps[k + 1] - pp[k + 1]) @ c.T
    return {"x": xs, "p": ps, "gain_h": gain_h, "accepted": accepted}


def fuse_smoother(
    z: FloatArray,
    *,
    samples: Sequence[tuple[FloatArray, FloatArray]],
    kinds: Sequence[str],
    names: Sequence[str],
    t: FloatArray,
    accel: tuple[FloatArray, FloatArray] | None = None,
    accel_noise: float | None = None,
    sigmas: dict[str, float] | None = None,
    gate: float = DEFAULT_GATE,
) -> FusionResult:
    """Kalman filter + RTS smoother over the whole flight (see the module doc).

    Parameters
    ----------
    z
        The sensors on the clock (T, n): used only to mark the ticks where no sensor is valid.
    samples
        Each sensor's own samples (time [s], height above take-off [m]), in ``z``'s order.
    kinds
        Each sensor's kind: ``gps``, ``baro`` or ``rangefinder``.
    t
        The clock [s] at which the result is reported.
    accel
        Earth-frame vertical acceleration samples (time [s], [m/s^2]) with the at-rest reading
        removed; ``None``: the altitude-only random-walk model.
    names
        Each sensor's name, for ``sigmas``.
    accel_noise
        White acceleration PSD [m^2/s^3]; default ``Q_ACCEL``, or ``Q_ACCEL_NO_IMU`` without IMU.
    sigmas
        Measurement noise [m] by sensor name; the others are estimated from the log (second
        differences, then EM).
    gate
        Innovation gate [standard deviations].
    """
    if not (math.isfinite(gate) and gate > 0):
        raise ParameterError(f"--gate must be a positive number of sigmas, got {gate}")
    if accel_noise is not None and not (math.isfinite(accel_noise) and accel_noise > 0):
        raise ParameterError(f"--accel-noise must be positive (m^2/s^3), got {accel_noise}")
    m = len(samples)
    use_imu = accel is not None and accel[0].size >= 2
    q_accel = accel_noise if accel_noise is not None else (Q_ACCEL if use_imu else Q_ACCEL_NO_IMU)
    given = dict(sigmas or {})
    unknown = sorted(set(given) - set(names))
    if unknown:
        raise ParameterError(f"--sigma names no sensor of this log: {', '.join(unknown)}")
    if any(not (math.isfinite(v) and v > 0) for v in given.values()):
        raise ParameterError("--sigma values must be positive numbers of metres")
    sigma = np.array(
        [given.get(name, measurement_sigma(s[1])) for name, s in zip(names, samples, strict=True)]
    )
    fixed = np.array([name in given for name in names])
    times, who, values = _events(samples, t)
    a = _mean_accel(accel if use_imu else None, times)
    first = [s[1][0] for s in samples if s[1].size]
    x0 = np.zeros(3 + m)
    x0[0] = float(np.median(first)) if first else 0.0
    r = sigma**2
    moments = offset_noise(z, float(np.median(np.diff(t))) if t.size > 1 else 0.1)
    q_state = np.array(
        [
            Q_OFFSET.get(k, 0.02) if not np.isfinite(q) else q
            for k, q in zip(kinds, moments, strict=True)
        ]
    )
    q_state = np.clip(q_state, Q_STATE_MIN, Q_STATE_MAX)
    sign = np.array([-1.0 if k == "rangefinder" else 1.0 for k in kinds])
    for npass in range(EM_PASSES + 1):
        out = _run(times, who, values, a, sign, r, q_accel, q_state, use_imu, gate, x0)
        if npass == EM_PASSES:
            break
        # EM, M-step: the measurement variances from the smoothed residuals
        xs, ps = out["x"], out["p"]
        for i in range(m):
            mine = (who == i) & out["accepted"]
            if not mine.any():
                continue
            resid = values[mine] - xs[mine, 0] - sign[i] * xs[mine, 3 + i]
            var_h = ps[mine, 0, 0] + ps[mine, 3 + i, 3 + i] + 2 * sign[i] * ps[mine, 0, 3 + i]
            if not fixed[i]:
                r[i] = max(float(np.mean(resid**2 + var_h)), _MIN_SIGMA_M**2)

    tick = who == -1
    xs, ps = out["x"][tick], out["p"][tick]
    # contributions: each sensor's share of the gain on h carried since the previous tick
    idx_tick = np.flatnonzero(tick)
    cum = np.zeros((times.size + 1, m))
    for i in range(m):
        cum[1:, i] = np.cumsum(np.where(who == i, out["gain_h"], 0.0))
    bounds = np.concatenate(([0], idx_tick[:-1] + 1))
    share = cum[idx_tick + 1] - cum[bounds]
    valid = np.asarray(np.isfinite(z).any(axis=1))
    total = share.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        weights = np.where(total > 0, share / total, np.nan)
    # a tick with no update since the previous one keeps the previous contributions
    for k in range(1, t.size):
        if not np.isfinite(weights[k]).all():
            weights[k] = weights[k - 1]
    weights = np.where(valid[:, None], np.nan_to_num(weights, nan=1.0 / m), np.nan)
    fused = np.where(valid, xs[:, 0], np.nan)
    rejected = {
        f"rejected_{name}": int(((who == i) & ~out["accepted"]).sum())
        for i, name in enumerate(names)
    }
    n_valid = np.isfinite(z).sum(axis=1)
    status = np.where(n_valid == 1, SINGLE, np.where(valid, FUSED, NONE))
    return FusionResult(
        method="smoother",
        fused=fused,
        weights=weights,
        status=status,
        traces={"offset": xs[:, 3:]},
        tick_traces={
            "fused_std": np.where(valid, np.sqrt(np.maximum(ps[:, 0, 0], 0.0)), np.nan),
            "velocity": xs[:, 1],
            "accel_bias": xs[:, 2],
        },
        params={
            "model": "accelerometer-driven" if use_imu else "altitude-only random walk (no IMU)",
            "accel_noise_m2_s3": q_accel,
            "gate_sigma": gate,
            **{f"sigma_{name}_m": float(math.sqrt(r[i])) for i, name in enumerate(names)},
            **{f"q_offset_{name}_m2_s": float(q_state[i]) for i, name in enumerate(names)},
            **rejected,
        },
    )
