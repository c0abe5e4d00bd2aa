"""The textbook steps of a linear Kalman filter and its fixed-interval smoother.

Symbols as in filterpy (``filterpy.kalman.KalmanFilter``, ``rts_smoother``) and Bar-Shalom, Li &
Kirubarajan (2001), ch. 5 and 8: state ``x``, covariance ``P``, transition ``F``, process noise
``Q``, control input ``u`` (already mapped into the state, ``B u``), measurement row ``H``
(one scalar measurement ``z`` per update, of variance ``R``).

The smoother is the modified Bryson-Frazier form (Bierman, *Factorization Methods for Discrete
Sequential Estimation*, 1977, ch. X): the same estimate as Rauch-Tung-Striebel's (AIAA J. 3(8),
1965, doi:10.2514/3.3166), carried back as the adjoint ``lambda`` and its information
``Lambda`` through each update and each transition, with no matrix to invert::

    through an update (K = P H' / S, innovation y):
        lambda <- (I - K H)' lambda - H' y / S
        Lambda <- (I - K H)' Lambda (I - K H) + H' H / S
    through a transition into step k:   lambda <- F' lambda,   Lambda <- F' Lambda F
    smoothed at step k, from its filtered (x, P) and the adjoint after it:
        x_s = x - P lambda,   P_s = P - P Lambda P

With one scalar measurement an update and ``F`` the identity plus a few entries, each step is
O(n^2) where Rauch-Tung-Striebel's gain ``P F' P_pred^-1`` is O(n^3); and only the variances
asked for are made of ``P_s`` (of ``h``; of a sample's own row, ``H P_s H'``), each O(n^2).
``tests/test_smoother_kalman.py`` checks the passes against filterpy's on a linear-Gaussian toy.

Each step works in place on its arrays, as loops, with the caller's scratch arrays
(:class:`Scratch`): compiled (:mod:`.compiled`), a flight's hundreds of thousands of steps then
allocate nothing (measured: 1.07 us a step with a new array per product, 0.08 us in place),
and, inlined into the passes' loops, count no references to them either
(:func:`altfuse.compiled.compiled_step`).
"""

from __future__ import annotations

import numpy as np

from altfuse.fuse.smoother.compiled import compiled, compiled_step
from altfuse.model import FloatArray

#: Work arrays for ``n`` states (:func:`scratch`): three (n, n), two (n,).
Scratch = tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]
#: ``F`` as the kernels take it: the dense matrix, its entries off the diagonal (rows of
#: (i, k)) and the states whose own entry on the diagonal is not 1 (a decay: a bounded offset,
#: in no row or column of those entries off the diagonal), where alone it differs from the
#: identity: ``F = D (I + E)``, ``D`` diagonal, ``E`` the entries off it.
Transition = tuple[FloatArray, np.ndarray, np.ndarray]


@compiled
def scratch(n: int) -> Scratch:
    """Work arrays for ``n`` states."""
    return np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n)), np.zeros(n), np.zeros(n)


@compiled_step
def assign(out: FloatArray, a: FloatArray) -> None:
    """``out[:] = a`` for vectors, element by element: numba's slice assignment may copy ``a``
    first, an allocation a :func:`.compiled.compiled_loop` cannot make (:func:`assign_matrix`
    for matrices; one for both, through flat views, spent 7 % of a run in numba's reshape)."""
    for i in range(a.size):
        out[i] = a[i]


@compiled_step
def assign_matrix(out: FloatArray, a: FloatArray) -> None:
    """``out[:] = a`` for matrices (:func:`assign`)."""
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            out[i, j] = a[i, j]


@compiled_step
def predict(
    x: FloatArray, p: FloatArray, fl: Transition, q: FloatArray, u: FloatArray, work: Scratch
) -> None:
    """The prior at the next step, in place: the state and its covariance carried through F."""
    f, links, decaying = fl
    xw = work[3]
    # x = F x + B u = D x + E x + B u  (F = D (I + E) = D + E: no decaying state has an E entry)
    for c in decaying:
        x[c] *= f[c, c]
    for i in range(x.size):
        xw[i] = x[i] + u[i]
    for e in range(links.shape[0]):
        i, k = links[e, 0], links[e, 1]
        xw[i] += f[i, k] * x[k]
    assign(x, xw)
    predict_covariance(p, fl, q, work)


