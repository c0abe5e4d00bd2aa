"""PX4 ULog logs (``.ulg``): the same :class:`~altfuse.model.FlightLog` as a DataFlash log gives.

pyulog (PX4's own parser, BSD-3) decodes the file into numpy arrays per topic instance, as
pymavlink serves DataFlash: on an intact file with pyulog's own classes along a compiled walk
of its messages (:mod:`altfuse.io.fastulog`: a 296 MB log in 0.42 s where pyulog's loop takes
5.33 s), on any other by pyulog whole. This module picks the topics and turns them into
altfuse's sources (``tests/test_ulog.py`` checks every value against pyulog's decoding):

- **GPS**: ``vehicle_gps_position`` or ``sensor_gps``, whichever has more samples (one is the
  autopilot's selection of the other's receivers), every instance (``gps``, ``gps2``, ...):
  ``altitude_msl_m``, or ``alt`` [mm] before PX4 v1.14; samples with ``fix_type < 3`` dropped.
  Its ``vel_m_s`` is the horizontal speed, ``-vel_d_m_s`` (where ``vel_ned_valid``) the vertical
  velocity up.
- **Barometer**: ``vehicle_air_data.baro_alt_meter`` (``baro``), else every ``sensor_baro``
  instance: its ``altitude`` (PX4 before v1.8), else its ``pressure`` (Pa; mbar before v1.12)
  through the standard atmosphere; else (PX4 before v1.7) ``sensor_combined.baro_alt_meter``,
  each sample once. Its temperature beside it.
- **Rangefinder**: every downward-facing ``distance_sensor`` instance (``orientation`` 25, or no
  orientation field): ``current_distance``, less the samples outside ``min_distance`` ..
  ``max_distance`` or with ``signal_quality`` 0 (invalid; -1 is unknown and kept). A distance
  along the sensor's axis: the pipeline tilt-corrects it with the attitude.
- **IMU**: ``sensor_combined.accelerometer_m_s2`` (FRD), each sample at ``timestamp +
  accelerometer_timestamp_relative``. **Attitude**: ``vehicle_attitude.q`` (body FRD to NED),
  kept as the quaternion (:class:`~altfuse.model.Attitude`), Euler angles beside it.
- **References**: the EKF2 estimate as ``ekf`` (``vehicle_global_position.alt``, else
  ``-vehicle_local_position.z``), the simulator's ``vehicle_global_position_groundtruth.alt``
  (else ``-vehicle_local_position_groundtruth.z``) as ``sim``, the truth of
  :mod:`altfuse.evaluation` (which checks it against the sensors before using it).

Times: each topic's ``timestamp_sample`` where it has one (the sensor's own sample time), else
``timestamp`` [us since boot]. A corrupt file (pyulog's ``file_corruption``: data it could not
parse, skipped) is read as far as pyulog recovers, with a note; logging dropouts are noted too.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from importlib.metadata import version
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from altfuse.errors import LogReadError
from altfuse.io import ULOG_MAGIC, appended_log
from altfuse.io.fastulog import decode
from altfuse.model import (
    DOWNWARD,
    Attitude,
    FlightLog,
    FloatArray,
    Imu,
    Samples,
    SensorKind,
    Series,
    counted,
    sensor_name,
    usable_series,
)
from altfuse.screen import MAX_BOOT_S, NOT_CONVERGED, not_converged

#: The topics read (pyulog parses no other).
TOPICS = (
    "vehicle_gps_position",
    "sensor_gps",
    "vehicle_air_data",
    "sensor_baro",
    "distance_sensor",
    "sensor_combined",
    "vehicle_attitude",
    "vehicle_global_position",
    "vehicle_local_position",
    "vehicle_global_position_groundtruth",
    "vehicle_local_position_groundtruth",
    "vehicle_land_detected",
)
#: The standard atmosphere's height from pressure [m]: ``44330.77 (1 - (p / p0)^0.190263)``.
SEA_LEVEL_PA = 101325.0
_ISA_EXPONENT = 0.190263
_ISA_SCALE_M = 44330.77
#: MAV_TYPE (the PX4 parameter) to altfuse's vehicle names (as DataFlash logs name them).
_VEHICLE_OF = {1: "plane", 2: "copter", 3: "copter", 4: "copter", 10: "rover", 11: "rover",
               12: "sub", 13: "copter", 14: "copter", 15: "copter", 19: "vtol", 20: "vtol",
               21: "vtol", 22: "vtol", 23: "vtol", 24: "vtol", 25: "vtol"}  # fmt: skip
_RELEASE_TYPES = {0: "dev", 64: "alpha", 128: "beta", 192: "rc", 255: ""}


@dataclass
class _Topics:
    """The decoded topics of one file: per name, its instances' columns in ``multi_id`` order."""

    instances: dict[str, list[dict[str, np.ndarray]]] = field(default_factory=dict)
    start_s: float = 0.0  # subtracted from every time: 0, or the start of a wall-clock log

    def of(self, name: str) -> list[dict[str, np.ndarray]]:
        return self.instances.get(name, [])

    def first(self, name: str, *columns: str) -> dict[str, np.ndarray] | None:
        """The first instance of ``name`` that has every column in ``columns``."""
        return next((d for d in self.of(name) if all(c in d for c in columns)), None)

    def times(self, data: dict[str, np.ndarray], relative: str | None = None) -> FloatArray:
        """A topic's sample times [s]: ``timestamp_sample`` where it has one (a driver that
        does not fill it leaves 0), else ``timestamp`` (plus the column ``relative`` [us])."""
        stamp = data["timestamp"].astype(np.float64)
        if relative is not None:
            stamp += data[relative]
        elif "timestamp_sample" in data:
            sample = data["timestamp_sample"].astype(np.float64)
            stamp = np.where(sample > 0, sample, stamp)
        return np.asarray(stamp / 1e6 - self.start_s)


