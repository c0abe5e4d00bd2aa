"""Observation-support dynamic weighting (Paper A).

Cheng Xianbin, Gao Yong, Li Bing, Meng Hao, "A Dynamic Weighted Fusion Algorithm Based on
Observation Support", Ordnance Industry Automation 41(6), 2022, doi:10.7690/bgzdh.2022.06.004.

Equations, as in the paper (``z_i(t)`` sensor ``i`` at tick ``t``, ``n`` valid sensors)::

    a_ij(t)     = exp(-alpha * (z_i(t) - z_j(t))**2),   a_ii = 1              (Eq. 2, 3)
    r_i(t)      = 1/n * sum_{j != i} a_ij(t)                                   (Eq. 4)
    rbar_i(T)   = 1/(k+1) * sum_{t=T-k..T} r_i(t)                              (Eq. 6)
    sigma2_i(T) = 1/(k+1) * sum_{t=T-k..T} (rbar_i(T) - r_i(t))**2             (Eq. 7)
    lambda_i(T) = rbar_i(T) * (1 - beta * sigma2_i(T))                         (Eq. 5)
    X(T)        = sum_i lambda_i(T) z_i(T) / sum_i lambda_i(T)                 (Eq. 8)

Eq. 4 divides by ``n``, not ``n - 1``, as the paper does. The paper gives no values for
``alpha``, ``beta``, ``k`` and says nothing of missing data; decided here:

- A sensor missing at ``t`` takes no part in ``a_ij(t)``, and ``n`` counts the sensors valid at
  ``t``. Support needs a pair: where fewer than two sensors are valid, ``r_i(t)`` is undefined
  (NaN) and those ticks do not enter any window.
- The window mean and population variance (Eq. 6, 7) run over the defined ``r_i`` among the last
  ``k + 1`` ticks; the first ``k`` ticks, and windows with gaps, use the samples available.
- ``lambda`` is clipped at 0 where ``beta * sigma2 > 1``. If every valid sensor's ``lambda`` is 0
  the valid sensors are averaged with equal weights; with one valid sensor the result is that
  sensor. Both are marked in the output's status column.
- ``alpha`` [1/m²] sets the disagreement that counts as "no support" and depends on units and
  noise. By default it comes from the data: ``alpha = 1 / (2 s**2)``, where ``s`` is the robust
  spread of all pairwise differences, ``s = 1.4826 median|z_i - z_j|`` (the standard deviation
  for Gaussian differences), floored at 1 cm. Two sensors that differ by ``s`` then support each
  other with ``exp(-1/2) = 0.61``, by ``3 s`` with 0.011. A fixed ``alpha`` can be given instead.
- ``k`` comes from a window in seconds, ``k = round(window_s / dt)``, so that a faster clock
  keeps the window's length rather than its tick count.
- Defaults ``beta = 10``, ``k = 5`` (0.5 s at 10 Hz) and the data-driven ``alpha`` were chosen by
  measurement (``benchmarks/tune_support.py``): on the synthetic Paper A experiment (10 seeds)
  they gave the lowest whole-flight RMSE of the grid alpha x {1/4, 1, 4}, beta {0, 1, 10, 100},
  k {0, 5, 10, 20, 40}, 0.153 m against 0.364 m for the mean. On real logs, against the
  autopilot's EKF (a reference, not truth), no setting moved the error by more than 10 %,
  except on a log with a faulty GPS2 where a larger alpha rejects it sooner.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from altfuse.fuse.base import FusionInput, FusionResult, combine
from altfuse.metrics import MAD_TO_SIGMA
from altfuse.model import FloatArray
from altfuse.params import Params, param

_MIN_SPREAD_M = 0.01


@dataclass(frozen=True, kw_only=True)
class SupportParams(Params):
    """Paper A's parameters (Eq. 2, 5, 6-7)."""

    alpha_per_m2: float | None = param(
        None,
        help="support kernel scale alpha (Eq. 2)",
        unit="1/m^2",
        check="positive",
        default_text="from the data",
    )
    beta: float = param(
        10.0, help="penalty on the support's variance (Eq. 5)", check="non-negative"
    )
    window_s: float = param(
        0.5,
        help="the window of Eq. 6-7, k = window / tick previous ticks",
        unit="s",
        check="non-negative",
    )