@compiled_step
def predict_covariance(p: FloatArray, fl: Transition, q: FloatArray, work: Scratch) -> None:
    """The prior's covariance, in place (:func:`predict` without the state)."""
    f, links, decaying = fl
    fp = work[0]
    n = p.shape[0]
    # P = F P F' + Q = (I + E) (D P D) (I + E)' + Q:  D P D first
    scale_diagonal(p, f, decaying)
    # then F P = P + E P, and (F P) F' = F P + (F P) E'
    assign_matrix(fp, p)
    for e in range(links.shape[0]):
        i, k = links[e, 0], links[e, 1]
        for j in range(n):
            fp[i, j] += f[i, k] * p[k, j]
    for i in range(n):
        for j in range(n):
            p[i, j] = fp[i, j] + q[i, j]
    for e in range(links.shape[0]):
        j, k = links[e, 0], links[e, 1]
        for i in range(n):
            p[i, j] += fp[i, k] * f[j, k]


@compiled_step
def innovation(
    x: FloatArray, p: FloatArray, z: float, h: FloatArray, r: float, ph: FloatArray
) -> tuple[float, float]:
    """A scalar measurement's innovation ``y`` and its variance ``S``; ``P H'`` into ``ph``."""
    n = x.size
    # y = z - H x
    y = z
    for i in range(n):
        y -= h[i] * x[i]
    # P H'
    for i in range(n):
        total = 0.0
        for j in range(n):
            total += p[i, j] * h[j]
        ph[i] = total
    # S = H P H' + R
    s = r
    for i in range(n):
        s += h[i] * ph[i]
    return y, s


@compiled_step
def update(x: FloatArray, p: FloatArray, y: float, s: float, ph: FloatArray) -> float:
    """The posterior after a measurement of innovation ``y`` (from :func:`innovation`), in
    place; the gain on the first state, ``K[0]``."""
    n = x.size
    for i in range(n):
        # K = P H' S^-1;  x = x + K y
        x[i] += ph[i] / s * y
    for i in range(n):
        ki = ph[i] / s
        for j in range(n):
            # P = (I - K H) P = P - K (P H')'
            p[i, j] -= ki * ph[j]
    return float(ph[0] / s)


@compiled_step
def adjoint_update(
    adjoint: tuple[FloatArray, FloatArray],
    h: FloatArray,
    measured: tuple[FloatArray, float, float],
    work: Scratch,
) -> None:
    """The smoother's adjoint ``(lambda, Lambda)`` carried back through an update, in place:
    from after it to before it. ``measured``: the update's ``P H'`` (the prior's), ``S`` and
    innovation ``y``, as :func:`innovation` gave them."""
    lam, big = adjoint
    ph, s, y = measured
    w = work[3]
    n = lam.size
    # K = P H' / S;  lambda = (I - K H)' lambda - H' y / S = lambda - H' (K' lambda + y / S)
    a = y / s
    for i in range(n):
        a += ph[i] / s * lam[i]
    for i in range(n):
        lam[i] -= h[i] * a
    # Lambda = (I - K H)' Lambda (I - K H) + H' H / S
    #        = Lambda - H' (Lambda K)' - (Lambda K) H + H' H (K' Lambda K + 1 / S)
    b = 1.0 / s
    for i in range(n):
        total = 0.0
        for j in range(n):
            total += big[i, j] * ph[j] / s
        w[i] = total
        b += ph[i] / s * total
    for i in range(n):
        for j in range(n):
            big[i, j] += h[i] * (h[j] * b - w[j]) - w[i] * h[j]


@compiled_step
def pack(p: FloatArray, out: FloatArray) -> None:
    """The upper triangle of the symmetric ``p`` (n, n), row by row, into ``out``
    (n (n + 1) / 2): what a kept covariance costs, 28 numbers instead of 49 for n = 7."""
    n = p.shape[0]
    m = 0
    for i in range(n):
        for j in range(i, n):
            out[m] = p[i, j]
            m += 1


