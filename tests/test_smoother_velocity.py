"""The GPS's vertical velocity as a measurement of the smoother (issue 15, item 3): fused with
its lag as a state, checked against its receiver's heights, floored in its noise."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from accuracy import measure
from altfuse.fuse import FusionInput
from altfuse.fuse.smoother import SmootherParams, fuse_smoother
from altfuse.fuse.smoother.noise import MIN_SIGMA_VELOCITY_M_S
from altfuse.fuse.smoother.velocity import checked_velocity
from altfuse.model import Samples
from altfuse.pipeline import FuseOptions, fuse_log
from conftest import shared_log

DT = 0.02


def _climbs(lag_s: float, garbage: bool = False, seed: int = 3) -> tuple[FusionInput, np.ndarray]:
    """Climbs and descents of 8 m at up to 5 m/s: a GPS (0.3 m of noise) and a barometer
    (0.1 m) at 50 Hz on the clock, the accelerometer exact, and the GPS's vertical velocity at
    every tenth of its records (5 Hz), ``lag_s`` late with 0.1 m/s of noise (or noise of
    +-20 m/s: ``garbage``)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 120.0, DT)
    w = 2 * np.pi / 10.0
    h = 8.0 * np.sin(w * t)
    z = np.column_stack([h + rng.normal(0.0, 0.3, t.size), h + rng.normal(0.0, 0.1, t.size)])
    inputs = FusionInput.from_heights(z, DT, kinds=("gps", "baro"), accel_up=-(w**2) * h)
    tv = inputs.t[::10]  # the GPS's records: its heights and its velocity at one time each
    v = 8.0 * w * np.cos(w * (tv - lag_s)) + rng.normal(0.0, 0.1, tv.size)
    if garbage:
        v = rng.uniform(-20.0, 20.0, tv.size)
    return replace(inputs, gps_velocity_up=Samples(tv, v)), h


@pytest.mark.parametrize("lag_s", [0.0, 0.25])
def test_the_velocity_is_fused_and_its_lag_found(lag_s: float) -> None:
    inputs, h = _climbs(lag_s)
    res = fuse_smoother(inputs, SmootherParams())
    assert res.params["gps_velocity_up_samples"] == 600
    assert res.params["gps_velocity_up_refused"] == 0
    assert res.params["lag_gps_velocity_up_s"] == pytest.approx(lag_s, abs=0.03)
    # its noise, 0.1 m/s, is not taken below the floor
    assert res.params["sigma_gps_velocity_up_m_s"] >= MIN_SIGMA_VELOCITY_M_S
    v_true = 8.0 * 2 * np.pi / 10.0 * np.cos(2 * np.pi / 10.0 * inputs.t)
    assert np.sqrt(np.mean((res.tick_traces["velocity"] - v_true) ** 2)) < 0.05
    assert np.sqrt(np.mean((res.fused - h) ** 2)) < 0.05


def test_a_velocity_its_heights_contradict_is_not_used() -> None:
    inputs, _ = _climbs(0.0, garbage=True)
    velocity, refused = checked_velocity(inputs)
    assert velocity is None
    assert refused > 300
    res = fuse_smoother(inputs, SmootherParams())
    assert res.params["gps_velocity_up_samples"] == 0
    assert "lag_gps_velocity_up_s" not in res.params


def test_only_the_records_whose_height_was_kept_give_a_velocity() -> None:
    inputs, _ = _climbs(0.0)
    gps = inputs.samples[0]
    kept = Samples(gps.t[gps.t >= 60.0], gps.value[gps.t >= 60.0])
    velocity, _ = checked_velocity(replace(inputs, samples=(kept, inputs.samples[1])))
    assert velocity is not None
    assert velocity.t.min() >= 60.0
    assert velocity.t.size == 300


def test_a_simulated_plane_log_whose_velocity_is_noise_refuses_it() -> None:
    """ArduPlane 3.3's simulator logs GPS.VZ uncorrelated with its climbs (+25.7 m/s in a 7 m/s
    climb), and 0 on the ground: refused as a whole, the heights fused as before."""
    run = fuse_log(
        shared_log("truth/plane_3.3.0a1_gitterbadger_autotest_climb386m_imunoise.BIN"),
        FuseOptions(method="smoother"),
    )
    assert run.result.params["gps_velocity_up_samples"] == 0
    assert run.result.params["gps_velocity_up_refused"] > 500


def test_an_attitude_error_the_velocity_contradicts_costs_centimetres() -> None:
    """Paper A's flight with the logged roll 30 degrees off for 10 s: the velocity tells the
    accelerometer's error from the sensors' within a sample (0.479 m RMSE without it, against
    the mean's 0.400; 0.038 m with; 0.055 since the simulated sensors lag)."""
    row = measure(("paper-a", 1, ("attitude-error",)))
    assert row["smoother"] < 0.1
