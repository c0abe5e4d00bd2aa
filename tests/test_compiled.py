"""altfuse.compiled: the loops numba compiles on a machine's first run are said, not silent;
they are kept where they can be, also where the install cannot be written."""

from __future__ import annotations

import logging
import os
import tempfile
import types
from collections.abc import Callable, Iterator
from pathlib import Path

import numba
import numpy as np
import pytest

import altfuse.compiled  # registers the listener on numba's compile events
from altfuse.compiled import compiled, compiled_loop, compiled_step


def _loop(module: str) -> Callable[[float], float]:
    """A loop numba has never compiled (not cached), as if of ``module``."""

    def add_one(x: float) -> float:
        return x + 1.0

    add_one.__module__ = module
    return numba.njit(add_one)  # type: ignore[no-any-return]


def test_the_first_compilation_of_a_modules_loops_is_said_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="altfuse.progress")
    assert _loop("altfuse.io.a_new_reader")(1.0) == 2.0
    said = [r.getMessage() for r in caplog.records if r.name == "altfuse.progress"]
    assert said == ["compiling altfuse.io.a_new_reader (numba, once per machine)"]
    caplog.clear()
    assert _loop("altfuse.io.a_new_reader")(2.0) == 3.0  # another loop of the same module
    assert _loop("someone_elses_package")(3.0) == 4.0  # not altfuse's: not ours to say
    assert not [r for r in caplog.records if r.name == "altfuse.progress"]


def _twice(x: float) -> float:
    return 2.0 * x


