"""The C heap's free memory given back to the system between the stages of a run.

numpy takes an array's memory from the C allocator; glibc's keeps what is freed for later
arrays instead of returning it, once its threshold for mapping a block apart has risen (to
32 MB: every per-event array of a 7-hour log, 6 MB each, then comes from the heap), and a
fragmented heap is not given back. On the 300 MB benchmark log a smoother run held 100 MB
more than it used; ``malloc_trim`` at the stages' ends returned 40 MB of the peak, at no
measurable cost (paired runs). Dask's workers deal with the same (their
``MALLOC_TRIM_THRESHOLD_``); setting glibc's thresholds instead cost 10-25 % of the run's time,
every array of a big log then mapped and faulted in anew.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from functools import cache


@cache
def _trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim``, where the process has it (not on macOS, Windows or musl)."""
    try:
        trim: Callable[[int], int] | None = getattr(ctypes.CDLL(None), "malloc_trim", None)
    except OSError:
        return None
    return trim


def release_free_memory() -> None:
    """Give the C heap's free pages back to the system, where the C library can."""
    trim = _trim()
    if trim is not None:
        trim(0)
