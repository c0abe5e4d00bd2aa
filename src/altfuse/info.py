"""What a log holds, for ``altfuse info``: sources, rates, ranges, gaps and references, and how
``altfuse fuse`` puts them on one clock and one datum."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from altfuse.errors import AltfuseError
from altfuse.inertial import VIBE_ACCEPTABLE_M_S2, VIBE_PROBLEM_M_S2, vibration_record
from altfuse.model import FlightLog, Series, counted
from altfuse.pipeline import (
    FuseOptions,
    Prepared,
    prepare,
    segment_record,
    span_record,
    step_record,
    wind_record,
)
from altfuse.screen import implausible_count, screen, screened_out

#: A pause between two samples longer than this counts as a gap [s].
GAP_S = 1.0


def describe_series(s: Series) -> dict[str, Any]:
    t = np.sort(s.t)
    dt = np.diff(t)
    gaps = dt[dt > GAP_S]
    return {
        "name": s.name,
        "kind": s.kind,
        "source": s.source,
        "datum": s.datum,
        "samples": int(t.size),
        "rate_hz": float(1.0 / np.median(dt)) if dt.size and np.median(dt) > 0 else None,
        "start_s": float(t[0]),
        "end_s": float(t[-1]),
        "min_m": float(np.min(s.value)),
        "max_m": float(np.max(s.value)),
        "gaps_over_1s": int(gaps.size),
        "longest_gap_s": float(gaps.max()) if gaps.size else 0.0,
        "samples_dropped": dict(s.dropped),
    }


def damage(flight: FlightLog) -> str | None:
    """One line on what reading left out: damage, bytes skipped, implausible samples dropped."""
    parts = list(flight.damaged)
    if flight.skipped_bytes:
        parts.append(
            f"{counted(flight.skipped_bytes, 'byte')} skipped (not part of any decodable record)"
        )
    implausible = implausible_count(flight)
    if implausible:
        per = ", ".join(f"{name} {n}" for name, n in implausible.items())
        parts.append(f"{counted(sum(implausible.values()), 'implausible sample')} dropped ({per})")
    gone = screened_out(flight)
    if gone:
        parts.append(f"{', '.join(gone)} left out: no plausible sample")
    return f"{Path(flight.path).name}: " + "; ".join(parts) if parts else None


def describe(raw: FlightLog) -> dict[str, Any]:
    """A JSON-ready summary of the log ``raw`` as read, screened, and referred as ``altfuse
    fuse`` would with its defaults (one source is enough here); ``datum`` says why not where
    it cannot be."""
    try:
        prepared: Prepared | None = prepare(raw, FuseOptions(min_sensors=1))
    except AltfuseError as exc:
        prepared, why = None, str(exc)
    flight = prepared.log if prepared is not None else screen(raw)
    sensors = [describe_series(s) for s in flight.sensors]
    spans = [(d["start_s"], d["end_s"]) for d in sensors]
    return {
        "file": Path(flight.path).name,
        "sha256": flight.sha256,
        "size_bytes": flight.size_bytes,
        "vehicle": flight.vehicle,
        "firmware": flight.firmware,
        "sensor_span_s": ([min(a for a, _ in spans), max(b for _, b in spans)] if spans else None),
        "duration_s": (max(b for _, b in spans) - min(a for a, _ in spans)) if spans else 0.0,
        "sensors": sensors,
        "sensors_dropped": dict(flight.dropped_sources),
        "references": [describe_series(r) for r in flight.references],
        "imu": None
        if flight.imu is None
        else {"source": flight.imu.source, "samples": int(flight.imu.t.size)},
        "attitude": None
        if flight.attitude is None
        else {"source": flight.attitude.source, "samples": int(flight.attitude.t.size)},
        # how far to trust the accelerometer, as the autopilot logged it (VIBE)
        "vibration": None if flight.vibration is None else vibration_record(flight.vibration),
        "reader": flight.reader,
        "skipped_bytes": flight.skipped_bytes,
        "damaged": list(flight.damaged),
        "samples_dropped_total": sum(sum(s.dropped.values()) for s in flight.sensors),
        "implausible_samples": implausible_count(flight),
        "record_counts": flight.record_counts,
        "notes": list(flight.notes),
        "datum": {"not referred": why} if prepared is None else describe_datum(prepared),
    }


def describe_datum(prepared: Prepared) -> dict[str, Any]:
    """Each source's lag, offset and scale, the take-off, its lift-off, the span the smoother
    holds the vehicle still and the one it offers the barometers a wash in, the segments and the
    steps between sensors."""
    referred = prepared.referred
    return {
        "takeoff_s": referred.takeoff_s,
        "liftoff_s": referred.liftoff_s,
        "still_s": span_record(referred.on_ground_s),
        "wash_s": span_record(referred.ground_effect_s),
        "segments": [segment_record(s) for s in referred.segments],
        "steps": [step_record(s) for s in referred.steps],
        "wind": wind_record(referred.wind),
        "sensors": [
            {
                "name": o.name,
                "lag_s": prepared.lags[o.name].lag_s if o.name in prepared.lags else None,
                "lag": prepared.lags[o.name].how if o.name in prepared.lags else None,
                "offset_m": o.offset_m,
                "offset": o.method,
                "scale": o.scale,
                "scale_method": o.scale_method,
            }
            for o in referred.offsets
        ],
    }


def as_text(summary: dict[str, Any]) -> list[str]:
    """The lines ``altfuse info`` prints for a :func:`describe` summary."""
    lines = [
        f"{summary['file']}: {summary['vehicle']} ({summary['firmware']}), "
        f"{summary['size_bytes']} bytes, sensors over {summary['duration_s']:.1f} s",
        "altitude sources:",
    ]
    # a column as wide as its longest source (PX4's: vehicle_air_data[0].baro_alt_meter)
    width = max([14, *(len(s["source"]) for s in summary["sensors"])])
    for s in summary["sensors"]:
        rate = f"{s['rate_hz']:.1f} Hz" if s["rate_hz"] else "? Hz"
        dropped = ", ".join(f"{n} {r}" for r, n in s["samples_dropped"].items())
        lines.append(
            f"  {s['name']:<12} {s['source']:<{width}} {rate:>8} {s['samples']:>7} samples "
            f"{s['min_m']:9.2f} .. {s['max_m']:9.2f} m  {s['start_s']:.1f}-{s['end_s']:.1f} s  "
            f"gaps>1s {s['gaps_over_1s']} (longest {s['longest_gap_s']:.1f} s)"
            + (f"  dropped: {dropped}" if dropped else "")
        )
    if not summary["sensors"]:
        lines.append("  none")
    lines += [f"  {name:<12} not used: {why}" for name, why in summary["sensors_dropped"].items()]
    lines += _datum_text(summary["datum"])
    refs = ", ".join(f"{r['name']} ({r['source']}, {r['datum']})" for r in summary["references"])
    imu, att = summary["imu"], summary["attitude"]
    names = {s["name"] for s in summary["sensors"]}
    implausible = summary["implausible_samples"]
    of_sensors = sum(n for name, n in implausible.items() if name in names)
    inputs = ", ".join(f"{name} {n}" for name, n in implausible.items() if name not in names)
    lines += [
        f"references (never fused): {refs or 'none'}",
        f"IMU: {imu['samples'] if imu else 'no'} samples; "
        f"attitude: {att['samples'] if att else 'no'} samples; "
        f"vibration: {_vibration_text(summary['vibration'])}",
        f"skipped bytes: {summary['skipped_bytes']}",
        f"dropped samples: {summary['samples_dropped_total']} of the altitude sources "
        f"({of_sensors} implausible; the others filtered by the reader or beyond a "
        "rangefinder's range: each source's line)",
        *([f"dropped as implausible from the other inputs: {inputs}"] if inputs else []),
    ]
    return lines + [f"note: {note}" for note in summary["notes"]]


def _vibration_text(vibration: dict[str, Any] | None) -> str:
    """The accelerometer's health (:func:`altfuse.inertial.vibration_record`) in a few words."""
    if vibration is None:
        return "not logged"
    clipped = vibration["clipped_samples"]
    return (
        f"up to {vibration['max_level_m_s2']:.1f} m/s² ({vibration['above_acceptable_s']:.1f} s "
        f"above {VIBE_ACCEPTABLE_M_S2:g}, {vibration['above_problem_s']:.1f} s above "
        f"{VIBE_PROBLEM_M_S2:g}), {clipped} sample{'' if clipped == 1 else 's'} clipped"
        + (f" (first at {vibration['clipped_at_s'][0]:.1f} s)" if clipped else "")
    )


