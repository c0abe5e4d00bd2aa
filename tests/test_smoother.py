"""The offline smoother (issue 8): its parts, its options, and the sample flights.

Every simulated scenario and fault: ``tests/test_smoother_accuracy.py`` and
``benchmarks/smoother_accuracy.py``."""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from accuracy import verdict
from altfuse.cli import cli
from altfuse.datum.scale import Track
from altfuse.evaluation import evaluate
from altfuse.fuse import FusionInput
from altfuse.fuse.smoother import NIS_CHECK, SmootherParams, fuse_smoother, model_check
from altfuse.fuse.smoother.compiled import _forget_other_versions
from altfuse.fuse.smoother.events import TICK, _triangle_sums, model_intervals, on_every_event
from altfuse.fuse.smoother.evidence import (
    DRIFT_GAIN,
    HEARD_SHARE,
    evidence_record,
    heard,
    stable_gain,
    witnessed,
)
from altfuse.fuse.smoother.model import (
    GPS_CORRELATION_S,
    LANDED_MARGIN_S,
    LEARN_SCALE_STD,
    OFFSET_PRIOR,
    SCALE_PRIOR,
    STILL_SIGMA,
    Events,
    datum_priors,
    landed_events,
    scales_to_relearn,
)
from altfuse.fuse.smoother.noise import (
    ACCEL_EM_GAIN,
    Q_AGREEMENT_MIN_SHARE,
    accel_refused,
    accel_spikes,
    em_accel,
    measurement_sigma,
    terrain_noise,
    wander_bound,
)
from altfuse.fuse.smoother.passes import LOCKOUT_S
from altfuse.io import read_log
from altfuse.metrics import coverage
from altfuse.model import Samples, SensorKind
from altfuse.params import InvalidParameter
from altfuse.pipeline import FuseOptions, fuse_log, prepare, prepare_log, run_method
from altfuse.simulate import simulate_flight, write_simulated_log
from altfuse.steps import find_steps
from conftest import ROOT, shared_log
from repeated import repeated_log
from variants import stepped, variant

FAULTS = ROOT / "sample_logs" / "mission_faults.bin"


def test_measurement_noise_from_second_differences() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(0, 60, 0.05)
    z = 10 * np.sin(t / 10) + rng.normal(0, 0.3, t.size)
    assert measurement_sigma(z) == pytest.approx(0.3, rel=0.1)


def test_a_constant_altitude_is_recovered_with_a_shrinking_std() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(0, 60, 0.1)
    z = np.column_stack([5 + rng.normal(0, s, t.size) for s in (0.8, 0.2)])
    res = fuse_smoother(FusionInput.from_heights(z, 0.1), SmootherParams())
    assert np.sqrt(np.mean((res.fused - 5) ** 2)) < 0.15
    assert res.params["model"] == "altitude-only random walk (no IMU)"
    np.testing.assert_array_less(0, res.tick_traces["fused_std"])
    assert res.params["sigma_baro_m"] < res.params["sigma_gps_m"]


def test_the_gps_glitch_is_the_gps_s_two_jumps_and_the_csv_has_fused_std(tmp_path: Path) -> None:
    """The 15 m glitch of 5 s: found as two steps between GPS and barometer (in and out), each
    the GPS's jump by the likelihood, its samples in it taken back by it (they were gated out,
    27 of them); the fused height stays within 0.1 m of the truth (0.074; 0.072 gated)."""
    out = tmp_path / "o.csv"
    result = CliRunner().invoke(cli, ["fuse", str(FAULTS), "-o", str(out), "-m", "smoother"])
    assert result.exit_code == 0, result.output
    table = pd.read_csv(out)
    assert (table.fused_std_m > 0).all()
    meta = json.loads(out.with_suffix(".meta.json").read_text())
    params = meta["parameters"]
    assert [s["between"] for s in meta["datum"]["steps"]] == [["gps", "baro"]] * 2
    jumps = [
        re.fullmatch(r"(\S+) s: (\S+) m, (\w+)", j).groups() for j in params["steps"].split("; ")
    ]
    assert [sensor for *_, sensor in jumps] == ["gps", "gps"]
    assert [float(size) for _, size, _ in jumps] == pytest.approx([13.6, -14.0], abs=0.1)
    inside = (table.time_s > float(jumps[0][0])) & (table.time_s < float(jumps[1][0]))
    truth = evaluate(FAULTS, ["smoother"], truth="sim").truth.h
    assert np.max(np.abs(table.fused_alt_m - truth)[inside]) < 0.1  # 0.074
    assert params["rejected_gps"] <= 10
    assert params["model"] == "accelerometer-driven"


def test_sigma_override_and_nonsense_options(tmp_path: Path) -> None:
    out = tmp_path / "o.csv"
    result = CliRunner().invoke(
        cli,
        [
            *("fuse", str(FAULTS), "-o", str(out), "-m", "smoother"),
            *("--sigma", "gps=2.5", "--offset-noise", "baro=0.003"),
        ],
    )
    assert result.exit_code == 0, result.output
    params = json.loads(out.with_suffix(".meta.json").read_text())["parameters"]
    assert params["sigma_gps_m"] == 2.5
    assert params["q_offset_baro_m2_s"] == pytest.approx(0.003)
    for args, fragment in (
        (["--sigma", "lidar=1"], "--sigma names no sensor altfuse reads: 'lidar'; sensors are"),
        (["--sigma", "gps1=1"], "--sigma names no sensor altfuse reads: 'gps1'"),
        (["--sigma", "gps"], "--sigma"),
        (["--gate", "0"], "--gate"),
        (["--offset-noise", "baro=-1"], "--offset-noise"),
        (["--offset-noise", "sonar=1"], "--offset-noise names no sensor altfuse reads: 'sonar'"),
        # the last silently won
        (["--sigma", "gps=0.5", "--sigma", "gps=0.8"], "--sigma gives gps twice (0.5 and 0.8)"),
    ):
        bad = CliRunner().invoke(
            cli, ["fuse", str(FAULTS), "-o", str(tmp_path / "x.csv"), "-m", "smoother", *args]
        )
        assert bad.exit_code == 2, bad.output
        assert fragment in bad.stderr
    with pytest.raises(InvalidParameter, match=r"^accel_noise_m2_s3 must be a positive number"):
        SmootherParams(accel_noise_m2_s3=-1.0)
    with pytest.raises(InvalidParameter, match=r"^sigma_m names no sensor altfuse reads: 'lid"):
        SmootherParams(sigma_m={"lidar": 1.0})  # before any log is read


def test_a_sensor_the_log_lacks_is_not_used_and_said(caplog: pytest.LogCaptureFixture) -> None:
    """A per-sensor value for a sensor this log does not have was an error, which failed
    every log of a batch without it (``--sigma rangefinder=0.05`` over the shared ArduPilot
    logs: 5 of 8 failed). It is not used, the result is the one without it, and the metadata
    says so; the method itself logs nothing (a batch's workers printed it once per log, without
    the log's name: the commands say it with the name)."""
    inputs = FusionInput.from_heights(np.column_stack([np.linspace(0, 5, 200)] * 2), 0.1)
    plain = fuse_smoother(inputs, SmootherParams())
    assert "not_used" not in plain.params
    values = SmootherParams(sigma_m={"rangefinder": 0.05}, offset_noise_m2_s={"gps2": 1, "gps": 1})
    with caplog.at_level(logging.WARNING, logger="altfuse"):
        given = fuse_smoother(inputs, SmootherParams(sigma_m={"rangefinder": 0.05}))
        both = fuse_smoother(inputs, values)
    np.testing.assert_array_equal(given.fused, plain.fused)
    assert caplog.messages == []
    assert given.params["not_used"] == "sigma_m (--sigma): rangefinder"
    assert both.params["not_used"] == (
        "sigma_m (--sigma): rangefinder; offset_noise_m2_s (--offset-noise): gps2"
    )


