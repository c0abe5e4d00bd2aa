"""Resampling onto one clock (ALGORITHMS.md section 1)."""

from __future__ import annotations

import numpy as np
import pytest

from altfuse.align import (
    Lag,
    _box_means,
    align,
    cell_means,
    estimate_lag,
    gps_lags,
    inertial_lag,
    merge_duplicates,
    resample,
    shift,
    splices,
)
from altfuse.errors import NoUsableSensorsError
from altfuse.metrics import cumulative_integral
from altfuse.model import Series


def series(name: str, t: np.ndarray, v: np.ndarray, kind: str = "baro") -> Series:
    return Series(name, kind, f"{name}.Alt", "test", t.astype(float), v.astype(float))


def test_spline_upsamples_a_smooth_signal_accurately() -> None:
    t = np.arange(0.0, 20.0, 0.2) + 0.05  # 5 Hz GPS, off the 10 Hz ticks
    grid = np.arange(1.0, 19.0, 0.1)
    out, stats = resample(t, np.sin(t / 2), grid, 10.0, 1.0)
    np.testing.assert_allclose(out, np.sin(grid / 2), atol=2e-5)
    assert stats.segments == 1
    assert stats.cells_averaged == 0


def test_gap_longer_than_max_gap_is_nan_not_invented() -> None:
    t = np.concatenate([np.arange(0.0, 5.0, 0.2), np.arange(8.0, 12.0, 0.2)])
    grid = np.arange(0, 121) / 10.0
    out, stats = resample(t, 3.0 + 0 * t, grid, 10.0, max_gap_s=1.0)
    assert np.isnan(out[(grid > 4.8 + 1e-9) & (grid < 8.0 - 1e-9)]).all()
    assert np.isfinite(out[grid <= 4.8 + 1e-9]).all()
    assert stats.gaps_over_max == 1
    # the same data with a generous max gap is bridged
    bridged, _ = resample(t, 3.0 + 0 * t, grid, 10.0, max_gap_s=5.0)
    assert np.isfinite(bridged[grid <= 11.8 + 1e-9]).all()


def test_no_extrapolation_outside_the_data() -> None:
    grid = np.arange(0, 101) / 10.0
    out, _ = resample(np.array([2.0, 2.5, 3.0, 3.5]), np.ones(4), grid, 10.0, 1.0)
    assert np.isnan(out[grid < 2.0 - 1e-9]).all()
    assert np.isnan(out[grid > 3.5 + 1e-9]).all()


def test_duplicates_merged_and_unsorted_sorted() -> None:
    t = np.array([3.0, 1.0, 2.0, 2.0, 4.0])
    v = np.array([30.0, 10.0, 19.0, 21.0, 40.0])
    ts, vs = merge_duplicates(t, v)
    np.testing.assert_array_equal(ts, [1.0, 2.0, 3.0, 4.0])
    np.testing.assert_array_equal(vs, [10.0, 20.0, 30.0, 40.0])
    out, stats = resample(t, v, np.array([1.0, 2.0, 2.5, 4.0]), 10.0, 2.0)
    np.testing.assert_allclose(out, [10.0, 20.0, 25.0, 40.0], atol=1e-9)
    assert stats.duplicates_merged == 1


def test_fast_noisy_sensor_is_averaged_before_decimation() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 60.0, 0.01)  # 100 Hz
    noise = rng.normal(0.0, 1.0, t.size)
    grid = np.arange(10, 590) / 10.0
    out, stats = resample(t, 5.0 + noise, grid, 10.0, 1.0)
    # ten samples per cell: the noise on the clock is ~1/sqrt(10) of the raw noise
    assert np.std(out - 5.0) == pytest.approx(1 / np.sqrt(10), rel=0.15)
    # 6000 samples fall into the 601 cells of the ticks 0.0 s .. 60.0 s
    assert stats.cells_averaged == 6000 - 601


def test_cell_means_leave_a_slow_sensor_alone() -> None:
    t = np.arange(0.0, 5.0, 0.2)
    ts, vs = cell_means(t, t * 2, 10.0)
    np.testing.assert_array_equal(ts, t)
    np.testing.assert_array_equal(vs, t * 2)


