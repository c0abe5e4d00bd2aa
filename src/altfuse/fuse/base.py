"""The contract of every fusion method: what it takes (:class:`FusionInput` and its own frozen
parameters), what it declares (:class:`Method`), what it returns (:class:`FusionResult`), and
the weighted combination most of them share (:func:`combine`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Final, Generic, Literal, TypeVar

import numpy as np
import numpy.typing as npt

from altfuse.datum.scale import Track, Wind
from altfuse.inertial import VerticalAcceleration
from altfuse.model import (
    SENSOR_KINDS,
    FloatArray,
    Samples,
    SensorKind,
    brief_repr,
    sensor_name,
)
from altfuse.params import Params

#: Per-tick status of the fused value.
Status = Literal["fused", "equal", "single", "none", "inertial", "diverged"]
FUSED: Final[Status] = "fused"  # weighted as the method says
EQUAL: Final[Status] = "equal"  # the method's weights were all zero: equal weights over the valid
SINGLE: Final[Status] = "single"  # one valid sensor: the result is that sensor
NONE: Final[Status] = "none"  # no valid sensor: the result is NaN
INERTIAL: Final[Status] = "inertial"  # no valid sensor; the accelerometer carried the estimate
DIVERGED: Final[Status] = "diverged"  # the value left every valid sensor (altfuse.guard)

#: What a method may ask the pipeline to compute from the log beyond what every method gets.
LogInput = Literal["accel"]
#: The largest height [m] :meth:`FusionInput.from_heights` takes, above or below its zero: 80
#: times the plausible envelope's top (``altfuse.screen``: 12,000 m AMSL). Heights of 1e201 m
#: overflowed every method's squares, a warning or an OverflowError from inside it.
MAX_HEIGHT_M = 1e6


#: A step between sensors: its time [s], the sensors that may have jumped, the jump [m], how
#: far from that time the jump may lie [s] (found across a gap of one sensor's: half the gap;
#: the smoother narrows it, :func:`altfuse.fuse.smoother.noise.with_jumps`), and how far it
#: settles after it [m] (:attr:`altfuse.steps.Step.settle_m`).
Jump = tuple[float, tuple[int, ...], float, float, float]


def own_jump(step: Jump, sensor: int) -> Jump:
    """``step`` (between two sensors, the second's jump against the first's) as ``sensor``'s
    own jump: its size and settling the other way round where it is the first."""
    time, sensors, size, half, settle = step
    sign = 1.0 if sensor == sensors[1] else -1.0
    return (time, (sensor,), sign * size, half, sign * settle)


def joined_jump(jumps: Sequence[Jump], sensors: tuple[int, ...], half: float) -> Jump:
    """``jumps`` made one jump of ``sensors`` at the first's time, within ``half`` of it [s]:
    their mean size and mean settling."""
    return (
        jumps[0][0],
        sensors,
        float(np.mean([j[2] for j in jumps])),
        half,
        float(np.mean([j[4] for j in jumps])),
    )


@dataclass(frozen=True)
class FusionInput:
    """Everything a method fuses, from one log, on one clock and one datum.

    Attributes
    ----------
    t
        The clock [s], shape (T,), uniform with tick ``dt_s``.
    z
        Each sensor's height above take-off [m] on the clock, shape (T, n); NaN where absent.
    names, kinds
        Each sensor's name (``gps``, ``baro2``, ...) and kind, in ``z``'s column order.
    samples
        Each sensor's own samples, referred to take-off like ``z``, in ``z``'s order.
    dt_s
        The clock's tick [s].
    on_ground_s
        The spans [s] in which the vehicle stood at its take-off point (one per segment of a
        spliced log with its own ground); empty if the log cannot tell.
    splices
        Each segment's start [s] after the first, where the log was spliced (nothing says where
        the vehicle went between), and whether its heights were referred to a ground (its own or
        the main segment's: every offset 0 there) or carry the main segment's offsets.
    track
        The GPS's horizontal speed over ground [m/s] and, where the log has it, its course
        (:class:`altfuse.datum.scale.Track`); None if the log has no speed (``speed`` reads it).
    wind
        The steady wind the datum's scale fit found beside the barometers' dynamic pressure
        (:class:`altfuse.datum.scale.Wind`); None where it found none.
    temperatures
        Each sensor's temperature [degC] samples or None, in ``z``'s order.
    accel
        The vertical acceleration, for a method that ``uses`` ``"accel"``; None otherwise and
        when the log has no IMU or attitude.
    gps_velocity_up
        The first GPS's vertical velocity [m/s, up] samples, moved by that GPS's lag; None if
        the log has none.
    datum_windows
        Each sensor's span [s] over which its offset was measured standing at the take-off
        point, in ``z``'s order; None where it was not (matched to another sensor, a log
        without a take-off).
    landed
        The autopilot's own on-ground verdict (1 on the ground, 0 flying) samples; None if the
        log has none.
    ground_effect_s
        The spans [s] in which the barometers may read in the air the vehicle stirs near the
        ground as it takes off (:attr:`altfuse.datum.Referred.ground_effect_s`); empty where
        the log has no take-off from a ground.
    scale_unknown
        Per sensor, in ``z``'s order: for a barometer whose scale the datum estimated and did not
        apply, that estimate and its standard error (:attr:`altfuse.datum.Offset.scale_unknown`);
        None otherwise.
    scale_known
        Per sensor, in ``z``'s order: for a barometer whose scale the datum applied, that scale
        and its standard error (:attr:`altfuse.datum.Offset.scale_known`); None otherwise.
    steps
        The instants [s] at which two sensors' heights jump against each other
        (:mod:`altfuse.steps`): each with the sensors that may have jumped, by their indices
        in ``z``'s order, and the jump [m]: of the second's heights against the first's, or,
        where a method found which one jumped, that one alone and its own jump.
    tentative
        As ``steps``, those found only across a gap of one sensor's, below
        :data:`altfuse.steps.STEP_SIGMAS` (:attr:`altfuse.steps.Step.tentative`): a jump where
        a method's evidence tells one from none.
    analysis
        The same inputs on the datum's clock (:data:`altfuse.datum.DATUM_RATE_HZ`), where ``t``
        is another: a method that decides its model on clock ticks (the smoother) decides it
        there, and its answer does not move with the output's rate; None on that clock.
    """

    __repr__ = brief_repr

    t: FloatArray
    z: FloatArray
    names: tuple[str, ...]
    kinds: tuple[SensorKind, ...]
    samples: tuple[Samples, ...]
    dt_s: float
    on_ground_s: tuple[tuple[float, float], ...] = ()
    splices: tuple[tuple[float, bool], ...] = ()
    track: Track | None = None
    wind: Wind | None = None
    temperatures: tuple[Samples | None, ...] = ()
    accel: VerticalAcceleration | None = None
    gps_velocity_up: Samples | None = None
    datum_windows: tuple[tuple[float, float] | None, ...] = ()
    scale_unknown: tuple[tuple[float, float] | None, ...] = ()
    scale_known: tuple[tuple[float, float] | None, ...] = ()
    landed: Samples | None = None
    ground_effect_s: tuple[tuple[float, float], ...] = ()
    steps: tuple[Jump, ...] = ()
    tentative: tuple[Jump, ...] = ()
    analysis: FusionInput | None = None

    def __post_init__(self) -> None:
        n = self.z.shape[1] if self.z.ndim == 2 else -1
        if self.z.shape[:1] != self.t.shape or n < 0:
            raise ValueError(f"z has shape {self.z.shape} for a clock of {self.t.size} ticks")
        for what in ("names", "kinds", "samples"):
            if len(getattr(self, what)) != n:
                raise ValueError(f"{len(getattr(self, what))} {what} for {n} sensors")
        # per sensor, None for each where not given
        for what in ("temperatures", "datum_windows", "scale_unknown", "scale_known"):
            if not getattr(self, what):
                object.__setattr__(self, what, (None,) * n)
            if len(getattr(self, what)) != n:
                raise ValueError(f"{len(getattr(self, what))} {what} for {n} sensors")
        if self.accel is not None and self.accel.on_clock.shape != self.t.shape:
            shape = self.accel.on_clock.shape
            raise ValueError(f"accel has shape {shape} for a clock of {self.t.size} ticks")
        if self.analysis is not None and self.analysis.names != self.names:
            raise ValueError(f"analysis has sensors {self.analysis.names} for {self.names}")

    @property
    def speed(self) -> Samples | None:
        """The GPS's horizontal speed over ground [m/s] (``track``'s); None without it."""
        return None if self.track is None else self.track.speed

    @classmethod
    def from_heights(
        cls,
        z: FloatArray,
        dt_s: float = 0.1,
        kinds: Sequence[SensorKind] | None = None,
        names: Sequence[str] | None = None,
        accel_up: FloatArray | None = None,
    ) -> FusionInput:
        """Heights already on a clock ``k dt_s``: ``z`` has a row per tick and a column per
        sensor (one sensor's heights may be given as a 1-D array); each sensor's samples are its
        valid ticks. ``kinds`` default to gps, baro, rangefinder, gps, ... in turn; ``names`` to
        the kinds, numbered from the second of a kind on (``gps2``), as the readers name them;
        ``accel_up`` [m/s², up, at rest 0] is the vertical acceleration at the ticks.
        ValueError for a shape, a tick or a kind that is none of these, and for a height that
        is infinite or beyond ``MAX_HEIGHT_M``."""
        z = np.asarray(z, dtype=np.float64)
        if z.ndim == 1:
            z = z[:, np.newaxis]
        if z.ndim != 2 or z.shape[0] == 0:
            raise ValueError(
                f"z has shape {z.shape}: heights are (ticks, sensors), one tick or more"
            )
        beyond = np.argwhere(~(np.abs(z) <= MAX_HEIGHT_M) & ~np.isnan(z))
        if beyond.size:
            tick, column = beyond[0]
            raise ValueError(
                f"z holds {z[tick, column]:g} at tick {tick}, column {column}: heights are finite "
                f"and within {MAX_HEIGHT_M:g} m, NaN where a sensor has none"
            )
        if not (np.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f"dt_s must be a positive number of seconds, got {dt_s}")
        t = np.asarray(np.arange(z.shape[0]) * dt_s, dtype=np.float64)
        cycle: tuple[SensorKind, ...] = ("gps", "baro", "rangefinder")
        kinds = tuple(kinds or [cycle[i % 3] for i in range(z.shape[1])])
        if len(kinds) != z.shape[1]:
            raise ValueError(f"{len(kinds)} kinds for {z.shape[1]} sensors (the columns of z)")
        if unknown := [k for k in kinds if k not in SENSOR_KINDS]:
            known = ", ".join(SENSOR_KINDS)
            raise ValueError(f"unknown sensor kind {unknown[0]!r}; kinds are {known}")
        if names is None:
            seen = [kinds[:i].count(k) for i, k in enumerate(kinds)]
            names = [sensor_name(k, c) for k, c in zip(kinds, seen, strict=True)]
        names = tuple(names)
        ok = np.isfinite(z)
        samples = tuple(Samples(t[ok[:, i]], z[ok[:, i], i]) for i in range(z.shape[1]))
        accel = None
        if accel_up is not None:
            accel_up = np.asarray(accel_up, dtype=np.float64)
            record = {"source": "given at the clock's ticks"}
            accel = VerticalAcceleration(Samples(t, accel_up), accel_up, record)
        return cls(t, z, names, kinds, samples, dt_s, accel=accel)


@dataclass(frozen=True)
class FusionResult:
    """A fused altitude and how it was made.

    Attributes
    ----------
    fused
        Fused height [m], shape (T,); NaN where no sensor is valid.
    weights
        Weight of each sensor, shape (T, n), summing to 1 over the valid sensors at each tick,
        0 for a sensor that is not valid there, NaN on ticks with no valid sensor.
    status
        Per tick: ``fused``, ``equal`` (the method's weights were all zero), ``single``,
        ``none``, or ``inertial`` (no sensor; the accelerometer carried the estimate).
    traces
        Method-specific diagnostics per sensor, each of shape (T, n), e.g. Paper A's support.
    tick_traces
        Method-specific diagnostics per tick, each of shape (T,), e.g. Paper B's gate k(n).
    params
        The parameters used, with any value the method chose from the data.
    """

    __repr__ = brief_repr

    method: str
    fused: FloatArray
    weights: FloatArray
    status: npt.NDArray[np.str_]  # of Status
    traces: dict[str, FloatArray] = field(default_factory=dict)
    tick_traces: dict[str, FloatArray] = field(default_factory=dict)
    params: dict[str, float | int | str] = field(default_factory=dict)

    @property
    def std(self) -> FloatArray | None:
        """The method's own standard deviation of ``fused`` per tick [m], where it gives one:
        the smoother's ``fused_std``, Paper B's filters' ``fused_variance`` (their P*); None
        for the weightings."""
        if "fused_std" in self.tick_traces:
            return self.tick_traces["fused_std"]
        if "fused_variance" in self.tick_traces:
            return np.sqrt(self.tick_traces["fused_variance"])
        return None


def combine(
    z: FloatArray,
    raw_weights: FloatArray,
    method: str,
    traces: dict[str, FloatArray] | None = None,
    params: dict[str, float | int | str] | None = None,
    tick_traces: dict[str, FloatArray] | None = None,
) -> FusionResult:
    """Normalise ``raw_weights`` over the valid sensors and form ``sum_i w_i z_i``.

    ``raw_weights`` must be >= 0; a sensor whose ``z`` is NaN gets weight 0 whatever its raw
    weight. Where every valid sensor's raw weight is 0 the valid sensors are weighted equally
    (status ``equal``, or ``single`` with one); where none is valid the result is NaN (``none``).
    """
    valid = np.isfinite(z)
    n_valid = valid.sum(axis=1)
    w = np.where(valid, np.nan_to_num(raw_weights, nan=0.0), 0.0)
    total = w.sum(axis=1)
    zero = total <= 0
    w[zero] = valid[zero]
    total = w.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = w / total
    fused = np.where(n_valid > 0, (w * np.where(valid, z, 0.0)).sum(axis=1), np.nan)
    status = np.where(zero, EQUAL, FUSED)
    status = np.where(n_valid == 1, SINGLE, status)
    status = np.where(n_valid == 0, NONE, status)
    return FusionResult(
        method=method,
        fused=fused,
        weights=w,
        status=status,
        traces=traces or {},
        tick_traces=tick_traces or {},
        params=params or {},
    )


P = TypeVar("P", bound=Params)


@dataclass(frozen=True)
class Method(Generic[P]):
    """A registered fusion method: its function, its parameters' type and what it needs.

    Attributes
    ----------
    function
        ``function(inputs, params) -> FusionResult``; never touches files.
    params
        Its frozen parameter dataclass (fields made with :func:`altfuse.params.param`): the CLI's
        options and their checks come from it. ``Params`` itself for a method without any.
    summary
        One line for the help.
    uses
        Inputs the pipeline computes for it only (``accel``: the vertical acceleration).
    requires
        Those of ``uses`` without which it cannot run: the pipeline refuses the log in one line.
    """

    function: Callable[[FusionInput, P], FusionResult]
    params: type[P]
    summary: str
    uses: frozenset[LogInput] = frozenset()
    requires: frozenset[LogInput] = frozenset()

    def __post_init__(self) -> None:
        if not self.requires <= self.uses:
            raise ValueError(f"requires {set(self.requires)} beyond uses {set(self.uses)}")

    def __call__(self, inputs: FusionInput, params: P | None = None) -> FusionResult:
        """Run the method, with its default parameters unless ``params`` are given."""
        return self.function(inputs, self.params() if params is None else params)