def test_terrain_roughness_is_per_metre_flown() -> None:
    """Other sensor minus rangefinder = ground height + noise; the ground changes only where
    the vehicle moves (5 m/s half the time)."""
    rng = np.random.default_rng(4)
    dt = 0.1
    speed = np.where((np.arange(2000) // 200) % 2 == 0, 0.0, 5.0)
    flown = np.cumsum(speed) * dt
    hills = 2 * np.sin(2 * np.pi * flown / 37)
    noise = rng.normal(0, 0.05, flown.size)
    white = 2 * 0.05**2  # the noise's share of a squared change
    assert terrain_noise(hills + noise, flown, 10, white) > 0.05
    assert terrain_noise(noise, flown, 10, white) < 0.002
    assert np.isnan(terrain_noise(noise, np.zeros_like(flown), 10, white))  # never moved
    # a rangefinder that reads only in fast flight (below its minimum on the ground): no still
    # span to measure the noise on, so the sensors' noise stands in for it
    fast = speed > 0
    flat = np.where(fast, noise, np.nan)
    assert terrain_noise(flat, flown, 10, white) < 0.002  # without it: unknown, 0.05 m^2/m
    assert terrain_noise(np.where(fast, hills + noise, np.nan), flown, 10, white) > 0.05


def test_a_step_of_the_other_sensor_is_no_ground() -> None:
    """The other sensor 2 m higher from half-way (a GPS's step, found between sensors): the
    change across it is no ground's. Counted as one, it made a flat field's ground 150 times
    as rough on a real log (beastayyg_log_0039), the rangefinder let loose and the whole
    flight's height moved 0.39 m RMS (``benchmarks/step_robustness.py``; 0.04 since)."""
    rng = np.random.default_rng(5)
    flown = np.cumsum(np.full(2000, 5.0)) * 0.1  # 5 m/s throughout
    d = rng.normal(0, 0.05, flown.size) + np.where(np.arange(flown.size) >= 1000, 2.0, 0.0)
    white = 2 * 0.05**2
    flat = terrain_noise(d - np.where(np.arange(flown.size) >= 1000, 2.0, 0.0), flown, 10, white)
    assert flat < 1e-3
    assert terrain_noise(d, flown, 10, white) > 50 * max(flat, 1e-5)  # the step as ground
    assert terrain_noise(d, flown, 10, white, [(999, 1001)]) == pytest.approx(flat, abs=2e-4)


def test_a_gps_step_on_a_real_log_leaves_its_height_where_it_was() -> None:
    """beastayyg_log_0039, its GPS 2 m higher from half-way: the step is found and given to
    the GPS, and the height should not move. It moved 0.387 m RMS (0.76 at most) while the
    step counted as rough ground under the rangefinder; 0.043 m since."""
    flight = read_log(shared_log("ardupilot/beastayyg_log_0039_mechanical_failure.bin"))
    one = tuple(stepped(s, 2.0) if s.name == "gps" else s for s in flight.sensors)
    plain = run_method(prepare(flight, FuseOptions()), FuseOptions()).result
    moved = run_method(prepare(replace(flight, sensors=one), FuseOptions()), FuseOptions()).result
    assert moved.params["steps"] == "128.15 s: +1.91 m, gps"
    assert moved.fused.shape == plain.fused.shape
    assert np.sqrt(np.nanmean((moved.fused - plain.fused) ** 2)) < 0.1


def _rmse_by_method(name: str) -> dict[str, float]:
    from altfuse.evaluation import evaluate

    result = evaluate(ROOT / "sample_logs" / name)
    return {r.name: r.overall.rmse for r in result.rows if r.kind == "method"}


@pytest.mark.parametrize(
    ("name", "ratio"),
    [("hover.bin", 0.3), ("mission.bin", 0.3), ("mission_faults.bin", 0.3), ("paper_a.bin", 0.3)],
)
def test_on_the_sample_flights_it_beats_every_other_method(name: str, ratio: float) -> None:
    """Measured: hover 0.051 m vs 0.370 (support); mission 0.058 vs 0.386; mission_faults (GPS
    glitch + rangefinder dropout) 0.045 vs 0.553; paper_a 0.017 vs 0.216 (multilayer)."""
    rmse = _rmse_by_method(name)
    best_other = min(v for k, v in rmse.items() if k != "smoother")
    assert rmse["smoother"] < ratio * best_other


def test_the_log_gives_the_thermal_coefficient_and_the_still_ground(tmp_path: Path) -> None:
    """The simulator's barometer drifts 0.12 m/degC with BARO.Temp."""
    out = tmp_path / "o.csv"
    hover = ROOT / "sample_logs" / "hover.bin"
    result = CliRunner().invoke(cli, ["fuse", str(hover), "-o", str(out), "-m", "smoother"])
    assert result.exit_code == 0, result.output
    params = json.loads(out.with_suffix(".meta.json").read_text())["parameters"]
    assert params["thermal_baro_m_per_degC"] == pytest.approx(0.12, abs=0.02)
    # flat ground and no horizontal motion: the ground under the rangefinder holds still
    assert params["q_offset_rangefinder_m2_s"] < 0.01


@pytest.mark.parametrize(("faults", "modelled"), [((), False), (("baro-drift",), True)])
def test_a_drifting_barometer_gets_a_drift_rate(
    tmp_path: Path, faults: tuple[str, ...], modelled: bool
) -> None:
    """The hover has no third sensor at 240 m: a barometer ramping at 0.05 m/s is told from the
    GPS's wander only by the likelihood (measured gain 10.7 against 5.4 needed). Without the
    fault the drift model rejects one sample more, and is not taken."""
    log = tmp_path / "hover.bin"
    write_simulated_log(simulate_flight("hover", 0, faults=faults), log)
    out = tmp_path / "o.csv"
    result = CliRunner().invoke(cli, ["fuse", str(log), "-o", str(out), "-m", "smoother"])
    assert result.exit_code == 0, result.output
    params = json.loads(out.with_suffix(".meta.json").read_text())["parameters"]
    if modelled:
        assert params["baro_drift"] == "modelled"
        assert params["baro_drift_loglik_gain"] > DRIFT_GAIN
    else:
        assert params["baro_drift"].startswith("not modelled")
        assert params.get("baro_drift_loglik_gain", -1.0) < DRIFT_GAIN


@pytest.mark.parametrize(
    ("receivers", "heard", "seen", "gain"),
    [
        (50.0, True, True, 109.0),
        (112.0, True, True, 109.0),
        (112.0, False, True, -577.0),
        (150.0, True, True, -577.0),
        (50.0, False, False, -577.0),
    ],
)
def test_the_stable_gps_wins_by_the_barometers_drift_only_where_it_beats_the_gps_s_own(
    receivers: float, heard: bool, seen: bool, gain: float
) -> None:
    """The stable GPS's gain over the wandering one (:func:`stable_gain`): with the barometers'
    drift where that gains DRIFT_GAIN and more than its receivers' own drift (as the drift
    test keeps it), else without. The passes' log-likelihoods, one sample each: the stable GPS
    -577 alone, 109 with the barometers' drift, ``receivers`` with the GPS's own (a 305 m
    climb's barometer flashed 3 m: the stable GPS won by a drift the drift test left out); the
    GPS's own drift within DRIFT_GAIN of the barometers' leaves the barometers' drift kept
    where the GPS's heights are ``heard`` (the witness of a barometer's drift), not where they
    are not; where no sensor's heights are ``seen``, the drift is never kept."""

    def made(loglik: float) -> dict[str, np.ndarray]:
        return {"accepted": np.array([True]), "loglik": np.array([loglik])}

    drifted = [made(DRIFT_GAIN / 2), made(109.0), made(receivers)]
    assert stable_gain(made(0.0), made(-577.0), drifted, heard=heard, witnessed=seen) == gain
    assert stable_gain(made(0.0), made(-577.0)) == -577.0


def test_a_gps_s_heights_are_heard_where_a_pass_accepts_half_of_them_or_more() -> None:
    """The witness of a barometer's drift (:func:`heard`): of the receivers' samples (the
    events of their columns; 1 a barometer's here) the pass accepted HEARD_SHARE or more; a
    receiver without samples is not heard."""
    who = np.array([0, 1, 2, 0, 1, 2, 0, 0])
    accepted = np.array([True, False, False, False, True, False, True, False])
    verdicts = {"accepted": accepted, "loglik": np.zeros(who.size)}
    assert HEARD_SHARE == 0.5
    assert heard(verdicts, who, (0,))  # 2 of its 4
    assert not heard(verdicts, who, (2,))  # 0 of 2
    assert not heard(verdicts, who, (0, 2))  # 2 of 6
    assert not heard(verdicts, who, (3,))


def test_a_barometers_drift_needs_another_sensor_s_heights_to_witness_it() -> None:
    """A sensor other than the barometers witnesses their drift where a pass accepts half of
    its heights or more (:func:`witnessed`); a barometer's own do not count."""
    who = np.array([0, 1, 2, 0, 1, 2])
    accepted = np.array([True, False, True, True, False, False])
    verdicts = {"accepted": accepted, "loglik": np.zeros(who.size)}
    assert witnessed(verdicts, who, ("baro", "gps", "rangefinder"))  # the rangefinder, 1 of 2
    assert not witnessed(verdicts, who, ("baro", "gps", "baro"))  # the GPS, 0 of 2
    assert not witnessed(verdicts, who, ("baro",))


def test_a_barometer_witnessed_by_nothing_is_given_no_drift_or_warming(tmp_path: Path) -> None:
    """rima48: a GPS 15 m off its barometer, 3 % of its heights accepted. At 20 Hz the drift
    gained 18.8 against the GPS's own 9.9 (9.2 against 9.8 at 10 Hz), was modelled, and the
    fused height went 1.5 m above the barometer and 12 m above the GPS for 42 s (836 ticks
    flagged); a temperature coefficient, modelled at both rates, was -0.043 m/degC at 10 Hz
    and -0.019 at 20: the two heights parted by up to 0.5 m. Neither has a witness: the
    smoother follows the barometer, flagged only over the log's last 0.2 s (the crash); at 10
    and 20 Hz the same heights (the model is decided on the datum's clock at every rate)."""
    log = shared_log("ardupilot/rima48_test_cascade.BIN")
    runs = {}
    for rate_hz in (10, 20):
        out = tmp_path / f"{rate_hz}.csv"
        args = ["fuse", str(log), "-o", str(out), "--rate", str(rate_hz)]
        assert CliRunner().invoke(cli, args).exit_code == 0
        meta = json.loads(out.with_suffix(".meta.json").read_text())
        for slow in ("baro_drift", "baro_thermal"):
            assert meta["parameters"][slow] == "not modelled (no other sensor's heights witness it)"
        assert [[a, b] for a, b in meta["guard"]["spans_s"] if b - a > 0.2] == []
        runs[rate_hz] = pd.read_csv(out).set_index("time_s").fused_alt_m
    both = runs[10].index[runs[10].index < 560.0]
    assert np.max(np.abs(runs[20].reindex(both) - runs[10][both])) < 1e-3


def test_a_gps_that_ramps_away_from_two_barometers_is_not_followed_by_their_drift() -> None:
    """Two barometers agree; the GPS ramps away at 0.1 m/s. Offered a drift rate, the
    barometers took the GPS's ramp (a gain of 947) and the height went 15 m astray; the GPS's own
    drift explains the log better (985), and the barometers are not made to drift."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 150.0, 0.1)
    truth = 10 * (1 - np.cos(2 * np.pi * t / 75))
    z = truth[:, None] + rng.normal(0.0, [0.05, 0.1, 0.1], (t.size, 3))
    z[:, 0] += 0.1 * t
    climb = np.gradient(np.gradient(truth, t), t)
    inputs = FusionInput.from_heights(z, 0.1, kinds=("gps", "baro", "baro"), accel_up=climb)
    result = fuse_smoother(inputs, SmootherParams())
    assert result.params["baro_drift"].startswith("not modelled (the GPS's own drift")
    assert result.params["gps_drift_loglik_gain"] > result.params["baro_drift_loglik_gain"]
    error = result.fused - truth
    assert np.ptp(error) < 1.0  # 0.34; 14.9 with the drift


def test_two_barometers_reading_one_air_do_not_outvote_the_gps() -> None:
    """A simulator's hop with two barometers in a 3 m/s wind (``windy-3``): both read its
    dynamic pressure, up to 0.3 m high over tens of seconds, where the GPS holds. Taken as
    independent, each needed a drift rate of its own where one drift of the GPS explained both
    (gains 49 and 62), and the height followed them: 0.168 m RMSE against the truth. They share
    their wander (BARO_SHARED): 0.045, as with either barometer alone."""
    log = read_log(shared_log("truth/copter_4.4.4_wlichon_home137m_rfndzero.BIN"))
    table = evaluate(variant(log, "windy-3"), ["smoother"]).table().set_index("name")
    assert table.loc["baro", "rmse"] > 0.15
    assert table.loc["smoother", "rmse"] < 0.06


def test_a_gps_parting_from_three_sensors_that_agree_does_not_make_the_barometer_drift() -> None:
    """A real log: its GPS starts before its fix converged and climbs 20 m in 150 s from a
    barometer, a second GPS and a rangefinder that agree. The barometer's drift (a gain of
    7.4 over the plain model) is not modelled where the GPS's own explains the log better
    (214): the height stays on the barometer (within 0.31 m; 2 m above it at the end with the
    drift), and from the log's start (the GPS's unconverged first 2 s, read, took it 3.4 m
    down)."""
    result = evaluate(shared_log("ardupilot/diaven_sample01.bin"), ["smoother"])
    run = result.runs["smoother"]
    params = run.result.params
    assert params["baro_drift"].startswith("not modelled (the GPS's own drift")
    assert params["gps_drift_loglik_gain"] > params["baro_drift_loglik_gain"] > DRIFT_GAIN
    referred = run.referred
    baro = referred.h[:, referred.names.index("baro")]
    assert np.nanmax(np.abs(run.result.fused - baro)) < 0.5


@pytest.mark.parametrize(("faults", "modelled"), [((), False), (("baro-scale",), True)])
def test_a_barometer_scale_the_datum_cannot_tell_is_learnt_where_the_log_asks(
    tmp_path: Path, faults: tuple[str, ...], modelled: bool
) -> None:
    """The mission climbs 15 m: against a GPS of 0.35 m noise the datum cannot tell a
    barometer 7 % high (1.05 +- 0.03, not applied) and the smoother followed it, 0.93 m RMSE
    against mean's 0.52. Now a scale error where the likelihood asks (a gain of 166): the
    truth's 7 %, and 0.05 m; without the fault the log does not ask and none is modelled."""
    log = tmp_path / "mission.bin"
    write_simulated_log(simulate_flight("mission", 2, faults=faults), log)
    result = evaluate(log, ["smoother"], truth="sim")
    offsets = {o.name: o for o in result.prepared.referred.offsets}
    assert offsets["baro"].scale_unknown
    assert offsets["baro"].scale == 1.0
    params = result.runs["smoother"].result.params
    rmse = next(r.overall.rmse for r in result.rows if r.name == "smoother")
    assert rmse < 0.1  # 0.050 and 0.059
    if modelled:
        assert params["baro_scale"] == "modelled"
        assert params["scale_error_baro"] == pytest.approx(0.07, abs=0.015)  # 0.072
    else:
        assert params["baro_scale"].startswith("not modelled")  # a gain of -2.2
        assert "scale_error_baro" not in params


