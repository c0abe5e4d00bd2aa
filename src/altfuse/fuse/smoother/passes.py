"""The smoother's passes over the events: the forward Kalman filter, with its innovation gate and
lockout release, and the Rauch-Tung-Striebel backward pass (steps from :mod:`.kalman`), each one
compiled loop over the events (:mod:`.compiled`)."""

from __future__ import annotations

import math

import numpy as np

from altfuse.fuse.smoother.compiled import compiled
from altfuse.fuse.smoother.kalman import (
    innovation,
    predict,
    predict_covariance,
    rts_step,
    scratch,
    update,
)
from altfuse.fuse.smoother.model import (
    Events,
    Layout,
    hold_still,
    measurement_matrix,
    prior,
    process_noise,
    transition,
)
from altfuse.model import FloatArray

#: Longest time [s] every sensor's samples may be rejected before the estimate is let loose,
#: and a rangefinder's alone before its ground height is.
LOCKOUT_S = 2.0
#: ... and when two sensors are rejected on the same side: they agree against the estimate.
AGREED_LOCKOUT_S = 0.5


def run(ev: Events, r: FloatArray, layout: Layout, smooth: bool = True) -> dict[str, np.ndarray]:
    """Forward filter and (if ``smooth``) RTS pass over the events: the states and diagnostics.

    ``r`` is each event's measurement variance. Also each accepted sample's log-likelihood (its
    innovation's density; NaN elsewhere): the evidence by which :func:`evidence_gain` compares two
    models.
    """
    x0, p0 = prior(ev, layout)
    dynamics = _dynamics(ev, layout)
    xp, xf, pf, released, gain_h, accepted, loglik, nu = _forward(
        _measured(ev, r, layout), dynamics, ev.still.astype(np.bool_), ev.gate, (x0, p0), True
    )
    if smooth:
        _backward(ev.t, (xp, xf, pf, released, ev.who.astype(np.int64)), dynamics)
    return {
        "x": xf, "p": pf, "gain_h": gain_h, "accepted": accepted, "loglik": loglik, "nu": nu
    }  # fmt: skip


def likelihood(ev: Events, r: FloatArray, layout: Layout) -> dict[str, np.ndarray]:
    """The forward filter's verdicts alone: which samples it accepted and their log-likelihood
    (:func:`run` without keeping any covariance: a flight's worth is hundreds of megabytes)."""
    _, _, _, _, _, accepted, loglik, _ = _forward(
        _measured(ev, r, layout),
        _dynamics(ev, layout),
        ev.still.astype(np.bool_),
        ev.gate,
        prior(ev, layout),
        False,
    )
    return {"accepted": accepted, "loglik": loglik}


def _measured(
    ev: Events, r: FloatArray, layout: Layout
) -> tuple[FloatArray, np.ndarray, FloatArray, FloatArray, FloatArray]:
    """The events' times, series, values, variances and rows of H, as the kernels take them."""
    h = measurement_matrix(layout, ev.who)
    return ev.t, ev.who.astype(np.int64), ev.z, np.asarray(r, dtype=np.float64), h


def _dynamics(
    ev: Events, layout: Layout
) -> tuple[FloatArray, FloatArray, FloatArray, np.ndarray, bool]:
    """The events' accelerations and process-noise densities, as the kernels take them."""
    q_state = np.ascontiguousarray(ev.q_state, dtype=np.float64)
    return ev.a, ev.q_accel, q_state, layout.drift_pairs.astype(np.int64), ev.use_bias


