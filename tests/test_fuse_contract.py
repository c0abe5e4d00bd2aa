"""Contracts every registered fusion method meets (parametrised over FUSERS)."""

from __future__ import annotations

import numpy as np
import pytest

from altfuse.fuse import FUSERS
from altfuse.fuse.mean import fuse_mean

METHODS = sorted(FUSERS)


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
    res = FUSERS[method](gappy)
    assert res.method == method
    assert res.fused.shape == (200,)
    assert res.weights.shape == (200, 3)
    valid = np.isfinite(gappy)
    some = valid.any(axis=1)
    np.testing.assert_allclose(res.weights[some].sum(axis=1), 1.0, rtol=1e-12)
    assert (res.weights[some][~valid[some]] == 0).all()
    assert np.isfinite(res.fused[some]).all()
    assert np.isnan(res.fused[~some]).all()
    assert set(res.status[90:95]) == {"none"}
    assert set(res.status[60:70]) == {"single"}
    np.testing.assert_array_equal(res.fused[60:70], gappy[60:70, 0])
    for trace in res.traces.values():
        assert trace.shape == (200, 3)


@pytest.mark.parametrize("method", METHODS)
def test_result_within_the_sensors(method: str, gappy: np.ndarray) -> None:
    res = FUSERS[method](gappy)
    some = np.isfinite(gappy).any(axis=1)
    lo, hi = np.nanmin(gappy[some], axis=1), np.nanmax(gappy[some], axis=1)
    assert (res.fused[some] >= lo - 1e-9).all()
    assert (res.fused[some] <= hi + 1e-9).all()


@pytest.mark.parametrize("method", METHODS)
def test_beats_the_worst_sensor_on_a_synthetic_truth(method: str, paper_a) -> None:  # type: ignore[no-untyped-def]
    res = FUSERS[method](paper_a.z)
    rmse = np.sqrt(np.mean((res.fused - paper_a.truth) ** 2))
    sensor_rmse = np.sqrt(np.mean((paper_a.z - paper_a.truth[:, None]) ** 2, axis=0))
    assert rmse < sensor_rmse.max()


def test_mean_is_the_equal_weight_average() -> None:
    z = np.array([[1.0, 2.0, 6.0], [1.0, np.nan, 3.0]])
    res = fuse_mean(z)
    np.testing.assert_allclose(res.fused, [3.0, 2.0])
    np.testing.assert_allclose(res.weights[1], [0.5, 0.0, 0.5])
