"""ArduPilot DataFlash (``.bin``) reader, through pymavlink.

pymavlink is the authority on the format: it parses FMT records, decodes each record and applies
the scale implied by the legacy format characters (``c C e E`` ×0.01, ``L`` ×1e-7). It does not
apply the FMTU multipliers that newer logs use instead (an ``h`` field with multiplier ``B`` holds
centimetres); this module does, from the log's own FMTU/UNIT/MULT records, and checks that every
altitude field is in metres.

The log is read in one sequential pass (``recv_msg``), not through pymavlink's type index: in a
damaged log the index can stop at the first header of an undefined type and hide every later
record, while the sequential parser resynchronises on the header bytes and finds them
(ALGORITHMS.md section 5).

What is read
------------
Altitude sources (inputs):

- ``GPS.Alt`` [m AMSL], only with ``Status >= 3`` (3D fix); every instance (``I`` field or GPS2).
- ``BARO.Alt`` [m above the calibration point], every instance (``I`` or BAR2/BAR3); samples
  flagged unhealthy (``Health``/``H`` == 0) are dropped.
- ``RFND.Dist`` [m above ground] per ``Instance`` (4.x) or ``Dist1``/``Dist2`` (3.x), only with
  ``Stat == 4`` (Good) where Stat is logged, else non-zero; ``SONR`` in old logs.
- Fallbacks: with no BARO records, ``CTUN.BAlt``/``BarAlt``; with no RFND/SONR records,
  ``CTUN.SAlt``/``SonAlt`` (0 there means "no reading"). The choice is noted.

Kept for later stages: IMU (first instance) accelerations, ATT attitude. References, never
inputs: EKF height (``XKF1``/``NKF1`` ``-PD``, with the EKF origin from ``ORGN``), ``AHR2.Alt``,
``POS.Alt``, ``CTUN.Alt`` and the simulator's true altitude ``SIM.Alt``.
"""

from __future__ import annotations

import logging
import math
import re
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink import DFReader

from altfuse.errors import LogReadError
from altfuse.io import sha256_of
from altfuse.io._quiet import captured_output
from altfuse.model import Attitude, FlightLog, FloatArray, Imu, Series

log = logging.getLogger(__name__)

_SENSOR_TYPES = ("GPS", "GPS2", "GPS3", "BARO", "BAR2", "BAR3", "RFND", "SONR", "CTUN")
_OTHER_TYPES = ("IMU", "ATT", "XKF1", "NKF1", "ORGN", "AHR2", "POS", "SIM", "MSG", "VER", "FMTU")
WANTED_TYPES = frozenset(_SENSOR_TYPES + _OTHER_TYPES)

#: Format characters whose scale pymavlink applies itself.
_SELF_SCALED = frozenset("cCeEL")
#: Multiplier ids that mean "none" ('-'), "unknown" ('?') or 1 ('0').
_NO_MULTIPLIER = frozenset("-?0")
_LENGTH_UNITS_OK = frozenset({"m", "", "UNKNOWN"})
_GROUND = "ground below the vehicle"

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


class _Records:
    """The records of the wanted types from one sequential pass, with their unit metadata."""

    def __init__(self, reader: Any) -> None:
        self.reader = reader
        self.by_type: dict[str, list[Any]] = {}
        self.counts: Counter[str] = Counter()
        self.fmtu: dict[int, tuple[str, str]] = {}
        self.decoded_bytes = 0
        self.stopped: str | None = None

    def collect(self) -> None:
        while True:
            try:
                msg = self.reader.recv_msg()
            except Exception as exc:  # pymavlink can raise anything on a damaged record
                self.stopped = f"decoding stopped at byte {self.reader.offset}: {exc}"
                break
            if msg is None:
                break
            name = msg.fmt.name
            self.counts[name] += 1
            self.decoded_bytes += msg.fmt.len
            if name == "FMTU":
                self.fmtu[int(msg.FmtType)] = (str(msg.UnitIds), str(msg.MultIds))
            elif name in WANTED_TYPES:
                self.by_type.setdefault(name, []).append(msg)

    # -- access -----------------------------------------------------------------------------

    def has(self, type_name: str, *fields: str) -> bool:
        msgs = self.by_type.get(type_name)
        return msgs is not None and all(f in msgs[0].fmt.colhash for f in fields)

    def raw(self, type_name: str, col: str) -> FloatArray:
        msgs = self.by_type[type_name]
        return np.fromiter(
            (_as_float(getattr(m, col, math.nan)) for m in msgs), np.float64, len(msgs)
        )

    def column(self, type_name: str, col: str) -> FloatArray:
        """Field values in the field's unit (format scale by pymavlink, FMTU multiplier here)."""
        return self.raw(type_name, col) * self.multiplier(type_name, col)

    def times(self, type_name: str) -> FloatArray:
        """Record times [s]: TimeUS / 1e6, or TimeMS / 1e3 in old logs."""
        if self.has(type_name, "TimeUS"):
            return self.raw(type_name, "TimeUS") / 1e6
        return self.raw(type_name, "TimeMS") / 1e3

    def _field(self, type_name: str, col: str) -> tuple[Any, int]:
        fmt = self.by_type[type_name][0].fmt
        return fmt, fmt.colhash[col]

    def multiplier(self, type_name: str, col: str) -> float:
        fmt, i = self._field(type_name, col)
        if fmt.format[i] in _SELF_SCALED:
            return 1.0
        ids = self.fmtu.get(fmt.type)
        if ids is None or i >= len(ids[1]) or ids[1][i] in _NO_MULTIPLIER:
            return 1.0
        return float(self.reader.mult_lookup.get(ids[1][i], 1.0))

    def unit(self, type_name: str, col: str) -> str:
        fmt, i = self._field(type_name, col)
        ids = self.fmtu.get(fmt.type)
        if ids is None or i >= len(ids[0]):
            return ""
        return str(self.reader.unit_lookup.get(ids[0][i], ""))


