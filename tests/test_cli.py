"""The command line as a user meets it: exit codes, files, one-line messages."""

from __future__ import annotations

import hashlib
import io
import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner, Result

from altfuse import __version__
from altfuse.cli import cli
from altfuse.fuse import METHODS
from conftest import SAMPLE_LOG, ardupilot_logs, shared_log


def run(*args: str | Path) -> Result:
    return CliRunner().invoke(cli, [str(a) for a in args])


def assert_one_line_error(result: Result, code: int, fragment: str) -> None:
    assert result.exit_code == code, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("altfuse: error: ")
    assert fragment in lines[0]
    assert "Traceback" not in result.output


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_fuse_sample_log_writes_csv_weights_and_provenance(tmp_path: Path) -> None:
    out = tmp_path / "out.csv"
    before = sha(SAMPLE_LOG)
    result = run("fuse", SAMPLE_LOG, "-o", out, "--weights", tmp_path / "w.csv")
    assert result.exit_code == 0, result.output
    # a sound log, nothing to warn of: its rangefinder's 4 samples at its minimum range on the
    # ground were "4 implausible samples dropped"
    assert result.stderr == ""
    assert sha(SAMPLE_LOG) == before
    table = pd.read_csv(out)
    sensors = ["gps", "baro", "rangefinder"]
    assert list(table.columns) == (
        ["time_s"]
        + [f"alt_{s}_m" for s in sensors]
        + ["fused_alt_m", "fused_std_m", "status", "n_sensors"]
        + [f"weight_{s}" for s in sensors]
    )
    assert len(table) == 1200
    np.testing.assert_allclose(np.diff(table.time_s), 0.1, atol=1e-6)
    assert table.time_s.iloc[0] == pytest.approx(30.0)  # the log's own clock
    weights = table[[f"weight_{s}" for s in sensors]].sum(axis=1)
    np.testing.assert_allclose(weights, 1.0, atol=1e-5)
    assert table.fused_alt_m.notna().all()
    assert (table.fused_std_m > 0).all()
    meta = json.loads((tmp_path / "out.meta.json").read_text())
    assert meta["input"]["sha256"] == before
    assert meta["altfuse_version"] == __version__
    assert meta["method"] == "smoother"  # the default
    assert {o["sensor"] for o in meta["datum"]["offsets"]} == set(sensors)
    gps = next(o for o in meta["datum"]["offsets"] if o["sensor"] == "gps")
    assert gps["offset_m"] == pytest.approx(112.0, abs=0.5)  # the simulated home, AMSL
    traces = pd.read_csv(tmp_path / "w.csv")
    for key in ("weight", "offset"):
        assert f"{key}_baro" in traces.columns
    assert not list(tmp_path.glob(".*tmp"))


@pytest.mark.parametrize("method", sorted(METHODS))
def test_every_method_runs_from_the_cli(tmp_path: Path, method: str) -> None:
    result = run("fuse", SAMPLE_LOG, "-o", tmp_path / "o.csv", "--method", method)
    assert result.exit_code == 0, result.output
    assert f"method {method}" in result.stdout


def test_fused_sample_is_close_to_the_simulated_truth(tmp_path: Path) -> None:
    out = tmp_path / "o.csv"
    assert run("fuse", SAMPLE_LOG, "-o", out).exit_code == 0
    table = pd.read_csv(out)
    from altfuse.io import read_log
    from altfuse.simulate import HOME_AMSL_M

    sim = next(r for r in read_log(SAMPLE_LOG).references if r.name == "sim")
    truth = np.interp(table.time_s, sim.t, sim.value) - HOME_AMSL_M
    rmse = float(np.sqrt(np.mean((table.fused_alt_m - truth) ** 2)))
    # measured: support 0.51 m, mean 0.55 m, best single sensor 0.58 m
    assert rmse < 0.56


def bad_inputs(tmp_path: Path) -> dict[str, Path]:
    text = tmp_path / "notes.txt"
    text.write_text("this is not a log\n")
    empty = tmp_path / "empty.bin"
    empty.touch()
    return {"missing": tmp_path / "missing.bin", "text": text, "empty": empty}


@pytest.mark.parametrize(
    ("case", "fragment"),
    [("missing", "no such file"), ("text", "not a DataFlash log"), ("empty", "empty")],
)
def test_bad_files(tmp_path: Path, case: str, fragment: str) -> None:
    out = tmp_path / "out.csv"
    result = run("fuse", bad_inputs(tmp_path)[case], "-o", out)
    assert_one_line_error(result, 1, fragment)
    assert not out.exists()
    assert not (tmp_path / "out.meta.json").exists()


def _refused(monkeypatch: pytest.MonkeyPatch, method: str, where: Path) -> None:
    """``Path.<method>`` on ``where`` refused by the system, as for a user without the right
    (the tests run as root, whom chmod does not stop)."""
    real = getattr(Path, method)

    def refuse(self: Path, *args: object, **kwargs: object) -> object:
        if self == where:
            raise PermissionError(13, "Permission denied", str(self))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Path, method, refuse)


