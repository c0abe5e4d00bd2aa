"""Contracts every registered fusion method meets (parametrised over METHODS), and what a new
method gets by being registered: its CLI options and these tests."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from altfuse.cli import cli
from altfuse.fuse import DEFAULT_METHOD, METHODS, FusionInput, FusionResult, Method
from altfuse.fuse.mean import fuse_mean
from altfuse.params import UNIT_SUFFIXES, Params, fields, flag_of, unit_of
from altfuse.pipeline import FuseOptions
from conftest import ROOT, SAMPLE_LOG

NAMES = sorted(METHODS)


def call(name: str, z: np.ndarray) -> FusionResult:
    """Run method ``name`` with its defaults on heights on a 10 Hz clock, each sensor's samples
    its valid ticks; a method that requires the accelerometer gets a still one."""
    method = METHODS[name]
    accel = np.zeros(z.shape[0]) if "accel" in method.requires else None
    return method(FusionInput.from_heights(z, 0.1, accel_up=accel))


@pytest.fixture
def gappy() -> np.ndarray:
    rng = np.random.default_rng(3)
    z = 20.0 + rng.normal(0.0, 0.3, (200, 3))
    z[20:40, 0] = np.nan  # GPS outage
    z[60:70, 1:] = np.nan  # only GPS left
    z[90:95, :] = np.nan  # nothing
    return z


@pytest.mark.parametrize("name", NAMES)
def test_shapes_weights_and_status(name: str, gappy: np.ndarray) -> None:
    res = call(name, gappy)
    assert res.method == name
    assert res.fused.shape == (200,)
    assert res.weights.shape == (200, 3)
    valid = np.isfinite(gappy)
    some = valid.any(axis=1)
    np.testing.assert_allclose(res.weights[some].sum(axis=1), 1.0, rtol=1e-12)
    assert (res.weights[some][~valid[some]] == 0).all()
    assert np.isfinite(res.fused[some]).all()
    assert set(res.status[90:95]) <= {"none", "inertial"}
    assert np.isnan(res.fused[res.status == "none"]).all()
    assert set(res.status[60:70]) == {"single"}
    np.testing.assert_array_equal(res.weights[60:70], [[1.0, 0.0, 0.0]] * 10)
    for trace in res.traces.values():
        assert trace.shape == (200, 3)
    for trace in res.tick_traces.values():
        assert trace.shape == (200,)


@pytest.mark.parametrize("name", NAMES)
def test_stays_near_the_sensors(name: str, gappy: np.ndarray) -> None:
    res = call(name, gappy)
    some = np.isfinite(gappy).any(axis=1)
    assert np.max(np.abs(res.fused[some] - 20.0)) < 1.0  # sensors: 20 m, sigma 0.3 m


@pytest.mark.parametrize("name", NAMES)
def test_beats_the_worst_sensor_on_a_synthetic_truth(name: str, paper_a) -> None:  # type: ignore[no-untyped-def]
    res = call(name, paper_a.z)
    rmse = np.sqrt(np.mean((res.fused - paper_a.truth) ** 2))
    sensor_rmse = np.sqrt(np.mean((paper_a.z - paper_a.truth[:, None]) ** 2, axis=0))
    assert rmse < sensor_rmse.max()


@pytest.mark.parametrize("name", NAMES)
def test_parameters_are_typed_documented_and_on_the_command_line(name: str) -> None:
    method = METHODS[name]
    assert issubclass(method.params, Params)
    defaults = method.params()  # the defaults pass the type's own checks
    assert FuseOptions(method=name, params={name: defaults}).params_of() == defaults
    help_text = CliRunner().invoke(cli, ["fuse", "--help"], terminal_width=200).output
    for f in fields(method.params):
        assert f.name.endswith(UNIT_SUFFIXES[unit_of(f)]), f"{f.name}: the unit in its name"
        assert f.metadata["help"]
        assert flag_of(f) in help_text
    assert name in help_text


@pytest.mark.parametrize("name", ["mean", "support"])
def test_instantaneous_methods_stay_within_the_sensors(name: str, gappy: np.ndarray) -> None:
    res = call(name, gappy)
    some = np.isfinite(gappy).any(axis=1)
    lo, hi = np.nanmin(gappy[some], axis=1), np.nanmax(gappy[some], axis=1)
    assert (res.fused[some] >= lo - 1e-9).all()
    assert (res.fused[some] <= hi + 1e-9).all()
    np.testing.assert_array_equal(res.fused[60:70], gappy[60:70, 0])


def test_mean_is_the_equal_weight_average() -> None:
    z = np.array([[1.0, 2.0, 6.0], [1.0, np.nan, 3.0]])
    res = fuse_mean(FusionInput.from_heights(z), Params())
    np.testing.assert_allclose(res.fused, [3.0, 2.0])
    np.testing.assert_allclose(res.weights[1], [0.5, 0.0, 0.5])


def test_heights_of_one_sensor_may_be_one_dimensional() -> None:
    inputs = FusionInput.from_heights(np.array([1.0, np.nan, 3.0]))
    assert inputs.z.shape == (3, 1)
    assert inputs.names == ("gps",)
    np.testing.assert_array_equal(inputs.samples[0].value, [1.0, 3.0])


@pytest.mark.parametrize(
    ("z", "keywords", "message"),
    [
        (np.zeros((3, 4, 5)), {}, r"shape \(3, 4, 5\): heights are \(ticks, sensors\)"),
        (np.zeros((10, 2)), {"dt_s": 0.0}, "dt_s must be a positive number of seconds, got 0"),
        (np.zeros((10, 2)), {"dt_s": float("nan")}, "dt_s must be a positive number"),
        (np.zeros((10, 2)), {"kinds": ["gps"]}, r"1 kinds for 2 sensors \(the columns of z\)"),
        (np.zeros((10, 2)), {"kinds": ["gps", "lidar"]}, "unknown sensor kind 'lidar'; kinds"),
        (np.zeros((10, 2)), {"accel_up": np.zeros(9)}, r"accel has shape \(9,\) for .* 10 ticks"),
        # each of these came out of a method: a warning, an OverflowError, numpy's "array of
        # sample points is empty" (the smoother)
        (np.zeros((0, 2)), {}, r"shape \(0, 2\): heights are \(ticks, sensors\), one tick or"),
        (np.array([[1.0, np.inf]]), {}, r"holds inf at tick 0, column 1: heights are finite"),
        (np.array([[1.0], [-np.inf]]), {}, "holds -inf at tick 1, column 0"),
        (np.array([[1.0, 1e201]]), {}, r"holds 1e\+201 at tick 0, column 1: .* within 1e\+06 m"),
    ],
)
def test_heights_the_methods_cannot_take_are_refused_in_words(
    z: np.ndarray, keywords: dict[str, object], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        FusionInput.from_heights(z, **keywords)  # type: ignore[arg-type]


def test_the_inputs_on_the_analysis_clock_are_of_the_same_sensors() -> None:
    inputs = FusionInput.from_heights(np.zeros((10, 2)))
    other = FusionInput.from_heights(np.zeros((5, 2)), 0.2, kinds=["gps", "gps"])
    with pytest.raises(ValueError, match=r"analysis has sensors \('gps', 'gps2'\) for"):
        dataclasses.replace(inputs, analysis=other)


#: A new method as a contributor writes it: one module, one registry line.
TOY_METHOD = """
from dataclasses import dataclass

