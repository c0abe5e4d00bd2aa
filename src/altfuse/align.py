"""Resampling every altitude source onto one uniform clock (Paper A, section 3.1).

Paper A brings 5 Hz GPS and faster sensors onto a common 10 Hz clock with cubic splines,
interpolating short series and decimating long ones. What the paper leaves unsaid and this
module decides (ALGORITHMS.md section 1):

- The clock is ``k / rate_hz`` for whole ``k``: ticks fall on round times of the log's own clock,
  so rows join with other tools' output.
- Duplicate timestamps are merged (mean value), unsorted samples sorted.
- A sensor faster than the clock is first averaged into the cell of width ``1 / rate_hz`` around
  each tick (a box filter), and the spline is fitted through the cell means: a spline through
  every raw sample would alias the noise into the decimated series.
- The spline never bridges a gap longer than ``max_gap_s`` (or, for a sensor logged more slowly,
  ``OWN_INTERVALS`` of its own sampling interval, ``MAX_OWN_GAP_S`` at most) and never
  extrapolates: ticks in a gap or
  outside a sensor's data are NaN for that sensor, not invented.
- The clock spans the union of the sensors' time ranges (NaN marks absence) or their overlap.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
import numpy.typing as npt

from altfuse.compiled import compiled
from altfuse.errors import NoUsableSensorsError
from altfuse.metrics import cumulative_integral
from altfuse.model import FloatArray, SensorKind, Series, brief_repr, sensor_kind
from altfuse.spline import cubic_spline

Span = Literal["union", "overlap"]
#: Most ticks a clock may have: ``TICKS_PER_SAMPLE`` per sample of all the sources, at least
#: ``MIN_TICK_CAP`` (a day at 10 Hz is 864,000). Timestamps the screening let through must not
#: allocate a clock of millions of empty ticks (a log's last records 970,000 s later gave a
#: 9.7 M-row CSV); a long pause between flights in one log stays well inside.
MIN_TICK_CAP = 1_000_000
TICKS_PER_SAMPLE = 1_000


def tick_cap(series: Sequence[Series]) -> int:
    """The most ticks a clock of ``series`` may have (see ``TICKS_PER_SAMPLE``)."""
    return max(MIN_TICK_CAP, TICKS_PER_SAMPLE * sum(s.t.size for s in series))


@dataclass(frozen=True)
class AlignStats:
    """How one source was resampled."""

    samples: int
    duplicates_merged: int
    cells_averaged: int
    segments: int
    gaps_over_max: int
    ticks_valid: int


@dataclass(frozen=True)
class Aligned:
    """Sources on one clock: ``z[:, i]`` is source ``names[i]`` at times ``t`` (NaN = absent)."""

    __repr__ = brief_repr

    t: FloatArray
    names: tuple[str, ...]
    kinds: tuple[SensorKind, ...]
    z: FloatArray
    rate_hz: float
    max_gap_s: float
    span: Span
    stats: dict[str, AlignStats]

    def part(self, start: int, stop: int) -> Aligned:
        """The ticks ``start:stop`` of the clock, every source on them."""
        return replace(self, t=self.t[start:stop], z=self.z[start:stop])


def merge_duplicates(t: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Sort by time and replace samples sharing a timestamp by their mean."""
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    unique_t, inverse, counts = np.unique(t, return_inverse=True, return_counts=True)
    if unique_t.size == t.size:
        return t, v
    return unique_t, np.bincount(inverse, weights=v) / counts


def cell_means(t: FloatArray, v: FloatArray, rate_hz: float) -> tuple[FloatArray, FloatArray]:
    """Average the samples falling in the cell ``[k - 1/2, k + 1/2) / rate_hz`` of each tick ``k``.

    Returns the mean time and mean value of every non-empty cell; a sensor slower than the clock
    comes back unchanged.
    """
    if t.size == 0:
        return t, v
    cell = np.floor(t * rate_hz + 0.5).astype(np.int64)
    boundaries = np.flatnonzero(np.diff(cell)) + 1
    if boundaries.size == t.size - 1:
        return t, v
    starts = np.concatenate(([0], boundaries))
    counts = np.diff(np.concatenate((starts, [t.size])))
    return np.add.reduceat(t, starts) / counts, np.add.reduceat(v, starts) / counts