def test_a_log_in_a_folder_that_may_not_be_entered_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``altfuse fuse /root/x.bin`` run by another user: its stat was refused, an internal
    error (exit 3) before."""
    log = tmp_path / "closed" / "x.bin"
    _refused(monkeypatch, "stat", log)
    for command in (["fuse", log, "-o", tmp_path / "out.csv"], ["info", log]):
        assert_one_line_error(run(*command), 1, f"{log}: cannot read (Permission denied)")
    assert not (tmp_path / "out.csv").exists()


def test_a_batch_whose_output_folder_may_not_be_made_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The system's refusals altfuse does not foresee (an output folder it may not create, a
    full disk) name the path and the reason, exit 1; an internal error (exit 3) before."""
    out = tmp_path / "results"
    _refused(monkeypatch, "mkdir", out)
    result = run("batch", SAMPLE_LOG, "-o", out)
    assert_one_line_error(result, 1, f"{out}: Permission denied")
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--rate", "0"], "--rate must be a positive number, got 0.0"),
        (["--rate", "-3"], "--rate must be a positive number, got -3.0"),
        (["--rate", "5000"], "--rate must be at most 1000, got 5000.0"),
        (["--max-gap", "0"], "--max-gap must be a positive number, got 0.0"),
        (["--method", "kalman"], "'kalman' is not one of"),
        (["-m", "support", "--alpha", "-1"], "--alpha must be a positive number, got -1.0"),
        (["-m", "support", "--alpha", "wide"], "'wide' is neither 'auto' nor a number"),
        (["-m", "support", "--beta", "-1"], "--beta must be a number >= 0, got -1.0"),
        (["-m", "support", "--window", "-2"], "--window must be a number >= 0, got -2.0"),
        (["--beta", "1"], "--beta does not apply to method 'smoother'"),
        (["--min-sensors", "0"], "--min-sensors must be a whole number >= 1, got 0"),
        (["--method", "mean", "--beta", "3"], "--beta does not apply to method 'mean'"),
        (["--method", "delay1", "--time-constant", "1"], "--time-constant does not apply"),
        (["--method", "delay1", "--q", "-1"], "--process-noise must be a number >= 0, got -1.0"),
        (["--method", "delay2", "--form", "exact"], "'exact' is not one of"),
        (["--method", "multilayer", "--time-constant", "0"], "--time-constant"),
        (["--method", "multilayer", "--e-max", "-1"], "--e-max"),
        (["--method", "multilayer", "--reopen", "-1"], "--reopen"),
        # beyond LARGEST: each an internal error (an overflow, NaN in the metadata) before
        (["-m", "support", "--window", "1e308"], "--window must be at most 1e+09, got 1e+308"),
        (["-m", "multilayer", "--time-constant", "1e308"], "--time-constant must be at most 1e+09"),
        (["--accel-noise", "1e308"], "--accel-noise must be at most 1e+09, got 1e+308"),
        (["--sigma", "gps=1e308"], "--sigma must be at most 1e+09, got 1e+308"),
    ],
)
def test_nonsense_parameters(tmp_path: Path, args: list[str], fragment: str) -> None:
    out = tmp_path / "out.csv"
    result = run("fuse", SAMPLE_LOG, "-o", out, *args)
    assert_one_line_error(result, 2, fragment)
    assert not out.exists()


def test_the_smallest_rate_and_ground_window_are_no_internal_error(tmp_path: Path) -> None:
    """At 1e-320 Hz the clock held one tick, at 0 s, and at a 1e-320 s ground window no tick
    was in the window: both were internal errors (NaN in the metadata; an empty window). The
    clock is refused as the log's fault for that rate, the window holds one tick."""
    out = tmp_path / "out.csv"
    result = run("fuse", SAMPLE_LOG, "-o", out, "--rate", "1e-320")
    assert_one_line_error(result, 1, "a single tick (a clock needs two) of a 9.99989e-321 Hz")
    assert not out.exists()
    result = run("fuse", SAMPLE_LOG, "-o", out, "--ground-window", "1e-320")
    assert result.exit_code == 0, result.output
    datum = json.loads(out.with_suffix(".meta.json").read_text())["datum"]
    start, end = datum["ground_window_s"]
    assert start == end  # one tick


