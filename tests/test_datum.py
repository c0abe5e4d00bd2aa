"""Referring every sensor to height above the take-off point (ALGORITHMS.md section 4)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from altfuse.align import Aligned
from altfuse.datum import (
    DATUM_RATE_HZ,
    _either_search,
    coarser_than_datum,
    on_clock,
    refer_to_takeoff,
    referred_samples,
)
from altfuse.datum.scale import Track, Wind, _robust_fit, dynamic_head
from altfuse.datum.takeoff import detector_takeoffs, lift_off
from altfuse.fuse import FusionInput
from altfuse.fuse.support import SupportParams, fuse_support
from altfuse.info import _datum_text, describe_datum
from altfuse.model import Samples, Series
from altfuse.params import InvalidParameter
from altfuse.pipeline import FuseOptions, fuse_log, prepare
from altfuse.steps import Step
from conftest import shared_log


def flight(gps_offset: float = 146.0) -> tuple[Aligned, np.ndarray]:
    """20 s on the ground, a climb to 20 m over 10 s, 30 s of cruise; 10 Hz."""
    rng = np.random.default_rng(1)
    t = 100.0 + np.arange(600) / 10.0
    h = np.clip((t - 120.0) * 2.0, 0.0, 20.0)
    baro = 1.3 + h + rng.normal(0, 0.05, t.size)
    gps = gps_offset + h + rng.normal(0, 0.3, t.size)
    gps[:150] = np.nan  # no fix until 115 s
    rng_f = 0.2 + h + rng.normal(0, 0.02, t.size)
    rng_f[:250] = np.nan  # out of range on the ground (and until 125 s)
    z = np.column_stack([gps, baro, rng_f])
    aligned = Aligned(
        t, ("gps", "baro", "rangefinder"), ("gps", "baro", "rangefinder"), z, 10.0, 1.0, "union", {}
    )
    return aligned, h


def test_offsets_on_the_ground_and_matched_to_the_reference() -> None:
    aligned, h = flight()
    ref = refer_to_takeoff(aligned, ground_window_s=5.0, takeoff_climb_m=1.0)
    assert ref.reference == "baro"
    # h exceeds 1 m (smoothed) at 120.5 s
    assert ref.takeoff_s == pytest.approx(120.5, abs=0.2)
    offsets = {o.name: o for o in ref.offsets}
    assert offsets["baro"].offset_m == pytest.approx(1.3, abs=0.03)
    assert offsets["gps"].offset_m == pytest.approx(146.0, abs=0.2)
    assert offsets["gps"].method.startswith("median over the ground")
    # the ground window ends one second before take-off
    assert offsets["baro"].window_s[1] == pytest.approx(ref.takeoff_s - 1.0)
    # the rangefinder had no sample on the ground: matched to the barometer in flight
    assert "median difference from baro" in offsets["rangefinder"].method
    assert offsets["rangefinder"].offset_m == pytest.approx(0.2, abs=0.05)
    np.testing.assert_allclose(ref.h[:, 1], h, atol=0.25)


@pytest.mark.parametrize("climb_m", [0.5, 1.0, 5.0, 15.0])
def test_a_larger_take_off_climb_places_the_take_off_where_the_climb_began(climb_m: float) -> None:
    """``--takeoff-climb`` confirms a take-off (against a barometer wandering on the ground):
    the take-off stays where the climb passed 1 m (or the climb, where less). Placed where a
    5 m climb was reached, the ground window lay in the climb (at 122.5 s, the window 116.5-
    121.5 s rising 3 m), and the vehicle was held still there."""
    aligned, _ = flight()
    ref = refer_to_takeoff(aligned, ground_window_s=5.0, takeoff_climb_m=climb_m)
    # h rises 2 m/s from 120 s; smoothed, it exceeds 0.5 m at 120.3 s and 1 m at 120.5 s
    assert ref.takeoff_s == pytest.approx(120.3 if climb_m < 1 else 120.5, abs=0.15)
    assert ref.ground_window_s[1] < 120.0


def test_a_real_flight_s_take_off_holds_with_a_larger_take_off_climb() -> None:
    """A real 150 s flight fused with ``--takeoff-climb 5``: before, its take-off was placed at
    250.2 s, 6.7 s into the climb, and the smoother, held still there, left both sensors on
    205 ticks (by 2.3 m)."""
    log = shared_log("ardupilot/beastayyg_log_0036_mechanical_failure.bin")
    runs = [fuse_log(log, FuseOptions(takeoff_climb_m=climb)) for climb in (1.0, 5.0)]
    assert runs[1].referred.takeoff_s == runs[0].referred.takeoff_s == pytest.approx(243.5)
    assert runs[1].provenance["guard"]["diverged_ticks"] == 0


def test_a_gentle_lift_off_ends_the_still_span_before_it() -> None:
    """A barometer warming 0.01 m/s on the ground; the vehicle lifts at 120 s and climbs 0.2
    m/s: the 1 m is passed 5 s after the lift-off, and the vehicle was held still until 2 s
    after it, 0.4 m up. The knee lies at the lift-off, not in the warming."""
    t = 100.0 + np.arange(500) / 10.0
    h = np.clip(0.2 * (t - 120.0), 0.0, None)
    baro = 0.01 * (t - 100.0) + h + np.random.default_rng(2).normal(0, 0.05, t.size)
    aligned = Aligned(t, ("baro",), ("baro",), baro[:, None], 10.0, 1.0, "union", {})
    ref = refer_to_takeoff(aligned)
    assert ref.takeoff_s == pytest.approx(124.5, abs=0.5)  # 1 m above the first seconds'
    assert ref.liftoff_s == pytest.approx(120.0, abs=0.5)
    assert ref.on_ground_s is not None
    assert ref.on_ground_s[1] < 120.0
    # a warming alone has no knee that turns upwards
    assert lift_off(t, 0.03 * t, 115.0) == 115.0


def test_a_real_hand_flown_take_off_is_not_held_still_after_its_lift_off() -> None:
    """A real Copter 3.4 log lifts at 91.3 s (its rangefinder), hovers 0.4 m up and passes
    1 m at 95.4 s: held still until 92.4 s, the smoother stayed 0.3-0.5 m under its GPS,
    barometer and rangefinder through the flight (0.482 m RMSE from its EKF; coverage 0.003)."""
    run = fuse_log(shared_log("ardupilot/beastayyg_log_0038_mechanical_failure.bin"))
    datum = run.provenance["datum"]
    assert datum["liftoff_s"] == pytest.approx(90.3, abs=0.3)
    assert datum["still_s"][1] < 91.3
    said = _datum_text(describe_datum(prepare(run.log, FuseOptions())))
    assert (
        "  take-off 95.4 s, lift-off 90.3 s; the smoother holds it still 89.4-89.8 s; "
        "its barometers' wash tested 85.3-98.4 s"
    ) in said
    # from 5 s before the lift-off to 3 s after the take-off
    assert datum["wash_s"] == pytest.approx([85.3, 98.4], abs=0.05)
    t, h = run.referred.t, run.referred.h
    flying = (t > 95.0) & (t < 104.0)
    below = run.result.fused[flying] < np.nanmin(h[flying], axis=1)
    assert below.mean() < 0.2  # 0.02; 1.00 held still into the lift-off


def test_offset_sensor_keeps_its_weight() -> None:
    near, _ = flight(gps_offset=146.0)
    far, _ = flight(gps_offset=2146.0)
    w_near = fuse_support(FusionInput.from_heights(refer_to_takeoff(near).h), SupportParams())
    w_far = fuse_support(FusionInput.from_heights(refer_to_takeoff(far).h), SupportParams())
    np.testing.assert_allclose(w_far.weights, w_near.weights, atol=1e-9)


def test_no_takeoff_uses_the_first_seconds() -> None:
    aligned, _ = flight()
    z = aligned.z.copy()
    z[:, 1] = 1.3  # the barometer never rises
    still = Aligned(aligned.t, aligned.names, aligned.kinds, z, 10.0, 1.0, "union", {})
    ref = refer_to_takeoff(still)
    assert ref.takeoff_s is None
    assert ref.ground_window_s == (100.0, pytest.approx(104.9))
    baro = next(o for o in ref.offsets if o.name == "baro")
    assert "no take-off found" in baro.method


def test_sensor_without_any_overlap_is_dropped_with_a_reason() -> None:
    aligned, _ = flight()
    z = aligned.z.copy()
    z[:, 2] = np.nan
    z[:5, 2] = 3.0  # five rangefinder ticks, none on the ground-window nor beside the baro
    z[:5, 1] = np.nan
    lone = Aligned(aligned.t, aligned.names, aligned.kinds, z, 10.0, 1.0, "union", {})
    ref = refer_to_takeoff(lone)
    assert "rangefinder" not in ref.names
    assert "rangefinder" in ref.dropped


def test_a_barometer_begun_after_the_reference_ended_is_referred_beside_the_gps() -> None:
    """A PX4 barometer failed over to another device at 140 s, 4 m apart: the second begins
    where the first (the reference) ends, and is matched to the GPS over its first seconds,
    though it comes first among the sources, before the GPS is referred (it was dropped: "too
    few beside baro")."""
    aligned, h = flight()
    z = aligned.z.copy()
    after = aligned.t > 140.0
    second = np.where(after, z[:, 1] + 4.0, np.nan)
    z[after, 1] = np.nan
    failed_over = Aligned(
        aligned.t, ("baro2", *aligned.names), ("baro", *aligned.kinds),
        np.column_stack([second, z]), 10.0, 1.0, "union", {},
    )  # fmt: skip
    ref = refer_to_takeoff(failed_over)
    assert ref.reference == "baro"
    assert not ref.dropped
    baro2 = next(o for o in ref.offsets if o.name == "baro2")
    assert baro2.method.startswith("median difference from gps")
    assert baro2.offset_m == pytest.approx(1.3 + 4.0, abs=0.15)
    np.testing.assert_allclose(ref.h[after, 0], h[after], atol=0.4)


@pytest.mark.parametrize(
    ("ground_s", "climb_m", "name"),
    [
        (0.0, 1.0, "ground_window_s"),
        (5.0, -1.0, "takeoff_climb_m"),
        (math.inf, 1.0, "ground_window"),
    ],
)
def test_nonsense_parameters_are_refused_by_the_options(
    ground_s: float, climb_m: float, name: str
) -> None:
    with pytest.raises(InvalidParameter, match=f"^{name}.* must be a positive number"):
        FuseOptions(ground_window_s=ground_s, takeoff_climb_m=climb_m)


def test_rangefinder_tilt_correction() -> None:
    from altfuse.datum.tilt import tilt_correct
    from altfuse.model import Attitude, Series

    t = np.array([0.5, 1.0, 2.0, 9.0])
    rfnd = Series("rangefinder", "rangefinder", "RFND.Dist", "ground", t, np.full(4, 10.0))
    att_t = np.array([0.0, 5.0])
    att = Attitude("ATT", att_t, np.radians([30.0, 30.0]), np.radians([0.0, 60.0]), np.zeros(2))
    out = tilt_correct(rfnd, att)
    # roll 30°, pitch 60° * t / 5: d cos(30°) cos(pitch)
    expected = 10.0 * np.cos(np.radians(30.0)) * np.cos(np.radians(60.0 * t[:3] / 5.0))
    np.testing.assert_allclose(out.value, expected, rtol=1e-12)
    assert out.dropped == {"outside the attitude's time range": 1}
    assert "tilt-corrected with ATT" in out.datum
    # CTUN.SAlt comes tilt-corrected by the autopilot; no attitude: unchanged and said so
    salt = Series("rangefinder", "rangefinder", "CTUN.SAlt", "ground", t, np.full(4, 10.0))
    assert tilt_correct(salt, att) is salt
    assert "not tilt-corrected" in tilt_correct(rfnd, None).datum


def test_a_rangefinder_tilted_beyond_45_degrees_measures_no_height() -> None:
    """PX4's EKF2 uses no rangefinder tilted more than 45 degrees; there a small error of the
    attitude is a large one of ``d cos(tilt)``."""
    from altfuse.datum.tilt import MAX_TILT_DEG, TILTED, tilt_correct
    from altfuse.model import Attitude, Series

    t = np.linspace(0.0, 9.0, 10)
    rfnd = Series("rangefinder", "rangefinder", "RFND.Dist", "ground", t, np.full(10, 10.0))
    roll = np.radians(np.linspace(0.0, 90.0, 10))  # 10 degrees a second
    att = Attitude("ATT", t, roll, np.zeros(10), np.zeros(10))
    out = tilt_correct(rfnd, att)
    assert MAX_TILT_DEG == 45.0
    np.testing.assert_array_equal(out.t, t[:5])  # 0-40 degrees; 50-90 go
    np.testing.assert_allclose(out.value, 10.0 * np.cos(roll[:5]), rtol=1e-12)
    assert out.dropped == {TILTED: 5}


def test_every_offset_is_measured_at_the_reference_s_instants() -> None:
    """A vehicle creeping up at 8 cm/s before take-off, its barometer (the reference) silent
    for 6 s of the ground window: the GPS's median over all its ticks there was 0.148 m from
    the barometer's over its own last 1.2 s."""
    t = np.arange(0.0, 40.0, 0.1)
    h = np.where(t < 12, 0.08 * t, 0.08 * 12 + 2.0 * (t - 12))
    baro = 3.0 + h
    baro[(t >= 4) & (t < 10)] = np.nan
    names = ("gps", "baro")
    z = np.column_stack([500 + h, baro])
    ref = refer_to_takeoff(Aligned(t, names, names, z, 10.0, 1.0, "union", {}))
    assert ref.reference == "baro"
    assert ref.on_real_ground
    assert {o.window_s for o in ref.offsets} == {ref.ground_window_s}
    both = np.isfinite(baro)
    np.testing.assert_allclose(ref.h[both, 0], ref.h[both, 1], atol=1e-9)


def test_a_log_begun_in_a_climb_has_no_ground() -> None:
    """Its first seconds rise 1 m or more: no ground window (the take-off a climb's continuation
    would suggest), the log's first seconds."""
    t = np.arange(0.0, 60.0, 0.1)
    h = 20.0 + np.minimum(2.4 * t, 100.0)
    names = ("gps", "baro")
    z = np.column_stack([500 + h, 3.0 + h])
    ref = refer_to_takeoff(Aligned(t, names, names, z, 10.0, 1.0, "union", {}))
    assert not ref.on_real_ground
    assert ref.on_ground_s is None
    assert all("moving before take-off was found" in o.method for o in ref.offsets)
    np.testing.assert_allclose(ref.h[:, 0], ref.h[:, 1], atol=1e-9)


def scaled_flight(
    scale: float, climb_m: float, drift_m_per_min: float = 0.0, seed: int = 4
) -> tuple[Aligned, np.ndarray]:
    """A barometer ``scale`` times the truth (plus a drift in time), a GPS with a slow random
    walk; 20 s on the ground, a climb to ``climb_m``, a hold, a descent; 10 Hz."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 200.0, 0.1)
    h = np.interp(t, [0, 20, 60, 140, 180, 200], [0, 0, climb_m, climb_m, 0, 0])
    gps = 500 + h + np.cumsum(rng.normal(0, 0.02, t.size)) + rng.normal(0, 0.3, t.size)
    baro = 2.0 + scale * h + drift_m_per_min * t / 60 + rng.normal(0, 0.1, t.size)
    names = ("gps", "baro")
    return Aligned(t, names, names, np.column_stack([gps, baro]), 10.0, 1.0, "union", {}), h


def test_a_known_barometer_scale_is_found_and_removed() -> None:
    aligned, h = scaled_flight(1.05, 150.0)
    ref = refer_to_takeoff(aligned)
    baro = {o.name: o for o in ref.offsets}["baro"]
    # the GPS's 0.9 m of wander over the flight: the scale to 0.3 %, within its error
    assert baro.scale == pytest.approx(1.05, abs=0.006)
    assert baro.scale_std is not None
    assert baro.scale_std < 0.006
    assert abs(baro.scale - 1.05) < 2 * baro.scale_std
    assert "against gps over the flight" in str(baro.scale_method)
    error = ref.h[:, 1] - h
    assert np.sqrt(np.mean(error**2)) < 0.35  # offset only: 4.5 m at the top
    offset_only = refer_to_takeoff(aligned, referral="offset")
    assert {o.name: o for o in offset_only.offsets}["baro"].scale == 1.0
    assert np.max(np.abs(offset_only.h[:, 1] - h)) > 7.0


def test_a_barometer_s_scale_is_found_beside_a_step_in_it() -> None:
    """A 10 m hover, the barometer 5 % high and 1 m higher from 120 s on, a GPS as precise as a
    simulator's: a level fit took the step for a scale (1.027 +- 0.014, refused; the simulators'
    hexacopter's 5 % went to 1.5 +- 4.4 %); with the step found (:mod:`altfuse.steps`) and free
    in the fit, 1.050 +- 0.010, applied."""
    t = np.arange(0.0, 200.0, 0.1)
    h = np.interp(t, [0, 20, 60, 140, 180, 200], [0, 0, 10, 10, 0, 0])
    _a_step_and_a_scale_found(t, h, 120.0, 6)


def _a_step_and_a_scale_found(t: np.ndarray, h: np.ndarray, at: float, seed: int) -> None:
    """Heights ``h``, a GPS 2 cm noisy, a barometer 10 cm noisy, 5 % high and 1 m higher from
    ``at`` [s] on: the step found there, 1 m, and the scale 5 %, applied."""
    rng = np.random.default_rng(seed)
    gps = 500 + h + rng.normal(0, 0.02, t.size)
    baro = 2.0 + 1.05 * h + np.where(t >= at, 1.0, 0.0) + rng.normal(0, 0.1, t.size)
    names = ("gps", "baro")
    ref = refer_to_takeoff(Aligned(t, names, names, np.column_stack([gps, baro]), 10.0, 1.0,
                                   "union", {}))  # fmt: skip
    (step,) = ref.steps
    assert (step.first, step.second) == ("gps", "baro")
    assert step.time_s == pytest.approx(at - 0.05, abs=0.11)
    assert step.size_m == pytest.approx(1.0, abs=0.1)
    baro_offset = {o.name: o for o in ref.offsets}["baro"]
    assert baro_offset.scale_applied
    assert baro_offset.scale == pytest.approx(1.05, abs=0.006)


def test_a_step_a_barometer_s_scale_hides_in_a_climb_is_found() -> None:
    """A climb at 2 +- 4 m/s (a plane's), the barometer 5 % high and 1 m higher from 45 s on:
    the 5 % of a changing climb rate bends the difference to the GPS everywhere, the lines
    either side of each instant read steps of 0.1-0.4 m all along and the 1 m one was 8.9
    sigma of them; the fit on the heights then took the step for scale and drift (1.062 +-
    0.008, applied). The fit on the changes, one of which crosses the step, tells 5 %: on the
    heights it refers, the step stands out."""
    t = np.arange(0.0, 80.0, 0.1)
    v = np.where(t < 10.0, 0.0, 2.0 + 4.0 * np.sin(2.0 * np.pi * (t - 10.0) / 6.0))
    _a_step_and_a_scale_found(t, np.cumsum(v) * 0.1, 45.0, 2)


def test_a_barometer_s_step_found_against_the_gps_is_free_against_the_rangefinder() -> None:
    """A 10 m hover over a rangefinder 2 cm noisy, beside a real receiver's GPS (0.3 m noisy,
    wandering), the barometer 5 % high, lost for 10 s and regained 2 m higher: the step is
    found against the GPS, whose fit cannot tell the scale (1.086 +- 0.077); the fit against
    the rangefinder, without the step (not one between those two), could not either (0.950 +-
    0.083). Which of a step's sensors jumped the datum does not know: a step of either is free
    in each fit, and the rangefinder tells 5 % to 1 %."""
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 120.0, 0.1)
    h = np.interp(t, [0, 20, 30, 120], [0, 0, 10, 10])
    walk = np.cumsum(rng.normal(0, np.sqrt(0.01 * 0.1), t.size))
    gps = 300 + h + walk + rng.normal(0, 0.3, t.size)
    baro = 2.0 + 1.05 * h + np.where(t >= 80.0, 2.0, 0.0) + rng.normal(0, 0.05, t.size)
    baro[(t >= 70.0) & (t < 80.0)] = np.nan
    rangefinder = np.where(h < 0.5, np.nan, 0.1 + h + rng.normal(0, 0.02, t.size))
    names = ("gps", "baro", "rangefinder")
    z = np.column_stack([gps, baro, rangefinder])
    ref = refer_to_takeoff(Aligned(t, names, names, z, 10.0, 1.0, "union", {}))
    assert [(s.first, s.second) for s in ref.steps] == [("gps", "baro")]
    baro_offset = {o.name: o for o in ref.offsets}["baro"]
    assert baro_offset.scale_applied
    assert "against rangefinder" in str(baro_offset.scale_method)
    assert baro_offset.scale == pytest.approx(1.05, abs=0.01)


def test_the_second_step_search_keeps_the_first_s_steps_across_a_gap_it_did_not_find() -> None:
    """The steps sought again on the scaled heights replace the first search's between the
    same sensors at the same place (within 2 s, or the gap a step lies in); the first's others
    across a gap stay: there the unscaled barometer misreads a step's size (the 3.3 plane's
    GPS regained 2 m higher: -6.0 m) but not that it is there. One between two ticks that the
    scaled heights do not have is the scale's, and goes."""
    across_gap = Step(162.45, "gps", "baro", -5.96, 10.5, 5.15)
    between_ticks = Step(40.05, "gps", "baro", 1.0, 12.0, 0.05)
    first = (between_ticks, across_gap)
    assert _either_search(first, (), 0.1) == (across_gap,)
    measured_again = Step(165.0, "gps", "baro", -2.1, 6.2, 5.0)
    assert _either_search(first, (measured_again,), 0.1) == (measured_again,)
    other_pair = Step(162.45, "gps", "baro2", -2.0, 11.0, 5.15)
    assert _either_search(first, (other_pair,), 0.1) == (other_pair, across_gap)
    found_again = Step(40.05, "gps", "baro", 1.02, 11.0, 0.05)
    assert _either_search(first, (found_again,), 0.1) == (found_again, across_gap)
    one_tick_gap = Step(40.1, "gps", "baro", 1.0, 12.0, 0.1)
    assert _either_search((one_tick_gap,), (), 0.1) == (one_tick_gap,)