#: A sensor's own sampling interval times this is never a gap: a GPS logged at 1 Hz (a PX4
#: low-rate logging profile) fell apart between every two samples at ``max_gap_s`` 1.0.
OWN_INTERVALS = 1.5
#: ... up to this [s]: the "interval" of a GPS with two samples 7 hours apart (a damaged log's
#: stamps) bridged the 7 hours, a column the guard measured the fused value against: the
#: smoother 1815 m off with its fused_std 27 km, unflagged, status single. The clock's own
#: tick times OWN_INTERVALS is never a gap either: two cells' means next to each other are a
#: tick apart. At 0.1 Hz a 10 Hz barometer's cells lay 9.99995-10.00005 s apart, and every one
#: over 10 s broke its column: its ticks came and went (diaven's GPS was left alone at one,
#: 4.9 m from the fused height, which the guard flagged).
MAX_OWN_GAP_S = 10.0


def resample(
    t: FloatArray,
    v: FloatArray,
    grid: FloatArray,
    rate_hz: float,
    max_gap_s: float,
    *,
    edge_cells: bool = False,
) -> tuple[FloatArray, AlignStats]:
    """Resample one series onto ``grid`` with cubic splines; NaN in gaps and outside the data.

    The spline runs through the means of the cells of the clock's ticks (:func:`cell_means`)
    and covers the ticks between their mean times; with ``edge_cells``, those between the
    first and last samples of each segment, its end pieces extended to the ticks its first and
    last cells' means lie beyond (up to half a tick). On a clock coarser than the sensors each
    cell averages seconds of samples: at 0.5 Hz the first or last tick of 20 of the 33 shared and
    sample logs that fuse was written with no sensor, its samples averaged into a cell whose
    mean time lay past it; a tick before a segment's first sample stays without."""
    n_in = t.size
    t, v = merge_duplicates(t, v)
    duplicates = n_in - t.size
    n_unique = t.size
    raw = t
    t, v = cell_means(t, v, rate_hz)
    out = np.full(grid.shape, np.nan)
    if t.size > 1:
        own = OWN_INTERVALS * float(np.median(np.diff(t)))
        max_gap_s = max(max_gap_s, min(own, MAX_OWN_GAP_S), OWN_INTERVALS / rate_hz)
    breaks = np.flatnonzero(np.diff(t) > max_gap_s) + 1
    segments = np.split(np.arange(t.size), breaks)
    half_cell = 0.5 / rate_hz
    eps = 1e-6  # the log's time resolution: a tick this close to a segment's end is inside it
    for idx in segments:
        ts, vs = t[idx], v[idx]
        if ts.size == 1:
            lo, hi = np.searchsorted(grid, [ts[0] - half_cell, ts[0] + half_cell])
            out[lo:hi] = vs[0]
            continue
        start, end = ts[0], ts[-1]
        if edge_cells:  # the samples the first and last cells averaged
            start = raw[np.searchsorted(raw, ts[0] - half_cell)]
            end = raw[np.searchsorted(raw, ts[-1] + half_cell) - 1]
        lo = np.searchsorted(grid, start - eps, side="left")
        hi = np.searchsorted(grid, end + eps, side="right")
        if hi > lo:
            out[lo:hi] = cubic_spline(ts, vs, grid[lo:hi])
    stats = AlignStats(
        samples=n_in,
        duplicates_merged=duplicates,
        cells_averaged=n_unique - t.size,
        segments=len(segments),
        gaps_over_max=int(breaks.size),
        ticks_valid=int(np.isfinite(out).sum()),
    )
    return out, stats


def tick_range(start: float, end: float, rate_hz: float) -> tuple[int, int]:
    """The first and last ``k`` of the ticks ``k / rate_hz`` within ``start`` .. ``end`` [s]
    (a bound that is a tick, to rounding, counts as one); last < first where none is."""
    return math.ceil(start * rate_hz - 1e-9), math.floor(end * rate_hz + 1e-9)