@pytest.mark.parametrize(
    ("command", "args", "fragment"),
    [
        ("fuse", ["-o", "{out}", "--weights", "--force"], "'--weights': '--force' is an option"),
        ("fuse", ["-o", "--force"], "'--output': '--force' is an option, not a file name"),
        ("fuse", ["-o", "{out}", "--meta", "-v"], "Option '--meta' requires an argument"),
        ("evaluate", ["--csv", "--force"], "'--csv': '--force' is an option, not a file name"),
        ("batch", ["-o", "--force"], "'--output': '--force' is an option, not a file name"),
        ("fuse", ["-o", "results/"], "'results/' names a folder; name the file in it"),
        ("fuse", ["-o", "{out}", "--weights", "w/"], "'w/' names a folder; name the file in it"),
        # an empty path (-o "$OUT", OUT unset) was the current folder: batch wrote there, and
        # fuse failed inside (exit 3)
        ("fuse", ["-o", ""], "'--output': an empty path; name a file or folder"),
        ("fuse", ["-o", "{out}", "--meta", ""], "'--meta': an empty path; name a file or"),
        ("evaluate", ["--csv", " "], "'--csv': an empty path; name a file or folder"),
        ("batch", ["-o", ""], "'--output': an empty path; name a file or folder"),
    ],
)
def test_an_option_given_where_a_file_name_goes_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: str, args: list[str], fragment: str
) -> None:
    """A path forgotten after an output option: ``--weights --force`` wrote the weights to a
    file named ``--force`` and left the table it meant to overwrite as it was (click takes
    the next word as the value). Now exit 2, one line, nothing written; ``./--force`` names
    such a file. So is a file's path that names a folder: ``-o results/`` wrote a file
    named ``results``."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out.csv"
    out.write_text("an earlier run's table")
    log = SAMPLE_LOG.parent if command == "batch" else SAMPLE_LOG
    result = run(command, log, *(a.format(out=out) for a in args))
    assert_one_line_error(result, 2, fragment)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]
    assert out.read_text() == "an earlier run's table"
    written = run("fuse", SAMPLE_LOG, "-o", "./--force")
    assert written.exit_code == 0, written.output
    assert (tmp_path / "--force").is_file()


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (
            ["fuse", "-o", "{d}/fused.json"],
            "fused.json: this table is written as CSV, or as Parquet",
        ),
        (["fuse", "-o", "{d}/fused.bin"], "fused.bin: this table is written as CSV"),
        (["fuse", "-o", "{d}/fused.xlsx.gz"], "fused.xlsx.gz: this table is written as CSV"),
        (["fuse", "-o", "{d}/a.csv", "--weights", "{d}/w.png"], "w.png: this table is"),
        (["evaluate", "--csv", "{d}/r.parquet"], "r.parquet: this table is written as CSV, not as"),
    ],
)
def test_a_table_named_as_another_format_is_refused(
    tmp_path: Path, args: list[str], named: str
) -> None:
    """``-o fused.json`` wrote CSV into a .json file, and ``-o fused.bin`` a CSV that reads later
    as a damaged log, exit 0; ``evaluate --csv r.parquet`` wrote CSV under a Parquet name. Now
    exit 2, one line, nothing written."""
    command, *rest = args
    result = run(command, SAMPLE_LOG, *(a.format(d=tmp_path) for a in rest))
    assert_one_line_error(result, 2, named)
    assert not list(tmp_path.iterdir())
    for kept in ("a.txt", "b.csv.gz", "c.tsv"):
        assert run("fuse", SAMPLE_LOG, "-o", tmp_path / kept).exit_code == 0


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["fuse", "-o", "{d}/a.csv", "--meta", "{d}/a.bin"], "a.bin: this is written as JSON"),
        (["fuse", "-o", "{d}/a.csv", "--meta", "{d}/m.csv.gz"], "m.csv.gz: this is written as"),
        (["evaluate", "-o", "{d}/report.csv"], "report.csv: this is written as JSON, not as .csv"),
        (["evaluate", "-o", "{d}/r.parquet"], "r.parquet: this is written as JSON, not as .parq"),
    ],
)
def test_a_json_output_named_as_another_format_is_refused(
    tmp_path: Path, args: list[str], named: str
) -> None:
    """``evaluate -o report.csv`` wrote the JSON report into a .csv file, and ``--meta a.bin``
    a sidecar that reads later as a damaged log, exit 0; tables were refused so, JSON not. Now
    exit 2, one line, nothing written; a name of no format's (``a.meta``) or JSON's in any case
    is taken."""
    command, *rest = args
    result = run(command, SAMPLE_LOG, *(a.format(d=tmp_path) for a in rest))
    assert_one_line_error(result, 2, named)
    assert not list(tmp_path.iterdir())
    for kept in ("a.meta", "b.JSON", "c.json.gz"):
        table = tmp_path / f"{kept}.csv"
        result = run("fuse", SAMPLE_LOG, "-o", table, "--meta", tmp_path / kept)
        assert result.exit_code == 0, result.output
        assert (tmp_path / kept).exists()


def test_output_onto_the_input_is_refused(tmp_path: Path) -> None:
    log = tmp_path / "log.bin"
    log.write_bytes(SAMPLE_LOG.read_bytes())
    result = run("fuse", log, "-o", log)
    assert_one_line_error(result, 2, "is the input log")
    assert sha(log) == sha(SAMPLE_LOG)


def test_truncated_logs_never_crash(tmp_path: Path) -> None:
    """A log cut anywhere is processed up to its last whole record, or refused in one line."""
    data = SAMPLE_LOG.read_bytes()
    rng = np.random.default_rng(11)
    cuts = [1, 2, 50, 89, 90, 400, 3000, *rng.integers(3000, len(data), 12).tolist()]
    outcomes = {0: 0, 1: 0}
    for cut in cuts:
        log = tmp_path / f"cut{cut}.bin"
        log.write_bytes(data[:cut])
        out = tmp_path / f"cut{cut}.csv"
        result = run("fuse", log, "-o", out)
        assert result.exit_code in (0, 1), (cut, result.output)
        outcomes[result.exit_code] += 1
        if result.exit_code == 0:
            assert len(pd.read_csv(out)) > 0
        else:
            assert_one_line_error(result, 1, "")
            assert not out.exists()
        assert log.read_bytes() == data[:cut]
    assert outcomes[1] >= 7  # every cut before the first sensor record
    assert outcomes[0] >= 10


# Every log in ../shared/logs/ardupilot has a decided outcome: (exit code, sensors or message).
OUTCOMES: dict[str, tuple[int, str]] = {
    "ardusubtools_small.BIN": (1, "ArduSub log; its BARO is water depth"),
    "beastayyg_log_0036_mechanical_failure.bin": (0, "gps, baro"),
    "beastayyg_log_0038_mechanical_failure.bin": (0, "gps, baro, rangefinder"),
    "beastayyg_log_0039_mechanical_failure.bin": (0, "gps, baro, rangefinder"),
    "beastayyg_sample.bin": (0, "gps, baro"),
    "diaven_sample01.bin": (0, "gps, gps2, baro, rangefinder"),
    "hatemslah_demo-flight.bin": (1, "no usable altitude source"),
    "pfcFlightData_center_0003.bin": (1, "1 usable altitude source (gps)"),
    "pymavlink_test.BIN": (0, "gps, baro"),
    "rima48_test_cascade.BIN": (0, "gps, baro"),
    "spark404_log.bin": (0, "gps, baro"),
}


def test_every_shared_log_has_a_decided_outcome() -> None:
    shared_log("ardupilot")
    assert ardupilot_logs() == sorted(OUTCOMES)


@pytest.mark.parametrize("name", sorted(OUTCOMES))
def test_shared_log_outcome(tmp_path: Path, name: str) -> None:
    log = shared_log(f"ardupilot/{name}")
    code, expected = OUTCOMES[name]
    out = tmp_path / "out.csv"
    before = sha(log)
    result = run("fuse", log, "-o", out)
    assert sha(log) == before
    if code == 0:
        assert result.exit_code == 0, result.output
        assert f"sensors {expected};" in result.stdout
        assert pd.read_csv(out).fused_alt_m.notna().any()
    else:
        assert_one_line_error(result, code, expected)
        assert not out.exists()


def test_single_source_log_with_min_sensors_one(tmp_path: Path) -> None:
    log = shared_log("ardupilot/pfcFlightData_center_0003.bin")
    out = tmp_path / "out.csv"
    result = run("fuse", log, "-o", out, "--min-sensors", "1")
    assert result.exit_code == 0, result.output
    table = pd.read_csv(out)
    # one sensor is never "fused"; where the smoother leaves it (its GPS velocity says level
    # flight where its heights sink 5 m, and the autopilot's EKF agrees) it says so
    assert "single" in set(table.status)
    assert set(table.status.dropna()) <= {"single", "none", "diverged"}


def test_more_sensors_asked_than_a_log_has_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "out.csv"
    result = run("fuse", SAMPLE_LOG, "-o", out, "--min-sensors", "4")
    assert_one_line_error(
        result,
        1,
        "mission.bin: 3 usable altitude sources (gps, baro, rangefinder) where min_sensors is "
        "4; min_sensors 3 (--min-sensors 3) fuses them",
    )
    assert not out.exists()


def test_skipped_bytes_are_one_warning_line(tmp_path: Path) -> None:
    data = SAMPLE_LOG.read_bytes()
    damaged = tmp_path / "damaged.bin"
    damaged.write_bytes(data[: len(data) // 2] + bytes(1000) + data[len(data) // 2 :])
    result = run("fuse", damaged, "-o", tmp_path / "o.csv")
    assert result.exit_code == 0
    skipped = [line for line in result.stderr.splitlines() if "skipped" in line]
    assert skipped == [
        "altfuse: warning: damaged.bin: 1000 bytes skipped (not part of any decodable record)"
    ]


def test_erased_flash_at_a_log_s_end_is_no_warning(tmp_path: Path) -> None:
    """rima48 was read off a flash chip: 50 KB of erased flash after its last record warned as
    skipped bytes, as it would on every log of ArduPilot's block logger."""
    result = run("fuse", shared_log("ardupilot/rima48_test_cascade.BIN"), "-o", tmp_path / "o.csv")
    assert result.exit_code == 0
    assert "skipped" not in result.stderr
    assert "bytes" not in result.stderr


