"""Referring every aligned source to height above the take-off point (ALGORITHMS.md section 4).

GPS measures height above mean sea level, the barometer height above wherever it was calibrated,
the rangefinder height above the ground under the vehicle. Paper A fuses them as if they shared a
datum (its table shows all three near 15 m). Here each source ``i`` becomes ``h_i = z_i - c_i``
with one constant offset ``c_i``, found in this order:

1. **On the ground**: the median of the source over the *ground window*, the ``ground_s`` seconds
   that end one second before take-off. Take-off is the first tick at which the reference source
   (the first barometer, else the first GPS, else the rangefinder; 1 s running median) rises
   ``climb_m`` above its level over the first ``ground_s`` seconds of the log; where the
   autopilot's land detector tells when the vehicle left the ground, the first such rise after
   the first of those times, above the level over the ``ground_s`` seconds before it, or
   without one that time (:func:`_refer_segment`). A log with no such rise (a log that starts
   in flight, a bench test) uses its first ``ground_s`` seconds instead, and says so.
2. **Matched to the reference**: a source with no samples in the ground window (a GPS without a
   fix at take-off, a rangefinder out of range on the ground) takes the median of its difference
   from the referred reference over the first ``ground_s`` seconds where both are valid.
3. Otherwise it is dropped, with that reason.

A barometer is also scaled (``referral="full"``, the default): ``h = (z - c) / scale``, the
scale fitted against the GPS over the flight, or a rangefinder where it tells the scale
better (:func:`.scale.baro_scales`). Barometers read 3-8 % high
in the simulators' climbs (16 m at 305 m) and real ones do the same (a sensor warmer than the
air; ArduPilot issue 15025: "both an offset and a gain"); an offset alone leaves that to every
method that averages. The scale is applied only where the flight can tell it: enough vertical
range against the GPS's own error, a value different from 1 and plausible; the metadata says
which, and why not. A drift in time is fitted beside it and left in the data, where fusion is
meant to see it; a source that is right but offset keeps its full weight.

The datum is found on a clock of :data:`DATUM_RATE_HZ`, whatever the output's rate
(:func:`on_clock` refers the output's ticks with it): on a coarser clock the take-off and the
ground before it blur into a few ticks, and the fused height moved with ``--rate``; on a finer
one the ground window's medians and the scale fits moved too.

Before that, :func:`.tilt.tilt_correct` turns a rangefinder's distance along the body's down
axis into a vertical height, ``d * cos(roll) * cos(pitch)``, with the logged attitude
(``CTUN.SAlt`` comes tilt-corrected by the autopilot and is left alone).

This module refers the sources (offsets, segments of a spliced log, the steps between sources,
the clocks); :mod:`.takeoff` finds the reference, the take-off and the ground before it;
:mod:`.scale` fits each barometer's scale (with its drift, its dynamic pressure and the wind);
:mod:`.tilt` the rangefinder's tilt.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
import numpy.typing as npt

from altfuse.align import Aligned, merge_duplicates, tick_range
from altfuse.datum.scale import Scale, Track, Wind, baro_scales, on_changes
from altfuse.datum.takeoff import (
    GROUND_EFFECT_AFTER_S,
    GROUND_EFFECT_BEFORE_S,
    LIFTOFF_MARGIN_S,
    STILL_MARGIN_S,
    choose_reference,
    detect_takeoff,
    first_seconds,
    ground_before,
    lift_off,
    smoothed,
)
from altfuse.errors import NoUsableSensorsError
from altfuse.model import (
    FloatArray,
    Samples,
    SensorKind,
    Series,
    brief_repr,
)
from altfuse.steps import STEP_WINDOWS_S, Step, find_steps

#: Fewest valid ticks a window must hold for an offset to be measured on it.
MIN_WINDOW_TICKS = 3
#: Least rate [Hz] of the clock the datum is found on (the default clock's): on the output's
#: own clock the 13 truth logs and 3 PX4 simulator logs at 0.5 Hz moved by 1.4 and 4.9 m on
#: two (a take-off 8 s into the log blurred into four ticks), and at 0.2 Hz 14 of the 16 were
#: refused (the GPS had too few ticks beside the barometer to be referred), the other two
#: 0.2 and 0.5 m off at most; at 1-2 Hz by up to 0.1 m (the noisy 3.3 plane aside).
DATUM_RATE_HZ = 10.0
#: A rangefinder valid on less of the ground window than this reads below its minimum range
#: there: its valid readings are the noise's tail above the minimum, biased high (a mount 0.1 m
#: up under a 0.2 m minimum gave an offset of 0.29 m), and its datum is found as without any.
RANGEFINDER_GROUND_SHARE = 0.5
#: A segment of a spliced log has a ground of its own only where the GPS says the vehicle stood
#: in its ground window: a median ground speed at most this [m/s]. A log resumed in a cruise
#: over hills rises 1 m, as a take-off does, after 5 s flown at 5 m/s: referred to that
#: "ground", the mission's last segment read 16 m below its take-off point on landing.
GROUND_MAX_SPEED_M_S = 1.0


Referral = Literal["full", "offset"]


@dataclass(frozen=True)
class Offset:
    """How one source was referred: ``h = (z - offset_m) / scale``, and how each was found."""

    name: str
    offset_m: float
    method: str
    window_s: tuple[float, float] | None  # None: not measured (a rangefinder's clearance)
    ticks: int
    scale: float = 1.0
    scale_std: float | None = None
    scale_method: str | None = None  # None: not a barometer, or not tested (referral "offset")
    on_ground: bool = False  # measured over the ground window (else matched, or a clearance)
    scale_applied: bool = False
    scale_estimate: float | None = None  # the fit's scale, applied or not; None: not estimated

    @property
    def scale_unknown(self) -> tuple[float, float] | None:
        """A barometer whose scale was estimated and not applied (too little range, too much
        noise, within its error of 1): the fit's scale and standard error; None otherwise."""
        if self.scale_applied or self.scale_estimate is None or self.scale_std is None:
            return None
        return self.scale_estimate, self.scale_std

    @property
    def scale_known(self) -> tuple[float, float] | None:
        """A barometer whose scale was applied: that scale and its standard error; None
        otherwise."""
        if not self.scale_applied or self.scale_std is None:
            return None
        return self.scale, self.scale_std


