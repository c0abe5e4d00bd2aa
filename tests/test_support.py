"""Paper A (observation support, Eq. 2-8) against hand-computed numbers and its experiment."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from altfuse.fuse import FusionInput, FusionResult
from altfuse.fuse.support import (
    SupportParams,
    auto_alpha,
    fuse_support,
    pairwise_support,
    window_mean_var,
)
from altfuse.params import InvalidParameter


def support(z: np.ndarray, **values: float) -> FusionResult:
    """Paper A on heights already on a 10 Hz clock."""
    return fuse_support(FusionInput.from_heights(z, dt_s=0.1), SupportParams(**values))


# Two ticks of three sensors; alpha = 0.5 1/m², beta = 2, k = 1.
Z = np.array([[10.0, 10.4, 11.0], [10.2, 10.2, 10.8]])
ALPHA, BETA, K = 0.5, 2.0, 1

# Eq. 2 at t0: a12 = exp(-0.5 * 0.4²) = exp(-0.08) = 0.923116346386
#              a13 = exp(-0.5 * 1.0²) = exp(-0.5)  = 0.606530659713
#              a23 = exp(-0.5 * 0.6²) = exp(-0.18) = 0.835270211411
# Eq. 4 divides by n = 3:
R0 = [
    (0.923116346386 + 0.606530659713) / 3,  # 0.509882335366
    (0.923116346386 + 0.835270211411) / 3,  # 0.586128852599
    (0.606530659713 + 0.835270211411) / 3,  # 0.480600290375
]
# t1: a12 = exp(0) = 1, a13 = a23 = exp(-0.18)
R1 = [(1 + 0.835270211411) / 3, (1 + 0.835270211411) / 3, 2 * 0.835270211411 / 3]
# Eq. 6, 7 with k = 1 at T = t1: the mean and the population variance of (r(t0), r(t1))
RBAR1 = [(a + b) / 2 for a, b in zip(R0, R1, strict=True)]
VAR1 = [((a - b) / 2) ** 2 for a, b in zip(R0, R1, strict=True)]
# = rbar 0.560819536252, 0.598942794868, 0.518723548991
# = var  2.594598434e-3, 1.641971165e-4, 1.453382848e-3
# Eq. 5: lambda = rbar (1 - 2 var) = 0.557909333271, 0.598746105509, 0.517215741174
LAM1 = [0.557909333271, 0.598746105509, 0.517215741174]
# Eq. 8: X = sum(lambda z) / sum(lambda)
X1 = (0.557909333271 * 10.2 + 0.598746105509 * 10.2 + 0.517215741174 * 10.8) / sum(LAM1)
# At t0 the window holds t0 alone: variance 0, lambda = r(t0); X = 10.453537121376
X0 = 10.453537121376


def test_support_eq2_to_4_hand_computed() -> None:
    r = pairwise_support(Z, ALPHA)
    np.testing.assert_allclose(r[0], R0, rtol=1e-11)
    np.testing.assert_allclose(r[1], R1, rtol=1e-11)
    np.testing.assert_allclose(r[0], [0.509882335366, 0.586128852599, 0.480600290375], atol=1e-12)


def test_window_mean_and_variance_eq6_eq7_hand_computed() -> None:
    rbar, var = window_mean_var(pairwise_support(Z, ALPHA), K)
    np.testing.assert_allclose(rbar[1], RBAR1, rtol=1e-11)
    np.testing.assert_allclose(var[1], VAR1, rtol=1e-8)
    np.testing.assert_allclose(var[1], [2.594598434e-3, 1.641971165e-4, 1.453382848e-3], rtol=1e-9)
    # the first tick uses the samples available: its own
    np.testing.assert_allclose(rbar[0], R0, rtol=1e-11)
    np.testing.assert_allclose(var[0], 0.0, atol=1e-15)


def test_weights_and_fused_eq5_eq8_hand_computed() -> None:
    res = support(Z, alpha_per_m2=ALPHA, beta=BETA, window_s=K * 0.1)
    np.testing.assert_allclose(res.traces["lambda"][1], LAM1, rtol=1e-9)
    np.testing.assert_allclose(res.weights[1], np.array(LAM1) / sum(LAM1), rtol=1e-9)
    assert res.fused[1] == pytest.approx(X1, abs=1e-9)
    assert res.fused[1] == pytest.approx(10.385396252962, abs=1e-9)
    assert res.fused[0] == pytest.approx(X0, abs=1e-9)
    assert list(res.status) == ["fused", "fused"]


def test_lambda_clipped_at_zero_falls_back_to_equal_weights() -> None:
    # r alternates 0.6 / ~0 for every sensor: variance ~0.09, beta 100 drives every lambda < 0
    z = np.array([[0.0, 0.0, 0.0], [0.0, 30.0, 60.0]] * 3)
    res = support(z, alpha_per_m2=1.0, beta=100.0, window_s=0.3)
    assert (res.traces["lambda"][-1] == 0).all()
    assert res.status[-1] == "equal"
    np.testing.assert_allclose(res.weights[-1], [1 / 3, 1 / 3, 1 / 3])
    assert res.fused[-1] == pytest.approx(30.0)


def test_missing_sensor_takes_no_part_and_n_counts_valid() -> None:
    z = np.array([[10.0, np.nan, 11.0]])
    r = pairwise_support(z, 0.5)
    # n = 2 valid sensors: r = exp(-0.5) / 2
    np.testing.assert_allclose(r[0, [0, 2]], math.exp(-0.5) / 2, rtol=1e-12)
    assert np.isnan(r[0, 1])
    res = support(z, alpha_per_m2=0.5)
    assert res.weights[0, 1] == 0.0
    assert res.fused[0] == pytest.approx(10.5)


def test_one_valid_sensor_is_the_result_and_none_is_nan() -> None:
    z = np.array([[12.0, np.nan], [np.nan, np.nan], [12.0, 12.4]])
    res = support(z, alpha_per_m2=1.0)
    assert res.fused[0] == 12.0
    assert list(res.status) == ["single", "none", "fused"]
    assert np.isnan(res.fused[1])
    assert np.isnan(res.weights[1]).all()
    assert np.isnan(res.traces["support"][0]).all()  # support needs a pair


def test_auto_alpha_from_the_robust_pairwise_spread() -> None:
    # pairwise |differences| are 0.5 everywhere: s = 1.482602 * 0.5, alpha = 1 / (2 s²)
    z = np.column_stack([np.zeros(20), np.full(20, 0.5)])
    assert auto_alpha(z) == pytest.approx(1 / (2 * (1.482602218505602 * 0.5) ** 2), rel=1e-12)
    # identical sensors: the spread is floored at 1 cm rather than dividing by zero
    assert auto_alpha(np.ones((5, 3))) == pytest.approx(1 / (2 * 0.01**2))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"alpha_per_m2": 0.0}, "alpha_per_m2 must be a positive number, got 0.0"),
        ({"alpha_per_m2": math.nan}, "alpha_per_m2 must be a positive number, got nan"),
        ({"beta": -1.0}, "beta must be a number >= 0, got -1.0"),
        ({"beta": "ten"}, "beta must be a number >= 0, got 'ten'"),
        ({"window_s": -0.1}, "window_s must be a number >= 0, got -0.1"),
    ],
)
def test_nonsense_parameters_are_refused_in_the_librarys_words(
    kwargs: dict[str, float], message: str
) -> None:
    with pytest.raises(InvalidParameter) as caught:
        SupportParams(**kwargs)
    assert str(caught.value) == message
    assert "--" not in str(caught.value)


def test_the_window_is_in_seconds_whatever_the_rate() -> None:
    z = np.random.default_rng(0).normal(10.0, 0.3, (50, 3))
    at_10hz = fuse_support(FusionInput.from_heights(z, 0.1), SupportParams(window_s=0.5))
    at_20hz = fuse_support(FusionInput.from_heights(z, 0.05), SupportParams(window_s=0.5))
    assert (at_10hz.params["window_ticks"], at_20hz.params["window_ticks"]) == (5, 10)


def test_paper_a_experiment_baro_departure(paper_a) -> None:  # type: ignore[no-untyped-def]
    """ALGORITHMS.md section 2: the barometer's weight falls while it departs, and support stays
    with GPS and sonar; the mean follows the barometer a third of the way."""
    f = paper_a
    fused = support(f.z)
    mean = f.z.mean(axis=1)
    w = fused.weights
    baro = f.names.index("baro")
    # measured (seed 7, defaults): baro weight 0.336 agreeing, 0.044 departing
    assert w[f.agree, baro].mean() == pytest.approx(1 / 3, abs=0.03)
    assert w[f.baro_departs, baro].mean() < 0.08
    dep = f.baro_departs
    rmse_support = np.sqrt(np.mean((fused.fused[dep] - f.truth[dep]) ** 2))
    rmse_mean = np.sqrt(np.mean((mean[dep] - f.truth[dep]) ** 2))
    # measured: 0.084 m against 0.582 m
    assert rmse_support < 0.12
    assert rmse_mean > 0.5
    assert rmse_support < 0.25 * rmse_mean


def test_paper_a_experiment_scatter_sonar_heaviest(paper_a) -> None:  # type: ignore[no-untyped-def]
    f = paper_a
    w = support(f.z).weights[f.scatter].mean(axis=0)
    # measured (seed 7): gps 0.28, baro 0.31, sonar 0.405
    assert np.argmax(w) == f.names.index("sonar")
    assert w[f.names.index("sonar")] > 0.38


finite = st.floats(-500.0, 5000.0, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(column=hnp.arrays(np.float64, st.integers(1, 40), elements=finite), n=st.integers(2, 4))
def test_identical_sensors_give_that_sensor(column: np.ndarray, n: int) -> None:
    z = np.repeat(column[:, None], n, axis=1)
    res = support(z)
    np.testing.assert_allclose(res.fused, column, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(res.weights, 1.0 / n, rtol=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    z=hnp.arrays(np.float64, st.tuples(st.integers(1, 30), st.integers(2, 4)), elements=finite),
    shift=st.floats(-1000.0, 1000.0),
)
def test_common_offset_shifts_the_result(z: np.ndarray, shift: float) -> None:
    base = support(z, alpha_per_m2=0.3)
    moved = support(z + shift, alpha_per_m2=0.3)
    np.testing.assert_allclose(moved.fused, base.fused + shift, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(moved.weights, base.weights, atol=1e-6)
