"""altfuse.compiled: the loops numba compiles on a machine's first run are said, not silent."""

from __future__ import annotations

import logging
from collections.abc import Callable

import numba
import pytest

import altfuse.compiled  # noqa: F401 (registers the listener on numba's compile events)


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
