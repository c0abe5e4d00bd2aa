"""altfuse batch: many logs, in parallel, resumable, locally or on Dask."""

from __future__ import annotations

import fcntl
import filecmp
import json
import multiprocessing
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import types
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner
from threadpoolctl import threadpool_info

from altfuse import __version__
from altfuse import batch as batch_module
from altfuse.batch import (
    EXIT_PARTIAL,
    BatchOptions,
    LogResult,
    _worker_start,
    doubted,
    find_logs,
    run_batch,
    unused,
)
from altfuse.cli import cli
from altfuse.errors import LogReadError, ParameterError
from altfuse.evaluation import evaluate
from altfuse.fuse.support import SupportParams
from altfuse.pipeline import FuseOptions
from conftest import ROOT, SAMPLE_LOG, shared_log

SAMPLES = ROOT / "sample_logs"
#: The test clusters' HTTP server on a free port: ``dashboard_address=None`` still listens on
#: 8787, and a second cluster (a concurrent test run) found it taken and failed to start.
DASHBOARD = ":0"


def outputs(folder: Path) -> dict[str, Path]:
    """Every per-log output under ``folder`` (not the summary, whose durations vary, nor the
    index, which names the scheduler's options)."""
    return {
        str(p.relative_to(folder)): p
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name not in ("summary.csv", "index.json")
    }


def test_batch_over_the_shared_logs_refuses_the_unfusable_and_exits_0(tmp_path: Path) -> None:
    """Issue 17: a log that is valid but not fusable (an ArduSub depth log, a single source) is
    ``refused`` with the reason, not ``failed``: nothing failed, exit 0. The summary says what a
    fleet operator acts on: the flight's span apart from the processing time, the vehicle, the
    reader's notes and skipped bytes, the take-off, the share fused, the divergences."""
    folder = shared_log("ardupilot")
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["batch", str(folder), "-o", str(out), "--jobs", "2"])
    assert result.exit_code == 0, result.output
    # no progress bar when stderr is not a terminal; one line on the log that needs a look
    assert result.stderr == (
        "altfuse: warning: 1 log of the 8 fused needs a look (the summary's left_out, damaged, "
        "diverged and model_check columns): rima48_test_cascade.BIN (diverged on 2 ticks, model "
        "check failed)\n"
    )
    summary = pd.read_csv(out / "summary.csv", keep_default_na=False)
    assert len(summary) == 11
    assert set(summary.status) == {"ok", "refused"}
    refused = summary[summary.status == "refused"].set_index("log").error.to_dict()
    assert set(refused) == {
        "ardusubtools_small.BIN",
        "hatemslah_demo-flight.bin",
        "pfcFlightData_center_0003.bin",
    }
    assert "water depth" in refused["ardusubtools_small.BIN"]
    assert "no usable altitude source" in refused["hatemslah_demo-flight.bin"]
    assert "1 usable altitude source (gps)" in refused["pfcFlightData_center_0003.bin"]
    # what the log is, though it was refused
    described = summary[summary.status == "refused"].set_index("log")
    assert described.loc["ardusubtools_small.BIN", "firmware"] == "ArduSub V4.1.0"
    assert described.loc["pfcFlightData_center_0003.bin", "vehicle"] == "plane"
    ok = summary[summary.status == "ok"].set_index("log")
    assert len(ok) == 8
    assert (ok.samples > 0).all()
    # the 150 s flight, processed in well under its duration: two columns, not one
    mechanical = ok.loc["beastayyg_log_0036_mechanical_failure.bin"]
    assert float(mechanical.flight_s) == pytest.approx(150.4)
    assert 0 < float(mechanical.processing_s) < 60
    assert mechanical.vehicle == "copter"
    damaged = ok.loc["rima48_test_cascade.BIN"]
    assert int(damaged.skipped_bytes) == 0  # its end is erased flash, not damage
    assert int(damaged.notes) >= 1
    # its GPS 15 m off its barometer, which its GPS velocity does not follow either, and steps
    # between them in its crash: the smoother left both for 43 s, counted, before the steps
    # were found (altfuse.steps); now only its last 0.2 s, 17 m off both where its GPS ends (the
    # guard's GROSS_M); each row as its log's sidecar says
    assert damaged.diverged == 2
    for log, row in ok.iterrows():
        meta = json.loads((out / Path(str(log)).with_suffix(".meta.json")).read_text())
        assert int(row.diverged) == meta["guard"]["diverged_ticks"]
        assert row.model_check == meta["parameters"]["model_check"]
    assert ok.loc["pymavlink_test.BIN"].model_check == "passed"
    assert all(0 < float(v) <= 1 for v in ok.fused_share)
    assert {str(v) for v in ok.takeoff_found} <= {"True", "False"}
    assert all(float(v) >= 0 for v in ok.max_excursion_m)
    for log in ok.index:
        stem = Path(log).with_suffix("").name
        assert (out / f"{stem}.csv").exists()
        assert (out / f"{stem}.meta.json").exists()
    assert not list(out.glob(f"{Path('ardusubtools_small').name}*"))
    assert "11 logs, ok 8, refused 3, skipped 0, failed 0" in result.stdout