def test_every_barometer_s_scale_is_learnt_again_where_one_is() -> None:
    """Where one barometer's applied scale is loose, every applied one is learnt again (they
    share the air); where none is, none; a barometer whose scale was not applied is left out."""
    loose, tight = (1.052, LEARN_SCALE_STD + 0.001), (1.048, LEARN_SCALE_STD - 0.002)
    assert scales_to_relearn([None, loose, tight]) == {1: loose, 2: tight}
    assert scales_to_relearn([None, tight, tight]) == {}
    assert scales_to_relearn([None, None, loose]) == {2: loose}


def test_a_scale_the_datum_applied_loosely_is_relearnt_by_the_smoother(tmp_path: Path) -> None:
    """The hover climbs 240 m with its barometer 7 % high: the datum, against the GPS alone,
    applies 1.074 +- 0.013, and at 240 m its error is a metre: the smoother followed it, 0.483 m
    RMSE, +-2 sigma coverage 0.17. Above LEARN_SCALE_STD the smoother relearns the scale from
    the barometer's own readings, with the accelerometer: 0.04 m; the other methods keep the
    datum's scale."""
    log = tmp_path / "hover.bin"
    write_simulated_log(simulate_flight("hover", 0, faults=("baro-scale",)), log)
    result = evaluate(log, ["support", "smoother"], truth="sim")
    baro = {o.name: o for o in result.prepared.referred.offsets}["baro"]
    assert baro.scale_applied
    assert baro.scale_std is not None
    assert baro.scale_std > LEARN_SCALE_STD
    params = result.runs["smoother"].result.params
    assert params["baro_scale"] == "modelled"
    assert params["scale_error_baro"] == pytest.approx(0.07, abs=0.01)
    rmse = {r.name: r.overall.rmse for r in result.rows}
    assert rmse["smoother"] < 0.1  # 0.040
    assert rmse["support"] < 1.0  # 0.505: the datum's scale, applied
    fused = result.runs["smoother"].result
    error = fused.fused - result.truth.h
    assert coverage(error, fused.tick_traces["fused_std"]) > 0.9  # 0.998


def test_a_log_resumed_in_flight_is_fused_from_where_its_sensors_say_the_vehicle_is(
    tmp_path: Path,
) -> None:
    """The plane's log paused for 20 s in its cruise at 300 m, resumed in flight: at the
    splice the height returns to the prior, centred on the segment's own first samples. Centred
    on the log's first guess (0 m +- 10 m), every sample was gated 30 sigma away and six ticks
    were written 300 m below every sensor (16.6 m RMSE; unspliced 0.011, both before the
    simulator's sensors lagged; now 0.044 against 0.041)."""
    rmse = {}
    for faults in ((), ("splice",)):
        log = tmp_path / f"climb{len(faults)}.bin"
        write_simulated_log(simulate_flight("climb", 0, faults=faults), log)
        result = evaluate(log, ["smoother"], truth="sim")
        assert len(result.prepared.referred.segments) == 2 * len(faults)
        rmse[faults] = next(r.overall.rmse for r in result.rows if r.name == "smoother")
        assert not (result.runs["smoother"].result.status == "diverged").any()
    assert rmse[("splice",)] < 1.2 * rmse[()]


def test_the_sensors_unknown_latency_widens_the_band_by_the_climb_rate() -> None:
    """fused_std adds |v| times the latency's sigma in quadrature, at the smoothed velocity;
    the estimate itself does not move."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 60.0, 0.1)
    truth = np.where(t < 20.0, 0.0, np.minimum(t - 20.0, 20.0) * 2.0)  # a 2 m/s climb to 40 m
    z = truth[:, None] + rng.normal(0.0, 0.05, (t.size, 2))
    accel = np.zeros(t.size)
    inputs = FusionInput.from_heights(z, 0.1, kinds=("gps", "baro"), accel_up=accel)
    exact = fuse_smoother(inputs, SmootherParams(timing_sigma_s=0.0))
    late = fuse_smoother(inputs, SmootherParams(timing_sigma_s=0.01))
    np.testing.assert_array_equal(late.fused, exact.fused)
    v = late.tick_traces["velocity"]
    widened = late.tick_traces["fused_std"] ** 2 - exact.tick_traces["fused_std"] ** 2
    np.testing.assert_allclose(widened, (0.01 * v) ** 2, rtol=1e-9, atol=1e-15)
    climbing = (t > 25.0) & (t < 35.0)
    assert np.median(np.abs(v[climbing])) == pytest.approx(2.0, abs=0.1)
    assert late.params["timing_sigma_s"] == 0.01


def _climb_at_two_rates(kinds: tuple[SensorKind, SensorKind]) -> FusionInput:
    """A 2 m/s climb to 40 m, its second sensor sampled at the clock's 10 Hz and its first at
    5 Hz (every other tick), both 5 cm noisy, the accelerometer level."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 60.0, 0.1)
    truth = np.where(t < 20.0, 0.0, np.minimum(t - 20.0, 20.0) * 2.0)
    z = truth[:, None] + rng.normal(0.0, 0.05, (t.size, 2))
    inputs = FusionInput.from_heights(z, 0.1, kinds=kinds, accel_up=np.zeros(t.size))
    # on the clock at every tick (as the spline puts it), sampled at every other
    return replace(inputs, samples=(Samples(t[::2], z[::2, 0]), inputs.samples[1]))


