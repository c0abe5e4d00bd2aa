"""Giving the C heap's free memory back between stages (:mod:`altfuse.memory`)."""

from __future__ import annotations

import ctypes
import subprocess
import sys
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


HEAPS = """
import ctypes, sys, tempfile, threading
import numpy as np
from altfuse.memory import one_heap
if sys.argv[1] == "one":
    one_heap()
kept = []
threads = [threading.Thread(target=lambda: kept.append(np.ones(1000))) for _ in range(3)]
for thread in threads:
    thread.start()
for thread in threads:
    thread.join()
libc = ctypes.CDLL(None)
libc.fopen.restype = ctypes.c_void_p
with tempfile.NamedTemporaryFile(suffix=".xml") as out:
    stream = libc.fopen(out.name.encode(), b"w")
    libc.malloc_info(0, ctypes.c_void_p(stream))
    libc.fclose(ctypes.c_void_p(stream))
    print(open(out.name).read().count("<heap nr="))
"""


@pytest.mark.skipif(getattr(ctypes.CDLL(None), "malloc_info", None) is None, reason="glibc only")
def test_threads_take_their_memory_from_one_heap() -> None:
    """glibc gives each new thread that allocates a heap of its own; after ``one_heap`` the
    threads share the first (the smoother's passes in threads: :func:`altfuse.memory.one_heap`)."""
    heaps = {
        how: int(subprocess.run(
            [sys.executable, "-c", HEAPS, how], capture_output=True, text=True, check=True
        ).stdout)
        for how in ("one", "default")
    }  # fmt: skip
    assert heaps["one"] == 1
    assert heaps["default"] > 1, heaps