def test_a_failed_model_check_is_one_warning_line(tmp_path: Path) -> None:
    # a PX4 log whose GPS is up to 2 m off its EKF within 6 s: its innovations average 8x
    # what the smoother's noises say, so its fused_std is too small, and the user is told
    log = shared_log("px4/pyulog_sample_log_small.ulg")
    result = run("fuse", log, "-o", tmp_path / "o.csv")
    assert result.exit_code == 0, result.output
    warned = [line for line in result.stderr.splitlines() if "model check" in line]
    assert len(warned) == 1
    assert warned[0].startswith(
        "altfuse: warning: pyulog_sample_log_small.ulg: smoother's model check failed: mean "
        "squared normalised innovation gps "
    )
    meta = json.loads((tmp_path / "o.meta.json").read_text())
    assert meta["parameters"]["model_check"].startswith("failed: ")
    # the method that has no such check says nothing of it
    result = run("fuse", log, "-o", tmp_path / "m.csv", "-m", "mean")
    assert result.exit_code == 0, result.output
    assert "model check" not in result.stderr
    report = run("evaluate", log, "--methods", "mean,smoother")
    assert report.exit_code == 0, report.output
    checks = [line for line in report.stdout.splitlines() if line.startswith("model check")]
    assert len(checks) == 1
    assert checks[0].startswith("model check: smoother failed: mean squared normalised ")