def test_align_union_and_overlap_grids() -> None:
    a = series("baro", np.arange(10.0, 20.0, 0.05), np.ones(200))
    b = series("gps", np.arange(12.02, 25.0, 0.2), np.ones(65), kind="gps")
    union = align([a, b], rate_hz=10.0, span="union")
    assert union.t[0] == 10.0
    assert union.t[-1] == pytest.approx(24.8)
    assert union.z.shape == (union.t.size, 2)
    np.testing.assert_allclose(np.diff(union.t), 0.1)
    overlap = align([a, b], rate_hz=10.0, span="overlap")
    assert overlap.t[0] == pytest.approx(12.1)
    assert overlap.t[-1] == pytest.approx(19.9)
    assert overlap.names == ("baro", "gps")


def test_ticks_fall_on_round_times_of_the_log_clock() -> None:
    a = series("baro", np.arange(100.03, 110.0, 0.05), np.ones(200))
    out = align([a], rate_hz=4.0)
    np.testing.assert_array_equal(out.t * 4.0, np.round(out.t * 4.0))


@pytest.mark.parametrize("rate_hz", [0.1, 0.05])
def test_on_a_slow_clock_a_sensor_s_cells_next_to_each_other_are_no_gap(rate_hz: float) -> None:
    """A 10 Hz barometer at 0.1 Hz: its cells' means lie a tick apart, to the jitter of its
    stamps, above the longest gap a sensor's own interval bridges (10 s). Each one a hair over
    it broke the column, and its ticks came and went."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 400.0, 0.1) + rng.uniform(-2e-4, 2e-4, 4000)
    out = align([series("baro", t, np.ones(t.size))], rate_hz=rate_hz)
    inside = (out.t > 0.5 / rate_hz) & (out.t < 400.0 - 0.5 / rate_hz)
    assert inside.sum() >= 400.0 * rate_hz - 2
    assert np.isfinite(out.z[inside, 0]).all()
    # an empty cell is a gap still
    gap = (t < 100.0) | (t > 100.0 + 2.5 / rate_hz)
    out = align([series("baro", t[gap], np.ones(gap.sum()))], rate_hz=rate_hz)
    assert np.isnan(out.z[(out.t > 100.0 + 0.5 / rate_hz) & (out.t < 100.0 + 2 / rate_hz), 0]).all()


def test_on_a_coarse_clock_a_segment_covers_the_ticks_from_its_first_sample_to_its_last() -> None:
    """A 10 Hz barometer at 0.5 Hz, in two segments: each cell's mean time lies inside it,
    past the tick where the samples begin partway through it (95.4 s: the cell of 96 s, its
    mean at 96.2 s), so the spline through the means left the first and last ticks of every
    segment without a value (32 of the 39 shared and sample logs' first or last row without
    a sensor). With ``edge_cells`` the ticks from a segment's first sample to its last have
    one, its ends extended; a tick before a segment's first sample still has none."""
    t = np.concatenate([np.arange(95.4, 119.95, 0.1), np.arange(130.3, 152.06, 0.1)])
    climb = series("baro", t, 2.0 * t)
    before = align([climb], rate_hz=0.5)
    after = align([climb], rate_hz=0.5, edge_cells=True)
    np.testing.assert_allclose(after.t[[0, -1]], [96.0, 152.0])
    for tick in (96.0, 152.0):
        assert np.isnan(before.z[before.t == tick, 0]).all()
    first, second = t[t < 125.0], t[t > 125.0]
    spanned = (after.t >= first[0] - 1e-6) & (after.t <= first[-1] + 1e-6)  # to the stamps'
    spanned |= (after.t >= second[0] - 1e-6) & (after.t <= second[-1] + 1e-6)  # resolution
    np.testing.assert_allclose(after.z[spanned, 0], 2.0 * after.t[spanned], rtol=1e-12)
    assert np.isnan(after.z[~spanned, 0]).all()  # 120-130 s: 130 s comes before 130.3 s
    inside = np.isfinite(before.z[:, 0])
    np.testing.assert_array_equal(after.z[inside, 0], before.z[inside, 0])


def test_disjoint_sensors_have_no_overlap() -> None:
    a = series("baro", np.arange(0.0, 5.0, 0.1), np.ones(50))
    b = series("gps", np.arange(10.0, 15.0, 0.2), np.ones(25), kind="gps")
    with pytest.raises(NoUsableSensorsError, match="overlap"):
        align([a, b], span="overlap")


