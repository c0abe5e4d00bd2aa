"""The smoother's events: every sample and clock tick in time order, the accelerometer averaged
over the intervals between them, and the sensors' contributions read back at the ticks."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from altfuse.model import FloatArray, Samples


def merge_events(
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


def interval_mean(series: Samples, t: FloatArray) -> FloatArray:
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


def contributions(
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