def test_a_value_for_a_sensor_the_log_lacks_is_one_line_with_the_log_name(
    tmp_path: Path,
) -> None:
    # the smoother leaves it out and records it; fuse and evaluate say so, naming the log
    result = run("fuse", SAMPLE_LOG, "-o", tmp_path / "o.csv", "--sigma", "gps2=0.5")
    assert result.exit_code == 0, result.output
    warned = [line for line in result.stderr.splitlines() if "not used" in line]
    assert warned == [
        f"altfuse: warning: {SAMPLE_LOG.name}: not used, as this log does not have the sensors "
        "(its sensors: gps, baro, rangefinder): sigma_m (--sigma): gps2"
    ]
    meta = json.loads((tmp_path / "o.meta.json").read_text())
    assert meta["parameters"]["not_used"] == "sigma_m (--sigma): gps2"
    report = run("evaluate", SAMPLE_LOG, "--methods", "mean,smoother", "--sigma", "gps2=0.5")
    assert report.exit_code == 0, report.output
    assert report.stdout.splitlines()[-1] == (
        "not used by smoother, as this log does not have the sensors: sigma_m (--sigma): gps2"
    )


def test_a_sensor_the_datum_leaves_out_is_said_and_in_the_report(tmp_path: Path) -> None:
    # a ground window of 0.2 s holds no sample of a 5 Hz GPS: it was gone from the table, with
    # only the summary line's list of sensors to say so
    log = shared_log("truth/copter_4.0.7_eduardoavila_sonar_9m.BIN")
    result = run("fuse", log, "-o", tmp_path / "o.csv", "--ground-window", "0.2")
    assert result.exit_code == 0, result.output
    why = "gps: no sample on the ground and too few beside baro, rangefinder to find its datum"
    assert result.stderr == f"altfuse: warning: {log.name}: left out: {why}\n"
    args = ["--methods", "smoother,mean", "--ground-window", "0.2", "--sigma", "gps2=1"]
    report = run("evaluate", log, *args, "-o", tmp_path / "r.json")
    assert report.stdout.splitlines()[-2] == f"left out: {why}"
    # the JSON report holds what the text says under the table
    written = json.loads((tmp_path / "r.json").read_text())
    assert written["sensors_dropped"] == {why.split(": ")[0]: why.split(": ", 1)[1]}
    assert written["model_check"] == {"smoother": "passed"}
    assert written["not_used"] == {"smoother": "sigma_m (--sigma): gps2"}
    # and a batch names it at its end, as its summary's left_out column
    batch = run("batch", log, "-o", tmp_path / "b", "--ground-window", "0.2", "-j", "1")
    assert batch.exit_code == 0, batch.output
    assert f"{log.name} (gps left out)" in batch.stderr
    assert pd.read_csv(tmp_path / "b" / "summary.csv").left_out.tolist() == ["gps"]
    assert run("fuse", log, "-o", tmp_path / "p.csv").stderr == ""


def test_an_empty_log_path_is_a_usage_error() -> None:
    # it was the current folder: ".: a folder, not a log", exit 1
    for command in ("fuse", "info", "evaluate", "batch"):
        out = ["-o", "out.csv"] if command in ("fuse", "batch") else []
        assert_one_line_error(run(command, "", *out), 2, "an empty path; name a file or folder")


