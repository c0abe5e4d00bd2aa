"""Parameters: typed, checked once when built, in the library's own words; routed to methods."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from altfuse.errors import ParameterError
from altfuse.fuse import METHODS, params_by_method, params_for
from altfuse.fuse.complementary import MultilayerParams
from altfuse.fuse.delay import DelayParams
from altfuse.fuse.smoother import SmootherParams
from altfuse.fuse.support import SupportParams
from altfuse.params import LARGEST, InvalidParameter, fields, flag_of
from altfuse.pipeline import FuseOptions


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"rate_hz": 0.0}, "rate_hz must be a positive number, got 0.0"),
        ({"rate_hz": -5.0}, "rate_hz must be a positive number, got -5.0"),
        ({"rate_hz": math.nan}, "rate_hz must be a positive number, got nan"),
        ({"rate_hz": 2000.0}, "rate_hz must be at most 1000, got 2000.0"),
        ({"max_gap_s": 0.0}, "max_gap_s must be a positive number, got 0.0"),
        ({"span": "all"}, "span must be one of union, overlap, got 'all'"),
        ({"min_sensors": 0}, "min_sensors must be a whole number >= 1, got 0"),
        ({"min_sensors": 1.5}, "min_sensors must be a whole number >= 1, got 1.5"),
        ({"takeoff_climb_m": True}, "takeoff_climb_m must be a positive number, got True"),
    ],
)
def test_fuse_options_check_themselves_when_built(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(InvalidParameter) as caught:
        FuseOptions(**kwargs)  # type: ignore[arg-type]
    assert str(caught.value) == message


@pytest.mark.parametrize("name", sorted(METHODS))
def test_no_number_is_taken_beyond_the_largest(name: str) -> None:
    """Every number a method or the options take is refused beyond LARGEST (some overflowed
    first: an internal error), with each field's own maximum where lower."""
    assert LARGEST == 1e9
    types = [METHODS[name].params, FuseOptions]
    for cls in types:
        for f in fields(cls):
            if f.name in ("method", "params", "span", "referral", "form", "gate_form"):
                continue
            value = {"gps": 1e10} if f.name in ("sigma_m", "offset_noise_m2_s") else 1e10
            limit = min(f.metadata["maximum"], LARGEST)
            said = re.escape(f"{f.name} must be at most {limit:g}, got ")
            with pytest.raises(InvalidParameter, match=f"^{said}"):
                cls(**{f.name: value})


def test_fuse_options_know_the_methods_and_their_parameter_types() -> None:
    with pytest.raises(ParameterError, match="unknown method 'kalman'; choose one of mean"):
        FuseOptions(method="kalman")
    with pytest.raises(ParameterError, match="'support' takes SupportParams, not DelayParams"):
        FuseOptions(params={"support": DelayParams()})
    options = FuseOptions(method="delay2", params={"delay1": DelayParams(form="paper")})
    assert options.params_of() == DelayParams()  # delay2: not given, its defaults
    assert options.params_of("delay1").form == "paper"  # type: ignore[attr-defined]
    # one method's parameters alone are the method's (an AttributeError 'items' before)
    assert FuseOptions("support", SupportParams(beta=5)).params == {
        "support": SupportParams(beta=5)
    }
    with pytest.raises(ParameterError, match="'mean' takes Params, not SupportParams"):
        FuseOptions("mean", SupportParams())
    with pytest.raises(ParameterError, match=r"^params must be a method's parameters or map "):
        FuseOptions("support", [SupportParams()])  # type: ignore[arg-type]


def test_values_are_stored_in_their_canonical_form() -> None:
    assert type(SupportParams(beta=3).beta) is float
    assert FuseOptions(min_sensors=3.0).min_sensors == 3  # type: ignore[arg-type]
    sigmas = {"gps": 1}
    params = SmootherParams(sigma_m=sigmas)
    sigmas["gps"] = 5
    assert params.sigma_m == {"gps": 1.0}  # a copy
    with pytest.raises(InvalidParameter, match="sigma_m must be a positive number, got -1"):
        SmootherParams(sigma_m={"gps": -1})
    with pytest.raises(InvalidParameter, match="sigma_m must map sensor names to numbers"):
        SmootherParams(sigma_m=[("gps", 1.0)])  # type: ignore[arg-type]
    # numpy's numbers are numbers: np.float32(1) was "must be a positive number"
    gate = np.float32(4)
    float32 = SmootherParams(sigma_m={"gps": np.float32(0.5)}, gate_sigma=gate)
    assert float32.sigma_m == {"gps": 0.5}
    assert type(float32.gate_sigma) is float
    assert FuseOptions(min_sensors=np.int64(3)).min_sensors == 3
    with pytest.raises(InvalidParameter, match="takeoff_climb_m must be a positive number, got"):
        FuseOptions(takeoff_climb_m=np.bool_(True))  # type: ignore[arg-type]


def test_parameters_are_keyword_only() -> None:
    with pytest.raises(TypeError):
        SmootherParams({"gps": 1.0})  # type: ignore[misc]


def test_flags_are_the_field_names_less_their_unit() -> None:
    flags = {f.name: flag_of(f) for m in METHODS.values() for f in fields(m.params)}
    flags |= {f.name: flag_of(f) for f in fields(FuseOptions)}
    assert flags["time_constant_s"] == "--time-constant"
    assert flags["alpha_per_m2"] == "--alpha"
    assert flags["gate_sigma"] == "--gate"
    assert flags["accel_noise_m2_s3"] == "--accel-noise"
    assert flags["sigma_m"] == "--sigma"
    assert flags["ground_window_s"] == "--ground-window"
    assert flags["rate_hz"] == "--rate"
    assert flags["beta"] == "--beta"


def test_values_are_routed_to_every_method_that_takes_them() -> None:
    routed = params_by_method({"form": "paper", "q_m2_s": 1.0}, ["mean", "delay1", "multilayer"])
    assert routed == {
        "delay1": DelayParams(form="paper", q_m2_s=1.0),
        "multilayer": MultilayerParams(form="paper", q_m2_s=1.0),
    }
    assert params_by_method({}, ["support"]) == {}
    with pytest.raises(InvalidParameter, match=r"^alpha_per_m2 does not apply to method 'mean'$"):
        params_by_method({"alpha_per_m2": 1.0}, ["mean"])
    with pytest.raises(InvalidParameter, match=r"^beta does not apply to any of mean, delay1$"):
        params_by_method({"beta": 1.0}, ["mean", "delay1"])
    with pytest.raises(InvalidParameter, match="it takes alpha_per_m2, beta, window_s"):
        params_for("support", {"alpha": 1.0})
    with pytest.raises(InvalidParameter, match="it takes none"):
        params_for("mean", {"alpha": 1.0})
