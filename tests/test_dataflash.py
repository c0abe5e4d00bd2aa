"""The DataFlash reader: parity with pymavlink's own decoding, units, and odd logs."""

from __future__ import annotations

import bz2
import gzip
import hashlib
import importlib
import io
import itertools
import lzma
import os
import pty
import re
import subprocess
import sys
import threading
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from pymavlink import mavutil

from altfuse.cli import cli
from altfuse.errors import LogReadError
from altfuse.evaluation import evaluate
from altfuse.io import dataflash, read_log
from altfuse.io.dataflash import RESET_MAX, _Records, rejoined
from altfuse.io.dataflash_writer import DataFlashWriter
from altfuse.io.fastdf import index_file
from altfuse.model import FEW_IN_A_ROW, NO_TIME, FloatArray, Samples, Series, usable_series
from altfuse.screen import GPS_CONVERGED_VACC_M, NOT_CONVERGED, not_converged
from altfuse.simulate import simulate_flight, write_simulated_log
from conftest import SAMPLE_LOG, shared_log

PARITY_LOGS = [
    "ardupilot/beastayyg_log_0039_mechanical_failure.bin",
    "ardupilot/diaven_sample01.bin",
    "ardupilot/rima48_test_cascade.BIN",
    "ardupilot/spark404_log.bin",
    "ardupilot/pfcFlightData_center_0003.bin",
]


def pymavlink_records(path: Path, type_name: str, field: str) -> dict[float, list[float]]:
    """TimeUS/1e6 -> values of ``type_name.field`` as pymavlink decodes them, with FMTU scale."""
    conn = mavutil.mavlink_connection(str(path))
    out: dict[float, list[float]] = {}
    try:
        while (msg := conn.recv_match(type=type_name)) is not None:
            out.setdefault(msg.TimeUS / 1e6, []).append(float(getattr(msg, field)))
    finally:
        conn.close()
    return out


def resolve(path: Path | str) -> Path:
    return SAMPLE_LOG if path == "sample" else shared_log(str(path))


@pytest.mark.parametrize("log", [*PARITY_LOGS, "sample"])
def test_every_extracted_value_equals_pymavlink(log: str) -> None:
    path = resolve(log)
    flight = read_log(path)
    assert flight.sensors
    for s in flight.sensors:
        type_name, field = s.source.split(".")
        ref = pymavlink_records(path, type_name, field)
        scale = 0.01 if (type_name, log) == ("RFND", "sample") else 1.0  # FMTU multiplier B
        # kept + dropped are this instance's records: all of them unless the type is shared
        n_records = sum(len(v) for v in ref.values())
        assert len(s.t) + sum(s.dropped.values()) <= n_records
        for t, v in zip(s.t, s.value, strict=True):
            assert t in ref, f"{s.source}: no pymavlink record at {t}"
            assert any(v == pytest.approx(x * scale, rel=1e-12, abs=1e-12) for x in ref[t])
    if flight.imu is not None:
        ref = pymavlink_records(path, "IMU", "AccZ")
        for t, v in zip(flight.imu.t, flight.imu.acc[:, 2], strict=True):
            assert v in ref[t]
    if flight.attitude is not None:
        ref = pymavlink_records(path, "ATT", "Roll")
        for t, v in zip(flight.attitude.t, flight.attitude.roll, strict=True):
            assert np.rad2deg(v) == pytest.approx(ref[t][0], rel=1e-12)


def test_record_counts_match_pymavlink() -> None:
    path = shared_log("ardupilot/beastayyg_log_0039_mechanical_failure.bin")
    flight = read_log(path)
    for type_name in ("GPS", "BARO", "CTUN", "IMU", "ATT", "NKF1"):
        ref = pymavlink_records(path, type_name, "TimeUS")
        assert flight.record_counts[type_name] == sum(len(v) for v in ref.values())
    sources = {s.name: s for s in flight.sensors}
    assert set(sources) == {"gps", "baro", "rangefinder"}
    assert sources["rangefinder"].source == "CTUN.SAlt"
    assert len(sources["gps"].t) == 478
    assert len(sources["baro"].t) == 955
    assert flight.vehicle == "copter"
    assert flight.firmware == "APM:Copter V3.4.6"
    assert {r.name for r in flight.references} == {"ekf", "ahrs2", "pos", "ctun"}


def test_simulated_log_reads_back_what_was_written(tmp_path: Path) -> None:
    sim = simulate_flight("mission", seed=3, duration_s=60.0)
    path = tmp_path / "sim.bin"
    write_simulated_log(sim, path)
    flight = read_log(path)
    sources = {s.name: s for s in flight.sensors}
    rfnd = sim.records["RFND"]
    runs = [list(run) for _, run in itertools.groupby(rfnd, key=lambda r: r[1][2] == 4)]
    # Good (Stat 4), in runs of three or more but for the log's first and last
    good = [
        (t, v[1])
        for i, run in enumerate(runs)
        if run[0][1][2] == 4 and (len(run) >= 3 or i in (0, len(runs) - 1))
        for t, v in run
    ]
    # RFND.Dist is an int16 in centimetres with FMTU multiplier B: the reader gives metres
    np.testing.assert_allclose(sources["rangefinder"].value, [v / 100 for _, v in good], rtol=1e-12)
    # GPS.Alt is 'e' (int32 centimetres): written and read back to the centimetre
    gps = [v[8] for _, v in sim.records["GPS"] if v[1] >= 3]
    np.testing.assert_allclose(sources["gps"].value, gps, atol=0.005 + 1e-9)
    assert sources["gps"].dropped == {"GPS Status < 3 (no 3D fix)": 15}
    truth = {r.name: r for r in flight.references}["sim"]
    assert truth.t.size == 600
    assert flight.skipped_bytes == 0


def test_the_blended_gps_instance_is_not_a_sensor(tmp_path: Path) -> None:
    """Blending receivers (GPS_AUTO_SWITCH 2), ArduPilot 4.1+ logs their blend as GPS instance
    2: read as a third GPS it was fused beside the two it averages. Left out, and said."""
    sim = simulate_flight("mission", seed=3, duration_s=60.0)
    gps = sim.records["GPS"]
    second = [(t, (1, *v[1:8], v[8] + 0.4, *v[9:])) for t, v in gps]
    blend = [(t, (2, *v[1:8], v[8] + 0.2, *v[9:])) for t, v in gps]
    path = tmp_path / "blended.bin"
    write_simulated_log(replace(sim, records={**sim.records, "GPS": gps + second + blend}), path)
    flight = read_log(path)
    assert [s.name for s in flight.sensors if s.kind == "gps"] == ["gps", "gps2"]
    assert flight.dropped_sources["gps3"] == (
        "GPS[2].Alt: not fused: the blend of the receivers (GPS_AUTO_SWITCH 2), not a sensor of "
        "its own"
    )