@dataclass(frozen=True)
class _Ground:
    """Where the offsets are measured: the ground window (or the log's first seconds), and
    what rangefinders read when landed [m], by name, for those with no sample there."""

    window: npt.NDArray[np.bool_]
    how: str
    seconds: float
    ref: int
    clearances: Mapping[str, float]
    real: bool  # before a detected take-off, not the log's first seconds
    takeoff_s: float | None = None  # the detected take-off, where the window is before it


@dataclass(frozen=True)
class Segment:
    """A part of a spliced log, and whose datum it was referred with: its own or the main
    segment's ground (``grounded``: each sensor's offset is 0 there, and ``on_ground_s`` the
    span in which the vehicle stood at that take-off point, where there is one), or the main
    segment's offsets carried over (a log resumed in flight)."""

    start_s: float
    end_s: float
    datum: str
    grounded: bool = True
    on_ground_s: tuple[float, float] | None = None
    offsets: tuple[Offset, ...] = ()  # its own datum's; empty: the main segment's


@dataclass(frozen=True)
class Referred:
    """Heights above take-off [m] on the aligned clock, for the sources that could be referred."""

    __repr__ = brief_repr

    t: FloatArray
    names: tuple[str, ...]
    kinds: tuple[SensorKind, ...]
    h: FloatArray
    reference: str
    takeoff_s: float | None
    ground_window_s: tuple[float, float]
    offsets: tuple[Offset, ...]
    dropped: dict[str, str]
    segments: tuple[Segment, ...] = ()  # empty: the log is one segment
    on_real_ground: bool = False  # the ground window lies before a detected take-off
    steps: tuple[Step, ...] = ()  # between two sensors' heights (:mod:`altfuse.steps`)
    wind: Wind | None = None  # the main segment's, as its barometers' scale fits told it
    detected: bool = False  # the take-off is the autopilot's land detector's, not a rise
    liftoff_s: float | None = None  # where the rise that found the take-off began
    datum_rate_hz: float | None = None  # the clock the datum was found on; None: ``t``'s own

    def datum_ticks(self, span: tuple[float, float]) -> FloatArray:
        """The ticks within ``span`` [s] of the clock the datum was found on (:func:`on_clock`):
        where a reference is referred as the sources were (a coarser ``t`` may have none in
        the ground window)."""
        lo, hi = span
        if self.datum_rate_hz is None:
            return self.t[(self.t >= lo) & (self.t <= hi)]
        first, last = tick_range(lo, hi, self.datum_rate_hz)  # its ticks, as the clock's own
        ticks: FloatArray = np.arange(first, last + 1) / self.datum_rate_hz
        return ticks

    @property
    def datum_windows(self) -> tuple[tuple[float, float] | None, ...]:
        """Per source, the span over which its offset was measured on the datum window (the
        ground window before a detected take-off, or the log's first seconds, where the datum
        is defined); None where it was matched to another source instead."""
        return tuple(o.window_s if o.on_ground else None for o in self.offsets)

    @property
    def ground_effect_s(self) -> tuple[float, float] | None:
        """The span in which the barometers may read in the air the vehicle stirs near the
        ground as it takes off (a rotorcraft's wash): from ``GROUND_EFFECT_BEFORE_S`` before
        its lift-off (or its take-off, where no lift-off was found) to ``GROUND_EFFECT_AFTER_S``
        after its take-off; None without a take-off found from a ground."""
        if self.takeoff_s is None or not self.on_real_ground:
            return None
        lift = self.takeoff_s if self.liftoff_s is None else self.liftoff_s
        return (lift - GROUND_EFFECT_BEFORE_S, self.takeoff_s + GROUND_EFFECT_AFTER_S)

    @property
    def on_ground_s(self) -> tuple[float, float] | None:
        """The span in which the vehicle stood still at the take-off point: the ground window,
        up to ``STILL_MARGIN_S`` before a take-off found where the reference rose and
        ``LIFTOFF_MARGIN_S`` before its lift-off (the autopilot's land detector says it before
        the lift-off); None if it is empty, or there
        was no take-off or no ground before it (a log begun in flight: held at 0 there, a climb
        took the smoother 3.4 m off every sensor for the whole flight)."""
        if self.takeoff_s is None or not self.on_real_ground:
            return None
        lo, hi = self.ground_window_s
        if not self.detected:
            hi = min(hi, self.takeoff_s - STILL_MARGIN_S)
        if self.liftoff_s is not None:
            hi = min(hi, self.liftoff_s - LIFTOFF_MARGIN_S)
        return (lo, hi) if hi > lo else None