@compiled
def _forward(
    measured: tuple[FloatArray, np.ndarray, FloatArray, FloatArray, FloatArray],
    dynamics: tuple[FloatArray, FloatArray, FloatArray, np.ndarray, bool],
    still: np.ndarray,
    gate: float,
    start: tuple[FloatArray, FloatArray],
    keep: bool,
) -> tuple[
    FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, np.ndarray, FloatArray, FloatArray
]:
    """The forward filter: each event's prior state, posterior state and covariance, what the
    lockout release added to the prior's (h, v) variances there (and to the sample's sensor
    state, where a rangefinder's ground height was let loose), each sample's gain on h,
    whether it passed the gate, its log-likelihood and its normalised innovation
    ``y / sqrt(S)``. The priors' covariances are not kept (a flight's worth is hundreds of
    megabytes): :func:`_backward` makes them again.

    ``measured``: the events' times, series (-1 a tick), values, variances and rows of H;
    ``dynamics``: the mean acceleration over the interval ending at each event, the white
    acceleration density there, the sensor states' densities, the drifting offsets' (offset,
    rate) state pairs and whether the bias is a state; ``start``: the prior; ``keep``: whether
    to keep the states and covariances (else one slot, overwritten).
    """
    t, who, z, r, h = measured
    a, q_accel, q_state, drifts, use_bias = dynamics
    x, p = start[0].copy(), start[1].copy()
    count, n = h.shape
    kept = count if keep else 1
    xp = np.zeros((kept, n))
    released = np.zeros((count, 3))  # added to the prior's h, v and the sample's sensor state
    sensor_accepted = np.full(n, np.nan)  # per state: its sensor's last accepted sample [s]
    sensor_r = np.full(n, np.inf)  # ... and that sample's variance
    refused = np.full((n, 2), np.nan)  # per state: its sensor's last rejection [s] and side
    xf = np.zeros((kept, n))
    pf = np.zeros((kept, n, n))
    gain_h = np.zeros(count)
    accepted = np.zeros(count, dtype=np.bool_)
    loglik = np.full(count, np.nan)
    nu = np.full(count, np.nan)
    f, q, u = np.eye(n), np.zeros((n, n)), np.zeros(n)
    work = scratch(n)
    ph = work[4]
    y = s = 0.0
    previous = last_accepted = t[0]
    for k in range(count):
        dt = t[k] - previous
        previous = t[k]
        if dt > 0:
            # the accelerometer as the control input: B u = [a dt^2 / 2, a dt, 0, ...]
            u[0], u[1] = 0.5 * a[k] * dt * dt, a[k] * dt
            transition(f, dt, use_bias, drifts)
            process_noise(q, dt, q_accel[k], q_state[k], use_bias, drifts)
            predict(x, p, f, q, u, work)
        i = who[k]
        if i >= 0:
            y, s = innovation(x, p, z[k], h[k], r[k], ph)
            if math.isnan(sensor_accepted[3 + i]):
                sensor_accepted[3 + i] = t[k]
            if y * y > gate * gate * s:  # shut: has the estimate, or a ground, gone astray?
                seen = (t[k], r[k], h[k, 3 + i], last_accepted, sensor_accepted, sensor_r)
                if _release(k, 3 + i, y, (seen, refused), p, released):
                    y, s = innovation(x, p, z[k], h[k], r[k], ph)
                refused[3 + i, 0], refused[3 + i, 1] = t[k], math.copysign(1.0, y)
            nu[k] = y / math.sqrt(s)
        xp[k if keep else 0] = x
        # the innovation gate: |y| <= gate sqrt(S)
        if i >= 0 and y * y <= gate * gate * s:
            gain_h[k] = abs(update(x, p, y, s, ph))
            accepted[k] = True
            last_accepted = sensor_accepted[3 + i] = t[k]
            sensor_r[3 + i] = r[k]
            # log N(y; 0, S)
            loglik[k] = -0.5 * (math.log(2 * math.pi * s) + y * y / s)
        if still[k]:
            hold_still(x, p)
        xf[k if keep else 0], pf[k if keep else 0] = x, p
    return xp, xf, pf, released, gain_h, accepted, loglik, nu


@compiled
def _agreed(c: int, y: float, last_accepted: float, refused: FloatArray) -> bool:
    """Whether another sensor than state ``c``'s was rejected on the side of the innovation
    ``y`` since the last accepted sample."""
    for j in range(3, refused.shape[0]):
        if j != c and refused[j, 0] > last_accepted and refused[j, 1] * y > 0.0:
            return True
    return False