def test_a_rangefinder_not_facing_down_is_not_an_altitude(tmp_path: Path) -> None:
    """A second rangefinder facing forward (obstacle avoidance: Orient 0, Good, a wall 5 m
    ahead) was fused as a height; PX4's ULog reader already kept only downward ones."""
    sim = simulate_flight("mission", seed=3, duration_s=60.0)
    down = sim.records["RFND"]
    ahead = [(t, (1, 500, 4, 0)) for t, _ in down]
    path = tmp_path / "avoidance.bin"
    write_simulated_log(replace(sim, records={**sim.records, "RFND": down + ahead}), path)
    flight = read_log(path)
    assert [s.name for s in flight.sensors if s.kind == "rangefinder"] == ["rangefinder"]
    assert flight.dropped_sources["rangefinder2"] == (
        f"RFND.Dist: no usable sample ({len(ahead)} Orient != 25 (not facing down))"
    )


@pytest.mark.parametrize(
    ("distance", "units"), [("DistCM", None), ("Dist", None), ("Dist", ("sm------", "CB------"))]
)
def test_a_planes_sonar_distance_is_read_in_metres(
    tmp_path: Path, distance: str, units: tuple[str, str] | None
) -> None:
    """Plane logs its sonar's distance in centimetres, as a float: FMTU's multiplier says so
    where logged; before FMTU (Plane 3.3's DistCM, then Dist) nothing did, and 5 m read 500."""
    path = tmp_path / "sonar.bin"
    with path.open("wb") as handle:
        writer = DataFlashWriter(handle)
        columns = f"TimeMS,{distance},Volt,BaroAlt,GSpd,Thr,Cnt,Corr"
        writer.define("SONR", "IffffBBf", columns, *(units or (None, None)))
        for k in range(50):
            writer.write("SONR", 1000 + 100 * k, 500.0, 4.9, 0.0, 0.0, 0, 1, 1.0)
    (sonar,) = read_log(path).sensors
    assert sonar.kind == "rangefinder"
    np.testing.assert_allclose(sonar.value, 5.0)


def test_reading_a_damaged_log_prints_nothing(capfd: pytest.CaptureFixture[str]) -> None:
    flight = read_log(shared_log("ardupilot/rima48_test_cascade.BIN"))
    out, err = capfd.readouterr()
    assert out == ""
    assert err == ""
    # read off a flash chip: ~50 KB of erased flash after its last record, not damage
    assert flight.skipped_bytes == 0
    assert flight.notes[-1] == (
        "the log ends in 50723 bytes of erased flash (0xFF) after its last record: read off a "
        "flash chip"
    )


@pytest.mark.parametrize(
    ("tail", "skipped", "note"),
    [
        (b"\xa3", 0, "the log ends inside its last record (1 byte of its header)"),
        (b"\xa3\x95", 0, "the log ends inside its last record (2 bytes of its header)"),
        (b"\xa3\x95\x80" + bytes(40), 0, "the log ends inside its last record (FMT, 43 of its 89"),
        (b"\x00", 1, "1 byte not part of any decodable record"),
        (b"\xa3\x00\xa3", 3, "3 bytes not part of any decodable record"),
        (b"\xff" * 4096, 0, "the log ends in 4096 bytes of erased flash (0xFF) after its last"),
        (b"\xff" * 4095 + b"\x00", 4096, "4096 bytes not part of any decodable record"),
        (b"\xa3\x95\x80" + b"\xff" * 100, 0, "the log ends in 14 bytes of erased flash (0xFF)"),
    ],
    ids=["header-1", "header-2", "record", "zero", "no-record", "erased", "not-erased", "cut"],
)
def test_a_log_that_ends_inside_a_record_has_no_skipped_bytes(
    tmp_path: Path, tail: bytes, skipped: int, note: str
) -> None:
    """Nearly every real log ends inside a record, where the autopilot stopped writing (15 of
    the 20 shared ArduPilot logs, 4-40 bytes): a note, not skipped bytes, which warned on each.
    So is a log read off a flash chip, which ends in erased flash (0xFF), its last record filled
    by it where writing stopped mid-record (a record to pymavlink, and so here). Bytes that
    begin no record are still skipped."""
    path = tmp_path / "cut.bin"
    path.write_bytes(SAMPLE_LOG.read_bytes() + tail)
    flight = read_log(path)
    assert flight.skipped_bytes == skipped
    assert flight.notes[-1].startswith(note)
    assert [s.value.size for s in flight.sensors] == [
        s.value.size for s in read_log(SAMPLE_LOG).sensors
    ]


@pytest.mark.parametrize("appended", [["hover.bin"], ["mission.bin", "hover.bin"]])
def test_a_log_with_another_appended_is_read_up_to_the_other(
    tmp_path: Path, appended: list[str]
) -> None:
    """Two logs joined in one file (``cat a.bin b.bin``): the second's clock starts again at its
    own boot. Its samples behind the first's latest time were dropped as out of order, and the
    rest spliced on: mission.bin with hover.bin after it fused 14,326 samples dropped as
    implausible and 60 s of hover after the mission, 425 ticks flagged 50.9 m off. The first
    is read alone, as from its own file, and the rest is said."""
    path = tmp_path / "joined.bin"
    path.write_bytes(
        b"".join((SAMPLE_LOG.parent / n).read_bytes() for n in ["mission.bin", *appended])
    )
    flight, alone = read_log(path), read_log(SAMPLE_LOG)
    first = SAMPLE_LOG.stat().st_size
    assert flight.damaged == (
        f"another log is appended from byte {first:,} ({path.stat().st_size - first:,} bytes; its "
        "clock starts again at 30.0 s, where this one's had reached 149.9 s): the first alone "
        "is read; to fuse the other, cut the file there",
    )
    assert flight.size_bytes == path.stat().st_size
    assert flight.skipped_bytes == 0
    assert flight.record_counts == alone.record_counts
    for ours, its in zip(flight.sensors, alone.sensors, strict=True):
        np.testing.assert_array_equal(ours.t, its.t)
        np.testing.assert_array_equal(ours.value, its.value)
    assert flight.notes[-1] == flight.damaged[0]  # in the sidecar and the batch's count too
    shown = CliRunner().invoke(cli, ["info", str(path)])
    assert f"\nnote: {flight.damaged[0]}" in shown.output


