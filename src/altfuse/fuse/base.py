"""What every fusion method returns, and the weighted combination they share."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from altfuse.model import FloatArray

#: Per-tick status of the fused value.
FUSED = "fused"  # weighted as the method says
EQUAL = "equal"  # the method's weights were all zero: equal weights over the valid sensors
SINGLE = "single"  # one valid sensor: the result is that sensor
NONE = "none"  # no valid sensor: the result is NaN
INERTIAL = "inertial"  # no valid sensor, the accelerometer carried the estimate (multilayer)


@dataclass(frozen=True)
class FusionResult:
    """A fused altitude and how it was made.

    Attributes
    ----------
    fused
        Fused height [m], shape (T,); NaN where no sensor is valid.
    weights
        Weight of each sensor, shape (T, n), summing to 1 over the valid sensors at each tick,
        0 for a sensor that is not valid there, NaN on ticks with no valid sensor.
    status
        Per tick: ``fused``, ``equal`` (the method's weights were all zero), ``single``,
        ``none``, or ``inertial`` (no sensor; the accelerometer carried the estimate).
    traces
        Method-specific diagnostics per sensor, each of shape (T, n), e.g. Paper A's support.
    tick_traces
        Method-specific diagnostics per tick, each of shape (T,), e.g. Paper B's gate k(n).
    params
        The parameters used, with any value the method chose from the data.
    """

    method: str
    fused: FloatArray
    weights: FloatArray
    status: npt.NDArray[np.str_]
    traces: dict[str, FloatArray] = field(default_factory=dict)
    tick_traces: dict[str, FloatArray] = field(default_factory=dict)
    params: dict[str, float | int | str] = field(default_factory=dict)


def combine(
    z: FloatArray,
    raw_weights: FloatArray,
    method: str,
    traces: dict[str, FloatArray] | None = None,
    params: dict[str, float | int | str] | None = None,
    tick_traces: dict[str, FloatArray] | None = None,
) -> FusionResult:
    """Normalise ``raw_weights`` over the valid sensors and form ``sum_i w_i z_i``.

    ``raw_weights`` must be >= 0; a sensor whose ``z`` is NaN gets weight 0 whatever its raw
    weight. Where every valid sensor's raw weight is 0 the valid sensors are weighted equally
    (status ``equal``, or ``single`` with one); where none is valid the result is NaN (``none``).
    """
    valid = np.isfinite(z)
    n_valid = valid.sum(axis=1)
    w = np.where(valid, np.nan_to_num(raw_weights, nan=0.0), 0.0)
    total = w.sum(axis=1)
    zero = total <= 0
    w[zero] = valid[zero]
    total = w.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = w / total
    fused = np.where(n_valid > 0, (w * np.where(valid, z, 0.0)).sum(axis=1), np.nan)
    status = np.where(zero, EQUAL, FUSED)
    status = np.where(n_valid == 1, SINGLE, status)
    status = np.where(n_valid == 0, NONE, status)
    return FusionResult(
        method=method,
        fused=fused,
        weights=w,
        status=status,
        traces=traces or {},
        tick_traces=tick_traces or {},
        params=params or {},
    )
