"""Shared fixtures: the real logs, the sample log, and synthetic flights with known truth."""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from altfuse.model import FloatArray

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_LOG = ROOT / "sample_logs" / "mission.bin"
SHARED_LOGS = Path(os.environ.get("ALTFUSE_SHARED_LOGS", ROOT.parent / "shared" / "logs"))


def shared_log(relative: str) -> Path:
    """Path of a log in ../shared/logs; skips the test if absent, or fails it under CI's
    ``ALTFUSE_REQUIRE_SHARED_LOGS=1``."""
    path = SHARED_LOGS / relative
    if not path.exists():
        message = (
            f"needs the real logs in ../shared/logs, beside the clone (no folder {SHARED_LOGS}; "
            "README: Setup)"
            if not SHARED_LOGS.is_dir()
            else f"{relative} not found in {SHARED_LOGS}"
        )
        if os.environ.get("ALTFUSE_REQUIRE_SHARED_LOGS") == "1":
            pytest.fail(message)
        pytest.skip(message)
    return path


def ardupilot_logs() -> list[str]:
    folder = SHARED_LOGS / "ardupilot"
    return sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []


@dataclass(frozen=True)
class PaperAFlight:
    """Paper A's experiment (ALGORITHMS.md section 2): 400 ticks at 10 Hz near 15 m."""

    truth: FloatArray
    z: FloatArray  # (400, 3): gps, baro, sonar, already referred to the take-off point
    names: ClassVar[tuple[str, ...]] = ("gps", "baro", "sonar")
    agree: ClassVar[slice] = slice(0, 136)  # samples 1-136: the sensors agree
    baro_departs: ClassVar[slice] = slice(136, 255)  # samples 137-255: the barometer departs
    scatter: ClassVar[slice] = slice(255, 400)  # samples 256-400: all scatter, sonar steadiest


def paper_a_flight(seed: int = 7) -> PaperAFlight:
    """A seeded synthetic version of Paper A's level flight (Table 1, Fig. 3-5).

    Level flight near 15 m with a slow 0.3 m wander. Regime 1: GPS sigma 0.15 m, baro 0.10 m,
    sonar 0.05 m. Regime 2: the barometer departs, ramping to +2.5 m and back (sigma 0.25 m).
    Regime 3: every sensor scatters (GPS sigma 0.6 m, baro 0.5 m), the sonar least (0.12 m).
    """
    rng = np.random.default_rng(seed)
    n = 400
    k = np.arange(n)
    truth = 15.0 + 0.3 * np.sin(2 * np.pi * k / 160.0)
    sigma = np.empty((n, 3))
    sigma[:136] = (0.15, 0.10, 0.05)
    sigma[136:255] = (0.15, 0.25, 0.05)
    sigma[255:] = (0.60, 0.50, 0.12)
    z = truth[:, None] + rng.normal(0.0, 1.0, (n, 3)) * sigma
    departure = 2.5 * np.sin(np.pi * (k[136:255] - 136) / 119.0)
    z[136:255, 1] += departure
    return PaperAFlight(truth=truth, z=z)


#: The ``altfuse`` logger as the session found it: handlers, level, propagation.
_LOGGER = logging.getLogger("altfuse")
_PRISTINE = (_LOGGER.handlers[:], _LOGGER.level, _LOGGER.propagate)


@pytest.fixture(autouse=True)
def _altfuse_logger_restored() -> Iterator[None]:
    """The ``altfuse`` logger as the session found it, after each test: a command run in the
    test's process (``CliRunner``) sets its handler, level and propagation for its own stderr,
    which later tests' ``caplog`` would otherwise miss (pytest before 9 sees no record of a
    logger that does not propagate). As the session found it, not as the test did: a session
    fixture is set up before this one, and its command's setup was kept for every later test."""
    yield
    _LOGGER.handlers[:], _LOGGER.level, _LOGGER.propagate = _PRISTINE[0][:], *_PRISTINE[1:]


@pytest.fixture(scope="session")
def long_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 900 s hover written as ``altfuse simulate`` writes it, once per session: the input of
    runs long enough to be signalled or hung up midway (altfuse never writes to its input).
    Written through the library, not the command, whose logging setup would be the test's that
    first asks for it (its logger no longer propagating; before :func:`_altfuse_logger_restored`
    restored the session's, every later test's ``caplog`` saw nothing with pytest before 9:
    the four tests of ``test_compiled.py`` on the lowest versions)."""
    from altfuse.simulate import simulate_flight, write_simulated_log

    log = tmp_path_factory.mktemp("long") / "long.bin"
    write_simulated_log(simulate_flight("hover", duration_s=900.0), log)
    return log


@pytest.fixture
def paper_a() -> PaperAFlight:
    return paper_a_flight()


@dataclass(frozen=True)
class HoverFlight:
    """Paper B's experiment: a hover at 240 m, on a 10 Hz clock."""

    truth: FloatArray
    z: FloatArray  # (T, 2): baro, GPS, referred to the same datum as the truth
    accel_up: FloatArray  # earth-frame vertical acceleration less the at-rest reading
    dt_s: float = 0.1


def hover_flight(seed: int = 5, duration_s: float = 120.0) -> HoverFlight:
    """A seeded hover at 240 m with the noise of a real Pixhawk and a noisy start.

    Truth: 240 m with the slow wander of a position hold (0.3 m, 20 s). Barometer: 0.4 m white
    noise and a 0.3 m/min drift; GPS: 0.7 m white noise plus a slow random walk (0.02 m per
    tick). For the first ~10 s both are noisier (x4 decaying with a 4 s time constant): the
    warm-up the paper reports. Accelerometer: 50 Hz samples with 0.3 m/s² noise and a 0.05 m/s²
    bias, averaged onto the clock, less the at-rest reading the paper subtracts (taken on 200
    samples before the flight, so 0.02 m/s² of bias error remains, at random).
    """
    rng = np.random.default_rng(seed)
    dt = 0.1
    t = np.arange(0.0, duration_s, dt)
    w = 2 * np.pi / 20.0
    truth = 240.0 + 0.3 * np.sin(w * t)
    start = 1 + 3 * np.exp(-t / 4.0)
    baro = truth + 0.3 / 60.0 * t + rng.normal(0.0, 0.4, t.size) * start
    gps = truth + np.cumsum(rng.normal(0.0, 0.02, t.size)) + rng.normal(0.0, 0.7, t.size) * start
    bias = 0.05
    at_rest = bias + rng.normal(0.0, 0.3, 200).mean()
    samples = -0.3 * w**2 * np.sin(w * t)[:, None] + bias + rng.normal(0.0, 0.3, (t.size, 5))
    return HoverFlight(
        truth=truth, z=np.column_stack([baro, gps]), accel_up=samples.mean(axis=1) - at_rest
    )