def test_info_text_and_json() -> None:
    result = run("info", SAMPLE_LOG)
    assert result.exit_code == 0
    assert "gps" in result.stdout
    assert "RFND.Dist" in result.stdout
    assert "sim (SIM.Alt" in result.stdout
    assert "vibration: not logged" in result.stdout  # altfuse's own logs have no VIBE
    data = json.loads(run("info", SAMPLE_LOG, "--json").stdout)
    assert data["vibration"] is None
    assert [s["name"] for s in data["sensors"]] == ["gps", "baro", "rangefinder"]
    gps = data["sensors"][0]
    assert gps["rate_hz"] == pytest.approx(5.0)
    assert gps["samples_dropped"] == {"GPS Status < 3 (no 3D fix)": 15}
    assert [r["name"] for r in data["references"]] == ["sim"]


def test_info_shows_the_steps_between_sensors() -> None:
    """The sample flight with faults: its GPS's 15 m glitch, in and out, two steps."""
    faults = str(Path(SAMPLE_LOG).with_name("mission_faults.bin"))
    result = run("info", faults)
    assert result.exit_code == 0
    lines = [line.strip() for line in result.stdout.splitlines() if "step at" in line]
    assert lines == [
        "step at 101.85 s: baro less gps -13.62 m (70 sigma)",
        "step at 106.95 s: baro less gps +14.00 m (59 sigma)",
    ]
    steps = json.loads(run("info", faults, "--json").stdout)["datum"]["steps"]
    assert [s["between"] for s in steps] == [["gps", "baro"]] * 2


def test_info_on_a_bad_file(tmp_path: Path) -> None:
    assert_one_line_error(run("info", bad_inputs(tmp_path)["text"]), 1, "not a DataFlash log")


def test_version_and_help() -> None:
    assert run("--version").stdout.strip() == f"altfuse, version {__version__}"
    for command in ("fuse", "info", "simulate"):
        result = run(command, "--help")
        assert result.exit_code == 0
        assert "Example" in result.stdout


def test_the_group_lists_each_command_by_its_own_first_sentence() -> None:
    """``altfuse --help`` shows the commands without importing them (cli.COMMANDS): each
    line is the command's own help, first paragraph."""
    from altfuse import cli as cli_module
    from altfuse import commands

    for name, summary in cli_module.COMMANDS.items():
        command = getattr(commands, name)
        assert command.name == name
        assert " ".join((command.help or "").split("\n\n")[0].split()) == summary
    shown = run("--help").output
    assert all(f"  {name}" in shown for name in cli_module.COMMANDS)


@pytest.mark.parametrize("argv", [["--help"], ["--version"], []])
def test_help_and_version_load_nothing_heavy(argv: list[str]) -> None:
    """Start-up pays only for what the command uses (issue 17): the group's help and the
    version load click and the standard library, not numpy, pandas, scipy or numba."""
    code = (
        "import sys\nfrom altfuse.cli import cli\ntry:\n    cli(sys.argv[1:])\n"
        "except SystemExit:\n    pass\n"
        "print(sorted(m for m in ('numpy', 'pandas', 'scipy', 'numba', 'pyarrow', 'matplotlib')"
        " if m in sys.modules))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, *argv], capture_output=True, text=True, check=True
    )
    assert done.stdout.strip().splitlines()[-1] == "[]"


#: A run of the console command (``main``) that says, in a destructor the interpreter's
#: teardown would call, whether it was torn down.
TORN_DOWN = (
    "import sys\nfrom altfuse.cli import main\n"
    "class Witness:\n    def __del__(self):\n        print('torn down', flush=True)\n"
    "witness = Witness()\nsys.argv = ['altfuse', *sys.argv[1:]]\nmain()\n"
)


