"""PX4 ULog input (issue 18): the reader against pyulog's decoding, every shared ULog fused or
refused in one line, the simulator's truth checked before it is used."""

from __future__ import annotations

import gzip
import io
import re
import struct
import subprocess
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from pyulog import ULog

from accuracy import verdict
from altfuse.cli import cli
from altfuse.errors import NoUsableSensorsError
from altfuse.evaluation import evaluate, evaluate_prepared
from altfuse.io import read_log, ulog
from altfuse.io.ulog import TOPICS, pressure_altitude
from altfuse.model import Attitude, Series
from altfuse.pipeline import FuseOptions, fuse_log, prepare, run_method
from altfuse.screen import NOT_CONVERGED
from conftest import SAMPLE_LOG, shared_log
from variants import variant

#: Every ULog in ../shared/logs/px4 and what ``altfuse fuse`` makes of it: ok (with the warning
#: line it must print, if any) or refused (with the reason's words).
OUTCOMES = {
    "px4_sitl_stifael_14_19_29.ulg": ("ok", None),
    "px4_sitl_yuneec_parameterchange.ulg": ("ok", None),
    "px4_sitl_yuneec_position.ulg": ("ok", None),
    "px4ulogrs_6ba1abc7-b433-4029-b8f5-3b2bb12d3b6c.ulg": ("ok", None),
    "px4ulogrs_corrupt_actuator_armed_wrong_size.ulg": ("refused", "1 usable altitude source"),
    "px4ulogrs_corrupt_unregistered_msg_id.ulg": ("ok", "corrupt: pyulog skipped the data"),
    "px4ulogrs_esc_status_log.ulg": ("ok", None),
    "px4ulogrs_quadrotor_local.ulg": ("refused", "926 fix_type < 3"),
    "pyulog_sample_appended_multiple.ulg": ("refused", "1 usable altitude source (baro)"),
    "pyulog_sample_log_small.ulg": ("ok", "smoother's model check failed"),
    "pyulog_sample_logging_tagged_and_default_params.ulg": ("ok", None),
    "pyulog_sample_px4_events.ulg": ("ok", None),
}


def test_the_outcomes_name_every_shared_ulog() -> None:
    folder = shared_log("px4")
    assert sorted(p.name for p in folder.glob("*.ulg")) == sorted(OUTCOMES)


@pytest.mark.parametrize("name", sorted(OUTCOMES))
def test_every_shared_ulog_is_fused_or_refused_in_one_line(name: str, tmp_path: Path) -> None:
    log = shared_log(f"px4/{name}")
    outcome, words = OUTCOMES[name]
    result = CliRunner().invoke(cli, ["fuse", str(log), "-o", str(tmp_path / "out.csv")])
    lines = result.stderr.splitlines()
    if outcome == "refused":
        assert result.exit_code == 1
        assert len(lines) == 1
        assert lines[0].startswith("altfuse: error: ")
        assert words in lines[0]
        assert not list(tmp_path.iterdir())  # nothing half-written
        return
    assert result.exit_code == 0, result.output
    assert (tmp_path / "out.csv").exists()
    assert "Traceback" not in result.output
    assert "pyulog" not in result.stdout  # its prints do not reach standard output
    if words is None:
        assert lines == []
    else:
        assert len(lines) == 1
        assert lines[0].startswith("altfuse: warning: ")
        assert words in lines[0]


def _pyulog(log: Path) -> dict[str, list[dict[str, np.ndarray]]]:
    ulog = ULog(str(log), list(TOPICS))
    out: dict[str, list[dict[str, np.ndarray]]] = {}
    for d in sorted(ulog.data_list, key=lambda d: (d.name, d.multi_id)):
        out.setdefault(d.name, []).append(d.data)
    return out