def read_ulog(path: str | Path, decoded: bool = False) -> FlightLog:
    """Read the altitude sources, IMU, attitude and references from a ULog file (``decoded``:
    another file's decoded form, whose bytes are not that file's).

    Raises
    ------
    LogReadError
        pyulog cannot parse the file (a truncated header, not a ULog).
    """
    from altfuse.io import hashing

    path = Path(path)
    with hashing(path) as digest:
        ulog, printed, end = _parse(path)
        sha256 = digest.result()
    corrupt = "corrupt: pyulog skipped the data it could not parse (read up to the rest)"
    damaged: tuple[str, ...] = (corrupt,) if ulog.file_corruption else ()
    if end is not None:
        damaged += (appended_log(None if decoded else end, path.stat().st_size),)
    notes = [*damaged, *(f"pyulog: {line}" for line in printed)]
    topics = _Topics()
    if ulog.start_timestamp / 1e6 > MAX_BOOT_S:  # a simulator logging the wall clock
        topics.start_s = ulog.start_timestamp / 1e6
        notes.append(
            f"timestamps are Unix time: taken from the log's start ({topics.start_s:.0f} s)"
        )
    counts: dict[str, int] = {}
    for d in sorted(ulog.data_list, key=lambda d: (d.name, d.multi_id)):
        # a damaged format can type a field as text: only numbers are read
        numbers = {k: v for k, v in d.data.items() if v.dtype.kind in "biuf"}
        if "timestamp" not in numbers:
            notes.append(f"{d.name}[{d.multi_id}]: no numeric timestamp, not read")
            continue
        topics.instances.setdefault(d.name, []).append(numbers)
        counts[f"{d.name}[{d.multi_id}]"] = int(d.data["timestamp"].size)
    if ulog.dropouts:
        lost = sum(d.duration for d in ulog.dropouts) / 1e3
        notes.append(f"{len(ulog.dropouts)} logging dropouts, {lost:.1f} s in all")
    params = {  # a damaged parameter decodes as bytes
        k: float(v)
        for k, v in ulog.initial_parameters.items()
        if isinstance(v, int | float) and not isinstance(v, bool)
    }
    sensors = _Sensors()
    _read_gps(topics, sensors)
    _read_baro(topics, sensors)
    _read_distance(topics, sensors)
    notes.extend(sensors.notes)
    return FlightLog(
        path=str(path),
        sha256=sha256,
        size_bytes=path.stat().st_size,
        vehicle=_VEHICLE_OF.get(int(params.get("MAV_TYPE", -1)), "unknown"),
        firmware=_firmware(ulog.msg_info_dict),
        sensors=tuple(sensors.found),
        references=tuple(_references(topics)),
        imu=_imu(topics),
        attitude=_attitude(topics),
        record_counts=dict(sorted(counts.items())),
        skipped_bytes=0,  # pyulog does not count them: a corrupt file says so in ``damaged``
        notes=tuple(notes),
        dropped_sources=sensors.dropped,
        params=params,
        ground_speed=sensors.speed,
        ground_course=sensors.course,
        vertical_velocity=sensors.climb,
        landed=_landed(topics),
        temperatures=sensors.temperatures,
        damaged=damaged,
        reader=f"ULog (pyulog {version('pyulog')})",
    )


