"""Error measures, used by ``altfuse evaluate`` and by the tests."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass

import bottleneck as bn
import numpy as np
import numpy.typing as npt

from altfuse.model import FloatArray

#: The standard deviation of a normal variable over its median absolute deviation (or, for one
#: centred on zero, over the median of its absolute value): 1 / Phi^-1(3/4) = 1.4826.
MAD_TO_SIGMA = 1.0 / 0.6744897501960817


def envelope(z: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per tick, the lowest and the highest valid source of ``z`` (T, n): inf and -inf where
    none is valid."""
    valid = np.isfinite(z)
    lo = np.min(np.where(valid, z, np.inf), axis=1, initial=np.inf)
    hi = np.max(np.where(valid, z, -np.inf), axis=1, initial=-np.inf)
    return lo, hi


def samples_in(span_s: float, step: float, most: int) -> int:
    """How many samples ``step`` apart span ``span_s`` (rounded), at most ``most``: stamps a
    few nanoseconds apart (a damaged log) ask for more than there are, or for infinitely
    many, and none apart for a division by zero."""
    ratio = span_s / step if step > 0 else math.inf
    return round(ratio) if ratio < most else most


def cumulative_integral(t: FloatArray, v: FloatArray) -> FloatArray:
    """The integral of the samples ``v`` at the sorted times ``t`` from the first to each,
    by trapezoids (scipy's ``cumulative_trapezoid(v, t, initial=0)``)."""
    steps = 0.5 * (v[1:] + v[:-1]) * np.diff(t)
    return np.asarray(np.concatenate(([0.0], np.cumsum(steps))))


def running_median(x: FloatArray, window: int, min_periods: int = 1) -> FloatArray:
    """The median over a centred window of ``window`` samples at each sample, NaN skipped, NaN
    where fewer than ``min_periods`` are valid: pandas' ``rolling(window, center=True,
    min_periods).median()`` (for an even window, one more sample behind than ahead), by
    bottleneck's ``move_median`` (its import is milliseconds where pandas' is 0.3 s)."""
    return _centred(bn.move_median, x, window, min_periods)


def running_white_noise(z: FloatArray, window: int, min_periods: int = 1) -> FloatArray:
    """The white noise around each sample of ``z`` (three at least), as
    :func:`white_noise_sigma` from the median absolute second difference, over a centred window
    of ``window`` of them (the first and last sample take their neighbour's); NaN where fewer
    than ``min_periods`` are there."""
    d2 = np.abs(np.diff(z, 2))
    d2 = np.concatenate(([d2[0]], d2, [d2[-1]]))
    return MAD_TO_SIGMA * running_median(d2, window, min_periods) / math.sqrt(6.0)


def running_max(x: FloatArray, window: int) -> FloatArray:
    """The largest over the same centred window (:func:`running_median`), NaN skipped."""
    return _centred(bn.move_max, x, window, 1)


def _centred(
    move: Callable[..., FloatArray], x: FloatArray, window: int, min_periods: int
) -> FloatArray:
    """bottleneck's trailing ``move`` over ``window`` samples, centred."""
    if x.size == 0:
        return np.zeros(0)
    ahead = (window - 1) // 2
    before = max(0, window - x.size - ahead)  # NaN in front: a window longer than the data
    padded = np.concatenate((np.full(before, np.nan), x, np.full(ahead, np.nan)))
    out: FloatArray = move(padded, window, min_count=min_periods)[before + ahead :]
    return out


def running_sum(x: FloatArray, window: int) -> FloatArray:
    """The sum over the same centred window (:func:`running_median`) of NaN-free ``x``, each
    window summed afresh: a running total that adds and subtracts drifts by its rounding
    over a flight's hundreds of thousands of steps."""
    ahead = (window - 1) // 2
    out: FloatArray = np.convolve(x, np.ones(window))[ahead : ahead + x.size]
    return out


def hold_nearest(x: FloatArray) -> FloatArray:
    """``x`` with each NaN replaced by the last valid value before it, or before the first
    valid one, by that one (all NaN: unchanged)."""
    valid = np.isfinite(x)
    if not valid.any() or valid.all():
        return np.array(x, dtype=float)
    last = np.maximum.accumulate(np.where(valid, np.arange(x.size), -1))
    out: FloatArray = x[np.where(last >= 0, last, np.flatnonzero(valid)[0])]
    return out


def mad_sigma(x: FloatArray) -> float:
    """The standard deviation of normal ``x`` from its median absolute deviation."""
    return MAD_TO_SIGMA * float(np.median(np.abs(x - np.median(x))))


def white_noise_sigma(z: FloatArray) -> float:
    """The white noise of samples ``z`` [their unit] from their second differences
    (``sigma = 1.4826 MAD(d2 z) / sqrt(6)``): a smooth signal cancels there, noise survives."""
    return mad_sigma(np.diff(z, 2)) / math.sqrt(6.0)


@dataclass(frozen=True)
class ErrorStats:
    """Errors of an estimate against a truth or reference [m], over the ticks where both exist.

    ``bias`` is the mean of ``estimate - truth``: positive when the estimate reads high.
    ``within_2std`` is :func:`coverage` of the estimate's own standard deviation, where it
    gives one (NaN otherwise).
    """

    n: int
    rmse: float
    mae: float
    max_abs: float
    bias: float
    within_2std: float = math.nan

    def as_dict(self) -> dict[str, float | int | None]:
        """The fields, with NaN (no common tick) as None so that the JSON stays strict."""
        return {k: (None if v != v else v) for k, v in asdict(self).items()}


def error_stats(
    estimate: FloatArray,
    truth: FloatArray,
    mask: npt.NDArray[np.bool_] | None = None,
    std: FloatArray | None = None,
) -> ErrorStats:
    """RMSE, mean absolute error, maximum absolute error and bias of ``estimate`` [m], and
    where its standard deviation ``std`` is given, how much of the errors it covers."""
    both = np.isfinite(estimate) & np.isfinite(truth)
    if mask is not None:
        both &= mask
    e = estimate[both] - truth[both]
    if e.size == 0:
        return ErrorStats(0, np.nan, np.nan, np.nan, np.nan)
    return ErrorStats(
        n=int(e.size),
        rmse=float(np.sqrt(np.mean(e**2))),
        mae=float(np.mean(np.abs(e))),
        max_abs=float(np.max(np.abs(e))),
        bias=float(np.mean(e)),
        within_2std=math.nan if std is None else coverage(e, std[both]),
    )


def coverage(error: FloatArray, std: FloatArray) -> float:
    """The share of the ticks with both whose ``error`` lies within +-2 ``std``: 0.954 where
    ``std`` is right and the errors normal; NaN where no tick has both."""
    ok = np.isfinite(error) & np.isfinite(std)
    return float(np.mean(np.abs(error[ok]) <= 2 * std[ok])) if ok.any() else math.nan


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The runs of True in ``mask`` as (start, stop) index pairs, stop exclusive."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]