@pytest.mark.parametrize("rate_hz", [2.0, 3.0, 20.0])
def test_the_smoother_s_answer_does_not_move_with_the_output_rate(rate_hz: float) -> None:
    """The smoother decides its model on the datum's 10 Hz clock at every ``--rate``; the
    output's ticks only read its state. It was decided on the output's clock: on the 3.3
    plane's truth log its height at 2 Hz lay up to 0.35 m from its height at 10 Hz at the same
    instants (0.58 m at 20 Hz), its band 2x as wide at 1 Hz; on the shared logs a barometer's
    drift was modelled at one rate and not at another, and a 628 s copter log's height moved
    by 0.15 m at 20 Hz. Now they agree to 6 micrometres, the tests' gains to 1e-6."""
    log = shared_log("truth/plane_3.3.0a1_gitterbadger_autotest_climb386m_imunoise.BIN")
    base = fuse_log(log, FuseOptions())
    other = fuse_log(log, FuseOptions(rate_hz=rate_hz))
    ticks = [np.round(run.referred.t, 6) for run in (base, other)]
    both = np.intersect1d(*ticks)
    assert both.size >= 230  # at 3 Hz, the whole seconds of 232 s
    at = [np.searchsorted(t, both) for t in ticks]
    fused = [run.result.fused[i] for run, i in zip((base, other), at, strict=True)]
    std = [run.result.tick_traces["fused_std"][i] for run, i in zip((base, other), at, strict=True)]
    valid = np.isfinite(fused[0]) & np.isfinite(fused[1])
    assert valid.sum() >= both.size - 2  # a coarse tick's cell may hold no sample of a sensor
    np.testing.assert_allclose(fused[1][valid], fused[0][valid], rtol=0, atol=1e-4)
    np.testing.assert_allclose(std[1][valid], std[0][valid], rtol=1e-4)
    decisions = [
        {k: v for k, v in run.result.params.items() if isinstance(v, str)} for run in (base, other)
    ]
    assert decisions[1] == decisions[0]


def test_an_output_tick_between_two_model_events_takes_their_interval() -> None:
    """An event of the output's clock alone splits the interval of the model event after it
    (the last one's after them all), and takes that interval's values."""
    model = np.array([True, False, False, True, False, True, False])
    assert model_intervals(model).tolist() == [0, 3, 3, 3, 5, 5, 5]
    np.testing.assert_array_equal(
        on_every_event(np.array([1.0, 2.0, 3.0]), model), [1.0, 2.0, 2.0, 2.0, 3.0, 3.0, 3.0]
    )


def test_the_triangle_sums_are_the_direct_sums() -> None:
    """The weights' kernel by cumulative sums equals the sum over every sample, at times on,
    between and beyond the samples."""
    rng = np.random.default_rng(7)
    t = np.sort(rng.uniform(0.0, 20.0, 300))
    g = rng.uniform(0.0, 1.0, t.size)
    at = np.concatenate([t[::7], rng.uniform(-1.0, 21.0, 50)])
    width = 0.37
    direct = [np.sum(g * np.maximum(1.0 - np.abs(t - a) / width, 0.0)) for a in at]
    np.testing.assert_allclose(_triangle_sums(t, g, at, width), direct, rtol=1e-9, atol=1e-12)


def test_a_sensor_sampled_at_half_the_clock_keeps_its_weight_between_its_samples() -> None:
    """A GPS at 5 Hz beside a barometer at 10 Hz: the weights are each sensor's gain per second
    around the tick, not the gain of the samples since the previous tick (which gave the GPS
    most of the weight at the ticks with its sample and none at the others)."""
    result = fuse_smoother(_climb_at_two_rates(("gps", "baro")), SmootherParams())
    gps = result.weights[220:380, 0]  # the steady climb, away from its corners
    assert np.max(np.abs(np.diff(gps))) < 0.1  # 0.054; 0.71 by the gain since the last tick
    assert 0.2 < np.median(gps) < 0.8


@pytest.mark.parametrize("kinds", [("baro", "baro"), ("gps", "baro")])
def test_a_barometer_scale_nothing_pins_widens_the_band_as_the_height_follows_it(
    kinds: tuple[SensorKind, SensorKind],
) -> None:
    """SCALE_PRIOR of a barometer's height, times how far the smoothed height moves with its
    scale: with two barometers alone (both unpinned, one error for both) all of it; beside a
    GPS whose fit could not tell the scale, part of it, and as smoothly as the height (it was
    the barometer's share of the gain at each tick: all of it between the GPS's samples)."""
    inputs = _climb_at_two_rates(kinds)
    pinned = fuse_smoother(replace(inputs, scale_known=((1.0, 0.0), (1.0, 0.0))), SmootherParams())
    loose = replace(inputs, scale_unknown=((1.0, 0.2), (1.0, 0.2)))
    unpinned = fuse_smoother(loose, SmootherParams())
    np.testing.assert_array_equal(unpinned.fused, pinned.fused)
    std, without = unpinned.tick_traces["fused_std"], pinned.tick_traces["fused_std"]
    term = np.sqrt(std**2 - without**2)
    top = unpinned.fused > 39.0
    share = term[top] / (SCALE_PRIOR * unpinned.fused[top])
    if kinds[0] == "baro":
        np.testing.assert_allclose(share, 1.0, atol=0.02)
    else:
        assert 0.05 < np.median(share) < 0.95
        ratio = std[21:] / std[20:-1]
        assert np.max(np.abs(np.log(ratio[top[21:]]))) < 0.05


def test_a_step_in_every_sensor_without_acceleration_is_followed() -> None:
    """Issue 15: 5 m in every sensor at once, the accelerometer still (a spliced log, a reset):
    the gate rejects every sample, and after LOCKOUT_S the estimate is let loose, not locked
    out for the rest of the flight."""
    rng = np.random.default_rng(8)
    t = np.arange(0.0, 60.0, 0.1)
    truth = np.where(t < 30.0, 10.0, 15.0)
    z = truth[:, None] + rng.normal(0.0, 0.05, (t.size, 2))
    still = np.zeros(t.size)
    inputs = FusionInput.from_heights(z, 0.1, kinds=("gps", "baro"), accel_up=still)
    res = fuse_smoother(inputs, SmootherParams())
    after = t >= 30.0 + LOCKOUT_S + 1.0
    assert np.max(np.abs(res.fused[after] - 15.0)) < 0.1
    assert res.params["rejected_gps"] + res.params["rejected_baro"] < 2 * 10 * (LOCKOUT_S + 1)


def _stepped(which: int) -> tuple[FusionInput, np.ndarray, np.ndarray]:
    """A climb to 30 m and a hold, a GPS 0.1 m noisy that wanders (0.01 m^2/s) and a barometer;
    ``which`` (0: the GPS, 1: the barometer) 1 m higher from 70 s on; the step between them as
    :mod:`altfuse.steps` finds it. The inputs, the truth, the clock."""
    rng = np.random.default_rng(2)
    dt = 0.1
    t = np.arange(0.0, 120.0, dt)
    h = np.interp(t, [0, 20, 40, 120], [0, 0, 30, 30])
    a = np.gradient(np.gradient(h, dt), dt) + rng.normal(0, 0.05, t.size)
    walk = np.cumsum(rng.normal(0, np.sqrt(0.01 * dt), t.size))
    z = np.column_stack([h + walk + rng.normal(0, 0.1, t.size), h + rng.normal(0, 0.05, t.size)])
    z[t >= 70.0, which] += 1.0
    inputs = FusionInput.from_heights(z, dt, kinds=("gps", "baro"), accel_up=a)
    (step,) = find_steps(t, z, inputs.names, inputs.kinds)
    jump = (step.time_s, (0, 1), step.size_m, step.half_width_s, step.settle_m)
    return replace(inputs, on_ground_s=((0.0, 18.0),), steps=(jump,)), h, t