@dataclass(frozen=True)
class _Told:
    """What the log tells the datum beside the heights: what rangefinders read when landed
    [m] by name, the GPS's ground track, the times the autopilot's land detector said the
    vehicle left the ground."""

    clearances: Mapping[str, float]
    track: Track | None
    takeoffs: Sequence[float]


def refer_to_takeoff(  # noqa: PLR0913 (keyword-only beyond the referral: what the log tells)
    aligned: Aligned,
    ground_window_s: float = 5.0,
    takeoff_climb_m: float = 1.0,
    referral: Referral = "full",
    *,
    clearances: Mapping[str, float] | None = None,
    splices: Sequence[float] = (),
    track: Track | None = None,
    takeoffs: Sequence[float] = (),
) -> Referred:
    """Subtract from each source its offset (and scale) to height above take-off, segment by
    segment (see module doc).

    ``splices`` are the times [s] at which a new segment of the log starts (a reboot, a log
    resumed: :func:`altfuse.align.splices`). The segment with the most valid ticks is referred
    as a whole log is; another with its own take-off, from a ground window in which the GPS's
    ground speed (``track``, where the log has one) says the vehicle stood, gets its own datum;
    one without (a log resumed in flight) the main segment's offsets and scales.

    ``takeoffs``: the times [s] at which the autopilot's land detector said the vehicle left
    the ground (:func:`.takeoff.detector_takeoffs`), where the log tells: the take-off is the
    reference's first rise after the first of them, or that time (see :func:`_refer_segment`).
    """
    t = aligned.t
    told = _Told(dict(clearances or {}), track, takeoffs)
    cuts = [0, *np.searchsorted(t, np.asarray(splices, dtype=np.float64)).tolist(), t.size]
    pieces = [(a, b) for a, b in itertools.pairwise(cuts) if b > a]
    if len(pieces) == 1:
        return _refer_segment(aligned, ground_window_s, takeoff_climb_m, referral, told)
    valid = np.asarray(np.isfinite(aligned.z).any(axis=1), dtype=bool)
    main = max(pieces, key=lambda p: int(valid[p[0] : p[1]].sum()))
    options = (ground_window_s, takeoff_climb_m, referral, told)
    owns = {
        (a, b): _refer_segment(aligned.part(a, b), *options)
        if (a, b) == main
        else _own_datum(aligned.part(a, b), *options)
        for a, b in pieces
    }
    # a barometer's scale is the sensor's, whichever segment tells it best
    best = _best_scales([r for r in owns.values() if r is not None])
    owns = {
        p: None if r is None else _with_scales(r, aligned.part(*p), best) for p, r in owns.items()
    }
    first = owns[main]
    assert first is not None  # the main segment is referred, or raises
    columns = [aligned.names.index(n) for n in first.names]
    h = np.full((t.size, len(columns)), np.nan)
    segments = []
    for a, b in pieces:
        part = aligned.part(a, b)
        own = None if (a, b) == main else owns[a, b]
        grounded, still = True, None
        offsets: tuple[Offset, ...] = ()
        if (a, b) == main:
            h[a:b], how, still = first.h, "the main segment's", first.on_ground_s
        elif own is not None:
            for j, name in enumerate(first.names):
                if name in own.names:
                    h[a:b, j] = own.h[:, own.names.index(name)]
            how = f"its own, ground before take-off at {own.takeoff_s:.1f} s"
            still, offsets = own.on_ground_s, own.offsets
        else:
            for j, o in enumerate(first.offsets):
                h[a:b, j] = (part.z[:, columns[j]] - o.offset_m) / o.scale
            how, grounded = "the main segment's offsets (no take-off in it)", False
        ticks = t[a:b][valid[a:b]]
        if ticks.size:
            span = (float(ticks[0]), float(ticks[-1]))
            segments.append(Segment(*span, how, grounded, still, offsets))
    steps = sorted(
        (s for r in owns.values() if r is not None for s in r.steps), key=lambda s: s.time_s
    )
    return replace(first, t=t, h=h, segments=tuple(segments), steps=tuple(steps))


