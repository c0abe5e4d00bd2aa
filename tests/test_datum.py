"""Referring every sensor to height above the take-off point (ALGORITHMS.md section 4)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from altfuse.align import Aligned
from altfuse.datum import refer_to_takeoff
from altfuse.fuse import FusionInput
from altfuse.fuse.support import SupportParams, fuse_support
from altfuse.params import InvalidParameter
from altfuse.pipeline import FuseOptions


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
    from altfuse.datum import tilt_correct
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