@compiled
def _release(
    k: int,
    c: int,
    y: float,
    seen: tuple[tuple[float, float, float, float, FloatArray, FloatArray], FloatArray],
    p: FloatArray,
    released: FloatArray,
) -> bool:
    """Sample ``k`` of the sensor with state ``c`` fails the gate by the innovation ``y``: let
    loose what has gone astray, in place on ``p`` and ``released[k]``, and say whether anything
    was. ``seen``: the sample's time and variance, its row of H at ``c``, the last accepted
    sample's time, per state its sensor's last accepted sample [s] and that one's variance;
    and per state its sensor's last rejection [s] and its side (the innovation's sign)."""
    (now, r, sign, last_accepted, sensor_accepted, sensor_r), refused = seen
    y2 = y * y
    waited = now - last_accepted
    if waited > LOCKOUT_S or (waited > AGREED_LOCKOUT_S and _agreed(c, y, last_accepted, refused)):
        # no sample of any sensor passed the gate for LOCKOUT_S, or for AGREED_LOCKOUT_S where
        # two sensors failed it on one side: the estimate, not every sensor, has gone astray
        # (ArduPilot's EKF3 resets its height after 5 s); its height and velocity become as
        # uncertain as this sample says. Two sensors agreeing against a confident estimate
        # for 2.5 s left it 1.4 m under both after a PX4 simulator's landing (the touchdown
        # absent from the logged IMU)
        released[k, 0], released[k, 1] = y2, y2 / LOCKOUT_S**2
        p[0, 0] += released[k, 0]
        p[1, 1] += released[k, 1]
        return True
    if sign < 0.0 and now - sensor_accepted[c] > LOCKOUT_S:
        # a rangefinder alone has failed the gate for LOCKOUT_S while a sensor at least as
        # precise passed (the estimate holds): the ground under it has stepped (an edge, a
        # roof); its ground height, not h, becomes as uncertain as this sample says. Where
        # only less precise sensors held the estimate, a rangefinder back from a dropout
        # followed the estimate's drift instead of correcting it (Paper A: 0.138 -> 0.170 m).
        for j in range(3, sensor_r.size):
            if j != c and now - sensor_accepted[j] <= LOCKOUT_S and sensor_r[j] <= r:
                released[k, 2] = y2
                p[c, c] += y2
                return True
    return False


@compiled
def _backward(
    t: FloatArray,
    filtered: tuple[FloatArray, FloatArray, FloatArray, FloatArray, np.ndarray],
    dynamics: tuple[FloatArray, FloatArray, FloatArray, np.ndarray, bool],
) -> None:
    """The Rauch-Tung-Striebel pass (:func:`.kalman.rts_step`) back over the filtered events, in
    place: the filtered states and covariances become the smoothed ones. Each prior covariance
    is made again from the filtered one before it, as :func:`_forward` made it."""
    xp, xs, ps, released, who = filtered
    _, q_accel, q_state, drifts, use_bias = dynamics
    n = xs.shape[1]
    f, q, pp = np.eye(n), np.zeros((n, n)), np.zeros((n, n))
    work = scratch(n)
    for k in range(t.size - 2, -1, -1):
        dt = t[k + 1] - t[k]
        transition(f, dt, use_bias, drifts)  # the identity where dt is 0
        pp[:] = ps[k]  # still the filtered covariance at k
        if dt > 0:
            process_noise(q, dt, q_accel[k + 1], q_state[k + 1], use_bias, drifts)
            predict_covariance(pp, f, q, work)
        pp[0, 0] += released[k + 1, 0]
        pp[1, 1] += released[k + 1, 1]
        if released[k + 1, 2] > 0.0:
            pp[3 + who[k + 1], 3 + who[k + 1]] += released[k + 1, 2]
        rts_step((xs[k], ps[k]), (xp[k + 1], pp), (xs[k + 1], ps[k + 1]), f, work)