def test_a_decoded_log_with_another_appended_says_no_byte_of_its_file(tmp_path: Path) -> None:
    """Compressed (or a text log, converted), the joined logs' bytes are not the file's: the
    warning says where the other log begins by its clock alone."""
    path = tmp_path / "joined.bin.gz"
    joined = SAMPLE_LOG.read_bytes() + (SAMPLE_LOG.parent / "hover.bin").read_bytes()
    path.write_bytes(gzip.compress(joined))
    assert read_log(path).damaged == (
        "another log is appended (its clock starts again at 30.0 s, where this one's had "
        "reached 149.9 s): the first alone is read; to fuse the other, split the file where "
        "it begins",
    )


def test_a_time_field_declared_as_text_is_looked_at_for_another_log_as_read(
    tmp_path: Path,
) -> None:
    """The look for another log appended read a type's time field as it is stored: one
    declared as text (``n``, damage) raised TypeError, a traceback. It reads it as the reader
    does: no number, said."""
    path = tmp_path / "text_time.bin"
    with path.open("wb") as handle:
        writer = DataFlashWriter(handle)
        writer.define("GPS", "nBff", "TimeMS,Status,Alt,Spd", "s-m-", "F---")
        writer.define("BARO", "IffB", "TimeMS,Alt,Temp,Health", "sm--", "F---")
        for k in range(300):
            writer.write("BARO", 100_000 + 100 * k, 1.0, 30.0, 1)
            if k % 2 == 0:
                writer.write("GPS", b"abcd", 3, 100.0, 0.0)
    flight = read_log(path)
    assert [s.name for s in flight.sensors] == ["baro"]
    assert "GPS.TimeMS: not read: declared as text ('n'), not a number" in flight.notes
    assert flight.damaged == ()


def test_a_block_of_records_written_twice_is_no_other_log(tmp_path: Path) -> None:
    """24 s of a log's records written again after themselves fall back as an appended log's
    would, and stay behind for thousands of records; but no log's header (FMT) begins them:
    the log is read to its end."""
    index = index_file(SAMPLE_LOG)
    data = SAMPLE_LOG.read_bytes()
    lo, hi = (int(index.offsets[round(index.offsets.size * f)]) for f in (0.4, 0.6))
    path = tmp_path / "twice.bin"
    path.write_bytes(data[:hi] + data[lo:hi] + data[hi:])
    flight, alone = read_log(path), read_log(SAMPLE_LOG)
    assert flight.damaged == ()
    assert [s.t.max() for s in flight.sensors] == [s.t.max() for s in alone.sensors]