def auto_alpha(z: FloatArray) -> float:
    """Data-driven ``alpha`` [1/m²]: ``1 / (2 s²)`` with ``s`` the robust pairwise spread."""
    n = z.shape[1]
    diffs = [np.abs(z[:, i] - z[:, j]) for i in range(n) for j in range(i + 1, n)]
    pooled = np.concatenate(diffs) if diffs else np.array([])
    pooled = pooled[np.isfinite(pooled)]
    spread = MAD_TO_SIGMA * float(np.median(pooled)) if pooled.size else 0.0
    spread = max(spread, _MIN_SPREAD_M)
    return 1.0 / (2.0 * spread**2)


def pairwise_support(z: FloatArray, alpha: float) -> FloatArray:
    """Observation support ``r_i(t)`` (Eq. 2-4), shape (T, n); NaN where undefined."""
    valid = np.isfinite(z)
    n_valid = valid.sum(axis=1)
    # Eq. 2: a_ij = exp(-alpha (z_i - z_j)^2), only between sensors valid at t
    d = z[:, :, None] - z[:, None, :]
    pair = valid[:, :, None] & valid[:, None, :]
    a = np.where(pair, np.exp(-alpha * np.where(pair, d, 0.0) ** 2), 0.0)
    # Eq. 3-4: the off-diagonal row sum of the support matrix, divided by n
    idx = np.arange(z.shape[1])
    a[:, idx, idx] = 0.0
    with np.errstate(invalid="ignore", divide="ignore"):
        r = a.sum(axis=2) / n_valid[:, None]
    return np.where(valid & (n_valid[:, None] >= 2), r, np.nan)


def window_mean_var(r: FloatArray, k: int) -> tuple[FloatArray, FloatArray]:
    """Mean and population variance of the defined ``r`` over ticks ``T-k..T`` (Eq. 6, 7)."""
    defined = np.isfinite(r)
    x = np.where(defined, r, 0.0)

    def trailing_sum(a: FloatArray) -> FloatArray:
        c = np.concatenate((np.zeros((1, a.shape[1])), np.cumsum(a, axis=0)))
        lower = np.maximum(np.arange(a.shape[0]) - k, 0)
        return c[1:] - c[lower]

    count = trailing_sum(defined.astype(np.float64))
    with np.errstate(invalid="ignore", divide="ignore"):
        rbar = trailing_sum(x) / count
        # Eq. 7 as E[r^2] - rbar^2 (r is in [0, 1): no cancellation worth the name)
        sigma2 = np.maximum(trailing_sum(x * x) / count - rbar**2, 0.0)
    return rbar, sigma2


def fuse_support(inputs: FusionInput, params: SupportParams) -> FusionResult:
    """Paper A's observation-support dynamic weighting (Eq. 2-8) of ``inputs.z`` [m], see the
    module doc.

    ``params.alpha_per_m2`` None chooses ``alpha`` from the data (:func:`auto_alpha`); the window
    holds the current and the ``k = round(window_s / dt_s)`` previous ticks (Eq. 6, 7).
    """
    z, alpha, beta = inputs.z, params.alpha_per_m2, params.beta
    k = round(params.window_s / inputs.dt_s)
    alpha_used = auto_alpha(z) if alpha is None else alpha
    r = pairwise_support(z, alpha_used)
    rbar, sigma2 = window_mean_var(r, k)
    # Eq. 5, clipped at 0 (the paper leaves beta * sigma2 > 1 open)
    lam = np.clip(rbar * (1.0 - beta * sigma2), 0.0, None)
    lam = np.where(np.isfinite(lam), lam, 0.0)
    # Eq. 8 (normalisation and the fall-backs in combine())
    return combine(
        z,
        lam,
        "support",
        traces={"lambda": lam, "support": r, "support_mean": rbar, "support_var": sigma2},
        params={
            "alpha_per_m2": alpha_used,
            "alpha_source": "data (robust pairwise spread)" if alpha is None else "option",
            "beta": beta,
            "window_s": params.window_s,
            "window_ticks": k,
        },
    )