def _best_scales(referrals: Sequence[Referred]) -> dict[str, Offset]:
    """Per barometer, the offset whose applied scale has the least standard error among the
    segments' referrals."""
    best: dict[str, Offset] = {}
    for referred in referrals:
        for o in referred.offsets:
            if o.scale_applied and o.scale_std is not None:
                known = best.get(o.name)
                if known is None or o.scale_std < (known.scale_std or math.inf):
                    best[o.name] = o
    return best


def _with_scales(referred: Referred, part: Aligned, best: Mapping[str, Offset]) -> Referred:
    """``referred`` (of the aligned ``part``) with each barometer's scale ``best``'s, its
    heights rescaled: a segment's own fit on a shorter climb (the Solo's log with a GPS 0.3 m
    noisy: the main segment's 42 m climb 1.038 +- 0.014, the other's 154 m climb 1.052 +- 0.007,
    SIM's 1.052) no longer refers the same barometer two ways."""
    h, offsets = referred.h.copy(), list(referred.offsets)
    for j, o in enumerate(offsets):
        chosen = best.get(o.name)
        if chosen is None or chosen is o:
            continue
        offsets[j] = replace(
            o,
            scale=chosen.scale,
            scale_std=chosen.scale_std,
            scale_method=f"{chosen.scale_method} (in another segment of the log)",
            scale_applied=True,
            scale_estimate=chosen.scale_estimate,
        )
        h[:, j] = (part.z[:, part.names.index(o.name)] - o.offset_m) / chosen.scale
    return replace(referred, h=h, offsets=tuple(offsets))


