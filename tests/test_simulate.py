"""altfuse simulate: genuine logs, reproducible, with every scenario and fault."""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from pymavlink import mavutil

from altfuse.cli import cli
from altfuse.errors import ParameterError
from altfuse.evaluation import evaluate
from altfuse.inertial import G, vertical_acceleration
from altfuse.io import read_log
from altfuse.pipeline import FuseOptions, prepare
from altfuse.simulate import (
    ARMING_LEAD_S,
    BARO_AIRFLOW_M,
    BARO_AIRFLOW_WIND_M_S,
    BOOT_S,
    DROP_M,
    FAULTS,
    GPS_LAG_S,
    HOME_AMSL_M,
    IMU_CLIP_M_S2,
    LATENCY_S,
    RESTITUTION,
    SCENARIOS,
    simulate_flight,
    write_simulated_log,
)
from conftest import ROOT

REGENERATE = ROOT / "sample_logs" / "regenerate.sh"
COMMANDS = [
    shlex.split(line)[1:]
    for line in REGENERATE.read_text().splitlines()
    if line.startswith("altfuse simulate")
]


def run(*args: str | Path) -> object:
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_every_sample_log_is_what_its_command_writes(tmp_path: Path) -> None:
    assert len(COMMANDS) >= 4
    for args in COMMANDS:
        target = ROOT / args[args.index("-o") + 1]
        made = tmp_path / target.name
        args[args.index("-o") + 1] = str(made)
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        assert made.read_bytes() == target.read_bytes(), (
            f"{target.name} differs from `altfuse {' '.join(args)}`: run sample_logs/regenerate.sh"
        )