def make_grid(series: Sequence[Series], rate_hz: float, span: Span) -> FloatArray:
    """Ticks ``k / rate_hz`` covering the union or the overlap of the series' time ranges."""
    starts = [float(s.t.min()) for s in series]
    ends = [float(s.t.max()) for s in series]
    start, end = (min(starts), max(ends)) if span == "union" else (max(starts), min(ends))
    first, last = tick_range(start, end, rate_hz)
    cap = tick_cap(series)
    if last - first + 1 > cap:
        hours = (end - start) / 3600
        raise NoUsableSensorsError(
            f"the altitude sources span {hours:,.1f} h: {last - first + 1:,} ticks at "
            f"{rate_hz:g} Hz, more than {cap:,} ({TICKS_PER_SAMPLE:,} per sample); lower --rate "
            "or check the log's timestamps"
        )
    if last <= first:  # one tick is no clock: at 1e-320 Hz, one at 0 s, before the log
        raise NoUsableSensorsError(
            "the altitude sources do not overlap in time; try --span union"
            if start > end
            else f"the altitude sources' {span} spans {end - start:.3g} s ({start:.1f}-"
            f"{end:.1f} s), "
            + ("between two ticks" if last < first else "a single tick (a clock needs two)")
            + f" of a {rate_hz:g} Hz clock; raise --rate"
        )
    return np.arange(first, last + 1, dtype=np.float64) / rate_hz


def align(
    series: Sequence[Series],
    rate_hz: float = 10.0,
    max_gap_s: float = 1.0,
    span: Span = "union",
    *,
    edge_cells: bool = False,
) -> Aligned:
    """Resample ``series`` onto one clock of ``rate_hz`` (Paper A section 3.1, see module doc).

    Parameters
    ----------
    series
        The altitude sources, each with its own sample times [s].
    rate_hz
        Rate of the common clock [Hz], > 0; Paper A uses 10 Hz.
    max_gap_s
        Longest gap between two samples [s] that the spline may bridge, > 0.
    span
        ``union``: the clock covers every source's time range; ``overlap``: only the common range.
    edge_cells
        Each segment covers the ticks from its first sample to its last, not from its first
        cell's mean time to its last's (:func:`resample`): for a clock coarser than the datum's.
    """
    if not series:
        raise NoUsableSensorsError("no altitude source to align")
    grid = make_grid(series, rate_hz, span)
    columns, stats = [], {}
    for s in series:
        column, stats[s.name] = resample(
            s.t, s.value, grid, rate_hz, max_gap_s, edge_cells=edge_cells
        )
        columns.append(column)
    return Aligned(
        t=grid,
        names=tuple(s.name for s in series),
        kinds=tuple(sensor_kind(s.kind) for s in series),
        z=np.column_stack(columns),
        rate_hz=rate_hz,
        max_gap_s=max_gap_s,
        span=span,
        stats=stats,
    )


#: The lags searched [s], and their step: a GPS trails the barometer by 0.1-0.4 s in the
#: simulators' logs; a negative lag is a sensor that leads.
LAG_RANGE_S = (-0.5, 1.0)
LAG_STEP_S = 0.01
#: Lags are matched on changes over this span [s]: over one 5 Hz GPS interval the barometer's
#: noise swamps the rate (a log with SIM_BARO_RND 0.2 gave 0.11 s where the truth says 0.21 s).
LAG_SPAN_S = 1.0
#: Least share of the sensor's changes the reference's must explain for a lag to be estimated:
#: with the simulators' GPS 0.97-1.00; with altfuse's own simulated GPS (0.3-1 m of noise, a
#: slow random walk) 0.57-0.82, and there the estimate was 0.1-0.6 s off.
LAG_MIN_EXPLAINED = 0.9
#: The reference is averaged over this span [s] around each time it is read at, and over
#: LAG_BOX_STEPS of its own sampling intervals where those are longer (at most LAG_SPAN_S, the
#: span of the changes it is matched on): a narrower box holds one sample or two by where it
#: falls, and the fit favours the lags that put it where the noise averages out (the truth
#: logs' sensors thinned to 2 Hz: lags 0.00-0.10 s off their full-rate values, 0.07-0.10 on
#: five of 13; 0.00-0.03 with two intervals).
LAG_BOX_S = 0.3
LAG_BOX_STEPS = 2
#: Two estimates of a GPS's lag (against a barometer, and its vertical velocity against the
#: accelerometer) disagree beyond this many of their combined standard errors: the simulators'
#: 13 logs 0.0-2.7 (their barometers within 0.03 s of the truth); with the barometer as noisy
#: as a GPS 3.3-3.6 on three, whose barometers' lags were 0.04-0.09 s off
#: (``benchmarks/gps_lags.py``).
LAG_AGREE_SIGMAS = 3.0


