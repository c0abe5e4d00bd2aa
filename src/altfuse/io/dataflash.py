"""ArduPilot DataFlash (``.bin``) reader.

The records come from :mod:`altfuse.io.fastdf`, which finds and decodes them with numpy as
pymavlink's sequential parser would (it resynchronises on damage, where pymavlink's type index can
hide every record after the first undefined header: ALGORITHMS.md section 5), and gives each
numeric field the value pymavlink gives it: the scale of the legacy format characters
(``c C e E`` x0.01, ``L`` x1e-7) divided out as pymavlink does. pymavlink does not apply the FMTU
multipliers that newer logs use instead (an ``h`` field with multiplier ``B`` holds centimetres);
this module does, from the log's own FMTU/UNIT/MULT records, and checks that every altitude field
is in metres.

What is read
------------
Altitude sources (inputs):

- ``GPS.Alt`` [m AMSL], only with ``Status >= 3`` (3D fix); every instance (``I`` field or GPS2).
- ``BARO.Alt`` [m above the calibration point], every instance (``I`` or BAR2/BAR3); samples
  flagged unhealthy (``Health``/``H`` == 0) are dropped. Where Copter re-zeroed its barometers
  (arming without a home: ``EV`` ``EKF_ALT_RESET``), their earlier samples are moved by the
  step there (:func:`rejoined`).
- ``RFND.Dist`` [m above ground] per ``Instance`` (4.x) or ``Dist1``/``Dist2`` (3.x), only with
  ``Stat == 4`` (Good) where Stat is logged, else non-zero; ``SONR`` in old logs.
- Fallbacks: with no BARO records, ``CTUN.BAlt``/``BarAlt``; with no RFND/SONR records,
  ``CTUN.SAlt``/``SonAlt`` (0 there means "no reading"). The choice is noted.

Times are each record's own (:meth:`_Records.time_field`); Copter up to 3.1 logs none in CTUN
(its barometer) and ATT, Copter 3.4 none in EV: those take the times of the records around
them (:meth:`_Records.times`).

Kept for later stages: IMU (first instance) accelerations, ATT attitude, the horizontal speed
over ground (``GPS.Spd`` of the first instance with a 3D fix), each barometer's temperature
(``BARO.Temp``). References, never
inputs: EKF height (``XKF1``/``NKF1`` ``-PD``, with the EKF origin from ``ORGN``), ``AHR2.Alt``,
``POS.Alt``, ``CTUN.Alt`` and the simulator's true altitude ``SIM.Alt``.
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Iterator, Mapping
from concurrent.futures import Future
from dataclasses import replace
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from altfuse.errors import LogReadError
from altfuse.io import appended_log, hashing
from altfuse.io.fastdf import Format, Index, _text, index_file
from altfuse.io.framing import FMT_TYPE, FORMAT_TO_STRUCT, HEADER
from altfuse.metrics import mad_sigma
from altfuse.model import (
    DOWNWARD,
    Attitude,
    FlightLog,
    FloatArray,
    Imu,
    Samples,
    SensorKind,
    Series,
    SeriesKind,
    Vibration,
    counted,
    sensor_name,
    usable_series,
)
from altfuse.screen import NOT_CONVERGED, not_converged

log = logging.getLogger(__name__)

_SENSOR_TYPES = ("GPS", "GPS2", "GPS3", "BARO", "BAR2", "BAR3", "RFND", "SONR", "CTUN")
_OTHER_TYPES = (
    "IMU", "ATT", "XKF1", "NKF1", "ORGN", "AHR2", "POS", "SIM", "MSG", "VER", "FMTU", "PARM",
    "VIBE", "STAT", "GPA", "GPA2", "GPA3", "EV", "INAV",
)  # fmt: skip
WANTED_TYPES = frozenset(_SENSOR_TYPES + _OTHER_TYPES)
#: The wanted types read as samples in time (the others are the log's text and parameters).
_RECORDED = WANTED_TYPES - {"MSG", "VER", "FMTU", "PARM"}
_UNIT_TYPES = frozenset({"UNIT", "MULT"})  # read with FMTU for the fields' units

#: Format characters of text, and of text and arrays: never a number.
_TEXT_CHARS = frozenset("nNZ")
_NOT_NUMBERS = _TEXT_CHARS | {"a"}
#: The most instances of one sensor type ArduPilot logs (RNGFND_MAX_INSTANCES is 10).
MAX_INSTANCES = 10
#: The GPS instance that is the blend of the receivers, where GPS_AUTO_SWITCH is 2 (ArduPilot's
#: GPS_BLENDED_INSTANCE, GPS_MAX_RECEIVERS: 2), logged since 4.1 as one more ``GPS`` instance
#: (as ``GPSB`` before, not read): a weighted mean of the receivers' heights, no sensor of its
#: own; fused beside them, their errors would count twice.
BLENDED_GPS_INSTANCE = 2
#: Format characters whose scale pymavlink applies itself.
_SELF_SCALED = frozenset("cCeEL")
#: Fields ArduPilot logged in centimetres as plain numbers before FMTU records said so: Plane's
#: sonar distance (``rangefinder.distance_cm()``, a float: ``DistCM`` to 3.3, then ``Dist``;
#: FMTU's multiplier B, 0.01, once logged). Read as metres, a 5 m height was 500.
_CENTIMETRES_UNSAID = frozenset({("SONR", "DistCM"), ("SONR", "Dist")})
#: Multiplier ids that mean "none" ('-'), "unknown" ('?') or 1 ('0').
_NO_MULTIPLIER = frozenset("-?0")
_LENGTH_UNITS_OK = frozenset({"m", "", "UNKNOWN"})
_GROUND = "ground below the vehicle"

#: A parameter only ArduSub has (its water surface's depth): a Sub log whose firmware text
#: (MSG, VER) is gone, its head cut, is still known for one (its BARO is water depth).
_SUB_ONLY_PARAMETER = "SURFACE_DEPTH"
_FIRMWARE_RE = re.compile(
    r"\b(ArduCopter|APM:Copter|ArduPlane|APM:Plane|ArduRover|APM:Rover|ArduSub|"
    r"AntennaTracker|Blimp|ArduHeli)\s+V?(\d+\.\d+[\w.\-]*)"
)
_VEHICLE_OF = {
    "ArduCopter": "copter",
    "APM:Copter": "copter",
    "ArduHeli": "copter",
    "ArduPlane": "plane",
    "APM:Plane": "plane",
    "ArduRover": "rover",
    "APM:Rover": "rover",
    "ArduSub": "sub",
    "AntennaTracker": "tracker",
    "Blimp": "blimp",
}


def _scaled(values: npt.NDArray[Any], char: str) -> FloatArray:
    """A numeric field as pymavlink gives it: the legacy format scales divided out as it does."""
    scale = FORMAT_TO_STRUCT[char][1]
    with np.errstate(invalid="ignore"):  # damaged bytes can hold signalling NaNs
        out: FloatArray = values.astype(np.float64)
    if scale is not None:
        # pymavlink divides by 1/scale (more exact for 0.01 and 1e-7 than multiplying)
        out = out / (1 / scale) if 0.0 < scale < 1.0 else out * scale
    return out


#: A GPS week [s]: Copter up to 3.0 logs no time but its GPS records' time of week.
GPS_WEEK_S = 7 * 86400.0
#: Another log appended to the first (two files joined: ``cat a.bin b.bin``) starts its clock
#: again at its own boot: the clock's records fall back by more than RESTART_BACK_S from the
#: time the RESTART_BEFORE records before reached (their median: a lone stamp hours ahead is
#: no time reached), each type's first after that point too, and stay behind it for
#: RESTART_RECORDS records (or to the end), with FMT records (its header) since the first
#: log's last. A stamp damaged alone falls back once, or leaps ahead once (the screen drops
#: it); a block of records written twice has no header; a log's clocks never run back.
RESTART_BACK_S = 10.0
RESTART_BEFORE = 5
RESTART_RECORDS = 50


def across_weeks(t: FloatArray) -> FloatArray:
    """GPS times of week [s] made continuous across the end of a week (Sunday 00:00 GPS time),
    where they fall back by more than half a week."""
    weeks = np.concatenate(([0.0], np.cumsum(np.diff(t) < -GPS_WEEK_S / 2)))
    out: FloatArray = t + GPS_WEEK_S * weeks
    return out


class _Records:
    """The decoded records of the wanted types, by type name, with their unit metadata."""

    def __init__(self, index: Index) -> None:
        self.index = index
        self.counts = index.counts()
        self.formats: dict[str, Format] = {}
        self.problems: dict[str, str] = {}  # wanted types whose records are not decoded, why
        for f in index.formats.values():
            if f.name in self.formats:  # two type ids, one name: which is which?
                other = self.formats[f.name].type_id
                f = replace(f, problem=f"type ids {other} and {f.type_id} both name it")
            self.formats[f.name] = f
            if f.problem is not None and f.name in WANTED_TYPES and self.n(f.name):
                self.problems[f.name] = f.problem
        # the wanted types and the unit tables in one pass (Index.records_of); another type is
        # gathered when asked
        wanted = {self.formats[n].type_id: n for n in WANTED_TYPES | _UNIT_TYPES if self.has(n)}
        self._tables: dict[str, npt.NDArray[Any]] = {
            wanted[t]: rows for t, rows in index.records_of(list(wanted)).items()
        }
        self._raw: dict[tuple[str, str], FloatArray] = {}
        self._times: dict[str, FloatArray] = {}
        self.fmtu: dict[int, tuple[str, str]] = {}
        self.unit_lookup: dict[str, str] = {}
        self.mult_lookup: dict[str, float] = {}
        if self.has("FMTU", "FmtType", "UnitIds", "MultIds"):
            types = self.table("FMTU")["FmtType"].tolist()
            unit_ids, mult_ids = self.text("FMTU", "UnitIds"), self.text("FMTU", "MultIds")
            self.fmtu = {int(t): (u, m) for t, u, m in zip(types, unit_ids, mult_ids, strict=True)}
        if self.has("UNIT", "Id", "Label"):
            ids = self.table("UNIT")["Id"].tolist()
            self.unit_lookup = dict(zip(map(_char, ids), self.text("UNIT", "Label"), strict=True))
        if self.has("MULT", "Id", "Mult"):
            ids = self.table("MULT")["Id"].tolist()
            # pymavlink rounds the logged double to 7 significant digits
            values = [float(f"{m:.7g}") for m in self.table("MULT")["Mult"].tolist()]
            self.mult_lookup = dict(zip(map(_char, ids), values, strict=True))

    # -- access -----------------------------------------------------------------------------

    def n(self, type_name: str) -> int:
        return self.counts.get(type_name, 0)

    def done(self, *type_names: str) -> None:
        """Let the records of ``type_names`` go, and the columns read of them: nothing reads
        them again (the wanted types' records of a 300 MB log are 92 MB, gathered at once; a
        type read again is gathered again)."""
        for name in type_names:
            self._tables.pop(name, None)
            self._times.pop(name, None)
        self._raw = {key: v for key, v in self._raw.items() if key[0] not in type_names}

    def table(self, type_name: str) -> npt.NDArray[Any]:
        if type_name not in self._tables:
            self._tables[type_name] = self.index.records(self.formats[type_name].type_id)
        return self._tables[type_name]

    def has(self, type_name: str, *fields: str) -> bool:
        fmt = self.formats.get(type_name)
        return (
            fmt is not None
            and fmt.problem is None
            and self.n(type_name) > 0
            and all(f in fmt.columns for f in fields)
        )

    def timed(self, type_name: str, *fields: str) -> bool:
        """:meth:`has`, and the type's records have times (:meth:`times`): a time field of
        their own (damage can rename it in its FMT), or the log's :attr:`clock`."""
        return self.has(type_name, *fields) and (
            self.time_field(type_name) is not None or bool(self.clock)
        )

    @cached_property
    def clock(self) -> tuple[str, ...]:
        """The wanted types of samples in time (not ``PARM``, ``MSG``: a 4.x log's thousand
        parameters come at boot) whose records have a time field of their own: they time the
        records of a type with none (:meth:`times`)."""
        return tuple(n for n in sorted(_RECORDED) if self.has(n) and self.time_field(n))

    @cached_property
    def _ticks(self) -> tuple[npt.NDArray[np.intp], FloatArray]:
        """The :attr:`clock`'s records' places in the log's chain of records, and their times;
        not those whose time is 0, none (a GPS's before it knows the time of week)."""
        types = self.index.types
        t = np.full(types.size, np.nan)
        for name in self.clock:
            t[types == self.formats[name].type_id] = self.times(name)
        at = np.flatnonzero(t > 0)
        return at, t[at]

    @cached_property
    def restart(self) -> tuple[int, float, float] | None:
        """Where another log begins, appended to this one (:data:`RESTART_BACK_S`): its place
        in the chain of records (its header's first FMT record, after the first log's last
        record of the :attr:`clock`), the time the first log had reached and the other's
        first [s]; None where none does."""
        if not any(self._falls_back(name) for name in self.clock):
            return None  # (the chain's times below are the file's records' count of floats)
        at, t = self._ticks
        types = self.index.types[at]
        for k in np.flatnonzero(t[1:] < t[:-1] - RESTART_BACK_S) + 1:
            # the time reached: the records' before it (a lone stamp ahead of them is none)
            reached = float(np.median(t[max(0, k - RESTART_BEFORE) : k]))
            # every type's clock starts again there: its first record after it falls back too
            _, firsts = np.unique(types[k:], return_index=True)
            again = (t[k + firsts] < reached - RESTART_BACK_S).all()
            # and a log's header before it (a block of records written twice has none)
            since, until = at[k - 1] + 1, at[k]
            header = np.flatnonzero(self.index.types[since:until] == FMT_TYPE)
            if again and header.size and (t[k : k + RESTART_RECORDS] < reached).all():
                return int(since + header[0]), reached, float(t[k])
        return None

    def _falls_back(self, type_name: str) -> bool:
        """Whether the times of a type of the :attr:`clock` fall back by more than
        RESTART_BACK_S somewhere: read from its records and let go (each clock type's kept at
        once put the 300 MB log's peak 20 MB higher)."""
        t = self._own_times(type_name, kept=False)
        return t.size > 1 and bool(np.any(t[1:] < np.fmax.accumulate(t)[:-1] - RESTART_BACK_S))

    def _own_times(self, type_name: str, kept: bool = True) -> FloatArray:
        """The times [s] of a type with a time field (:meth:`time_field`), from that field;
        its values ``kept`` for the next to ask (:meth:`raw`), or read and let go."""
        found = self.time_field(type_name)
        if found is None:
            raise KeyError(f"{type_name} has no time field")
        name, per_second = found
        t = (self.raw if kept else self._decoded)(type_name, name) / per_second
        return across_weeks(t) if name == "Time" else t

    def time_field(self, type_name: str) -> tuple[str, float] | None:
        """The field that holds a record's time since boot, and its units per second.

        ``TimeUS`` [us], else ``TimeMS`` [ms] where it is the first field. In Copter up to 3.4
        and Plane up to 3.3 a GPS record's ``TimeMS`` is the GPS time of week and its boot time
        is ``T`` [ms], as pymavlink's DFReaderClock_msec reads it. Copter up to 3.0 logs no
        boot time at all: its GPS records' ``Time`` [ms], the GPS time of week, is the only
        time in the log (:data:`GPS_WEEK_S`).
        """
        columns = self.formats[type_name].columns
        if "TimeUS" in columns:
            return "TimeUS", 1e6
        if columns[:1] == ("TimeMS",):
            return "TimeMS", 1e3
        gps = type_name.startswith("GPS")  # another type's T is a temperature (IMU.T)
        if gps and "T" in columns:
            return "T", 1e3
        if "TimeMS" in columns:
            return "TimeMS", 1e3
        return ("Time", 1e3) if gps and "Time" in columns else None

    def raw(self, type_name: str, col: str) -> FloatArray:
        """A numeric field as pymavlink decodes it (legacy format scales applied); computed once
        per column (each instance of a type asks for its times again). Do not modify it."""
        key = (type_name, col)
        if key not in self._raw:
            self._raw[key] = self._decoded(type_name, col)
        return self._raw[key]

    def _decoded(self, type_name: str, col: str) -> FloatArray:
        """:meth:`raw`, decoded now and not kept."""
        char = self.format_char(type_name, col)
        if char in _NOT_NUMBERS:  # a number declared as text: no number to read
            self.problems[f"{type_name}.{col}"] = f"declared as text ({char!r}), not a number"
            return np.full(self.n(type_name), np.nan)
        return _scaled(self.table(type_name)[col], char)

    def format_char(self, type_name: str, col: str) -> str:
        fmt = self.formats[type_name]
        return fmt.format[fmt.columns.index(col)]

    def text(self, type_name: str, col: str) -> list[str]:
        """A text field's values; for a field declared as a number, empty strings and a
        problem."""
        char = self.format_char(type_name, col)
        if char not in _TEXT_CHARS:
            self.problems[f"{type_name}.{col}"] = f"declared as a number ({char!r}), not text"
            return [""] * self.n(type_name)
        return [_text(v) for v in self.table(type_name)[col].tolist()]

    def column(self, type_name: str, col: str) -> FloatArray:
        """Field values in the field's unit (format scale as pymavlink, FMTU multiplier here)."""
        return self.raw(type_name, col) * self.multiplier(type_name, col)

    def times(self, type_name: str) -> FloatArray:
        """Record times since boot [s] (see :meth:`time_field`); for a type with no time field,
        the times of the :attr:`clock`'s records around each record, interpolated by its place
        among the records between them (Copter up to 3.1 logs times in its GPS and IMU records
        alone, Copter 3.4 its ``EV`` records without one). After the last timed record, its
        time (pymavlink's reader gives such a record the time of the record before it, in a 3.1
        log without IMU records up to 0.2 s early); before the first, NaN. Do not modify it."""
        if type_name not in self._times:
            if self.time_field(type_name) is not None:
                self._times[type_name] = self._own_times(type_name)
            elif self.clock:
                at = np.flatnonzero(self.index.types == self.formats[type_name].type_id)
                self._times[type_name] = np.interp(at, *self._ticks, left=np.nan)
            else:
                raise KeyError(f"{type_name} has no time field, and no record type has one")
        return self._times[type_name]

    def multiplier(self, type_name: str, col: str) -> float:
        fmt = self.formats[type_name]
        i = fmt.columns.index(col)
        if fmt.format[i] in _SELF_SCALED:
            return 1.0
        ids = self.fmtu.get(fmt.type_id)
        if ids is None:
            return 0.01 if (type_name, col) in _CENTIMETRES_UNSAID else 1.0
        if i >= len(ids[1]) or ids[1][i] in _NO_MULTIPLIER:
            return 1.0
        return float(self.mult_lookup.get(ids[1][i], 1.0))

    def unit(self, type_name: str, col: str) -> str:
        fmt = self.formats[type_name]
        i = fmt.columns.index(col)
        ids = self.fmtu.get(fmt.type_id)
        if ids is None or i >= len(ids[0]):
            return ""
        return str(self.unit_lookup.get(ids[0][i], ""))