def _raw(series: Series, topics: dict[str, list[dict[str, np.ndarray]]]) -> tuple[Any, Any]:
    """The pyulog arrays behind ``series``: its topic instance's times [us] and column."""
    match = re.match(r"(\w+)(?:\[(\d+)\])?\.(-?)(\w+(?:\[\d\])?)", series.source)
    assert match, series.source
    topic, k, _, column = match.groups()
    data = topics[topic][int(k or 0)]
    stamp = data["timestamp"].astype(np.float64)
    if "timestamp_sample" in data:
        stamp = np.where(data["timestamp_sample"] > 0, data["timestamp_sample"], stamp)
    return stamp, data[column]


PARITY_LOGS = [n for n, (outcome, _) in OUTCOMES.items() if outcome == "ok"]


@pytest.mark.parametrize("name", PARITY_LOGS)
def test_every_extracted_value_is_pyulog_s(name: str) -> None:
    """Acceptance 2: each sample of each source and reference is pyulog's value at pyulog's
    time (the reader's selection and units, and nothing else, in between)."""
    log = shared_log(f"px4/{name}")
    flight = read_log(log)
    topics = _pyulog(log)
    start = 0.0
    if any("Unix time" in note for note in flight.notes):
        start = ULog(str(log), ["vehicle_attitude"]).start_timestamp / 1e6
    checked = 0
    for series in (*flight.sensors, *flight.references):
        stamp, column = _raw(series, topics)
        if series.source.startswith("sensor_combined") or "standard atmosphere" in series.source:
            continue  # derived: checked below
        at = np.searchsorted(stamp / 1e6 - start, series.t)
        np.testing.assert_array_equal(stamp[at] / 1e6 - start, series.t)
        expected = column[at].astype(np.float64)
        if series.source.endswith(".alt") and series.kind == "gps":
            expected = expected / 1e3  # mm before PX4 v1.14
        if ".-" in series.source:
            expected = -expected
        np.testing.assert_array_equal(series.value, expected, err_msg=series.source)
        checked += 1
    assert checked >= 2
    imu = flight.imu
    assert imu is not None
    combined = topics["sensor_combined"][0]
    t = (combined["timestamp"] + combined["accelerometer_timestamp_relative"]) / 1e6 - start
    np.testing.assert_array_equal(imu.t, t)
    for i in range(3):
        np.testing.assert_array_equal(imu.acc[:, i], combined[f"accelerometer_m_s2[{i}]"])
    att = flight.attitude
    assert att is not None
    assert att.quaternion is not None
    q = np.column_stack([topics["vehicle_attitude"][0][f"q[{i}]"].astype(float) for i in range(4)])
    np.testing.assert_allclose(att.quaternion, q / np.linalg.norm(q, axis=1, keepdims=True))


@pytest.mark.parametrize("compressed", [False, True], ids=["plain", "gzip"])
def test_a_ulog_with_another_appended_is_read_up_to_the_other(
    tmp_path: Path, compressed: bool
) -> None:
    """Two ULogs joined in one file: pyulog read on into the second's messages as damage, its
    barometer samples behind the first's time dropped as out of order (1,988 of them) and the
    fused height 561 m off. The first is read as from its own file, and where the second
    begins is said: by its byte where the file is the log itself."""
    first = shared_log("px4/px4_sitl_yuneec_position.ulg")
    joined = first.read_bytes() + shared_log("px4/px4_sitl_yuneec_parameterchange.ulg").read_bytes()
    path = tmp_path / ("joined.ulg.gz" if compressed else "joined.ulg")
    path.write_bytes(gzip.compress(joined) if compressed else joined)
    flight, alone = read_log(path), read_log(first)
    size = first.stat().st_size
    where = "" if compressed else f" from byte {size:,} ({len(joined) - size:,} bytes)"
    how = "split the file where it begins" if compressed else "cut the file there"
    said = f"another log is appended{where}: the first alone is read; to fuse the other, {how}"
    assert flight.damaged == (said,)
    assert said in flight.notes
    assert flight.record_counts == alone.record_counts
    for ours, its in zip(flight.sensors, alone.sensors, strict=True):
        np.testing.assert_array_equal(ours.value, its.value)


