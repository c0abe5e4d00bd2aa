"""Giving the C heap's free memory back between stages (:mod:`altfuse.memory`)."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest

from altfuse.memory import release_free_memory

STATUS = Path("/proc/self/status")


def anonymous_mb() -> float:
    """The process's resident anonymous memory [MB] (Linux)."""
    line = next(x for x in STATUS.read_text().splitlines() if x.startswith("RssAnon:"))
    return int(line.split()[1]) / 1024


@pytest.mark.skipif(
    not STATUS.exists() or getattr(ctypes.CDLL(None), "malloc_trim", None) is None,
    reason="glibc on Linux only",
)
def test_freed_arrays_in_a_fragmented_heap_go_back_to_the_system() -> None:
    # a freed block raises glibc's threshold for mapping a block apart: the arrays after it
    # come from the heap, and one kept between two freed ones keeps the heap from shrinking
    block = np.ones(2**20 // 8 * 4)  # 4 MB, mapped apart
    del block
    arrays = [np.ones(2**20 // 8) for _ in range(300)]  # 300 x 1 MB, from the heap
    kept = arrays[1::2]
    arrays.clear()  # every other one freed
    before = anonymous_mb()
    release_free_memory()
    assert before - anonymous_mb() > 100
    assert sum(float(a[0]) for a in kept) == len(kept)  # the arrays kept are intact
