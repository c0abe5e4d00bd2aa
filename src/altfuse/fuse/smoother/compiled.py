"""The smoother's loops compiled by numba: a Python loop over a flight's events cost 138 us
an event (benchmarks/smoother_bench.py); compiled, with its steps in place, a few.

:func:`compiled` is ``numba.njit`` with its compilation cached on disk (the first run on a
machine compiles, for some seconds; later ones load it), typed for mypy.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba

F = TypeVar("F", bound=Callable[..., Any])


def compiled(function: F) -> F:
    """``function`` compiled to machine code (nopython mode, cached)."""
    return cast(F, numba.njit(cache=True)(function))