@pytest.mark.parametrize(
    ("argv", "code"),
    [(["fuse", "{log}", "-o", "{out}"], 0), (["fuse", "{missing}", "-o", "{out}"], 1),
     (["fuse", "{log}", "-o", "{out}", "--rate", "-1"], 2)],
)  # fmt: skip
def test_the_command_ends_with_its_exit_code_without_the_teardown(
    tmp_path: Path, argv: list[str], code: int
) -> None:
    """Issue 17: the process ends once every exit handler has run, with the command's own
    exit code, its outputs whole, and without the interpreter freeing its modules object by
    object (0.12-0.2 s of a 0.9 s run on the sample log)."""
    out = tmp_path / "out.csv"
    paths = {"log": SAMPLE_LOG, "missing": tmp_path / "none.bin", "out": out}
    done = subprocess.run(
        [sys.executable, "-c", TORN_DOWN, *(a.format(**paths) for a in argv)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == code, done.stderr
    assert "torn down" not in done.stdout
    if code:
        assert len(done.stderr.strip().splitlines()) == 1
        assert not out.exists()
    else:
        rows = int(done.stdout.split(": ")[1].split()[0])  # "out.csv: 1200 rows, ..."
        assert len(pd.read_csv(out)) == rows > 1000
        assert json.loads(out.with_suffix(".meta.json").read_text())["clock"]["ticks"] == rows


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_progress_line_on_a_terminal_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 17: a long single run says what it does on one line of stderr, overwritten step
    by step and cleared at the end, only where stderr is a terminal."""
    from altfuse import commands

    logging.getLogger("altfuse").setLevel(logging.WARNING)
    for stream, expected in ((_Terminal(), True), (io.StringIO(), False)):
        monkeypatch.setattr(sys, "stderr", stream)
        with commands._progress_line():
            logging.getLogger("altfuse.progress").info("flight.bin: reading")
            logging.getLogger("altfuse.progress").info("smoother: noise pass 1 of 3")
        written = stream.getvalue()
        if expected:
            assert written == (
                "\r\033[Kaltfuse: flight.bin: reading ..."
                "\r\033[Kaltfuse: smoother: noise pass 1 of 3 ..."
                "\r\033[K"
            )
        else:
            assert written == ""
    assert logging.getLogger("altfuse.progress").handlers == []


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="a pseudo-terminal")
@pytest.mark.parametrize("command", ["fuse", "batch"])
def test_a_run_outlives_its_terminal(long_log: Path, tmp_path: Path, command: str) -> None:
    """A job left running when its shell exited (``altfuse batch ... &``, then ``exit``: no
    SIGHUP) writes its progress line into a hung-up terminal, which fails (EIO): that had ended
    ``fuse`` without its outputs, and a batch, its workers finishing every log, without its
    summary, exit 1. The run goes on without the line."""
    import pty
    import shutil

    out = tmp_path / "out"
    if command == "fuse":
        args = ["fuse", str(long_log), "-o", str(out / "a.csv")]
        expected = ["a.csv", "a.meta.json"]
    else:
        logs = tmp_path / "logs"
        logs.mkdir()
        for copy in ("a.bin", "b.bin", "c.bin"):
            shutil.copy(long_log, logs / copy)
        args = ["batch", str(logs), "-o", str(out), "-j", "1"]
        expected = [f"{s}.{x}" for s in "abc" for x in ("csv", "meta.json")]
        expected += ["index.json", "summary.csv"]
    primary, secondary = pty.openpty()
    with subprocess.Popen(
        [sys.executable, "-m", "altfuse", *args],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=secondary,
        text=True,
    ) as proc:
        os.close(secondary)
        assert os.read(primary, 200)  # the progress line began: a terminal
        os.close(primary)  # which hangs up
        stdout, _ = proc.communicate(timeout=120)
    assert proc.returncode == 0, stdout
    assert sorted(p.name for p in out.iterdir()) == expected


POOLS = """
import sys
from altfuse import cli
sys.argv = ["altfuse", "--version"]
try:
    cli.main()
except SystemExit:
    pass
import numpy
from threadpoolctl import threadpool_info
print(max(pool["num_threads"] for pool in threadpool_info()))
"""


@pytest.mark.parametrize(("given", "threads"), [(None, "1"), ("2", "2")])
def test_the_command_holds_numpy_s_thread_pools_to_one_thread(
    given: str | None, threads: str
) -> None:
    """A BLAS pool's threads only spin beside altfuse's work (and beside a batch's other
    workers); a user's own setting stands."""
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    done = subprocess.run(
        [sys.executable, "-c", POOLS], env=env, capture_output=True, text=True, check=True
    )
    assert done.stdout.split()[-1] == threads


def test_a_bare_altfuse_prints_the_help() -> None:
    """Issue 19: the help as --help prints it, not squashed onto one error line."""
    result = CliRunner().invoke(cli, [])
    assert result.exit_code == 0
    assert result.stdout == CliRunner().invoke(cli, ["--help"]).stdout
    assert "Commands:" in result.stdout
    assert result.stdout.count("\n") > 10


def test_the_global_flags_work_after_the_command(tmp_path: Path) -> None:
    """Issue 19: -v, -q and --debug after the command, as before it; after "--" they are
    arguments."""
    out = tmp_path / "m.csv"
    result = run("fuse", SAMPLE_LOG, "-o", out, "-v")
    assert result.exit_code == 0, result.output
    assert "altfuse: info: mission.bin: reading" in result.stderr
    quiet = run("fuse", SAMPLE_LOG, "-o", out, "--force", "-q")
    assert quiet.exit_code == 0
    assert quiet.stderr == ""  # not even the warning line
    literal = run("info", "--", "-v")
    assert literal.exit_code == 1
    assert "-v: no such file" in literal.stderr


@pytest.mark.parametrize("command", ["fuse", "evaluate", "batch", "info", "simulate"])
def test_every_command_s_help_gives_its_exit_codes(command: str) -> None:
    text = " ".join(run(command, "--help").stdout.split())
    assert "Exit codes: 0 done; 1 the log cannot be processed" in text
    assert "2 a usage or parameter error" in text
    if command == "batch":
        assert "4 when some failed" in text


def test_o_dash_writes_the_csv_to_standard_output(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 19: ``-o -`` is standard output (the CSV), not a file named "-"; the sidecar goes
    where --meta says, or nowhere, with a warning; the summary line goes to stderr."""
    monkeypatch.chdir(tmp_path)
    piped = run("fuse", SAMPLE_LOG, "-o", "-")
    assert piped.exit_code == 0, piped.output
    table = pd.read_csv(io.StringIO(piped.stdout))
    assert len(table) == 1200
    assert table.columns[0] == "time_s"
    assert "without its provenance (--meta names a file)" in piped.stderr
    assert "standard output: 1200 rows" in piped.stderr
    assert list(tmp_path.iterdir()) == []  # no file "-", no sidecar
    kept = run("fuse", SAMPLE_LOG, "-o", "-", "--meta", "m.json")
    assert kept.exit_code == 0
    assert "without its provenance" not in kept.stderr
    assert json.loads((tmp_path / "m.json").read_text())["outputs"] == {
        "csv": "-",
        "meta": "m.json",
    }
    assert kept.stdout == piped.stdout
    quiet = run("-q", "fuse", SAMPLE_LOG, "-o", "-", "--meta", "q.json")
    assert (quiet.exit_code, quiet.stderr, quiet.stdout) == (0, "", piped.stdout)


def test_an_end_of_input_within_a_command_is_an_error_not_an_interruption(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """click takes an EOFError for a prompt's Ctrl+D ("Aborted"); altfuse asks nothing, and a
    library's EOFError (numba reading an empty cache file) ended the run as interrupted, exit
    130, after an empty line."""

    from altfuse import commands

    def damaged(*_args: object) -> None:
        raise EOFError("Ran out of input")

    monkeypatch.setattr(commands, "run_to_files", damaged)
    result = run("fuse", SAMPLE_LOG, "-o", tmp_path / "f.csv")
    assert_one_line_error(result, 3, "internal error: EOFError: Ran out of input")


def test_a_closed_standard_output_is_said(tmp_path: Path) -> None:
    """``-o - >&-``: Python's sys.stdout is None; an internal error before."""
    closed = subprocess.run(
        f"'{sys.executable}' -m altfuse fuse '{SAMPLE_LOG}' -o - >&-",
        shell=True, cwd=tmp_path, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert (closed.returncode, closed.stderr) == (
        1,
        "altfuse: error: -: standard output is closed; name a file with -o\n",
    )
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("command", "written"),
    [
        (f"fuse '{SAMPLE_LOG}' -o f.csv", {"f.csv", "f.meta.json"}),
        (f"batch '{SAMPLE_LOG}' -o out --jobs 1", {"out"}),
        (f"evaluate '{SAMPLE_LOG}' -o e.json", {"e.json"}),
        (f"info '{SAMPLE_LOG}'", set()),
    ],
    ids=["fuse", "batch", "evaluate", "info"],
)
def test_a_closed_standard_error_runs_the_command(
    tmp_path: Path, command: str, written: set[str]
) -> None:
    """``2>&-`` (a daemon's or cron's job started with stderr closed): Python's sys.stderr is
    None, and ``fuse`` and ``batch``, asking whether it is a terminal for their progress line,
    ended in an internal error (exit 3) before writing anything. Nothing can be said there;
    the command runs."""
    closed = subprocess.run(
        f"'{sys.executable}' -m altfuse {command} 2>&-",
        shell=True, cwd=tmp_path, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert closed.returncode == 0
    assert {p.name for p in tmp_path.iterdir()} == written


@pytest.mark.parametrize(
    "args",
    [
        ("fuse", SAMPLE_LOG, "-o", "x.csv", "--weights", "-"),
        ("fuse", SAMPLE_LOG, "-o", "-", "--weights", "-"),
        ("fuse", SAMPLE_LOG, "-o", "x.csv", "--meta", "-"),
        ("evaluate", SAMPLE_LOG, "-o", "-"),
        ("evaluate", SAMPLE_LOG, "--csv", "-"),
        ("simulate", "hover", "-o", "-"),
    ],
)
def test_dash_is_standard_output_for_the_fused_table_alone(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, args: tuple[str | Path, ...]
) -> None:
    """Only ``fuse -o -`` reads "-" as standard output: any other output named "-" was
    written to a file of that name (the weights beside a table on standard output too)."""
    monkeypatch.chdir(tmp_path)
    assert_one_line_error(run(*args), 2, "'-' is standard output, which takes the fused table")
    assert list(tmp_path.iterdir()) == []