@dataclass(frozen=True)
class Lag:
    """How far a sensor trails the reference [s], and how that was found. Its samples are
    moved ``lag_s`` earlier before alignment (0 when not estimated)."""

    sensor: str
    reference: str
    lag_s: float
    explained: float | None  # share of its changes over LAG_SPAN_S the reference explains
    how: str
    std_s: float | None = None  # the estimate's standard error, where it was estimated


def estimate_lag(series: Series, reference: Series) -> Lag:
    """The lag of ``series`` behind ``reference``: the shift of its sample times at which the
    reference best explains its changes over ``LAG_SPAN_S``.

    For each candidate lag ``tau``, with ``d`` the change of the series between samples
    ``LAG_SPAN_S`` apart and ``r`` the reference's change between the same times less ``tau``
    (the reference averaged over ``LAG_BOX_S`` there, or ``LAG_BOX_STEPS`` of its sampling
    intervals), and a free gain ``k`` (a barometer's scale error must not pull the lag)::

        explained(tau) = 1 - min_k sum (d - k r)^2 / sum d^2 = (sum d r)^2 / (sum d^2 sum r^2)

    The lag is the ``tau`` that maximises it, kept when it lies inside ``LAG_RANGE_S`` and the
    reference explains at least ``LAG_MIN_EXPLAINED`` of the changes; otherwise it is 0.
    Windows near a gap in the reference are left out (it would be interpolated across it).
    Its standard error: :func:`_lag_std`.
    """
    t, v = merge_duplicates(series.t, series.value)
    rt, rv = merge_duplicates(reference.t, reference.value)
    none = Lag(series.name, reference.name, 0.0, None, "not estimated: too few samples")
    if t.size < 10 or rt.size < 10:
        return none
    step = float(np.median(np.diff(t)))
    if not step > 1e-6:  # stamps a microsecond apart, or garbage
        return none
    k = max(1, round(LAG_SPAN_S / step))
    if t.size <= k:
        return none
    apart = (t[k:] - t[:-k]) <= 1.5 * LAG_SPAN_S  # no gap between the two samples
    # nor in the reference wherever a lag searched would read it (it is interpolated there)
    box = min(max(LAG_BOX_S, LAG_BOX_STEPS * float(np.median(np.diff(rt)))), LAG_SPAN_S)
    covered = _covered(t, rt, LAG_RANGE_S[0] - box, LAG_RANGE_S[1] + box)
    apart &= covered[k:] & covered[:-k]
    d = (v[k:] - v[:-k])[apart]
    energy = float(np.dot(d, d))
    if d.size < 10 or energy <= 0:
        return Lag(series.name, reference.name, 0.0, None, "not estimated: no motion")
    taus = np.arange(LAG_RANGE_S[0], LAG_RANGE_S[1] + LAG_STEP_S / 2, LAG_STEP_S)
    # the reference's mean over the box around each time, from its running integral: a point
    # interpolated between two samples averages their noise, one on a sample does not, and the
    # fit would favour the lags that fall between samples
    integral = cumulative_integral(rt, rv)
    explained_at = np.empty(taus.size)
    at = np.empty(t.size)
    for j, tau in enumerate(taus):
        _box_means(t, float(tau), box, rt, integral, at)
        r = (at[k:] - at[:-k])[apart]
        rr = float(np.dot(r, r))
        explained_at[j] = float(np.dot(d, r)) ** 2 / (rr * energy) if rr > 0 else 0.0
    best = int(np.argmax(explained_at))
    explained = float(explained_at[best])
    tau = float(np.round(taus[best], 3))
    if best in (0, taus.size - 1):
        how = f"not estimated: the best match ({tau:+.2f} s) is at the edge of the search"
        return Lag(series.name, reference.name, 0.0, explained, how)
    if explained < LAG_MIN_EXPLAINED:
        how = (
            f"not estimated: {reference.name} explains {explained:.1%} of its changes "
            f"(< {LAG_MIN_EXPLAINED:.0%})"
        )
        return Lag(series.name, reference.name, 0.0, explained, how)
    std = _lag_std(energy * (1.0 - explained_at[best - 1 : best + 2]), d.size, k)
    how = f"changes matched to {reference.name}'s ({explained:.1%} explained, +-{std:.3f} s)"
    return Lag(series.name, reference.name, tau, explained, how, std)


