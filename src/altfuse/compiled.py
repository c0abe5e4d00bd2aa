"""Loops compiled by numba, where numpy cannot say them without a Python loop: the smoother's
passes over a flight's events, the DataFlash reader's walk along its record chain.

:func:`compiled` is ``numba.njit`` with its compilation cached on disk (the first run on a
machine compiles, for some seconds; later ones load it), typed for mypy. numba keys a cached
function on its own source file: a kernel that calls functions of another file must have its
cache forgotten when that file changes (:mod:`altfuse.fuse.smoother.compiled` does so for its
package).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba

F = TypeVar("F", bound=Callable[..., Any])


def compiled(function: F) -> F:
    """``function`` compiled to machine code (nopython mode, cached), releasing the GIL while
    it runs (the reader hashes the file in a thread meanwhile)."""
    return cast(F, numba.njit(cache=True, nogil=True)(function))