@pytest.fixture
def no_cache_choice(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """altfuse.compiled's choice of cache directory made afresh in the test, and forgotten."""
    monkeypatch.setattr(altfuse.compiled._CONFIG, "CACHE_DIR", "")
    altfuse.compiled.cache_dir.cache_clear()
    yield
    altfuse.compiled.cache_dir.cache_clear()


def _unwritable(*where: str) -> Callable[[Path], bool]:
    """altfuse.compiled._writable, but False for directories named as in ``where``."""
    writable = altfuse.compiled._writable
    return lambda d: d.name not in where and d.parent.name not in where and writable(d)


@pytest.mark.usefixtures("no_cache_choice")
def test_an_install_that_cannot_be_written_keeps_its_loops_in_the_users_cache(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # numba refused such an install at import ("cannot cache function ...: no locator
    # available") where the user had no writable home either
    monkeypatch.setattr(altfuse.compiled, "_writable", _unwritable("__pycache__"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    first = compiled(_twice)
    assert first(2.0) == 4.0
    kept = Path(first.stats.cache_path)  # type: ignore[attr-defined]
    digest = altfuse.compiled.sources_digest(Path(__file__).resolve().parent)
    assert kept.is_relative_to(tmp_path / "altfuse" / f"numba-{digest[:16]}")
    assert list(kept.glob("*.nbi")), "nothing cached"
    again = compiled(_twice)  # as the next process would: loaded, not compiled
    assert again(3.0) == 6.0
    assert sum(again.stats.cache_hits.values()) == 1  # type: ignore[attr-defined]


@pytest.mark.usefixtures("no_cache_choice")
def test_with_no_cache_directory_the_loops_are_compiled_and_that_is_said_once(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(altfuse.compiled, "_writable", lambda _d: False)
    caplog.set_level(logging.INFO, logger="altfuse")
    loops = []
    for module in ("altfuse.uncached_a", "altfuse.uncached_b"):
        loop = types.FunctionType(_twice.__code__, globals())
        loop.__module__ = module  # as if a loop of that module
        loops.append(compiled(loop))
    assert [loop(1.5) for loop in loops] == [3.0, 3.0]
    assert [loop.stats.cache_path for loop in loops] == [None, None]  # type: ignore[attr-defined]
    said = [(r.levelname, r.getMessage()) for r in caplog.records]
    assert said == [
        (
            "WARNING",
            "compiling altfuse's loops (numba) for this run only, as for every run: no cache "
            "directory can be written (NUMBA_CACHE_DIR names one)",
        )
    ]


def test_a_temporary_cache_directory_is_used_only_when_no_one_else_can_write_it(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(altfuse.compiled._CONFIG, "CACHE_DIR", "")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    mine = tmp_path / f"altfuse-{os.getuid()}"
    assert list(altfuse.compiled._cache_roots())[-1] == mine  # the last resort
    assert mine.stat().st_mode & 0o777 == 0o700
    mine.chmod(0o777)  # made by anyone, or open to them: their code would be loaded
    assert mine not in altfuse.compiled._cache_roots()
    mine.rmdir()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir(mode=0o700)
    mine.symlink_to(elsewhere)
    assert mine not in altfuse.compiled._cache_roots()
    if os.getuid() == 0:  # someone else's
        mine.unlink()
        mine.mkdir(mode=0o700)
        os.chown(mine, 65534, 65534)
        assert mine not in altfuse.compiled._cache_roots()


def _thrice(x: float) -> float:
    return 3.0 * x


@pytest.fixture
def users_cache(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Iterator[None]:
    """The loops kept under ``tmp_path`` (the install's ``__pycache__`` taken as unwritable),
    and what the caches could not do said afresh."""
    monkeypatch.setattr(altfuse.compiled._CONFIG, "CACHE_DIR", "")
    monkeypatch.setattr(altfuse.compiled, "_writable", _unwritable("__pycache__"))
    monkeypatch.setattr(altfuse.compiled, "_CACHE_FAILED", set(), raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    altfuse.compiled.cache_dir.cache_clear()
    yield
    altfuse.compiled.cache_dir.cache_clear()


def _said(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]


@pytest.mark.usefixtures("users_cache")
def test_a_loop_that_cannot_be_kept_is_compiled_and_that_is_said(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A full disk, or a home over its quota (a cluster's, where a site install keeps the loops
    in the user's cache): numba's saving raised, and every run failed ("the system refused:
    No space left on device")."""

    def full(*_args: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(numba.core.caching.IndexDataCacheFile, "_save_data", full)
    assert compiled(_thrice)(2.0) == 6.0
    assert compiled(_twice)(2.0) == 4.0  # a second loop: said once
    (said,) = _said(caplog)
    assert said.startswith("cannot keep altfuse's compiled loops in ")
    assert said.endswith(
        "(No space left on device): this run compiles them, and so will the next until that "
        "can be written"
    )


@pytest.mark.usefixtures("users_cache")
def test_a_damaged_index_is_compiled_again_and_kept_anew(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """An index file left empty (a power cut before the disk had it) made numba's loading
    raise EOFError, which click took for a Ctrl+D: every run ended "interrupted"."""
    first = compiled(_thrice)
    assert first(2.0) == 6.0
    indexes = list(Path(first.stats.cache_path).glob("*.nbi"))  # type: ignore[attr-defined]
    assert indexes, "nothing cached"
    for index in indexes:
        index.write_bytes(b"")
    again = compiled(_thrice)  # as the next process would
    assert again(3.0) == 9.0
    (said,) = _said(caplog)
    assert said.startswith("cannot read altfuse's compiled loops in ")
    assert said.endswith(
        "(EOFError: Ran out of input): this run compiles them again and keeps them anew"
    )
    healed = compiled(_thrice)  # and the one after: loaded
    assert healed(4.0) == 12.0
    assert sum(healed.stats.cache_hits.values()) == 1  # type: ignore[attr-defined]


def _doubled_sum(a: np.ndarray) -> float:
    return float((2.0 * a).sum())  # a temporary array


def _double_into(out: np.ndarray, a: np.ndarray, step: Callable[[float], float]) -> None:
    for i in range(a.size):
        out[i] = step(a[i])


@pytest.mark.usefixtures("users_cache")
def test_a_compiled_loop_counts_no_references_and_cannot_allocate() -> None:
    """A loop over a flight's events with numba's reference counts spent two thirds of its
    time on them; without them it must allocate nothing, and numba refuses one that would
    rather than run it with its memory unmanaged. Its steps run inlined into it, and alone."""
    a = np.array([1.0, 2.5, -4.0])
    out = np.zeros(3)
    step = compiled_step(_twice)
    compiled_loop(_double_into)(out, a, step)
    assert out.tolist() == [2.0, 5.0, -8.0]
    assert step(1.5) == 3.0
    with pytest.raises(numba.core.errors.NumbaError, match="NRT required but not enabled"):
        compiled_loop(_doubled_sum)(a)
    # managed, it may (first: numba keys a kept loop on its source, not on these options)
    assert compiled(_doubled_sum)(a) == -1.0