@pytest.mark.parametrize("which", [0, 1])
def test_a_step_in_one_sensor_is_that_sensor_s_jump(which: int) -> None:
    """Issue 15, item 1 (a fault the random walks cannot take): the barometer 1 m higher from
    70 s on beside a GPS that wanders, and the smoother followed it (0.89 m RMSE after it: the
    GPS is the sensor that wanders); found by the likelihood of either sensor's jump, and each
    sensor's heights after it taken back by it, the height stays within 3 cm."""
    inputs, h, t = _stepped(which)
    res = fuse_smoother(inputs, SmootherParams())
    when, size, sensor = re.fullmatch(r"(\S+) s: (\S+) m, (\w+)", str(res.params["steps"])).groups()
    assert (float(when), sensor) == (69.95, ("gps", "baro")[which])
    assert float(size) == pytest.approx(1.0, abs=0.03)
    after = t >= 70.0
    assert np.max(np.abs(res.fused[after] - h[after])) < 0.04
    if which == 1:  # without the step: the barometer followed
        plain = fuse_smoother(replace(inputs, steps=()), SmootherParams())
        assert np.sqrt(np.mean((plain.fused[after] - h[after]) ** 2)) > 0.5


@pytest.mark.parametrize(
    ("gap", "found"),
    [(False, [("baro", 69.95), ("baro2", 69.95)]), (True, [("baro2", 64.95), ("baro", 69.95)])],
)
def test_a_gps_s_step_against_two_barometers_is_one_jump_of_the_gps(
    gap: bool, found: list[tuple[str, float]]
) -> None:
    """Two steps at one instant (the GPS 2 m higher from 70 s on, against each barometer):
    tried one at a time, the first went to the GPS and the second then to a barometer; as one
    event, the sensor both share jumped, once (its samples moved back by one jump, not two).
    With the second barometer lost from 58 to 72 s (``gap``) its step lies in the gap's middle,
    64.95 s, another event: both went to the GPS at the instant of its own jump and its samples
    were moved back twice ("69.95 s: +2.10 m, gps; 69.95 s: +1.93 m, gps"); one jump now."""
    rng = np.random.default_rng(4)
    dt = 0.1
    t = np.arange(0.0, 120.0, dt)
    h = np.interp(t, [0, 20, 40, 120], [0, 0, 30, 30])
    a = np.gradient(np.gradient(h, dt), dt) + rng.normal(0, 0.05, t.size)
    z = h[:, None] + rng.normal(0, [0.05, 0.1, 0.1], (t.size, 3))
    z[t >= 70.0, 0] += 2.0
    if gap:
        z[(t >= 58.0) & (t < 72.0), 2] = np.nan
    inputs = FusionInput.from_heights(z, dt, kinds=("gps", "baro", "baro"), accel_up=a)
    steps = find_steps(t, z, inputs.names, inputs.kinds)
    assert [(s.second, s.time_s) for s in steps] == found
    jumps = tuple(
        (s.time_s, (0, inputs.names.index(s.second)), s.size_m, s.half_width_s, s.settle_m)
        for s in steps
    )
    res = fuse_smoother(replace(inputs, on_ground_s=((0.0, 18.0),), steps=jumps), SmootherParams())
    when, size, sensor = re.fullmatch(r"(\S+) s: (\S+) m, (\w+)", str(res.params["steps"])).groups()
    assert (float(when), sensor) == (69.95, "gps")
    assert float(size) == pytest.approx(2.0, abs=0.05)
    after = t >= 70.0
    assert np.max(np.abs(res.fused[after] - h[after])) < 0.05


def _regained(seed: int, jump_m: float) -> tuple[FusionInput, np.ndarray, np.ndarray]:
    """A climb to 30 m and a hold, a GPS 5 cm noisy and a barometer 0.6 m noisy (the 3.3
    plane's), lost from 60 to 70 s and ``jump_m`` higher once regained. The inputs, the truth,
    the clock."""
    rng = np.random.default_rng(seed)
    dt = 0.1
    t = np.arange(0.0, 120.0, dt)
    h = np.interp(t, [0, 20, 40, 120], [0, 0, 30, 30])
    a = np.gradient(np.gradient(h, dt), dt) + rng.normal(0, 0.05, t.size)
    z = np.column_stack([h + rng.normal(0, 0.05, t.size), h + rng.normal(0, 0.6, t.size)])
    z[(t >= 60.0) & (t < 70.0), 1] = np.nan
    z[t >= 70.0, 1] += jump_m
    inputs = FusionInput.from_heights(z, 0.1, kinds=("gps", "baro"), accel_up=a)
    return replace(inputs, on_ground_s=((0.0, 18.0),)), h, t


def test_a_sensor_regained_elsewhere_is_its_jump_where_the_likelihood_says_so() -> None:
    """The barometer regained 2 m higher: 5.6 sigma across its gap, under the sure steps' 10;
    taken as a tentative step, the likelihood makes it the barometer's jump and the height
    stays on the truth (without it the smoother followed the barometer 2.0 m up, until the GPS
    was offered as stable beside the barometer's drift: 0.020 m, the drift taken). A
    tentative step where nothing jumped is not taken: the height as without it."""
    inputs, h, t = _regained(6, 2.0)
    (step,) = find_steps(t, inputs.z, inputs.names, inputs.kinds)
    assert step.tentative
    jump = (step.time_s, (0, 1), step.size_m, step.half_width_s, step.settle_m)
    res = fuse_smoother(replace(inputs, tentative=(jump,)), SmootherParams())
    when, size, sensor = re.fullmatch(r"(\S+) s: (\S+) m, (\w+)", str(res.params["steps"])).groups()
    assert (float(when), sensor) == (64.95, "baro")
    assert float(size) == pytest.approx(2.0, abs=0.3)
    after = t >= 70.0
    assert np.sqrt(np.mean((res.fused[after] - h[after]) ** 2)) < 0.05
    inputs, h, t = _regained(0, 0.0)
    made_up = replace(inputs, tentative=((64.95, (0, 1), 2.0, 5.0, 0.0),))
    res = fuse_smoother(made_up, SmootherParams())
    assert res.params["steps"] == ""
    np.testing.assert_array_equal(res.fused, fuse_smoother(inputs, SmootherParams()).fused)


@pytest.mark.parametrize("stepped", ["gps", "gps2", "baro"])
def test_a_real_log_s_sensor_stepped_2_m_is_its_jump_beside_the_others(stepped: str) -> None:
    """A real log with two GPS receivers and a barometer, one of them 2 m higher from 80 s on.
    Both offsets loose where the likelihood did not tell (a GPS's step against the other GPS
    and the barometer): the fused height moved 0.30 m; gated before steps were sought (the
    GPS's: 0.008 m; the barometer's: 0.76 m); now the sensor the others agree moved (0.002 m;
    the barometer's 0.37: its level, which held the height, is lost at its jump)."""
    flight = read_log(shared_log("ardupilot/diaven_sample01.bin"))
    plain = run_method(prepare(flight, FuseOptions()), FuseOptions()).result.fused
    sensors = tuple(
        replace(s, value=s.value + np.where(s.t >= 80.0, 2.0, 0.0)) if s.name == stepped else s
        for s in flight.sensors
    )
    run = run_method(prepare(replace(flight, sensors=sensors), FuseOptions()), FuseOptions())
    assert str(run.result.params["steps"]).endswith(f" m, {stepped}")
    moved = run.result.fused - plain
    assert np.sqrt(np.nanmean(moved**2)) < (0.5 if stepped == "baro" else 0.02)


def _unlogged_landing(
    gps_m: float, baro_m: float, baro_every: int
) -> tuple[np.ndarray, dict[str, object], np.ndarray, np.ndarray]:
    """A descent at 0.6 m/s that stops on the ground at 20 s, the touchdown absent from the
    logged IMU (a PX4 simulator's landing), a GPS ``gps_m`` noisy at 5 Hz and a barometer
    ``baro_m`` noisy every ``baro_every`` 50 Hz tick: the smoother's fused height, its
    metadata, and the truth and the clock."""
    rng = np.random.default_rng(11)
    dt = 0.02
    t = np.arange(0.0, 40.0, dt)
    h = np.where(t < 10.0, 6.0, np.clip(0.6 * (20.0 - t), 0.0, None))  # on the ground at 20 s
    a = rng.normal(0.0, 0.02, t.size)  # level flight, then the descent starts: both logged
    a[int(10.0 / dt)] -= 0.6 / dt  # the descent's start, not its stop
    z = np.column_stack([h + rng.normal(0, gps_m, t.size), h + rng.normal(0, baro_m, t.size)])
    z[np.arange(t.size) % 10 != 0, 0] = np.nan  # the GPS at 5 Hz
    z[np.arange(t.size) % baro_every != 0, 1] = np.nan
    inputs = FusionInput.from_heights(z, dt, kinds=("gps", "baro"), accel_up=a)
    res = fuse_smoother(inputs, SmootherParams())
    return res.fused, dict(res.params), h, t


def test_a_landing_the_accelerometer_did_not_log_is_followed_from_the_first_rejection() -> None:
    """Issue 15, item 1: the landing's GPS and barometer (10 Hz) leave the estimate together:
    the forward filter lets it loose after AGREED_LOCKOUT_S, not the 2 s of LOCKOUT_S (1.4 m
    under both sensors for 2.5 s on that PX4 log), and the EM passes at their first rejection
    (0.43 m under both for 1 s when the forward filter's decision stood; 0.03 m now)."""
    fused, params, h, t = _unlogged_landing(0.02, 0.05, 5)
    error = np.abs(fused - h)
    assert np.nanmax(error[t >= 19.0]) < 0.1
    assert int(params["rejected_gps"]) + int(params["rejected_baro"]) <= 2