def _char(value: int) -> str:
    return chr(value % 256)


def _instances(rec: _Records, type_name: str, field: str, default: int) -> Iterator[Any]:
    """Yield (instance number, boolean mask) for each instance in ``type_name``'s records."""
    n = rec.n(type_name)
    if not rec.has(type_name, field):
        yield default, np.ones(n, dtype=bool)
        return
    inst = rec.raw(type_name, field)
    found = np.unique(inst[np.isfinite(inst)])
    if found.size > MAX_INSTANCES or np.any((found < 0) | (found != np.round(found))):
        rec.problems[f"{type_name}.{field}"] = (
            f"{found.size:,} distinct instance numbers (at most {MAX_INSTANCES}, whole, from 0): "
            "its FMT's columns are likely mislabelled"
        )
        return
    for i in found:
        yield int(i), inst == i


class _Builder:
    """Collects the sources found in a log, with the reason for every one left out."""

    def __init__(self, rec: _Records) -> None:
        self.rec = rec
        self.sensors: dict[str, Series] = {}
        self.dropped_sources: dict[str, str] = {}
        self.notes: list[str] = []
        self.temperatures: dict[str, Series] = {}
        # per GPS type, its records from before its receiver's fix converged
        self.not_converged: dict[str, npt.NDArray[np.bool_]] = {}

    def add(  # noqa: PLR0913 (keyword-only: what one source is, by name)
        self,
        *,
        name: str,
        kind: SensorKind,
        type_name: str,
        col: str,
        datum: str,
        select: np.ndarray,
        invalid: dict[str, np.ndarray] | None = None,
    ) -> None:
        """Add ``type_name.col`` (records in ``select``) minus the ``invalid`` masks, by reason."""
        source = f"{type_name}.{col}"
        if name in self.sensors:
            self.notes.append(f"{source}: a second source named {name!r}, ignored")
            return
        unit = self.rec.unit(type_name, col)
        if unit not in _LENGTH_UNITS_OK:
            self.dropped_sources[name] = f"{source} is in {unit!r}, not metres"
            return
        samples = Samples(
            self.rec.times(type_name)[select], self.rec.column(type_name, col)[select]
        )
        masks = {reason: mask[select] for reason, mask in (invalid or {}).items()}
        found = usable_series(name, kind, source, datum, samples, masks)
        if isinstance(found, str):
            self.dropped_sources[name] = found
        else:
            self.sensors[name] = found