def test_a_scale_fit_with_too_few_rows_to_reject_from_keeps_them() -> None:
    """Ten changes (a 40 s flight's, its GPS lost for 10 s), three of them 0.5-0.8 m off: the
    3-sigma rejection of so few rows left seven, fewer than SCALE_MIN_CHANGES, and no scale
    was estimated (17 of 200 such sets; the 4.5 plane's second barometer beside a GPS regained
    2 m higher, its scale 5 % left on). Now that fit stands: a scale for every set, within 3
    standard errors of the truth on 95 %."""
    z = []
    for seed in range(200):
        rng = np.random.default_rng(seed)
        x = rng.uniform(-5.0, 5.0, 10)
        y = 1.05 * x + rng.normal(0.0, 0.2, 10)
        y[:3] += rng.choice([-1.0, 1.0], 3) * rng.uniform(0.5, 0.8, 3)
        fit = _robust_fit(np.column_stack([x, np.ones(10)]), y, [math.inf, math.inf])
        assert fit is not None
        z.append((fit[0][0] - 1.05) / fit[1][0])
    assert np.mean(np.abs(z) < 3.0) >= 0.95


def test_a_long_fit_is_least_squares_over_the_rows_it_keeps() -> None:
    """A fit over 300,000 rows (a ULog's barometer at 97 Hz over 50 minutes), 1 % of them
    glitched by 5 m, its normal equations summed a block of rows at a time rather than over a
    copy of the rows kept (two such copies, 27 MB each, set a 300 MB ULog's peak): the same
    coefficients and standard errors as least squares over those rows, refitted without the
    residuals beyond 3 sigma as the fit does; and the glitches left out."""
    rng = np.random.default_rng(7)
    n = 300_000
    design = np.column_stack([np.ones(n), rng.uniform(0.0, 50.0, n), rng.uniform(0, 8.0, n)])
    y = design @ np.array([0.4, 0.002, 0.25]) + rng.normal(0.0, 0.1, n)
    glitched = rng.choice(n, n // 100, replace=False)
    y[glitched] += 5.0
    fit = _robust_fit(design, y, [math.inf, math.inf, math.inf])
    assert fit is not None
    keep = np.ones(n, dtype=bool)
    for _ in range(4):  # the fit's own refits, each over a copy of the rows kept
        coef = np.linalg.lstsq(design[keep], y[keep], rcond=None)[0]
        r = y - design @ coef
        sigma = 1.4826 * np.median(np.abs(r[keep] - np.median(r[keep])))
        keep = np.abs(r) <= max(3.0 * sigma, 0.1)
    assert not keep[glitched].any()
    np.testing.assert_allclose(fit[0], coef, rtol=1e-9, atol=1e-12)
    residual = np.sum(r[keep] ** 2) / (keep.sum() - 3)
    std = np.sqrt(np.diag(np.linalg.inv(design[keep].T @ design[keep] / residual)))
    np.testing.assert_allclose(fit[1], std, rtol=1e-9)


def test_a_scale_fit_with_too_few_changes_says_so() -> None:
    """A GPS in three bursts (8, 2 and 2 s) across a 20 m climb: its ticks are enough to fit
    levels on, but no span of the changes' fit has both ends. The scale is not estimated for
    that reason, named (it said "no vertical range" of a 20 m climb)."""
    aligned, _ = flight()
    t, z = aligned.t, aligned.z.copy()
    bursts = ((t >= 110) & (t < 118)) | ((t >= 130) & (t < 132)) | ((t >= 150) & (t < 152))
    z[~bursts, 0] = np.nan
    z[:, 2] = np.nan  # no rangefinder to fit against instead
    ref = refer_to_takeoff(Aligned(t, aligned.names, aligned.kinds, z, 10.0, 1.0, "union", {}))
    baro = {o.name: o for o in ref.offsets}["baro"]
    assert baro.scale_method == "not estimated: 0 spans with both heights' change, fewer than 8"


def test_a_barometer_s_scale_is_found_beside_its_dynamic_pressure() -> None:
    """A climb to 50 m, a cruise there at 8 m/s and back, the barometer 5 % high and reading
    0.8 V^2 / 2g higher (2.6 m at 8 m/s: its static pressure lowered by the air flowing past):
    a fit of the heights alone takes the cruise's rise for a scale (1.078); with the ground speed
    the head is fitted beside it (:func:`altfuse.datum.scale.dynamic_head`) and the scale is
    1.05."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 200.0, 0.1)
    h = np.interp(t, [0, 20, 60, 140, 180, 200], [0, 0, 50, 50, 0, 0])
    v = np.interp(t, [0, 70, 80, 120, 130, 200], [0, 0, 8, 8, 0, 0])
    head = v**2 / (2 * 9.80665)
    gps = 500 + h + rng.normal(0, 0.02, t.size)
    baro = 2.0 + 1.05 * h + 0.8 * head + rng.normal(0, 0.1, t.size)
    names = ("gps", "baro")
    aligned = Aligned(t, names, names, np.column_stack([gps, baro]), 10.0, 1.0, "union", {})
    alone = {o.name: o for o in refer_to_takeoff(aligned).offsets}["baro"]
    assert alone.scale_estimate == pytest.approx(1.078, abs=0.01)
    speed = Samples(t, v)
    track = Track(speed)
    baro_scale = {o.name: o for o in refer_to_takeoff(aligned, track=track).offsets}["baro"]
    assert baro_scale.scale_applied
    assert baro_scale.scale == pytest.approx(1.05, abs=0.003)
    assert "against gps beside its dynamic pressure over the flight" in str(baro_scale.scale_method)
    assert dynamic_head(speed, t) == pytest.approx(head)
    assert dynamic_head(Samples(t, v / 3), t) is None  # 2.7 m/s at most: 0.36 m, too little


def _out_and_back(wind_north: float) -> tuple[Aligned, Track]:
    """A climb to 50 m, a cruise north at 8 m/s there and back south, the barometer 5 % high
    and reading ``0.8 |V - W|^2 / 2g`` higher in a wind ``W`` blowing north at
    ``wind_north``; the GPS's heights, and its speed and course (0 out, 180 back)."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 200.0, 0.1)
    h = np.interp(t, [0, 20, 60, 140, 180, 200], [0, 0, 50, 50, 0, 0])
    north = np.interp(t, [0, 65, 75, 95, 105, 125, 135, 200], [0, 0, 8, 8, -8, -8, 0, 0])
    air = np.abs(north - wind_north)
    baro = 2.0 + 1.05 * h + 0.8 * air**2 / (2 * 9.80665) + rng.normal(0, 0.1, t.size)
    gps = 500 + h + rng.normal(0, 0.02, t.size)
    names = ("gps", "baro")
    aligned = Aligned(t, names, names, np.column_stack([gps, baro]), 10.0, 1.0, "union", {})
    course = np.where(north < 0, 180.0, 0.0)
    return aligned, Track(Samples(t, np.abs(north)), Samples(t, course))


def test_a_wind_is_found_beside_the_dynamic_pressure() -> None:
    """Out and back in a 3 m/s wind from the south: 5 and 11 m/s through the air at one
    ground speed, the barometer 1.0 and 4.9 m high. With the course the fit finds the wind
    (the ground velocity's north component beside the head) and the scale; the airspeed it
    leaves is the truth's. Without the course, the ground speed alone tells no head."""
    aligned, track = _out_and_back(3.0)
    baro = {o.name: o for o in refer_to_takeoff(aligned, track=track).offsets}["baro"]
    wind = refer_to_takeoff(aligned, track=track).wind
    assert wind is not None
    assert wind.north_m_s == pytest.approx(3.0, abs=0.2)
    assert wind.east_m_s == 0.0  # the track has no east: nothing told, nothing assumed
    assert wind.east_std_m_s is None
    assert wind.north_std_m_s is not None
    assert wind.north_std_m_s < 0.2
    assert wind.sigmas == pytest.approx(wind.north_m_s / wind.north_std_m_s)
    assert "in a wind of 3.0 m/s from 180 deg (north +3.0 +- 0.1)" in str(baro.scale_method)
    assert baro.scale == pytest.approx(1.05, abs=0.003)
    assert track.course is not None
    north = np.where(track.course.value == 180.0, -1.0, 1.0) * track.speed.value
    air = track.airspeed(wind)
    np.testing.assert_allclose(air.value, np.abs(north - wind.north_m_s), atol=1e-12)
    ground = {o.name: o for o in refer_to_takeoff(aligned, track=Track(track.speed)).offsets}
    assert "dynamic pressure" not in str(ground["baro"].scale_method)  # told by neither fit
    assert abs(baro.scale - 1.05) < abs(ground["baro"].scale - 1.05) / 4  # 0.0001 and 0.0043


def test_a_track_s_velocity_is_interpolated_as_components() -> None:
    """A course of 350 then 10 deg is north between them, not south (an angle interpolated
    through 180); a course of one sample tells no velocity, and the airspeed is the ground
    speed."""
    t = np.array([0.0, 2.0])
    track = Track(Samples(t, np.array([5.0, 5.0])), Samples(t, np.array([350.0, 10.0])))
    ne = track.components(np.array([1.0]))
    assert ne is not None
    np.testing.assert_allclose(ne[:, 0], [5.0 * np.cos(np.radians(10.0)), 0.0], atol=1e-12)
    lone = Track(track.speed, Samples(t[:1], np.array([90.0])))
    assert lone.components(t) is None
    assert lone.airspeed(Wind(1.0, 1.0, 0.1, 0.1)) is lone.speed


def test_no_wind_is_told_where_the_air_is_still() -> None:
    """The same flight in still air: the course changes nothing, no wind is told."""
    aligned, track = _out_and_back(0.0)
    with_course = refer_to_takeoff(aligned, track=track)
    without = refer_to_takeoff(aligned, track=Track(track.speed))
    assert with_course.wind is None
    assert with_course.offsets == without.offsets
    assert track.airspeed(None) is track.speed


@pytest.mark.parametrize("gps", [False, True])
def test_a_barometer_s_scale_is_found_against_a_rangefinder_that_tells_it_better(
    gps: bool,
) -> None:
    """An indoor flight (no GPS), and one whose GPS is a real receiver's (0.3 m noisy, wandering
    1 m in 100 s): a rangefinder over a flat floor and a barometer 6 % high. The scale went "not
    estimated: no GPS", or unapplied against the GPS, and the smoother followed the barometer
    0.4-0.7 m above the rangefinder (the simulators' 9 and 10 m sonar flights so changed)."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 120.0, 0.1)
    h = np.interp(t, [0, 20, 30, 100, 110, 120], [0, 0, 10, 10, 0, 0])
    rangefinder = 0.1 + h + rng.normal(0, 0.01, t.size)
    baro = 2.0 + 1.06 * h + rng.normal(0, 0.05, t.size)
    names: tuple[str, ...] = ("rangefinder", "baro")
    z = np.column_stack([rangefinder, baro])
    if gps:
        walk = np.cumsum(rng.normal(0, np.sqrt(0.01 * 0.1), t.size))
        z = np.column_stack([500 + h + walk + rng.normal(0, 0.3, t.size), z])
        names = ("gps", *names)
    baro_offset = {
        o.name: o
        for o in refer_to_takeoff(Aligned(t, names, names, z, 10.0, 1.0, "union", {})).offsets
    }["baro"]
    assert "against rangefinder" in str(baro_offset.scale_method)
    assert baro_offset.scale == pytest.approx(1.06, abs=0.005)


@pytest.mark.parametrize(
    ("scale", "climb_m", "drift", "why"),
    [
        (1.05, 5.0, 0.0, "too little vertical range"),  # 5 m: the GPS's wander is as large
        (1.0, 150.0, 0.3, "not different from 1"),  # a drift in time is not a scale
        (1.5, 150.0, 0.0, "implausible"),
    ],
)
def test_a_scale_the_flight_cannot_tell_is_not_applied(
    scale: float, climb_m: float, drift: float, why: str
) -> None:
    aligned, _ = scaled_flight(scale, climb_m, drift)
    baro = {o.name: o for o in refer_to_takeoff(aligned).offsets}["baro"]
    assert baro.scale == 1.0
    assert str(baro.scale_method).startswith("not applied")
    assert why in str(baro.scale_method)


def test_a_log_ending_seconds_after_take_off_still_has_its_scale_estimated() -> None:
    """3 s on the ground and a 4 s launch to 16 m, the barometer 5 % high: too few spans of
    1 s for the changes' fit (the scale was "not estimated"); shorter spans tell it (to about
    3 %, not applied: the smoother's scale test takes it from there)."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 7.0, 0.1)
    h = np.maximum(t - 3.0, 0.0) * 4.0
    gps = 500 + h + rng.normal(0, 0.02, t.size)
    baro = 2.0 + 1.05 * h + rng.normal(0, 0.12, t.size)
    names = ("gps", "baro")
    aligned = Aligned(t, names, names, np.column_stack([gps, baro]), 10.0, 1.0, "union", {})
    baro_offset = {o.name: o for o in refer_to_takeoff(aligned).offsets}["baro"]
    assert baro_offset.scale_estimate is not None, baro_offset.scale_method
    assert baro_offset.scale_std is not None
    assert abs(baro_offset.scale_estimate - 1.05) < 2 * baro_offset.scale_std


def test_a_rangefinder_without_ground_readings_takes_its_ground_clearance() -> None:
    aligned, h = flight()  # the rangefinder reads 0.2 m + h, nothing on the ground
    ref = refer_to_takeoff(aligned, clearances={"rangefinder": 0.2})
    rangefinder = {o.name: o for o in ref.offsets}["rangefinder"]
    assert rangefinder.offset_m == 0.2
    assert rangefinder.method.startswith("its ground clearance, 0.20 m")
    assert rangefinder.window_s is None
    np.testing.assert_allclose(ref.h[:, 2][np.isfinite(ref.h[:, 2])], h[250:], atol=0.1)


def censored_flight() -> tuple[Aligned, np.ndarray]:
    """:func:`flight` with the rangefinder mounted 0.1 m up under a 0.2 m minimum: on the ground
    only the noise's tail above its minimum is valid, a few scattered readings, biased high."""
    aligned, h = flight()
    rng = np.random.default_rng(2)
    reading = 0.1 + h + rng.normal(0, 0.08, h.size)
    z = aligned.z.copy()
    z[:, 2] = np.where(reading >= 0.2, reading, np.nan)
    return Aligned(aligned.t, aligned.names, aligned.kinds, z, 10.0, 1.0, "union", {}), h


def test_a_rangefinder_below_its_minimum_on_the_ground_is_not_referred_on_its_tail() -> None:
    aligned, _ = censored_flight()
    ground = refer_to_takeoff(aligned, ground_window_s=5.0)
    window = (aligned.t >= ground.ground_window_s[0]) & (aligned.t <= ground.ground_window_s[1])
    tail = aligned.z[window, 2]
    assert 0.0 < np.isfinite(tail).mean() < 0.5
    assert np.nanmedian(tail) > 0.2  # what a median over the ground window would have taken
    with_clearance = refer_to_takeoff(aligned, ground_window_s=5.0, clearances={"rangefinder": 0.1})
    offset = {o.name: o for o in with_clearance.offsets}["rangefinder"]
    assert offset.offset_m == 0.1
    assert "below its minimum there" in offset.method
    # without a clearance: matched to the barometer after take-off, not on the ground's tail
    offset = {o.name: o for o in ground.offsets}["rangefinder"]
    assert "median difference from baro" in offset.method
    assert offset.window_s is not None
    assert offset.window_s[0] > ground.takeoff_s
    assert offset.offset_m == pytest.approx(0.1, abs=0.05)


def two_flights(second_takes_off: bool) -> tuple[Aligned, np.ndarray]:
    """Two 80 s flights from the same ground, 30 s apart with nothing logged between (a
    reboot): the barometer recalibrates to 0 on the second boot, 3 m below its first zero; the
    second part starts in flight when it does not take off."""
    rng = np.random.default_rng(6)
    t = np.arange(0.0, 190.0, 0.1)
    h = np.interp(
        t, [0, 20, 40, 60, 80, 110, 130, 150, 170, 190], [0, 0, 10, 10, 0, 0, 0, 10, 10, 0]
    )
    if not second_takes_off:
        h[t >= 110] = 10.0
    baro = np.where(t < 110, 3.0 + h, h) + rng.normal(0, 0.05, t.size)
    gps = 400 + h + rng.normal(0, 0.3, t.size)
    z = np.column_stack([gps, baro])
    z[(t > 80) & (t < 110)] = np.nan
    names = ("gps", "baro")
    return Aligned(t, names, names, z, 10.0, 1.0, "union", {}), h


def test_each_segment_of_a_spliced_log_with_a_take_off_gets_its_own_datum() -> None:
    aligned, h = two_flights(second_takes_off=True)
    ref = refer_to_takeoff(aligned, splices=[110.0])
    assert [s.datum.split(",")[0] for s in ref.segments] == ["the main segment's", "its own"]
    assert ref.segments[1].start_s == pytest.approx(110.0)
    error = ref.h[:, 1] - h
    assert np.nanmax(np.abs(error)) < 0.3  # one datum: 3 m off after the reboot
    one = refer_to_takeoff(aligned)
    assert np.nanmax(np.abs(one.h[:, 1] - h)) > 2.5


def test_a_segment_s_samples_are_referred_with_its_own_datum() -> None:
    """The samples each sensor gives the smoother are the clock's heights at their times, in
    every segment: the main segment's offsets gave the second flight's barometer, recalibrated
    on its reboot, 3 m (and a scale its own datum applied: a fused height 0.25 m above both
    sensors)."""
    aligned, _ = two_flights(second_takes_off=True)
    ref = refer_to_takeoff(aligned, splices=[110.0])
    sensors = [
        Series(name, name, name, "test", aligned.t[ok], aligned.z[ok, j])
        for j, name in enumerate(aligned.names)
        for ok in [np.isfinite(aligned.z[:, j])]
    ]
    for j, samples in enumerate(referred_samples(sensors, ref)):
        on_clock = ref.h[np.searchsorted(ref.t, samples.t), j]
        np.testing.assert_allclose(samples.value, on_clock, atol=1e-9)
        assert (samples.t > 110).sum() > 500  # the second flight's samples are there


@pytest.mark.parametrize("second_takes_off", [True, False])
def test_another_clock_s_ticks_are_referred_as_the_datum_s_own(second_takes_off: bool) -> None:
    """A datum found on one clock refers another's ticks (a coarser output: :func:`on_clock`)
    as it referred its own, segment by segment: every fifth tick, the same heights."""
    aligned, _ = two_flights(second_takes_off)
    ref = refer_to_takeoff(aligned, splices=[110.0])
    rows = np.arange(0, aligned.t.size, 5)
    coarse = Aligned(
        aligned.t[rows], aligned.names, aligned.kinds, aligned.z[rows], 2.0, 1.0, "union", {}
    )
    moved = on_clock(ref, coarse, 10.0)
    assert moved.t is coarse.t
    assert moved.offsets == ref.offsets
    np.testing.assert_allclose(moved.h, ref.h[rows], atol=1e-12)


def test_a_barometer_s_scale_is_the_one_its_best_segment_tells() -> None:
    """A reboot splits a log: the longer part hovers 5 m up (its barometer's 6 % cannot be
    told there), the shorter climbs 60 m (it can). Both parts take the second's scale: one
    barometer, one scale, in the heights and in the samples the smoother fuses."""
    rng = np.random.default_rng(8)
    t = np.arange(0.0, 300.0, 0.1)
    h = np.interp(t, [0, 20, 25, 180, 185, 200, 220, 240, 260, 280, 300],
                  [0, 0, 5, 5, 0, 0, 0, 60, 60, 0, 0])  # fmt: skip
    baro = np.where(t < 200, 3.0, 0.0) + 1.06 * h + rng.normal(0, 0.05, t.size)
    gps = 400 + h + rng.normal(0, 0.05, t.size)
    z = np.column_stack([gps, baro])
    z[(t > 185) & (t < 200)] = np.nan
    names = ("gps", "baro")
    ref = refer_to_takeoff(Aligned(t, names, names, z, 10.0, 1.0, "union", {}), splices=[200.0])
    assert ref.segments[1].datum.startswith("its own")
    baro_main = {o.name: o for o in ref.offsets}["baro"]
    baro_second = {o.name: o for o in ref.segments[1].offsets}["baro"]
    assert baro_main.scale == baro_second.scale == pytest.approx(1.06, abs=0.01)
    assert "in another segment" in str(baro_main.scale_method)
    np.testing.assert_allclose(ref.h[t < 185, 1], h[t < 185], atol=0.25)


def test_a_segment_resumed_in_flight_keeps_the_main_datum() -> None:
    aligned, _ = two_flights(second_takes_off=False)
    ref = refer_to_takeoff(aligned, splices=[110.0])
    assert ref.segments[1].datum == "the main segment's offsets (no take-off in it)"
    np.testing.assert_allclose(ref.h[:, 0], refer_to_takeoff(aligned).h[:, 0])  # the GPS


def test_a_segment_resumed_in_a_cruise_that_climbs_keeps_the_main_datum() -> None:
    """Resumed in flight at 10 m, the second segment climbs 2 m at 130 s: to the heights alone
    a take-off from a ground at 10 m. The GPS says the vehicle flew at 5 m/s through that
    "ground": the main segment's offsets, not a datum 10 m up; where it stood (0.2 m/s), its
    own."""
    aligned, h = two_flights(second_takes_off=False)
    t = aligned.t
    climb = np.interp(t, [130.0, 140.0], [0.0, 2.0]) * (t >= 110)
    z = aligned.z + climb[:, None]
    aligned = Aligned(t, aligned.names, aligned.kinds, z, 10.0, 1.0, "union", {})
    flying = Samples(t, np.where(t >= 110, 5.0, 0.0))
    ref = refer_to_takeoff(aligned, splices=[110.0], track=Track(flying))
    assert ref.segments[1].datum == "the main segment's offsets (no take-off in it)"
    gps = ref.h[:, 0]
    late = t >= 150
    assert np.nanmedian(gps[late] - (h + climb)[late]) == pytest.approx(0.0, abs=0.3)
    standing = Samples(t, np.where((t >= 110) & (t < 135), 0.2, 5.0))
    own = refer_to_takeoff(aligned, splices=[110.0], track=Track(standing))
    assert own.segments[1].datum.startswith("its own, ground before take-off at 13")


def warming_on_the_ground() -> tuple[Aligned, np.ndarray]:
    """A copter's barometer warming on the ground: 0.03 m/s for the 75 s it stands (2.2 m), a
    hop to 1 m at 176 s; the GPS 3 m noisy. 10 Hz."""
    rng = np.random.default_rng(3)
    t = 100.0 + np.arange(1200) / 10.0
    h = np.interp(t, [176.0, 177.0, 200.0, 201.0], [0.0, 1.0, 1.0, 0.0])
    baro = 0.03 * np.minimum(t - 100.0, 75.0) + h + rng.normal(0, 0.05, t.size)
    gps = 40.0 + h + rng.normal(0, 3.0, t.size)
    names = ("gps", "baro")
    return Aligned(t, names, names, np.column_stack([gps, baro]), 10.0, 1.0, "union", {}), h


def test_a_warming_barometer_is_no_take_off_while_the_land_detector_says_landed() -> None:
    """ArduPilot's Copter logs when its land detector says the vehicle left the ground
    (``EV`` NOT_LANDED, 175 s here, at the motors' spool-up): the barometer's 1 m rise over
    its first 5 s comes at 135 s, on the ground; the one after 175 s is the take-off, and the
    hop reads 1 m above the ground the vehicle left, not 1 m + 2 m of warming."""
    aligned, _ = warming_on_the_ground()
    plain = refer_to_takeoff(aligned)
    assert plain.takeoff_s == pytest.approx(135.0, abs=2.0)
    told = refer_to_takeoff(aligned, takeoffs=(175.0,))
    assert told.takeoff_s == pytest.approx(177.0, abs=0.3)  # the rise after 175 s
    assert not told.detected  # a rise: held still up to STILL_MARGIN_S before it
    hop = (aligned.t > 180.0) & (aligned.t < 195.0)
    assert np.median(told.h[hop, 1]) == pytest.approx(1.0, abs=0.1)
    assert np.median(plain.h[hop, 1]) > 2.0
    baro = {o.name: o for o in told.offsets}["baro"]
    assert baro.method == "median over the ground before take-off at 177.1 s"


def test_a_hop_lower_than_the_rise_takes_off_where_the_land_detector_says() -> None:
    aligned, h = warming_on_the_ground()
    z = aligned.z.copy()
    z[:, 1] -= 0.6 * h  # a 0.4 m hop: no 1 m rise after the detector's take-off
    low = Aligned(aligned.t, aligned.names, aligned.kinds, z, 10.0, 1.0, "union", {})
    ref = refer_to_takeoff(low, takeoffs=(175.0,))
    assert ref.takeoff_s == 175.0
    assert ref.detected
    assert ref.on_ground_s == (pytest.approx(169.0), pytest.approx(174.0))  # all the window
    assert "(the autopilot's land detector)" in {o.name: o for o in ref.offsets}["baro"].method


def test_a_land_detector_before_the_log_leaves_the_take_off_to_the_rise() -> None:
    """Said flying before the reference's first sample (or before the segment): no ground
    window before it to stand on; the rise decides as without it."""
    aligned, _ = flight()
    plain = refer_to_takeoff(aligned)
    for said in (50.0, 100.5):  # before the clock, in the log's first second
        ref = refer_to_takeoff(aligned, takeoffs=(said,))
        assert (ref.takeoff_s, ref.ground_window_s) == (plain.takeoff_s, plain.ground_window_s)


def test_the_take_offs_of_a_sampled_verdict_are_its_turns_from_landed_to_flying() -> None:
    landed = Samples(np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]), np.array([1, 1, 0, 0, 1, 0.0]))
    assert detector_takeoffs(landed) == (3.0, 6.0)
    assert detector_takeoffs(None) == ()


def test_a_clock_is_coarser_than_the_datum_s_below_its_rate_not_at_its_step_s_rounding() -> None:
    """The pipeline (given ``--rate``) and the guard (given the clock's step) ask alike."""
    assert coarser_than_datum(5.0)
    assert coarser_than_datum(9.9)
    assert not coarser_than_datum(DATUM_RATE_HZ)
    assert not coarser_than_datum(1.0 / (1.0 / DATUM_RATE_HZ * (1 + 1e-12)))
    assert not coarser_than_datum(50.0)
