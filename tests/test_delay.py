"""Paper B layer 1 (ALGORITHMS.md 3.1-3.4) against hand-computed numbers, and on a moving flight."""

from __future__ import annotations

import numpy as np
import pytest

from altfuse.fuse import FusionInput
from altfuse.fuse.delay import (
    VARIANCE_FLOOR_M2,
    DelayParams,
    fuse_delay1,
    fuse_delay2,
    measurement_variances,
    spatial_weights,
    temporal_fusion,
)
from altfuse.params import InvalidParameter
from altfuse.pipeline import FuseOptions, fuse_log
from conftest import shared_log

FLOOR = VARIANCE_FLOOR_M2


def test_measurement_variance_3_1_hand_computed() -> None:
    z = np.array([[1.0, 2.0], [3.0, 5.0], [2.0, 2.0]])
    # k=1: x = (0, 0): R = 0, delta2 floored
    # k=2: mu = (2, 3.5), x = (1, 1.5): R_pp = (1/2, 2.25/2), R_pq = 1.5/2 = 0.75
    #      delta2 = (0.5 - 0.75 -> floor, 1.125 - 0.75 = 0.375)
    # k=3: mu = (2, 3), x = (0, -1): R_pp = (1/3, 3.25/3), R_pq = 1.5/3 = 0.5
    #      delta2 = (1/3 - 0.5 -> floor, 1.083333 - 0.5 = 0.583333)
    expected = [[FLOOR, FLOOR], [FLOOR, 0.375], [FLOOR, 3.25 / 3 - 0.5]]
    np.testing.assert_allclose(measurement_variances(z), expected, rtol=1e-12)


def test_measurement_variance_of_independent_noise_converges_in_a_hover() -> None:
    rng = np.random.default_rng(0)
    signal = 240.0 + 0.3 * np.sin(np.arange(20000) / 30.0)  # a hover: common to all sensors
    z = signal[:, None] + rng.normal(0.0, 1.0, (20000, 3)) * [0.3, 1.0, 2.0]
    np.testing.assert_allclose(measurement_variances(z)[-1], [0.09, 1.0, 4.0], rtol=0.1)


def test_measurement_variance_is_lost_under_a_moving_signal() -> None:
    """A documented limit of 3.1: deviations from the running mean carry the vehicle's motion,
    whose chance correlation with the noise swamps it (measured: 1e-4 floor, 0.66, 4.43)."""
    rng = np.random.default_rng(0)
    signal = np.cumsum(rng.normal(0, 0.5, 20000))
    z = signal[:, None] + rng.normal(0.0, 1.0, (20000, 3)) * [0.3, 1.0, 2.0]
    assert measurement_variances(z)[-1, 0] == FLOOR


def test_one_step_delay_3_2_hand_computed() -> None:
    z = np.array([[10.0], [12.0], [13.0]])
    d = np.array([[1.0], [1.0], [2.0]])
    zp, pp = temporal_fusion(z, d, steps=1, form="paper", q=0.0)
    # Z+(2) = (1*10 + 1*12) / 2 = 11, P+(2) = 1*1/2 = 0.5
    # Z+(3) = (2*11 + 0.5*13) / 2.5 = 11.4, P+(3) = 0.5*2/2.5 = 0.4
    np.testing.assert_allclose(zp[:, 0], [10.0, 11.0, 11.4], rtol=1e-12)
    np.testing.assert_allclose(pp[:, 0], [1.0, 0.5, 0.4], rtol=1e-12)
    zp, pp = temporal_fusion(z, d, steps=1, form="practical", q=0.5)
    # prior P+(1) + q = 1.5: Z+(2) = (1*10 + 1.5*12)/2.5 = 11.2, P+(2) = 1.5/2.5 = 0.6
    # prior 1.1: Z+(3) = (2*11.2 + 1.1*13)/3.1 = 11.838710, P+(3) = 2.2/3.1 = 0.709677
    np.testing.assert_allclose(zp[:, 0], [10.0, 11.2, 36.7 / 3.1], rtol=1e-12)
    np.testing.assert_allclose(pp[:, 0], [1.0, 0.6, 2.2 / 3.1], rtol=1e-12)