def test_a_precise_sensor_rejected_while_a_noisy_one_leans_its_way_lets_the_height_loose() -> None:
    """Issue 15, item 1: the same landing with a barometer (25 Hz) noisy enough to pass the
    gate as the estimate sinks under the ground. The GPS alone is rejected, so no two sensors
    agree by failing the gate together; the barometer's accepted samples lean its way (a PX4
    simulator's landing: the height 0.18 m under both for 3 s, fused_std 0.024 m), and the
    height is let loose after AGREED_LOCKOUT_S, from the GPS's first rejection in the EM
    passes."""
    fused, params, h, t = _unlogged_landing(0.01, 0.25, 2)
    error = np.abs(fused - h)
    assert np.nanmax(error[t >= 20.5]) < 0.05  # 0.027; 0.145 before
    assert int(params["rejected_gps"]) <= 1


def test_a_real_landing_is_back_on_its_sensors_within_a_second() -> None:
    """The PX4 simulator's landing of the test above (pyulog's sample with events): on the
    ground from 25.7 s, the estimate sank under a GPS and a barometer that agree at 0 m, the
    GPS rejected and the barometer passing; the height stayed 0.18 m under both for 3 s
    (0.14 m at 26.5 s), its band 0.024 m. Now it is back on them within a second."""
    options = FuseOptions()
    run = run_method(prepare_log(shared_log("px4/pyulog_sample_px4_events.ulg"), options), options)
    t, z = run.referred.t, run.referred.h
    after = (t >= 26.5) & (t <= 28.8)
    assert run.referred.names == ("gps", "baro")
    assert np.isfinite(z[after]).all()
    assert np.abs(z[after, 0] - z[after, 1]).mean() < 0.06  # the two agree
    assert np.max(np.abs(run.result.fused[after] - z[after, 0])) < 0.04  # 0.020; 0.139 before


def test_a_landed_verdict_is_held_short_of_its_turns_only() -> None:
    """A detector says "landed" after the touch-down and "flying" after the lift-off: the hold
    keeps LANDED_MARGIN_S from each turn of the verdict, and none from the log's own ends,
    where the verdict has no turn (a log begun and ended on the ground)."""
    times = np.arange(0.0, 30.0 + 1e-9, 0.1)
    said = Samples(np.array([0.0, 10.0, 20.0, 30.0]), np.array([1.0, 0.0, 1.0, 1.0]))
    held = landed_events(times, np.full(times.size, TICK), said, None)
    m = LANDED_MARGIN_S
    expected = ((times >= 0.0) & (times <= 10.0 - m)) | ((times >= 20.0 + m) & (times <= 30.0))
    np.testing.assert_array_equal(held, expected)
    # a sample is no tick: the hold is on the clock's ticks alone
    assert not landed_events(times, np.zeros(times.size, dtype=int), said, None).any()


@pytest.mark.parametrize("step_m", [0.0, 3.0])
def test_a_land_detector_saying_landed_in_a_descent_is_not_held(step_m: float) -> None:
    """A land detector can say landed in the air: Copter 3.4's did in a 10 m/s descent from
    150 m, its motors at their lower limit. Here one says landed from 11 s, in an 8 m/s
    descent from 50 m to 10 m (12-17 s): held at v = 0 from 13 s, the height ended 5.2 m off
    both sensors, every sample of theirs rejected. The sensors agree it sinks: no hold, 0.11 m
    at most. A step of one sensor on the ground (its GPS 3 m up, the barometer still) is no
    climb: the hold stays."""
    rng = np.random.default_rng(5)
    dt = 0.02
    t = np.arange(0.0, 40.0, dt)
    h = np.interp(t, [0.0, 12.0, 17.0, 40.0], [50.0, 50.0, 10.0, 10.0])
    if step_m:
        h = np.zeros_like(t)  # on the ground all along
    a = np.gradient(np.gradient(h, t), t) + rng.normal(0.0, 0.05, t.size)
    gps = h + rng.normal(0.0, 0.3, t.size) + np.where(t >= 25.0, step_m, 0.0)
    z = np.column_stack([gps, h + rng.normal(0.0, 0.1, t.size)])
    z[np.arange(t.size) % 10 != 0, 0] = np.nan  # the GPS at 5 Hz, the barometer at 10 Hz
    z[np.arange(t.size) % 5 != 0, 1] = np.nan
    inputs = FusionInput.from_heights(z, dt, kinds=("gps", "baro"), accel_up=a)
    said = Samples(np.array([0.0, 11.0, 11.0, 40.0]), np.array([0.0, 0.0, 1.0, 1.0]))
    res = fuse_smoother(replace(inputs, landed=said), SmootherParams())
    if step_m:
        assert res.params["landed_held_s"] == pytest.approx(27.0, abs=0.1)  # 13 s to the end
        assert np.nanmax(np.abs(res.fused)) < 0.15  # 0.07: the GPS's step is its own
        return
    assert res.params["landed_held_s"] == 0.0
    assert np.nanmax(np.abs(res.fused - h)) < 0.2  # 0.11; 5.2 m held


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_an_accelerometer_impulse_is_recovered_from_within_2_s(sign: float) -> None:
    """Issue 15: one 25 Hz IMU sample worth +-20 m/s (an impact, a clipped sample), GPS and
    barometer agreeing: the height stays with them (it ran 40 m away for the 2 s of the
    lockout before)."""
    rng = np.random.default_rng(3)
    dt = 0.04
    t = np.arange(0.0, 80.0, dt)
    h = 10 + 5 * np.sin(t / 6)
    a = -5 / 36 * np.sin(t / 6) + rng.normal(0.0, 0.05, t.size)
    a[int(40 / dt)] += sign * 20.0 / dt
    z = np.column_stack([h + rng.normal(0, 0.3, t.size), h + rng.normal(0, 0.1, t.size)])
    z[np.arange(t.size) % 5 != 0, 0] = np.nan  # the GPS at 5 Hz
    inputs = FusionInput.from_heights(z, dt, kinds=("gps", "baro"), accel_up=a)
    res = fuse_smoother(inputs, SmootherParams())
    error = np.abs(res.fused - h)
    assert error[(t >= 40.0) & (t < 42.0)].max() < 0.2
    assert error[t >= 42.0].max() < 0.15
    assert res.params["rejected_gps"] + res.params["rejected_baro"] < 10


