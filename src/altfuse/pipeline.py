"""read -> align -> datum -> fuse, with the provenance of every step."""

from __future__ import annotations

import inspect
import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from altfuse import __version__
from altfuse.align import Aligned, align, check_align_parameters, merge_duplicates
from altfuse.datum import Referred, check_datum_parameters, refer_to_takeoff, tilt_correct
from altfuse.errors import NoUsableSensorsError, ParameterError, UnsupportedLogError
from altfuse.fuse import FUSERS, LOG_INPUTS, FusionResult
from altfuse.inertial import on_clock, vertical_acceleration
from altfuse.io import read_log
from altfuse.model import FlightLog, FloatArray, Series

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FuseOptions:
    """Everything that decides a fusion run besides the log itself."""

    method: str = "support"
    rate_hz: float = 10.0
    max_gap_s: float = 1.0
    span: str = "union"
    ground_s: float = 5.0
    climb_m: float = 1.0
    min_sensors: int = 2
    params: dict[str, Any] = field(default_factory=dict)

    def check(self) -> None:
        """Raise :class:`ParameterError` before any work if an option means nothing."""
        if self.method not in FUSERS:
            raise ParameterError(
                f"unknown method {self.method!r}; choose one of {', '.join(FUSERS)}"
            )
        accepted = inspect.signature(FUSERS[self.method]).parameters
        for name in self.params:
            if name not in accepted or name == "z" or name in LOG_INPUTS:
                raise ParameterError(
                    f"--{name.replace('_', '-')} does not apply to method {self.method!r}"
                )
        check_align_parameters(self.rate_hz, self.max_gap_s, self.span)
        check_datum_parameters(self.ground_s, self.climb_m)
        if self.min_sensors < 1:
            raise ParameterError(f"--min-sensors must be at least 1, got {self.min_sensors}")


@dataclass(frozen=True)
class FuseRun:
    """The value of every stage of one run, and the provenance record built from them."""

    log: FlightLog
    aligned: Aligned
    referred: Referred
    result: FusionResult
    options: FuseOptions
    provenance: dict[str, Any]


def _require_sensors(
    log_name: str, names: tuple[str, ...], options: FuseOptions, dropped: dict[str, str]
) -> None:
    if len(names) >= options.min_sensors:
        return
    why = "".join(f"; {k}: {v}" for k, v in dropped.items())
    if not names:
        raise NoUsableSensorsError(
            f"{log_name}: no usable altitude source (looked for GPS, BARO, RFND, SONR, CTUN){why}"
        )
    raise NoUsableSensorsError(
        f"{log_name}: {len(names)} usable altitude source ({', '.join(names)}) where --min-sensors "
        f"is {options.min_sensors}{why}; --min-sensors 1 writes a single source"
    )


@dataclass(frozen=True)
class Prepared:
    """The method-independent stages of a run: sources tilt-corrected, aligned and referred."""

    log: FlightLog
    sensors: list[Series]
    aligned: Aligned
    referred: Referred
    dropped: dict[str, str]


def prepare(flight: FlightLog, options: FuseOptions) -> Prepared:
    """Tilt-correct, align and refer the altitude sources of ``flight`` to take-off."""
    options.check()
    name = Path(flight.path).name
    if flight.vehicle == "sub":
        raise UnsupportedLogError(
            f"{name}: an ArduSub log; its BARO is water depth, "
            "and altfuse fuses the altitude of aircraft"
        )
    dropped = dict(flight.dropped_sources)
    _require_sensors(name, tuple(s.name for s in flight.sensors), options, dropped)
    started = time.perf_counter()
    sensors = [tilt_correct(s, flight.attitude) for s in flight.sensors]
    sensors = [s for s in sensors if s.t.size]
    aligned = align(sensors, options.rate_hz, options.max_gap_s, options.span)
    aligned_at = time.perf_counter()
    referred = refer_to_takeoff(aligned, options.ground_s, options.climb_m)
    log.info(
        "%s: aligned %d ticks in %.2f s, datum in %.2f s",
        name,
        aligned.t.size,
        aligned_at - started,
        time.perf_counter() - aligned_at,
    )
    dropped.update(referred.dropped)
    _require_sensors(name, referred.names, options, dropped)
    return Prepared(flight, sensors, aligned, referred, dropped)