def _add_instances(  # noqa: PLR0913 (what each instance's source is, as add() takes it)
    b: _Builder,
    kind: SensorKind,
    type_name: str,
    col: str,
    datum: str,
    *,
    instance_field: str,
    default: int,
    invalid: dict[str, Any],
    not_sensors: Mapping[int, str] | None = None,
) -> None:
    """Add one series per instance of ``type_name.col``, named ``kind``, ``kind2``, ...; the
    instances numbered in ``instance_field`` that ``not_sensors`` names left out, for the
    reason it gives."""
    left_out = (not_sensors or {}) if b.rec.has(type_name, instance_field) else {}
    for inst, sel in _instances(b.rec, type_name, instance_field, default):
        if inst in left_out:
            b.dropped_sources[sensor_name(kind, inst)] = left_out[inst]
            continue
        b.add(
            name=sensor_name(kind, inst),
            kind=kind,
            type_name=type_name,
            col=col,
            datum=datum,
            select=sel,
            invalid=invalid,
        )


def _not_converged(rec: _Records, type_name: str) -> npt.NDArray[np.bool_]:
    """Per record of ``type_name`` (GPS, GPS2, GPS3): whether its receiver's fix had not yet
    converged (:func:`altfuse.screen.not_converged`) by the vertical accuracy of its accuracy
    records (GPA, GPA2, GPA3; by instance ``I`` where both have one)."""
    out = np.zeros(rec.n(type_name), dtype=bool)
    accuracy = "GPA" + type_name.removeprefix("GPS")
    if not rec.timed(accuracy, "VAcc"):
        return out
    t, vacc, at = rec.times(accuracy), rec.column(accuracy, "VAcc"), rec.times(type_name)
    by_instance = rec.has(accuracy, "I") and rec.has(type_name, "I")
    for inst, sel in _instances(rec, type_name, "I", 0):
        mine = rec.raw(accuracy, "I") == inst if by_instance else np.ones(t.size, dtype=bool)
        out[sel] = not_converged(t[mine], vacc[mine], at[sel])
    return out


