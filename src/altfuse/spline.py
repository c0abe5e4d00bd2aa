"""The cubic interpolating spline with not-a-knot ends: scipy's ``CubicSpline(x, y)`` (its
default ``bc_type``), solved and evaluated in one compiled loop.

scipy's ``interpolate`` package costs 0.2-0.36 s to import (it loads ``optimize`` and
``special``), a sixth of ``altfuse fuse`` on a small log, for this one spline. The equations
are scipy's (``scipy/interpolate/_cubic.py``): the slope ``s_i`` at each knot solves, for
``i = 1 .. n-2``, with ``dx_i = x_{i+1} - x_i`` and ``m_i = (y_{i+1} - y_i) / dx_i``::

    dx_i s_{i-1} + 2 (dx_{i-1} + dx_i) s_i + dx_{i-1} s_{i+1} = 3 (dx_i m_{i-1} + dx_{i-1} m_i)

and at each end "not a knot" (the third derivative continuous across the second knot)::

    dx_1 s_0 + (dx_0 + dx_1) s_1 = ((dx_0 + 2 d) dx_1 m_0 + dx_0^2 m_1) / d,   d = x_2 - x_0

(and its mirror at the end). The tridiagonal system is solved by elimination without pivoting
(its pivots stay positive: the first row's is ``dx_1``, the second's after it ``dx_0 + dx_1``;
scipy pivots, LAPACK's ``gbsv``); each interval is then the cubic Hermite polynomial of its
ends' values and slopes. Two knots give the line, three the parabola through them (as scipy).
``tests/test_spline.py`` checks it against scipy to 1e-9 of the data's range.
"""

from __future__ import annotations

import numpy as np

from altfuse.compiled import compiled
from altfuse.model import FloatArray


def cubic_spline(x: FloatArray, y: FloatArray, at: FloatArray) -> FloatArray:
    """The not-a-knot cubic spline through ``(x, y)`` (``x`` strictly increasing, at least two
    knots) at ``at``; beyond the knots, the end intervals' polynomials extended."""
    if x.size < 2:
        raise ValueError("a spline needs at least two knots")
    return _spline(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(y, dtype=float),
                   np.ascontiguousarray(at, dtype=float))  # fmt: skip


@compiled
def _slopes(x: FloatArray, y: FloatArray) -> FloatArray:
    """The spline's first derivative at each knot (see the module doc)."""
    n = x.size
    dx = x[1:] - x[:-1]
    m = (y[1:] - y[:-1]) / dx
    s = np.empty(n)
    if n == 2:  # the line
        s[:] = m[0]
        return s
    if n == 3:  # the parabola through the three knots
        curvature = (m[1] - m[0]) / (x[2] - x[0])
        s[0] = m[0] - curvature * dx[0]
        s[1] = m[0] + curvature * dx[0]
        s[2] = m[1] + curvature * dx[1]
        return s
    lower, diag, upper, rhs = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    for i in range(1, n - 1):
        lower[i], diag[i], upper[i] = dx[i], 2.0 * (dx[i - 1] + dx[i]), dx[i - 1]
        rhs[i] = 3.0 * (dx[i] * m[i - 1] + dx[i - 1] * m[i])
    d = x[2] - x[0]
    diag[0], upper[0] = dx[1], d
    rhs[0] = ((dx[0] + 2.0 * d) * dx[1] * m[0] + dx[0] ** 2 * m[1]) / d
    d = x[n - 1] - x[n - 3]
    lower[n - 1], diag[n - 1] = d, dx[n - 3]
    rhs[n - 1] = (dx[n - 2] ** 2 * m[n - 3] + (2.0 * d + dx[n - 2]) * dx[n - 3] * m[n - 2]) / d
    # elimination down the rows, then substitution back up
    for i in range(1, n):
        w = lower[i] / diag[i - 1]
        diag[i] -= w * upper[i - 1]
        rhs[i] -= w * rhs[i - 1]
    s[n - 1] = rhs[n - 1] / diag[n - 1]
    for i in range(n - 2, -1, -1):
        s[i] = (rhs[i] - upper[i] * s[i + 1]) / diag[i]
    return s


@compiled
def _spline(x: FloatArray, y: FloatArray, at: FloatArray) -> FloatArray:
    """:func:`cubic_spline`, compiled."""
    s = _slopes(x, y)
    out = np.empty(at.size)
    last = x.size - 2
    for k in range(at.size):
        i = min(max(np.searchsorted(x, at[k], side="right") - 1, 0), last)
        h = x[i + 1] - x[i]
        m = (y[i + 1] - y[i]) / h
        # the Hermite cubic of the interval: y_i + s_i u + c2 u^2 + c3 u^3, u = at - x_i
        t = (s[i] + s[i + 1] - 2.0 * m) / h
        c3, c2 = t / h, (m - s[i]) / h - t
        u = at[k] - x[i]
        out[k] = ((c3 * u + c2) * u + s[i]) * u + y[i]
    return out