def test_two_step_delay_3_3_hand_computed() -> None:
    z = np.array([[10.0], [12.0], [13.0], [14.0]])
    d = np.array([[1.0], [1.0], [2.0], [1.0]])
    zp, pp = temporal_fusion(z, d, steps=2, form="paper", q=0.0)
    # Z+(1), Z+(2) from the one-step recursion: 10 (P 1), 11 (P 0.5)
    # k=3: 1/P = 1/2 + 1/0.5 + 1/1 = 3.5; Z = (13/2 + 11/0.5 + 10/1) / 3.5 = 11
    # k=4: 1/P = 1/1 + 3.5 + 1/0.5 = 6.5; Z = (14/1 + 11*3.5 + 11/0.5) / 6.5 = 11.461538
    np.testing.assert_allclose(zp[:, 0], [10.0, 11.0, 11.0, 74.5 / 6.5], rtol=1e-12)
    np.testing.assert_allclose(pp[:, 0], [1.0, 0.5, 1 / 3.5, 1 / 6.5], rtol=1e-12)
    zp, pp = temporal_fusion(z, d, steps=2, form="practical", q=0.5)
    # k=2 as the one-step practical: 11.2, 0.6. k=3: priors P+(2) + q = 1.1, P+(1) + 2q = 2
    # 1/P = 1/2 + 1/1.1 + 1/2 = 1.909091; Z = P (13/2 + 11.2/1.1 + 10/2) = 11.357143
    np.testing.assert_allclose(zp[2, 0], 11.357142857142856, rtol=1e-12)
    np.testing.assert_allclose(pp[2, 0], 0.5238095238095238, rtol=1e-12)


def test_spatial_weighting_3_4_hand_computed() -> None:
    pplus = np.array([[0.5, 2.0]])
    w = spatial_weights(pplus, np.array([[True, True]]))
    # W = (1/0.5, 1/2) / 2.5 = (0.8, 0.2)
    np.testing.assert_allclose(w, [[0.8, 0.2]], rtol=1e-12)
    # a sensor not measured at k takes no part
    np.testing.assert_allclose(spatial_weights(pplus, np.array([[False, True]])), [[0.0, 1.0]])


def test_delay_fusers_combine_temporal_estimates_with_spatial_weights() -> None:
    rng = np.random.default_rng(4)
    z = 50.0 + rng.normal(0.0, 1.0, (300, 2)) * [0.3, 1.2]
    for fuser in (fuse_delay1, fuse_delay2):
        res = fuser(FusionInput.from_heights(z), DelayParams())
        zplus, pplus = res.traces["temporal_estimate"], res.traces["temporal_variance"]
        w = (1 / pplus) / (1 / pplus).sum(axis=1, keepdims=True)
        np.testing.assert_allclose(res.weights, w, rtol=1e-12)
        np.testing.assert_allclose(res.fused, (w * zplus).sum(axis=1), rtol=1e-12)
        # P* = 1 / sum 1/P+ is never larger than any single P+
        assert (res.tick_traces["fused_variance"] <= pplus.min(axis=1) + 1e-15).all()
        assert res.weights[100:, 0].mean() > 0.6  # the quieter sensor weighs more


def climb_and_descend() -> tuple[np.ndarray, np.ndarray]:
    """10 Hz, 150 s: 20 s still, climb at 2 m/s to 60 m, hold, descend, hold."""
    rng = np.random.default_rng(8)
    t = np.arange(0.0, 150.0, 0.1)
    truth = np.interp(t, [0, 20, 50, 80, 110, 150], [0, 0, 60, 60, 0, 0])
    z = truth[:, None] + rng.normal(0.0, 1.0, (t.size, 2)) * [0.3, 0.8]
    return truth, z