#: How often pyulog may step back from the file's end before its parse is stopped. In its
#: definitions section, where damage claims a message's length past the end, pyulog reads up
#: to the end and steps back by the length it asked for rather than by what it read: to before
#: where the message began, whence it reads the same bytes again and returns to the end, for
#: ever (a 12 kB file; 2 of 1,000 damaged logs of the fuzz, past 300 s). A parse that ends
#: steps back from the end at most once (its search for a sync sequence, 7 bytes).
END_REWINDS = 16


class _Endless(Exception):
    """pyulog's parse of a file went back over it without end (not one of the errors its own
    parsing catches and goes on from)."""


class _Bounded:
    """A binary file as pyulog reads it (``read``, ``seek``, ``tell``, ``close``), that stops
    the parse past ``END_REWINDS`` steps back from the file's end. Its reads are the file's
    own (a counted read cost 17 % of a 49 MB ULog's read time); only a seek is watched. Where
    another log follows at ``end``, its reads end there (counted: a joined file alone)."""

    def __init__(self, handle: BinaryIO, size: int, end: int | None = None) -> None:
        self._handle, self._size, self._left = handle, size, END_REWINDS
        self.read, self.tell, self.close = handle.read, handle.tell, handle.close
        if end is not None:  # another log after ``end``: the file ends there for pyulog
            self._size, self.read = end, self._read_to_end

    def _read_to_end(self, n: int = -1) -> bytes:
        left = max(self._size - self._handle.tell(), 0)
        return self._handle.read(left if n is None or n < 0 else min(n, left))

    def seek(self, offset: int, whence: int = 0) -> int:
        if whence == 1 and offset < 0 and self._handle.tell() >= self._size:
            self._left -= 1
            if self._left < 0:
                raise _Endless(
                    "pyulog's reading of its damage did not end: it stepped back from the "
                    f"file's end {END_REWINDS} times"
                )
        return self._handle.seek(offset, whence)


def _parse(path: Path) -> tuple[Any, list[str], int | None]:
    """pyulog's decoding of the topics altfuse reads, what it printed meanwhile (its warnings
    on a corrupt file go to standard output, where a CSV may be going), and where another log
    appended to this one begins (:func:`_appended_at`), None where none does: the first is
    read alone. Joined, pyulog read on into the other's messages as damage: two PX4 simulator
    logs one after the other put 1,988 barometer samples out of order and the fused height
    561 m off. It flags every such file corrupt (the 90 pairs of the 10 shared PX4 logs not
    corrupt already), so only a corrupt one is searched for the other's header and parsed again:
    the others are read once. So is one whose other log pyulog cannot parse at all (pyulog
    1.0 raises a KeyError on two joined simulator logs, where 1.3 flags them corrupt)."""
    try:
        ulog, printed = _parsed(path)
    except LogReadError:
        end = _appended(path)
        if end is None:
            raise
        return (*_parsed(path, end), end)
    if not ulog.file_corruption:
        return ulog, printed, None
    end = _appended(path)
    return (ulog, printed, None) if end is None else (*_parsed(path, end), end)


