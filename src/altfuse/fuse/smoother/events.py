"""The smoother's events: every sample and clock tick in time order, the accelerometer averaged
over the intervals between them, and the sensors' contributions read back at the ticks."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from altfuse.metrics import cumulative_integral
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


def model_intervals(model: np.ndarray) -> np.ndarray:
    """Per event, the event of ``model`` (a mask) whose interval, from the model event before
    it, holds it: itself for a model event, else the next model event (the last one, after
    them all). An output tick between two model events splits their interval and takes its
    acceleration and noise densities: it moves no state."""
    n = model.size
    mine = np.where(model, np.arange(n), n)
    following = np.minimum.accumulate(mine[::-1])[::-1]
    last = int(np.flatnonzero(model)[-1]) if model.any() else n - 1
    return np.asarray(np.where(following == n, last, following))


def on_every_event(values: FloatArray, model: np.ndarray) -> FloatArray:
    """``values``, one per event of ``model`` (a mask), given to every event: each other one
    its interval's (:func:`model_intervals`)."""
    return np.asarray(values[np.cumsum(model)[model_intervals(model)] - 1])


def interval_mean(series: Samples, t: FloatArray) -> FloatArray:
    """The mean of a sampled signal over each interval between consecutive times ``t`` (the
    samples integrated exactly, trapezoids); NaN where ``t`` leaves the samples' span."""
    ts, v = series
    order = np.argsort(ts, kind="stable")
    ts, v = ts[order], v[order]
    integral = cumulative_integral(ts, v)
    at_events = np.interp(t, ts, integral)
    dt = np.diff(t, prepend=t[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.diff(at_events, prepend=at_events[0]) / dt
    mean[~np.isfinite(mean) | (t < ts[0]) | (t > ts[-1])] = np.nan
    return np.asarray(mean)


def contributions(
    events: tuple[FloatArray, np.ndarray, FloatArray], ticks: FloatArray, z: FloatArray, dt_s: float
) -> tuple[FloatArray, np.ndarray]:
    """Each sensor's share per tick of the gain on h its accepted samples carried around the
    tick (summing to 1 over the sensors present at the tick), and which ticks have a sensor.

    ``events`` are the events' times, series (:func:`merge_events`) and gains on h; ``ticks``
    and ``z`` the output's clock and the sensors' heights on it. The gains
    are summed under a triangle centred on the tick, its half-width the longest of the
    sensors' median sampling intervals (at least the tick ``dt_s``), so that each sensor's
    sum holds whole cycles of every other's: from the samples since the previous tick, a GPS
    sampled at 5 Hz beside a barometer at 10 Hz took most of the weight at the ticks with its
    sample and none at the others (on the shared logs the weights swung by more than 0.5 from
    one tick to the next on 56-99 % of the ticks of 17 logs of 34)."""
    times, who, gain_h = events
    mine = [who == i for i in range(z.shape[1])]
    steps = [float(np.median(np.diff(times[m]))) for m in mine if m.sum() > 1]
    width = max([dt_s, *steps])
    rate = np.zeros((ticks.size, z.shape[1]))
    for i, m in enumerate(mine):
        if m.any():
            ts = times[m]
            rate[:, i] = _triangle_sums(ts - ts[0], gain_h[m], ticks - ts[0], width)
    valid = np.asarray(np.isfinite(z).any(axis=1))
    total = rate.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        weights = np.where(total > 0, rate / total, np.nan)
    # a tick no sample reaches keeps the previous contributions: each tick takes the row of
    # the last tick up to it whose row is whole (the first tick's own row if none is)
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


def _triangle_sums(t: FloatArray, g: FloatArray, at: FloatArray, width: float) -> FloatArray:
    """At each time of ``at``: the sum of ``g`` over the times ``t`` (sorted) under a triangle
    of half-width ``width`` centred there, ``sum g_k (1 - |t_k - a| / width)``; by cumulative
    sums of ``g`` and ``g t``, linear in the sizes."""
    gs = np.concatenate(([0.0], np.cumsum(g)))
    gts = np.concatenate(([0.0], np.cumsum(g * t)))
    lo = np.searchsorted(t, at - width, side="right")
    mid = np.searchsorted(t, at, side="right")
    hi = np.searchsorted(t, at + width, side="left")
    before, after = gs[mid] - gs[lo], gs[hi] - gs[mid]
    # behind: g (1 - (a - t) / width); ahead: g (1 - (t - a) / width)
    behind = before - (at * before - (gts[mid] - gts[lo])) / width
    ahead = after - ((gts[hi] - gts[mid]) - at * after) / width
    return np.asarray(behind + ahead)