@compiled_step
def unpack(packed: FloatArray, out: FloatArray) -> None:
    """The symmetric matrix (n, n) of :func:`pack`'s ``packed``, into ``out``."""
    n = out.shape[0]
    m = 0
    for i in range(n):
        for j in range(i, n):
            out[i, j] = out[j, i] = packed[m]
            m += 1


@compiled_step
def restart(
    x: FloatArray, p: FloatArray, start: tuple[FloatArray, FloatArray], states: np.ndarray
) -> None:
    """The ``states`` (a mask) return to the prior ``start``, in place: their mean and
    covariance the prior's, uncorrelated with the rest (a transition with ``F = 0`` and
    ``Q`` the prior's covariance for them, the identity for the others)."""
    x0, p0 = start
    n = x.size
    # x_R = x0_R;  P_R. = P_.R = 0
    for i in range(n):
        if states[i]:
            x[i] = x0[i]
            for j in range(n):
                p[i, j] = p[j, i] = 0.0
    # P_RR = P0_RR
    for i in range(n):
        for j in range(n):
            if states[i] and states[j]:
                p[i, j] = p0[i, j]


@compiled_step
def adjoint_restart(adjoint: tuple[FloatArray, FloatArray], states: np.ndarray) -> None:
    """The adjoint carried back through :func:`restart`, in place: ``F = 0`` for the
    ``states``, so their entries of lambda and their rows and columns of Lambda vanish."""
    lam, big = adjoint
    n = lam.size
    # lambda = F' lambda, Lambda = F' Lambda F, with F the identity but F_RR = 0
    for i in range(n):
        if states[i]:
            lam[i] = 0.0
            for j in range(n):
                big[i, j] = big[j, i] = 0.0


@compiled_step
def adjoint_predict(adjoint: tuple[FloatArray, FloatArray], fl: Transition, work: Scratch) -> None:
    """The smoother's adjoint carried back through a transition, in place: from the prior at
    step k to the posterior at k - 1 (``F`` between them)."""
    lam, big = adjoint
    f, links, decaying = fl
    old, bf = work[3], work[0]
    n = lam.size
    # lambda = F' lambda = D (lambda + E' lambda)
    assign(old, lam)
    for e in range(links.shape[0]):
        i, k = links[e, 0], links[e, 1]
        lam[k] += f[i, k] * old[i]
    for c in decaying:
        lam[c] *= f[c, c]
    # Lambda = F' (Lambda F):  Lambda F = Lambda + Lambda E, then F' (Lambda F) adds E' (Lambda F)
    assign_matrix(bf, big)
    for e in range(links.shape[0]):
        i, k = links[e, 0], links[e, 1]
        for r in range(n):
            bf[r, k] += big[r, i] * f[i, k]
    assign_matrix(big, bf)
    for e in range(links.shape[0]):
        i, k = links[e, 0], links[e, 1]
        for c in range(n):
            big[k, c] += f[i, k] * bf[i, c]
    # then D (F' Lambda F) D
    scale_diagonal(big, f, decaying)


@compiled_step
def scale_diagonal(m: FloatArray, f: FloatArray, decaying: np.ndarray) -> None:
    """``D m D`` in place, for a symmetric ``m``: ``D`` the identity but for ``F``'s own entries
    ``f[c, c]`` of the ``decaying`` states."""
    for c in decaying:
        d = f[c, c]
        for j in range(m.shape[0]):
            m[c, j] *= d
            m[j, c] *= d


@compiled_step
def smoothed_variance(p: FloatArray, big: FloatArray, h: FloatArray, work: Scratch) -> float:
    """``H P_s H'`` of a row ``h``, from the filtered ``P`` and the adjoint's ``Lambda`` after it:
    ``H P H' - (P H')' Lambda (P H')``."""
    g = work[4]
    n = h.size
    # g = P H'
    for i in range(n):
        total = 0.0
        for j in range(n):
            total += p[i, j] * h[j]
        g[i] = total
    var = 0.0
    for i in range(n):
        total = 0.0
        for j in range(n):
            total += big[i, j] * g[j]
        var += h[i] * g[i] - g[i] * total
    return var