def run_method(prepared: Prepared, options: FuseOptions) -> FuseRun:
    """Fuse prepared sources with ``options.method`` and its parameters."""
    options.check()
    flight, referred = prepared.log, prepared.referred
    fuser = FUSERS[options.method]
    inputs: dict[str, Any] = {}
    wanted = _params(fuser)
    accel_record: dict[str, Any] | None = None
    if "accel_up" in wanted:
        inputs["accel_up"], accel_record = accel_on_clock(flight, referred, options)
    if "accel" in wanted:
        inputs["accel"], accel_record = accel_samples(flight, referred, options)
    if "dt_s" in wanted:
        inputs["dt_s"] = 1.0 / options.rate_hz
    if "samples" in wanted:
        inputs["samples"] = referred_samples(prepared)
    if "on_ground" in wanted:
        inputs["on_ground"] = referred.on_ground_s
    if "speed" in wanted:
        speed = flight.ground_speed
        inputs["speed"] = None if speed is None else (speed.t, speed.value)
    if "temperatures" in wanted:
        temps = flight.temperatures
        inputs["temperatures"] = [
            (temps[n].t, temps[n].value) if n in temps else None for n in referred.names
        ]
    for name, value in (("t", referred.t), ("kinds", referred.kinds), ("names", referred.names)):
        if name in wanted:
            inputs[name] = value
    started = time.perf_counter()
    result = fuser(referred.h, **inputs, **options.params)
    log.info(
        "%s: fused with %s in %.2f s",
        Path(flight.path).name,
        options.method,
        time.perf_counter() - started,
    )
    record = provenance(prepared, result)
    record["options"] = asdict(options)
    if accel_record is not None:
        record["vertical_acceleration"] = accel_record
    return FuseRun(
        log=flight,
        aligned=prepared.aligned,
        referred=referred,
        result=result,
        options=options,
        provenance=record,
    )


def accel_on_clock(
    flight: FlightLog, referred: Referred, options: FuseOptions
) -> tuple[FloatArray, dict[str, Any]]:
    """Earth-frame vertical acceleration on the clock, less its at-rest reading."""
    _, _, a_clock, record = _vertical(flight, referred, options)
    return a_clock - record["at_rest_bias_m_s2"], record


def _vertical(
    flight: FlightLog, referred: Referred, options: FuseOptions
) -> tuple[FloatArray, FloatArray, FloatArray, dict[str, Any]]:
    """The vertical acceleration samples, their averages on the clock, and the at-rest reading.

    Paper B subtracts the at-rest reading; here it is the median of ``a_up`` over the datum's
    ground window (the vehicle still, on the ground or in a steady hover). The median, because
    that window can end in the first second of a gentle take-off.
    """
    missing = [n for n, v in (("IMU", flight.imu), ("ATT", flight.attitude)) if v is None]
    if flight.imu is None or flight.attitude is None:
        others = ", ".join(m for m, f in FUSERS.items() if "accel_up" not in _params(f))
        raise NoUsableSensorsError(
            f"{Path(flight.path).name}: method {options.method!r} needs the accelerometer, and "
            f"the log has no {' or '.join(missing)} records; {others} work without it"
        )
    t, a = vertical_acceleration(flight.imu, flight.attitude)
    a_clock = on_clock(t, a, referred.t, options.rate_hz)
    lo, hi = referred.ground_window_s
    still = (referred.t >= lo) & (referred.t <= hi) & np.isfinite(a_clock)
    bias = float(np.median(a_clock[still])) if still.any() else 0.0
    record = {
        "source": f"{flight.imu.source} rotated by {flight.attitude.source}",
        "at_rest_bias_m_s2": bias,
        "bias_window_s": [lo, hi],
        "ticks_without_imu": int((~np.isfinite(a_clock)).sum()),
    }
    return t, a, a_clock, record


