"""Steps between two sensors' heights (:mod:`altfuse.steps`): found where they are and as large
as they are; a ramp, a drift, a real GPS's wander and a spike are none."""

from __future__ import annotations

import numpy as np
import pytest

from altfuse.model import SensorKind
from altfuse.pipeline import step_record
from altfuse.steps import (
    REGAIN_SIGMAS,
    STEP_GAP_S,
    STEP_MIN_M,
    STEP_SETTLE_S,
    STEP_SIGMAS,
    _end_error,
    _line_ends,
    _step_at,
    find_steps,
    jump_instant,
)

KINDS: tuple[SensorKind, SensorKind] = ("gps", "baro")


def two_sensors(
    seed: int = 1, gps_noise: float = 0.1, walk_m2_s: float = 0.0, scale: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 10 Hz clock of 200 s, the truth (a climb to 50 m, a hold, a descent), and the heights
    of a GPS (white noise, a random walk) and of a barometer ``scale`` times the truth."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 200.0, 0.1)
    h = np.interp(t, [0, 20, 60, 140, 180, 200], [0, 0, 50, 50, 0, 0])
    walk = np.cumsum(rng.normal(0.0, np.sqrt(walk_m2_s * 0.1), t.size))
    gps = h + walk + rng.normal(0.0, gps_noise, t.size)
    baro = scale * h + rng.normal(0.0, 0.05, t.size)
    return t, h, np.column_stack([gps, baro])


@pytest.mark.parametrize("right", [True, False])
def test_a_line_s_end_is_its_least_squares_line_at_the_boundary(right: bool) -> None:
    rng = np.random.default_rng(2)
    d, n = rng.normal(size=40), 7
    d[30] = np.nan
    ends = _line_ends(d, n, right=right)
    for k in range(d.size):
        ticks = np.arange(k, k + n) if right else np.arange(k - n, k)
        if ticks[0] < 0 or ticks[-1] >= d.size or np.isnan(d[ticks]).any():
            assert np.isnan(ends[k])
            continue
        line = np.polyfit(ticks, d[ticks], 1)
        assert ends[k] == pytest.approx(np.polyval(line, k - 0.5), abs=1e-12)


@pytest.mark.parametrize(("which", "size"), [(0, 1.0), (1, -0.8)])
def test_a_step_is_found_where_and_as_large_as_it_is(which: int, size: float) -> None:
    t, _, z = two_sensors()
    z[t >= 100.0, which] += size
    (step,) = find_steps(t, z, ("gps", "baro"), KINDS)
    assert step.time_s == pytest.approx(100.0 - 0.05, abs=0.11)
    assert (step.first, step.second) == ("gps", "baro")
    # the barometer's heights less the GPS's
    assert step.size_m == pytest.approx(size if which == 1 else -size, abs=0.05)
    assert step.sigmas > 10


def test_a_scale_a_drift_and_a_real_gps_s_wander_are_no_steps() -> None:
    """A barometer 5 % high in 50 m climbs, drifting 0.3 m/min, beside a GPS 0.3 m noisy that
    wanders by a random walk of 0.01 m^2/s (a real receiver's: 1.4 m over the flight)."""
    for seed in range(5):
        t, _, z = two_sensors(seed, gps_noise=0.3, walk_m2_s=0.01, scale=1.05)
        z[:, 1] += 0.3 * t / 60.0
        assert find_steps(t, z, ("gps", "baro"), KINDS) == ()


def test_a_spike_out_and_back_is_no_step_and_a_glitch_is_two() -> None:
    t, _, z = two_sensors()
    spiked = z.copy()
    spiked[(t >= 100.0) & (t < 100.4), 0] += 3.0
    assert find_steps(t, spiked, ("gps", "baro"), KINDS) == ()
    glitched = z.copy()
    glitched[(t >= 100.0) & (t < 105.0), 0] += 15.0
    first, second = find_steps(t, glitched, ("gps", "baro"), KINDS)
    assert (first.time_s, second.time_s) == pytest.approx((99.95, 104.95), abs=0.11)
    assert (first.size_m, second.size_m) == pytest.approx((-15.0, 15.0), abs=0.5)


def test_a_rangefinder_s_ground_is_not_a_step_nor_one_under_half_a_metre() -> None:
    t, _, z = two_sensors()
    rangefinder = z.copy()
    rangefinder[t >= 100.0, 1] += 2.0  # a roof under it
    assert find_steps(t, rangefinder, ("gps", "rangefinder"), ("gps", "rangefinder")) == ()
    small = z.copy()
    small[t >= 100.0, 1] += 0.9 * STEP_MIN_M
    assert find_steps(t, small, ("gps", "baro"), KINDS) == ()


@pytest.mark.parametrize(("which", "size"), [(0, 1.0), (1, -0.8), (1, 10.0)])
def test_the_sensor_whose_own_heights_jump_is_the_one_that_jumped(which: int, size: float) -> None:
    """Its own lines either side of the step part by it, the other's hold: that one jumped
    (:attr:`altfuse.steps.Step.jumped`), for the fusion method to take as given. Where the
    vehicle's own motion parts both by more than a quarter of the step (a descent begun at 3
    m/s^2 from rest: 1 m between lines over 2 s), or the step lies in a gap, the heights do
    not tell."""
    t, _, z = two_sensors()
    stepped = z.copy()
    stepped[t >= 100.0, which] += size
    (step,) = find_steps(t, stepped, ("gps", "baro"), KINDS)
    assert step.jumped == ("gps", "baro")[which]
    assert step_record(step)["jumped"] == step.jumped
    jerk = z - np.where(t >= 100.0, 1.5 * (t - 100.0) ** 2, 0.0)[:, None]
    jerk[t >= 100.0, which] += size
    (step,) = find_steps(t, jerk, ("gps", "baro"), KINDS)
    assert step.size_m == pytest.approx(size if which == 1 else -size, abs=0.05)
    assert step.jumped == (None if abs(size) < 4.0 else ("gps", "baro")[which])
    lost = stepped.copy()
    lost[(t >= 95.0) & (t < 105.0), 1 - which] = np.nan
    (step,) = find_steps(t, lost, ("gps", "baro"), KINDS)
    assert step.half_width_s > 4.0
    assert step.jumped is None


def test_a_step_settles_as_far_as_the_difference_moves_back_after_it() -> None:
    """A barometer flashed 3 m at 100 s, settling back with a time constant of 5 s: it settles
    by the difference's move back over STEP_SETTLE_S (2.4 m, from its mean over the first 2
    s). A step that holds, or one the difference goes on from (a crash's last seconds part two
    sensors further), or one found across a gap, settles by none; lost before the span ends, by
    the whole step (it may settle unseen)."""
    t, _, z = two_sensors()
    after = t >= 100.0
    flashed = z.copy()
    flashed[after, 1] += 3.0 * np.exp(-(t[after] - 100.0) / 5.0)
    (step,) = find_steps(t, flashed, ("gps", "baro"), KINDS)
    # its means over the first 2 s after the step and over the last 2 s of the span
    first, last = (3.0 * np.exp(-np.arange(a, a + 2.0, 0.1) / 5.0).mean() for a in (0.0, 18.0))
    assert STEP_SETTLE_S == 20.0
    assert step.settle_m == pytest.approx(last - first, abs=0.1)
    assert step_record(step)["settle_m"] == round(step.settle_m, 3)
    held = z.copy()
    held[after, 1] += 3.0
    assert find_steps(t, held, ("gps", "baro"), KINDS)[0].settle_m == 0.0
    further = held.copy()
    further[after, 1] += np.clip(t[after] - 105.0, 0.0, 3.0)
    assert find_steps(t, further, ("gps", "baro"), KINDS)[0].settle_m == 0.0
    lost = flashed.copy()
    lost[t >= 110.0, 0] = np.nan
    (step,) = find_steps(t, lost, ("gps", "baro"), KINDS)
    assert step.settle_m == pytest.approx(-step.size_m)
    # found across the GPS's gap, it has no instant to settle from
    regained = flashed.copy()
    regained[(t >= 95.0) & (t < 100.0), 0] = np.nan
    (step,) = find_steps(t, regained, ("gps", "baro"), KINDS)
    assert step.half_width_s > 2.0
    assert step.settle_m == 0.0


def test_a_step_across_a_gap_is_found_in_its_middle_and_a_long_gap_is_not_bridged() -> None:
    """A GPS lost for 10 s in the climb and regained 2 m higher (its fix elsewhere), the
    barometer measuring on; lost for longer than STEP_GAP_S, or both lost, nothing is said."""
    t, _, z = two_sensors()
    lost = z.copy()
    lost[(t >= 40.0) & (t < 50.0), 0] = np.nan
    lost[t >= 50.0, 0] += 2.0
    (step,) = find_steps(t, lost, ("gps", "baro"), KINDS)
    assert step.time_s == pytest.approx(44.95, abs=0.11)
    assert step.size_m == pytest.approx(-2.0, abs=0.25)  # 0.057 m standard error
    longer = z.copy()
    longer[(t >= 40.0) & (t < 40.0 + STEP_GAP_S + 5.0), 0] = np.nan
    longer[t >= 40.0, 0] += 2.0
    assert find_steps(t, longer, ("gps", "baro"), KINDS) == ()
    # nor a pause of the log (both lost): it ends an excursion as often as it starts a level
    paused = lost.copy()
    paused[(t >= 40.0) & (t < 50.0), 1] = np.nan
    assert find_steps(t, paused, ("gps", "baro"), KINDS) == ()


def test_a_step_across_a_gap_is_a_candidate_from_regain_sigmas() -> None:
    """A real receiver's GPS (0.3 m noisy, wandering) lost for 10 s and regained 2 m higher:
    6.8 sigma across its gap, a tentative step (the smoother takes it where the likelihood
    says it jumped); the same 2 m without the gap is not 10 sigma, and no step."""
    t, _, z = two_sensors(4, gps_noise=0.3, walk_m2_s=0.01)
    lost = z.copy()
    lost[(t >= 40.0) & (t < 50.0), 0] = np.nan
    lost[t >= 50.0, 0] += 2.0
    (step,) = find_steps(t, lost, ("gps", "baro"), KINDS)
    assert step.tentative
    assert step_record(step)["tentative"] is True
    assert REGAIN_SIGMAS < step.sigmas <= STEP_SIGMAS
    assert step.time_s == pytest.approx(44.95, abs=0.11)
    assert step.size_m == pytest.approx(-2.0, abs=0.6)
    jumped = z.copy()
    jumped[t >= 45.0, 0] += 2.0
    assert find_steps(t, jumped, ("gps", "baro"), KINDS) == ()


@pytest.mark.parametrize("gap", [0, 1, 13])
def test_a_step_is_two_least_squares_lines_drawn_to_the_gap_s_middle(gap: int) -> None:
    rng = np.random.default_rng(gap)
    n, k = 9, 30
    d = rng.normal(size=60)
    d[k - gap : k] = np.nan
    before, after = np.arange(k - gap - n, k - gap), np.arange(k, k + n)
    middle = (k - gap - 1 + k) / 2
    expected = np.polyval(np.polyfit(after, d[after], 1), middle) - np.polyval(
        np.polyfit(before, d[before], 1), middle
    )
    assert _step_at(d, k, n, gap) == pytest.approx(expected, abs=1e-12)
    # its standard deviation per unit noise, by the lines' covariance
    design = [np.column_stack([np.ones(n), x - middle]) for x in (after, before)]
    variance = sum(np.linalg.inv(a.T @ a)[0, 0] for a in design)
    assert _end_error(n, gap) == pytest.approx(np.sqrt(variance), rel=1e-12)


def test_a_sensor_s_own_jump_is_found_in_a_span_by_its_own_heights() -> None:
    """A climb at 2 m/s, 0.05 m noisy, 1 m higher from 66.27 s: within 62-75 s its own heights
    jump at the boundary before the first stepped tick (the climb's ramp meets itself); a span
    with no whole lines either side, none."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 120.0, 0.1)
    h = 2.0 * t + rng.normal(0, 0.05, t.size) + np.where(t >= 66.27, 1.0, 0.0)
    instant = jump_instant(t, h, (62.0, 75.0))
    assert instant is not None
    assert instant == pytest.approx(66.25, abs=0.051)
    assert jump_instant(t, np.full(t.size, np.nan), (62.0, 75.0)) is None
    assert jump_instant(t[:1], h[:1], (0.0, 1.0)) is None
