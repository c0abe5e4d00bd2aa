"""Paper B, layer 1: delay-based temporal fusion per sensor, then optimal spatial weighting.

Huang He, Liu Yiheng, Zhao Xi, Xu Zhe, Guo Lu, multi-layer multi-source information fusion for
the altitude of a hovering rotor UAV (ALGORITHMS.md section 3). The paper's text lost its
equations in extraction: every form below is **reconstructed** from its prose and the standard
literature it cites, as ALGORITHMS.md sets out; each function says which section it is.

Measurement variance (3.1, reconstructed). For sensors ``p``, ``q`` with independent zero-mean
noise, the noise variance of ``p`` is its auto-covariance less its cross-covariance with the
others. With deviations from the running mean ``x = z - mu`` (the paper's ``mu``)::

    R_pp(k) = (k-1)/k R_pp(k-1) + x_p(k)**2 / k
    R_pq(k) = (k-1)/k R_pq(k-1) + x_p(k) x_q(k) / k
    delta2_p(k) = R_pp(k) - mean_{q != p} R_pq(k)           (floored at VARIANCE_FLOOR_M2)

where the mean runs over the sensors ``q`` valid at ``k`` (decided here: a sensor that has gone
out of range would otherwise bring a covariance from another part of the flight).

Temporal fusion per sensor: one-step delay (3.2, the paper's baseline from radar processing)::

    Z+(1) = Z(1),   P+(1) = delta2(1)
    Z+(k) = (delta2(k) Z+(k-1) + P+(k-1) Z(k)) / (P+(k-1) + delta2(k))
    P+(k) = P+(k-1) delta2(k) / (P+(k-1) + delta2(k))

and two-step delay (3.3, Paper B's layer 1): the current measurement and the two previous
estimates, each weighted by the inverse of its variance, ``Z+(1), Z+(2)`` from the one-step form::

    1/P+(k) = 1/delta2(k) + 1/P+(k-1) + 1/P+(k-2)
    Z+(k)   = P+(k) (Z(k)/delta2(k) + Z+(k-1)/P+(k-1) + Z+(k-2)/P+(k-2))

Both model a *constant* altitude (the paper's hover): ``P+`` shrinks towards 0 and the estimate
freezes. ``form="paper"`` is that, faithfully. ``form="practical"`` (the default: on the moving
sample flight the paper's form is 6.4 m RMS off, the practical 0.79 m) inflates each previous
variance by the process noise of the steps since, ``P+(k-1) + q`` and ``P+(k-2) + 2 q``,
which makes the recursion a random-walk filter that follows a moving vehicle. ``q`` is per tick
in the recursion; the parameter is the random walk's density ``q_m2_s`` [m²/s], ``q = q_m2_s dt``,
so that the filter means the same at any clock rate.

Spatial weighting (3.4) over the sensors measured at ``k``::

    W_i(k) = (1/P+_i(k)) / sum_j 1/P+_j(k),   Z*(k) = sum_i W_i(k) Z+_i(k),
    P*(k)  = 1 / sum_j 1/P+_j(k)

The estimate in 3.1 assumes a stationary altitude, as in the paper's hover. Under a moving
vehicle the deviations from the running mean carry the motion, whose chance correlation with the
noise swamps the noise variance (tests/test_delay.py: on a random walk the quietest sensor is
floored at 1e-4 m²); the spatial weights are then unreliable. Measured on the moving sample flight,
``delay1``/``delay2`` are 0.79 m RMS off against 0.54 m for the plain mean.

Decided here, as the paper is silent: a sensor absent at ``k`` keeps its estimate (its variance
grows by ``q`` in the practical form) and takes no part in the spatial weighting at ``k``; a sensor
starts its recursion at its first sample; with a single sensor, ``delta2`` is its
auto-covariance ``R_pp`` (no cross-covariance to subtract); a sensor alone at ``k`` after it had
a partner keeps the ``delta2`` of its last tick with one (``R_pp`` alone is the flight's
motion: 10^3 m^2 for a barometer in a climb while the GPS was out).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from altfuse.align import pauses
from altfuse.fuse.base import FusionInput, FusionResult, combine
from altfuse.model import FloatArray
from altfuse.params import Params, param

#: Smallest measurement variance [m²]: keeps 1/delta2 finite where the estimate is 0 (the first
#: sample has no spread) or negative (cross-covariance larger than auto-covariance by chance).
VARIANCE_FLOOR_M2 = 1e-4
#: A pause this long [s] in every sensor, or in any one, restarts the recursions (3.1-3.3):
#: their running statistics describe one stationary flight. Across a log's splice the one
#: before it held the estimate 50 m off for a minute (the 3.4 Solo log); across a GPS outage
#: in a climb, 220 m (a GPS frozen for 80 s, its samples dropped as stuck).
RESTART_S = 5.0
#: Smallest estimate variance P+ [m²]: only numerical (the paper's form drives P+ towards 0).
ESTIMATE_FLOOR_M2 = 1e-12
Form = Literal["practical", "paper"]


def process_noise(default_m2_s: float) -> Any:
    """The practical form's process noise ``q_m2_s``, a parameter field with this default."""
    return param(
        default_m2_s,
        help="process noise of the practical form, a random walk's density",
        unit="m^2/s",
        check="non-negative",
        flag="--process-noise",
        aliases=("--q",),
    )