def _read_gps(b: _Builder) -> None:
    for default, type_name in enumerate(("GPS", "GPS2", "GPS3")):
        if not b.rec.timed(type_name, "Alt", "Status"):
            continue
        no_fix = b.rec.raw(type_name, "Status") < 3
        b.not_converged[type_name] = _not_converged(b.rec, type_name)
        if b.rec.time_field(type_name) == ("T", 1e3):
            b.notes.append(
                f"{type_name} time from {type_name}.T, the boot time: its TimeMS is the GPS time "
                "of week in this firmware"
            )
        _add_instances(
            b,
            "gps",
            type_name,
            "Alt",
            "AMSL",
            instance_field="I",
            default=default,
            invalid={
                "GPS Status < 3 (no 3D fix)": no_fix,
                NOT_CONVERGED: b.not_converged[type_name],
            },
            not_sensors={
                BLENDED_GPS_INSTANCE: f"{type_name}[{BLENDED_GPS_INSTANCE}].Alt: not fused: the "
                "blend of the receivers (GPS_AUTO_SWITCH 2), not a sensor of its own"
            },
        )


def _read_baro(b: _Builder) -> bool:
    found = False
    for default, type_name in enumerate(("BARO", "BAR2", "BAR3")):
        if not b.rec.timed(type_name, "Alt"):
            continue
        found = True
        invalid = {}
        for health in ("Health", "H"):
            if b.rec.has(type_name, health):
                invalid["flagged unhealthy"] = b.rec.raw(type_name, health) == 0
                break
        _add_instances(
            b,
            "baro",
            type_name,
            "Alt",
            "baro calibration",
            instance_field="I",
            default=default,
            invalid=invalid,
        )
        if b.rec.has(type_name, "Temp"):
            for inst, sel in _instances(b.rec, type_name, "I", default):
                t, temp = b.rec.times(type_name)[sel], b.rec.column(type_name, "Temp")[sel]
                keep = np.isfinite(t) & np.isfinite(temp)
                name = sensor_name("baro", inst)
                if keep.any() and name not in b.temperatures:
                    b.temperatures[name] = Series(
                        name, "temperature", f"{type_name}.Temp", "degC", t[keep], temp[keep]
                    )
    return found


