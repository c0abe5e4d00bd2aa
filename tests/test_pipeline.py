"""The whole chain on real logs, through the library API."""

from __future__ import annotations

import numpy as np
import pytest

from altfuse.errors import UnsupportedLogError
from altfuse.pipeline import FuseOptions, fuse_log
from conftest import shared_log


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
