"""Referring every aligned source to height above the take-off point (ALGORITHMS.md section 4).

GPS measures height above mean sea level, the barometer height above wherever it was calibrated,
the rangefinder height above the ground under the vehicle. Paper A fuses them as if they shared a
datum (its table shows all three near 15 m). Here each source ``i`` becomes ``h_i = z_i - c_i``
with one constant offset ``c_i``, found in this order:

1. **On the ground**: the median of the source over the *ground window*, the ``ground_s`` seconds
   that end one second before take-off. Take-off is the first tick at which the reference source
   (the first barometer, else the first GPS, else the rangefinder; 1 s running median) rises
   ``climb_m`` above its level over the first ``ground_s`` seconds of the log. A log with no such
   rise (a log that starts in flight, a bench test) uses its first ``ground_s`` seconds instead,
   and says so.
2. **Matched to the reference**: a source with no samples in the ground window (a GPS without a
   fix at take-off, a rangefinder out of range on the ground) takes the median of its difference
   from the referred reference over the first ``ground_s`` seconds where both are valid.
3. Otherwise it is dropped, with that reason.

A constant offset is all that is removed: a source that is right but offset keeps its full
weight, and drift (the barometer's) stays in the data, where fusion is meant to see it.

Before that, :func:`tilt_correct` turns a rangefinder's distance along the body's down axis into a
vertical height, ``d * cos(roll) * cos(pitch)``, with the logged attitude (``CTUN.SAlt`` comes
tilt-corrected by the autopilot and is left alone).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
import pandas as pd

from altfuse.align import Aligned, merge_duplicates
from altfuse.errors import NoUsableSensorsError
from altfuse.model import SENSOR_KINDS, Attitude, FloatArray, Samples, SensorKind, Series

#: Fewest valid ticks a window must hold for an offset to be measured on it.
MIN_WINDOW_TICKS = 3
#: The ground window ends this long before the detected take-off [s].
TAKEOFF_MARGIN_S = 1.0
#: The vehicle is taken to stand still until this long before the detected take-off [s]: a gentle
#: climb can take 2-3 s to rise the 1 m that detects it (0.3 m at the ground window's end).
STILL_MARGIN_S = 3.0


@dataclass(frozen=True)
class Offset:
    """The constant removed from one source, and how it was found."""

    name: str
    offset_m: float
    method: str
    window_s: tuple[float, float]
    ticks: int


@dataclass(frozen=True)
class Referred:
    """Heights above take-off [m] on the aligned clock, for the sources that could be referred."""

    t: FloatArray
    names: tuple[str, ...]
    kinds: tuple[SensorKind, ...]
    h: FloatArray
    reference: str
    takeoff_s: float | None
    ground_window_s: tuple[float, float]
    offsets: tuple[Offset, ...]
    dropped: dict[str, str]

    @property
    def on_ground_s(self) -> tuple[float, float] | None:
        """The span in which the vehicle stood still at the take-off point: the ground window
        up to ``STILL_MARGIN_S`` before a detected take-off; None if it is empty or there was no
        take-off."""
        if self.takeoff_s is None:
            return None
        lo, hi = self.ground_window_s
        hi = min(hi, self.takeoff_s - STILL_MARGIN_S)
        return (lo, hi) if hi > lo else None


def tilt_correct(series: Series, attitude: Attitude | None) -> Series:
    """Vertical height from a downward rangefinder's distance [m]: ``d cos(roll) cos(pitch)``.

    Only for ``RFND``/``SONR`` distances, and only where the attitude covers the sample (the
    samples outside its time range are dropped, counted in ``dropped``). Without attitude the
    series is returned unchanged, and its datum says so.
    """
    if series.kind != "rangefinder" or not series.source.startswith(("RFND", "SONR")):
        return series
    if attitude is None or attitude.t.size < 2:
        return replace(series, datum=f"{series.datum} (not tilt-corrected: no attitude)")
    inside = (series.t >= attitude.t[0]) & (series.t <= attitude.t[-1])
    roll = np.interp(series.t[inside], attitude.t, attitude.roll)
    pitch = np.interp(series.t[inside], attitude.t, attitude.pitch)
    dropped = dict(series.dropped)
    if (~inside).any():
        dropped["outside the attitude's time range"] = int((~inside).sum())
    return replace(
        series,
        datum=f"{series.datum} (tilt-corrected with {attitude.source})",
        t=series.t[inside],
        value=series.value[inside] * np.cos(roll) * np.cos(pitch),
        dropped=dropped,
    )


def choose_reference(aligned: Aligned) -> int:
    """Index of the datum reference: the first kind in SENSOR_KINDS order with most valid ticks."""
    valid = np.isfinite(aligned.z).sum(axis=0)
    for kind in SENSOR_KINDS:
        candidates = [i for i, k in enumerate(aligned.kinds) if k == kind and valid[i] > 0]
        if candidates:
            return max(candidates, key=lambda i: (valid[i], -i))
    raise NoUsableSensorsError("no altitude source has a valid sample on the common clock")


def _first_seconds(
    mask: npt.NDArray[np.bool_], t: FloatArray, seconds: float
) -> npt.NDArray[np.bool_]:
    """The first ``seconds`` of ticks where ``mask`` holds."""
    out: npt.NDArray[np.bool_] = np.zeros(mask.shape, dtype=bool)
    idx = np.flatnonzero(mask)
    if idx.size:
        out[idx[t[idx] < t[idx[0]] + seconds]] = True
    return out


def detect_takeoff(
    t: FloatArray, h: FloatArray, rate_hz: float, ground_s: float, climb_m: float
) -> float | None:
    """First time [s] at which ``h`` (1 s running median) rises ``climb_m`` above its start."""
    valid = np.isfinite(h)
    start = _first_seconds(valid, t, ground_s)
    if not start.any():
        return None
    ground = float(np.median(h[start]))
    window = max(1, round(rate_hz))
    smooth = pd.Series(h).rolling(window, center=True, min_periods=1).median().to_numpy()
    above = np.flatnonzero(valid & (smooth > ground + climb_m))
    return float(t[above[0]]) if above.size else None


def refer_to_takeoff(
    aligned: Aligned, ground_window_s: float = 5.0, takeoff_climb_m: float = 1.0
) -> Referred:
    """Subtract from each source its offset to height above take-off (see module doc).

    Parameters
    ----------
    aligned
        Sources on one clock.
    ground_window_s
        Length of the ground window [s], > 0 (checked by :class:`altfuse.FuseOptions`).
    takeoff_climb_m
        Rise of the reference source that marks take-off [m], > 0.
    """
    ground_s, climb_m = ground_window_s, takeoff_climb_m
    t, z = aligned.t, aligned.z
    ref = choose_reference(aligned)
    ref_valid = np.isfinite(z[:, ref])
    takeoff = detect_takeoff(t, z[:, ref], aligned.rate_hz, ground_s, climb_m)
    window = np.zeros(t.size, dtype=bool)
    if takeoff is None:
        ground_how = "first seconds of the log (no take-off found)"
    elif t[ref_valid][0] >= takeoff - TAKEOFF_MARGIN_S:
        ground_how = "first seconds of the log (take-off too early for a ground window)"
    else:
        end = takeoff - TAKEOFF_MARGIN_S
        window = (t >= end - ground_s) & (t <= end)
        ground_how = f"ground before take-off at {takeoff:.1f} s"
        if not (window & ref_valid).any():
            ground_how = "first seconds of the log (no reference sample before take-off)"
    if not (window & ref_valid).any():
        window = _first_seconds(ref_valid, t, ground_s)
    win_idx = np.flatnonzero(window & ref_valid)
    ground_window = (float(t[win_idx[0]]), float(t[win_idx[-1]]))

    offsets: dict[int, Offset] = {}
    h = np.full_like(z, np.nan)
    dropped: dict[str, str] = {}
    order = [ref] + [i for i in range(len(aligned.names)) if i != ref]
    for i in order:
        name, valid = aligned.names[i], np.isfinite(z[:, i])
        on_ground = window & valid
        if on_ground.sum() >= MIN_WINDOW_TICKS or (i == ref and on_ground.any()):
            sel, base, how = on_ground, np.zeros_like(t), f"median over the {ground_how}"
        else:
            sel = _first_seconds(valid & np.isfinite(h[:, ref]), t, ground_s)
            if sel.sum() < MIN_WINDOW_TICKS:
                dropped[name] = (
                    f"no sample on the ground and too few beside {aligned.names[ref]} "
                    "to find its datum"
                )
                continue
            base = h[:, ref]
            how = f"median difference from {aligned.names[ref]} (no samples on the ground)"
        offset = float(np.median(z[sel, i] - base[sel]))
        sel_t = t[sel]
        offsets[i] = Offset(name, offset, how, (float(sel_t[0]), float(sel_t[-1])), int(sel.sum()))
        h[:, i] = z[:, i] - offset

    keep = [i for i in range(len(aligned.names)) if i in offsets]
    return Referred(
        t=t,
        names=tuple(aligned.names[i] for i in keep),
        kinds=tuple(aligned.kinds[i] for i in keep),
        h=h[:, keep],
        reference=aligned.names[ref],
        takeoff_s=takeoff,
        ground_window_s=ground_window,
        offsets=tuple(offsets[i] for i in keep),
        dropped=dropped,
    )


def referred_samples(sensors: Sequence[Series], referred: Referred) -> tuple[Samples, ...]:
    """Each referred sensor's own samples (time, height above take-off), duplicates merged, in
    the clock's column order."""
    by_name = {s.name: s for s in sensors}
    out = []
    for o in referred.offsets:
        s = by_name[o.name]
        out.append(Samples(*merge_duplicates(s.t, s.value - o.offset_m)))
    return tuple(out)