def _own_datum(
    part: Aligned,
    ground_window_s: float,
    takeoff_climb_m: float,
    referral: Referral,
    told: _Told,
) -> Referred | None:
    """A segment's own referral, where it has a take-off and a ground window before it, and
    the vehicle stood in that window where the GPS's ground speed tells (``told.track``; see
    ``GROUND_MAX_SPEED_M_S``)."""
    try:
        own = _refer_segment(part, ground_window_s, takeoff_climb_m, referral, told)
    except NoUsableSensorsError:
        return None
    if not own.on_real_ground:
        return None
    if told.track is not None:
        speed = told.track.speed
        lo, hi = own.ground_window_s
        inside = (speed.t >= lo) & (speed.t <= hi) & np.isfinite(speed.value)
        if inside.any() and np.median(speed.value[inside]) > GROUND_MAX_SPEED_M_S:
            return None
    return own


def _refer_segment(
    aligned: Aligned,
    ground_window_s: float,
    takeoff_climb_m: float,
    referral: Referral,
    told: _Told,
) -> Referred:
    """:func:`refer_to_takeoff` of one segment.

    Parameters
    ----------
    aligned
        Sources on one clock.
    ground_window_s
        Length of the ground window [s], > 0 (checked by :class:`altfuse.FuseOptions`).
    takeoff_climb_m
        Rise of the reference source that marks take-off [m], > 0.
    referral
        ``full``: each barometer's scale too, where the flight can tell it
        (:func:`.scale.baro_scales`); ``offset``: offsets only.
    told
        What a rangefinder reads when landed [m] by name (``RNGFNDn_GNDCLEAR``): its offset
        when it has no valid reading in the ground window (its ground readings below its
        minimum range), rather than one matched in flight to a barometer that may drift. The
        GPS's ground speed and course, where the log has them: a barometer's scale is fitted
        beside its dynamic pressure in a wind (:func:`.scale.baro_scales`). The times the
        autopilot's land detector said the vehicle left the ground: the first of them in the
        segment is where the reference's rise is sought from, or, without a rise after it (a
        hop lower than ``takeoff_climb_m``), the take-off itself.
    """
    ground_s, climb_m = ground_window_s, takeoff_climb_m
    t, z = aligned.t, aligned.z
    ref = choose_reference(aligned)
    ref_valid = np.isfinite(z[:, ref])
    smooth = smoothed(z[:, ref], aligned.rate_hz)
    heights = (t, z[:, ref], smooth)
    # a barometer's ground is witnessed by the other kinds of source (:func:`.takeoff._moving`)
    witnesses = [
        smoothed(z[:, i], aligned.rate_hz)
        for i, kind in enumerate(aligned.kinds)
        if aligned.kinds[ref] == "baro" and kind != "baro"
    ]
    flagged = next((x for x in told.takeoffs if t[0] <= x <= t[-1]), None)
    # the first rise once the autopilot says the vehicle flies, else the time it says so (a
    # hop lower than ``climb_m``), else the first rise
    found = [(detect_takeoff(*heights, ground_s, climb_m), "")]
    if flagged is not None:
        after = detect_takeoff(*heights, ground_s, climb_m, flagged)
        found = [(after, ""), (flagged, " (the autopilot's land detector)"), *found]
    for takeoff, told_by in found:
        window, ground_how, real = ground_before(
            takeoff, (t, ref_valid, smooth, witnesses), ground_s, climb_m
        )
        if real:
            ground_how += told_by
            break
    detected = real and bool(told_by)
    if not (window & ref_valid).any():
        window = first_seconds(ref_valid, t, ground_s)
    win_idx = np.flatnonzero(window & ref_valid)
    ground_window = (float(t[win_idx[0]]), float(t[win_idx[-1]]))

    ground = _Ground(
        window, ground_how, ground_s, ref, told.clearances, real, takeoff if real else None
    )
    offsets, h, dropped = _refer(aligned, ground, {})
    steps = _steps(aligned, h, offsets)
    wind = None
    if referral == "full":
        scales = baro_scales(aligned, h, offsets, steps, told.track)
        steps, scales = _sought_again(aligned, ground, (h, offsets), steps, scales, told.track)
        wind = max(
            (sc.wind for sc in scales.values() if sc.wind is not None),
            key=lambda w: w.sigmas,
            default=None,
        )
        if any(sc.applied for sc in scales.values()):
            offsets, h, dropped = _refer(aligned, ground, scales)
        for i, sc in scales.items():
            if i in offsets:
                offsets[i] = replace(
                    offsets[i],
                    scale_std=sc.std,
                    scale_method=sc.how,
                    scale_applied=sc.applied,
                    scale_estimate=sc.scale if sc.std is not None else None,
                )

    keep = [i for i in range(len(aligned.names)) if i in offsets]
    return Referred(
        t=t,
        names=tuple(aligned.names[i] for i in keep),
        kinds=tuple(aligned.kinds[i] for i in keep),
        h=h[:, keep],
        reference=aligned.names[ref],
        takeoff_s=takeoff,
        liftoff_s=(
            lift_off(t, np.where(ref_valid, smooth, np.nan), takeoff)
            if takeoff is not None and real and not detected
            else None
        ),
        ground_window_s=ground_window,
        offsets=tuple(offsets[i] for i in keep),
        dropped=dropped,
        on_real_ground=real,
        steps=steps,
        detected=detected,
        wind=wind,
    )