def _as_float(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _instances(rec: _Records, type_name: str, field: str, default: int) -> Iterator[Any]:
    """Yield (instance number, boolean mask) for each instance in ``type_name``'s records."""
    n = len(rec.by_type[type_name])
    if not rec.has(type_name, field):
        yield default, np.ones(n, dtype=bool)
        return
    inst = rec.raw(type_name, field)
    for i in np.unique(inst[np.isfinite(inst)]):
        yield int(i), inst == i


def _instance_name(kind: str, instance: int) -> str:
    return kind if instance == 0 else f"{kind}{instance + 1}"


class _Builder:
    """Collects the sources found in a log, with the reason for every one left out."""

    def __init__(self, rec: _Records) -> None:
        self.rec = rec
        self.sensors: dict[str, Series] = {}
        self.dropped_sources: dict[str, str] = {}
        self.notes: list[str] = []

    def add(
        self,
        *,
        name: str,
        kind: str,
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
        t = self.rec.times(type_name)[select]
        value = self.rec.column(type_name, col)[select]
        keep = np.isfinite(t) & np.isfinite(value)
        dropped: dict[str, int] = {}
        if (~keep).any():
            dropped["not a finite number"] = int((~keep).sum())
        for reason, mask in (invalid or {}).items():
            hit = keep & mask[select]
            if hit.any():
                dropped[reason] = int(hit.sum())
            keep &= ~mask[select]
        if not keep.any():
            detail = ", ".join(f"{n} {r}" for r, n in dropped.items()) or "no records"
            self.dropped_sources[name] = f"{source}: no usable sample ({detail})"
            return
        self.sensors[name] = Series(
            name=name,
            kind=kind,
            source=source,
            datum=datum,
            t=t[keep],
            value=value[keep],
            dropped=dropped,
        )


def _add_instances(
    b: _Builder,
    kind: str,
    type_name: str,
    col: str,
    datum: str,
    *,
    instance_field: str,
    default: int,
    invalid: dict[str, Any],
) -> None:
    """Add one series per instance of ``type_name.col``, named ``kind``, ``kind2``, ..."""
    for inst, sel in _instances(b.rec, type_name, instance_field, default):
        b.add(
            name=_instance_name(kind, inst),
            kind=kind,
            type_name=type_name,
            col=col,
            datum=datum,
            select=sel,
            invalid=invalid,
        )


def _read_gps(b: _Builder) -> None:
    for default, type_name in enumerate(("GPS", "GPS2", "GPS3")):
        if not b.rec.has(type_name, "Alt", "Status"):
            continue
        no_fix = b.rec.raw(type_name, "Status") < 3
        _add_instances(
            b,
            "gps",
            type_name,
            "Alt",
            "AMSL",
            instance_field="I",
            default=default,
            invalid={"GPS Status < 3 (no 3D fix)": no_fix},
        )


def _read_baro(b: _Builder) -> bool:
    found = False
    for default, type_name in enumerate(("BARO", "BAR2", "BAR3")):
        if not b.rec.has(type_name, "Alt"):
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
    return found


def _rangefinder_invalid(b: _Builder, type_name: str, dist: str, stat: str) -> dict[str, Any]:
    if b.rec.has(type_name, stat):
        return {"Stat != 4 (not Good)": b.rec.raw(type_name, stat) != 4}
    return {"0 (no reading)": b.rec.raw(type_name, dist) <= 0}


def _read_rangefinder(b: _Builder) -> bool:
    found = False
    rfnd = "RFND"
    if b.rec.has(rfnd, "Dist"):
        found = True
        _add_instances(
            b,
            "rangefinder",
            rfnd,
            "Dist",
            _GROUND,
            instance_field="Instance",
            default=0,
            invalid=_rangefinder_invalid(b, rfnd, "Dist", "Stat"),
        )
    elif rfnd in b.rec.by_type:
        for inst in (0, 1):
            dist = f"Dist{inst + 1}"
            if not b.rec.has(rfnd, dist):
                continue
            found = True
            b.add(
                name=_instance_name("rangefinder", inst),
                kind="rangefinder",
                type_name=rfnd,
                col=dist,
                datum=_GROUND,
                select=np.ones(len(b.rec.by_type[rfnd]), dtype=bool),
                invalid=_rangefinder_invalid(b, rfnd, dist, f"Stat{inst + 1}"),
            )
    for col in ("Dist", "DistCM"):
        if not found and b.rec.has("SONR", col):
            found = True
            b.add(
                name="rangefinder",
                kind="rangefinder",
                type_name="SONR",
                col=col,
                datum=_GROUND,
                select=np.ones(len(b.rec.by_type["SONR"]), dtype=bool),
                invalid={"0 (no reading)": b.rec.raw("SONR", col) <= 0},
            )
    return found


def _read_ctun_fallbacks(b: _Builder, have_baro: bool, have_rangefinder: bool) -> None:
    if "CTUN" not in b.rec.by_type:
        return
    everything = np.ones(len(b.rec.by_type["CTUN"]), dtype=bool)
    if not have_baro:
        for col in ("BAlt", "BarAlt"):
            if b.rec.has("CTUN", col):
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
            if not b.rec.has("CTUN", col):
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
    if not rec.has(type_name, col):
        return None
    select = np.ones(len(rec.by_type[type_name]), dtype=bool)
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
    if not rec.has("ORGN", "Alt", "Type"):
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
        _reference(rec, "sim", "SIM", "Alt", "AMSL (simulator truth)"),
    ]
    return [c for c in candidates if c is not None]


def _read_imu(rec: _Records) -> Imu | None:
    if not rec.has("IMU", "AccX", "AccY", "AccZ"):
        return None
    select = np.ones(len(rec.by_type["IMU"]), dtype=bool)
    if rec.has("IMU", "I"):
        select = rec.raw("IMU", "I") == 0
    acc = np.column_stack([rec.column("IMU", c)[select] for c in ("AccX", "AccY", "AccZ")])
    return Imu("IMU[0].Acc", rec.times("IMU")[select], acc)


def _read_attitude(rec: _Records) -> Attitude | None:
    if not rec.has("ATT", "Roll", "Pitch", "Yaw"):
        return None
    angles = [np.deg2rad(rec.column("ATT", c)) for c in ("Roll", "Pitch", "Yaw")]
    return Attitude("ATT", rec.times("ATT"), *angles)


def _firmware(rec: _Records) -> tuple[str, str]:
    texts = [str(getattr(m, "FWS", "")) for m in rec.by_type.get("VER", [])]
    texts += [str(getattr(m, "Message", "")) for m in rec.by_type.get("MSG", [])]
    for text in texts:
        match = _FIRMWARE_RE.search(text)
        if match:
            return _VEHICLE_OF.get(match.group(1), "unknown"), match.group(0)
    return "unknown", "unknown"


def read_dataflash(path: str | Path) -> FlightLog:
    """Read the altitude sources, IMU, attitude and references from a DataFlash log.

    Raises
    ------
    LogReadError
        pymavlink cannot open the file as a DataFlash log.
    """
    path = Path(path)
    with captured_output() as printed:
        try:
            reader = DFReader.DFReader_binary(str(path), zero_time_base=False)
        except Exception as exc:
            raise LogReadError(f"{path}: not a readable DataFlash log ({exc})") from exc
        rec = _Records(reader)
        try:
            rec.collect()
        finally:
            reader.filehandle.close()
    if printed:
        log.debug("pymavlink printed %d lines while reading %s", len(printed), path)

    b = _Builder(rec)
    _read_gps(b)
    have_baro = _read_baro(b)
    have_rangefinder = _read_rangefinder(b)
    _read_ctun_fallbacks(b, have_baro, have_rangefinder)
    if rec.stopped:
        b.notes.append(rec.stopped)
    vehicle, firmware = _firmware(rec)
    skipped = max(0, int(reader.data_len) - rec.decoded_bytes)
    if skipped:
        b.notes.append(f"{skipped} bytes were not part of any decodable record")
    return FlightLog(
        path=str(path),
        sha256=sha256_of(path),
        size_bytes=int(reader.data_len),
        vehicle=vehicle,
        firmware=firmware,
        sensors=tuple(b.sensors[k] for k in sorted(b.sensors, key=_sensor_order)),
        references=tuple(_read_references(rec)),
        imu=_read_imu(rec),
        attitude=_read_attitude(rec),
        record_counts=dict(sorted(rec.counts.items())),
        skipped_bytes=skipped,
        notes=tuple(b.notes),
        dropped_sources=b.dropped_sources,
    )


def _sensor_order(name: str) -> tuple[int, str]:
    for rank, kind in enumerate(("gps", "baro", "rangefinder")):
        if name.startswith(kind):
            return rank, name
    return 99, name