def _rangefinder_invalid(
    b: _Builder, type_name: str, dist: str, stat: str, orient: str
) -> dict[str, Any]:
    """A rangefinder's samples to leave out: not Good (or 0 where no status is logged), and
    not facing down where its orientation is logged (an avoidance sensor measures no height)."""
    rec = b.rec
    if rec.has(type_name, stat):
        invalid = {"Stat != 4 (not Good)": rec.raw(type_name, stat) != 4}
    else:
        invalid = {"0 (no reading)": rec.raw(type_name, dist) <= 0}
    if rec.has(type_name, orient):
        invalid[f"{orient} != {DOWNWARD} (not facing down)"] = (
            rec.raw(type_name, orient) != DOWNWARD
        )
    return invalid


def _read_rangefinder(b: _Builder) -> bool:
    found = False
    rfnd = "RFND"
    if b.rec.timed(rfnd, "Dist"):
        found = True
        _add_instances(
            b,
            "rangefinder",
            rfnd,
            "Dist",
            _GROUND,
            instance_field="Instance",
            default=0,
            invalid=_rangefinder_invalid(b, rfnd, "Dist", "Stat", "Orient"),
        )
    elif b.rec.n(rfnd):
        for inst in (0, 1):
            dist = f"Dist{inst + 1}"
            if not b.rec.timed(rfnd, dist):
                continue
            found = True
            b.add(
                name=sensor_name("rangefinder", inst),
                kind="rangefinder",
                type_name=rfnd,
                col=dist,
                datum=_GROUND,
                select=np.ones(b.rec.n(rfnd), dtype=bool),
                invalid=_rangefinder_invalid(b, rfnd, dist, f"Stat{inst + 1}", f"Orient{inst + 1}"),
            )
    for col in ("Dist", "DistCM"):
        if not found and b.rec.timed("SONR", col):
            found = True
            b.add(
                name="rangefinder",
                kind="rangefinder",
                type_name="SONR",
                col=col,
                datum=_GROUND,
                select=np.ones(b.rec.n("SONR"), dtype=bool),
                invalid={"0 (no reading)": b.rec.raw("SONR", col) <= 0},
            )
    return found


def _read_ctun_fallbacks(b: _Builder, have_baro: bool, have_rangefinder: bool) -> None:
    if not b.rec.n("CTUN"):
        return
    everything = np.ones(b.rec.n("CTUN"), dtype=bool)
    if not have_baro:
        for col in ("BAlt", "BarAlt"):
            if b.rec.timed("CTUN", col):
                b.add(
                    name="baro",
                    kind="baro",
                    type_name="CTUN",
                    col=col,
                    datum="baro calibration",
                    select=everything,
                )
                b.notes.append(f"no BARO records: barometer altitude taken from CTUN.{col}")
                break
    if not have_rangefinder:
        for col in ("SAlt", "SonAlt"):
            if not b.rec.timed("CTUN", col):
                continue
            values = b.rec.column("CTUN", col)
            if not np.any(values[np.isfinite(values)] != 0):
                b.notes.append(f"CTUN.{col} is 0 throughout: no rangefinder")
                break
            b.add(
                name="rangefinder",
                kind="rangefinder",
                type_name="CTUN",
                col=col,
                datum="ground below the vehicle (tilt-corrected by the autopilot)",
                select=everything,
                invalid={"0 (no reading)": values == 0},
            )
            b.notes.append(f"no RFND records: rangefinder altitude taken from CTUN.{col}")
            break


def _reference(
    rec: _Records, name: str, type_name: str, col: str, datum: str, sign: float = 1.0
) -> Series | None:
    if not rec.timed(type_name, col):
        return None
    select = np.ones(rec.n(type_name), dtype=bool)
    if rec.has(type_name, "C"):  # EKF3 logs one record per core: take core 0
        select = rec.raw(type_name, "C") == 0
    t = rec.times(type_name)[select]
    value = sign * rec.column(type_name, col)[select]
    keep = np.isfinite(t) & np.isfinite(value)
    if not keep.any():
        return None
    source = f"{type_name}.{'-' if sign < 0 else ''}{col}"
    return Series(name, "reference", source, datum, t[keep], value[keep])


