"""The smoother's Kalman and Rauch-Tung-Striebel passes against filterpy's (issue 15, item 8).

A linear-Gaussian toy with the smoother's own state layout (height, velocity, accelerometer
bias, two sensor offsets, a barometer's scale error and drift rate), irregular event times, one
scalar measurement of either sensor per event or none (a clock tick), no gate:
:func:`passes.run` must give filterpy's ``KalmanFilter.batch_filter`` and ``rts_smoother`` to
1e-9.
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter, rts_smoother

from altfuse.fuse.smoother.model import (
    Events,
    Layout,
    Regressor,
    prior,
    process_noise,
    transition,
)
from altfuse.fuse.smoother.passes import run

M = 2  # sensors: a GPS and a barometer, the barometer with a drift rate


def toy(seed: int, accel: bool) -> tuple[Events, Layout, np.ndarray]:
    """Events of a simulated flight, the layout, and each event's measurement variance."""
    rng = np.random.default_rng(seed)
    count = 300
    t = np.cumsum(rng.uniform(0.01, 0.2, count))
    t[5] = t[4]  # two events at one instant: no prediction between them
    who = rng.integers(-1, M, count)
    truth = 3 * np.sin(t / 4)
    r = rng.uniform(0.05, 0.5, count) ** 2
    z = np.where(who >= 0, truth + (who == 1) * 0.3 + rng.normal(0, np.sqrt(r)), np.nan)
    a = -3 / 16 * np.sin(t / 4) + rng.normal(0, 0.1, count) if accel else np.zeros(count)
    q_state = np.tile([0.01, 1e-4], (count, 1))
    still = np.zeros(count, dtype=bool)
    q_accel = np.full(count, 0.05)
    events = Events(t, who, z, a, q_state, still, q_accel, True, np.inf, float(z[who >= 0][0]))
    scale = Regressor("scale", 1, np.where(who == 1, truth, 0.0), 0.02)
    layout = Layout(np.ones(M), (scale,), drifting=(1,))
    return events, layout, r


def filterpy_passes(
    ev: Events, layout: Layout, r: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """filterpy's filtered and smoothed means and covariances over the same events."""
    n, drifts = layout.n, layout.drift_pairs
    dts = np.diff(ev.t, prepend=ev.t[0])
    qa = ev.q_accel
    fs, qs = [], []
    for k, dt in enumerate(dts):
        f, q = np.eye(n), np.zeros((n, n))
        transition(f, dt, ev.use_bias, drifts)
        process_noise(q, dt, qa[k], ev.q_state[k], True, drifts)
        fs.append(f)
        qs.append(q)
    us = [np.array([[0.5 * ev.a[k] * dt * dt], [ev.a[k] * dt]]) for k, dt in enumerate(dts)]
    bs = [np.vstack([np.eye(2), np.zeros((n - 2, 2))])] * ev.t.size
    hs = []
    for k, i in enumerate(ev.who):
        row = np.zeros((1, n))
        row[0, 0] = 1.0
        if i >= 0:
            row[0, 3 + i] = 1.0
        if i == 1:  # the barometer's scale error, times its height
            row[0, 3 + M] = layout.regressors[0].coef[k]
        hs.append(row)
    zs = [np.array([z]) if i >= 0 else None for i, z in zip(ev.who, ev.z, strict=True)]
    kf = KalmanFilter(dim_x=n, dim_z=1, dim_u=2)
    x0, kf.P = prior(ev, layout)
    kf.x = x0.reshape(n, 1)
    rs = [np.array([[v]]) for v in r]
    xf, pf, _, _ = kf.batch_filter(zs, Fs=fs, Qs=qs, Hs=hs, Rs=rs, Bs=bs, us=us)
    xf = xf.reshape(-1, n)
    # filterpy's smoother steps k -> k + 1 with Fs[k] and no control input
    xs, ps, _, _ = rts_smoother(xf.copy(), pf.copy(), [*fs[1:], np.eye(n)], [*qs[1:], qs[0]])
    return xf, pf, xs, ps


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_forward_filter_is_filterpys_kalman_filter(seed: int) -> None:
    ev, layout, r = toy(seed, accel=True)
    ours = run(ev, r, layout, smooth=False)
    xf, pf, _, _ = filterpy_passes(ev, layout, r)
    assert ours["accepted"][ev.who >= 0].all()
    np.testing.assert_allclose(ours["x"], xf, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours["p"], pf, rtol=0, atol=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_smoother_is_filterpys_rts_smoother(seed: int) -> None:
    # filterpy's rts_smoother takes no control input: the toy's accelerometer reads 0
    ev, layout, r = toy(seed, accel=False)
    ours = run(ev, r, layout)
    _, _, xs, ps = filterpy_passes(ev, layout, r)
    np.testing.assert_allclose(ours["x"], xs, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours["p"], ps, rtol=0, atol=1e-9)
    # and smoothing did something: the first state moved from its filtered value
    filtered = run(ev, r, layout, smooth=False)
    assert np.abs(ours["x"][0] - filtered["x"][0]).max() > 1e-3
