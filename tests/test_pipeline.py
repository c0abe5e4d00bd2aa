"""The whole chain on real logs, through the library API."""

from __future__ import annotations

import numpy as np
import pytest

from altfuse.errors import UnsupportedLogError
from altfuse.fuse import method
from altfuse.pipeline import FuseOptions, fuse_log, fusion_input, prepare_log, run_method
from conftest import SAMPLE_LOG, shared_log


@pytest.mark.parametrize("method", ["support", "mean"])
def test_log_0039_three_sensors_finite_over_the_flight(method: str) -> None:
    run = fuse_log(
        shared_log("ardupilot/beastayyg_log_0039_mechanical_failure.bin"),
        FuseOptions(method=method),
    )
    assert run.referred.names == ("gps", "baro", "rangefinder")
    assert run.provenance["sensors_dropped"] == {}
    assert np.isfinite(run.result.fused).all()
    # 80.5 s to 175.9 s of sensor data at 10 Hz
    assert run.referred.t.size == 955
    assert run.referred.takeoff_s == pytest.approx(88.2, abs=0.5)
    # a low hop: baro peaks 4.0 m, GPS 2.4 m, rangefinder 2.5 m above take-off; fused 2.41/2.45 m
    assert 2.0 < np.max(run.result.fused) < 3.0


def test_ardusub_is_refused() -> None:
    with pytest.raises(UnsupportedLogError, match="ArduSub"):
        fuse_log(shared_log("ardupilot/ardusubtools_small.BIN"))


def test_a_run_without_the_raw_inertial_records_is_the_same() -> None:
    """fuse_to_files lets the log's IMU and attitude go once the method's inputs are made: the
    run is the one made with them."""
    options = FuseOptions(method="smoother")
    prepared = prepare_log(SAMPLE_LOG, options)
    assert prepared.log.imu is not None
    assert prepared.log.attitude is not None
    inputs = fusion_input(prepared, method("smoother"), "smoother")
    lean = prepared.without_inertial()
    assert lean.log.imu is None
    assert lean.log.attitude is None
    assert lean.log.references == prepared.log.references
    ours = run_method(lean, options, inputs).result
    theirs = run_method(prepared, options).result
    np.testing.assert_array_equal(ours.fused, theirs.fused)
    np.testing.assert_array_equal(ours.tick_traces["fused_std"], theirs.tick_traces["fused_std"])