def _datum_text(datum: dict[str, Any]) -> list[str]:
    if "not referred" in datum:
        return [f"clock and datum: not referred: {datum['not referred']}"]
    lines = ["clock and datum (as fuse refers them):"]
    for s in datum["sensors"]:
        lag = f"lag {s['lag_s']:.2f} s ({s['lag']}); " if s["lag"] else ""
        scale = f"; scale {s['scale']:.4f} ({s['scale_method']})" if s["scale_method"] else ""
        lines.append(f"  {s['name']:<12} {lag}offset {s['offset_m']:.2f} m ({s['offset']}){scale}")
    if datum["takeoff_s"] is not None:
        lift = "" if datum["liftoff_s"] is None else f", lift-off {datum['liftoff_s']:.1f} s"
        still = datum["still_s"]
        held = (
            ""
            if still is None
            else f"; the smoother holds it still {still[0]:.1f}-{still[1]:.1f} s"
        )
        wash = datum["wash_s"]
        washed = (
            "" if wash is None else f"; its barometers' wash tested {wash[0]:.1f}-{wash[1]:.1f} s"
        )
        lines.append(f"  take-off {datum['takeoff_s']:.1f} s{lift}{held}{washed}")
    lines += [
        f"  segment {s['start_s']:.1f}-{s['end_s']:.1f} s: datum {s['datum']}"
        for s in datum["segments"]
    ]
    lines += [
        f"  step at {s['time_s']:.2f} s: {s['between'][1]} less {s['between'][0]} "
        f"{s['size_m']:+.2f} m ({s['sigmas']:.0f} sigma)"
        for s in datum["steps"]
    ]
    return lines
