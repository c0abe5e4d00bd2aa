"""The divergence guard: a fused value that leaves every sensor is flagged, never silent."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from altfuse.cli import cli
from altfuse.errors import AltfuseError
from altfuse.fuse import METHODS, FusionInput
from altfuse.fuse.base import FusionResult, combine
from altfuse.guard import BRIDGE_S, FLOOR_M, GROSS_M, MIN_S, excursion, guard
from altfuse.metrics import white_noise_sigma
from altfuse.model import Samples
from altfuse.pipeline import FuseOptions, fuse_log
from conftest import ROOT, SHARED_LOGS, shared_log


def heights() -> FusionInput:
    rng = np.random.default_rng(7)
    z = 10.0 + rng.normal(0.0, 0.1, (300, 2))  # 30 s at 10 Hz, two sensors near 10 m
    return FusionInput.from_heights(z, 0.1)


def shifted(inputs: FusionInput, start: int, stop: int, by_m: float) -> FusionResult:
    mean = combine(inputs.z, np.isfinite(inputs.z).astype(float), "toy")
    fused = mean.fused.copy()
    fused[start:stop] += by_m
    return FusionResult("toy", fused, mean.weights, mean.status)


def test_the_excursion_is_the_distance_outside_the_sensors_envelope() -> None:
    z = np.array([[1.0, 3.0], [1.0, np.nan], [np.nan, np.nan]])
    np.testing.assert_allclose(excursion(np.array([2.0, 4.0, 5.0]), z), [0.0, 3.0, np.nan])
    np.testing.assert_allclose(excursion(np.array([-1.0, 1.0, 0.0]), z), [2.0, 0.0, np.nan])


def test_a_long_excursion_is_flagged_and_a_short_one_is_not() -> None:
    inputs = heights()
    long_run = guard(shifted(inputs, 100, 130, 5.0), inputs)  # 3 s, 5 m above both
    assert long_run.record["diverged_ticks"] == 30
    assert long_run.record["spans_s"] == [[10.0, pytest.approx(12.9)]]
    assert set(long_run.result.status[100:130]) == {"diverged"}
    assert "diverged" not in set(long_run.result.status[:100])
    short = guard(shifted(inputs, 100, 100 + round(MIN_S / 0.1) - 1, 5.0), inputs)
    assert short.record["diverged_ticks"] == 0
    small = guard(shifted(inputs, 100, 200, 0.8 * FLOOR_M), inputs)
    assert small.record["diverged_ticks"] == 0  # below the floor in metres
    assert small.result.status is small.result.status  # nothing to flag: the result as it was


def test_an_excursion_is_not_cut_short_by_a_pause_of_a_tick() -> None:
    """Two 1.5 s stretches 5 m above both sensors, one tick apart: one 3.1 s excursion (two
    of 1.5 s went unflagged); the same two 1 s apart are two short ones."""
    inputs = heights()
    result = shifted(inputs, 100, 131, 5.0)
    result.fused[115] -= 5.0  # one tick back among the sensors
    bridged = guard(result, inputs)
    assert bridged.record["spans_s"] == [[10.0, pytest.approx(13.0)]]
    assert bridged.record["diverged_ticks"] == 31
    apart = shifted(inputs, 100, 135, 5.0)
    apart.fused[115:125] -= 5.0  # 1 s back: longer than BRIDGE_S
    assert guard(apart, inputs).record["diverged_ticks"] == 0
    assert BRIDGE_S < 1.0


def test_a_gross_excursion_is_flagged_however_brief() -> None:
    assert GROSS_M == 10.0  # at 100 m, rima48's smoother 17 m off both sensors passed
    inputs = heights()
    one_tick = guard(shifted(inputs, 299, 300, 1.5 * GROSS_M), inputs)  # at the log's end
    assert one_tick.record["diverged_ticks"] == 1
    assert one_tick.result.status[-1] == "diverged"
    below = guard(shifted(inputs, 299, 300, 0.9 * GROSS_M), inputs)
    assert below.record["diverged_ticks"] == 0
    # however wide the method's own band: a smoother 1.8 km off with a fused_std of 27 km,
    # hours after its last sample, passed as within 3 sigma
    wide = shifted(inputs, 100, 200, 1.5 * GROSS_M)
    wide = replace(wide, tick_traces={"fused_std": np.full(300, 27e3)})
    assert guard(wide, inputs).record["diverged_ticks"] == 100
    wide = replace(wide, fused=shifted(inputs, 100, 200, 0.9 * GROSS_M).fused)
    assert guard(wide, inputs).record["diverged_ticks"] == 0


def test_on_a_coarse_clock_an_estimate_is_held_to_the_sensors_at_its_tick() -> None:
    """At 0.2 Hz a column is its sensor's mean over 5 s, and an estimate at the tick is not:
    a climb bending at 2 m/s^2 puts the true height 2 m outside both sensors' means (the
    smoother's estimates in the truth logs' climbing turns, within 0.3 m of the truth, were
    flagged 11 m outside them). The samples at the tick hold it, and the means a method that
    fuses them; a real excursion is still flagged."""
    fine = np.arange(0.0, 200.0, 0.1)
    true = 20.0 * np.sin(2 * np.pi * fine / 20.0)  # 20 m up and down every 20 s
    rng = np.random.default_rng(3)
    samples = [true + rng.normal(0.0, 0.05, fine.size) for _ in range(2)]
    t = np.arange(5.0, 195.0, 5.0)
    cell = np.floor((fine + 2.5) / 5.0).astype(int) - 1  # fine sample's tick, cells +-2.5 s
    z = np.stack([[v[cell == k].mean() for k in range(t.size)] for v in samples], axis=1)
    inputs = FusionInput(
        t, z, ("gps", "baro"), ("gps", "baro"), tuple(Samples(fine, v) for v in samples), 5.0
    )
    at_ticks = 20.0 * np.sin(2 * np.pi * t / 20.0)
    assert np.max(excursion(at_ticks, z)) > 1.5 * FLOOR_M  # what was flagged
    truth = FusionResult("toy", at_ticks, np.ones(z.shape) / 2, np.full(t.size, "fused"))
    assert guard(truth, inputs).record["diverged_ticks"] == 0
    means = FusionResult("toy", z.mean(axis=1), truth.weights, truth.status)  # mean's
    assert np.max(excursion(means.fused, np.stack(samples, axis=1)[::50][1:-1])) > FLOOR_M
    assert guard(means, inputs).record["diverged_ticks"] == 0
    off = at_ticks.copy()
    off[10:12] += 5.0  # 10 s 5 m above everything either sensor read
    astray = guard(FusionResult("toy", off, truth.weights, truth.status), inputs)
    assert astray.record["diverged_ticks"] == 2
    assert list(np.flatnonzero(astray.result.status == "diverged")) == [10, 11]


LOGS = [
    f"{folder}/{p.name}"
    for folder in ("ardupilot", "truth", "px4")
    for p in sorted((SHARED_LOGS / folder).glob("*"))
]


@pytest.mark.parametrize("log", LOGS)
def test_no_method_leaves_every_sensor_unflagged(log: str) -> None:
    """Every method on every shared log: an unflagged run of MIN_S or more never lies beyond
    every sensor by more than the guard's largest possible limit, nor any tick by GROSS_M
    (rima48's smoother, delay1 and multilayer 17-31 m off both sensors over its last 0.2 s
    passed while GROSS_M was 100 m)."""
    path = shared_log(log)
    for name in METHODS:
        try:
            run = fuse_log(path, FuseOptions(method=name, min_sensors=1))
        except AltfuseError:
            continue
        z, fused, status = run.referred.h, run.result.fused, run.result.status
        # the noise of each sensor's own samples, as the guard measures it (the clock's
        # interpolated heights are quieter: a 4.7 Hz barometer's 0.49 m reads 0.07 m there)
        noise = max(
            white_noise_sigma(s.value)
            for s in run.log.sensors
            if s.name in run.referred.names and s.value.size > 2
        )
        std = run.result.tick_traces.get("fused_std", np.zeros(fused.size))
        bound = np.maximum(FLOOR_M, 3 * np.sqrt(noise**2 + np.nan_to_num(std) ** 2))
        lo = np.min(np.where(np.isfinite(z), z, np.inf), axis=1)
        hi = np.max(np.where(np.isfinite(z), z, -np.inf), axis=1)
        some = np.isfinite(z).any(axis=1)
        outside = ((fused < lo - bound) | (fused > hi + bound)) & (status != "diverged") & some
        run_ticks, longest = 0, 0
        for bad in outside:
            run_ticks = run_ticks + 1 if bad else 0
            longest = max(longest, run_ticks)
        assert longest * 0.1 < MIN_S, f"{name}: {longest} ticks beyond every sensor, unflagged"
        gross = (fused < lo - GROSS_M) | (fused > hi + GROSS_M)
        assert not (gross & (status != "diverged") & some).any(), f"{name}: {GROSS_M} m, unflagged"
        assert (status == "diverged").sum() == run.provenance["guard"]["diverged_ticks"]


def test_a_divergence_is_warned_in_one_line_and_reported_by_evaluate_and_batch(
    tmp_path: Path,
) -> None:
    """delay1 in the paper's form freezes at the start of the hover's 240 m climb (the
    constant-altitude recursion, kept selectable on purpose): a divergence by design."""
    log = ROOT / "sample_logs" / "hover.bin"
    paper = ["-m", "delay1", "--form", "paper"]
    out = tmp_path / "o.csv"
    result = CliRunner().invoke(cli, ["fuse", str(log), "-o", str(out), *paper])
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.stderr.splitlines() if "diverged" in line]
    assert warnings == [
        "altfuse: warning: hover.bin: delay1 left every sensor on 1653 ticks (by up to 113.2 m): "
        "status 'diverged'"
    ]
    table = pd.read_csv(out)
    meta = json.loads(out.with_suffix(".meta.json").read_text())
    assert (table.status == "diverged").sum() == meta["guard"]["diverged_ticks"] == 1653
    assert meta["status_counts"]["diverged"] == 1653
    report = CliRunner().invoke(
        cli, ["evaluate", str(log), "--methods", "support,delay1", "--form", "paper"]
    )
    assert "diverged: delay1 left every sensor on 1653 ticks" in report.stdout
    assert "diverged: support" not in report.stdout
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / log.name).symlink_to(log)
    args = ["batch", str(folder), "-o", str(tmp_path / "b"), *paper, "--jobs", "1"]
    assert CliRunner().invoke(cli, args).exit_code == 0
    summary = pd.read_csv(tmp_path / "b" / "summary.csv")
    assert summary.diverged[0] == 1653