def test_a_sensor_value_applies_to_the_logs_that_have_the_sensor(tmp_path: Path) -> None:
    """``--sigma rangefinder=0.05`` over a fleet: the logs with a rangefinder use it, those
    without fuse as they would (each failed before: 5 of the 8 fusable shared ArduPilot logs)."""
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("beastayyg_log_0038_mechanical_failure.bin", "spark404_log.bin"):
        (logs / name).symlink_to(shared_log(f"ardupilot/{name}"))
    out = tmp_path / "out"
    args = ["batch", str(logs), "-o", str(out), "-j", "1", "--sigma", "rangefinder=0.05"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    summary = pd.read_csv(out / "summary.csv").set_index("log")
    assert summary.status.to_dict() == {
        "beastayyg_log_0038_mechanical_failure.bin": "ok",
        "spark404_log.bin": "ok",
    }
    used = json.loads((out / "beastayyg_log_0038_mechanical_failure.meta.json").read_text())
    assert used["parameters"]["sigma_rangefinder_m"] == 0.05
    alone = CliRunner().invoke(cli, ["fuse", str(logs / "spark404_log.bin"), "-o", "-"])
    assert (out / "spark404_log.csv").read_text() == alone.stdout
    # said once at the end, not once per log without the log's name (a worker's warning)
    assert summary.not_used.fillna("").to_dict() == {
        "beastayyg_log_0038_mechanical_failure.bin": "",
        "spark404_log.bin": "sigma_m (--sigma): rangefinder",
    }
    assert [line for line in result.stderr.splitlines() if "not used" in line] == [
        "altfuse: warning: not used in 1 log of the 2 fused, for want of the sensors (the "
        "summary's not_used column): sigma_m (--sigma): rangefinder (spark404_log.bin)"
    ]


def test_the_logs_that_need_a_look_are_named_in_one_line() -> None:
    """The end of a batch names the logs fused now that ``fuse`` would have warned of: those
    with a sensor left out, those the guard flagged and those whose model check failed, by
    name, three at most; not a log refused, failed or skipped, nor one whose check passed or
    was not run (not the smoother)."""
    failed_check = "failed: mean squared normalised innovation gps 2.78"
    results = [
        LogResult("e.bin", "ok", diverged=12),
        LogResult("a.bin", "ok", model_check="passed"),
        LogResult("d.bin", "ok", diverged=3, model_check=failed_check),
        LogResult("b.ulg", "ok", model_check=failed_check),
        LogResult("f.bin", "ok", diverged=1),
        LogResult("c.bin", "ok"),  # a method without a model check
        LogResult("g.bin", "refused", "1 usable altitude source"),
        LogResult("h.bin", "failed", "cannot read", diverged=5),
        LogResult("i.bin", "skipped"),
        LogResult("j.bin", "ok", left_out="gps gps2", model_check="passed"),
    ]
    said = "need a look (the summary's left_out, damaged, diverged and model_check columns): "
    assert doubted(results) == (
        f"5 logs of the 7 fused {said}b.ulg (model check failed); d.bin (diverged on 3 ticks, "
        "model check failed); e.bin (diverged on 12 ticks); and 2 more"
    )
    assert doubted(results[4:]) == (
        f"2 logs of the 3 fused {said}f.bin (diverged on 1 tick); j.bin (gps gps2 left out)"
    )
    assert doubted(results[4:9]) == (
        f"1 log of the 2 fused {said.replace('need', 'needs', 1)}f.bin (diverged on 1 tick)"
    )
    assert doubted([results[1], results[5], *results[6:9]]) is None
    damaged = LogResult("k.bin", "ok", damaged="another log is appended", diverged=2)
    assert doubted([damaged]) == (
        f"1 log of the 1 fused {said.replace('need', 'needs', 1)}k.bin (damaged, diverged on "
        "2 ticks)"
    )


def test_a_log_with_another_appended_is_named_as_damaged(tmp_path: Path) -> None:
    """The summary's row of a file holding two logs says so (``damaged``), its sidecar too,
    and the batch's last line names it among those that need a look."""
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "joined.bin").write_bytes(
        SAMPLE_LOG.read_bytes() + (ROOT / "sample_logs" / "hover.bin").read_bytes()
    )
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["batch", str(logs), "-o", str(out), "--jobs", "1"])
    assert result.exit_code == 0, result.output
    assert "needs a look" in result.stderr
    assert "joined.bin (damaged)" in result.stderr
    row = pd.read_csv(out / "summary.csv", keep_default_na=False).iloc[0]
    said = json.loads((out / "joined.meta.json").read_text())["input"]["damaged"]
    assert len(said) == 1
    assert said[0].startswith("another log is appended from byte 311,792")
    assert row.damaged == said[0]
    assert row.notes >= 1