def _appended(path: Path) -> int | None:
    """Where another log appended to the one at ``path`` begins (:func:`_appended_at`)."""
    try:
        with path.open("rb") as handle:
            return _appended_at(handle)
    except OSError as exc:
        raise LogReadError(f"{path}: cannot read ({exc.strerror})") from exc


def _parsed(path: Path, end: int | None = None) -> tuple[Any, list[str]]:
    """pyulog's decoding of the file up to ``end`` (None: all of it), and what it printed:
    :func:`.fastulog.decode`'s where the file is intact, else pyulog's own parse."""
    from pyulog import ULog

    try:
        decoded = decode(path, TOPICS, end)
    except OSError as exc:
        raise LogReadError(f"{path}: cannot read ({exc.strerror})") from exc
    if decoded is not None:
        return decoded, []
    captured = io.StringIO()
    try:  # the file opened here: pyulog leaves its own handle open when it raises
        with path.open("rb") as handle, contextlib.redirect_stdout(captured):
            size = os.fstat(handle.fileno()).st_size
            ulog = ULog(_Bounded(handle, size, end), list(TOPICS))
    except OSError as exc:
        raise LogReadError(f"{path}: cannot read ({exc.strerror})") from exc
    except Exception as exc:  # pyulog raises what its parsing meets (struct.error, ...)
        raise LogReadError(f"{path}: not a readable ULog file ({exc})") from exc
    printed = [line.strip() for line in captured.getvalue().splitlines() if line.strip()]
    return ulog, sorted(set(printed), key=printed.index)


#: The bytes read at a time looking for another log's header (:func:`_appended_at`).
_SEARCH_CHUNK = 1 << 22


def _appended_at(handle: BinaryIO) -> int | None:
    """Where another ULog's header (its magic bytes) begins in the file, after its own; None
    where none does (seven given bytes: never by chance in the 12 shared PX4 logs). Read a
    chunk at a time, and the handle put back at the file's start: a mapping of the whole file
    would count it all in the process's memory."""
    at, tail = 1, len(ULOG_MAGIC) - 1
    handle.seek(at)
    try:
        while chunk := handle.read(max(_SEARCH_CHUNK, len(ULOG_MAGIC))):
            found = chunk.find(ULOG_MAGIC)
            if found >= 0:
                return at + found
            if len(chunk) < len(ULOG_MAGIC):  # the file's last bytes: no header there
                return None
            at += len(chunk) - tail  # a header across two chunks: read its start again
            handle.seek(at)
        return None
    finally:
        handle.seek(0)


@dataclass
class _Sensors:
    """The sources found, with the reason for every one left out."""

    found: list[Series] = field(default_factory=list)
    dropped: dict[str, str] = field(default_factory=dict)
    temperatures: dict[str, Series] = field(default_factory=dict)
    speed: Series | None = None
    course: Series | None = None
    climb: Series | None = None
    notes: list[str] = field(default_factory=list)

    def add(  # noqa: PLR0913 (what one source is, by name)
        self,
        name: str,
        kind: SensorKind,
        source: str,
        datum: str,
        t: FloatArray,
        value: FloatArray,
        invalid: dict[str, np.ndarray],
    ) -> None:
        found = usable_series(name, kind, source, datum, Samples(t, value), invalid)
        if isinstance(found, str):
            self.dropped[name] = found
        else:
            self.found.append(found)


def _names(kind: str) -> Iterator[str]:
    """``gps``, ``gps2``, ``gps3``, ...: :func:`~altfuse.model.sensor_name` in turn."""
    return (sensor_name(kind, k) for k in itertools.count())