def _ekf_origin(rec: _Records) -> float | None:
    if not rec.timed("ORGN", "Alt", "Type"):
        return None
    kind = rec.raw("ORGN", "Type")
    alt = rec.column("ORGN", "Alt")[kind == 0]
    return float(alt[-1]) if alt.size else None


def _read_references(rec: _Records) -> list[Series]:
    origin = _ekf_origin(rec)
    ekf_datum = "EKF origin" + (f" ({origin:.2f} m AMSL)" if origin is not None else "")
    candidates = [
        _reference(rec, "ekf", "XKF1", "PD", ekf_datum, sign=-1.0)
        or _reference(rec, "ekf", "NKF1", "PD", ekf_datum, sign=-1.0),
        _reference(rec, "ahrs2", "AHR2", "Alt", "AMSL"),
        _reference(rec, "pos", "POS", "Alt", "AMSL"),
        _reference(rec, "ctun", "CTUN", "Alt", "home"),
        # Copter up to 3.1's onboard estimate, its inertial navigation (int16 cm: to 327 m)
        _reference(rec, "inav", "INAV", "IAlt", "home (inertial navigation)"),
        _reference(rec, "sim", "SIM", "Alt", "AMSL (simulator truth)"),
    ]
    return [c for c in candidates if c is not None]


def _read_gps_field(
    rec: _Records, col: str, not_yet: dict[str, npt.NDArray[np.bool_]], sign: float = 1.0
) -> Series | None:
    """``sign`` times ``col`` of the first GPS instance with a 3D fix: its horizontal speed
    over ground (``Spd`` [m/s]), its course over ground (``GCrs`` [deg]), or its vertical
    velocity up (``-VZ`` [m/s]: ArduPilot logs it down); not its records from before its fix
    converged (``not_yet``, per GPS type)."""
    meaning: dict[str, tuple[str, SeriesKind, str]] = {
        "Spd": ("ground_speed", "speed", "horizontal"),
        "GCrs": ("ground_course", "course", "from north"),
        "VZ": ("gps_velocity_up", "velocity", "up"),
    }
    name, kind, datum = meaning[col]
    for type_name in ("GPS", "GPS2", "GPS3"):
        if not rec.timed(type_name, col, "Status"):
            continue
        select = rec.raw(type_name, "Status") >= 3
        if type_name in not_yet:
            select &= ~not_yet[type_name]
        if rec.has(type_name, "I"):
            select &= rec.raw(type_name, "I") == 0
        t, v = rec.times(type_name)[select], sign * rec.column(type_name, col)[select]
        keep = np.isfinite(t) & np.isfinite(v) & ((v >= 0) if col == "Spd" else True)
        if keep.any():
            source = f"{type_name}.{'-' if sign < 0 else ''}{col}"
            return Series(name, kind, source, datum, t[keep], v[keep])
    return None


def _read_vibration(rec: _Records) -> Vibration | None:
    """The first IMU's vibration levels and cumulative clip count (VIBE: ``IMU`` and ``Clip``
    since Copter 4.0, ``Clip0`` before)."""
    if not rec.timed("VIBE", "VibeX", "VibeY", "VibeZ"):
        return None
    select = np.ones(rec.n("VIBE"), dtype=bool)
    if rec.has("VIBE", "IMU"):
        select = rec.raw("VIBE", "IMU") == 0
    clip = next((c for c in ("Clip", "Clip0") if rec.has("VIBE", c)), None)
    if clip is None:
        return None
    level = np.column_stack([rec.column("VIBE", c)[select] for c in ("VibeX", "VibeY", "VibeZ")])
    return Vibration(
        f"VIBE[0].{clip}", rec.times("VIBE")[select], level, rec.raw("VIBE", clip)[select]
    )


def _read_landed(rec: _Records) -> Series | None:
    """The autopilot's on-ground verdict: ``STAT.isFlying`` (Plane, QuadPlane, Rover), 1 where
    it says the vehicle is not flying."""
    if not rec.timed("STAT", "isFlying"):
        return None
    t, flying = rec.times("STAT"), rec.raw("STAT", "isFlying")
    keep = np.isfinite(t)
    if not keep.any():
        return None
    value = (flying[keep] == 0).astype(np.float64)
    return Series("landed", "landed", "STAT.isFlying == 0", "on the ground", t[keep], value)


#: Copter's land detector logs no verdict, only its changes, as ``EV`` records: this one
#: (``LogEvent::NOT_LANDED`` in AP_Logger.h) when it says the vehicle has left the ground.
EV_NOT_LANDED = 28
#: Copter arming without a home (no GPS fix yet: an indoor flight) resets the EKF's height
#: datum, which re-zeroes every barometer at the vehicle's height (``AP_Arming_Copter::arm``,
#: ``NavEKF3_core::resetHeightDatum``: ``AP::baro().update_calibration()``), and logs this
#: event (``LogEvent::EKF_ALT_RESET``): ``BARO.Alt`` steps by what it drifted since boot.
EV_EKF_ALT_RESET = 60
#: A barometer's level on each side of a reset: its median over this span [s], beyond
#: RESET_MARGIN_S of the event (where a sample or two may still read the old zero, or already
#: the new one).
RESET_SPAN_S = 1.0
RESET_MARGIN_S = 0.2
#: Fewest samples on each side for a reset's step to be measured.
RESET_MIN_SAMPLES = 3
#: A step is moved out where it exceeds this many standard errors of the two levels' difference
#: (the event is logged where the EKF did not reset, a rangefinder its height source).
RESET_MIN_SIGMAS = 4.0
#: Most resets one log is taken to hold (one at each arming without a home); a log with more is
#: damaged or hostile, and its resets are not used: each costs a pass over every barometer
#: sample (5 ms over a 300 MB log's 1.2 M; 100 k of them would read for minutes).
RESET_MAX = 100