def test_values_for_sensors_logs_lack_are_said_once_per_set() -> None:
    """One line per set of values not used, with how many of the logs fused now did not use
    it and the first three by name; not for a log refused, failed or skipped."""
    sigma = "sigma_m (--sigma): rangefinder"
    both = f"{sigma}; offset_noise_m2_s (--offset-noise): gps2"
    results = [
        *(LogResult(f"{n}.bin", "ok", not_used=sigma) for n in "edcba"),
        LogResult("f.bin", "ok", not_used=both),
        LogResult("g.bin", "ok"),
        LogResult("h.bin", "failed", "cannot read", not_used=sigma),
        LogResult("i.bin", "skipped", not_used=sigma),
    ]
    assert unused(results) == [
        "not used in 5 logs of the 7 fused, for want of the sensors (the summary's "
        f"not_used column): {sigma} (a.bin, b.bin, c.bin and 2 more)",
        "not used in 1 log of the 7 fused, for want of the sensors (the summary's "
        f"not_used column): {both} (f.bin)",
    ]
    assert unused(results[6:]) == []


def test_all_ok_exits_0_and_mirrors_the_tree(tmp_path: Path) -> None:
    tree = tmp_path / "logs"
    (tree / "day1").mkdir(parents=True)
    (tree / "day2" / "copter").mkdir(parents=True)
    shutil.copy(SAMPLES / "mission.bin", tree / "day1" / "a.bin")
    shutil.copy(SAMPLES / "paper_a.bin", tree / "day2" / "copter" / "B.BIN")
    (tree / "day1" / "notes.txt").write_text("not a log")
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["batch", str(tree), "-o", str(out), "--jobs", "1"])
    assert result.exit_code == 0, result.output
    assert (out / "day1" / "a.csv").exists()
    assert (out / "day2" / "copter" / "B.meta.json").exists()
    assert sorted(pd.read_csv(out / "summary.csv").log) == ["day1/a.bin", "day2/copter/B.BIN"]


def test_finding_logs(tmp_path: Path) -> None:
    (tmp_path / "x").mkdir()
    for name in ("a.bin", "b.BIN", ".hidden.bin", "c.tlog", "x/d.Bin", "x/a.bin"):
        (tmp_path / name).write_bytes(name.encode())
    found = [str(rel) for _, rel in find_logs([tmp_path])]
    assert found == ["a.bin", "b.BIN", "x/a.bin", "x/d.Bin"]
    assert [str(rel) for _, rel in find_logs([tmp_path], "*.tlog")] == ["c.tlog"]
    # a log named twice is run once
    assert len(find_logs([tmp_path, tmp_path / "b.BIN"])) == 4
    # two logs of one name: the folder above both keeps them apart ("give the folders
    # separately" said nothing a user could do: they had been)
    above = re.escape(f"give the folder above both ({tmp_path}: its tree keeps them apart)")
    with pytest.raises(ParameterError, match=f"would write the same outputs .*; {above}, or run"):
        find_logs([tmp_path / "a.bin", tmp_path / "x" / "a.bin"])
    assert len(find_logs([tmp_path], "a.bin")) == 2  # as the message says
    with pytest.raises(LogReadError, match="no such file or folder"):
        find_logs([tmp_path / "nope"])
    with pytest.raises(LogReadError, match=r"^-: a batch takes files and folders, not standard"):
        find_logs(["-"])
    with pytest.raises(LogReadError, match="no file matching"):
        run_batch([tmp_path / "x"], tmp_path / "out", pattern="*.ulg")