@dataclass(frozen=True, kw_only=True)
class DelayParams(Params):
    """Layer 1's temporal recursion (3.2, 3.3)."""

    form: Form = param(
        "practical",
        help="temporal recursion: 'practical' (a random walk) or 'paper' (a constant altitude)",
    )
    #: 0.5 m²/s (0.05 m² per 0.1 s tick) is a vertical random walk of ~0.7 m/√s. Measured: best
    #: of 0.01-5 m² per tick for delay1 on the seeded hover (RMSE 0.381 m); every value within
    #: 1 % on the moving sample flight.
    q_m2_s: float = process_noise(0.5)


def measurement_variances(z: FloatArray) -> FloatArray:
    """Noise variance of each sensor at each tick from auto- and cross-covariances (3.1).

    Parameters
    ----------
    z
        Heights [m], shape (T, n); NaN where a sensor is absent (it then takes no part).

    Returns
    -------
    delta2
        Shape (T, n) [m²], ``R_pp(k) - mean_q R_pq(k)`` floored at ``VARIANCE_FLOOR_M2``; NaN
        before a sensor's first sample.
    """
    valid = np.isfinite(z)
    zz = np.where(valid, z, 0.0)
    count = np.cumsum(valid, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mu = np.cumsum(zz, axis=0) / count  # running mean, the paper's mu
    x = np.where(valid, zz - mu, 0.0)  # deviation at k from the mean up to k
    # R_pp(k) = (k-1)/k R_pp(k-1) + x_p(k)^2 / k, i.e. the running mean of x_p^2
    with np.errstate(invalid="ignore", divide="ignore"):
        r_pp = np.cumsum(x * x, axis=0) / count
    n = z.shape[1]
    if n == 1:
        return np.where(count > 0, np.maximum(r_pp, VARIANCE_FLOOR_M2), np.nan)
    cross = np.zeros_like(z)
    partnered = np.zeros(z.shape, dtype=bool)
    for p in range(n):
        total = np.zeros(z.shape[0])
        others = np.zeros(z.shape[0])
        for q in range(n):
            if q == p:
                continue
            both = valid[:, p] & valid[:, q]
            # R_pq(k) = (k-1)/k R_pq(k-1) + x_p(k) x_q(k) / k over the ticks both are valid
            with np.errstate(invalid="ignore", divide="ignore"):
                r_pq = np.cumsum(np.where(both, x[:, p] * x[:, q], 0.0)) / np.cumsum(both)
            total += np.where(both, r_pq, 0.0)
            others += both
        # R_p(k): the mean over the other sensors valid at k
        with np.errstate(invalid="ignore", divide="ignore"):
            cross[:, p] = np.where(others > 0, total / others, 0.0)
        partnered[:, p] = others > 0
    delta2 = np.maximum(r_pp - cross, VARIANCE_FLOOR_M2)
    # a sensor alone at k keeps the variance it had with a partner: its noise did not grow when
    # the other went, and R_pp alone holds the flight's motion (a GPS frozen for 80 s, dropped,
    # made the barometer's variance 10^3 m^2 and held delay2 at 77 m while it climbed to 220 m)
    ticks = np.arange(z.shape[0])[:, None]
    last = np.maximum.accumulate(np.where(partnered, ticks, -1), axis=0)
    held = np.take_along_axis(delta2, np.maximum(last, 0), axis=0)
    delta2 = np.where(~partnered & (last >= 0), held, delta2)
    return np.where(count > 0, delta2, np.nan)


def temporal_fusion(
    z: FloatArray, delta2: FloatArray, steps: int, form: Form, q: float
) -> tuple[FloatArray, FloatArray]:
    """One-step (3.2, ``steps=1``) or two-step (3.3, ``steps=2``) delay fusion of each sensor,
    with the process noise ``q`` [m² per tick] of the practical form.

    Returns the estimates ``Z+`` and their variances ``P+``, shape (T, n); NaN before a sensor's
    first sample.
    """
    q_step = q if form == "practical" else 0.0
    T, n = z.shape
    zp = np.full((T, n), np.nan)
    pp = np.full((T, n), np.nan)
    # per sensor: the last two estimates and variances, and how many updates it has had
    z1 = np.full(n, np.nan)
    p1 = np.full(n, np.nan)
    z2 = np.full(n, np.nan)
    p2 = np.full(n, np.nan)
    seen = np.zeros(n, dtype=np.int64)
    for k in range(T):
        zk, dk = z[k], delta2[k]
        meas = np.isfinite(zk)
        first = meas & (seen == 0)
        later = meas & (seen >= 1)
        # the previous variances, inflated by the process noise of the steps since (practical)
        p1_prior = p1 + q_step
        p2_prior = p2 + 2 * q_step
        new_z = z1.copy()
        new_p = p1_prior.copy()  # no measurement: the estimate holds, its variance grows
        # Z+(1) = Z(1), P+(1) = delta2(1)
        new_z[first], new_p[first] = zk[first], dk[first]
        one = later & ((seen == 1) | (steps == 1))
        # 3.2: Z+ = (delta2 Z+(k-1) + P+(k-1) Z) / (P+(k-1) + delta2), P+ = P+(k-1) delta2 / (...)
        s = p1_prior[one] + dk[one]
        new_z[one] = (dk[one] * z1[one] + p1_prior[one] * zk[one]) / s
        new_p[one] = p1_prior[one] * dk[one] / s
        two = later & (seen >= 2) & (steps == 2)
        # 3.3: 1/P+ = 1/delta2 + 1/P+(k-1) + 1/P+(k-2); Z+ = P+ (Z/delta2 + Z+(k-1)/P+(k-1) + ...)
        info = 1 / dk[two] + 1 / p1_prior[two] + 1 / p2_prior[two]
        new_p[two] = 1 / info
        new_z[two] = new_p[two] * (
            zk[two] / dk[two] + z1[two] / p1_prior[two] + z2[two] / p2_prior[two]
        )
        z2, p2 = np.where(meas, z1, z2), np.where(meas, p1_prior - q_step, p2)
        # the paper's form drives P+ to 0; keep it representable so 1/P+ stays finite
        z1, p1 = new_z, np.maximum(new_p, ESTIMATE_FLOOR_M2)
        seen += meas
        zp[k], pp[k] = z1, p1
    return zp, pp


def spatial_weights(pplus: FloatArray, valid: FloatArray) -> FloatArray:
    """3.4: ``W_i = (1/P+_i) / sum_j (1/P+_j)`` over the sensors measured at each tick."""
    inv = np.where(valid & np.isfinite(pplus), 1.0 / pplus, 0.0)
    total = inv.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, inv / total, np.nan)


