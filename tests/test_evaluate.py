"""altfuse evaluate, the error measures and the figures."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from altfuse.cli import cli
from altfuse.errors import ParameterError
from altfuse.evaluation import _row, choose_truth, evaluate, parse_segments
from altfuse.fuse.support import SupportParams
from altfuse.metrics import error_stats
from altfuse.pipeline import FuseOptions, prepare_log
from altfuse.simulate import BOOT_S, simulate_flight
from conftest import ROOT, shared_log

PAPER_A = ROOT / "sample_logs" / "paper_a.bin"


def test_error_stats_hand_computed() -> None:
    estimate = np.array([1.0, 2.0, np.nan, 4.0])
    truth = np.array([0.0, 2.5, 3.0, 4.0])
    s = error_stats(estimate, truth)
    # errors +1, -0.5, 0 over three common ticks
    assert s.n == 3
    assert s.rmse == pytest.approx(np.sqrt(1.25 / 3))
    assert s.mae == pytest.approx(0.5)
    assert s.max_abs == 1.0
    assert s.bias == pytest.approx(0.5 / 3)
    assert error_stats(estimate, truth, np.zeros(4, dtype=bool)).as_dict()["rmse"] is None
    assert s.as_dict()["within_2std"] is None  # no standard deviation given
    # errors +1, -0.5 against 2 sigma of 1.0 and 0.4: within on the first only; the third
    # tick has no estimate, the fourth's error no sigma: not counted
    std = np.array([0.5, 0.2, 9.0, np.nan])
    assert error_stats(estimate, truth, std=std).within_2std == pytest.approx(0.5)


def test_each_method_s_standard_deviation_is_measured_against_the_truth(tmp_path: Path) -> None:
    """``evaluate`` says how much of a method's true errors its own +-2 sigma covers (the
    smoother's ``fused_std_m``; Paper B's filters' variance), over the flight and each
    segment, in the table, the JSON and the CSV; "-" for the weightings, which give none
    (the bar's coverage was a test helper's alone)."""
    report = tmp_path / "report.json"
    table = tmp_path / "report.csv"
    result = CliRunner().invoke(
        cli,
        ["evaluate", str(PAPER_A), "--methods", "support,delay1,smoother", "--segments", "60",
         "-o", str(report), "--csv", str(table)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[1].split() == ["name", "kind", "RMSE", "MAE", "max", "bias", "+-2std", "n"]
    cells = {line.split()[0]: line.split() for line in lines[2:7]}
    assert cells["support"][6] == "-"
    assert cells["gps"][6] == "-"
    evaluation = evaluate(PAPER_A, ["support", "delay1", "smoother"], segments="60")
    run = evaluation.runs["smoother"].result
    error = run.fused - evaluation.truth.h
    ok = np.isfinite(error)
    by_hand = float(np.mean(np.abs(error[ok]) <= 2 * run.tick_traces["fused_std"][ok]))
    assert 0.9 < by_hand < 1.0  # measured: 0.932
    assert float(cells["smoother"][6]) == pytest.approx(by_hand, abs=5e-4)
    assert 0 < float(cells["delay1"][6]) <= 1
    rows = {r["name"]: r for r in json.loads(report.read_text())["rows"]}
    assert rows["smoother"]["overall"]["within_2std"] == pytest.approx(by_hand)
    assert rows["support"]["overall"]["within_2std"] is None
    assert all(0 < s["within_2std"] <= 1 for s in rows["smoother"]["segments"].values())
    csv = pd.read_csv(table)
    overall = csv[(csv["name"] == "smoother") & (csv["segment"] == "all")]
    assert overall["within_2std"].iloc[0] == pytest.approx(by_hand)


def test_segments_by_length_and_by_boundaries() -> None:
    t = np.arange(0, 101) / 1.0  # 0..100 s
    assert list(parse_segments("40", t).values()) == [(0.0, 40.0), (40.0, 80.0), (80.0, 100.0)]
    assert list(parse_segments("30,70", t).values()) == [(0.0, 30.0), (30.0, 70.0), (70.0, 100.0)]
    with pytest.raises(ParameterError, match=r"^segments takes seconds or boundaries, got 'soon'"):
        parse_segments("soon", t)
    for empty in (",", " , ,"):  # no boundary: not one segment over the whole log, unsaid
        with pytest.raises(ParameterError, match=r"^segments takes seconds or boundaries, got '"):
            parse_segments(empty, t)
    # issue 19: a boundary outside the log is said, not silently dropped
    with pytest.raises(ParameterError, match=r"^segments 150, -5 s outside the log's clock"):
        parse_segments("30,150,-5", t)


@pytest.mark.parametrize("length", ["0.5", "1e-9", "0", "-5", "nan", "inf"])
def test_a_segment_shorter_than_a_tick_is_refused(length: str) -> None:
    """Segments of 1e-9 s on a two-minute log were 1.2e11 of them: 893 GiB asked for, and an
    out-of-memory error advising a lower --rate."""
    t = np.arange(0, 1001) / 10.0  # 0..100 s at 10 Hz
    said = r"^segments length must be at least the clock's tick \(1 s\) and finite, got "
    with pytest.raises(ParameterError, match=said + f"{float(length):g}$"):
        parse_segments(length, np.arange(0, 101) / 1.0)
    assert len(parse_segments("0.1", t)) == 1000
    assert len(parse_segments("0.1", 30 + t)) == 1000  # its tick 0.10000000000000142


def test_segment_labels_tell_close_boundaries_apart() -> None:
    """Labelled with one decimal, boundaries 0.01 s apart gave two segments the label
    "50.5-50.5s": the second silently replaced the first."""
    t = np.arange(0, 10001) / 100.0  # 0..100 s at 100 Hz
    assert list(parse_segments("50.51,50.52,50.53", t)) == [
        "0.00-50.51s",
        "50.51-50.52s",
        "50.52-50.53s",
        "50.53-100.00s",
    ]
    assert list(parse_segments("40", t)) == ["0.0-40.0s", "40.0-80.0s", "80.0-100.0s"]
    assert len(parse_segments("0.01", t)) == 10000


def test_each_segment_holds_its_ticks_the_last_its_end() -> None:
    estimate, truth = np.arange(11.0), np.zeros(11)  # the error is the time
    t = np.arange(11.0)
    spans = parse_segments("2.5,7", t)
    row = _row("x", "method", estimate, truth, t, spans)
    assert [(s.n, s.max_abs) for s in row.segments.values()] == [(3, 2.0), (4, 6.0), (4, 10.0)]
    assert row.overall.n == 11


def test_a_folder_given_to_fuse_points_to_batch(tmp_path: Path) -> None:
    result = CliRunner().invoke(cli, ["fuse", str(tmp_path), "-o", str(tmp_path / "x.csv")])
    assert result.exit_code == 1
    assert "a folder, not a log; for its logs: altfuse batch" in result.stderr


def test_simulated_log_is_measured_against_the_sim_truth() -> None:
    result = evaluate(PAPER_A)
    assert result.truth.name == "sim"
    assert not result.truth.is_reference
    names = {r.name: r.kind for r in result.rows}
    assert names == {
        "mean": "method",
        "support": "method",
        "delay1": "method",
        "delay2": "method",
        "multilayer": "method",
        "smoother": "method",
        "gps": "sensor",
        "baro": "sensor",
        "rangefinder": "sensor",
    }
    # the truth is referred to take-off like the sensors: 0 on the ground
    lo, hi = result.prepared.referred.ground_window_s
    t = result.prepared.referred.t
    assert np.median(result.truth.h[(t >= lo) & (t <= hi)]) == pytest.approx(0.0, abs=1e-9)


def test_paper_a_support_beats_mean_while_the_baro_departs() -> None:
    """Acceptance: on a paper-a log, support beats mean in the baro-departure segment."""
    segments = simulate_flight("paper-a").profile.segments
    lo, hi = (BOOT_S + v for v in segments["baro-departs"])
    result = evaluate(PAPER_A, ["mean", "support"], segments=f"{lo},{hi}")
    label = next(k for k, (a, b) in result.segments.items() if a == pytest.approx(lo))
    rows = {r.name: r for r in result.rows}
    support, mean = rows["support"].segments[label], rows["mean"].segments[label]
    # measured: support 0.286 m, mean 0.829 m; the barometer alone 2.211 m
    assert support.rmse < 0.4 * mean.rmse
    assert support.max_abs < mean.max_abs


def test_real_log_uses_the_ekf_as_a_reference_and_says_so(tmp_path: Path) -> None:
    log = shared_log("ardupilot/beastayyg_log_0039_mechanical_failure.bin")
    out, table = tmp_path / "r.json", tmp_path / "r.csv"
    result = CliRunner().invoke(
        cli, ["evaluate", str(log), "-o", str(out), "--csv", str(table), "--segments", "30"]
    )
    assert result.exit_code == 0, result.output
    assert "NKF1.-PD as reference (the autopilot's estimate, not truth)" in result.stdout
    report = json.loads(out.read_text())
    assert report["truth"]["is_reference"] is True
    assert {r["name"] for r in report["rows"]} >= {"support", "mean", "gps", "baro", "rangefinder"}
    assert len(report["segments"]) == 4  # 80.5-175.9 s in 30 s windows
    frame = pd.read_csv(table)
    assert set(frame.segment) == {"all", *report["segments"]}
    assert set(frame.columns) == {
        "name", "kind", "segment", "n", "rmse", "mae", "max_abs", "bias", "within_2std",
    }  # fmt: skip


def test_asking_for_a_reference_the_log_lacks_fails_in_one_line() -> None:
    result = CliRunner().invoke(cli, ["evaluate", str(PAPER_A), "--truth", "ekf"])
    assert result.exit_code == 1
    assert "no EKF estimate (XKF1/NKF1, CTUN.Alt" in result.stderr


def test_method_parameters_pass_through_evaluate(tmp_path: Path) -> None:
    reports = {}
    for extra in ([], ["--alpha", "0.5"]):
        out = tmp_path / f"report{len(extra)}.json"
        args = ["evaluate", str(PAPER_A), "--methods", "support,mean", "-o", str(out), *extra]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        rows = json.loads(out.read_text())["rows"]
        reports[len(extra)] = {r["name"]: r["overall"]["rmse"] for r in rows}
    given = {"support": SupportParams(alpha_per_m2=0.5)}
    library = evaluate(PAPER_A, ["support"], FuseOptions(params=given)).rows[0].overall.rmse
    assert reports[2]["support"] == pytest.approx(library, abs=1e-9)
    assert reports[2]["support"] != pytest.approx(reports[0]["support"], abs=1e-3)
    assert reports[2]["mean"] == reports[0]["mean"]  # alpha is support's alone
    refused = CliRunner().invoke(cli, ["evaluate", str(PAPER_A), "--methods", "mean", "--q", "1"])
    assert refused.exit_code == 2
    assert "--process-noise does not apply to method 'mean'" in refused.stderr  # --q: its alias


def test_a_method_named_twice_is_evaluated_once(tmp_path: Path) -> None:
    out = tmp_path / "report.json"
    args = ["evaluate", str(PAPER_A), "--methods", "mean, support,mean,", "-o", str(out)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    rows = json.loads(out.read_text())["rows"]
    assert [r["name"] for r in rows if r["kind"] == "method"] == ["mean", "support"]
    assert result.stdout.count("\nmean ") == 1


def test_a_list_of_no_method_is_refused() -> None:
    """``--methods ,`` (and ``evaluate(log, [])``) ran every method without a word."""
    for given in (",", "", " , "):
        result = CliRunner().invoke(cli, ["evaluate", str(PAPER_A), "--methods", given])
        assert result.exit_code == 2
        assert result.stderr == (
            "altfuse: error: --methods names no method; choose from mean, support, delay1, "
            "delay2, multilayer, smoother\n"
        )
    with pytest.raises(ParameterError, match=r"^methods names no method; choose from mean"):
        evaluate(Path("not read.bin"), [])  # refused before the log is read


def test_one_method_may_be_named_by_its_name_alone() -> None:
    """``evaluate(log, "support")``, not its letters as methods ("unknown method 's'")."""
    result = evaluate(PAPER_A, "support")
    assert [r.name for r in result.rows if r.kind == "method"] == ["support"]


def test_method_that_cannot_run_is_listed() -> None:
    log = shared_log("ardupilot/diaven_sample01.bin")  # no IMU: multilayer cannot run
    result = CliRunner().invoke(cli, ["evaluate", str(log)])
    assert result.exit_code == 0, result.output
    assert "CTUN.Alt as reference" in result.stdout
    assert "not run: multilayer:" in result.stdout


@pytest.mark.parametrize("suffix", [".png", ".svg"])
@pytest.mark.parametrize("command", ["fuse", "evaluate"])
def test_plots_for_a_simulated_and_a_real_log(tmp_path: Path, command: str, suffix: str) -> None:
    for log in (PAPER_A, shared_log("ardupilot/beastayyg_log_0039_mechanical_failure.bin")):
        figure = tmp_path / f"{log.stem}{suffix}"
        args = [command, str(log), "--plot", str(figure)]
        if command == "fuse":
            args += ["-o", str(tmp_path / f"{log.stem}.csv")]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        head = figure.read_bytes()[:200]
        assert (
            head.startswith(b"\x89PNG") if suffix == ".png" else b"<svg" in head or b"<?xml" in head
        )
        assert figure.stat().st_size > 20_000
    assert not list(tmp_path.glob(".*tmp*"))


def test_plot_needs_a_known_format(tmp_path: Path) -> None:
    out = tmp_path / "o.csv"
    result = CliRunner().invoke(cli, ["fuse", str(PAPER_A), "-o", str(out), "--plot", "x.pdf"])
    assert result.exit_code == 2
    assert "--plot must end in .png or .svg" in result.stderr
    assert not out.exists()


def test_the_table_s_columns_stay_apart_at_any_magnitude() -> None:
    """Issue 19: 19793.323 beside 12698.125 ran together in fixed-width columns."""
    from altfuse.commands import _aligned, _stats_cells
    from altfuse.metrics import ErrorStats

    huge = ErrorStats(n=1234567, rmse=19793.32312, mae=12698.125, max_abs=-1e7, bias=-98765.4)
    small = ErrorStats(n=3, rmse=0.01, mae=0.01, max_abs=0.02, bias=0.0, within_2std=0.5)
    lines = _aligned(
        [["name", "kind", "RMSE", "MAE", "max", "bias", "+-2std", "n"],
         _stats_cells("a-long-method-name", "method", huge), _stats_cells("gps", "sensor", small)]
    )  # fmt: skip
    assert [len(line.split()) for line in lines] == [8, 8, 8]
    assert lines[1].split()[2:4] == ["19793.323", "12698.125"]
    assert len({len(line) for line in lines}) == 1  # numbers right-aligned to one edge


def test_a_segment_with_its_own_ground_has_its_truth_referred_there() -> None:
    """The Solo's log is spliced: its first segment took off from its own ground, and its
    sensors are referred there; the truth is too, as the sensors are (on the main segment's
    ground it read 9 cm off in the first segment)."""
    prepared = prepare_log(
        shared_log("truth/copter_3.4dev-solo_djnugent_climb154m_ekf1.BIN"), FuseOptions()
    )
    segments = prepared.referred.segments
    assert len(segments) == 2
    assert segments[0].on_ground_s is not None
    truth = choose_truth(prepared.log, prepared.referred, "sim").h
    t = prepared.referred.t
    for segment in segments:
        assert segment.on_ground_s is not None
        lo, hi = segment.on_ground_s
        ground = (t >= lo) & (t <= hi)
        assert abs(np.nanmedian(truth[ground])) < 1e-6


def test_the_truth_is_referred_where_the_datum_was_found_whatever_the_clock() -> None:
    """At 0.2 Hz the 4.5 plane's first tick comes 2 s after its ground window (50.6-52.6 s, on
    the 10 Hz clock the datum is found on): its truth was referred over the whole flight
    instead, and every method and sensor measured 27 m off. Now at the datum's own ticks."""
    path = shared_log("truth/plane_4.5.0dev_eozbademci_autotest_climb88m.BIN")
    fine = evaluate(path, ["smoother"])
    coarse = evaluate(path, ["smoother"], FuseOptions(rate_hz=0.2))
    assert coarse.prepared.referred.t[0] > coarse.prepared.referred.ground_window_s[1]
    rmse = {r.name: r.overall.rmse for r in coarse.rows}
    assert rmse["smoother"] < 0.05  # 0.019
    on_both = np.isin(fine.prepared.referred.t, coarse.prepared.referred.t)
    np.testing.assert_allclose(coarse.truth.h, fine.truth.h[on_both], atol=1e-9)