def _steps(aligned: Aligned, h: FloatArray, offsets: dict[int, Offset]) -> tuple[Step, ...]:
    """The steps between the referred sources' heights ``h`` (:func:`altfuse.steps.find_steps`;
    ``offsets``: those referred)."""
    referred = sorted(offsets)
    names, kinds = [aligned.names[i] for i in referred], [aligned.kinds[i] for i in referred]
    return find_steps(aligned.t, h[:, referred], names, kinds)


def _sought_again(
    aligned: Aligned,
    ground: _Ground,
    referred: tuple[FloatArray, dict[int, Offset]],
    steps: tuple[Step, ...],
    scales: dict[int, Scale],
    track: Track | None,
) -> tuple[tuple[Step, ...], dict[int, Scale]]:
    """The ``steps`` found on the heights referred by offsets (``referred``: those heights and
    offsets) and those found again on the heights the barometers' fit on the changes scales
    (:func:`.scale.on_changes`), and the ``scales`` fitted again with them where they differ.

    In a climb a barometer's scale hides a step from the lines either side of it, and the step
    moves the scale's fit on the heights; not the fit on their changes, which has one change
    across it."""
    h, offsets = referred
    rescaled = on_changes(scales)
    if not rescaled:
        return steps, scales
    again = _steps(aligned, _refer(aligned, ground, rescaled)[1], offsets)
    if again == steps:
        return steps, scales
    steps = _either_search(steps, again, 1.0 / aligned.rate_hz)
    return steps, baro_scales(aligned, h, offsets, steps, track)


def _either_search(first: Sequence[Step], again: Sequence[Step], tick_s: float) -> tuple[Step, ...]:
    """The steps of two searches, by time: ``again``'s, and each of ``first``'s found across
    a gap (of the clock's ticks ``tick_s`` apart) that ``again`` has not between the same
    sensors within STEP_WINDOWS_S[0] or their gaps. A step across a climb's gap measured
    against the barometer's scale is seconds of the climb off in size (the 3.3 plane's GPS
    regained 2 m higher after 10 s: -6.0 m), but it is there. One between two ticks that the
    scaled heights do not have is the scale's: a barometer 8.6 % high parts from the GPS at
    3.3 m/s in a 38 m/s dive, and the lines either side of the dive's end read a step (the 3.3
    plane with its barometer 5 % higher: -1.93 m, 10.6 sigma; both offsets let loose there,
    the fused height was 1.3 m below both sensors to the log's end, 0.812 m RMSE)."""

    def found(s: Step) -> bool:
        near = max(STEP_WINDOWS_S[0], s.half_width_s)
        return any(
            {a.first, a.second} == {s.first, s.second}
            and abs(a.time_s - s.time_s) <= max(near, a.half_width_s)
            for a in again
        )

    # a step between two ticks lies in half a tick either side of its boundary
    gapped = (s for s in first if round(2.0 * s.half_width_s / tick_s) > 1)
    return tuple(sorted([*again, *(s for s in gapped if not found(s))], key=lambda s: s.time_s))