def _stretches(t: FloatArray, z: FloatArray) -> list[slice]:
    """The parts of the clock between the ends of pauses of ``RESTART_S`` or more, in every
    sensor or in any one: the running statistics of 3.1 describe one stationary flight, and a
    sensor back from an outage in a climb comes back to another."""
    each = [pauses(t, z[:, [j]], RESTART_S) for j in range(z.shape[1])]
    cuts = sorted({after for pauses_of_one in each for _, after in pauses_of_one})
    return [slice(a, b) for a, b in itertools.pairwise([0, *cuts, z.shape[0]])]


def layer1(inputs: FusionInput, steps: int, params: DelayParams) -> FusionResult:
    """Temporal (3.2 or 3.3), then spatial (3.4) fusion, with ``P*`` as a per-tick trace."""
    z, form = inputs.z, params.form
    q = params.q_m2_s * inputs.dt_s
    delta2, zplus, pplus = (np.full(z.shape, np.nan) for _ in range(3))
    for part in _stretches(inputs.t, z):
        delta2[part] = measurement_variances(z[part])
        zplus[part], pplus[part] = temporal_fusion(z[part], delta2[part], steps, form, q)
    valid = np.isfinite(z)
    w = spatial_weights(pplus, valid)
    inv = np.where(valid, 1.0 / pplus, 0.0).sum(axis=1)
    with np.errstate(divide="ignore"):
        pstar = np.where(inv > 0, 1.0 / inv, np.nan)  # P* = 1 / sum_j 1/P+_j
    # combine() forms Z* = sum W_i Z+_i over the measured sensors: it weighs Z+, not z
    return combine(
        np.where(valid, zplus, np.nan),
        np.nan_to_num(w),
        f"delay{steps}",
        traces={"variance": delta2, "temporal_estimate": zplus, "temporal_variance": pplus},
        tick_traces={"fused_variance": pstar},
        params={"form": form, "q_m2_s": params.q_m2_s if form == "practical" else 0.0},
    )


def fuse_delay1(inputs: FusionInput, params: DelayParams) -> FusionResult:
    """Paper B's baseline: one-step delay temporal fusion (3.2), then spatial weighting (3.4),
    of ``inputs.z`` [m]."""
    return layer1(inputs, 1, params)


def fuse_delay2(inputs: FusionInput, params: DelayParams) -> FusionResult:
    """Paper B's first layer: two-step delay temporal fusion (3.3), then spatial weighting (3.4),
    of ``inputs.z`` [m]."""
    return layer1(inputs, 2, params)