def _wrong_accelerometer(kinds: tuple[str, str]) -> tuple[FusionInput, np.ndarray, np.ndarray]:
    """Two sensors agreeing with the truth and an accelerometer 8 m/s^2 off for 3 s (an attitude
    error that rotates gravity into the vertical): the inputs, the truth, the clock."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 120.0, 0.1)
    h = 50 + 20 * np.sin(t / 10)
    a = -0.2 * np.sin(t / 10) + rng.normal(0.0, 0.05, t.size)
    a[(t >= 60) & (t < 63)] += 8.0
    z = np.column_stack([h + rng.normal(0, 0.05, t.size), h + rng.normal(0, 0.2, t.size)])
    return FusionInput.from_heights(z, 0.1, kinds=kinds, accel_up=a), h, t


def a_of(inputs: FusionInput) -> np.ndarray:
    """The vertical acceleration ``inputs`` was given at its ticks."""
    assert inputs.accel is not None
    return inputs.accel.on_clock


def test_the_sensors_refuse_an_accelerometer_they_all_contradict() -> None:
    """Issue 15, item 2: where a GPS and a barometer agree against the accelerometer for seconds,
    its noise is raised there, and only there; where they are the only witnesses, two
    barometers (one air) refuse it too; a sensor that sides with the accelerometer keeps it."""
    inputs, h, t = _wrong_accelerometer(("gps", "baro"))
    assert inputs.accel is not None
    refused = accel_refused(inputs, inputs.accel.on_clock)
    assert refused[(t >= 60.5) & (t < 62.5)].min() > 1.0  # m^2/s^3: metres per second in 1 s
    assert not refused[(t < 58) | (t > 65)].any()
    res = fuse_smoother(inputs, SmootherParams())
    assert np.max(np.abs(res.fused - h)) < 0.3  # 40 m away before
    one_air, _, _ = _wrong_accelerometer(("baro", "baro"))
    assert one_air.accel is not None
    assert accel_refused(one_air, one_air.accel.on_clock)[(t >= 60.5) & (t < 62.5)].min() > 1.0
    # the barometer alone moves (a pressure transient): the GPS sides with the accelerometer
    bump = np.where((t >= 60) & (t < 63), 3.0 * np.sin(np.pi * (t - 60) / 3) ** 2, 0.0)
    transient = FusionInput.from_heights(
        inputs.z + np.column_stack([0 * t, bump]),
        0.1,
        ("gps", "baro"),
        accel_up=a_of(inputs) - np.where((t >= 60) & (t < 63), 8.0, 0.0),
    )
    assert transient.accel is not None
    assert not accel_refused(transient, transient.accel.on_clock).any()
    # a third sensor absent there has no vote, and takes none away
    gone = np.where(((t > 50) & (t < 70))[:, None], np.nan, inputs.z[:, :1])
    three = FusionInput.from_heights(
        np.column_stack([inputs.z, gone]), 0.1, ("gps", "baro", "gps"), accel_up=a_of(inputs)
    )
    assert three.accel is not None
    assert accel_refused(three, three.accel.on_clock)[(t >= 60.5) & (t < 62.5)].min() > 1.0


def test_a_test_the_richer_model_lost_outright_is_recorded_without_its_gain() -> None:
    """The metadata is JSON: a richer model that rejected more samples (a gain of -inf) is
    said in words (it broke ``altfuse fuse -m smoother`` on beastayyg_sample.bin)."""
    record = evidence_record("thermal", False, -math.inf)
    assert record == {
        "baro_thermal": "not modelled (it rejected more samples than the model without)"
    }
    json.dumps(record, allow_nan=False)
    assert evidence_record("drift", True, 12.0)["baro_drift_loglik_gain"] == 12.0
    assert evidence_record("drift", True, math.nan) == {}


def test_the_normalised_innovations_check_the_noise_model() -> None:
    """Issue 15, item 4: each sensor's mean squared normalised innovation is recorded; about 1
    with the noise learnt from the log, far below 1 with a noise 10x too large given."""
    inputs, _, _ = _wrong_accelerometer(("gps", "baro"))
    learnt = fuse_smoother(inputs, SmootherParams()).params
    assert 0.7 < learnt["nis_gps"] < 1.4
    assert 0.7 < learnt["nis_baro"] < 1.4
    told = fuse_smoother(inputs, SmootherParams(sigma_m={"baro": 2.0})).params
    assert told["nis_baro"] < 0.1


def test_accelerometer_spikes_add_their_excess_as_unknown() -> None:
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 100.0, 0.02)
    a = np.sin(t) + rng.normal(0.0, 0.1, t.size)
    # normal noise adds (almost) nothing: under 1 cm/s of velocity over the 100 s
    assert np.sqrt(np.sum(accel_spikes(t, a) * 0.02)) < 0.01
    a[2000] += 50.0
    added = accel_spikes(t, a)
    # the sample's excess beyond 5 sigma, as velocity: about (50 - 0.5) m/s^2 over 0.02 s
    assert np.sqrt(added[2000] * 0.02) == pytest.approx(49.5 * 0.02, rel=0.05)
    assert np.sqrt(np.sum(np.delete(added, 2000) * 0.02)) < 0.01


def test_the_agreement_of_two_sensors_bounds_their_wander_from_above() -> None:
    """Var(d(t + L) - d(t)) = q L + 2 sigma^2 >= q L: the bound does not undercut the density
    beyond its sampling error."""
    rng = np.random.default_rng(10)
    dt, q = 0.1, 0.01  # a difference wandering at 0.01 m^2/s
    walk = np.cumsum(rng.normal(0.0, np.sqrt(q * dt), 20000))
    assert 0.8 * q < wander_bound(walk, dt) < 1.5 * q  # within its sampling error
    # a real GPS's noise: it loosens the bound of single samples, its blocks' means hold
    noisy = walk + rng.normal(0.0, 0.7, walk.size)
    assert 0.8 * q < wander_bound(noisy, dt) < 1.5 * q
    still = rng.normal(0.0, 0.005, walk.size)  # two simulated sensors: millimetres apart
    assert wander_bound(still, dt) < 1e-5
    # neither wandering, one 0.11 m noisy (the Solo's barometer, 231 s): single samples alone
    # bounded nothing under 6e-4 m^2/s
    quiet = rng.normal(0.0, 0.11, 2310)
    assert wander_bound(quiet, dt) < 5e-5


def test_sensors_that_agree_tighten_the_default_random_walks() -> None:
    rng = np.random.default_rng(11)
    t = np.arange(0.0, 200.0, 0.1)
    h = 20 * np.sin(t / 30)
    agree = np.column_stack([h + rng.normal(0, 0.005, t.size), h + rng.normal(0, 0.005, t.size)])
    res = fuse_smoother(FusionInput.from_heights(agree, 0.1), SmootherParams())
    # a GPS that agrees with its barometer is taken as stable as it, and both are tightened
    assert res.params["gps_stable"] == "modelled"
    assert res.params["q_offset_gps_m2_s"] == pytest.approx(res.params["q_offset_baro_m2_s"])
    assert res.params["q_offset_gps_m2_s"] < 1e-4 * 2 * Q_AGREEMENT_MIN_SHARE
    wander = agree.copy()
    wander[:, 0] += np.cumsum(rng.normal(0, np.sqrt(0.01 * 0.1), t.size)) + rng.normal(
        0, 0.5, t.size
    )
    res = fuse_smoother(FusionInput.from_heights(wander, 0.1), SmootherParams())
    # it wanders at the default's density: kept, within the bound's sampling error (never raised)
    assert 0.7 * 0.01 < res.params["q_offset_gps_m2_s"] <= 0.01
    assert res.params["gps_stable"].startswith("not modelled")


def test_a_gps_that_does_not_wander_is_not_held_to_a_noisy_barometer() -> None:
    """A GPS as stable as its barometer (an RTK fix, a simulator's) with a noisy barometer
    whose level errs by 6 cm after a climb (as the 92 m SITL climb's): the two offsets share
    the step, where the default preference of the barometer's level followed the barometer."""
    rng = np.random.default_rng(12)
    t = np.arange(0.0, 120.0, 0.1)
    h = np.clip((t - 20.0) * 2.0, 0.0, 80.0)
    gps = h + rng.normal(0, 0.005, t.size)
    baro = h + 0.06 * (t > 60.0) + rng.normal(0, 0.1, t.size)
    z = np.column_stack([gps, baro])
    res = fuse_smoother(FusionInput.from_heights(z, 0.1), SmootherParams())
    assert res.params["gps_stable"] == "modelled"
    late = t > 65.0
    assert np.sqrt(np.mean((res.fused - h)[late] ** 2)) < 0.04  # the step shared: 0.032 m
    held = fuse_smoother(
        FusionInput.from_heights(z, 0.1), SmootherParams(offset_noise_m2_s={"gps": 0.01})
    )
    assert "gps_stable" not in held.params  # the user's densities are not tested
    assert np.sqrt(np.mean((held.fused - h)[late] ** 2)) > 0.06  # the barometer's: 0.086 m


def test_the_compiled_cache_is_kept_for_one_version_of_the_sources(tmp_path: Path) -> None:
    """numba keys a cached kernel on its own file only; a change to a step it calls, in
    another file, must not leave the old kernel cached."""
    (tmp_path / "steps.py").write_text("x = 1\n")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    (cache / "passes.kernel-1.py311.nbi").write_text("old")
    _forget_other_versions(tmp_path)
    assert not list(cache.glob("*.nbi"))  # made from unknown sources: gone
    (cache / "passes.kernel-1.py311.nbi").write_text("new")
    _forget_other_versions(tmp_path)
    assert list(cache.glob("*.nbi"))  # the same sources: kept
    (tmp_path / "steps.py").write_text("x = 2\n")
    _forget_other_versions(tmp_path)
    assert not list(cache.glob("*.nbi"))


def test_an_offset_measured_on_the_ground_is_known_to_its_standard_error() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(100) * 0.1
    noisy = Samples(t, rng.normal(0.0, 0.1, t.size))
    priors = datum_priors([noisy, noisy, Samples(t[:2], np.zeros(2))], [(0.0, 9.9), None, (0, 9)])
    # 0.1 m over root 100 samples, with how well standing at the take-off point holds
    assert priors[0] == pytest.approx(math.hypot(0.01, STILL_SIGMA), rel=0.15)
    assert priors[1] == OFFSET_PRIOR  # matched to another sensor: nothing better known
    assert priors[2] == OFFSET_PRIOR  # two samples say too little


def test_a_log_that_starts_just_before_take_off_gets_its_datum_from_the_ground() -> None:
    """The 4.5 plane's log starts 3 s before take-off: no span to hold h = 0 in, and the 1 m
    offset priors alone made fused_std 0.58 m (coverage 1.00) where the datum, measured on the
    ground window, is known to centimetres. The model's own band, without the sensors' unknown
    latency (which takes it to 0.995)."""
    exact = FuseOptions(params={"smoother": SmootherParams(timing_sigma_s=0.0)})
    log = shared_log("truth/plane_4.5.0dev_eozbademci_autotest_climb88m.BIN")
    ev = evaluate(log, ["smoother"], exact)
    assert ev.prepared.referred.on_ground_s is None
    windows = ev.prepared.referred.datum_windows
    assert all(w is not None for w in windows)
    sigma = ev.runs["smoother"].result.tick_traces["fused_std"]
    assert 0.01 < np.nanmedian(sigma) < 0.05  # measured 0.027 m
    assert ev.runs["smoother"].result.params["offset_prior_gps_m"] < 0.05  # in the metadata
    assert 0.90 <= verdict(ev, "smoother")["coverage"] <= 0.99  # measured 0.946


def _ground_step(kinds: tuple[str, ...]) -> FusionInput:
    """A 90 s hover at 10 m (no speed over ground) over a ground that rises 4 cm under the
    rangefinder from 30 s to 60 s (an edge, a box); the other two sensors read 3 mm of noise."""
    rng = np.random.default_rng(7)
    t = np.arange(900) * 0.1
    ground = np.where((t >= 30.0) & (t < 60.0), 0.04, 0.0)
    z = 10.0 + rng.normal(0.0, 0.003, (t.size, 3))
    z[:, 2] -= ground  # the rangefinder's height, referred to the ground at take-off
    inputs = FusionInput.from_heights(z, 0.1, kinds=kinds)  # type: ignore[arg-type]
    return dataclasses.replace(inputs, track=Track(Samples(t, np.zeros(t.size))))


def test_a_rangefinder_over_a_ground_step_is_not_rejected_for_more_than_two_seconds() -> None:
    """Issue 15, item 1: no sensor that agrees with another is rejected for more than 2 s.
    Hovering, the ground's random walk per metre flown lets it move by nothing, and the step
    back at 60 s was rejected for good (sonar_10m: 8 s). Its ground height is let loose after
    LOCKOUT_S where a sensor at least as precise passed; the estimate does not move."""
    res = fuse_smoother(_ground_step(("gps", "baro", "rangefinder")), SmootherParams())
    # two steps, each rejected for LOCKOUT_S at most (10 samples a second)
    assert res.params["rejected_rangefinder"] <= 2 * 10 * LOCKOUT_S + 2
    assert np.abs(res.fused - 10.0).max() < 0.02
    # the ground height follows the step (the trace of the rangefinder's state)
    ground = res.traces["offset"][:, 2]
    assert ground[450] == pytest.approx(0.04, abs=0.01)
    assert ground[850] == pytest.approx(0.0, abs=0.01)


def test_a_barometer_alone_refuses_an_accelerometer_it_contradicts() -> None:
    """The GPS out (a frozen receiver, dropped as stuck) while the accelerometer is 8 m/s^2 off
    for 3 s: the barometer is the only witness, and its word stands (a wrong sensor costs its
    own error, a wrong accelerometer grows without bound: 100 m on the 3.3 plane log; here
    measured 23.8 m before, 0.24 m after)."""
    inputs, h, t = _wrong_accelerometer(("gps", "baro"))
    z = inputs.z.copy()
    z[(t > 40) & (t < 80), 0] = np.nan
    alone = FusionInput.from_heights(z, 0.1, ("gps", "baro"), accel_up=a_of(inputs))
    assert alone.accel is not None
    assert accel_refused(alone, alone.accel.on_clock)[(t >= 60.5) & (t < 62.5)].min() > 1.0
    res = fuse_smoother(alone, SmootherParams())
    assert np.max(np.abs(res.fused - h)) < 1.0


def test_the_acceleration_noise_is_raised_where_the_smoothed_flight_departs_from_it() -> None:
    """EM's M-step per second: the smoothed velocity gains 1 m/s in the third second that the
    accelerometer (reading 0.5 m/s^2 throughout, its bias 0.5) does not explain; there the
    density becomes ACCEL_EM_GAIN * 1^2 / 1 s, elsewhere it keeps the log's own; and so
    without an accelerometer, where the density is the velocity's random walk's."""
    t = np.arange(0.0, 5.0, 0.1)
    v = np.where(t >= 2.5, 1.0, 0.0)
    x = np.column_stack([np.zeros(t.size), v, np.full(t.size, 0.5)])
    floor = np.full(t.size, 1e-3)
    who = np.full(t.size, -1)
    ev = Events(t, who, np.zeros(t.size), np.full(t.size, 0.5), np.zeros((t.size, 0)),
                np.zeros(t.size, bool), floor, True, 3.5, 0.0)  # fmt: skip
    raised = em_accel(ev, x, floor).q_accel
    third = (t >= 2.0 - 1e-9) & (t < 3.0 - 1e-9)
    np.testing.assert_allclose(raised[third], ACCEL_EM_GAIN * 1.0**2 / 1.0, rtol=1e-9)
    np.testing.assert_array_equal(raised[~third], floor[~third])
    # without the accelerometer (a = 0, b = 0) the velocity's own change raises it the same
    alone = replace(ev, use_bias=False, a=np.zeros(t.size))
    x[:, 2] = 0.0
    raised = em_accel(alone, x, floor).q_accel
    np.testing.assert_allclose(raised[third], ACCEL_EM_GAIN * 1.0**2 / 1.0, rtol=1e-9)
    np.testing.assert_array_equal(raised[~third], floor[~third])


def test_the_model_check_fails_on_the_sensors_beyond_twice_their_variance() -> None:
    assert model_check({"nis_gps": 0.2, "nis_baro": NIS_CHECK}) == "passed"
    verdict = model_check({"nis_gps": 5.09, "nis_gps2": 1.0, "nis_baro": 2.5})
    assert verdict.startswith("failed: mean squared normalised innovation gps 5.09, baro 2.50 ")
    assert "gps2" not in verdict


def test_a_splice_starts_the_motion_and_the_offsets_afresh() -> None:
    """A log stopped for 10 minutes on the ground and resumed: the second segment has its own
    ground, and every sensor its offset 0 there. Bridged by the model instead, the barometer's
    drift rate carried 1.8 m over the gap and the fused height sat above both sensors."""
    run = fuse_log(shared_log("ardupilot/beastayyg_sample.bin"), FuseOptions())
    segments = run.referred.segments
    assert len(segments) == 2
    assert segments[1].on_ground_s is not None
    t, z = run.referred.t, run.referred.h
    second = (t >= segments[1].start_s) & np.isfinite(run.result.fused)
    assert second.sum() > 200
    # from the sensors' median (GPS and barometer): measured 0.10 m at the median of the
    # segment's ticks, 0.22 m at 90 %; bridged, 1.80 and 1.93 m
    apart = np.abs(run.result.fused[second] - np.nanmedian(z[second], axis=1))
    assert np.median(apart) < 0.3
    assert np.quantile(apart, 0.9) < 0.5
    # in the pause the states are the model's guess (the velocity ramped to 6 m/s): not written
    pause = np.isnan(run.result.fused)
    assert pause.sum() > 1000
    assert np.isnan(run.result.tick_traces["velocity"][pause]).all()
    assert np.isnan(run.result.traces["offset"][pause]).all()


def test_a_long_flight_keeps_its_height_with_its_agreeing_sensors(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """45 minutes of flight: a real 150 s flight (a crash at its end) repeated 18 times. GPS
    and barometer agree within a metre throughout, but for the crashes. With both offsets
    random walks nothing held the height's common mode: the fused height wandered 4.2 m from
    both sensors, its fused_std growing to 2.6 m (2.0 m from them since the EM passes let the
    height loose at a crash's first rejection). A GPS's error is bounded (GPS_CORRELATION_S):
    0.68 m at most, fused_std below 0.6 m. (The barometer's dynamic pressure, which explains
    much of what the two part by, is left out of the random walk's run: with it that run too
    stays within 0.63 m.)"""
    log = tmp_path / "long.bin"
    repeated_log(shared_log("ardupilot/beastayyg_log_0036_mechanical_failure.bin"), log, 30)
    prepared = prepare_log(log, FuseOptions())
    assert prepared.referred.t[-1] - prepared.referred.t[0] > 2700.0
    run = run_method(prepared, FuseOptions())
    assert run.result.params["gps_correlation_s"] == GPS_CORRELATION_S
    guard = run.provenance["guard"]
    assert guard["diverged_ticks"] == 0
    assert guard["max_excursion_m"] < 1.5
    assert np.nanmax(run.result.tick_traces["fused_std"]) < 1.0
    # a bound of 10^6 s is a random walk over any flight: as before
    monkeypatch.setattr("altfuse.fuse.smoother.evidence.DYNAMIC_GAIN", math.inf)
    walk = {"smoother": SmootherParams(gps_correlation_s=1e6)}
    run = run_method(prepared, FuseOptions(params=walk))
    assert run.provenance["guard"]["max_excursion_m"] > 1.5
    assert np.nanmax(run.result.tick_traces["fused_std"]) > 2.0


def test_a_sensor_left_alone_is_let_loose_though_the_estimate_never_followed_it() -> None:
    """The lockout's release takes a sample of a sensor the estimate followed until it went
    astray; where every such sensor has gone silent (a barometer lost), the one left must still
    be let loose after LOCKOUT_S, or the estimate coasts on the accelerometer for the rest of
    the flight. Here the GPS steps 15 m at 20 s and stays (rejected against the barometer),
    and the barometer is lost at 40 s: from then on only the GPS says where the vehicle is."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 90.0, 0.1)
    truth = np.full(t.size, 10.0)
    gps = truth + np.where(t >= 20.0, 15.0, 0.0) + rng.normal(0.0, 0.1, t.size)
    baro = np.where(t < 40.0, truth + rng.normal(0.0, 0.05, t.size), np.nan)
    inputs = FusionInput.from_heights(
        np.column_stack([gps, baro]), 0.1, kinds=("gps", "baro"), accel_up=np.zeros(t.size)
    )
    res = fuse_smoother(inputs, SmootherParams())
    late = t >= 40.0 + LOCKOUT_S + 5.0
    # with nothing else left, the GPS is followed (its step is no longer told from a climb)
    assert np.max(np.abs(res.fused[late] - gps[late])) < 1.0
    assert res.params["rejected_gps"] < 10 * (20.0 + LOCKOUT_S + 5.0)
