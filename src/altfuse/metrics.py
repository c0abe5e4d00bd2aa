"""Error measures, used by ``altfuse evaluate`` and by the tests."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

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
    """

    n: int
    rmse: float
    mae: float
    max_abs: float
    bias: float

    def as_dict(self) -> dict[str, float | int | None]:
        """The fields, with NaN (no common tick) as None so that the JSON stays strict."""
        return {k: (None if v != v else v) for k, v in asdict(self).items()}


def error_stats(
    estimate: FloatArray, truth: FloatArray, mask: npt.NDArray[np.bool_] | None = None
) -> ErrorStats:
    """RMSE, mean absolute error, maximum absolute error and bias of ``estimate`` [m]."""
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
    )
