"""The C heap's free memory given back to the system between the stages of a run, and one
heap for all of a process's threads.

numpy takes an array's memory from the C allocator; glibc's keeps what is freed for later
arrays instead of returning it, once its threshold for mapping a block apart has risen (to
32 MB: every per-event array of a 7-hour log, 6 MB each, then comes from the heap), and a
fragmented heap is not given back. On the 300 MB benchmark log a smoother run held 100 MB
more than it used; ``malloc_trim`` at the stages' ends returned 40 MB of the peak, at no
measurable cost (paired runs). Dask's workers deal with the same (their
``MALLOC_TRIM_THRESHOLD_``); setting glibc's thresholds instead cost 10-25 % of the run's time,
every array of a big log then mapped and faulted in anew. Threads take their memory from heaps
of their own, whose holes neither the trim nor the next stage reaches: :func:`one_heap`.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from functools import cache


@cache
def _libc(name: str) -> Callable[..., int] | None:
    """glibc's function ``name``, where the process has it (not on macOS, Windows or musl)."""
    try:
        found: Callable[..., int] | None = getattr(ctypes.CDLL(None), name, None)
    except OSError:
        return None
    return found


def release_free_memory() -> None:
    """Give the C heap's free pages back to the system, where the C library can."""
    trim = _libc("malloc_trim")
    if trim is not None:
        trim(0)


#: mallopt's parameter for the most heaps ("arenas") glibc's allocator keeps (malloc.h).
_M_ARENA_MAX = -8


def one_heap() -> None:
    """Have every thread of the process take its memory from one C heap, where the C library
    can (glibc's ``MALLOC_ARENA_MAX=1``). glibc gives a thread that allocates a heap of its
    own ("arena"), up to eight per core; the smoother's likelihood passes run in
    threads, each filling its arrays from its thread's heap, and the holes they leave there
    are neither given back by ``malloc_trim`` nor reused by the next stage's arrays. Set
    before the first thread starts (the command line's start)."""
    mallopt = _libc("mallopt")
    if mallopt is not None:
        mallopt(_M_ARENA_MAX, 1)
