"""The smoother's loops compiled by numba: a Python loop over a flight's events cost 138 us
an event (benchmarks/smoother_bench.py); compiled, with its steps in place, a few.

:func:`compiled` is :func:`altfuse.compiled.compiled` (``numba.njit``, cached on disk).

numba keys a cached function on its own source file only: a kernel in ``passes.py`` compiled
with the steps of ``kalman.py`` stays cached when only ``kalman.py`` changes, and would run the
old steps. So the cache in this package's ``__pycache__`` is kept for one version of the
package's sources (:func:`_forget_other_versions`, at import).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from altfuse.compiled import compiled

__all__ = ["compiled"]

_HERE = Path(__file__).resolve().parent
_STAMP = "altfuse-sources.sha256"


def _forget_other_versions(package: Path = _HERE) -> None:
    """Remove numba's cache files from ``package/__pycache__`` unless they were made from the
    package's present sources (a digest of its ``.py`` files, kept beside them)."""
    digest = hashlib.sha256()
    for source in sorted(package.glob("*.py")):
        digest.update(source.name.encode() + b"\0" + source.read_bytes())
    cache = package / "__pycache__"
    stamp = cache / _STAMP
    try:
        if stamp.read_text() == digest.hexdigest():
            return
    except OSError:
        pass
    try:
        cache.mkdir(exist_ok=True)
        for old in [*cache.glob("*.nbi"), *cache.glob("*.nbc")]:
            old.unlink(missing_ok=True)
        stamp.write_text(digest.hexdigest())
    except OSError:  # a read-only install: numba caches per user elsewhere, or compiles
        pass


_forget_other_versions()