def _box_means(
    t: FloatArray, tau: float, box: float, rt: FloatArray, integral: FloatArray, out: FloatArray
) -> None:
    """``out``: the reference's mean over ``box`` around each of the times ``t - tau``, from
    its running ``integral`` at its times ``rt`` (both sorted, distinct):
    ``(np.interp(t - tau + box/2, rt, integral) - np.interp(t - tau - box/2, rt, integral)) /
    box`` to the bit. Compiled (:func:`_walked_box_means`), where numpy's interpolation gives
    a number at its first try; numpy's own where it does not (a NaN: it tries again)."""
    _walked_box_means(t, tau, box, rt, integral, out)
    again = np.isnan(out)
    if again.any():
        shifted = t[again] - tau
        half = box / 2
        out[again] = (
            np.interp(shifted + half, rt, integral) - np.interp(shifted - half, rt, integral)
        ) / box


@compiled
def _walked_box_means(
    t: FloatArray, tau: float, box: float, rt: FloatArray, integral: FloatArray, out: FloatArray
) -> None:
    """:func:`_box_means`, each end's interval found by walking on from the last time's
    instead of numpy's search (151 lags over a 300 MB log's 132 k GPS samples: 1.76 s with
    numpy), a NaN where numpy would try again (a check of it here made the loop 6x slower)."""
    half = box / 2
    lo = hi = 0
    for i in range(t.size):
        shifted = t[i] - tau
        low, lo = _interpolated(shifted - half, lo, rt, integral)
        high, hi = _interpolated(shifted + half, hi, rt, integral)
        out[i] = (high - low) / box


@compiled
def _interpolated(x: float, j: int, rt: FloatArray, integral: FloatArray) -> tuple[float, int]:
    """numpy's ``interp(x, rt, integral)`` at its first try (its ends held, a knot's own
    value), the interval ``rt[j] <= x < rt[j + 1]`` searched on from ``j``; and ``j``."""
    last = rt.size - 1
    while j < last and rt[j + 1] <= x:
        j += 1
    if x < rt[0]:
        return integral[0], j
    if j == last or rt[j] == x:
        return integral[j], j
    slope = (integral[j + 1] - integral[j]) / (rt[j + 1] - rt[j])
    return slope * (x - rt[j]) + integral[j], j


def _lag_std(rss: FloatArray, n: int, k: int) -> float:
    """The standard error [s] of a lag chosen on the grid of LAG_STEP_S from the residual sums
    of squares ``rss`` at it and its two neighbours, over ``n`` changes each ``k`` samples
    long: by least squares, ``Var(tau) = 2 s^2 / RSS''`` (``s^2 = RSS / (n - 2)``: the gain
    and the lag fitted) times ``k``, and the grid's own ``step^2 / 12``. The factor ``k``: the
    changes' errors are not white (the reference averaged over LAG_BOX_S, a GPS's error
    correlated over seconds, the sensors' own filters), and least squares alone put 15 % of
    the lags of altfuse's simulated flights within one standard error of the truth (92 % with
    it; 92 % within two either way; white noise alone: 2.5x too wide). A flat or bent-down
    curve (no curvature at the best lag): the whole search range."""
    step = LAG_STEP_S
    curvature = float(rss[0] - 2.0 * rss[1] + rss[2]) / step**2
    if not curvature > 0 or n <= 2:
        return float(LAG_RANGE_S[1] - LAG_RANGE_S[0])
    variance = 2.0 * float(rss[1]) / (n - 2) / curvature * k
    return math.sqrt(variance + step**2 / 12.0)


def _covered(t: FloatArray, rt: FloatArray, lo: float, hi: float) -> npt.NDArray[np.bool_]:
    """Whether the reference's samples ``rt`` leave no gap (over 0.5 s or five of its steps)
    between ``t - hi`` and ``t - lo``, and span them, for each ``t``."""
    step = float(np.median(np.diff(rt)))
    gap = np.flatnonzero(np.diff(rt) > max(0.5, 5 * step))
    inside = (t - hi >= rt[0]) & (t - lo <= rt[-1])
    for g in gap:
        inside &= ~((t - hi < rt[g + 1]) & (t - lo > rt[g]))
    return np.asarray(inside, dtype=bool)