def test_a_span_shorter_than_a_tick_says_so() -> None:
    """pymavlink's 0.8 s test log at 0.2 Hz: 'the altitude sources hold no time span to
    resample', though they hold 0.8 s."""
    a = series("baro", np.arange(81.9, 82.7, 0.1), np.ones(8))
    message = r"union spans 0.7 s \(81.9-82.6 s\), between two ticks of a 0.2 Hz clock; raise"
    with pytest.raises(NoUsableSensorsError, match=message):
        align([a], rate_hz=0.2)
    # one tick is no clock either: at 1e-320 Hz, one tick at 0 s (the log's 82 s to rounding),
    # whose fused value was NaN, an internal error where the metadata was written
    for rate_hz in (1.0, 1e-320):
        with pytest.raises(NoUsableSensorsError, match=r"a single tick \(a clock needs two\)"):
            align([a], rate_hz=rate_hz)
    assert align([a], rate_hz=2.0).t.tolist() == [82.0, 82.5]


def climb_profile(t: np.ndarray) -> np.ndarray:
    """Climbs and descents at up to 3 m/s, with a wobble: a flight whose rates tell a lag."""
    return 40 * (1 - np.cos(2 * np.pi * t / 60)) + 2 * np.sin(2 * np.pi * t / 7)


@pytest.mark.parametrize("lag_s", [0.0, 0.1, 0.25, 0.4])
def test_a_known_gps_lag_is_found_against_the_barometer(lag_s: float) -> None:
    rng = np.random.default_rng(2)
    tb = np.arange(0.0, 120.0, 0.1)
    tg = np.arange(0.0, 120.0, 0.2) + 0.013
    baro = series("baro", tb, 1.05 * climb_profile(tb) + rng.normal(0, 0.1, tb.size))
    gps = series("gps", tg, climb_profile(tg - lag_s) + rng.normal(0, 0.05, tg.size), "gps")
    lag = estimate_lag(gps, baro)
    assert lag.lag_s == pytest.approx(lag_s, abs=0.015)  # the 5 % scale does not pull it
    assert lag.explained is not None
    assert lag.explained > 0.99
    assert gps_lags([gps, baro]) == {"gps": lag}
    moved = shift(gps, lag)
    np.testing.assert_allclose(moved.t, gps.t - lag.lag_s)


@pytest.mark.parametrize("lag_s", [0.0, 0.1, 0.2, 0.3])
def test_a_gps_lag_is_found_between_sensors_logged_at_2_hz(lag_s: float) -> None:
    """With the barometer at 2 Hz the reference's box average held one sample or two by
    where it fell, and the fit favoured the lags that put it between samples: 0.15 s for 0.2,
    0.21 s for 0.3. Averaged over two of its intervals: within 0.01 s."""
    rng = np.random.default_rng(1)
    tb = np.arange(0.0, 300.0, 0.5) + 0.03
    tg = np.arange(0.0, 300.0, 0.5) + 0.11
    baro = series("baro", tb, 1.05 * climb_profile(tb) + rng.normal(0, 0.1, tb.size))
    gps = series("gps", tg, climb_profile(tg - lag_s) + rng.normal(0, 0.05, tg.size), "gps")
    lag = estimate_lag(gps, baro)
    assert lag.lag_s == pytest.approx(lag_s, abs=0.02)
    assert lag.std_s is not None
    assert abs(lag.lag_s - lag_s) < 2 * lag.std_s + 0.005


def inertial(lag_s: float, seed: int) -> tuple[Series, Series]:
    """A GPS's vertical velocity at 5 Hz ``lag_s`` late (0.05 m/s noisy), and the integral
    of a 400 Hz accelerometer (0.5 m/s^2 noisy, 0.1 m/s^2 biased) on ``climb_profile``."""
    rng = np.random.default_rng(seed)
    ta, tg = np.arange(0.0, 120.0, 0.0025), np.arange(0.0, 120.0, 0.2) + 0.013
    w1, w2 = 2 * np.pi / 60, 2 * np.pi / 7
    a = 40 * w1**2 * np.cos(w1 * ta) - 2 * w2**2 * np.sin(w2 * ta)
    a = a + 0.1 + rng.normal(0, 0.5, ta.size)
    integral = cumulative_integral(ta, a)
    v = 40 * w1 * np.sin(w1 * (tg - lag_s)) + 2 * w2 * np.cos(w2 * (tg - lag_s))
    velocity = series("gps_velocity_up", tg, v + rng.normal(0, 0.05, tg.size), "velocity")
    return velocity, series("accelerometer", ta, integral, "reference")