def test_a_folder_that_cannot_be_listed_is_said(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A subfolder the user may not list (another user's flights): its logs are not in the
    batch, and a warning says so (rglob passed over it in silence)."""
    for name in ("open/a.bin", "closed/b.bin"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_bytes(b"x")
    real = os.scandir

    def scandir(path: str | Path) -> object:
        if Path(path) == tmp_path / "closed":
            raise PermissionError(13, "Permission denied", str(path))
        return real(path)

    monkeypatch.setattr(os, "scandir", scandir)
    assert [str(rel) for _, rel in find_logs([tmp_path])] == ["open/a.bin"]
    assert [r.getMessage() for r in caplog.records] == [
        f"{tmp_path / 'closed'}: cannot list (Permission denied): its logs are not in this batch"
    ]


def test_what_is_no_file_is_said_not_waited_on(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A link to nothing (a sync cut short) and a named pipe named as logs are warned of, one
    line each, and left out (passed over in silence before); named themselves, refused for
    what they are (before: "no such file or folder")."""
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "a.bin").write_bytes(b"x")
    (logs / "gone.bin").symlink_to(tmp_path / "nowhere.bin")
    os.mkfifo(logs / "pipe.bin")
    os.mkfifo(logs / "pipe.txt")  # not a log's name: not looked at
    assert [str(rel) for _, rel in find_logs([logs])] == ["a.bin"]
    assert [r.getMessage() for r in caplog.records] == [
        f"{logs / 'gone.bin'}: a link to nothing: not in this batch",
        f"{logs / 'pipe.bin'}: a pipe: not in this batch",
    ]
    for name, kind in (("gone.bin", "a link to nothing"), ("pipe.bin", "a pipe")):
        with pytest.raises(LogReadError, match=f"^{logs / name}: {kind}, not a log file$"):
            find_logs([logs / name])


def test_a_batch_that_finds_no_log_lists_its_folders_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """Its hint counts the text logs in the listing it chose from: an unlistable folder is
    warned of once, not once more for the hint."""
    for name in ("open/a.log", "closed/b.bin"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_bytes(b"x")
    real = os.scandir
    listed: list[Path] = []

    def scandir(path: str | Path) -> object:
        listed.append(Path(path))
        if Path(path) == tmp_path / "closed":
            raise PermissionError(13, "Permission denied", str(path))
        return real(path)

    monkeypatch.setattr(os, "scandir", scandir)
    with pytest.raises(LogReadError, match=r"1 \*\.log there: --pattern"):
        run_batch([tmp_path], tmp_path / "out")
    assert sorted(listed) == [tmp_path, tmp_path / "closed", tmp_path / "open"]
    assert [r.getMessage() for r in caplog.records] == [
        f"{tmp_path / 'closed'}: cannot list (Permission denied): its logs are not in this batch"
    ]
    assert not (tmp_path / "out").exists()


def test_nonsense_batch_options(tmp_path: Path) -> None:
    for args, fragment in ((["--jobs", "0"], "--jobs"), (["--rate", "0"], "--rate")):
        result = CliRunner().invoke(cli, ["batch", str(SAMPLES), "-o", str(tmp_path), *args])
        assert result.exit_code == 2
        assert fragment in result.stderr


def test_evaluate_and_plot_in_a_batch(tmp_path: Path) -> None:
    out = tmp_path / "out"
    results = run_batch(
        [SAMPLES / "paper_a.bin"],
        out,
        BatchOptions(evaluate=True, plot="png", weights=True),
        jobs=1,
    )
    assert [r.status for r in results] == ["ok"]
    assert sorted(p.name for p in out.iterdir()) == [
        "index.json",
        "paper_a.csv",
        "paper_a.evaluation.json",
        "paper_a.meta.json",
        "paper_a.png",
        "paper_a.weights.csv",
        "summary.csv",
    ]
    summary = pd.read_csv(out / "summary.csv")
    assert summary.truth[0] == "SIM.Alt"
    assert summary.support_rmse[0] == pytest.approx(0.2355, abs=1e-3)
    assert "support_within_2std" not in summary  # a weighting: no standard deviation
    evaluated = json.loads((out / "paper_a.evaluation.json").read_text())
    smoother = next(r for r in evaluated["rows"] if r["name"] == "smoother")["overall"]
    assert summary.smoother_within_2std[0] == pytest.approx(smoother["within_2std"], abs=1e-6)


def test_local_processes_and_a_dask_local_cluster_write_identical_outputs(tmp_path: Path) -> None:
    distributed = pytest.importorskip("dask.distributed")
    logs = [
        SAMPLES,
        shared_log("ardupilot/beastayyg_log_0039_mechanical_failure.bin"),
        shared_log("ardupilot/hatemslah_demo-flight.bin"),
    ]
    options = BatchOptions(evaluate=True, plot="svg", weights=True)
    local = run_batch(logs, tmp_path / "local", options, jobs=2)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=DASHBOARD
    ) as cluster:
        remote = run_batch(logs, tmp_path / "dask", options, scheduler=cluster.scheduler_address)
    assert sorted((r.log, r.status) for r in local) == sorted((r.log, r.status) for r in remote)
    a, b = outputs(tmp_path / "local"), outputs(tmp_path / "dask")
    assert sorted(a) == sorted(b)
    assert len(a) == 5 * 5  # 4 samples + log 0039, five files each; hatemslah failed: none
    different = [name for name in a if not filecmp.cmp(a[name], b[name], shallow=False)]
    assert different == []


def test_a_log_whose_dask_workers_die_fails_its_own_row(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A worker killed (out of memory) on every try ended the batch as an internal error with
    no summary; a log that died beside it failed with it. Now the logs that ended on the
    cluster run again one at a time, and only what fails alone fails: its row says why."""
    distributed = pytest.importorskip("dask.distributed")
    tries = tmp_path / "tries"  # a file per log, a line per try (the function runs as a copy)
    tries.mkdir()

    def process(job: batch_module.Job, options: BatchOptions) -> batch_module.LogResult:  # noqa: ARG001
        name = job.log.name
        with (tries / name).open("a") as tried:
            tried.write("try\n")
        first = (tries / name).read_text().count("try") == 1
        if name == "greedy.bin" or (name == "beside.bin" and first):
            worker = types.SimpleNamespace(address="tcp://worker")
            raise distributed.KilledWorker(f"process-{name}", worker, 3)
        if name == "bare.bin":
            raise ModuleNotFoundError("No module named 'altfuse'")
        return batch_module.LogResult(name, "ok")

    monkeypatch.setattr(batch_module, "process", process)
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("greedy.bin", "beside.bin", "bare.bin"):
        (logs / name).write_bytes(b"x")
    with distributed.LocalCluster(
        n_workers=1, processes=False, dashboard_address=DASHBOARD
    ) as cluster:
        results = run_batch([logs], tmp_path / "out", scheduler=cluster.scheduler_address)
    rows = {r.log: (r.status, r.error) for r in results}
    assert rows["beside.bin"] == ("ok", "")
    assert rows["greedy.bin"][0] == "failed"
    assert rows["greedy.bin"][1].startswith(
        "not finished on the Dask cluster: KilledWorker: Attempted to run task "
        "'process-greedy.bin' on 4 different workers, but all those workers died"
    )
    assert rows["bare.bin"] == (
        "failed",
        "not finished on the Dask cluster: ModuleNotFoundError: No module named 'altfuse'",
    )
    counted = {p.name: len(p.read_text().splitlines()) for p in tries.iterdir()}
    assert counted == {"greedy.bin": 2, "beside.bin": 2, "bare.bin": 1}
    summary = pd.read_csv(tmp_path / "out" / "summary.csv")
    assert sorted(summary.status) == ["failed", "failed", "ok"]


@pytest.mark.parametrize(
    ("address", "code", "said"),
    [
        ("tcp://127.0.0.1:9", 2, "cannot reach the Dask scheduler at tcp://127.0.0.1:9: "),
        ("nonsense", 2, "--scheduler must be an address such as tcp://host:8786, got 'nonsense'"),
        ("foo://x:1", 2, "unknown address scheme 'foo'"),
        ("", 2, "--scheduler must be an address such as tcp://host:8786, got ''"),
    ],
)
def test_a_scheduler_out_of_reach_or_no_address_is_one_line(
    tmp_path: Path, address: str, code: int, said: str
) -> None:
    """Not an internal error (a malformed address raised dask's ValueError), not a batch run
    on local processes (an empty address), and no output folder left behind."""
    pytest.importorskip("dask.distributed")
    out = tmp_path / "out"
    result = CliRunner().invoke(
        cli, ["batch", str(SAMPLES / "mission.bin"), "-o", str(out), "--scheduler", address]
    )
    assert result.exit_code == code
    assert said in result.stderr
    assert result.stderr.count("\n") == 1
    assert not out.exists()


def test_killed_batch_resumes_without_redoing_finished_logs(tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    logs.mkdir()
    for i in range(6):
        for sample in ("mission.bin", "paper_a.bin"):
            shutil.copy(SAMPLES / sample, logs / f"{i}_{sample}")
    out = tmp_path / "out"
    command = [
        sys.executable,
        "-m",
        "altfuse",
        "batch",
        str(logs),
        "-o",
        str(out),
        "--jobs",
        "1",
        "--plot",
        "png",
    ]
    proc = subprocess.Popen(
        command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    deadline = time.monotonic() + 120
    while len(list(out.glob("*.meta.json"))) < 3 and time.monotonic() < deadline:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done = {p.stem.removesuffix(".meta"): p.stat().st_mtime_ns for p in out.glob("*.meta.json")}
    assert 3 <= len(done) < 12, "the batch was not killed midway"
    assert not (out / "summary.csv").exists()
    # every log is complete (all four files) or has no output at all
    for stem in {p.name.split(".")[0] for p in out.iterdir() if not p.name.startswith(".")}:
        files = sorted(p.name for p in out.glob(f"{stem}.*"))
        assert files == [f"{stem}.csv", f"{stem}.meta.json", f"{stem}.png"] or stem not in done

    command.append("--skip-existing")
    rerun = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False)
    assert rerun.returncode == 0, rerun.stderr
    summary = pd.read_csv(out / "summary.csv").set_index("log")
    skipped = {Path(log).stem for log in summary.index[summary.status == "skipped"]}
    assert skipped == set(done)
    assert (summary.status[~summary.index.map(lambda x: Path(x).stem).isin(done)] == "ok").all()
    for stem, mtime in done.items():
        assert (out / f"{stem}.meta.json").stat().st_mtime_ns == mtime  # not redone
    assert len(list(out.glob("*.meta.json"))) == 12
    assert not list(out.glob(".*.tmp"))


def test_a_rerun_without_force_or_skip_existing_is_refused_whole(tmp_path: Path) -> None:
    """It failed each log alone ("exists"), exit 4, and the summary's rows of the earlier run,
    every metric, gave way to those failures: now one line, exit 2, nothing written."""
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(SAMPLES / "paper_a.bin", logs / "a.bin")
    out = tmp_path / "out"
    args = ["batch", str(logs), "-o", str(out), "-j", "1"]
    assert CliRunner().invoke(cli, args).exit_code == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    shutil.copy(SAMPLES / "mission.bin", logs / "b.bin")  # a new log beside it
    again = CliRunner().invoke(cli, args)
    assert again.exit_code == 2
    assert again.stderr == (
        f"altfuse: error: {out} holds the outputs of 1 of these 2 logs (a.bin): "
        "--skip-existing keeps the complete ones, --force redoes them\n"
    )
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    kept = CliRunner().invoke(cli, [*args, "--skip-existing"])
    assert kept.exit_code == 0, kept.stderr
    summary = pd.read_csv(out / "summary.csv").set_index("log")
    assert list(summary.status) == ["skipped", "ok"]
    assert summary.flight_s.notna().all()  # the skipped log's row kept from the first run


def test_skip_existing_redoes_changed_inputs_and_options(tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(SAMPLES / "mission.bin", logs / "m.bin")
    out = tmp_path / "out"
    assert [r.status for r in run_batch([logs], out, jobs=1)] == ["ok"]
    again = BatchOptions(skip_existing=True)
    assert [r.status for r in run_batch([logs], out, again, jobs=1)] == ["skipped"]
    other = BatchOptions(skip_existing=True, fuse=FuseOptions(method="mean"))
    # stale outputs (other options) are not overwritten without --force: the batch is
    # refused whole, its summary kept (each log failed alone, its summary row given away)
    summary = (out / "summary.csv").read_bytes()
    with pytest.raises(ParameterError, match=r"cannot keep \(method smoother, here mean\)"):
        run_batch([logs], out, other, jobs=1)
    with pytest.raises(ParameterError, match=r"cannot keep \(no m.weights.csv\)"):
        run_batch([logs], out, replace(again, weights=True), jobs=1)
    assert (out / "summary.csv").read_bytes() == summary
    other = BatchOptions(skip_existing=True, force=True, fuse=FuseOptions(method="mean"))
    assert [r.status for r in run_batch([logs], out, other, jobs=1)] == ["ok"]
    assert [r.status for r in run_batch([logs], out, other, jobs=1)] == ["skipped"]
    shutil.copy(SAMPLES / "paper_a.bin", logs / "m.bin")  # same name, new content
    [changed] = run_batch([logs], out, replace(other, force=False), jobs=1)
    assert changed.status == "failed"  # told by its hash, in its own run
    assert "not the complete outputs of this log as it is now" in changed.error
    assert [r.status for r in run_batch([logs], out, other, jobs=1)] == ["ok"]
    (out / "m.csv").unlink()  # an output lost
    assert [r.status for r in run_batch([logs], out, other, jobs=1)] == ["ok"]


def test_method_parameters_pass_through_a_batch(tmp_path: Path) -> None:
    out = tmp_path / "out"
    args = ["batch", str(SAMPLES / "paper_a.bin"), "-o", str(out), "--jobs", "1"]
    result = CliRunner().invoke(cli, [*args, "-m", "support", "--alpha", "0.5", "--evaluate"])
    assert result.exit_code == 0, result.output
    meta = json.loads((out / "paper_a.meta.json").read_text())
    assert meta["parameters"]["alpha_per_m2"] == 0.5
    assert meta["parameters"]["alpha_source"] == "option"
    assert meta["options"]["params"] == {
        "support": {"alpha_per_m2": 0.5, "beta": 10.0, "window_s": 0.5}
    }
    # the evaluation ran support with alpha 0.5 too: as `evaluate --alpha 0.5` measures it
    summary = pd.read_csv(out / "summary.csv")
    given = {"support": SupportParams(alpha_per_m2=0.5)}
    alone = evaluate(SAMPLES / "paper_a.bin", ["support"], FuseOptions(params=given))
    assert summary.support_rmse[0] == pytest.approx(alone.rows[0].overall.rmse, abs=1e-6)
    assert summary.support_rmse[0] != pytest.approx(0.2355, abs=1e-3)  # the default's
    refused = CliRunner().invoke(cli, [*args, "--force", "-m", "mean", "--alpha", "0.5"])
    assert refused.exit_code == 2
    assert "--alpha does not apply to method 'mean'" in refused.stderr


def test_a_failed_log_exits_4_and_a_refused_one_does_not(tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(SAMPLES / "mission.bin", logs / "good.bin")
    (logs / "bad.bin").write_bytes(b"\xa3\x95" + bytes(range(200)))  # not a log
    result = CliRunner().invoke(cli, ["batch", str(logs), "-o", str(tmp_path / "out")])
    assert result.exit_code == EXIT_PARTIAL
    summary = pd.read_csv(tmp_path / "out" / "summary.csv").set_index("log")
    assert summary.status.to_dict() == {"bad.bin": "failed", "good.bin": "ok"}
    assert "2 logs, ok 1, refused 0, skipped 0, failed 1" in result.stdout


def test_a_log_that_runs_out_of_memory_fails_saying_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Memory is the machine's limit, not a bug: the command says "out of memory" and what
    needs less on one line, exit 1 (it said "internal error ... rerun with --debug", exit 3),
    and a batch's row says the same (a 7.4-hour log at --rate 100 under a 1.5 GB limit)."""
    from altfuse import batch as batch_module
    from altfuse import commands

    def short(*_args: object, **_kwargs: object) -> object:
        raise MemoryError("Unable to allocate 118. MiB for an array")

    monkeypatch.setattr(commands, "run_to_files", short)
    monkeypatch.setattr(batch_module, "run_to_files", short)
    result = CliRunner().invoke(
        cli, ["fuse", str(SAMPLES / "mission.bin"), "-o", str(tmp_path / "f.csv")]
    )
    assert result.exit_code == 1
    assert result.stderr.strip().splitlines() == [
        "altfuse: error: out of memory (Unable to allocate 118. MiB for an array); less at once "
        "needs less: a lower --rate, fewer --jobs, a shorter --duration"
    ]
    assert not (tmp_path / "f.csv").exists()
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(SAMPLES / "mission.bin", logs / "long.bin")
    run_batch([logs], tmp_path / "out", jobs=1)
    row = pd.read_csv(tmp_path / "out" / "summary.csv").iloc[0]
    assert row.status == "failed"
    assert row.error.startswith("out of memory (Unable to allocate")


def test_a_batch_takes_compressed_logs_by_their_names(tmp_path: Path) -> None:
    """``flight.bin.gz`` (and ``.bz2``, ``.xz``; ``.ulg`` too) is found and fused, its outputs
    named as the log's (``flight.csv``), and skipped when complete on a rerun."""
    import gzip

    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "flight.BIN.gz").write_bytes(gzip.compress((SAMPLES / "mission.bin").read_bytes()))
    results = run_batch([logs], tmp_path / "out", jobs=1)
    assert [r.status for r in results] == ["ok"]
    assert (tmp_path / "out" / "flight.csv").is_file()
    again = run_batch([logs], tmp_path / "out", BatchOptions(skip_existing=True), jobs=1)
    assert [r.status for r in again] == ["skipped"]


def test_the_shards_of_a_job_array_cover_every_log_once(tmp_path: Path) -> None:
    """Issue 17: --shard 1/2 and 2/2 side by side in one folder (their shared lock refuses a
    whole batch meanwhile), each with its summary; the two summaries hold every log once."""
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("a", "b", "c", "d", "e"):
        shutil.copy(SAMPLES / "hover.bin", logs / f"{name}.bin")
    out = tmp_path / "out"
    out.mkdir()
    fd = os.open(out, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_SH)  # another shard, still running
    try:
        with pytest.raises(ParameterError, match="another altfuse batch is writing"):
            run_batch([logs], out, jobs=1)
        first = run_batch([logs], out, jobs=1, shard=(1, 2))
    finally:
        os.close(fd)
    result = CliRunner().invoke(cli, ["batch", str(logs), "-o", str(out), "--shard", "2/2"])
    assert result.exit_code == 0, result.output
    assert "summary.shard-2-of-2.csv: 2 logs" in result.stdout
    one = pd.read_csv(out / "summary.shard-1-of-2.csv")
    two = pd.read_csv(out / "summary.shard-2-of-2.csv")
    assert [r.log for r in first] == one.log.tolist() == ["a.bin", "c.bin", "e.bin"]
    assert two.log.tolist() == ["b.bin", "d.bin"]
    assert not (out / "summary.csv").exists()
    # the documented commands combine them: every log once, as one batch of them all writes
    readme = (ROOT / "docs" / "commands.md").read_text()
    block = readme[readme.index("The shards' summaries and indexes combine") :]
    start = block.index("```bash\n") + len("```bash\n")
    block = block[start : block.index("\n```", start)]
    assert len(block.splitlines()) == 2
    for line in block.splitlines():
        code = line.removeprefix('python -c "').removesuffix('"').replace("results/", "out/")
        subprocess.run([sys.executable, "-c", code], cwd=tmp_path, check=True)
    whole = tmp_path / "whole"
    run_batch([logs], whole, jobs=1)
    combined = pd.read_csv(out / "summary.csv")
    assert combined.log.tolist() == ["a.bin", "b.bin", "c.bin", "d.bin", "e.bin"]
    together = json.loads((out / "index.json").read_text())
    assert together["logs"] == json.loads((whole / "index.json").read_text())["logs"]
    bad = CliRunner().invoke(cli, ["batch", str(logs), "-o", str(out), "--shard", "3/2"])
    assert bad.exit_code == 2
    assert "'3/2' is not I/N with 1 <= I <= N" in bad.output


def test_the_index_says_what_made_each_log_s_outputs(tmp_path: Path) -> None:
    """Issue 17: index.json beside the summary, per log the altfuse version and fusion options
    its outputs were made with; a log that fails on a rerun keeps its entry (its outputs are
    still there), the failure said under ``rerun``."""
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(SAMPLES / "hover.bin", logs / "a.bin")
    shutil.copy(SAMPLES / "paper_a.bin", logs / "b.bin")
    out = tmp_path / "out"
    run_batch([logs], out, jobs=1)
    first = json.loads((out / "index.json").read_text())
    assert first["altfuse_version"] == __version__
    assert first["options"]["fuse"]["method"] == "smoother"
    assert first["logs"]["a.bin"]["outputs"] == ["a.csv", "a.meta.json"]
    assert first["logs"]["a.bin"]["fuse"]["method"] == "smoother"
    # a.bin changed since, run again without --force: its outputs are in the way
    shutil.copy(SAMPLES / "mission.bin", logs / "a.bin")
    again = run_batch([logs / "a.bin"], out, BatchOptions(skip_existing=True))
    assert [r.status for r in again] == ["failed"]
    index = json.loads((out / "index.json").read_text())
    rerun = index["logs"]["a.bin"].pop("rerun")
    assert index["logs"]["a.bin"] == first["logs"]["a.bin"]  # what made the files there
    assert rerun["status"] == "failed"
    assert index["logs"]["b.bin"] == first["logs"]["b.bin"]
    run_batch([logs], out, BatchOptions(skip_existing=True), jobs=1, shard=(2, 2))
    shard = json.loads((out / "index.shard-2-of-2.json").read_text())
    assert list(shard["logs"]) == ["b.bin"]


def test_a_batch_starts_no_more_workers_than_logs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    started: list[int] = []
    real = batch_module.ProcessPoolExecutor

    def pool(max_workers: int, **kwargs: object) -> ProcessPoolExecutor:
        started.append(max_workers)
        return real(max_workers, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(batch_module, "ProcessPoolExecutor", pool)
    results = run_batch([SAMPLES / "paper_a.bin", SAMPLES / "hover.bin"], tmp_path, jobs=8)
    assert [r.status for r in results] == ["ok", "ok"]
    assert started == [2]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="forked on Linux alone")
def test_a_batch_forks_its_workers_whatever_python_s_default(tmp_path: Path) -> None:
    """Python 3.14 starts processes with a fork server on Linux by default: its workers, the
    server's children, ended at their start (their parent not the batch), and every log
    failed; a killed batch's server and workers would run on."""
    default = multiprocessing.get_start_method(allow_none=True)
    multiprocessing.set_start_method("forkserver", force=True)
    try:
        results = run_batch([SAMPLES / "paper_a.bin", SAMPLES / "hover.bin"], tmp_path, jobs=2)
    finally:
        multiprocessing.set_start_method(default, force=True)
    assert [r.status for r in results] == ["ok", "ok"]


def test_a_batch_worker_computes_on_one_thread() -> None:
    """The workers fork from a process that loaded numpy (a Python caller's): each holds its
    BLAS pool to one thread, or the pools spin beside the other workers (8 logs of 30 MB on 2
    cores: as long at two jobs as at one)."""
    context = multiprocessing.get_context(batch_module.START_METHOD)
    started = context.SimpleQueue()
    with ProcessPoolExecutor(
        1, mp_context=context, initializer=_worker_start, initargs=(os.getpid(), started)
    ) as pool:
        pools = pool.submit(threadpool_info).result()
    assert pools
    assert {p["num_threads"] for p in pools} == {1}