def _read_gps(topics: _Topics, sensors: _Sensors) -> None:
    topic = max(
        ("vehicle_gps_position", "sensor_gps"),
        key=lambda n: sum(d["timestamp"].size for d in topics.of(n)),
    )
    instances = [d for d in topics.of(topic) if "fix_type" in d]
    for k, (name, d) in enumerate(zip(_names("gps"), instances, strict=False)):
        if "altitude_msl_m" in d:
            column, value = "altitude_msl_m", d["altitude_msl_m"].astype(np.float64)
        elif "alt" in d:
            column, value = "alt", d["alt"].astype(np.float64) / 1e3  # mm
        else:
            sensors.dropped[name] = f"{topic}[{k}] has no altitude field"
            continue
        t, fixed = topics.times(d), d["fix_type"] >= 3
        settling = np.zeros(t.size, dtype=bool)
        if "epv" in d:  # the receiver's vertical accuracy [m]
            settling = not_converged(t, d["epv"].astype(np.float64), t)
        source = f"{topic}[{k}].{column}"
        invalid = {"fix_type < 3": ~fixed, NOT_CONVERGED: settling}
        sensors.add(name, "gps", source, "AMSL", t, value, invalid)
        fixed &= ~settling
        if k == 0 and "vel_m_s" in d:
            sensors.speed = _series("ground_speed", "speed", f"{topic}[0].vel_m_s", "horizontal",
                                    t, d["vel_m_s"], fixed)  # fmt: skip
        if k == 0 and "vel_n_m_s" in d and "vel_e_m_s" in d:
            course = np.degrees(np.arctan2(d["vel_e_m_s"], d["vel_n_m_s"])) % 360.0
            sensors.course = _series("ground_course", "course", f"{topic}[0].vel_n/e_m_s",
                                     "from north", t, course, fixed)  # fmt: skip
        if k == 0 and "vel_d_m_s" in d:
            valid = fixed & (d["vel_ned_valid"] != 0) if "vel_ned_valid" in d else fixed
            sensors.climb = _series("gps_velocity_up", "velocity", f"{topic}[0].-vel_d_m_s", "up",
                                    t, -d["vel_d_m_s"], valid)  # fmt: skip


def _series(  # noqa: PLR0913 (a Series' fields)
    name: str, kind: Any, source: str, datum: str, t: FloatArray, v: np.ndarray, keep: np.ndarray
) -> Series | None:
    value = np.asarray(v, dtype=np.float64)
    keep = keep & np.isfinite(t) & np.isfinite(value)
    return Series(name, kind, source, datum, t[keep], value[keep]) if keep.any() else None


def pressure_altitude(pressure_pa: FloatArray) -> FloatArray:
    """Height [m] of a pressure [Pa] in the standard atmosphere (as PX4 computes
    ``baro_alt_meter`` with its default sea-level pressure)."""
    ratio = np.asarray(pressure_pa, dtype=np.float64) / SEA_LEVEL_PA
    return np.asarray(_ISA_SCALE_M * (1.0 - np.power(ratio, _ISA_EXPONENT)))


def _combined_baro(
    combined: dict[str, np.ndarray],
) -> tuple[str, dict[str, np.ndarray], np.ndarray]:
    """PX4's barometer before v1.7, in ``sensor_combined``: each sample once (it is repeated
    until the next), at its own time, with its temperature where the topic has it (a damaged
    format may have lost the column)."""
    stamp = combined["timestamp"] + combined["baro_timestamp_relative"].astype(np.int64)
    fresh = np.concatenate(([True], np.diff(stamp) != 0))
    d = {"timestamp": stamp[fresh]}
    if "baro_temp_celcius" in combined:
        d["baro_temp_celcius"] = combined["baro_temp_celcius"][fresh]
    return "sensor_combined.baro_alt_meter", d, combined["baro_alt_meter"][fresh]


