"""The smoother's loops compiled by numba: a Python loop over a flight's events cost 138 us
an event (benchmarks/smoother_bench.py); compiled, with its steps in place, a few.

:func:`compiled`, :func:`compiled_loop` and :func:`compiled_step` are
:mod:`altfuse.compiled`'s (``numba.njit``, cached on disk).

numba keys a cached function on its own source file only: a kernel in ``passes.py`` compiled
with the steps of ``kalman.py`` stays cached when only ``kalman.py`` changes, and would run the
old steps. So the cache in this package's ``__pycache__`` is kept for one version of the
package's sources (:func:`_forget_other_versions`, at import); a cache kept elsewhere is named
after them (:func:`altfuse.compiled.cache_dir`).
"""

from __future__ import annotations

from pathlib import Path

from altfuse.compiled import compiled, compiled_loop, compiled_step, sources_digest

__all__ = ["compiled", "compiled_loop", "compiled_step"]

_HERE = Path(__file__).resolve().parent
_STAMP = "altfuse-sources.sha256"


def _forget_other_versions(package: Path = _HERE) -> None:
    """Remove numba's cache files from ``package/__pycache__`` unless they were made from the
    package's present sources (a digest of its ``.py`` files, kept beside them)."""
    digest = sources_digest(package)
    cache = package / "__pycache__"
    stamp = cache / _STAMP
    try:
        if stamp.read_text() == digest:
            return
    except OSError:
        pass
    try:
        cache.mkdir(exist_ok=True)
        for old in [*cache.glob("*.nbi"), *cache.glob("*.nbc")]:
            old.unlink(missing_ok=True)
        stamp.write_text(digest)
    except OSError:  # a read-only install: the cache is kept elsewhere, or nowhere
        pass


_forget_other_versions()
