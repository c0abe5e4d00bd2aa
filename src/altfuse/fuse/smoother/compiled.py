"""The smoother's loops compiled by numba: a Python loop over a flight's events cost 140 us
an event; compiled, the same arithmetic runs at the speed of C.

:func:`compiled` is ``numba.njit`` with its compilation cached on disk (the first run on a
machine compiles, for some seconds; later ones load it), typed for mypy.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba
import numpy as np

from altfuse.model import FloatArray

F = TypeVar("F", bound=Callable[..., Any])


def compiled(function: F) -> F:
    """``function`` compiled to machine code (nopython mode, cached)."""
    return cast(F, numba.njit(cache=True)(function))


# Small dense linear algebra, as loops: for the smoother's 6-12 states a call into BLAS or
# LAPACK costs more than the arithmetic (measured: 2.7 us an event and pass with them).


@compiled
def matmul(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a @ b`` for 2-D arrays."""
    rows, inner, cols = a.shape[0], a.shape[1], b.shape[1]
    out = np.zeros((rows, cols))
    for i in range(rows):
        for k in range(inner):
            aik = a[i, k]
            if aik != 0.0:
                for j in range(cols):
                    out[i, j] += aik * b[k, j]
    return out


@compiled
def matvec(a: FloatArray, v: FloatArray) -> FloatArray:
    """``a @ v`` for a 2-D ``a`` and a 1-D ``v``."""
    out = np.zeros(a.shape[0])
    for i in range(a.shape[0]):
        total = 0.0
        for k in range(a.shape[1]):
            total += a[i, k] * v[k]
        out[i] = total
    return out


@compiled
def dot(u: FloatArray, v: FloatArray) -> float:
    """``u @ v`` for 1-D arrays."""
    total = 0.0
    for i in range(u.size):
        total += u[i] * v[i]
    return total


@compiled
def solve_spd(a: FloatArray, b: FloatArray) -> FloatArray:
    """``x`` with ``a x = b`` for a symmetric positive definite ``a`` (Cholesky, ``a = L L'``)
    and a 2-D ``b``."""
    n = a.shape[0]
    low = np.zeros((n, n))
    for j in range(n):
        d = a[j, j]
        for k in range(j):
            d -= low[j, k] * low[j, k]
        low[j, j] = np.sqrt(d)
        for i in range(j + 1, n):
            s = a[i, j]
            for k in range(j):
                s -= low[i, k] * low[j, k]
            low[i, j] = s / low[j, j]
    x: FloatArray = b.copy()
    for c in range(b.shape[1]):
        for i in range(n):  # L y = b
            s = x[i, c]
            for k in range(i):
                s -= low[i, k] * x[k, c]
            x[i, c] = s / low[i, i]
        for i in range(n - 1, -1, -1):  # L' x = y
            s = x[i, c]
            for k in range(i + 1, n):
                s -= low[k, i] * x[k, c]
            x[i, c] = s / low[i, i]
    return x