def gps_lags(series: Sequence[Series]) -> dict[str, Lag]:
    """Each GPS's lag behind the first barometer (:func:`estimate_lag`), without one behind the
    first rangefinder (its height's changes are the vertical motion's over the ground it sees;
    the simulators' 8 m rangefinder flight with its barometer left out: the GPS 0.2 s late in
    the climbs, 0.19 m below the rangefinder, and the fused height with it); none without
    either."""
    references = [s for s in series if s.kind == "baro"] or [
        s for s in series if s.kind == "rangefinder"
    ]
    if not references:
        return {}
    return {s.name: estimate_lag(s, references[0]) for s in series if s.kind == "gps"}


def inertial_lag(lag: Lag, velocity: Series, integral: Series) -> Lag:
    """A GPS's lag (``lag``, against a barometer or rangefinder) checked against its vertical
    velocity's (``velocity``, from the same fixes) lag behind the accelerometer's integral
    (``integral``, :func:`altfuse.inertial.velocity_integral`), by :func:`estimate_lag` (the
    accelerometer's bias is a ramp of the integral: a constant in every change, which the
    reference's motion swamps). The accelerometer's lag is taken where the barometer's was not
    estimated, or where the two disagree by more than LAG_AGREE_SIGMAS of their standard errors
    and the accelerometer's is the smaller; else ``lag`` (with why the other was not estimated,
    where neither was).

    The accelerometer lags nothing that matters here, and no barometer's noise enters: a real
    barometer explained 9-76 % of its GPS's changes on the real logs shared (none estimated),
    and one made as noisy as a GPS (0.3 m) left the simulators' GPS lags unestimated on five of
    13 logs, and 0.04-0.09 s off on three more (0.1-0.2 s: 0.2-0.5 m in their climbs). Against
    the accelerometer the simulators' GPS lags come out within 0.04 s of their lags behind
    ``SIM`` on 12 of 13 (the 3.3 plane's noisy IMU explains 1 %; the barometer's, within 0.03
    s, disagree with them by 0.0-2.7 standard errors); on the real logs, 0.11 and 0.16 s on
    two (95 % explained)."""
    found = estimate_lag(velocity, integral)
    if found.std_s is None:
        if lag.std_s is not None:
            return lag
        why = found.how.removeprefix("not estimated: ")
        return replace(lag, how=f"{lag.how}; its vertical velocity: {why}")
    how = f"its vertical velocity's {found.how}"
    if lag.std_s is not None:
        error = math.hypot(lag.std_s, found.std_s)
        if found.std_s >= lag.std_s or abs(found.lag_s - lag.lag_s) <= LAG_AGREE_SIGMAS * error:
            return lag
        how += f"; {lag.reference}'s {lag.lag_s:.2f} +- {lag.std_s:.3f} s disagreed"
    return replace(found, sensor=lag.sensor, how=how)


def shift(series: Series, lag: Lag) -> Series:
    """``series`` with its sample times moved ``lag.lag_s`` earlier."""
    return series if lag.lag_s == 0 else replace(series, t=series.t - lag.lag_s)


#: A pause in every altitude source at least this long [s], with no accelerometer sample in it
#: either, is a splice: the log stopped and resumed (a reboot, a disarmed pause, a log that
#: was cut and joined), and nothing says where the vehicle went meanwhile.
SPLICE_MIN_GAP_S = 5.0


def pauses(t: FloatArray, z: FloatArray, min_s: float) -> list[tuple[int, int]]:
    """Every pause of at least ``min_s`` [s] in all the sources ``z`` (T, n) on the clock
    ``t``: the last tick with a value before it and the first after it."""
    some = np.flatnonzero(np.isfinite(z).any(axis=1))
    gaps = np.flatnonzero(np.diff(t[some]) >= min_s)
    return [(int(some[g]), int(some[g + 1])) for g in gaps]


def splices(aligned: Aligned, inertial_t: FloatArray | None) -> list[float]:
    """The times [s] at which a new segment of the log starts (see ``SPLICE_MIN_GAP_S``)."""
    t, out = aligned.t, []
    for before, after in pauses(t, aligned.z, SPLICE_MIN_GAP_S):
        lo, hi = t[before] + 1.0, t[after] - 1.0  # the clock's cells and the IMU's last samples
        if inertial_t is None or not ((inertial_t > lo) & (inertial_t < hi)).any():
            out.append(float(t[after]))
    return out