def test_another_ulog_s_header_is_found_across_the_chunks_read(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    header = b"ULog\x01\x12\x35"
    data = header + b"x" * 100 + header + b"y" * 50
    for chunk in range(1, 130):
        monkeypatch.setattr(ulog, "_SEARCH_CHUNK", chunk)
        handle = io.BytesIO(data)
        assert ulog._appended_at(handle) == 107
        assert handle.tell() == 0
    assert ulog._appended_at(io.BytesIO(header + b"x" * 100)) is None


def test_a_pressure_becomes_the_standard_atmosphere_s_height() -> None:
    """sensor_baro's pressure (PX4 v1.12 on) as PX4's own baro_alt_meter with its default
    sea-level pressure: 101325 Pa is 0 m, 89875 Pa about 1000 m."""
    np.testing.assert_allclose(
        pressure_altitude(np.array([101325.0, 89874.6])), [0, 1000], atol=0.5
    )


def test_the_quaternion_gives_the_euler_angles_down_row() -> None:
    """The rotation's last row from the quaternion equals the Euler angles' (ZYX), and
    interpolating across the quaternion's sign flip (q and -q: one rotation) stays on it."""
    rng = np.random.default_rng(3)
    roll, pitch, yaw = rng.uniform(-3, 3, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-3, 3, 50)
    cr, sr, cp, sp, cy, sy = (f(a / 2) for a in (roll, pitch, yaw) for f in (np.cos, np.sin))
    q = np.column_stack([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                         cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])  # fmt: skip
    t = np.arange(50.0)
    euler = Attitude("ATT", t, roll, pitch, yaw)
    quaternion = Attitude(
        "q", t, roll, pitch, yaw, quaternion=q * np.sign(rng.normal(size=(50, 1)))
    )
    np.testing.assert_allclose(quaternion.down_at(t), euler.down_at(t), atol=1e-12)
    # level, then the same attitude written as -q: halfway is level, not a half-turn
    level = np.array([[1.0, 0, 0, 0], [-1.0, 0, 0, 0]])
    flipped = Attitude("q", np.array([0.0, 1.0]), np.zeros(2), np.zeros(2), np.zeros(2), level)
    np.testing.assert_allclose(flipped.down_at(np.array([0.5])), [[0, 0, 1]], atol=1e-12)


def test_a_truth_that_moves_against_the_sensors_is_refused() -> None:
    """Acceptance 3's check: PX4 v1.7.3 and v1.8.0's simulator groundtruth climbs when the vehicle
    descends (Gazebo's sign error of 2018); it is not the truth. The v1.9 log's is."""
    inverted = shared_log("px4/px4_sitl_yuneec_parameterchange.ulg")
    with pytest.raises(NoUsableSensorsError, match=r"correlation -1\.00.*opposite"):
        evaluate(inverted, ["mean"], truth="sim")
    fallback = evaluate(inverted, ["mean"])
    assert fallback.truth.name == "ekf"
    assert fallback.truth.is_reference
    assert "refused as truth" in fallback.truth.label
    good = evaluate(shared_log("px4/px4_sitl_yuneec_position.ulg"), ["smoother"], truth="sim")
    assert good.truth.source == "vehicle_global_position_groundtruth.alt"
    assert not good.truth.refused
    smoother = next(r for r in good.rows if r.name == "smoother")
    ekf = next(r for r in good.rows if r.kind == "onboard")
    assert smoother.overall.rmse < 0.02 < ekf.overall.rmse


def test_a_truth_that_stays_constant_where_the_sensors_move_is_refused_as_such() -> None:
    """A PX4 simulator log standing on the ground, its groundtruth altitude constant, with
    its barometer 1 m higher from half-way (``step-baro``): the sensors' median moves, and the
    truth is refused with what it does (the correlation was "+nan")."""
    stepped = variant(
        read_log(shared_log("px4/px4ulogrs_6ba1abc7-b433-4029-b8f5-3b2bb12d3b6c.ulg")), "step-baro"
    )
    with pytest.raises(NoUsableSensorsError) as refused:
        evaluate_prepared(prepare(stepped, FuseOptions()), ["mean"], truth="sim")
    assert str(refused.value).endswith(
        "vehicle_global_position_groundtruth.alt refused as truth: its heights stay constant "
        "where the sensors' median moves (standard deviation 0.25 m)"
    )


def test_a_batch_takes_dataflash_and_ulog_together(tmp_path: Path) -> None:
    """Acceptance 4: the default pattern takes .bin and .ulg into one summary."""
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "mission.bin").write_bytes(SAMPLE_LOG.read_bytes())
    ulog = shared_log("px4/px4ulogrs_esc_status_log.ulg")
    (logs / "px4.ULG").write_bytes(ulog.read_bytes())
    result = CliRunner().invoke(cli, ["batch", str(logs), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    summary = (tmp_path / "out" / "summary.csv").read_text()
    assert "mission.bin,ok" in summary
    assert "px4.ULG,ok" in summary
    assert "PX4 v1.9.0-beta" in summary
    assert (tmp_path / "out" / "px4.csv").exists()


def test_a_truncated_or_broken_ulog_is_one_line(tmp_path: Path) -> None:
    source = shared_log("px4/px4ulogrs_esc_status_log.ulg").read_bytes()
    for size, words in ((10, "not a readable ULog file"), (3000, "no usable altitude source")):
        cut = tmp_path / f"cut{size}.ulg"
        cut.write_bytes(source[:size])
        result = CliRunner().invoke(cli, ["fuse", str(cut), "-o", str(tmp_path / "x.csv")])
        assert result.exit_code == 1
        assert result.stderr.count("\n") == 1
        assert words in result.stderr
    half = tmp_path / "half.ulg"
    half.write_bytes(source[: len(source) // 2])
    result = CliRunner().invoke(cli, ["fuse", str(half), "-o", str(tmp_path / "half.csv")])
    assert result.exit_code == 0, result.output  # read up to the cut
    assert half.read_bytes() == source[: len(source) // 2]  # the input untouched


def test_damage_that_sends_pyulog_back_without_end_is_one_line(tmp_path: Path) -> None:
    """A message claiming 10,240 bytes 3 bytes before the end: pyulog steps back by the
    length it asked for, not by what it read, 10 kB before where it began, and reads the same
    zeros again without end (damaged logs of the fuzz: over 300 s). Run apart, so that the
    old reader fails the test rather than hanging the suite."""
    header = b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0)
    log = tmp_path / "loops.ulg"
    log.write_bytes(header + bytes(12_000) + bytes([0x00, 0x28, 0x00]))
    out = tmp_path / "x.csv"
    command = [sys.executable, "-m", "altfuse", "fuse", str(log), "-o", str(out)]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 1
    assert done.stderr == (
        f"altfuse: error: {log}: not a readable ULog file (pyulog's reading of its damage did "
        "not end: it stepped back from the file's end 16 times)\n"
    )
    assert not out.exists()


def test_a_log_with_no_take_off_knows_its_datum() -> None:
    """A PX4 simulator log standing on the ground (no take-off: referred to its first seconds)
    had fused_std 0.70 m for errors of 1 cm: the offsets took the 1 m prior of a datum the
    flight says nothing about, where the datum is defined on those seconds."""
    run = fuse_log(shared_log("px4/px4ulogrs_6ba1abc7-b433-4029-b8f5-3b2bb12d3b6c.ulg"))
    assert "no take-off found" in run.referred.offsets[0].method
    sigma = run.result.tick_traces["fused_std"]
    assert 0.005 < np.nanmedian(sigma) < 0.05


def test_the_gps_course_is_its_velocity_s_direction() -> None:
    """PX4 logs the GPS's velocity north and east: the course over ground is their direction
    [deg from north], on the samples the speed is read from."""
    path = shared_log("px4/px4_sitl_yuneec_position.ulg")
    flight = read_log(path)
    speed, course = flight.ground_speed, flight.ground_course
    assert speed is not None
    assert course is not None
    np.testing.assert_array_equal(course.t, speed.t)
    (gps,) = [d for d in ULog(str(path), ["vehicle_gps_position"]).data_list if d.multi_id == 0]
    north, east = gps.data["vel_n_m_s"], gps.data["vel_e_m_s"]
    expected = np.degrees(np.arctan2(east, north)) % 360.0
    at = np.searchsorted(gps.data["timestamp"] / 1e6, course.t - 1e-7)
    np.testing.assert_allclose(course.value, expected[at], atol=1e-4)
    assert (speed.value > 1.0).sum() > 40  # 47 samples moving: the course tells there


@pytest.mark.parametrize(
    ("name", "bound"),
    [
        ("px4ulogrs_6ba1abc7-b433-4029-b8f5-3b2bb12d3b6c.ulg", 0.004),
        ("pyulog_sample_logging_tagged_and_default_params.ulg", 0.009),
    ],
)
def test_the_land_detector_holds_a_vehicle_on_the_ground_still(name: str, bound: float) -> None:
    """PX4's vehicle_land_detected says the simulator's vehicle stood on the ground throughout:
    the smoother holds v = 0 over the whole verdict, which never turns, where the
    accelerometer alone let the height wander 1-2 cm. Held 2 s in from each end of the
    verdict as from a turn, the 11 s log's height sloped 4 cm in its first seconds: RMSE
    against the groundtruth 0.0066 and 0.0129 m (the EKF's 0.0088 and 0.0106); 0.0021 and
    0.0067 held throughout."""
    path = shared_log(f"px4/{name}")
    landed = read_log(path).landed
    assert landed is not None
    assert landed.source == "vehicle_land_detected.landed"
    assert landed.value.min() == 1.0
    result = evaluate(path, ["smoother"], truth="sim")
    params = result.runs["smoother"].result.params
    span = float(landed.t[-1] - landed.t[0])
    assert params["landed_held_s"] == pytest.approx(span, abs=0.3)
    rmse = {r.name: r.overall.rmse for r in result.rows}
    assert rmse["smoother"] < min(bound, rmse["ekf"])
    held = result.runs["smoother"].result.tick_traces["velocity"][20:-20]
    free = run_method(prepare(replace(read_log(path), landed=None), FuseOptions()), FuseOptions())
    loose = free.result.tick_traces["velocity"][20:-20]
    assert np.std(held) < 0.5 * np.std(loose)


def test_a_gps_is_read_from_its_first_epv_of_a_converged_fix(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """As for DataFlash logs (GPA.VAcc): a receiver's samples until its first ``epv`` within
    GPS_CONVERGED_VACC_M are dropped, counted, its velocities too. The log's receiver reports
    0.7-0.8 m from its first fix on; its first ten reports are made 12 m here."""

    def settling(name: str, data: dict[str, np.ndarray]) -> None:
        if name == "vehicle_gps_position":  # the log's one receiver
            data["epv"] = data["epv"].copy()
            data["epv"][:10] = 12.0

    log = shared_log("px4/px4ulogrs_esc_status_log.ulg")
    plain = read_log(log)
    _patched(monkeypatch, settling)
    settled = read_log(log)
    before = next(s for s in plain.sensors if s.kind == "gps")
    after = next(s for s in settled.sensors if s.kind == "gps")
    assert after.dropped == {**before.dropped, NOT_CONVERGED: 10}
    np.testing.assert_array_equal(after.t, before.t[10:])
    for speeds in ("vertical_velocity", "ground_speed", "ground_course"):
        was, now = getattr(plain, speeds), getattr(settled, speeds)
        np.testing.assert_array_equal(now.t, was.t[was.t >= after.t[0]])


def test_a_distance_sensor_not_facing_down_is_left_out_and_said(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The log's one distance sensor made to face forward (orientation 0, obstacle avoidance):
    no rangefinder, and the reason in the dropped sources (it was left out in silence)."""

    def forward(name: str, data: dict[str, np.ndarray]) -> None:
        if name == "distance_sensor":
            data["orientation"] = np.zeros_like(data["orientation"])

    log = shared_log("px4/px4ulogrs_esc_status_log.ulg")
    assert "rangefinder" in {s.kind for s in read_log(log).sensors}
    _patched(monkeypatch, forward)
    flight = read_log(log)
    assert "rangefinder" not in {s.kind for s in flight.sensors}
    assert flight.dropped_sources["distance_sensor[0]"] == (
        "distance_sensor[0].current_distance: orientation [0], not 25 (facing down): no height"
    )


def _patched(
    monkeypatch: pytest.MonkeyPatch, change: Callable[[str, dict[str, np.ndarray]], object]
) -> None:
    """The reader's decoding (pyulog's, whole or along the compiled walk: ``ulog._parsed``)
    made to pass each topic's name and columns through ``change`` (in place)."""
    parsed = ulog._parsed

    def changed(*args: Any) -> tuple[Any, list[str]]:
        decoded, printed = parsed(*args)
        for d in decoded.data_list:
            change(d.name, d.data)
        return decoded, printed

    monkeypatch.setattr(ulog, "_parsed", changed)


def _failing_over(monkeypatch: pytest.MonkeyPatch, at: float, step_m: float) -> None:
    """``vehicle_air_data`` failed over to another barometer at the share ``at`` of its
    samples' span, ``step_m`` higher from there (``baro_device_id`` one more; a log from
    before PX4 v1.11 given the column, device 7)."""

    def change(name: str, data: dict[str, np.ndarray]) -> None:
        if name == "vehicle_air_data":
            t = data["timestamp"]
            after = t > t[0] + at * (t[-1] - t[0])
            data["baro_alt_meter"] = data["baro_alt_meter"] + step_m * after
            device = data.get("baro_device_id", np.full(t.size, 7, dtype=np.uint32))
            data["baro_device_id"] = np.where(after, device + 1, device)

    _patched(monkeypatch, change)


def test_each_barometer_px4_fails_over_to_is_its_own(monkeypatch: pytest.MonkeyPatch) -> None:
    """``vehicle_air_data`` from two devices: two barometers, each with its own samples and
    the device (and calibration) in its source, and a note of the change."""
    log = shared_log("px4/pyulog_sample_px4_events.ulg")
    plain = next(s for s in read_log(log).sensors if s.kind == "baro")
    _failing_over(monkeypatch, 0.6, 0.5)
    flight = read_log(log)
    baros = [s for s in flight.sensors if s.kind == "baro"]
    assert [s.name for s in baros] == ["baro", "baro2"]
    first, second = baros
    assert first.source.endswith("(baro_device_id 6620172, calibration_count 0)")
    assert second.source.endswith("(baro_device_id 6620173, calibration_count 0)")
    np.testing.assert_array_equal(np.concatenate([first.t, second.t]), plain.t)
    np.testing.assert_allclose(first.value, plain.value[: first.t.size])
    np.testing.assert_allclose(second.value, plain.value[first.t.size :] + 0.5, atol=1e-5)
    assert set(flight.temperatures) == {"baro", "baro2"}
    assert (
        "vehicle_air_data: the barometer or its calibration changed 1 time (baro_device_id "
        "6620172, calibration_count 0; baro_device_id 6620173, calibration_count 0): each read "
        "as its own barometer"
    ) in flight.notes


def test_a_barometer_failover_s_step_is_not_followed(monkeypatch: pytest.MonkeyPatch) -> None:
    """A PX4 simulator flight whose barometer fails over at 70 % of the log to one 0.3 m
    higher, under STEP_SIGMAS beside its GPS: read as one barometer, the smoother followed it
    (RMSE 0.161 m, maximum 0.31, against the GPS's 0.015); each device its own, 0.010 m."""
    _failing_over(monkeypatch, 0.7, 0.3)
    result = evaluate(shared_log("px4/px4_sitl_yuneec_position.ulg"), ["smoother"], truth="sim")
    v = verdict(result, "smoother")
    assert {"rmse", "max"}.isdisjoint(v["fails"])  # type: ignore[arg-type]
    assert v["rmse"] < 0.02  # type: ignore[operator]


def test_a_barometer_device_changing_at_every_sample_is_damage(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A ``baro_device_id`` different at every sample is no vehicle's: one barometer, as
    logged, and a note (each its own would be 623 sensors to fuse)."""

    def scrambled(name: str, data: dict[str, np.ndarray]) -> None:
        if name == "vehicle_air_data":
            data["baro_device_id"] = np.arange(data["timestamp"].size, dtype=np.uint32)

    log = shared_log("px4/pyulog_sample_px4_events.ulg")
    plain = read_log(log)
    _patched(monkeypatch, scrambled)
    flight = read_log(log)
    assert [s.name for s in flight.sensors] == [s.name for s in plain.sensors]
    assert (
        "vehicle_air_data: 623 barometers or calibrations, more than 8: damage, read as one "
        "barometer" in flight.notes
    )


def test_the_barometer_with_most_samples_keeps_the_name(monkeypatch: pytest.MonkeyPatch) -> None:
    """Three first samples logged with ``baro_device_id`` 0 (before the device was set up) are
    a barometer of their own, ``baro2``; the log's main one stays ``baro`` and the reference
    (it was ``baro2``, and its CSV column ``alt_baro2_m``)."""

    def early(name: str, data: dict[str, np.ndarray]) -> None:
        if name == "vehicle_air_data":
            data["baro_device_id"] = data["baro_device_id"].copy()
            data["baro_device_id"][:3] = 0

    _patched(monkeypatch, early)
    flight = read_log(shared_log("px4/pyulog_sample_px4_events.ulg"))
    baros = {s.name: s for s in flight.sensors if s.kind == "baro"}
    assert {name: s.t.size for name, s in baros.items()} == {"baro": 620, "baro2": 3}
    assert "baro_device_id 6620172" in baros["baro"].source
    assert prepare(flight, FuseOptions()).referred.reference == "baro"


def test_a_barometer_calibrated_to_the_gnss_on_the_ground_is_no_take_off(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """PX4's GNSS-baro calibration (``SENS_BAR_AUTOCAL``, on by default) moves the barometer's
    offset to the GNSS altitude on the ground, ``calibration_count`` one more: 30 m at 12 s
    here, with no land detector logged. Read as one barometer, that step was the take-off
    (12.0 s, where the vehicle leaves the ground at 20.4 s); each calibration its own, the
    take-off and the fused heights are the log's as logged."""

    def calibrated(name: str, data: dict[str, np.ndarray]) -> None:
        data.pop("landed", None)  # vehicle_land_detected's
        if name == "vehicle_air_data":
            after = (data["timestamp"] - data["timestamp"][0]) / 1e6 > 12.0
            data["baro_alt_meter"] = data["baro_alt_meter"] + 30.0 * after
            data["calibration_count"] = data["calibration_count"] + after

    log = shared_log("px4/pyulog_sample_px4_events.ulg")
    unmodified = fuse_log(log, FuseOptions())
    _patched(monkeypatch, calibrated)
    calibrated_run = fuse_log(log, FuseOptions())
    assert calibrated_run.referred.takeoff_s == pytest.approx(20.4, abs=0.3)
    assert calibrated_run.referred.names == ("gps", "baro", "baro2")
    n = min(calibrated_run.result.fused.size, unmodified.result.fused.size)
    fused = calibrated_run.result.fused[:n]
    assert np.nanmax(np.abs(fused - unmodified.result.fused[:n])) < 0.1


def test_an_old_log_s_barometer_without_its_temperature_is_read(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """PX4 before v1.7 logs its barometer in ``sensor_combined``; with the temperature's column
    gone (a bit flipped in its format's name: ``tests/fuzz_long.py``, seed 18) the read ended
    in an internal error (KeyError). The barometer is read, without a temperature."""
    log = shared_log("px4/pyulog_sample_appended_multiple.ulg")
    assert "baro" in read_log(log).temperatures

    def lost(name: str, data: dict[str, np.ndarray]) -> None:
        if name == "sensor_combined":
            del data["baro_temp_celcius"]

    _patched(monkeypatch, lost)
    flight = read_log(log)
    (baro,) = (s for s in flight.sensors if s.kind == "baro")
    assert baro.source == "sensor_combined.baro_alt_meter"
    assert baro.t.size > 100
    assert "baro" not in flight.temperatures
