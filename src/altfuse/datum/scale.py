"""Each barometer's scale against the GPS or a rangefinder (the ``full`` referral of
:mod:`altfuse.datum`): a least-squares fit of its referred heights beside a drift in time, its
dynamic pressure at the ground speed and, from the GPS's course, a steady wind; robust to
glitches, with a standard error that counts the GPS's wander (:func:`baro_scales`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from altfuse.align import Aligned
from altfuse.inertial import G
from altfuse.metrics import MAD_TO_SIGMA
from altfuse.model import FloatArray, Samples, brief_repr
from altfuse.steps import Step

if TYPE_CHECKING:
    from altfuse.datum import Offset

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


def on_changes(scales: dict[int, Scale]) -> dict[int, Scale]:
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