@pytest.mark.parametrize("lag_s", [0.1, 0.2, 0.3])
def test_a_gps_lag_is_found_against_the_accelerometer_where_the_barometer_cannot_tell(
    lag_s: float,
) -> None:
    """A barometer that says nothing of the motion (a blocked port: its noise alone): the
    GPS's vertical velocity against the accelerometer's integral tells its lag."""
    rng = np.random.default_rng(4)
    tb, tg = np.arange(0.0, 120.0, 0.1), np.arange(0.0, 120.0, 0.2) + 0.013
    baro = series("baro", tb, rng.normal(0, 0.5, tb.size))
    gps = series("gps", tg, climb_profile(tg - lag_s) + rng.normal(0, 0.05, tg.size), "gps")
    against_baro = gps_lags([gps, baro])["gps"]
    assert against_baro.std_s is None  # not estimated
    lag = inertial_lag(against_baro, *inertial(lag_s, 5))
    assert lag.sensor == "gps"
    assert lag.reference == "accelerometer"
    assert lag.lag_s == pytest.approx(lag_s, abs=0.015)
    assert lag.std_s is not None
    assert lag.how.startswith("its vertical velocity's changes matched to accelerometer's")


def test_the_barometers_gps_lag_stands_unless_the_accelerometer_says_otherwise() -> None:
    """Two estimates of one lag: the barometer's stands where they agree within
    LAG_AGREE_SIGMAS of their errors, or where the accelerometer's is the less precise; the
    accelerometer's where they disagree and it is the more precise."""
    velocity, integral = inertial(0.2, 6)
    inertial_alone = inertial_lag(
        Lag("gps", "baro", 0.0, None, "not estimated"), velocity, integral
    )
    assert inertial_alone.std_s is not None
    near = Lag("gps", "baro", 0.21, 0.99, "changes matched to baro's", 0.01)
    assert inertial_lag(near, velocity, integral) is near
    vague = Lag("gps", "baro", 0.05, 0.95, "changes matched to baro's", 0.2)
    assert inertial_lag(vague, velocity, integral) is vague
    off = Lag("gps", "baro", 0.05, 0.95, "changes matched to baro's", inertial_alone.std_s * 2)
    rng = np.random.default_rng(7)
    still = series("gps_velocity_up", velocity.t, rng.normal(0, 0.05, velocity.t.size), "velocity")
    neither = Lag("gps", "baro", 0.0, 0.4, "not estimated: baro explains 40% of its changes")
    unknown = inertial_lag(neither, still, integral)
    assert (unknown.lag_s, unknown.std_s, unknown.reference) == (0.0, None, "baro")
    assert unknown.how.startswith(f"{neither.how}; its vertical velocity: "), unknown.how
    taken = inertial_lag(off, velocity, integral)
    assert taken.reference == "accelerometer"
    assert taken.lag_s == inertial_alone.lag_s
    assert "baro's 0.05 +- " in taken.how


def test_no_lag_where_the_reference_explains_too_little() -> None:
    rng = np.random.default_rng(3)
    tb, tg = np.arange(0.0, 120.0, 0.1), np.arange(0.0, 120.0, 0.2)
    hover = 0.2 * np.sin(tb / 5)  # a hover: the GPS's noise is all its changes hold
    baro = series("baro", tb, hover + rng.normal(0, 0.05, tb.size))
    gps = series("gps", tg, rng.normal(0, 0.5, tg.size) + np.interp(tg - 0.3, tb, hover), "gps")
    lag = estimate_lag(gps, baro)
    assert lag.lag_s == 0.0
    assert lag.explained is not None
    # one decimal, as where it is estimated: 0.898 is not "90% (< 90%)"
    assert lag.how == f"not estimated: baro explains {lag.explained:.1%} of its changes (< 90%)"
    assert gps_lags([gps]) == {}  # no barometer, no lag


def test_a_pause_in_every_sensor_and_the_accelerometer_splits_the_log() -> None:
    t = np.concatenate([np.arange(0.0, 50.0, 0.1), np.arange(70.0, 120.0, 0.1)])
    aligned = align([series("baro", t, np.ones(t.size)), series("gps", t, np.ones(t.size), "gps")])
    assert splices(aligned, None) == [pytest.approx(70.0)]
    imu_through = np.arange(0.0, 120.0, 0.02)
    assert splices(aligned, imu_through) == []  # the accelerometer saw the pause: one flight
    imu_paused = imu_through[(imu_through < 50.0) | (imu_through >= 70.0)]
    assert splices(aligned, imu_paused) == [pytest.approx(70.0)]