@pytest.mark.parametrize("log", sorted((ROOT / "sample_logs").glob("*.bin")))
def test_pymavlink_reads_every_sample_log_without_a_word(
    log: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    conn = mavutil.mavlink_connection(str(log))
    counts: dict[str, int] = {}
    try:
        while (msg := conn.recv_msg()) is not None:
            counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
    finally:
        conn.close()
    out, err = capfd.readouterr()
    assert out == ""
    assert err == ""
    assert {"FMT", "FMTU", "UNIT", "MULT", "GPS", "BARO", "RFND", "IMU", "ATT", "SIM"} <= set(
        counts
    )
    flight = read_log(log)
    assert flight.skipped_bytes == 0
    assert [r.name for r in flight.references] == ["sim"]
    assert flight.imu is not None
    assert flight.attitude is not None


@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
def test_scenarios_have_realistic_sensor_rates_and_truth(scenario: str) -> None:
    sim = simulate_flight(scenario, seed=2)
    rates = {name: len(rows) / sim.duration_s for name, rows in sim.records.items()}
    assert rates["GPS"] == pytest.approx(5.0)
    assert rates["BARO"] == pytest.approx(20.0)
    assert rates["IMU"] == pytest.approx(50.0)
    assert rates["SIM"] == pytest.approx(10.0)
    gps_status = [values[1] for _, values in sim.records["GPS"]]
    assert gps_status[:15] == [1] * 15  # no fix for 3 s
    temps = [values[2] for _, values in sim.records["BARO"]]
    assert temps[0] == pytest.approx(25.0)
    assert temps[-1] > 30.0
    truth = np.array([values[0] for _, values in sim.records["SIM"]]) - HOME_AMSL_M
    assert truth[0] == pytest.approx(0.0, abs=1e-9)  # on the ground at take-off


def test_hover_scenario_climbs_to_240_m_and_the_rangefinder_pins_at_max() -> None:
    sim = simulate_flight("hover", seed=0)
    truth = np.array([values[0] for _, values in sim.records["SIM"]]) - HOME_AMSL_M
    assert truth[-1] == pytest.approx(240.0, abs=0.5)
    rfnd = sim.records["RFND"]
    high = [v for _, v in rfnd if v[2] == 3]
    assert high
    assert {v[1] for v in high} == {4000}


def test_paper_a_scenario_baro_departs_in_its_segment() -> None:
    sim = simulate_flight("paper-a", seed=0)
    lo, hi = sim.profile.segments["baro-departs"]
    t = sim.profile.t
    inside = (t >= lo) & (t < hi)
    assert sim.profile.baro_error_m[inside].max() == pytest.approx(2.5, abs=0.01)
    assert (sim.profile.baro_error_m[~inside] == 0).all()


#: The faults with a test of their own below.
OWN_TESTS = ("roll-flip", "splice", "hard-landing", "baro-airflow", "baro-rezero")


@pytest.mark.parametrize("fault", [f for f in FAULTS if f not in OWN_TESTS])
def test_faults(fault: str, tmp_path: Path) -> None:
    clean = read_log(_write(tmp_path / "clean.bin", "mission", []))
    faulty = read_log(_write(tmp_path / "faulty.bin", "mission", [fault]))
    a = {s.name: s for s in clean.sensors}
    b = {s.name: s for s in faulty.sensors}
    if fault.startswith("lose-"):
        lost = b[fault.removeprefix("lose-")]
        assert lost.t.max() < BOOT_S + 60.0 < a[lost.name].t.max()
    elif fault == "rangefinder-dropout":
        assert b["rangefinder"].dropped["Stat != 4 (not Good)"] >= 200  # 10 s at 20 Hz
    elif fault == "gps-glitch":
        jump = b["gps"].value - a["gps"].value
        assert np.sum(np.isclose(jump, 15.0, atol=1e-3)) == 25  # 5 s at 5 Hz
    elif fault == "imu-impact":  # one sample 25 g up (-Z in FRD)
        assert clean.imu is not None
        assert faulty.imu is not None
        dz = faulty.imu.acc[:, 2] - clean.imu.acc[:, 2]
        assert np.sum(np.abs(dz) > 1e-6) == 1
        assert dz.min() == pytest.approx(-25 * 9.80665, rel=1e-3)
    elif fault == "attitude-error":  # the logged roll 30 degrees off for 10 s (10 Hz)
        assert clean.attitude is not None
        assert faulty.attitude is not None
        off = np.rad2deg(faulty.attitude.roll - clean.attitude.roll)
        assert np.sum(np.isclose(off, 30.0, atol=1e-3)) == 100
        assert np.sum(np.abs(off) > 1e-3) == 100
    elif fault == "imu-clip":  # five samples pinned at -16 g on Z
        assert faulty.imu is not None
        pinned = np.isclose(faulty.imu.acc[:, 2], -16 * 9.80665, rtol=1e-4)
        assert pinned.sum() == 5
        assert np.ptp(np.flatnonzero(pinned)) == 4
    elif fault == "imu-25hz":
        assert clean.imu is not None
        assert faulty.imu is not None
        assert np.median(np.diff(faulty.imu.t)) == pytest.approx(0.04, rel=1e-3)
        assert faulty.imu.t.size == pytest.approx(clean.imu.t.size / 2, abs=1)
    elif fault == "baro-scale":  # 7 % of the height above take-off
        extra = b["baro"].value - a["baro"].value
        height = a["baro"].value - a["baro"].value[0]
        assert np.corrcoef(extra, height)[0, 1] > 0.99
    elif fault == "rangefinder-low":  # OutOfRangeLow on the ground, in range in flight
        assert b["rangefinder"].dropped["Stat != 4 (not Good)"] > a["rangefinder"].dropped.get(
            "Stat != 4 (not Good)", 0
        )
        assert b["rangefinder"].value.size > 0
    else:  # baro-drift: 0.05 m/s from 40 % of the flight
        assert (b["baro"].value - a["baro"].value)[-1] == pytest.approx(0.05 * 72, abs=0.1)


def test_a_barometer_re_zeroed_at_arming_is_read_as_one_zero(tmp_path: Path) -> None:
    """``baro-rezero``: 2 m high on the ground until the vehicle arms, 3 s before take-off, where
    ``EV`` ``EKF_ALT_RESET`` is logged; read back continuous, on the zero it flew with."""
    ((armed, _),) = simulate_flight("mission", 3, faults=["baro-rezero"]).records["EV"]
    assert armed == pytest.approx(10.0 - ARMING_LEAD_S, abs=0.02)
    clean = read_log(_write(tmp_path / "clean.bin", "mission", []))
    faulty = read_log(_write(tmp_path / "faulty.bin", "mission", ["baro-rezero"]))
    assert f"re-zeroed by the autopilot at {BOOT_S + armed:.1f} s" in faulty.notes[-1]
    (a,), (b,) = ([s for s in f.sensors if s.kind == "baro"] for f in (clean, faulty))
    moved = b.value - a.value
    after = b.t >= BOOT_S + armed
    np.testing.assert_array_equal(moved[after], 0.0)
    assert np.ptp(moved[~after]) < 1e-5  # one shift (float32), the step to its noise
    assert abs(moved[0]) < 0.1


def test_a_barometer_in_the_airflow_reads_high_as_the_square_of_the_airspeed(
    tmp_path: Path,
) -> None:
    """``baro-airflow``: 1 m higher at the mission's top airspeed, 7 m/s (k 0.40), as the
    square of the airspeed in a 2 m/s wind along the track (3 m/s out, 7 back, at one ground
    speed). The datum cannot tell the wind against this GPS (0.35 m noisy, wandering); the
    barometer's readings against the height smoothed without them tell it (1.8 m/s here,
    1.4-2.0 on seeds 0-2), and the smoother learns k (0.42) at that airspeed: 0.021 m RMSE,
    0.540 m at the ground speed, the best sensor 1.03 m."""
    clean = read_log(_write(tmp_path / "clean.bin", "mission", []))
    path = _write(tmp_path / "airflow.bin", "mission", ["baro-airflow"])
    faulty = read_log(path)
    speed, course = faulty.ground_speed, faulty.ground_course
    assert speed is not None
    assert course is not None
    baro = next(s for s in faulty.sensors if s.name == "baro")
    extra = baro.value - next(s for s in clean.sensors if s.name == "baro").value
    north = np.where(course.value == 180.0, -1.0, 1.0) * speed.value
    air = np.abs(np.interp(baro.t, speed.t, north) - BARO_AIRFLOW_WIND_M_S)
    assert extra.max() == pytest.approx(1.0, abs=0.02)
    assert np.corrcoef(extra, air**2)[0, 1] > 0.99
    evaluation = evaluate(path, ["smoother"], truth="sim")
    params = evaluation.runs["smoother"].result.params
    assert params["baro_dynamic"] == "modelled"
    assert params["baro_dynamic_speed"].startswith("the airspeed")
    assert "from 180 deg (north +1.8" in params["baro_dynamic_wind"]
    assert params["dynamic_pressure_baro"] == pytest.approx(BARO_AIRFLOW_M * 2 * G / 49, abs=0.1)
    rmse = {row.name: row.overall.rmse for row in evaluation.rows}
    assert rmse["smoother"] < 0.05


def test_the_gps_course_follows_the_mission_out_and_back() -> None:
    """GPS.GCrs: the mission's track runs north and back south, its course 0 then 180 deg
    where it flies (0 standing), lagging as the speed does."""
    flight = read_log(ROOT / "sample_logs" / "mission.bin")
    speed, course = flight.ground_speed, flight.ground_course
    assert speed is not None
    assert course is not None
    np.testing.assert_array_equal(course.t, speed.t)
    assert set(np.unique(course.value)) == {0.0, 180.0}
    flying = speed.value > 1.0
    turn = course.t[flying & (course.value == 180.0)][0]
    assert (course.value[flying & (course.t < turn)] == 0.0).all()
    assert (course.value[flying & (course.t >= turn)] == 180.0).all()
    assert turn - course.t[flying][0] == pytest.approx(85.0 / 2, abs=1.0)  # half of 85 s flown


def test_a_roll_flip_wraps_the_logged_roll_and_keeps_the_vertical_acceleration(
    tmp_path: Path,
) -> None:
    """One turn about the roll axis in 1 s, logged in [-180, 180) as ArduPilot logs it."""
    clean = read_log(_write(tmp_path / "clean.bin", "mission", []))
    flip = read_log(_write(tmp_path / "flip.bin", "mission", ["roll-flip"]))
    assert clean.attitude is not None
    assert clean.imu is not None
    assert flip.attitude is not None
    assert flip.imu is not None
    roll = np.rad2deg(flip.attitude.roll)
    assert roll.min() >= -180.0
    assert roll.max() < 180.0
    assert np.sum(np.abs(np.diff(roll)) > 180.0) == 1  # wrapped once, through +-180
    turned = np.unwrap(flip.attitude.roll) - np.unwrap(clean.attitude.roll)
    assert np.rad2deg(turned[-1]) == pytest.approx(360.0, abs=1e-3)
    # upside down the rangefinder sees the sky: out of range
    a, b = ({s.name: s for s in log.sensors}["rangefinder"] for log in (clean, flip))
    assert b.dropped["Stat != 4 (not Good)"] >= a.dropped.get("Stat != 4 (not Good)", 0) + 5
    # read back, the flip is the attitude it is: the vertical acceleration stays the clean
    # flight's but for the attitude's interpolation between its 10 Hz samples (0.4 m/s^2;
    # through 0 degrees instead of +-180, 17.7)
    _, a_clean = vertical_acceleration(clean.imu, clean.attitude)
    _, a_flip = vertical_acceleration(flip.imu, flip.attitude)
    assert np.abs(a_flip - a_clean).max() < 1.0


def test_a_spliced_log_has_nothing_logged_for_20_s_from_half_the_flight(tmp_path: Path) -> None:
    """Every record stops at 60 s of the mission's 120 and resumes at 80 s, the flight going
    on meanwhile: a log stopped and resumed."""
    path = _write(tmp_path / "spliced.bin", "mission", ["splice"])
    reader = mavutil.mavlink_connection(str(path))
    types = ["GPS", "BARO", "RFND", "IMU", "ATT", "SIM"]
    times: dict[str, list[float]] = {}
    try:
        while (msg := reader.recv_match(type=types)) is not None:
            times.setdefault(msg.get_type(), []).append(msg.TimeUS / 1e6 - BOOT_S)
    finally:
        reader.close()
    assert set(times) == set(types)
    for name, ts in times.items():
        t = np.array(ts)
        assert not ((t >= 60.0) & (t < 80.0)).any(), name
        assert (t < 60.0).any(), name
        assert t.max() > 110.0, name
        assert np.diff(t).max() == pytest.approx(20.0, abs=0.25), name


def test_every_sensor_lags_the_truth_by_the_flight_s_latency() -> None:
    """Drawn per flight from the seed: each sensor fits the truth best that far behind it (the
    barometer and the rangefinder in the climb's 18 m/s, where 1 ms is 2 cm), the GPS by its
    own lag besides."""
    flights = [simulate_flight("climb", seed) for seed in (0, 1, 2)]
    assert len({f.latency_s for f in flights}) == 3
    for flight in flights:
        assert LATENCY_S[0] <= flight.latency_s <= LATENCY_S[1]
        lag = flight.gps_lag_s - flight.latency_s
        assert GPS_LAG_S[0] <= lag <= GPS_LAG_S[1]
        p = flight.profile
        baro = np.array([(ts, row[1]) for ts, row in flight.records["BARO"]])
        temp = np.array([row[2] for _, row in flight.records["BARO"]])
        clean = baro[:, 1] - 0.12 * (temp - 25.0)  # the thermal drift, as simulated
        candidates = np.arange(0.0, 0.02, 0.0005)
        misfit = [
            np.mean((clean - np.interp(baro[:, 0] - lag, p.t, p.height_m)) ** 2)
            for lag in candidates
        ]
        assert candidates[int(np.argmin(misfit))] == pytest.approx(flight.latency_s, abs=0.002)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_gps_lag_drawn_is_the_one_altfuse_finds_in_the_log(tmp_path: Path, seed: int) -> None:
    """The GPS lags the other sensors by 0.1-0.25 s, drawn per flight: the pipeline's estimate
    (:func:`altfuse.align.gps_lags`, against the barometer) finds it."""
    flight = simulate_flight("climb", seed)
    write_simulated_log(flight, tmp_path / "climb.bin")
    lags = prepare(read_log(tmp_path / "climb.bin"), FuseOptions()).lags
    assert lags["gps"].lag_s == pytest.approx(flight.gps_lag_s - flight.latency_s, abs=0.03)


def test_a_hard_landing_falls_the_last_metre_bounces_and_clips_the_accelerometer() -> None:
    """The motors cut at 1 m on the last descent: free fall (the accelerometer reads no specific
    force), an impact at 4.2-4.5 m/s clipped at the IMU's 16 g, a bounce of RESTITUTION."""
    clean = simulate_flight("mission", 3)
    hard = simulate_flight("mission", 3, faults=("hard-landing",))
    t, h = hard.profile.t, hard.profile.height_m
    first = int(np.flatnonzero(h > DROP_M)[-1]) + 1
    touch = first + int(np.argmax(np.diff(h[first:]) > 0))  # the lowest tick: the impact
    impact = float(h[touch - 1] - h[touch]) / float(t[touch] - t[touch - 1])
    assert 4.0 < impact < 5.0  # sqrt(v0^2 + 2 g 1 m)
    bounce = h[touch:].max()
    assert bounce == pytest.approx((RESTITUTION * impact) ** 2 / (2 * G), rel=0.15)
    np.testing.assert_array_equal(h[:first], clean.profile.height_m[:first])
    assert h[-1] == 0.0
    # the log: one IMU sample pinned at the range on the impact, free fall just before it
    imu = np.array([(ts, *row[1:]) for ts, row in hard.records["IMU"]])
    pinned = np.isclose(imu[:, 3], -IMU_CLIP_M_S2)
    assert pinned.sum() >= 1
    assert t[touch] - 0.03 <= imu[pinned, 0].min() <= t[touch] + 0.03
    falling = (imu[:, 0] > t[first] + 0.1) & (imu[:, 0] < t[touch] - 0.05)
    assert np.abs(imu[falling, 3]).max() < 1.0  # 0 g, and the sensor's noise and bias
    # the truth logged is the flight flown
    sim = np.array([row[0] for _, row in hard.records["SIM"]]) - HOME_AMSL_M
    assert sim.min() >= -1e-9


@pytest.mark.parametrize(
    ("fault", "said"),
    [
        ("hard-landing", "hover does not land: hard-landing needs one of paper-a, mission, climb"),
        ("baro-airflow", "hover does not cruise: baro-airflow needs one of mission, climb"),
    ],
)
def test_a_fault_needs_a_scenario_that_can_have_it(fault: str, said: str, tmp_path: Path) -> None:
    result = CliRunner().invoke(
        cli, ["simulate", "hover", "-o", str(tmp_path / "h.bin"), "--fault", fault]
    )
    assert result.exit_code == 2
    assert said in result.output
    assert not (tmp_path / "h.bin").exists()


def _write(path: Path, scenario: str, faults: list[str]) -> Path:
    args = ["simulate", scenario, "-o", str(path), "--seed", "3"]
    for fault in faults:
        args += ["--fault", fault]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    return path


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["mission", "--duration", "5"], "--duration must be from 60 s (for mission) to 43200 s"),
        # 11.6 days (1e6 s) ran out of a 24 GB machine's memory, killed without a word
        (["hover", "--duration", "1e7"], "to 43200 s (12 hours), got 1e+07"),
        (["hover", "--duration", "inf"], "to 43200 s (12 hours), got inf"),  # was "at least"
        (["hover", "--duration", "nan"], "--duration must be from"),
        (["orbit"], "'orbit' is not one of"),
        (["hover", "--fault", "ice"], "'ice' is not one of"),
        (["hover", "--seed", "-1"], "'--seed': -1 is not in the range x>=0"),  # numpy's error
    ],
)
def test_nonsense_simulate_arguments(tmp_path: Path, args: list[str], fragment: str) -> None:
    out = tmp_path / "x.bin"
    result = CliRunner().invoke(cli, ["simulate", *args, "-o", str(out)])
    assert result.exit_code == 2
    assert fragment in result.stderr
    assert not out.exists()


def test_a_simulated_log_named_as_another_format_is_refused(tmp_path: Path) -> None:
    """``simulate -o hover.csv`` (or ``.ulg``, ``.log``: a text log's) wrote a binary DataFlash
    log that a batch's patterns pass over; refused, nothing written. Any case of ``.bin``, a
    compressed one and a name of no format are written."""
    for name in ("hover.csv", "hover.ulg", "hover.log", "hover.json.gz"):
        result = CliRunner().invoke(cli, ["simulate", "hover", "-o", str(tmp_path / name)])
        assert result.exit_code == 2
        suffix = Path(name.removesuffix(".gz")).suffix
        said = f"{tmp_path / name}: this is written as a DataFlash log, not as {suffix}: name it"
        assert result.stderr == f"altfuse: error: {said} .bin\n"
    assert not list(tmp_path.iterdir())
    flight = simulate_flight("hover", 0, duration_s=120.0)
    for name in ("a.BIN", "b.bin.xz", "c.dat"):
        assert write_simulated_log(flight, tmp_path / name) > 0
    with pytest.raises(ParameterError, match=r"this is written as a DataFlash log, not as \.ulg"):
        write_simulated_log(flight, tmp_path / "d.ulg")