def _read_events(rec: _Records, *events: int) -> tuple[tuple[float, ...], ...]:
    """Per ``Id`` in ``events``, the times [s] of Copter's ``EV`` records with it."""
    if not rec.timed("EV", "Id"):
        return tuple(() for _ in events)
    t, ids = rec.times("EV"), rec.raw("EV", "Id")
    told = np.isfinite(t)
    return tuple(tuple(sorted(t[told & (ids == event)].tolist())) for event in events)


def rejoined(
    s: Series, resets: tuple[float, ...], takeoffs: tuple[float, ...] = ()
) -> tuple[Series, list[str]]:
    """The height ``s`` (a barometer, or the EKF's own height: the reset zeroes both) made
    continuous across the times ``resets`` [s] its autopilot re-zeroed it on the ground
    (:data:`EV_EKF_ALT_RESET`): the samples before each moved by the step there (the level
    after less the level before, :data:`RESET_SPAN_S`, the level after up to the land
    detector's next ``takeoffs`` time, or over its first RESET_MIN_SAMPLES where that comes
    sooner: an auto take-off may climb a second after arming), so that the ground before it
    and the flight after it share one zero; a note on each step moved. Left as it is where a
    side has too few samples or the step is within the levels' noise."""
    t, value, notes = s.t, s.value.copy(), []
    for at in sorted(resets, reverse=True):  # a later step moves both sides of an earlier one
        before = (t >= at - RESET_MARGIN_S - RESET_SPAN_S) & (t < at - RESET_MARGIN_S)
        after = (t > at + RESET_MARGIN_S) & (t <= at + RESET_MARGIN_S + RESET_SPAN_S)
        flying = min((x for x in takeoffs if x > at), default=math.inf)
        if (after & (t <= flying)).sum() >= RESET_MIN_SAMPLES:
            after &= t <= flying
        else:
            after[np.flatnonzero(after)[RESET_MIN_SAMPLES:]] = False
        if min(before.sum(), after.sum()) < RESET_MIN_SAMPLES:
            continue
        low, high = float(np.median(value[before])), float(np.median(value[after]))
        spread = np.concatenate((value[before] - low, value[after] - high))
        sigma = mad_sigma(spread)
        # a median's standard error: sqrt(pi / 2) that of a mean
        error = math.sqrt(math.pi / 2.0) * sigma * math.sqrt(1 / before.sum() + 1 / after.sum())
        step = high - low
        if not abs(step) > RESET_MIN_SIGMAS * error:
            continue
        # each sample within the margin on the side it reads
        near = (t >= at - RESET_MARGIN_S) & (t <= at + RESET_MARGIN_S)
        moved = (t < at - RESET_MARGIN_S) | (near & (np.abs(value - low) < np.abs(value - high)))
        value[moved] += step
        notes.append(
            f"{s.name}: re-zeroed by the autopilot at {at:.1f} s (EV EKF_ALT_RESET): "
            f"{int(moved.sum())} samples before it moved by its step, {step:+.2f} m"
        )
    return replace(s, value=value), notes


#: The references the same reset zeroes: the EKF's height from its origin (``XKF1.PD``: set to
#: 0 there) and Copter's altitude above home (``CTUN.Alt``); not the EKF's height above sea
#: level (``POS``, ``AHR2``), whose origin moves to keep it, nor the simulator's truth.
RESET_REFERENCES = ("ekf", "ctun")


def _rejoin_resets(
    b: _Builder, references: list[Series], resets: tuple[float, ...], takeoffs: tuple[float, ...]
) -> tuple[Series, ...]:
    """Every barometer of ``b``, and the ``references`` of RESET_REFERENCES (returned),
    :func:`rejoined` across the autopilot's ``resets`` (the land detector's ``takeoffs``
    bounding the ground after each)."""
    if len(resets) > RESET_MAX:
        b.notes.append(
            f"EV EKF_ALT_RESET: {len(resets)} events, more than the {RESET_MAX} armings a log "
            "is taken to hold: not used (the barometers read as logged)"
        )
        return tuple(references)

    def each(s: Series) -> Series:
        out, notes = rejoined(s, resets, takeoffs)
        b.notes.extend(notes)
        return out

    if resets:
        b.sensors.update({n: each(s) for n, s in b.sensors.items() if s.kind == "baro"})
    return tuple(each(r) if resets and r.name in RESET_REFERENCES else r for r in references)


def _read_imu(rec: _Records) -> Imu | None:
    if not rec.timed("IMU", "AccX", "AccY", "AccZ"):
        return None
    select = np.isfinite(rec.times("IMU"))
    if rec.has("IMU", "I"):
        select &= rec.raw("IMU", "I") == 0
    acc = np.column_stack([rec.column("IMU", c)[select] for c in ("AccX", "AccY", "AccZ")])
    return Imu("IMU[0].Acc", rec.times("IMU")[select], acc)


def _read_attitude(rec: _Records) -> Attitude | None:
    if not rec.timed("ATT", "Roll", "Pitch", "Yaw"):
        return None
    timed = np.isfinite(rec.times("ATT"))
    angles = [np.deg2rad(rec.column("ATT", c))[timed] for c in ("Roll", "Pitch", "Yaw")]
    return Attitude("ATT", rec.times("ATT")[timed], *angles)


def _firmware(rec: _Records) -> tuple[str, str]:
    texts = rec.text("VER", "FWS") if rec.has("VER", "FWS") else []
    texts += rec.text("MSG", "Message") if rec.has("MSG", "Message") else []
    for text in texts:
        match = _FIRMWARE_RE.search(text)
        if match:
            return _VEHICLE_OF.get(match.group(1), "unknown"), match.group(0)
    return "unknown", "unknown"