def _refer(
    aligned: Aligned, ground: _Ground, scales: dict[int, Scale]
) -> tuple[dict[int, Offset], FloatArray, dict[str, str]]:
    """Every source's offset (on the ground, else matched to the referred reference, else to
    another source referred) and its referred heights ``(z - c) / scale``, with the scales
    given; the sources dropped, and why. A source matched to none is tried again once the others
    are referred: a PX4 barometer failed over to another device begins after the first ends,
    beside the GPS alone."""
    z, ref = aligned.z, ground.ref
    offsets: dict[int, Offset] = {}
    h = np.full_like(z, np.nan)
    pending = [ref] + [i for i in range(len(aligned.names)) if i != ref]
    while pending:
        left = []
        for i in pending:
            found = _offset(i, aligned, ground, scales.get(i), (h, list(offsets)))
            if found is None:
                left.append(i)
                continue
            offsets[i] = found
            h[:, i] = (z[:, i] - found.offset_m) / found.scale
        if len(left) == len(pending):
            break
        pending = left
    referred = ", ".join(aligned.names[j] for j in offsets)
    dropped = {
        aligned.names[i]: f"no sample on the ground and too few beside {referred} to find its datum"
        for i in pending
    }
    return offsets, h, dropped


def _offset(
    i: int,
    aligned: Aligned,
    ground: _Ground,
    scale_of: Scale | None,
    referred: tuple[FloatArray, list[int]],
) -> Offset | None:
    """Source ``i``'s offset: on the ground, else its ground clearance (a rangefinder), else
    its median difference over its first seconds from the first of the ``referred`` heights
    (``h`` and their columns, the reference first) beside which it has MIN_WINDOW_TICKS; None
    where it has none."""
    t, z, ref = aligned.t, aligned.z, ground.ref
    name, valid = aligned.names[i], np.isfinite(z[:, i])
    scale = scale_of.scale if scale_of is not None and scale_of.applied else 1.0
    # at the reference's own instants in the window: where it moves (a log begun in a
    # climb), a tick more or less of one sensor is a different height
    at_ref = ground.window & np.isfinite(z[:, ref])
    on_ground = at_ref & valid
    why = "no valid reading on the ground"
    if aligned.kinds[i] == "rangefinder" and on_ground.any() and i != ref:
        share = on_ground.sum() / max(int(at_ref.sum()), 1)
        if share < RANGEFINDER_GROUND_SHARE:  # the tail of readings below its minimum
            on_ground = np.zeros_like(on_ground)
            why = f"valid on {share:.0%} of the ground window: below its minimum there"
            if ground.takeoff_s is not None:  # matched in flight, not on that tail
                valid = valid & (t > ground.takeoff_s)
    if on_ground.sum() >= MIN_WINDOW_TICKS or (i == ref and on_ground.any()):
        sel, base, how = on_ground, np.zeros_like(t), f"median over the {ground.how}"
        measured = True
    elif name in ground.clearances and ground.real:
        clearance = ground.clearances[name]
        return Offset(name, clearance, f"its ground clearance, {clearance:.2f} m ({why})", None, 0)
    else:
        h, columns = referred
        beside = _beside(valid, h, t, ground.seconds, columns)
        if beside is None:
            return None
        j, sel = beside
        base = h[:, j]
        how = f"median difference from {aligned.names[j]} ({why})"
        measured = False
    offset = float(np.median(z[sel, i] - scale * base[sel]))
    sel_t = t[sel]
    window = (float(sel_t[0]), float(sel_t[-1]))
    return Offset(name, offset, how, window, int(sel.sum()), scale, on_ground=measured)


