"""The smoother's passes over the events: the forward Kalman filter, with its innovation gate and
lockout release, and the Rauch-Tung-Striebel backward pass (steps from :mod:`.kalman`)."""

from __future__ import annotations

import math

import numpy as np

from altfuse.fuse.smoother.kalman import innovation, predict, rts_step, update
from altfuse.fuse.smoother.model import (
    Events,
    Layout,
    hold_still,
    measurement_row,
    prior,
    process_noise,
    transition,
)
from altfuse.model import FloatArray

#: Longest time [s] every sensor's samples may be rejected before the estimate is let loose.
LOCKOUT_S = 2.0


def run(ev: Events, r: FloatArray, layout: Layout, smooth: bool = True) -> dict[str, np.ndarray]:
    """Forward filter and (if ``smooth``) RTS pass over the events: the states and diagnostics.

    ``r`` is each event's measurement variance. Also each accepted sample's log-likelihood (its
    innovation's density; NaN elsewhere): the evidence by which :func:`evidence_gain` compares two
    models.
    """
    drifts, n = layout.drift_pairs, layout.n
    count = ev.t.size
    loglik = np.full(count, np.nan)
    xp = np.zeros((count, n))
    pp = np.zeros((count, n, n))
    xf = np.zeros((count, n))
    pf = np.zeros((count, n, n))
    gain_h = np.zeros(count)
    accepted = np.zeros(count, dtype=bool)
    x, p = prior(ev, layout)
    previous = last_accepted = ev.t[0]
    for k in range(count):
        dt = ev.t[k] - previous
        previous = ev.t[k]
        if dt > 0:
            # the accelerometer as the control input: B u = [a dt^2 / 2, a dt, 0, ...]
            u = np.zeros(n)
            u[0], u[1] = 0.5 * ev.a[k] * dt * dt, ev.a[k] * dt
            f = transition(dt, n, ev.use_bias, drifts)
            x, p = predict(x, p, f, process_noise(ev, k, dt, n, drifts), u)
        i = ev.who[k]
        if i >= 0:
            hrow = measurement_row(layout, i, k)
            y, s, ph = innovation(x, p, ev.z[k], hrow, r[k])
            if ev.t[k] - last_accepted > LOCKOUT_S and y * y > ev.gate * ev.gate * s:
                # no sample of any sensor passed the gate for LOCKOUT_S: the estimate, not
                # every sensor, has gone astray (ArduPilot's EKF3 resets its height after
                # 5 s); its height and velocity become as uncertain as this sample says
                p = p.copy()
                p[0, 0] += y * y
                p[1, 1] += (y / LOCKOUT_S) ** 2
                y, s, ph = innovation(x, p, ev.z[k], hrow, r[k])
        xp[k], pp[k] = x, p
        # the innovation gate: |y| <= gate sqrt(S)
        if i >= 0 and y * y <= ev.gate * ev.gate * s:
            x, p, kg = update(x, p, y, s, ph)
            gain_h[k] = abs(kg[0])
            accepted[k] = True
            last_accepted = ev.t[k]
            # log N(y; 0, S)
            loglik[k] = -0.5 * (math.log(2 * math.pi * s) + y * y / s)
        if ev.still[k]:
            x, p = hold_still(x, p)
        xf[k], pf[k] = x, p
    if smooth:
        xf, pf = rts(ev, layout, (xp, pp, xf, pf))
    return {"x": xf, "p": pf, "gain_h": gain_h, "accepted": accepted, "loglik": loglik}


def rts(
    ev: Events, layout: Layout, filtered: tuple[FloatArray, FloatArray, FloatArray, FloatArray]
) -> tuple[FloatArray, FloatArray]:
    """The Rauch-Tung-Striebel pass (:func:`.kalman.rts_step`) back over the filtered events."""
    xp, pp, xf, pf = filtered
    xs, ps = xf.copy(), pf.copy()
    for k in range(ev.t.size - 2, -1, -1):
        f = transition(ev.t[k + 1] - ev.t[k], layout.n, ev.use_bias, layout.drift_pairs)
        xs[k], ps[k] = rts_step((xf[k], pf[k]), (xp[k + 1], pp[k + 1]), (xs[k + 1], ps[k + 1]), f)
    return xs, ps