def _skipped(index: Index, notes: list[str]) -> int:
    """The bytes of ``index``'s file in no record, less those where its writing stopped: the
    record it ends inside (the end of nearly every log) or erased flash after its last record
    (a log read off a flash chip), each said in ``notes``."""
    cut = erased = appended = 0
    if index.appended_at is not None:  # another log's: said as damage (read_dataflash)
        appended = index.size - index.appended_at
    elif index.cut_at is not None:
        cut = index.size - index.cut_at
        what = f"{counted(cut, 'byte')} of its header"
        if cut >= HEADER:
            cut_type = index.formats[int(index.data[index.cut_at + 2])]
            what = f"{cut_type.name}, {cut} of its {cut_type.length} bytes"
        notes.append(f"the log ends inside its last record ({what}): read up to the one before")
    elif index.erased_at is not None:
        erased = index.size - index.erased_at
        notes.append(
            f"the log ends in {counted(erased, 'byte')} of erased flash (0xFF) after its last "
            "record: read off a flash chip"
        )
    skipped = index.size - index.decoded_bytes - cut - erased - appended
    if skipped:
        notes.append(f"{counted(skipped, 'byte')} not part of any decodable record")
    return skipped


def _note_clock(b: _Builder) -> None:
    """Say where the times of the records read come from, where not from their own fields;
    a sensor's records with none, in a log where no record has one, are left out, and why."""
    rec = b.rec
    untimed = [n for n in sorted(_RECORDED) if rec.has(n) and rec.time_field(n) is None]
    if not rec.clock:
        for name in untimed:
            if name in _SENSOR_TYPES:
                b.dropped_sources[name] = "no time of its own, and no record in the log has one"
        return
    if all(rec.time_field(n) == ("Time", 1e3) for n in rec.clock):
        times = ", ".join(f"{name}.Time" for name in rec.clock)
        b.notes.append(
            f"the log's times are {times}, the GPS time of week: this firmware logs no time "
            "since boot"
        )
    if untimed:
        b.notes.append(
            f"{', '.join(untimed)}: no time of their own in this firmware, each record timed by "
            "its place between the records around it that have one"
        )


def read_dataflash(path: str | Path, decoded: bool = False) -> FlightLog:
    """Read the altitude sources, IMU, attitude and references from a DataFlash log
    (``decoded``: another file's decoded form, whose bytes are not that file's).

    Raises
    ------
    LogReadError
        pymavlink cannot open the file as a DataFlash log.
    """
    path = Path(path)
    with hashing(path) as digest:
        try:
            rec = _Records(index_file(path))
            said = _appended(rec, decoded)
            if rec.restart is not None:  # the first log alone: the other's clock is its own
                rec = _Records(rec.index.before(rec.restart[0]))
        except OSError as exc:
            raise LogReadError(f"{path}: cannot read ({exc.strerror})") from exc
        flight = _flight(path, rec, digest)
    if said is None:
        return flight
    return replace(flight, notes=(*flight.notes, said), damaged=(*flight.damaged, said))


def _appended(rec: _Records, decoded: bool) -> str | None:
    """What the log says of another log appended to it (:attr:`_Records.restart`); None
    where none is."""
    if rec.restart is None:
        return None
    place, reached, again = rec.restart
    at = None if decoded else int(rec.index.offsets[place])
    clock = f"its clock starts again at {again:.1f} s, where this one's had reached {reached:.1f} s"
    return appended_log(at, rec.index.size, clock)


def _flight(path: Path, rec: _Records, digest: Future[str]) -> FlightLog:
    """The flight in ``rec``, the log at ``path`` whose sha256 ``digest`` is computing."""
    b = _Builder(rec)
    takeoffs, resets = _read_events(rec, EV_NOT_LANDED, EV_EKF_ALT_RESET)
    _note_clock(b)
    _read_gps(b)
    rec.done("GPA", "GPA2", "GPA3")
    have_baro = _read_baro(b)
    rec.done("BARO", "BAR2", "BAR3")
    have_rangefinder = _read_rangefinder(b)
    rec.done("RFND", "SONR")
    _read_ctun_fallbacks(b, have_baro, have_rangefinder)
    vehicle, firmware = _firmware(rec)
    params = _params(rec)
    if vehicle == "unknown" and _SUB_ONLY_PARAMETER in params:
        vehicle = "sub"
    # each type's records go once read: the largest, IMU's, are converted with less beside them
    imu = _read_imu(rec)
    rec.done("IMU")
    attitude = _read_attitude(rec)
    rec.done("ATT")
    vibration = _read_vibration(rec)
    rec.done("VIBE")
    references = _rejoin_resets(b, _read_references(rec), resets, takeoffs)
    rec.done("XKF1", "NKF1", "ORGN", "AHR2", "POS", "CTUN", "INAV", "SIM")
    speed = _read_gps_field(rec, "Spd", b.not_converged)
    course = _read_gps_field(rec, "GCrs", b.not_converged)
    climb = _read_gps_field(rec, "VZ", b.not_converged, sign=-1.0)
    rec.done("GPS", "GPS2", "GPS3")
    skipped = _skipped(rec.index, b.notes)
    for what, problem in rec.problems.items():  # after every read: reading finds some
        b.notes.append(f"{what}: not read: {problem}")
        if what.split(".")[0] in _SENSOR_TYPES:
            b.dropped_sources.setdefault(what, f"not read: {problem}")
    return FlightLog(
        path=str(path),
        sha256=digest.result(),
        size_bytes=rec.index.size,
        vehicle=vehicle,
        firmware=firmware,
        sensors=tuple(b.sensors[k] for k in sorted(b.sensors, key=_sensor_order)),
        references=references,
        imu=imu,
        attitude=attitude,
        record_counts=dict(sorted(rec.counts.items())),
        skipped_bytes=skipped,
        notes=tuple(b.notes),
        dropped_sources=b.dropped_sources,
        params=params,
        ground_speed=speed,
        ground_course=course,
        vertical_velocity=climb,
        vibration=vibration,
        landed=_read_landed(rec),
        takeoffs=takeoffs,
        temperatures=b.temperatures,
    )


def _params(rec: _Records) -> dict[str, float]:
    if not rec.has("PARM", "Name", "Value"):
        return {}
    return dict(zip(rec.text("PARM", "Name"), rec.raw("PARM", "Value").tolist(), strict=True))


def _sensor_order(name: str) -> tuple[int, str]:
    for rank, kind in enumerate(("gps", "baro", "rangefinder")):
        if name.startswith(kind):
            return rank, name
    return 99, name