def _read_baro(topics: _Topics, sensors: _Sensors) -> None:
    air = topics.first("vehicle_air_data", "baro_alt_meter")
    combined = topics.first("sensor_combined", "baro_alt_meter", "baro_timestamp_relative")
    if air is not None:
        sources = [
            (f"vehicle_air_data[0].baro_alt_meter{which}", d, d["baro_alt_meter"])
            for which, d in _devices(air, sensors)
        ]
    elif combined is not None and not topics.of("sensor_baro"):  # PX4 before v1.7
        sources = [_combined_baro(combined)]
    else:
        sources = []
        for k, d in enumerate(topics.of("sensor_baro")):
            if "altitude" in d:
                sources.append((f"sensor_baro[{k}].altitude", d, d["altitude"]))
            elif "pressure" in d:
                p = d["pressure"].astype(np.float64)
                pa = p if np.nanmedian(p) > 2000.0 else p * 100.0  # mbar before PX4 v1.12
                sources.append((f"sensor_baro[{k}].pressure (standard atmosphere)", d,
                                pressure_altitude(pa)))  # fmt: skip
    for name, (source, d, value) in zip(_names("baro"), sources, strict=False):
        t = topics.times(d)
        sensors.add(name, "baro", source, "baro calibration", t, value.astype(np.float64), {})
        for column in ("baro_temp_celcius", "ambient_temperature", "temperature"):
            if column in d:
                where = source.split(".")[0]
                kept = _series(name, "temperature", f"{where}.{column}", "degC", t, d[column],
                               np.ones(t.size, dtype=bool))  # fmt: skip
                if kept is not None:
                    sensors.temperatures[name] = kept
                break


#: Most barometer devices and calibrations a log's ``vehicle_air_data`` is read as, each its own
#: barometer: PX4 carries at most 4 barometers (``MAX_SENSOR_COUNT``), and a calibration or two
#: more is a lot; more is damage, and each would be one more sensor to fuse.
MAX_BAROMETERS = 8


def _devices(
    air: dict[str, np.ndarray], sensors: _Sensors
) -> list[tuple[str, dict[str, np.ndarray]]]:
    """``vehicle_air_data``'s samples per barometer (``baro_device_id``) and calibration
    (``calibration_count``), the one with the most samples first, each named where there are more;
    a note of the changes. PX4 fails over to another barometer when the selected one fails, and
    a new calibration moves a barometer's offset (its GNSS-baro calibration, ``SENS_BAR_AUTOCAL``
    on by default, to the GNSS altitude on the ground): EKF2 resets its barometer bias at either
    (``EKF2::UpdateBaroSample``). Read as one barometer, the change is a step, which the
    smoother follows where it is under STEP_SIGMAS (a PX4 simulator flight failed over at 70 %
    to a barometer 0.3 m higher: 0.161 m RMSE, its GPS's 0.015); each read as its own
    barometer, with its own offset (0.010 m, whatever the step)."""
    columns = [c for c in ("baro_device_id", "calibration_count") if c in air]
    if not columns:
        return [("", air)]
    keys = np.column_stack([air[c].astype(np.int64) for c in columns])
    unique, first, inverse, counts = np.unique(
        keys, axis=0, return_index=True, return_inverse=True, return_counts=True
    )
    inverse = inverse.reshape(-1)
    if len(unique) < 2:
        return [("", air)]
    if len(unique) > MAX_BAROMETERS:
        sensors.notes.append(
            f"vehicle_air_data: {len(unique)} barometers or calibrations, more than "
            f"{MAX_BAROMETERS}: damage, read as one barometer"
        )
        return [("", air)]
    # the most samples first: the barometer named ``baro`` is the log's main one, whatever a
    # first sample or two logged before the device was set up say
    order = sorted(range(len(unique)), key=lambda u: (-counts[u], first[u]))
    names = [
        ", ".join(f"{c} {v}" for c, v in zip(columns, unique[u].tolist(), strict=True))
        for u in order
    ]
    changes = int(np.count_nonzero(np.diff(inverse)))
    sensors.notes.append(
        f"vehicle_air_data: the barometer or its calibration changed {counted(changes, 'time')} "
        f"({'; '.join(names)}): each read as its own barometer"
    )
    masks = [inverse == u for u in order]
    return [
        (f" ({name})", {c: v[mask] for c, v in air.items()})
        for mask, name in zip(masks, names, strict=True)
    ]