def _beside(
    valid: npt.NDArray[np.bool_], h: FloatArray, t: FloatArray, seconds: float, referred: list[int]
) -> tuple[int, npt.NDArray[np.bool_]] | None:
    """The first of the ``referred`` columns of ``h`` beside which a source ``valid`` at these
    ticks has MIN_WINDOW_TICKS in its first ``seconds`` with it, and those ticks; None where
    none has."""
    for j in referred:
        sel = first_seconds(valid & np.isfinite(h[:, j]), t, seconds)
        if sel.sum() >= MIN_WINDOW_TICKS:
            return j, sel
    return None


def referred_samples(sensors: Sequence[Series], referred: Referred) -> tuple[Samples, ...]:
    """Each referred sensor's own samples (time, height above take-off), duplicates merged, in
    the clock's column order; in a spliced log, a segment's samples as its ticks are, with its
    own datum's offset and scale where it has one (none for a sensor that datum lacks). The
    main segment's instead gave the smoother a barometer 5 % high in a segment whose own datum
    applied its scale (a 10 m sonar flight's log cut short: the fused height 0.25 m above both
    sensors in the table, band 8 mm)."""
    by_name = {s.name: s for s in sensors}
    out = []
    for o in referred.offsets:
        s = by_name[o.name]
        value, keep = _referred_values(referred, o, s.t, s.value)
        out.append(Samples(*merge_duplicates(s.t[keep], value[keep])))
    return tuple(out)


def on_datum_clock(rate_hz: float) -> bool:
    """Whether a clock of ``rate_hz`` is the datum's (DATUM_RATE_HZ), within the rounding of a
    rate read back from a clock's step (``1 / dt``)."""
    return abs(rate_hz / DATUM_RATE_HZ - 1.0) <= 1e-9


def coarser_than_datum(rate_hz: float) -> bool:
    """Whether a clock of ``rate_hz`` is coarser than the datum's (DATUM_RATE_HZ): its sensor
    columns are means over cells wider than the datum's ticks. A rate read back from a clock's
    step (``1 / dt``) within rounding of DATUM_RATE_HZ is not."""
    return rate_hz * (1.0 + 1e-9) < DATUM_RATE_HZ


def on_clock(referred: Referred, aligned: Aligned, datum_rate_hz: float) -> Referred:
    """``referred``, found on another clock of the same sources (of ``datum_rate_hz``:
    :data:`DATUM_RATE_HZ`), with its heights on ``aligned``'s: each source's ticks referred as
    its samples are (:func:`referred_samples`)."""
    h = np.full((aligned.t.size, len(referred.offsets)), np.nan)
    for j, o in enumerate(referred.offsets):
        z = aligned.z[:, aligned.names.index(o.name)]
        value, keep = _referred_values(referred, o, aligned.t, z)
        h[keep, j] = value[keep]
    return replace(referred, t=aligned.t, h=h, datum_rate_hz=datum_rate_hz)


def _referred_values(
    referred: Referred, o: Offset, t: FloatArray, z: FloatArray
) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """A source's readings ``z`` at the times ``t`` referred with ``o``, its offset, or in a
    spliced log with the offset of the segment whose datum is its own; and where the source
    has one (not in a segment whose own datum lacks it)."""
    starts = [seg.start_s for seg in referred.segments]
    value, keep = (z - o.offset_m) / o.scale, np.ones(t.size, dtype=bool)
    for k, segment in enumerate(referred.segments):
        if not segment.offsets:
            continue
        # its span, from its first tick to the next segment's (where the smoother starts afresh)
        start = segment.start_s if k else -math.inf
        end = starts[k + 1] if k + 1 < len(starts) else math.inf
        inside = (t >= start) & (t < end)
        own = next((x for x in segment.offsets if x.name == o.name), None)
        if own is None:
            keep &= ~inside
        else:
            value[inside] = (z[inside] - own.offset_m) / own.scale
    return value, keep