def test_a_sensor_logged_slower_than_the_gap_is_not_cut_between_its_samples() -> None:
    """A GPS at 1 Hz (a PX4 low-rate logging profile) with the default max_gap of 1 s: its
    jittered intervals (1.000-1.004 s) are its sampling, not gaps; a 3 s pause still is one."""
    rng = np.random.default_rng(2)
    t = np.cumsum(1.0 + rng.uniform(0.0, 0.004, 40))
    t = np.delete(t, [20, 21])  # a pause of 3 s
    v = np.sin(t / 5)
    grid = np.arange(np.ceil(t[0] * 10), np.floor(t[-1] * 10) + 1) / 10
    out, stats = resample(t, v, grid, 10.0, 1.0)
    pause = (grid > t[19] + 1e-6) & (grid < t[20] - 1e-6)
    assert np.isnan(out[pause]).all()
    assert np.isfinite(out[~pause]).all()
    assert stats.gaps_over_max == 1


def test_two_samples_hours_apart_are_not_a_sensor_s_sampling() -> None:
    """A GPS with two samples 7 hours apart (a damaged log's stamps: the long fuzz run) had a
    sampling interval of 7 hours: its column was the spline across them, at every tick, and
    the guard measured the fused value against it (the smoother 1815 m off, unflagged). An own
    interval counts up to MAX_OWN_GAP_S; a GPS at 0.2 Hz is still bridged."""
    grid = np.arange(0.0, 25300.0, 0.1)
    out, stats = resample(np.array([81.9, 25282.0]), np.array([0.0, 0.05]), grid, 10.0, 1.0)
    assert np.isfinite(out).sum() == 2  # each sample's own cell, nothing between
    assert stats.gaps_over_max == 1
    t = np.arange(0.0, 60.0, 5.0)
    out, _ = resample(t, np.sin(t / 20), np.arange(0.0, 55.05, 0.1), 10.0, 1.0)
    assert np.isfinite(out).all()


def test_a_lags_standard_error_describes_its_error() -> None:
    """Over 40 noises of the same climb, the barometer 0.3 m noisy: the lag's error lies within
    2 standard errors on 85-100 % of them (white noise: the error's spread is 0.4 of the
    standard error, which is made for the correlated errors of real sensors), and a quieter
    barometer gives a smaller one."""
    tb, tg = np.arange(0.0, 120.0, 0.1), np.arange(0.0, 120.0, 0.2) + 0.013

    def estimated(seed: int, noise_m: float) -> tuple[float, float]:
        rng = np.random.default_rng(seed)
        baro = series("baro", tb, climb_profile(tb) + rng.normal(0, noise_m, tb.size))
        gps = series("gps", tg, climb_profile(tg - 0.2) + rng.normal(0, 0.05, tg.size), "gps")
        lag = estimate_lag(gps, baro)
        assert lag.std_s is not None
        assert f"+-{lag.std_s:.3f} s" in lag.how
        return lag.lag_s - 0.2, lag.std_s

    noisy = np.array([estimated(seed, 0.3) for seed in range(40)])
    z = np.abs(noisy[:, 0]) / noisy[:, 1]
    assert 0.85 <= np.mean(z <= 2.0) <= 1.0
    assert 0.25 * np.median(noisy[:, 1]) < np.std(noisy[:, 0]) < np.median(noisy[:, 1])
    quiet = np.array([estimated(seed, 0.03) for seed in range(5)])
    assert np.median(quiet[:, 1]) < 0.6 * np.median(noisy[:, 1])  # the GPS is 0.05 m noisy


@pytest.mark.filterwarnings("ignore:invalid value encountered in subtract:RuntimeWarning")
def test_the_lags_box_means_are_numpys_to_the_bit() -> None:
    """The compiled walk gives numpy's interpolation exactly: ends held, knots hit exactly (a
    grid of 0.1 s), and where a non-finite reference makes numpy try again."""
    rng = np.random.default_rng(5)
    for trial in range(60):
        rt = np.unique(np.round(rng.uniform(0, 50, 200), 1 if trial % 2 else 6))
        integral = cumulative_integral(rt, rng.normal(size=rt.size))
        if trial % 3 == 0:
            integral[rng.integers(0, rt.size, 3)] = (np.nan, np.inf, -np.inf)
        t = np.unique(np.round(rng.uniform(-5, 55, 150), 2))
        box = float(rng.choice([0.05, 0.3, 1.0]))
        out = np.empty(t.size)
        for tau in np.arange(-0.5, 1.005, 0.05):
            _box_means(t, float(tau), box, rt, integral, out)
            half = box / 2
            numpy = (
                np.interp(t - tau + half, rt, integral) - np.interp(t - tau - half, rt, integral)
            ) / box
            np.testing.assert_array_equal(out, numpy)
