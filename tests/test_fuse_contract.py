"""Contracts every registered fusion method meets (parametrised over FUSERS)."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from altfuse.fuse import FUSERS, LOG_INPUTS, FusionResult
from altfuse.fuse.mean import fuse_mean

METHODS = sorted(FUSERS)


def call(method: str, z: np.ndarray) -> FusionResult:
    """Run ``method``, giving it the log inputs it asks for: no acceleration, speed or
    temperature, a 10 Hz clock, the clock's values as each sensor's samples."""
    t = np.arange(z.shape[0]) * 0.1
    n = z.shape[1]
    inputs = {
        "accel_up": np.zeros(z.shape[0]),
        "dt_s": 0.1,
        "accel": None,
        "t": t,
        "samples": [(t[np.isfinite(z[:, i])], z[np.isfinite(z[:, i]), i]) for i in range(n)],
        "kinds": ("gps", "baro", "rangefinder")[:n],
        "names": ("gps", "baro", "rangefinder")[:n],
        "on_ground": None,
        "speed": None,
        "temperatures": None,
    }
    wanted = set(inspect.signature(FUSERS[method]).parameters) & LOG_INPUTS
    return FUSERS[method](z, **{k: inputs[k] for k in wanted})


@pytest.fixture
def gappy() -> np.ndarray:
    rng = np.random.default_rng(3)
    z = 20.0 + rng.normal(0.0, 0.3, (200, 3))
    z[20:40, 0] = np.nan  # GPS outage
    z[60:70, 1:] = np.nan  # only GPS left
    z[90:95, :] = np.nan  # nothing
    return z


@pytest.mark.parametrize("method", METHODS)
def test_shapes_weights_and_status(method: str, gappy: np.ndarray) -> None:
    res = call(method, gappy)
    assert res.method == method
    assert res.fused.shape == (200,)
    assert res.weights.shape == (200, 3)
    valid = np.isfinite(gappy)
    some = valid.any(axis=1)
    np.testing.assert_allclose(res.weights[some].sum(axis=1), 1.0, rtol=1e-12)
    assert (res.weights[some][~valid[some]] == 0).all()
    assert np.isfinite(res.fused[some]).all()
    assert set(res.status[90:95]) <= {"none", "inertial"}
    assert np.isnan(res.fused[res.status == "none"]).all()
    assert set(res.status[60:70]) == {"single"}
    np.testing.assert_array_equal(res.weights[60:70], [[1.0, 0.0, 0.0]] * 10)
    for trace in res.traces.values():
        assert trace.shape == (200, 3)
    for trace in res.tick_traces.values():
        assert trace.shape == (200,)


@pytest.mark.parametrize("method", METHODS)
def test_stays_near_the_sensors(method: str, gappy: np.ndarray) -> None:
    res = call(method, gappy)
    some = np.isfinite(gappy).any(axis=1)
    assert np.max(np.abs(res.fused[some] - 20.0)) < 1.0  # sensors: 20 m, sigma 0.3 m


@pytest.mark.parametrize("method", METHODS)
def test_beats_the_worst_sensor_on_a_synthetic_truth(method: str, paper_a) -> None:  # type: ignore[no-untyped-def]
    res = call(method, paper_a.z)
    rmse = np.sqrt(np.mean((res.fused - paper_a.truth) ** 2))
    sensor_rmse = np.sqrt(np.mean((paper_a.z - paper_a.truth[:, None]) ** 2, axis=0))
    assert rmse < sensor_rmse.max()


@pytest.mark.parametrize("method", ["mean", "support"])
def test_instantaneous_methods_stay_within_the_sensors(method: str, gappy: np.ndarray) -> None:
    res = call(method, gappy)
    some = np.isfinite(gappy).any(axis=1)
    lo, hi = np.nanmin(gappy[some], axis=1), np.nanmax(gappy[some], axis=1)
    assert (res.fused[some] >= lo - 1e-9).all()
    assert (res.fused[some] <= hi + 1e-9).all()
    np.testing.assert_array_equal(res.fused[60:70], gappy[60:70, 0])


def test_mean_is_the_equal_weight_average() -> None:
    z = np.array([[1.0, 2.0, 6.0], [1.0, np.nan, 3.0]])
    res = fuse_mean(z)
    np.testing.assert_allclose(res.fused, [3.0, 2.0])
    np.testing.assert_allclose(res.weights[1], [0.5, 0.0, 0.5])
