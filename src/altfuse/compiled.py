"""Loops compiled by numba, where numpy cannot say them without a Python loop: the smoother's
passes over a flight's events, the DataFlash reader's walk along its record chain.

:func:`compiled` is ``numba.njit`` with its compilation cached on disk (the first run on a
machine compiles, for some seconds; later ones load it), typed for mypy. A loop over hundreds
of thousands of events takes :func:`compiled_loop`, and the steps it calls
:func:`compiled_step`: numba counts the references of every array a compiled function holds,
each count an atomic instruction, and its pass that prunes them cannot across a loop's
branches (numba issue 2350). On the smoother's forward pass over the 300 MB log's 791,616
events they took half its 0.34 s; with its steps inlined, still 69 an event and 70 % of its
0.23 s; without them it takes 0.094 s, to the same numbers to the last bit.

numba keys a cached function on its own source file: a kernel that calls functions of another
file must have its cache forgotten when that file changes (:mod:`altfuse.fuse.smoother.compiled`
does so for its package), and on none of the options that tell :func:`compiled_loop` and
:func:`compiled_step` from :func:`compiled`: a function is decorated one way only.

The first run on a machine compiles them, 20-25 s where loading them takes a fraction of a
second; so that it does not pass in silence, each module whose loops are being compiled is
said once per process on the ``altfuse.progress`` logger (the progress line of ``altfuse
fuse`` on a terminal, a line with ``-v``), by a listener on numba's compile events
(:class:`_Compiling`, registered at import): numba broadcasts them only where nothing was
cached, never when it loads a loop.

Where the cache is kept (:func:`cache_dir`): numba's own place, the ``__pycache__`` beside the
source, where that can be written. An install the user cannot write (a system's
``site-packages``, a container's image run as another user) with no writable home made numba
refuse at import: "RuntimeError: cannot cache function '_slopes': no locator available", every
command an internal error (numba issues 4908, 5566). There the loops are kept in a directory
of altfuse's own, named after a digest of their package's sources (a loop compiled with
another file's functions must not outlive a change to them), under ``NUMBA_CACHE_DIR`` where
the user set it, else the user's cache directory, else the system's temporary one (a directory
of the user's own, no one else's to write); with none writable they are compiled by each
process, and that is said as a warning. A cache that cannot be written after all (a full disk,
a quota) or read (a damaged file) is said as well, and compiled around (:func:`_tolerant`).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import inspect
import logging
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar, cast

import numba
from numba.core import event

from altfuse.signals import interruption

F = TypeVar("F", bound=Callable[..., Any])
#: numba's settings (set from its environment variables at its import, untyped)
_CONFIG: Any = numba.config


def compiled(function: F) -> F:
    """``function`` compiled to machine code (nopython mode, cached in :func:`cache_dir`),
    releasing the GIL while it runs (the reader hashes the file in a thread meanwhile)."""
    return _compiled(function, {})


def compiled_loop(function: F) -> F:
    """:func:`compiled` without numba's reference counts (its ``_nrt=False``, as numba's own
    string kernels): for a loop that allocates nothing (its caller hands it every array it
    works in, whose references the caller holds) and takes no array apart but for views it
    drops (a row, a slice copied element by element). numba refuses to compile one that
    would allocate ("NRT required but not enabled")."""
    return _compiled(function, {"_nrt": False})


def compiled_step(function: F) -> F:
    """A step of a :func:`compiled_loop`: inlined into the loop that calls it (numba's
    ``inline="always"``: a call's array arguments are references counted as well), and called
    alone (a test, another kernel) compiled as one."""
    return _compiled(function, {"_nrt": False, "inline": "always"})


def _compiled(function: F, options: dict[str, Any]) -> F:
    """``function`` as :func:`compiled` makes it, with numba's further ``options``."""
    directory = cache_dir(Path(inspect.getfile(function)).resolve().parent)
    if directory is None:
        _UNCACHED.add(function.__module__)
        return cast(F, numba.njit(nogil=True, **options)(function))
    with _numba_cache_dir(directory):  # numba reads it once, when the function is decorated
        dispatcher = numba.njit(cache=True, nogil=True, **options)(function)
    _tolerant(getattr(dispatcher, "_cache", None))
    return cast(F, dispatcher)


def _tolerant(cache: Any) -> None:
    """numba's ``cache`` of one loop made a saving of time and no more: a loop it cannot keep
    (a full disk, a home over its quota: on Linux numba raises) is compiled by each run, and a
    kept one it cannot read (an empty or damaged file) is compiled again, each said once per
    process (:func:`_said`). Before, a full disk failed every run ("the system refused: No space
    left on device"), and an empty index file every run after it ("interrupted", numba's
    EOFError). A numba whose cache lacks these two methods keeps its own ways."""
    load = getattr(cache, "load_overload", None)
    save = getattr(cache, "save_overload", None)
    if load is None or save is None:
        return

    def load_or_compile(sig: Any, target_context: Any) -> Any:
        try:
            return load(sig, target_context)
        except Exception as exc:
            if interruption(exc) is not None:  # a signal's, out of numba's callbacks
                raise
            _said("read", cache, exc)
            if not isinstance(exc, OSError):  # read but damaged: numba reads the index to save
                _forget_index(cache)
            return None  # as if nothing were kept: numba compiles it, and keeps it anew

    def save_or_say(sig: Any, data: Any) -> None:
        try:
            save(sig, data)
        except Exception as exc:
            if interruption(exc) is not None:
                raise
            _said("keep", cache, exc)

    cache.load_overload = load_or_compile
    cache.save_overload = save_or_say


def _forget_index(cache: Any) -> None:
    """Remove the index file of numba's ``cache`` (``_cache_file._index_path``, where this numba
    has it): numba reads the index before it keeps anything, so a damaged one would stop every
    later run from keeping the loop again."""
    index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    if isinstance(index, str):
        with contextlib.suppress(OSError):
            os.unlink(index)


#: What a cache could not do, said once per process: "read", "keep".
_CACHE_FAILED: set[str] = set()


def _said(what: str, cache: Any, exc: Exception) -> None:
    """Say once per process that the compiled loops in ``cache``'s folder could not be read
    or kept (``what``), and why (``exc``)."""
    if what in _CACHE_FAILED:
        return
    _CACHE_FAILED.add(what)
    why = (
        exc.strerror
        if isinstance(exc, OSError) and exc.strerror
        else f"{type(exc).__name__}: {exc}"
    )
    where = getattr(cache, "cache_path", None) or "numba's cache"
    logging.getLogger("altfuse").warning(
        "cannot %s altfuse's compiled loops in %s (%s): %s",
        what,
        where,
        why,
        "this run compiles them again and keeps them anew"
        if what == "read"
        else "this run compiles them, and so will the next until that can be written",
    )


@functools.cache
def cache_dir(package: Path) -> str | None:
    """Where numba keeps the compiled loops of ``package`` (a directory of sources), as numba's
    ``CACHE_DIR``: "" (numba's own choice, ``package/__pycache__``) where that can be written;
    else a directory named after :func:`sources_digest` under the first of ``NUMBA_CACHE_DIR``,
    the user's cache directory and the system's temporary one that can be; None where none can
    (module docstring)."""
    if not _CONFIG.CACHE_DIR and _writable(package / "__pycache__"):
        return ""
    kept = f"numba-{sources_digest(package)[:16]}"
    for root in _cache_roots():
        if _writable(root / kept):
            return str(root / kept)
    return None


def sources_digest(package: Path) -> str:
    """sha256 of the ``.py`` files of ``package``, names and contents, in name order."""
    digest = hashlib.sha256()
    for source in sorted(package.glob("*.py")):
        digest.update(source.name.encode() + b"\0" + source.read_bytes())
    return digest.hexdigest()


def _cache_roots() -> Iterator[Path]:
    """The directories altfuse may keep compiled loops in, by preference (:func:`cache_dir`)."""
    if _CONFIG.CACHE_DIR:
        yield Path(_CONFIG.CACHE_DIR) / "altfuse"
    home = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    if os.path.isabs(home):  # "~" unexpanded: no home known
        yield Path(home) / "altfuse"
    shared = Path(tempfile.gettempdir()) / f"altfuse-{_uid()}"
    with contextlib.suppress(OSError):
        shared.mkdir(mode=0o700, exist_ok=True)
        mine = shared.lstat()
        # a directory of the shared temporary one that someone else made or can write holds
        # code of theirs: numba would load it
        if not os.path.islink(shared) and mine.st_uid == _uid() and not mine.st_mode & 0o077:
            yield shared


def _writable(directory: Path) -> bool:
    """Whether ``directory`` exists or can be made, and a file can be made in it (numba's own
    test of a cache directory)."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=directory).close()
    except OSError:
        return False
    return True


def _uid() -> int:
    """The user's id (0 where the system has none: Windows, whose temporary folder is the
    user's own)."""
    return os.getuid() if hasattr(os, "getuid") else 0


@contextlib.contextmanager
def _numba_cache_dir(directory: str) -> Iterator[None]:
    """numba's ``CACHE_DIR`` set to ``directory`` meanwhile."""
    before = _CONFIG.CACHE_DIR
    _CONFIG.CACHE_DIR = directory
    try:
        yield
    finally:
        _CONFIG.CACHE_DIR = before


#: The modules with loops that :func:`compiled` could keep nowhere: compiled by every process.
_UNCACHED: set[str] = set()


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
            if module in _UNCACHED:  # one line for them all
                if not self.said & _UNCACHED - {module}:
                    logging.getLogger("altfuse").warning(
                        "compiling altfuse's loops (numba) for this run only, as for every run: "
                        "no cache directory can be written (NUMBA_CACHE_DIR names one)"
                    )
            else:
                logging.getLogger("altfuse.progress").info(
                    "compiling %s (numba, once per machine)", module
                )

    def on_end(self, _ev: event.Event) -> None:
        self.depth -= 1


event.register("numba:compile", _Compiling())  # type: ignore[no-untyped-call]
