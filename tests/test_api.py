"""The public face: ``import altfuse``, the README's Python example, the library job."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import altfuse
from altfuse.cli import cli
from altfuse.params import InvalidParameter
from conftest import ROOT, SAMPLE_LOG


def readme_python_examples() -> list[str]:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("\n## Python\n", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```python\n(.*?)```", section, flags=re.DOTALL)


def test_the_readme_python_example_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    example = readme_python_examples()[0]
    assert example.count("\n") == 4  # import, blank, three lines at most of code
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(example, "README.md", "exec"), {})
    lines = printed.getvalue().splitlines()
    assert lines[0].split() == ["time_s", "fused_alt_m", "status"]
    assert len(lines) == 4
    # the last ticks of the sample flight: time, a height near the ground, a status
    _, time_s, height, status = lines[-1].split()
    assert float(time_s) == pytest.approx(149.9)
    assert abs(float(height)) < 1.0
    assert status in {"fused", "single"}


def test_import_altfuse_names_its_public_face_without_loading_numpy() -> None:
    code = "import sys, altfuse; print(altfuse.__all__); print('numpy' in sys.modules)"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.splitlines()
    names = eval(out[0])  # a list literal
    for name in ("read_log", "fuse_log", "fuse_file", "evaluate", "FuseOptions", "METHODS"):
        assert name in names
    assert out[1] == "False"
    assert sorted(names) == sorted(["__version__", *altfuse._PUBLIC])
    for name in names:
        assert getattr(altfuse, name) is not None
    assert callable(altfuse.evaluate)  # the function, not the module altfuse.evaluation


def test_fuse_file_is_the_csv_table_with_the_options_and_parameters_routed() -> None:
    table = altfuse.fuse_file(SAMPLE_LOG, method="support", alpha_per_m2=0.5, rate_hz=5)
    assert list(table.columns[:2]) == ["time_s", "alt_gps_m"]
    np.testing.assert_allclose(np.diff(table.time_s), 0.2)
    default = altfuse.fuse_file(SAMPLE_LOG, rate_hz=5)
    assert not np.allclose(table.fused_alt_m, default.fused_alt_m)
    indexed = altfuse.fuse_file(SAMPLE_LOG, method="mean", time_index=True)
    assert isinstance(indexed.index, pd.TimedeltaIndex)
    assert indexed.index[0] == pd.Timedelta(seconds=indexed.time_s.iloc[0])
    assert len(indexed.resample("1s").mean(numeric_only=True)) == 120
    with pytest.raises(InvalidParameter, match=r"^beta must be a number >= 0, got -1"):
        altfuse.fuse_file(SAMPLE_LOG, method="support", beta=-1)
    with pytest.raises(InvalidParameter, match=r"^alpha is not a parameter of method 'support'"):
        altfuse.fuse_file(SAMPLE_LOG, method="support", alpha=0.5)


def test_a_run_s_repr_at_a_prompt_is_a_summary_not_every_sample() -> None:
    """At a prompt, ``run`` printed every sample of every series: 137 kB for a 3 min flight
    (a FlightLog 126 kB, an evaluation 420 kB). Arrays show their ends and their shape."""
    run = altfuse.fuse_log(SAMPLE_LOG, altfuse.FuseOptions(method="support"))
    gps = run.log.sensors[0]
    n = gps.t.size
    assert n > 100
    text = repr(gps)
    assert text.startswith(f"Series(name='gps', kind='gps', source='{gps.source}'")
    ends = ", ".join(f"{v:.6g}" for v in gps.t[[0, 1]]) + ", ..., "
    ends += ", ".join(f"{v:.6g}" for v in gps.t[[-2, -1]])
    assert f"t=array([{ends}], {n} float64)" in text
    for value in (run, run.log, run.result, altfuse.evaluate(SAMPLE_LOG, ["mean"])):
        text = repr(value)
        assert text.startswith(type(value).__name__ + "(")
        assert len(text) < 6000, (type(value).__name__, len(text))
    status = run.result.status
    assert f"status=array([{str(status[0])!r}, {str(status[1])!r}, ...," in repr(run.result)
    many = dataclasses.replace(run.log, params={f"P{i:03}": float(i) for i in range(900)})
    assert "params={'P000': 0.0, 'P001': 1.0, 'P002': 2.0, 'P003': 3.0, ...}" in repr(many)


def test_a_log_already_read_and_changed_is_fused_and_evaluated_as_given() -> None:
    """An experiment: read a log, leave a sensor out, fuse and measure what is left."""
    log = altfuse.read_log(SAMPLE_LOG)
    as_read = altfuse.fuse_log(log, altfuse.FuseOptions(method="support"))
    from_file = altfuse.fuse_log(SAMPLE_LOG, altfuse.FuseOptions(method="support"))
    np.testing.assert_array_equal(as_read.result.fused, from_file.result.fused)
    without_gps = dataclasses.replace(log, sensors=tuple(s for s in log.sensors if s.kind != "gps"))
    report = altfuse.evaluate(without_gps, ["support", "smoother"])
    assert report.truth.name == "sim"
    table = report.table()
    assert list(table.name) == ["support", "smoother", "baro", "rangefinder"]
    assert list(table.columns) == [
        "name", "kind", "segment", "n", "rmse", "mae", "max_abs", "bias", "within_2std"
    ]  # fmt: skip
    smoother = report.rows[1].overall
    assert table.rmse[1] == smoother.rmse
    assert table.within_2std[1] == smoother.within_2std
    assert np.isnan(table.within_2std[0])  # support gives no standard deviation
    table = altfuse.fuse_file(without_gps, method="mean")
    assert "alt_gps_m" not in table.columns
    assert "alt_gps_m" in altfuse.fuse_file(log, method="mean").columns


def test_a_simulated_flight_from_python_is_the_command_s_log(tmp_path: Path) -> None:
    """``simulate_flight`` and ``write_simulated_log`` write the log ``altfuse simulate``
    writes; one fault may be named alone."""
    flight = altfuse.simulate_flight("hover", 2, faults="gps-glitch")
    assert flight.faults == ("gps-glitch",)
    assert len(repr(flight)) < 3000  # its records and truth summarised
    ours = tmp_path / "ours.bin"
    altfuse.write_simulated_log(flight, ours)
    theirs = tmp_path / "theirs.bin"
    args = ["simulate", "hover", "--seed", "2", "--fault", "gps-glitch", "-o", str(theirs)]
    assert CliRunner().invoke(cli, args).exit_code == 0
    assert ours.read_bytes() == theirs.read_bytes()
    report = altfuse.evaluate(ours, "smoother")
    assert report.truth.name == "sim"
    assert report.table().rmse[0] < 0.5
    # a seed or a duration that is no number is said in the library's words (numpy's "expected
    # non-negative integer" and a TypeError before; the string "60" was taken as 60 s)
    same = altfuse.simulate_flight("hover", np.int64(2), faults="gps-glitch")
    altfuse.write_simulated_log(same, tmp_path / "same.bin")
    assert (tmp_path / "same.bin").read_bytes() == ours.read_bytes()
    assert type(same.seed) is int
    for seed, said in ((-1, "-1"), (1.5, "1.5"), ("1", "'1'"), (True, "True")):
        with pytest.raises(
            InvalidParameter, match=rf"^seed must be a whole number >= 0, got {said}$"
        ):
            altfuse.simulate_flight("hover", seed)  # type: ignore[arg-type]
    with pytest.raises(
        InvalidParameter, match=r"^duration_s must be a number of seconds, got '60'"
    ):
        altfuse.simulate_flight("hover", 1, duration_s="60")  # type: ignore[arg-type]