@pytest.mark.parametrize(
    ("records", "shift_s"),
    [(slice(300, 301), -50.0), (slice(300, 301), 3600.0), (slice(None), 100_000.0)],
    ids=["one-stamp-behind", "one-stamp-ahead", "another-time-base"],
)
def test_a_clock_falling_back_without_a_new_log_is_none(
    tmp_path: Path, records: slice, shift_s: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One GPS record stamped 50 s early (damage) falls back once, and the clock runs on; one
    an hour late leaves every later record behind it, but not behind those before it; a GPS
    whose every stamp is on another base (a time of week, 100,000 s ahead) puts every other
    type's next record behind it, but its own next record is not: no log begins there. Each is
    told by the records after the fall (RESTART_RECORDS) and, with one record alone, by each
    type's first after it."""
    index = index_file(SAMPLE_LOG)
    gps = next(t for t, f in index.formats.items() if f.name == "GPS")
    data = bytearray(SAMPLE_LOG.read_bytes())
    for record in index.offsets[index.types == gps][records].tolist():
        at = int(record) + 3  # its TimeUS, after the header
        stamp = int.from_bytes(data[at : at + 8], "little")
        data[at : at + 8] = (stamp + round(shift_s * 1e6)).to_bytes(8, "little")
    path = tmp_path / "stamps.bin"
    path.write_bytes(bytes(data))
    for _ in range(2):
        flight = read_log(path)
        assert flight.damaged == ()
        assert flight.record_counts == read_log(SAMPLE_LOG).record_counts
        monkeypatch.setattr(dataflash, "RESTART_RECORDS", 1)


def test_a_rangefinder_s_valid_readings_count_in_runs_of_three() -> None:
    bad = np.array([0, 0, 1, 0, 1, 0, 0, 1, 0, 0, 0, 1, 0], dtype=bool)
    t = np.arange(bad.size) * 0.1
    samples = Samples(t, 1.0 + t)
    invalid = {"Stat != 4 (not Good)": bad}
    rangefinder = usable_series("rangefinder", "rangefinder", "RFND.Dist", "", samples, invalid)
    assert isinstance(rangefinder, Series)
    # a lone valid reading and a pair go; a run of three stays, and so do the runs the log
    # begins and ends with (they may go on beyond it)
    np.testing.assert_array_equal(rangefinder.t, t[[0, 1, 8, 9, 10, 12]])
    assert rangefinder.dropped == {"Stat != 4 (not Good)": 4, FEW_IN_A_ROW: 3}
    baro = usable_series("baro", "baro", "BARO.Alt", "", samples, invalid)
    assert isinstance(baro, Series)
    assert baro.t.size == 9


def test_a_real_log_s_last_record_cut_is_a_note() -> None:
    solo = read_log(shared_log("truth/copter_3.4dev-solo_djnugent_climb154m_ekf1.BIN"))
    assert solo.skipped_bytes == 0
    assert solo.notes[-1] == (
        "the log ends inside its last record (IMU2, 17 of its 45 bytes): read up to the one before"
    )


def test_ctun_fallbacks_and_multi_instance_gps() -> None:
    flight = read_log(shared_log("ardupilot/diaven_sample01.bin"))
    sources = {s.name: s for s in flight.sensors}
    assert set(sources) == {"gps", "gps2", "baro", "rangefinder"}
    assert sources["baro"].source == "CTUN.BAlt"
    assert sources["rangefinder"].source == "RFND.Dist"
    assert sources["gps"].dropped == {"GPS Status < 3 (no 3D fix)": 43, NOT_CONVERGED: 7}
    assert any("CTUN.BAlt" in note for note in flight.notes)


def test_the_gps_course_is_read_beside_its_speed() -> None:
    """GPS.GCrs [deg] of the records GPS.Spd is read from (the first receiver, a 3D fix), as
    pymavlink decodes them: the ground velocity's direction for the barometer's airspeed."""
    path = shared_log("ardupilot/spark404_log.bin")
    flight = read_log(path)
    speed, course = flight.ground_speed, flight.ground_course
    assert speed is not None
    assert course is not None
    assert course.source == "GPS.GCrs"
    np.testing.assert_array_equal(course.t, speed.t)
    logged = pymavlink_records(path, "GPS", "GCrs")
    np.testing.assert_allclose(course.value, [logged[round(t, 6)][0] for t in course.t])
    assert 0.0 <= course.value.min() < course.value.max() <= 360.0


def test_a_gps_is_read_from_when_its_receiver_first_reports_a_converged_fix() -> None:
    """The log starts as its GPS gets a 3D fix: GPA.VAcc 12.5 m, 7.5 m 2.2 s later. Its
    samples (and speeds) until then are dropped, counted; the rest are kept, poorer reports
    later included."""
    path = shared_log("ardupilot/diaven_sample01.bin")
    flight = read_log(path)
    gps = next(s for s in flight.sensors if s.name == "gps")
    accuracy = pymavlink_records(path, "GPA", "VAcc")
    times = np.array(sorted(accuracy))
    vacc = np.array([accuracy[t][0] for t in times])  # the first instance's record first
    converged = times[np.argmax(vacc <= GPS_CONVERGED_VACC_M)]
    assert vacc[0] > 12.0
    assert converged - times[0] == pytest.approx(2.2, abs=0.1)
    assert gps.t[0] == converged
    assert flight.vertical_velocity is not None
    assert flight.vertical_velocity.t[0] >= converged


def test_not_yet_converged_is_between_the_first_report_and_the_first_good_one() -> None:
    t = np.array([1.0, 2.0, 3.0, 4.0])
    at = np.array([0.5, 1.0, 2.5, 3.0, 9.0])
    np.testing.assert_array_equal(
        not_converged(t, np.array([0.0, 12.0, 7.5, 20.0]), at), [False, False, True, False, False]
    )  # before any report: unknown, kept; a report of 0: unknown; later poor ones: kept
    never = not_converged(t, np.full(4, 9.0), at)
    assert not never.any()  # a receiver poor all flight is not dropped


def test_ardusub_baro_instances() -> None:
    flight = read_log(shared_log("ardupilot/ardusubtools_small.BIN"))
    assert flight.vehicle == "sub"
    assert [s.name for s in flight.sensors] == ["baro", "baro2"]


def test_an_ardusub_log_without_its_firmware_text_is_known_by_its_parameters(
    tmp_path: Path,
) -> None:
    """Its MSG and VER types renamed (as if its head were cut): still a Sub (SURFACE_DEPTH),
    whose BARO is water depth; it was an aircraft of unknown kind."""
    data = shared_log("ardupilot/ardusubtools_small.BIN").read_bytes()
    for name, other in ((b"MSG", b"MSX"), (b"VER", b"VEX")):  # in their FMT records
        fmt = re.compile(rb"(\xa3\x95\x80..)" + name + rb"\x00", re.DOTALL)
        data = fmt.sub(lambda m, other=other: m.group(1) + other + b"\x00", data)
    path = tmp_path / "sub.bin"
    path.write_bytes(data)
    flight = read_log(path)
    assert (flight.vehicle, flight.firmware) == ("sub", "unknown")


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "empty"),
        (b"time,alt\n1,2\n", "not a DataFlash log"),
        (b"ULog\x01\x12\x35" + bytes(2), "not a readable ULog file"),  # its header cut short
    ],
)
def test_not_a_log(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "x.bin"
    path.write_bytes(content)
    with pytest.raises(LogReadError, match=message):
        read_log(path)


@pytest.mark.parametrize(("version", "signed"), [("v10", False), ("v20", False), ("v20", True)])
def test_a_telemetry_log_is_named_as_one(tmp_path: Path, version: str, signed: bool) -> None:
    """A ground station's recording (``.tlog``: MAVLink packets, each after its time) is what
    a user finds first on the laptop; said so, with what to fuse instead, not 'not a log'."""
    dialect = importlib.import_module(f"pymavlink.dialects.{version}.ardupilotmega")
    mav = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    if signed:
        mav.signing.secret_key, mav.signing.sign_outgoing = bytes(32), True
    packets = [
        dialect.MAVLink_heartbeat_message(2, 3, 81, 4, 4, 3),
        dialect.MAVLink_global_position_int_message(1000, 1, 2, 584_270, 1500, 0, 0, -3, 0),
        dialect.MAVLink_vfr_hud_message(0.0, 0.0, 0, 40, 584.27, -0.03),
        dialect.MAVLink_heartbeat_message(2, 3, 81, 4, 4, 3),
    ]
    path = tmp_path / "flight.tlog"
    path.write_bytes(
        b"".join(
            int(1_733_400_000e6 + k * 1e5).to_bytes(8, "big") + message.pack(mav)
            for k, message in enumerate(packets)
        )
    )
    reader = mavutil.mavlink_connection(str(path))  # pymavlink reads it as a .tlog
    assert [m.get_type() for m in iter(reader.recv_msg, None)] == [
        "HEARTBEAT", "GLOBAL_POSITION_INT", "VFR_HUD", "HEARTBEAT"
    ]  # fmt: skip
    reader.close()
    with pytest.raises(LogReadError, match=r"flight.tlog: a MAVLink telemetry log \(.tlog"):
        read_log(path)
    path.write_bytes(b"\xfe" + path.read_bytes()[1:])  # no time before the packet
    with pytest.raises(LogReadError, match="not a DataFlash log"):
        read_log(path)


def test_an_archive_is_named_as_one_with_what_it_holds(tmp_path: Path) -> None:
    """A fleet's logs come zipped from a cloud or a ground station: a zip, 7z, rar or tar
    archive is refused as such, a zip naming its files, not as 'not a log'; a batch that finds
    no log but zips says so."""
    import tarfile
    import zipfile

    zipped = tmp_path / "logs" / "flights.zip"
    zipped.parent.mkdir()
    with zipfile.ZipFile(zipped, "w") as archive:
        for name in ("00000001.BIN", "00000002.BIN", "00000003.BIN", "00000004.BIN"):
            archive.write(SAMPLE_LOG, name)
    with pytest.raises(LogReadError, match=re.escape(
        "flights.zip: a zip archive of 4 files (00000001.BIN, 00000002.BIN, 00000003.BIN and "
        "1 more), not a log: extract the log from it"
    )):  # fmt: skip
        read_log(zipped)
    tarred = tmp_path / "flight.tar"
    with tarfile.open(tarred, "w") as archive:
        archive.add(shared_log("px4/px4_sitl_yuneec_position.ulg"), "flight.ulg")
    with pytest.raises(LogReadError, match=r"flight\.tar: a tar archive, not a log"):
        read_log(tarred)
    seven = tmp_path / "flight.7z"
    seven.write_bytes(b"7z\xbc\xaf\x27\x1c" + bytes(100))
    with pytest.raises(LogReadError, match=r"flight\.7z: a 7z archive, not a log"):
        read_log(seven)
    batch = subprocess.run(
        [sys.executable, "-m", "altfuse", "batch", str(zipped.parent), "-o", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert batch.returncode == 1
    assert "; 1 *.zip there: extract the logs from them" in batch.stderr


@pytest.mark.parametrize(("suffix", "pack"), [(".gz", gzip.compress), (".bz2", bz2.compress),
                                               (".xz", lzma.compress)])  # fmt: skip
def test_a_compressed_log_reads_as_the_log_it_holds(
    tmp_path: Path, suffix: str, pack: Callable[[bytes], bytes]
) -> None:
    """Fleets keep logs compressed (``flight.bin.gz``): read as the log within (its heights
    the same to the bit), described as the file given (its name, size and sha256), noted."""
    packed = tmp_path / f"mission.bin{suffix}"
    packed.write_bytes(pack(SAMPLE_LOG.read_bytes()))
    plain, flight = read_log(SAMPLE_LOG), read_log(packed)
    for a, b in zip(plain.sensors, flight.sensors, strict=True):
        assert a.name == b.name
        np.testing.assert_array_equal(a.value, b.value)
        np.testing.assert_array_equal(a.t, b.t)
    assert flight.path == str(packed)
    assert flight.size_bytes == packed.stat().st_size
    assert flight.sha256 == hashlib.sha256(packed.read_bytes()).hexdigest()
    assert any("compression" in note for note in flight.notes)


def test_a_compressed_log_cut_short_is_read_up_to_the_cut(tmp_path: Path) -> None:
    """As a log cut short is (its last whole record), with the damage said; a stream that
    gives nothing is not a log."""
    whole = gzip.compress(SAMPLE_LOG.read_bytes())
    cut = tmp_path / "cut.bin.gz"
    cut.write_bytes(whole[: len(whole) // 3])
    flight = read_log(cut)
    assert 0 < flight.sensors[0].t.size < read_log(SAMPLE_LOG).sensors[0].t.size
    assert any("its gzip compression cut after" in line for line in flight.damaged)
    bad = tmp_path / "bad.bin.gz"
    bad.write_bytes(b"\x1f\x8b" + bytes(100))
    with pytest.raises(LogReadError, match="cannot read its gzip compression"):
        read_log(bad)


def test_a_piped_log_reads_as_the_log_it_carries(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A log that flows in (``altfuse fuse - < x``, ``<(zcat x.gz)``, a named pipe; "not a
    file" before) is copied and read: its heights bit for bit, its size and sha256 the bytes
    that came; errors name the path given, never the copy."""
    data = SAMPLE_LOG.read_bytes()
    plain = read_log(SAMPLE_LOG)
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    writer = threading.Thread(target=fifo.write_bytes, args=(gzip.compress(data),), daemon=True)
    writer.start()
    piped = read_log(fifo)
    writer.join(timeout=30)
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data)))
    stdin = read_log("-")
    for flight in (piped, stdin):
        np.testing.assert_array_equal(flight.sensors[0].value, plain.sensors[0].value)
    assert stdin.path == "-"
    assert (stdin.sha256, stdin.size_bytes) == (hashlib.sha256(data).hexdigest(), len(data))
    assert piped.path == str(fifo)
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(b"")))
    with pytest.raises(LogReadError, match=r"^-: nothing came from standard input$"):
        read_log("-")
    with pytest.raises(LogReadError, match=r"^/dev/null: nothing came from a device$"):
        read_log("/dev/null")  # "from a pipe" before
    packed = tmp_path / "text.bin.gz"
    packed.write_bytes(gzip.compress(b"not a log"))
    with pytest.raises(LogReadError, match=f"^{re.escape(str(packed))}: not a DataFlash log"):
        read_log(packed)


def test_a_terminal_is_no_log(tmp_path: Path) -> None:
    """``altfuse fuse - -o f.csv`` typed without a pipe waited for a log to be typed, as if the
    command hung; a terminal given by name (``/dev/tty``) did the same. A closed standard
    input is said too."""
    master, terminal = pty.openpty()
    try:
        for log, stdin in (("-", terminal), (os.ttyname(terminal), subprocess.DEVNULL)):
            ran = subprocess.run(
                [sys.executable, "-m", "altfuse", "fuse", log, "-o", str(tmp_path / "f.csv")],
                stdin=stdin, capture_output=True, text=True, timeout=120, check=False,
            )  # fmt: skip
            assert (ran.returncode, ran.stderr) == (
                1,
                f"altfuse: error: {log}: a terminal, not a log; pipe one in "
                "(altfuse fuse - -o f.csv < flight.bin)\n",
            )
    finally:
        os.close(master)
        os.close(terminal)
    closed = subprocess.run(
        f"'{sys.executable}' -m altfuse fuse - -o '{tmp_path / 'f.csv'}' <&-",
        shell=True, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert (closed.returncode, closed.stderr) == (
        1,
        "altfuse: error: -: standard input is closed; pipe a log in\n",
    )  # an internal error before: sys.stdin is None
    assert not (tmp_path / "f.csv").exists()


class _Zeros(io.RawIOBase):
    """An endless stream of zeros (``/dev/zero``), counting what is read of it (1 GB at most:
    a reader that took it all would fill a disk)."""

    def __init__(self) -> None:
        self.given = 0

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        size = min(len(buffer), 10**9 - self.given)
        buffer[:size] = bytes(size)
        self.given += size
        return size


def test_a_stream_that_is_no_log_is_refused_from_its_first_bytes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``altfuse fuse /dev/zero`` (or a pipe of junk) is refused as a file of junk is, from its
    first bytes, without copying the rest: the copy would have filled the disk."""
    zeros = _Zeros()
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BufferedReader(zeros)))
    with pytest.raises(LogReadError, match=r"^-: not a DataFlash log"):
        read_log("-")
    assert zeros.given <= 4 << 20


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(LogReadError, match="no such file"):
        read_log(tmp_path / "nope.bin")


def test_the_land_detector_is_read_from_stat() -> None:
    """ArduPilot's Plane and QuadPlane log their own verdict, STAT.isFlying: the quadplane
    stands armed on the ground for 6 s of STAT records, then flies to the log's end."""
    path = shared_log("truth/quadplane_4.6.0dev_yakupabaci_climb65m.BIN")
    landed = read_log(path).landed
    assert landed is not None
    assert landed.source == "STAT.isFlying == 0"
    m = mavutil.mavlink_connection(str(path))
    flying = []
    try:
        while (msg := m.recv_match(type="STAT")) is not None:
            flying.append(msg.isFlying)
    finally:
        m.close()
    np.testing.assert_array_equal(landed.value, 1.0 - np.array(flying, dtype=float))
    assert landed.value[0] == 1.0
    assert landed.value[-1] == 0.0


@pytest.mark.parametrize(
    "log",
    [
        "ardupilot/diaven_sample01.bin",  # EV with its own TimeUS (Copter 4.0)
        "truth/copter_3.4dev-solo_djnugent_climb154m_ekf1.BIN",  # EV with its Id alone
    ],
)
def test_copters_take_offs_are_read_from_its_land_detectors_events(log: str) -> None:
    """Copter logs no state of its land detector, only its changes: NOT_LANDED (``EV`` 28)
    when it says the vehicle left the ground; in Copter 3.4 the record has no time, and is
    timed by its place among the records around it: within 50 ms of the time of the record
    before it, which pymavlink's reader gives it."""
    path = shared_log(log)
    m = mavutil.mavlink_connection(str(path))
    said, clock = [], 0.0
    try:
        while (msg := m.recv_match()) is not None:
            fields = msg.get_fieldnames()
            if "TimeUS" in fields:
                clock = msg.TimeUS / 1e6
            elif "TimeMS" in fields and msg.get_type() != "GPS":
                clock = msg.TimeMS / 1e3
            if msg.get_type() == "EV" and msg.Id == 28:
                said.append(clock)
    finally:
        m.close()
    takeoffs = read_log(path).takeoffs
    assert len(takeoffs) == len(said) >= 1
    np.testing.assert_allclose(takeoffs, said, atol=0.05)


def _standing_baro(level_before: float, at: float, lagging: int = 0) -> Series:
    """A barometer at 10 Hz on the ground for 20 s, reading ``level_before`` until ``at`` [s]
    (and ``lagging`` samples after it) and 0 from then on, with 5 cm of noise."""
    rng = np.random.default_rng(4)
    t = 100.0 + np.arange(200) / 10.0
    old = t < at
    old[np.flatnonzero(~old)[:lagging]] = True
    value = np.where(old, level_before, 0.0) + rng.normal(0.0, 0.05, t.size)
    return Series("baro", "baro", "BARO.Alt", "baro calibration", t, value)


def test_a_barometer_re_zeroed_at_arming_is_rejoined_across_its_step() -> None:
    """Copter arming without a home re-zeroes its barometers (EV EKF_ALT_RESET): the ground
    before it read 2.4 m higher, a whole flight off where the datum's window held it. Its
    earlier samples are moved by the step, a sample after the event still on the old zero
    with them."""
    s = _standing_baro(2.4, 110.0, lagging=1)
    out, notes = rejoined(s, (110.0,))
    np.testing.assert_array_equal(out.value[s.t > 110.1], s.value[s.t > 110.1])
    assert abs(np.median(out.value[s.t < 110.0])) < 0.05  # on the new zero
    assert abs(out.value[np.flatnonzero(s.t >= 110.0)[0]]) < 0.2  # the lagging sample too
    assert np.ptp(out.value - s.value) == pytest.approx(2.4, abs=0.05)
    step = (out.value - s.value)[0]
    assert notes == [
        "baro: re-zeroed by the autopilot at 110.0 s (EV EKF_ALT_RESET): 101 samples before "
        f"it moved by its step, {step:+.2f} m"
    ]


def test_a_reset_s_step_is_measured_on_the_ground_before_an_early_take_off() -> None:
    """An auto take-off climbs at 2 m/s from 0.6 s after arming: the level after the reset was
    a median over the climb's first second, 0.4 m high (the ground before it as much low);
    with the land detector's take-off it ends there."""
    s = _standing_baro(2.4, 110.0)
    climbing = s.t > 110.6
    s = replace(s, value=s.value + np.where(climbing, 2.0 * (s.t - 110.6), 0.0))
    out, _ = rejoined(s, (110.0,), takeoffs=(105.0, 110.6))
    assert abs(np.median(out.value[s.t < 109.8])) < 0.05
    early, _ = rejoined(s, (110.0,))
    assert np.median(early.value[s.t < 109.8]) > 0.2
    # the detector's verdict inside the margin: the first three samples after it, not none
    # (the 2.4 m step was left whole)
    soon, notes = rejoined(s, (110.0,), takeoffs=(110.25,))
    assert abs(np.median(soon.value[s.t < 109.8])) < 0.1
    assert len(notes) == 1


@pytest.mark.parametrize(
    ("level", "resets"),
    [
        (0.0, (110.0,)),  # logged where the EKF kept its datum (a rangefinder its height)
        (2.4, (100.05,)),  # too few samples before it to tell a level
        (2.4, ()),
    ],
)
def test_a_barometer_is_left_as_read_where_no_step_is_told(
    level: float, resets: tuple[float, ...]
) -> None:
    s = _standing_baro(level, resets[0] if resets else 110.0)
    out, notes = rejoined(s, resets)
    np.testing.assert_array_equal(out.value, s.value)
    assert notes == []


def test_the_heights_an_arming_reset_zeroes_are_read_continuous(tmp_path: Path) -> None:
    """A log with ``EV`` 60 (EKF_ALT_RESET) at 110 s: BARO.Alt and XKF1.PD step there on the
    ground, POS.Alt (above sea level: the EKF's origin moves to keep it) does not. Read, the
    first two are continuous, the third as logged; each step said in the notes."""
    path = tmp_path / "rezero.bin"
    with path.open("wb") as handle:
        writer = DataFlashWriter(handle)
        writer.define("BARO", "QBffB", "TimeUS,I,Alt,Temp,Health", "s#mO-", "F-00-")
        writer.define("XKF1", "QBf", "TimeUS,C,PD", "s#m", "F-0")
        writer.define("POS", "Qf", "TimeUS,Alt", "sm", "F0")
        writer.define("EV", "QB", "TimeUS,Id", "s-", "F-")
        for k in range(200):  # 20 s at 10 Hz, on the ground
            t = 100.0 + k / 10.0
            drift = 1.5 if t < 110.0 else 0.0
            us = round(t * 1e6)
            writer.write("BARO", us, 0, drift + 0.01 * (k % 3), 30.0, 1)
            writer.write("XKF1", us, 0, -drift - 0.01 * (k % 2))
            writer.write("POS", us, 584.0 + 0.01 * (k % 2))
            if k == 100:
                writer.write("EV", us - 5_000, 60)
    flight = read_log(path)
    (baro,) = flight.sensors
    refs = {r.name: r for r in flight.references}
    assert np.ptp(baro.value) < 0.05
    assert np.ptp(refs["ekf"].value) < 0.05
    assert np.ptp(refs["pos"].value) == pytest.approx(0.01, abs=1e-4)
    said = [n for n in flight.notes if "re-zeroed by the autopilot at 110.0 s" in n]
    assert [n.split(":")[0] for n in said] == ["baro", "ekf"]
    assert "by its step, -1.50 m" in said[0]


def test_a_log_with_more_resets_than_armings_reads_its_barometers_as_logged(
    tmp_path: Path,
) -> None:
    """Each reset is a pass over every barometer sample: 100 k of them in a hostile log would
    read for minutes. Past RESET_MAX the events are not used, and the notes say so."""
    path = tmp_path / "resets.bin"
    with path.open("wb") as handle:
        writer = DataFlashWriter(handle)
        writer.define("BARO", "QBffB", "TimeUS,I,Alt,Temp,Health", "s#mO-", "F-00-")
        writer.define("EV", "QB", "TimeUS,Id", "s-", "F-")
        for k in range(400):  # 40 s at 10 Hz, a 1.5 m step at 20 s
            us = round((100.0 + k / 10.0) * 1e6)
            writer.write("BARO", us, 0, 1.5 if k < 200 else 0.0, 30.0, 1)
            if k < RESET_MAX + 1:
                writer.write("EV", us + (0 if k else 20_000_000), 60)  # the first at 120 s
    flight = read_log(path)
    (baro,) = flight.sensors
    assert np.ptp(baro.value) == pytest.approx(1.5)
    assert any(f"{RESET_MAX + 1} events, more than the {RESET_MAX}" in n for n in flight.notes)


def test_records_read_again_once_let_go_are_the_same() -> None:
    # the reader lets each type's records go once read (a 300 MB log's: 92 MB at once); one
    # read again is gathered again, not lost
    rec = _Records(index_file(SAMPLE_LOG))
    before = rec.column("BARO", "Alt").copy(), rec.times("BARO").copy()
    rec.done("BARO")
    assert "BARO" not in rec._tables
    assert not any(key[0] == "BARO" for key in rec._raw)
    np.testing.assert_array_equal(rec.column("BARO", "Alt"), before[0])
    np.testing.assert_array_equal(rec.times("BARO"), before[1])


#: The FMT lines of Copter 3.0 and 3.1 logs (ArduPilot's LogAnalyzer examples
#: ``underpowered.log``, 3.0.1, and ``mechanical_fail.log``, 3.1): times only in GPS records
#: (3.0: ``Time``, the GPS time of week; 3.1: ``T``, since boot) and 3.1's IMU records.
_INAV_FMT = "FMT, 17, 37, INAV, cccfffiiff, BAlt,IAlt,IClb,ACorrX,ACorrY,ACorrZ,GLat,GLng,ILat,ILng"
_OLD_COPTER_FMT = {
    "3.0": [
        _INAV_FMT,
        "FMT, 130, 35, GPS, BIBcLLeeEe, Status,Time,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs",
        "FMT, 4, 25, CTUN, hcefhhhhh, ThrIn,SonAlt,BarAlt,WPAlt,NavThr,AngBst,CRate,ThrOut,DCRate",
    ],
    "3.1": [
        _INAV_FMT,
        "FMT, 130, 45, GPS, BIHBcLLeeEefI, "
        "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T",
        "FMT, 131, 31, IMU, Iffffff, TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ",
        "FMT, 4, 25, CTUN, hcefchhhh, "
        "ThrIn,SonAlt,BarAlt,WPAlt,DesSonAlt,AngBst,CRate,ThrOut,DCRate",
    ],
}


def _old_copter_log(path: Path, version: str, start_ms: int) -> FloatArray:
    """A text log as Copter ``version`` writes it: 60 s at a 50 Hz loop from ``start_ms``, a
    climb to 10 m from 20 s; GPS at 5 Hz, CTUN (the barometer) at 10 Hz, each followed by INAV
    (the onboard estimate), neither with a time of its own, 3.1's IMU at 50 Hz. Returns the
    CTUN records' true times [s]."""
    lines = ["FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format", *_OLD_COPTER_FMT[version]]
    lines.append(f"MSG, ArduCopter V{version}.1")
    ctun = []
    for k in range(3000):
        ms = start_ms + 20 * k
        height = float(np.clip((k - 1000) / 50.0, 0.0, 10.0))
        if version == "3.1":
            lines.append(f"IMU, {ms}, 0, 0, 0, 0, 0, -9.81")
        inav = f"INAV, 0, {height:.2f}, 0, 0, 0, 0, 0, 0, 0, 0"
        if k % 10 == 5 or (version == "3.0" and k < 10 and k % 5 == 0):
            ctun.append(ms / 1e3)  # 3.0: two records before the first GPS record, untimed
            lines += [f"CTUN, 0, 0, {height:.2f}, 0, 0, 0, 0, 0, 0", inav]
        if k % 10 == 9:
            times = f"{ms % 604_800_000}" if version == "3.0" else f"{ms + 300}, 1774"
            lines.append(
                f"GPS, 3, {times}, 9, 1.2, -39.49, 176.75, {height:.2f}, {50 + height:.2f}, "
                "0, 0" + ("" if version == "3.0" else f", 0, {ms}")
            )
        elif version == "3.1" and k % 10 == 4:
            lines += [f"CTUN, 0, 0, {height:.2f}, 0, 0, 0, 0, 0, 0", inav]
            ctun.append(ms / 1e3)
    path.write_text("\n".join(lines) + "\n")
    return np.asarray(ctun)


@pytest.mark.parametrize(
    ("version", "start_ms", "before_clock"),
    [("3.1", 60_000, 0), ("3.0", 604_800_000 - 30_000, 2)],  # 3.0: across a GPS week's end
)
def test_records_without_times_of_their_own_are_timed_by_their_place_among_those_with(
    tmp_path: Path, version: str, start_ms: int, before_clock: int
) -> None:
    """Copter up to 3.1 logs times in GPS and IMU records alone (3.0: the GPS time of week,
    nothing since boot): its barometer, in CTUN, is timed by each record's place between the
    timed records around it, to within the interval between those (20 ms with 3.1's IMU,
    200 ms with 3.0's GPS alone), across the end of a GPS week; a record before the first
    timed one has no time, and is counted so."""
    truth = _old_copter_log(tmp_path / "old.log", version, start_ms)
    log = read_log(tmp_path / "old.log")
    baro = next(s for s in log.sensors if s.source == "CTUN.BarAlt")
    assert baro.dropped == ({NO_TIME: before_clock} if before_clock else {})
    clock_s = 0.02 if version == "3.1" else 0.2
    np.testing.assert_allclose(baro.t, truth[before_clock:], atol=clock_s)
    assert np.all(np.diff(baro.t) > 0)
    gps = next(s for s in log.sensors if s.kind == "gps")
    assert np.all(np.diff(gps.t) == pytest.approx(0.2))  # 3.0: on from 604800 s, one week on
    said = " ".join(log.notes)
    assert "CTUN, INAV: no time of their own in this firmware" in said
    assert ("times are GPS.Time, the GPS time of week: this firmware logs no time" in said) == (
        version == "3.0"
    )


def test_an_old_copters_inertial_navigation_is_its_onboard_estimate(tmp_path: Path) -> None:
    """Copter up to 3.1 logs no EKF: its onboard height is INAV.IAlt (above home), read as a
    reference and measured against where the log has no better."""
    _old_copter_log(tmp_path / "old.log", "3.1", 60_000)
    (inav,) = read_log(tmp_path / "old.log").references
    assert (inav.name, inav.source, inav.datum) == (
        "inav",
        "INAV.IAlt",
        "home (inertial navigation)",
    )
    assert np.ptp(inav.value) == pytest.approx(10.0)
    report = evaluate(tmp_path / "old.log", ["support"])
    assert report.truth.source == "INAV.IAlt"
    assert report.rows[0].overall.rmse < 0.1


def test_a_gps_time_of_0_times_nothing(tmp_path: Path) -> None:
    """A receiver without a fix knows no time of week (``GPS.Time`` 0): in a Copter 3.0 log
    the records before its first known time have none, rather than times spread from 0 to
    that time (so spread, they were dropped as "time far outside the log", and warned of as
    implausible)."""
    truth = _old_copter_log(tmp_path / "old.log", "3.0", 604_800_000 - 30_000)
    lines = (tmp_path / "old.log").read_text().splitlines()
    unknown = [k for k, line in enumerate(lines) if line.startswith("GPS")][:20]
    for k in unknown:
        fields = lines[k].split(", ")
        lines[k] = ", ".join([fields[0], "1", "0", *fields[3:]])
    (tmp_path / "nofix.log").write_text("\n".join(lines) + "\n")
    baro = next(s for s in read_log(tmp_path / "nofix.log").sensors if s.kind == "baro")
    # the 21st GPS record, the first with a time, is the loop's 209th (every 10th from the 9th)
    timed = int(np.sum(truth > truth[0] + 209 * 0.02))
    assert baro.dropped == {NO_TIME: truth.size - timed}
    np.testing.assert_allclose(baro.t, truth[-timed:], atol=0.2)


def test_a_log_with_no_time_in_any_record_says_so(tmp_path: Path) -> None:
    """A log whose records have no time (Copter 3.0's without a GPS record) is refused, and
    not as a log without sensors."""
    _old_copter_log(tmp_path / "old.log", "3.0", 0)
    text = (tmp_path / "old.log").read_text().splitlines()
    (tmp_path / "untimed.log").write_text("\n".join(x for x in text if not x.startswith("GPS")))
    log = read_log(tmp_path / "untimed.log")
    assert log.sensors == ()
    assert log.dropped_sources == {"CTUN": "no time of its own, and no record in the log has one"}


def test_a_temperature_named_t_is_no_time(tmp_path: Path) -> None:
    """``T`` is a GPS record's time since boot in Copter 3.1-3.4, an IMU record's temperature
    [degC]: an IMU record without a time field takes the times around it, not its
    temperature's."""
    path = tmp_path / "imu_t.bin"
    with path.open("wb") as handle:
        writer = DataFlashWriter(handle)
        writer.define("BARO", "Qf", "TimeUS,Alt", "sm", "F0")
        writer.define("IMU", "ffff", "AccX,AccY,AccZ,T", "oooO", "0000")
        for k in range(100):
            writer.write("BARO", 10_000_000 + 20_000 * k, 0.0)
            writer.write("IMU", 0.0, 0.0, -9.81, 45.0)
    imu = read_log(path).imu
    assert imu is not None  # half-way between two BARO records; after the last, at its time
    np.testing.assert_allclose(imu.t, np.minimum(10.01 + 0.02 * np.arange(100), 11.98))
