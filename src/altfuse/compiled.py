"""Loops compiled by numba, where numpy cannot say them without a Python loop: the smoother's
passes over a flight's events, the DataFlash reader's walk along its record chain.

:func:`compiled` is ``numba.njit`` with its compilation cached on disk (the first run on a
machine compiles, for some seconds; later ones load it), typed for mypy. numba keys a cached
function on its own source file: a kernel that calls functions of another file must have its
cache forgotten when that file changes (:mod:`altfuse.fuse.smoother.compiled` does so for its
package).

The first run on a machine compiles them, 20-25 s where loading them takes a fraction of a
second; so that it does not pass in silence, each module whose loops are being compiled is
said once per process on the ``altfuse.progress`` logger (the progress line of ``altfuse
fuse`` on a terminal, a line with ``-v``), by a listener on numba's compile events
(:class:`_Compiling`, registered at import): numba broadcasts them only where nothing was
cached, never when it loads a loop.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba
from numba.core import event

F = TypeVar("F", bound=Callable[..., Any])


def compiled(function: F) -> F:
    """``function`` compiled to machine code (nopython mode, cached), releasing the GIL while
    it runs (the reader hashes the file in a thread meanwhile)."""
    return cast(F, numba.njit(cache=True, nogil=True)(function))


class _Compiling(event.Listener):
    """Says on ``altfuse.progress`` which of altfuse's modules numba compiles loops of, once
    per module: at the start of each outermost compilation (one loop compiles the loops it
    calls within its own), of a loop of altfuse's."""

    def __init__(self) -> None:
        self.depth = 0
        self.said: set[str] = set()

    def on_start(self, ev: event.Event) -> None:
        self.depth += 1
        # a listener that raised would fail the compilation, and the run with it
        module = str(getattr(getattr(ev.data.get("dispatcher"), "py_func", None), "__module__", ""))
        if self.depth == 1 and module.startswith("altfuse") and module not in self.said:
            self.said.add(module)
            logging.getLogger("altfuse.progress").info(
                "compiling %s (numba, once per machine)", module
            )

    def on_end(self, _ev: event.Event) -> None:
        self.depth -= 1


event.register("numba:compile", _Compiling())  # type: ignore[no-untyped-call]