@pytest.mark.parametrize("fuser", [fuse_delay1, fuse_delay2])
def test_practical_form_tracks_and_paper_form_freezes(fuser) -> None:  # type: ignore[no-untyped-def]
    truth, z = climb_and_descend()
    practical = fuser(FusionInput.from_heights(z), DelayParams(form="practical"))
    rmse = np.sqrt(np.mean((practical.fused - truth) ** 2))
    # measured: delay1 0.71 m, delay2 0.79 m (a random-walk filter lags a 2 m/s climb)
    assert rmse < 1.0
    paper = fuser(FusionInput.from_heights(z), DelayParams(form="paper"))
    # the constant-altitude form freezes: P+ -> 0 and the climb is not followed
    # (measured at the end of the climb: delay1 26.0 m, delay2 -0.6 m; truth 60 m)
    climb_end = 500
    assert paper.fused[climb_end] < 30.0
    assert np.sqrt(np.mean((paper.fused - truth) ** 2)) > 15.0
    assert paper.traces["temporal_variance"][-1].max() < 1e-5
    assert np.isfinite(paper.fused).all()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"form": "exact"}, "form must be one of practical, paper, got 'exact'"),
        ({"q_m2_s": -1.0}, "q_m2_s must be a number >= 0, got -1.0"),
    ],
)
def test_nonsense_parameters(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(InvalidParameter) as caught:
        DelayParams(**kwargs)  # type: ignore[arg-type]
    assert str(caught.value) == message


def test_process_noise_is_a_density_per_second() -> None:
    """The same random walk at any rate: q per tick = q_m2_s * dt (0.05 m² at 10 Hz)."""
    z = climb_and_descend()[1]
    at_10hz = temporal_fusion(z, measurement_variances(z), 1, "practical", 0.05)
    fused = fuse_delay1(FusionInput.from_heights(z, 0.1), DelayParams(q_m2_s=0.5))
    np.testing.assert_array_equal(fused.traces["temporal_estimate"], at_10hz[0])


def test_a_pause_in_every_sensor_restarts_the_recursions() -> None:
    """After 20 s with nothing logged (a splice) the running statistics of 3.1 start again:
    the second part is fused as if it were a log of its own."""
    rng = np.random.default_rng(9)
    first = 30.0 + np.cumsum(rng.normal(0.0, 0.3, (300, 2)), axis=0)  # a flight that moves
    second = 10.0 + rng.normal(0.0, 0.1, (300, 2))
    z = np.concatenate([first, np.full((200, 2), np.nan), second])
    for fuser in (fuse_delay1, fuse_delay2):
        whole = fuser(FusionInput.from_heights(z, 0.1), DelayParams())
        alone = fuser(FusionInput.from_heights(second, 0.1), DelayParams())
        np.testing.assert_allclose(whole.fused[500:], alone.fused, rtol=1e-12)
        np.testing.assert_allclose(whole.traces["variance"][500:], alone.traces["variance"])


def test_the_solo_log_s_splice_no_longer_derails_delay2() -> None:
    """The 3.4 Solo log resumes after 16 s on the ground: carried across, the running
    statistics held delay2 up to 50 m off in the next descent (2.14 m RMSE)."""
    run = fuse_log(shared_log("truth/copter_3.4dev-solo_djnugent_climb154m_ekf1.BIN"),
                   FuseOptions(method="delay2"))  # fmt: skip
    assert run.provenance["guard"]["diverged_ticks"] == 0


@pytest.mark.parametrize("fuser", [fuse_delay1, fuse_delay2])
def test_a_sensor_out_through_a_climb_neither_freezes_nor_derails_the_other(fuser) -> None:  # type: ignore[no-untyped-def]
    """The GPS out for 30 s of the climb (a frozen receiver, its samples dropped as stuck):
    alone, the barometer's variance was its whole climb (R_pp without a partner) and its
    estimate froze; back, the running statistics from before the outage held it off (measured,
    delay1 / delay2, RMSE before 5.2 / 27.3 m, max 15.3 / 50.1 m; after 0.43 / 1.67 m, max
    1.8 / 4.2 m)."""
    truth, z = climb_and_descend()
    z[250:550, 0] = np.nan  # 25-55 s: most of the climb and the start of the hold
    fused = fuser(FusionInput.from_heights(z, 0.1), DelayParams()).fused
    assert np.sqrt(np.mean((fused - truth) ** 2)) < 2.0
    assert np.abs(fused - truth).max() < 5.0
