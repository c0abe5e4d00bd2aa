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
better (:func:`baro_scales`). Barometers read 3-8 % high
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

Before that, :func:`tilt_correct` turns a rangefinder's distance along the body's down axis into a
vertical height, ``d * cos(roll) * cos(pitch)``, with the logged attitude (``CTUN.SAlt`` comes
tilt-corrected by the autopilot and is left alone).
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
from altfuse.errors import NoUsableSensorsError
from altfuse.inertial import G
from altfuse.metrics import MAD_TO_SIGMA, running_median, runs
from altfuse.model import (
    SENSOR_KINDS,
    Attitude,
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
#: The ground window ends this long before the detected take-off [s].
TAKEOFF_MARGIN_S = 1.0
#: A take-off is placed where the rise that reached ``--takeoff-climb`` last passed this height
#: above the ground [m] (or the climb, where that is less). A larger climb confirms a take-off
#: against a barometer that wanders on the ground; placed where it was reached, a 5 m climb put
#: the ground window in the climb itself, and the vehicle was held still there (a real 150 s
#: flight: 205 ticks diverged, 2.3 m from both sensors).
TAKEOFF_RISE_M = 1.0
#: The vehicle is taken to stand still until this long before the detected take-off [s]: a gentle
#: climb can take 2-3 s to rise the 1 m that detects it (0.3 m at the ground window's end).
STILL_MARGIN_S = 3.0
#: ... and until this long before the lift-off [s], where the rise that found the take-off
#: began (:func:`lift_off`, over the LIFTOFF_LOOKBACK_S before the take-off): a hand-flown
#: take-off lifts, hovers low and climbs. A real Copter 3.4 log (``beastayyg_log_0038``)
#: lifted at 91.3 s (its rangefinder) and passed 1 m at 95.4 s; held still until 92.4 s, 0.3 m
#: up, the smoother stayed 0.3-0.5 m under its GPS, barometer and rangefinder for the whole
#: flight and 0.7 m under the rangefinder once landed (0.482 m RMSE from its EKF, coverage
#: 0.003; support 0.160). Its lift-off is found at 90.3 s (its barometer's dip as the motors
#: spun up): 0.214 m, 0.265. Every other shared log lifts off less than 2.5 s before its
#: take-off's 1 m, where STILL_MARGIN_S ends the span first (the simulators' logs 0.2-1.2 s,
#: the real ones 0.6-2.2 s), but one PX4 log (410.5 s where its barometer dips, 3.7 s before:
#: its still span 1.2 s shorter, 1.109 -> 1.126 m from its EKF, the fused height within 0.19 m
#: of before). Of altfuse's 210 simulated flights the hovers of seed 2 moved (RMSE -0.026 to
#: +0.007 m); coverage within 0.90-0.99 on 88, where 86.
LIFTOFF_MARGIN_S = 0.5
LIFTOFF_LOOKBACK_S = 10.0
LIFTOFF_RISE_M = 0.1
#: A vehicle's barometers may read in the air it stirs near the ground from this long before
#: its lift-off [s] to this long after its take-off [s] (:attr:`Referred.ground_effect_s`): a
#: copter's rotor wash raises the static pressure under and around it as its motors spin up,
#: and its barometers read low until it climbs out of it (a real Copter 3.4 log's dipped 0.4
#: m as its motors spun up, and a PX4 log's as much). ArduPilot's EKF3 ignores the barometer's
#: dips near the ground until 5 s after the take-off (``EK3_GND_EFF_DZ``). The smoother
#: offers the barometers an error there that vanishes at both ends, where the log's evidence
#: asks for it (:func:`altfuse.fuse.smoother.evidence.wash_evidence`).
#: Measured on the truth logs' variants (:data:`altfuse.fuse.smoother.model.WASH_SIGMA`): from
#: 3 s before, the hexa 0.067 -> 0.097 m RMSE and the 10 m sonar 0.088 -> 0.102 with their
#: barometers 0.5 m low (the variant's wash begins 3 s before); to 5 s after, those 0.011 and
#: 0.055 but the 8 m rangefinder flight 0.034 -> 0.048, its maximum 0.17 -> 0.22 m (its GPS's
#: lag, measured against its washed barometers, 0.10 -> 0.23 s, leads the climb out).
GROUND_EFFECT_BEFORE_S = 5.0
GROUND_EFFECT_AFTER_S = 3.0


Referral = Literal["full", "offset"]
#: A barometer's scale is applied when its standard error is at most this [-] (with the next
#: rule, a scale at least 4 % from 1: a 35 s climb-only log's 5.3 % +- 1.0 %, which SIM says is
#: 5.4 %; the real logs' scales, 3-21 %, all stay refused)...
MAX_SCALE_STD = 0.02
#: ... it differs from 1 by this many standard errors (a barometer right to within its error
#: keeps its own scale) ...
SCALE_MIN_SIGMAS = 2.0
#: ... and it lies in this range: a barometer off by more than a quarter is broken, not biased.
SCALE_RANGE = (0.8, 1.25)
#: A GPS's error wanders (a random walk of metres over minutes): its heights' errors are
#: correlated over a flight, so the fit on the heights counts one independent sample per
#: SCALE_BLOCK_S [s] (its residuals' variance, not the drift's prior, raised by the samples per
#: block: raising the whole error made a 20 s climb of 50 m, whose scale and drift the prior
#: alone tells apart, 1.053 +- 0.061 where the changes say +- 0.012), and the fit on the heights'
#: changes over successive spans (the flight's length over SCALE_CHANGES, within SCALE_SPAN_S
#: [s]), whose errors are nearly independent, must agree: the scale's standard error is the
#: larger of the two. Spans down to 1 s: a log that ends 12 s after take-off (a simulator's 10 m
#: flight cut short, its barometer 5 % high) had no 8 spans of 2 s, its scale was not estimated
#: and the smoother followed the barometer 0.49 m off (now 1.051 +- 0.006, applied: 0.004 m
#: RMSE); every log 32 s or longer keeps its spans. With under 16 s of ticks beside the GPS,
#: the spans are shorter still, SCALE_CHANGES of them: a plane's log that ends 4 s after its
#: launch (the 4.5 plane's first 20 %, barometers 5 % high) had 6 spans of 1 s, its scale was
#: not estimated and the smoother followed the barometers 0.48 m off with a band of 4 cm (now
#: 1.057 +- 0.037, not applied, and the smoother's scale test learns 4.5 %: 0.061 m RMSE).
SCALE_BLOCK_S = 10.0
SCALE_CHANGES = 16
SCALE_SPAN_S = (1.0, 10.0)
#: Fewest changes (and twice as many ticks) a scale is fitted on.
SCALE_MIN_CHANGES = 8
#: A barometer's drift beside the scale has a zero-mean prior of this [m/min]: in a climb with
#: no hold or descent the two are otherwise one (a 65 m climb-only log: 1.4 % error, where the
#: scale is 5 %); a board warming by 10 degC over a few minutes drifts about 0.4 m/min.
DRIFT_PRIOR_M_PER_MIN = 1.0
#: A residual is an outlier of the scale's fit only beyond 3 sigma and this [m] (a simulator's
#: noiseless sensors have a sigma of millimetres).
SCALE_MIN_OUTLIER_M = 0.1
#: Air flowing past the vehicle at the speed V lowers the static pressure its barometer reads
#: by ``k`` times the dynamic pressure ``rho V^2 / 2``: the barometer reads ``k V^2 / 2g``
#: higher (1.3 m at 5 m/s where k is 1; ArduPilot compensates it by BARO1_WCF_*, per direction,
#: from -1 to 1). ``k`` has this zero-mean prior in the scale's fit and the smoother's
#: (:func:`dynamic_head`).
DYNAMIC_PRIOR = 1.0
#: ... and is sought only where the flight's fastest ``V^2 / 2g`` reaches this [m] (3.1 m/s):
#: slower, it is lost in the barometer's noise; the scale's fit keeps it where it lies this
#: many standard errors from 0.
DYNAMIC_MIN_M = 0.5
DYNAMIC_SIGMAS = 3.0
#: The air moves: the barometer feels the airspeed ``|V - W|``, ``V`` the ground velocity (the
#: GPS's speed along its course) and ``W`` the wind, whose components have a zero-mean prior of
#: this [m/s] in the scale's fit. ``k |V - W|^2 / 2g = k V^2 / 2g - k W.V / g + k |W|^2 / 2g``
#: is linear in ``k`` and ``k W``: the fit takes ``V_north / g`` and ``V_east / g`` as columns
#: beside the head (the constant joins the offset), and ``W`` is told where it lies
#: DYNAMIC_SIGMAS of its components' errors from still air (:attr:`Wind.sigmas`).
WIND_PRIOR_M_S = 5.0
#: A receiver's velocity resolution [m/s] (centimetres per second): a component of the ground
#: velocity never beyond it is none (a column of zeros would leave the fit nothing to solve).
TRACK_RESOLUTION_M_S = 0.01


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
class Track:
    """The GPS's horizontal motion: its ground ``speed`` [m/s] and, where the log has it, its
    ``course`` over the ground [deg from north], read from the same records."""

    __repr__ = brief_repr

    speed: Samples
    course: Samples | None = None

    def components(self, t: FloatArray) -> FloatArray | None:
        """The ground velocity's north and east components [m/s] at the times ``t`` (``(2,
        n)``, interpolated as components, not as an angle that wraps); None without a
        course (fewer than two samples of it)."""
        if self.course is None or self.course.t.size < 2:
            return None
        course = np.radians(_at(self.course, self.speed.t, period=360.0))
        speed = np.nan_to_num(self.speed.value)
        north, east = speed * np.cos(course), speed * np.sin(course)
        return np.asarray([_at(Samples(self.speed.t, c), t) for c in (north, east)])

    def airspeed(self, wind: Wind | None) -> Samples:
        """The speed through the air at the GPS's samples, ``|V - W|``: the ground speed
        where there is no ``wind`` (or no course)."""
        ne = None if wind is None else self.components(self.speed.t)
        if wind is None or ne is None:
            return self.speed
        return Samples(self.speed.t, np.hypot(ne[0] - wind.north_m_s, ne[1] - wind.east_m_s))


def _at(samples: Samples, t: FloatArray, period: float | None = None) -> FloatArray:
    """``samples`` linearly interpolated at the times ``t`` (NaN read as 0; an angle of that
    ``period`` unwrapped first)."""
    order = np.argsort(samples.t, kind="stable")
    value = np.nan_to_num(samples.value[order])
    if period is not None:
        value = np.unwrap(value, period=period)
    return np.asarray(np.interp(t, samples.t[order], value))


@dataclass(frozen=True)
class Wind:
    """A steady wind [m/s] (the air's velocity: blowing towards north and east), as a
    barometer's dynamic pressure beside the GPS's ground velocity tells it (:func:`_wind`),
    and each component's standard error (None: a component the flight never had, taken as
    0)."""

    north_m_s: float
    east_m_s: float
    north_std_m_s: float | None
    east_std_m_s: float | None

    @property
    def sigmas(self) -> float:
        """How many standard errors from still air (the components' errors taken as
        independent)."""
        return math.hypot(
            *(w / e for w, e in self._components() if e is not None),
        )

    def _components(self) -> tuple[tuple[float, float | None], ...]:
        return (self.north_m_s, self.north_std_m_s), (self.east_m_s, self.east_std_m_s)

    def __str__(self) -> str:
        speed = math.hypot(self.north_m_s, self.east_m_s)
        origin = math.degrees(math.atan2(-self.east_m_s, -self.north_m_s)) % 360.0
        parts = [
            f"{name} {w:+.1f} +- {e:.1f}"
            for name, (w, e) in zip(("north", "east"), self._components(), strict=True)
            if e is not None
        ]
        return f"a wind of {speed:.1f} m/s from {origin:.0f} deg ({', '.join(parts)})"


@dataclass(frozen=True)
class Scale:
    """A barometer's scale against a GPS or a rangefinder (the reference):
    ``z_baro - c = scale * h_ref + b`` over the flight; and the wind its dynamic pressure told
    (None: none told)."""

    scale: float
    std: float | None  # None: not estimated
    reference: str
    how: str
    applied: bool
    wind: Wind | None = None
    # the fit on the heights' changes alone, where it was made: its scale and standard error
    changes: tuple[float, float] | None = None


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


#: A rangefinder tilted further than this from the vertical measures no height: PX4's EKF2
#: uses none (``range_cos_max_tilt``, 45 degrees), ArduPilot's Copter corrects for no more.
#: Beyond it a small error of the attitude (10 Hz, interpolated through a roll) is a large one
#: of ``d cos(tilt)``, and the beam meets ground far to the side.
MAX_TILT_DEG = 45.0
MIN_COS_TILT = math.cos(math.radians(MAX_TILT_DEG))
TILTED = f"tilted more than {MAX_TILT_DEG:.0f} degrees"


def tilt_at(series: Series, attitude: Attitude) -> FloatArray:
    """``cos(roll) cos(pitch)`` at each sample of ``series`` that ``attitude`` covers (at least
    two samples of it), NaN at the others."""
    tilt = np.full(series.t.size, np.nan)
    inside = (series.t >= attitude.t[0]) & (series.t <= attitude.t[-1])
    tilt[inside] = attitude.down_at(series.t[inside])[:, 2]
    return tilt


def tilt_correct(series: Series, attitude: Attitude | None) -> Series:
    """Vertical height from a downward rangefinder's distance [m]: ``d cos(roll) cos(pitch)``.

    Only for ``RFND``/``SONR`` distances, and only where the attitude covers the sample and the
    sensor is within ``MAX_TILT_DEG`` of the vertical (the other samples are dropped, counted in
    ``dropped``). Without attitude the series is returned unchanged, and its datum says so.
    """
    if not series.is_raw_rangefinder:
        return series
    if attitude is None or attitude.t.size < 2:
        return replace(series, datum=f"{series.datum} (not tilt-corrected: no attitude)")
    tilt = tilt_at(series, attitude)
    inside = np.isfinite(tilt)
    level = tilt >= MIN_COS_TILT
    dropped = dict(series.dropped)
    if (~inside).any():
        dropped["outside the attitude's time range"] = int((~inside).sum())
    if (inside & ~level).any():
        dropped[TILTED] = int((inside & ~level).sum())
    return replace(
        series,
        datum=f"{series.datum} (tilt-corrected with {attitude.source})",
        t=series.t[level],
        value=series.value[level] * tilt[level],
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
    """The first ``seconds`` of ticks where ``mask`` holds, the first of them at least (a
    ``--ground-window`` of 1e-320 s added to a tick's time is that time: no tick was in it,
    and referring the sensors failed on an empty window)."""
    out: npt.NDArray[np.bool_] = np.zeros(mask.shape, dtype=bool)
    idx = np.flatnonzero(mask)
    if idx.size:
        out[idx[t[idx] < t[idx[0]] + seconds]] = True
        out[idx[0]] = True
    return out


def _smoothed(h: FloatArray, rate_hz: float) -> FloatArray:
    """``h`` on a clock of ``rate_hz`` as the take-off is looked for in it: its 1 s running
    median."""
    return running_median(h, max(1, round(rate_hz)))


def detect_takeoff(
    t: FloatArray,
    h: FloatArray,
    smooth: FloatArray,
    ground_s: float,
    climb_m: float,
    since: float | None = None,
) -> float | None:
    """The take-off [s] of the first rise of ``h`` (``smooth``: :func:`_smoothed`) ``climb_m``
    above its level over the log's first ``ground_s`` seconds; or, ``since`` the autopilot's
    land detector said the vehicle flies, above its level over the ``ground_s`` seconds before
    that and after it (a barometer warming on the ground rises as well: a copter's rose 1 m in
    30 s of the 72 s it stood before take-off). The take-off is where that rise last passed
    ``TAKEOFF_RISE_M`` (or ``climb_m``, where less) above the ground."""
    valid = np.isfinite(h)
    if since is None:
        start, after = _first_seconds(valid, t, ground_s), valid
    else:
        start, after = valid & (t > since - ground_s) & (t <= since), valid & (t >= since)
    if not start.any():
        return None
    ground = float(np.median(h[start]))
    above = np.flatnonzero(after & (smooth > ground + climb_m))
    if not above.size:
        return None
    rising = int(above[0])
    low = np.flatnonzero(after[:rising] & (smooth[:rising] <= ground + TAKEOFF_RISE_M))
    if low.size:  # the tick after the rise's last at or under TAKEOFF_RISE_M
        rising = int(low[-1] + 1 + np.argmax(after[low[-1] + 1 :]))
    return float(t[rising])


def detector_takeoffs(landed: Samples | None) -> tuple[float, ...]:
    """The times [s] at which the autopilot's land detector (``landed``: its verdict, 1 on the
    ground) turns from landed to flying."""
    if landed is None or landed.t.size < 2:
        return ()
    order = np.argsort(landed.t, kind="stable")
    t, on = landed.t[order], landed.value[order] > 0.5
    # each landed span's end, where one follows: as the smoother reads the spans
    return tuple(float(t[end]) for _, end in runs(on) if end < t.size)


def _ground_before(
    takeoff: float | None,
    clock: tuple[FloatArray, npt.NDArray[np.bool_], FloatArray, Sequence[FloatArray]],
    ground_s: float,
    climb_m: float,
) -> tuple[npt.NDArray[np.bool_], str, bool]:
    """The ground window before ``takeoff`` on the ``clock`` (its ticks, where the reference
    is valid, the reference smoothed: :func:`_smoothed`, and the witnesses of :func:`_moving`),
    how it was found, and whether the vehicle stood there (empty, and why not, where it did
    not)."""
    t, ref_valid, smooth, witnesses = clock
    empty = np.zeros(t.size, dtype=bool)
    if takeoff is None:
        return empty, "first seconds of the log (no take-off found)", False
    if t[ref_valid][0] >= takeoff - TAKEOFF_MARGIN_S:
        return empty, "first seconds of the log (take-off too early for a ground window)", False
    end = takeoff - TAKEOFF_MARGIN_S
    window = (t >= end - ground_s) & (t <= end)
    if not (window & ref_valid).any():
        return window, "first seconds of the log (no reference sample before take-off)", False
    if _moving(smooth, window & ref_valid, climb_m, witnesses):
        # a log begun in flight: its first seconds are a climb, not a ground
        return empty, "first seconds of the log (moving before take-off was found)", False
    return window, f"ground before take-off at {takeoff:.1f} s", True


def lift_off(t: FloatArray, smooth: FloatArray, takeoff: float) -> float:
    """Where the rise of the reference (``smooth``: :func:`_smoothed`, NaN where it has no
    value) that reached the ``takeoff`` began: over the LIFTOFF_LOOKBACK_S before it, the
    knee of a line and a steeper one joined there (the least squares over each knee at a
    tick), steeper by LIFTOFF_RISE_M at least by the take-off: a barometer warming on the
    ground rises along the first line, not at the knee. ``takeoff`` where no knee turns
    upwards so."""
    span = (t >= takeoff - LIFTOFF_LOOKBACK_S) & (t <= takeoff) & np.isfinite(smooth)
    x, y = t[span] - takeoff, smooth[span]
    best, knee = math.inf, takeoff
    for at in x[1:-1]:
        columns = np.column_stack([np.ones(x.size), x, np.maximum(x - at, 0.0)])
        coef = np.linalg.lstsq(columns, y, rcond=None)[0]
        misfit = float(np.sum((columns @ coef - y) ** 2))
        if -coef[2] * at >= LIFTOFF_RISE_M and misfit < best:
            best, knee = misfit, takeoff + float(at)
    return knee


def _moving(
    smooth: FloatArray,
    window: npt.NDArray[np.bool_],
    climb_m: float,
    witnesses: Sequence[FloatArray] = (),
) -> bool:
    """Whether a height (``smooth``: :func:`_smoothed`) changes by ``climb_m`` or more over the
    ticks of ``window``: the vehicle did not stand there; unless one of ``witnesses`` (other
    sources' heights, smoothed alike), valid on half the window's ticks at least, changes by
    less than half of that there: a barometer alone moved (in the rotors' wash as the motors
    spin up, ``tests/variants.py``'s ``wash-1``: a PX4 simulator log's ground refused and its
    first seconds taken for it, 0.652 m RMSE)."""
    there = smooth[window]
    if not (there.size and float(np.nanmax(there) - np.nanmin(there)) >= climb_m):
        return False
    for other in witnesses:
        seen = other[window]
        seen = seen[np.isfinite(seen)]
        if 2 * seen.size >= there.size and float(np.ptp(seen)) < climb_m / 2:
            return False
    return True


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
    the ground (:func:`detector_takeoffs`), where the log tells: the take-off is the
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
        ``full``: each barometer's scale too, where the flight can tell it (:func:`baro_scales`);
        ``offset``: offsets only.
    told
        What a rangefinder reads when landed [m] by name (``RNGFNDn_GNDCLEAR``): its offset
        when it has no valid reading in the ground window (its ground readings below its
        minimum range), rather than one matched in flight to a barometer that may drift. The
        GPS's ground speed and course, where the log has them: a barometer's scale is fitted
        beside its dynamic pressure in a wind (:func:`baro_scales`). The times the autopilot's
        land detector said the vehicle left the ground: the first of them in the segment is
        where the reference's rise is sought from, or, without a rise after it (a hop lower
        than ``takeoff_climb_m``), the take-off itself.
    """
    ground_s, climb_m = ground_window_s, takeoff_climb_m
    t, z = aligned.t, aligned.z
    ref = choose_reference(aligned)
    ref_valid = np.isfinite(z[:, ref])
    smooth = _smoothed(z[:, ref], aligned.rate_hz)
    heights = (t, z[:, ref], smooth)
    # a barometer's ground is witnessed by the other kinds of source (:func:`_moving`)
    witnesses = [
        _smoothed(z[:, i], aligned.rate_hz)
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
        window, ground_how, real = _ground_before(
            takeoff, (t, ref_valid, smooth, witnesses), ground_s, climb_m
        )
        if real:
            ground_how += told_by
            break
    detected = real and bool(told_by)
    if not (window & ref_valid).any():
        window = _first_seconds(ref_valid, t, ground_s)
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
    (:func:`_on_changes`), and the ``scales`` fitted again with them where they differ.

    In a climb a barometer's scale hides a step from the lines either side of it, and the step
    moves the scale's fit on the heights; not the fit on their changes, which has one change
    across it."""
    h, offsets = referred
    rescaled = _on_changes(scales)
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
        sel = _first_seconds(valid & np.isfinite(h[:, j]), t, seconds)
        if sel.sum() >= MIN_WINDOW_TICKS:
            return j, sel
    return None


def dynamic_head(speed: Samples | None, t: FloatArray) -> FloatArray | None:
    """``V^2 / 2g`` [m] at the times ``t``, ``V`` the horizontal ``speed`` over the ground (the
    airspeed where the air is still): how much higher a barometer reads per unit of its
    dynamic-pressure coefficient (DYNAMIC_PRIOR); None without a speed, or in a flight never
    fast enough to tell it (DYNAMIC_MIN_M)."""
    if speed is None or speed.t.size < 2 or not t.size:
        return None
    head: FloatArray = _at(speed, t) ** 2 / (2.0 * G)
    return head if head.max() >= DYNAMIC_MIN_M else None


#: The dynamic pressure's columns of the scale's fit (:func:`_air_columns`), and which of
#: the ground velocity's components (0 north, 1 east) follow the head's.
_Air = tuple[FloatArray, tuple[int, ...]]


def _air_columns(track: Track | None, t: FloatArray) -> _Air | None:
    """The scale fit's columns of the dynamic pressure at the times ``t``: the head
    (:func:`dynamic_head`) and, where the log has the course, ``V_north / g`` and ``V_east /
    g`` (``WIND_PRIOR_M_S``), each where the flight has it beyond ``TRACK_RESOLUTION_M_S`` (a
    track along a meridian has no east); None where there is no head to fit."""
    head = None if track is None else dynamic_head(track.speed, t)
    if track is None or head is None:
        return None
    ne = track.components(t)
    if ne is None:
        return head[:, None], ()
    axes = tuple(int(i) for i in np.flatnonzero(np.max(np.abs(ne), axis=1) > TRACK_RESOLUTION_M_S))
    return np.column_stack([head, *(ne[list(axes)] / G)]), axes


def baro_scales(
    aligned: Aligned,
    h: FloatArray,
    offsets: dict[int, Offset],
    steps: Sequence[Step] = (),
    track: Track | None = None,
) -> dict[int, Scale]:
    """Each barometer's scale against the GPS with the most referred ticks, or against the
    rangefinder with the most where that fit's standard error is the smaller (see the module
    doc). The simulators' sonar flights with their GPS left out had scale 1, "not estimated: no
    GPS", and the smoother followed the barometer 0.40 and 0.70 m above the rangefinder; with a
    real receiver's GPS (0.3 m noisy, wandering) 0.37 and 0.65 m. Against the rangefinder the
    10 m one's is 1.052 +- 0.005, applied: 0.021 and 0.026 m (the 8 m rangefinder's 0.223 ->
    0.017 and 0.016 m). The 9 m one's without GPS, 1.083 +- 0.033 (one 6 s climb among its 10 s
    spans), is not applied. With the simulators' own GPS, the GPS's fit is the better on all.

    ``h`` holds the sources referred by offsets only. Over the ticks where both are valid (but
    the 20 s after a step that settles back, :func:`_unsettled`), ``h_baro = scale * h_gps +
    drift * t + b`` by least squares, twice more without those beyond 3 sigma (a glitch), with
    a drift in time (a barometer warming: a drift is not a scale)
    and a constant ``b`` (a datum matched in flight); and ``+ k |V - W|^2 / 2g`` where the
    GPS's ground velocity (``track``) tells ``k`` from 0 (:func:`dynamic_head`, DYNAMIC_SIGMAS:
    fast stretches flown high read as a scale otherwise), ``W`` the wind where the log has the
    course (WIND_PRIOR_M_S; each leg of a flight out and back in a wind feels its own airspeed
    at one ground speed). Its standard error is the larger of that
    fit's (one sample per ``SCALE_BLOCK_S``) and the same fit's on the changes over successive
    spans (``SCALE_CHANGES``): the GPS's wander counts. Applied when that error is at most
    ``MAX_SCALE_STD``, the scale differs from 1 by ``SCALE_MIN_SIGMAS`` of it and lies in
    ``SCALE_RANGE``; otherwise the barometer keeps scale 1 and the record says why.
    """
    kinds, names = aligned.kinds, aligned.names
    baros = [i for i in offsets if kinds[i] == "baro"]
    if not baros:
        return {}
    # the GPS, and a rangefinder: over the ground it measures, the height itself
    references = [
        max(found, key=lambda j: (int(np.isfinite(h[:, j]).sum()), -j))
        for kind in ("gps", "rangefinder")
        if (found := [j for j in offsets if kinds[j] == kind])
    ]
    if not references:
        return {
            i: Scale(1.0, None, "", "not estimated: no GPS or rangefinder", False) for i in baros
        }
    air = _air_columns(track, aligned.t)

    def fit(i: int, j: int) -> Scale:
        theirs = _between(steps, names[i], names[j])
        y = _unsettled(aligned.t, h[:, i], theirs)
        return _scale(aligned.t, (h[:, j], y), names[j], [s.time_s for s in theirs], air)

    return {
        i: min(
            (fit(i, j) for j in references), key=lambda sc: math.inf if sc.std is None else sc.std
        )
        for i in baros
    }


def _on_changes(scales: dict[int, Scale]) -> dict[int, Scale]:
    """``scales`` with each barometer's fit on the changes (:func:`_scale`) applied where it is
    a scale that fit could apply: its standard error within MAX_SCALE_STD and its value in
    SCALE_RANGE."""
    out = {}
    for i, sc in scales.items():
        if sc.changes is not None:
            scale, std = sc.changes
            if std <= MAX_SCALE_STD and SCALE_RANGE[0] <= scale <= SCALE_RANGE[1]:
                out[i] = replace(sc, scale=scale, applied=True)
    return out


def _in_time(t: FloatArray, valid: npt.NDArray[np.bool_]) -> tuple[FloatArray, float]:
    """A level fit's time column [min from the first ``valid`` tick, a drift's regressor], and
    its rows per independent one: the GPS's wander correlates the residuals, one independent
    sample per SCALE_BLOCK_S."""
    blocks = float(np.ptp(t[valid])) / SCALE_BLOCK_S
    return (t - t[valid][0]) / 60.0, float(valid.sum()) / max(blocks, 2.0)


def _between(steps: Sequence[Step], a: str, b: str) -> list[Step]:
    """The ``steps`` of sensor ``a`` or ``b`` against any other: which of a step's two sensors
    jumped the datum does not know, and a barometer's jump found against the GPS is one against
    a rangefinder too."""
    return [s for s in steps if {s.first, s.second} & {a, b}]


def _unsettled(t: FloatArray, y: FloatArray, steps: Sequence[Step]) -> FloatArray:
    """A barometer's heights ``y`` without those over STEP_SETTLE_S after each of the ``steps``
    (its own or its reference's, :func:`_between`) that settles back
    (:attr:`altfuse.steps.Step.settle_m`): a transient, which a scale fit takes for a scale
    where the flight climbs or descends around it."""
    out: FloatArray = y.copy()
    for s in steps:
        if s.settle_m:
            start, end = s.settling_s
            out[(t > start) & (t <= end)] = np.nan
    return out


def _scale(
    t: FloatArray,
    heights: tuple[FloatArray, FloatArray],
    reference: str,
    steps: Sequence[float] = (),
    air: _Air | None = None,
) -> Scale:
    """``y = scale x + drift t + b`` (``heights``: ``x``, ``y``), the scale and its standard
    error (see :func:`baro_scales`); with a free step in ``y - x`` at each of ``steps`` [s],
    and the dynamic pressure's columns ``air`` (:func:`_air_columns`) where given and both
    fits tell its ``k`` from 0 (:func:`_told`), and the wind they tell (:func:`_wind`)."""
    x, y = heights
    both = np.isfinite(x) & np.isfinite(y)
    if both.sum() < 2 * SCALE_MIN_CHANGES:
        return Scale(1.0, None, reference, f"not estimated: too few ticks beside {reference}",
                     False)  # fmt: skip
    minutes, per_independent = _in_time(t, both)
    # one free level per split of the ticks both have (steps in one gap, or at one instant
    # against two sensors, are one)
    shared = t[both]
    splits = {int(np.searchsorted(shared, at, side="right")) for at in steps} - {0, shared.size}
    jumps = [(t >= shared[k]).astype(np.float64) for k in sorted(splits)]
    levels = (
        np.column_stack([x, minutes, np.ones(t.size), *jumps])[both],
        y[both],
        [math.inf, DRIFT_PRIOR_M_PER_MIN, math.inf] + [math.inf] * len(jumps),
        per_independent,
    )
    lo, hi = SCALE_SPAN_S
    # too few ticks for SCALE_CHANGES spans that long: shorter ones, as many
    lo = min(lo, float(both.sum()) * float(t[1] - t[0]) / SCALE_CHANGES)
    span = min(max(float(np.ptp(t[both])) / SCALE_CHANGES, lo), hi)
    k = max(1, round(span / float(t[1] - t[0])))
    # the same on the changes over successive spans: drift and b become one constant
    dx, dy = x[::k][1:] - x[::k][:-1], y[::k][1:] - y[::k][:-1]
    ok = np.isfinite(dx) & np.isfinite(dy)
    ends = t[::k]
    for at in steps:  # a change across a step is no scale's
        ok &= ~((ends[:-1] < at) & (ends[1:] > at))
    drift_per_span = DRIFT_PRIOR_M_PER_MIN * k * float(t[1] - t[0]) / 60.0
    changes = (
        np.column_stack([dx[ok], np.ones(int(ok.sum()))]), dy[ok], [math.inf, drift_per_span], 1.0
    )  # fmt: skip
    told, wind = None, None
    if air is not None:
        cols, axes = air
        rows = (cols[both], np.diff(cols[::k], axis=0)[ok])
        told, wind = _with_wind(rows, axes, (levels, changes))
    fit, change = told or (_robust_fit(*levels), _robust_fit(*changes))
    if fit is None or change is None:
        return Scale(1.0, None, reference, f"not estimated: {_unfit(changes[1].size)}", False)
    scale = float(fit[0][0])
    std = max(float(fit[1][0]), float(change[1][0]))
    by_changes = (float(change[0][0]), float(change[1][0]))
    beside = (" beside its dynamic pressure" + (f" in {wind}" if wind else "")) if told else ""
    label = f"{scale:.4f} +- {std:.4f} against {reference}{beside}"
    if not std <= MAX_SCALE_STD:
        how = f"not applied: {label}: too little vertical range to tell"
        return Scale(scale, std, reference, how, False, wind, by_changes)
    if abs(scale - 1.0) < SCALE_MIN_SIGMAS * std:
        how = f"not applied: {label}: not different from 1"
        return Scale(scale, std, reference, how, False, wind, by_changes)
    if not SCALE_RANGE[0] <= scale <= SCALE_RANGE[1]:
        how = f"not applied: {label}: implausible"
        return Scale(scale, std, reference, how, False, wind, by_changes)
    return Scale(scale, std, reference, f"{label} over the flight", True, wind, by_changes)


def _unfit(changes: int) -> str:
    """Why a barometer's scale fit told nothing, with ``changes`` rows of height changes: too
    few of them, else too little vertical range to tell a scale from an offset."""
    if changes < SCALE_MIN_CHANGES:
        return f"{changes} spans with both heights' change, fewer than {SCALE_MIN_CHANGES}"
    return "no vertical range"


#: A least-squares problem for :func:`_robust_fit`: design, observations, priors, rows per
#: independent one; and its solution: the coefficients and their standard errors.
_Fit = tuple[FloatArray, FloatArray, list[float], float]
_Solved = tuple[FloatArray, FloatArray]


def _told(fits: Sequence[tuple[FloatArray, _Fit]]) -> list[_Solved] | None:
    """Each fit solved with its columns of the dynamic pressure last (``fits``: those columns,
    the head's first, and the fit without them; :func:`_air_columns`) where every one tells
    the head's coefficient from 0 by DYNAMIC_SIGMAS of its standard error; None where one does
    not. The levels' fit alone took a real receiver's wander (0.3 m noisy and walking) for a
    head 3 sigma from 0 in a 305 m climb, and the scale it left was 0.7 % off (2 m at the
    top)."""
    out: list[_Solved] = []
    for air, (design, y, prior, per_independent) in fits:
        m = air.shape[1]
        wind = [DYNAMIC_PRIOR * WIND_PRIOR_M_S] * (m - 1)
        solved = _robust_fit(
            np.column_stack([design, air]), y, [*prior, DYNAMIC_PRIOR, *wind], per_independent
        )
        if solved is None or not abs(solved[0][-m]) > DYNAMIC_SIGMAS * solved[1][-m]:
            return None
        out.append(solved)
    return out


def _with_wind(
    rows: tuple[FloatArray, FloatArray], axes: tuple[int, ...], fits: tuple[_Fit, _Fit]
) -> tuple[list[_Solved] | None, Wind | None]:
    """The levels' and the changes' ``fits`` with the dynamic pressure's columns (``rows``:
    each fit's rows of them, :func:`_air_columns`), and the wind they tell: with the wind's
    columns where both fits tell the head and the wind there (a
    wind strong beside the cruise leaves the ground speed's head untold: out and back at 8
    m/s in a 3 m/s wind, k 0.24 +- 0.03 and -0.15 +- 0.15 for 0.8); else the head alone where
    both tell it, with the wind where the levels' fit tells it beside that head (the changes
    over a 305 m climb's 26 spans cannot tell three coefficients); else None."""
    if axes:
        told = _told(tuple(zip(rows, fits, strict=True)))
        wind = None if told is None else _wind(told[0], axes)
        if told is not None and wind is not None:
            return told, wind
    told = _told(tuple(zip((r[:, :1] for r in rows), fits, strict=True)))
    if told is None or not axes:
        return told, None
    windy = _told(((rows[0], fits[0]),))
    wind = None if windy is None else _wind(windy[0], axes)
    return ([windy[0], told[1]] if windy is not None and wind is not None else told), wind


def wind_beside(t: FloatArray, residual: FloatArray, track: Track) -> Wind | None:
    """The wind a barometer's ``residual`` at its samples' times ``t`` against a height not its
    own tells: ``residual = b + drift t + k |V - W|^2 / 2g``, fitted as the scale's levels are
    (:func:`baro_scales`), where it tells the head and the wind (:func:`_wind`); None where
    it does not, or without a head or a course."""
    air = _air_columns(track, t)
    ok = np.isfinite(residual)
    if air is None or not air[1] or ok.sum() < 2 * SCALE_MIN_CHANGES:
        return None
    minutes, per_independent = _in_time(t, ok)
    levels = (
        np.column_stack([np.ones(t.size), minutes])[ok],
        residual[ok],
        [math.inf, DRIFT_PRIOR_M_PER_MIN],
        per_independent,
    )
    told = _told(((air[0][ok], levels),))
    return None if told is None else _wind(told[0], air[1])


def _wind(fit: _Solved, axes: tuple[int, ...]) -> Wind | None:
    """The wind a fit with the dynamic pressure's columns last tells (:func:`_told`; the
    head's, then the ground velocity's components ``axes``): ``W = -(k W) / k`` from their
    coefficients, each component's error to first order in theirs, where it lies
    DYNAMIC_SIGMAS from still air (:attr:`Wind.sigmas`: a component the flight seldom flew
    along is poorly told, and matters as little to its airspeed); None where it does not, or
    without a course (no ``axes``; 0 along a component the flight never has)."""
    m = len(axes)
    if not m:
        return None
    (k, *kw), (k_std, *kw_std) = fit[0][-m - 1 :], fit[1][-m - 1 :]
    value: list[float] = [0.0, 0.0]
    std: list[float | None] = [None, None]
    for axis, c, c_std in zip(axes, kw, kw_std, strict=True):
        value[axis] = float(-c / k)
        std[axis] = float(math.hypot(c_std, value[axis] * k_std) / abs(k))
    wind = Wind(value[0], value[1], std[0], std[1])
    return wind if wind.sigmas > DYNAMIC_SIGMAS else None


def _robust_fit(
    design: FloatArray, y: FloatArray, prior: Sequence[float], per_independent: float = 1.0
) -> _Solved | None:
    """The coefficients of ``y ~ design`` by least squares, with a zero-mean normal prior of
    standard deviation ``prior[j]`` on coefficient ``j`` (``inf``: none), refitted twice
    without the residuals beyond 3 sigma (and ``SCALE_MIN_OUTLIER_M``), and their standard
    errors, the residuals' variance counted ``per_independent`` times (correlated residuals:
    rows per independent one); a rejection that would leave fewer than SCALE_MIN_CHANGES rows
    is not made (the fit before it stands); None with fewer rows than that, or where the
    design cannot tell the coefficients."""
    if y.size < SCALE_MIN_CHANGES:
        return None
    keep = np.ones(y.size, dtype=bool)
    precision = np.diag(1.0 / np.asarray(prior, dtype=np.float64) ** 2)
    sigma = math.inf  # the first fit has no prior to weigh against
    for _ in range(4):
        ata, atb = _normal_equations(design, y, keep)
        weight = 0.0 if math.isinf(sigma) else 1.0 / max(sigma, 1e-6) ** 2
        normal = weight * ata + precision if weight else ata
        if np.linalg.cond(normal) > 1e12:
            return None
        coef = np.asarray(np.linalg.solve(normal, (weight or 1.0) * atb), dtype=np.float64)
        r = y - design @ coef
        sigma = max(MAD_TO_SIGMA * float(np.median(np.abs(r[keep] - np.median(r[keep])))), 1e-6)
        inside = np.abs(r) <= max(3.0 * sigma, SCALE_MIN_OUTLIER_M)
        if inside.sum() < SCALE_MIN_CHANGES:  # too few rows to refit on: this fit stands
            break
        keep = inside
    n, p = int(keep.sum()), design.shape[1]
    if n <= p + 1:
        return None
    residual = max(float(np.sum(r[keep] ** 2)) / (n - p), 1e-12) * per_independent
    normal = _normal_equations(design, y, keep)[0] / residual + precision
    return coef, np.sqrt(np.diag(np.linalg.inv(normal)))


#: Rows of a fit's design taken at once into its normal equations (:func:`_normal_equations`).
NORMAL_ROWS = 1 << 16


def _normal_equations(
    design: FloatArray, y: FloatArray, keep: npt.NDArray[np.bool_]
) -> tuple[FloatArray, FloatArray]:
    """``A^T A`` and ``A^T y`` over the rows of ``design`` (``A``) that ``keep`` keeps, summed
    over NORMAL_ROWS rows at a time: the kept rows' copy was the design's size (a ULog's
    barometer at 97 Hz: 27 MB a copy, two alive at once, in a 300 MB log's wind fit)."""
    ata: FloatArray = np.zeros((design.shape[1], design.shape[1]))
    atb: FloatArray = np.zeros(design.shape[1])
    for start in range(0, y.size, NORMAL_ROWS):
        rows = slice(start, start + NORMAL_ROWS)
        a, b = design[rows][keep[rows]], y[rows][keep[rows]]
        ata += a.T @ a
        atb += a.T @ b
    return ata, atb


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