def accel_samples(
    flight: FlightLog, referred: Referred, options: FuseOptions
) -> tuple[tuple[FloatArray, FloatArray] | None, dict[str, Any]]:
    """The vertical acceleration samples less the at-rest reading of :func:`accel_on_clock`, or
    None (and the record says so) when the log has no IMU or ATT."""
    if flight.imu is None or flight.attitude is None:
        return None, {"source": None, "note": "no IMU or ATT records: altitude-only model"}
    t, a, _, record = _vertical(flight, referred, options)
    return (t, a - record["at_rest_bias_m_s2"]), record


def referred_samples(prepared: Prepared) -> list[tuple[FloatArray, FloatArray]]:
    """Each fused sensor's own samples (time, height above take-off), in the clock's order."""
    by_name = {s.name: s for s in prepared.sensors}
    out = []
    for o in prepared.referred.offsets:
        s = by_name[o.name]
        t, v = merge_duplicates(s.t, s.value - o.offset_m)
        out.append((t, v))
    return out


def _params(fuser: Any) -> set[str]:
    return set(inspect.signature(fuser).parameters)


def fuse_flight(flight: FlightLog, options: FuseOptions) -> FuseRun:
    """Fuse the altitude sources of an already-read log."""
    return run_method(prepare(flight, options), options)


def fuse_log(path: str | Path, options: FuseOptions | None = None) -> FuseRun:
    """Read the log at ``path`` and fuse its altitude sources (the ``altfuse fuse`` job)."""
    options = options or FuseOptions()
    options.check()
    started = time.perf_counter()
    flight = read_log(path)
    log.info(
        "%s: read %d bytes in %.2f s",
        Path(path).name,
        flight.size_bytes,
        time.perf_counter() - started,
    )
    return fuse_flight(flight, options)


def provenance(prepared: Prepared, result: FusionResult) -> dict[str, Any]:
    """How the output was made: enough to reproduce it and to judge it."""
    flight, aligned, referred = prepared.log, prepared.aligned, prepared.referred
    statuses, counts = np.unique(result.status, return_counts=True)
    return {
        "altfuse_version": __version__,
        "input": {
            "file": Path(flight.path).name,
            "sha256": flight.sha256,
            "size_bytes": flight.size_bytes,
            "vehicle": flight.vehicle,
            "firmware": flight.firmware,
            "skipped_bytes": flight.skipped_bytes,
            "notes": list(flight.notes),
        },
        "method": result.method,
        "parameters": result.params,
        "clock": {
            "rate_hz": aligned.rate_hz,
            "max_gap_s": aligned.max_gap_s,
            "span": aligned.span,
            "start_s": float(aligned.t[0]),
            "end_s": float(aligned.t[-1]),
            "ticks": int(aligned.t.size),
            "time": "seconds since the autopilot booted (TimeUS / 1e6)",
        },
        "datum": {
            "meaning": "height above the take-off point [m]",
            "reference": referred.reference,
            "takeoff_s": referred.takeoff_s,
            "ground_window_s": list(referred.ground_window_s),
            "offsets": [
                {
                    "sensor": o.name,
                    "offset_m": o.offset_m,
                    "method": o.method,
                    "window_s": list(o.window_s),
                    "ticks": o.ticks,
                }
                for o in referred.offsets
            ],
        },
        "sensors_used": [
            {
                "name": s.name,
                "kind": s.kind,
                "source": s.source,
                "raw_datum": s.datum,
                "samples": int(s.t.size),
                "samples_dropped": s.dropped,
                "alignment": vars(aligned.stats[s.name]),
            }
            for s in prepared.sensors
            if s.name in referred.names
        ],
        "sensors_dropped": prepared.dropped,
        "references": [
            {"name": r.name, "source": r.source, "datum": r.datum, "samples": int(r.t.size)}
            for r in flight.references
        ],
        "status_counts": {str(s): int(c) for s, c in zip(statuses, counts, strict=True)},
    }