import numpy as np

from altfuse.fuse import METHODS, FusionInput, FusionResult, Method
from altfuse.fuse.base import combine
from altfuse.params import Params, param


@dataclass(frozen=True, kw_only=True)
class ToyParams(Params):
    lean_m: float = param(0.0, help="height added to the mean", unit="m")


def fuse_toy(inputs: FusionInput, params: ToyParams) -> FusionResult:
    mean = combine(inputs.z, np.isfinite(inputs.z).astype(float), "toy")
    return FusionResult("toy", mean.fused + params.lean_m, mean.weights, mean.status)


METHODS["toy"] = Method(fuse_toy, ToyParams, "the mean, leaning")
"""


def test_a_registered_method_gets_its_cli_option(tmp_path: Path) -> None:
    namespace: dict[str, object] = {}
    exec(compile(TOY_METHOD, "toy_method.py", "exec"), namespace)  # registers "toy"
    toy = METHODS["toy"]
    assert isinstance(toy, Method)
    try:
        help_text = CliRunner().invoke(cli, ["fuse", "--help"], terminal_width=200).output
        assert "--lean" in help_text
        assert "toy: height added to the mean [m] [default: 0]." in help_text
        out = tmp_path / "toy.csv"
        args = ["fuse", str(SAMPLE_LOG), "-o", str(out), "-m", "toy", "--lean", "0.5"]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        mean = tmp_path / "mean.csv"
        args = ["fuse", str(SAMPLE_LOG), "-o", str(mean), "-m", "mean"]
        assert CliRunner().invoke(cli, args).exit_code == 0
        np.testing.assert_allclose(
            pd.read_csv(out).fused_alt_m, pd.read_csv(mean).fused_alt_m + 0.5, atol=2e-6
        )
        refused = CliRunner().invoke(
            cli, ["fuse", str(SAMPLE_LOG), "-o", str(tmp_path / "x.csv"), "--lean", "1"]
        )
        assert refused.exit_code == 2
        assert f"--lean does not apply to method '{DEFAULT_METHOD}'" in refused.stderr
    finally:
        del METHODS["toy"]


def test_a_registered_method_gets_the_contract_tests(tmp_path: Path) -> None:
    (tmp_path / "toy_method.py").write_text(textwrap.dedent(TOY_METHOD))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), str(ROOT / "tests")]))
    plugin = ["-p", "toy_method", "-p", "no:cacheprovider"]
    done = subprocess.run(
        [sys.executable, "-m", "pytest", *plugin, "-q", "-k", "toy", str(Path(__file__))],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    # shapes, near the sensors, beats the worst sensor, typed parameters: 4 for "toy"
    assert "4 passed" in done.stdout, done.stdout