def _read_distance(topics: _Topics, sensors: _Sensors) -> None:
    down = []
    for k, d in enumerate(topics.of("distance_sensor")):
        if "current_distance" not in d:
            continue
        if "orientation" in d and not (d["orientation"] == DOWNWARD).all():
            facing = sorted(set(d["orientation"].tolist()))
            sensors.dropped[f"distance_sensor[{k}]"] = (
                f"distance_sensor[{k}].current_distance: orientation {facing}, not "
                f"{DOWNWARD} (facing down): no height"
            )
            continue
        down.append((k, d))
    for name, (k, d) in zip(_names("rangefinder"), down, strict=False):
        value = d["current_distance"].astype(np.float64)
        invalid: dict[str, np.ndarray] = {}
        if "min_distance" in d and "max_distance" in d:
            invalid["outside min_distance..max_distance"] = (value < d["min_distance"]) | (
                value > d["max_distance"]
            )
        if "signal_quality" in d:
            invalid["signal_quality 0 (invalid)"] = d["signal_quality"] == 0
        source = f"distance_sensor[{k}].current_distance"
        sensors.add(name, "rangefinder", source, "ground below the vehicle", topics.times(d), value,
                    invalid)  # fmt: skip


def _imu(topics: _Topics) -> Imu | None:
    axes = [f"accelerometer_m_s2[{i}]" for i in range(3)]
    d = topics.first("sensor_combined", *axes)
    if d is None:
        return None
    relative = "accelerometer_timestamp_relative"
    t = topics.times(d, relative if relative in d else None)
    acc = np.column_stack([d[a].astype(np.float64) for a in axes])
    return Imu("sensor_combined.accelerometer_m_s2", t, acc)


def _attitude(topics: _Topics) -> Attitude | None:
    d = topics.first("vehicle_attitude", "q[0]", "q[1]", "q[2]", "q[3]")
    if d is None:
        return None
    q = np.column_stack([d[f"q[{i}]"].astype(np.float64) for i in range(4)])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    # ZYX Euler angles of the body-to-NED rotation, for the record and the screening
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return Attitude("vehicle_attitude.q", topics.times(d), roll, pitch, yaw, quaternion=q)


def _landed(topics: _Topics) -> Series | None:
    """PX4's land detector: ``vehicle_land_detected.landed``, 1 on the ground."""
    found = next((d for d in topics.of("vehicle_land_detected") if "landed" in d), None)
    if found is None:
        return None
    t, value = topics.times(found), (found["landed"] != 0).astype(np.float64)
    return _series("landed", "landed", "vehicle_land_detected.landed", "on the ground", t, value,
                   np.ones(t.size, dtype=bool))  # fmt: skip


def _references(topics: _Topics) -> list[Series]:
    """The EKF2 estimate (``ekf``) and the simulator's groundtruth (``sim``): each topic's
    global altitude, else its local position's ``-z``."""
    out = []
    for name, suffix, what in (("ekf", "", "EKF2"), ("sim", "_groundtruth", "simulator truth")):
        found = _reference(
            topics, name, f"vehicle_global_position{suffix}", "alt", f"AMSL ({what})"
        ) or _reference(
            topics, name, f"vehicle_local_position{suffix}", "z", f"{what} origin", sign=-1.0
        )
        if found is not None:
            out.append(found)
    return out


def _reference(
    topics: _Topics, name: str, topic: str, column: str, datum: str, sign: float = 1.0
) -> Series | None:
    d = topics.first(topic, column)
    if d is None:
        return None
    t = topics.times(d)
    source = f"{topic}.{'-' if sign < 0 else ''}{column}"
    return _series(name, "reference", source, datum, t, sign * d[column].astype(np.float64),
                   np.ones(t.size, dtype=bool))  # fmt: skip


def _firmware(info: dict[str, Any]) -> str:
    """``PX4 v1.9.0-beta (654ed4b9)`` from the log's version fields."""
    release = info.get("ver_sw_release")
    text = "PX4"
    if isinstance(release, int) and release:
        major, minor, patch, kind = (
            (release >> 24) & 0xFF,
            (release >> 16) & 0xFF,
            (release >> 8) & 0xFF,
            release & 0xFF,
        )
        tag = _RELEASE_TYPES.get(kind, "")
        text += f" v{major}.{minor}.{patch}" + (f"-{tag}" if tag else "")
    commit = str(info.get("ver_sw", ""))[:8]
    return text + (f" ({commit})" if commit else "")
