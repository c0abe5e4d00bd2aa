"""The textbook steps of a linear Kalman filter and Rauch-Tung-Striebel smoother.

Symbols as in filterpy (``filterpy.kalman.KalmanFilter``, ``rts_smoother``) and Bar-Shalom, Li &
Kirubarajan (2001), ch. 5 and 8: state ``x``, covariance ``P``, transition ``F``, process noise
``Q``, control input ``u`` (already mapped into the state, ``B u``), measurement row ``H``
(one scalar measurement ``z`` per update, of variance ``R``). Rauch, Tung & Striebel, AIAA J.
3(8), 1965, doi:10.2514/3.3166. ``tests/test_smoother_kalman.py`` checks them against filterpy's
on a linear-Gaussian toy.
"""

from __future__ import annotations

import numpy as np

from altfuse.fuse.smoother.compiled import compiled, dot, matmul, matvec, solve_spd
from altfuse.model import FloatArray


@compiled
def predict(
    x: FloatArray, p: FloatArray, f: FloatArray, q: FloatArray, u: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The prior at the next step: the state and its covariance carried through ``F``."""
    # x = F x + B u
    x = matvec(f, x) + u
    # P = F P F' + Q
    p = matmul(matmul(f, p), f.T) + q
    return x, p


@compiled
def innovation(
    x: FloatArray, p: FloatArray, z: float, h: FloatArray, r: float
) -> tuple[float, float, FloatArray]:
    """A scalar measurement's innovation ``y``, its variance ``S`` and ``P H'``."""
    # y = z - H x
    y = z - dot(h, x)
    # P H'
    ph = matvec(p, h)
    # S = H P H' + R
    s = dot(h, ph) + r
    return y, s, ph


@compiled
def update(
    x: FloatArray, p: FloatArray, y: float, s: float, ph: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The posterior after a measurement of innovation ``y`` (from :func:`innovation`), and the
    gain ``K``."""
    # K = P H' S^-1
    k = ph / s
    # x = x + K y
    x = x + k * y
    # P = (I - K H) P = P - K (P H')'
    p = p - np.outer(k, ph)
    return x, p, k


@compiled
def rts_step(
    filtered: tuple[FloatArray, FloatArray],
    predicted_next: tuple[FloatArray, FloatArray],
    smoothed_next: tuple[FloatArray, FloatArray],
    f: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """One backward step: the smoothed ``(x, P)`` at ``k`` from the filtered one at ``k``, the
    prior at ``k + 1`` (``F`` between them) and the smoothed one at ``k + 1``."""
    xf, pf = filtered
    xp, pp = predicted_next
    xs, ps = smoothed_next
    # C = P_f F' P_p(k+1)^-1   (solved, not inverted: P_p C' = F P_f, P_p symmetric)
    c = solve_spd(pp, matmul(f, pf)).T
    # x_s = x_f + C (x_s(k+1) - x_p(k+1))
    # P_s = P_f + C (P_s(k+1) - P_p(k+1)) C'
    return xf + matvec(c, xs - xp), pf + matmul(matmul(c, ps - pp), c.T)
