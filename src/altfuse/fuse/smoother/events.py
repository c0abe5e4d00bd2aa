"""The smoother's events: every sample and clock tick in time order, the accelerometer averaged
over the intervals between them, and the sensors' contributions read back at the ticks."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from altfuse.model import FloatArray, Samples

#: The series of an event that is no height sample: a clock tick, a GPS's vertical velocity.
TICK = -1
VELOCITY = -2


def merge_events(
    samples: Sequence[Samples], ticks: FloatArray, velocity: Samples | None = None
) -> tuple[FloatArray, np.ndarray, FloatArray, np.ndarray]:
    """All sample and tick times in order: (time, sensor index, TICK for a tick or VELOCITY for
    a vertical-velocity sample, value, and each event's position in its series)."""
    series = [(TICK, Samples(ticks, np.full(ticks.size, np.nan)))]
    series += list(enumerate(samples))
    if velocity is not None:
        series.append((VELOCITY, velocity))
    times = [s.t for _, s in series]
    which = [np.full(s.t.size, i) for i, s in series]
    values = [s.value for _, s in series]
    position = [np.arange(s.t.size) for _, s in series]
    t = np.concatenate(times)
    who = np.concatenate(which)
    # at equal times the tick comes last: it reports the state after its instant's samples
    order = np.lexsort((who == TICK, t))
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
    # a tick with no update since the previous one keeps the previous contributions: each
    # tick takes the row of the last tick up to it whose row is whole (the first tick's own
    # row if none is)
    whole = np.isfinite(weights).all(axis=1)
    weights = weights[np.maximum.accumulate(np.where(whole, np.arange(whole.size), 0))]
    # a sensor absent from the clock at a tick (a gap longer than --max-gap) gets no weight there,
    # though its samples near the gap still informed the smoother
    present = np.isfinite(z)
    weights = np.where(present, np.nan_to_num(weights), 0.0)
    total = weights.sum(axis=1, keepdims=True)
    even = present / np.maximum(present.sum(axis=1, keepdims=True), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        weights = np.where(total > 0, weights / total, even)
    return np.asarray(np.where(valid[:, None], weights, np.nan)), valid
