"""What a log holds, for ``altfuse info``: sources, rates, ranges, gaps and references."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from altfuse.model import FlightLog, Series
from altfuse.screen import implausible_count

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
    """One line on what reading left out: bytes skipped, implausible samples dropped."""
    parts = []
    if flight.skipped_bytes:
        parts.append(f"{flight.skipped_bytes} bytes skipped (not part of any decodable record)")
    implausible = implausible_count(flight)
    if implausible:
        per = ", ".join(f"{name} {n}" for name, n in implausible.items())
        parts.append(f"{sum(implausible.values())} implausible samples dropped ({per})")
    return f"{Path(flight.path).name}: " + "; ".join(parts) if parts else None


def describe(flight: FlightLog) -> dict[str, Any]:
    """A JSON-ready summary of ``flight``."""
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
        "skipped_bytes": flight.skipped_bytes,
        "samples_dropped_total": sum(sum(s.dropped.values()) for s in flight.sensors),
        "implausible_samples": implausible_count(flight),
        "record_counts": flight.record_counts,
        "notes": list(flight.notes),
    }
