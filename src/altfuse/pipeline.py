"""read -> align -> datum -> fuse, with the provenance of every step."""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, cast

import numpy as np

from altfuse import __version__
from altfuse.align import Aligned, Lag, Span, align, gps_lags, inertial_lag, shift, splices
from altfuse.datum import (
    DATUM_RATE_HZ,
    Offset,
    Referral,
    Referred,
    Segment,
    coarser_than_datum,
    on_clock,
    on_datum_clock,
    refer_to_takeoff,
    referred_samples,
)
from altfuse.datum.scale import Track, Wind
from altfuse.datum.takeoff import detector_takeoffs
from altfuse.datum.tilt import tilt_correct
from altfuse.errors import NoUsableSensorsError, ParameterError, Refusal, UnsupportedLogError
from altfuse.fuse import DEFAULT_METHOD, METHODS, FusionInput, FusionResult, Method, method
from altfuse.fuse.base import Jump, own_jump
from altfuse.guard import guard
from altfuse.inertial import (
    VerticalAcceleration,
    referred_vertical_acceleration,
    velocity_integral,
    vibration_record,
)
from altfuse.io import read_log
from altfuse.memory import release_free_memory
from altfuse.model import FlightLog, Samples, Series, brief_repr
from altfuse.params import Params, param, validate
from altfuse.screen import rangefinder_param, screen
from altfuse.steps import Step

log = logging.getLogger(__name__)
#: What a run is doing now, for a progress line (``altfuse fuse`` on a terminal) or ``-v``.
progress = logging.getLogger("altfuse.progress")


@dataclass(frozen=True)
class FuseOptions:
    """Everything that decides a fusion run besides the log itself; checked when built.

    ``params`` holds the parameters of any method by its name (as ``altfuse evaluate`` runs
    several); a method not in it runs with its defaults. One method's parameters alone are
    ``method``'s (``FuseOptions("support", SupportParams(beta=5))``).
    """

    method: str = DEFAULT_METHOD
    params: Mapping[str, Params] | Params = field(default_factory=dict)
    rate_hz: float = param(
        10.0,
        help="rate of the common clock, the output's (the datum and the smoother's model are "
        "found on a 10 Hz clock at every rate)",
        unit="Hz",
        check="positive",
        maximum=1000.0,
    )
    max_gap_s: float = param(
        1.0,
        help="longest gap in a sensor's data the spline may bridge (at least 1.5 of its own "
        "sampling interval, up to 10 s)",
        unit="s",
        check="positive",
    )
    span: Span = param(
        "union", help="the clock over the union or the overlap of the sensors' time ranges"
    )
    ground_window_s: float = param(
        5.0, help="time on the ground used to find each sensor's datum", unit="s", check="positive"
    )
    takeoff_climb_m: float = param(1.0, help="rise that marks take-off", unit="m", check="positive")
    min_sensors: int = param(
        2, help="fail unless at least this many altitude sources are usable", check="at least 1"
    )
    referral: Referral = param(
        "full",
        help="how sensors are referred to one clock and datum: 'full' (offset, a barometer's "
        "scale and a GPS's lag where the flight shows them) or 'offset' (an offset only)",
    )

    def __post_init__(self) -> None:
        validate(self)
        method(self.method)
        if isinstance(self.params, Params):
            object.__setattr__(self, "params", {self.method: self.params})
        if not isinstance(self.params, Mapping):
            raise ParameterError(
                f"params must be a method's parameters or map method names to them, got "
                f"{type(self.params).__name__}"
            )
        for name, given in self.params.items():
            wanted = method(name).params
            if type(given) is not wanted:
                raise ParameterError(
                    f"method {name!r} takes {wanted.__name__}, not {type(given).__name__}"
                )
        object.__setattr__(self, "params", dict(self.params))
        self.params_of().check_tick(1.0 / self.rate_hz)

    def params_of(self, name: str | None = None) -> Params:
        """The parameters method ``name`` (default: ``method``) runs with."""
        name = name or self.method
        given = cast("Mapping[str, Params]", self.params).get(name)  # a dict since built
        return method(name).params() if given is None else given


@dataclass(frozen=True)
class FuseRun:
    """The value of every stage of one run, and the provenance record built from them."""

    __repr__ = brief_repr

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
            f"{log_name}: no usable altitude source (looked for GPS, barometer, rangefinder){why}"
        )
    n = len(names)
    hint = "writes a single source" if n == 1 else "fuses them"
    raise NoUsableSensorsError(
        f"{log_name}: {n} usable altitude source{'s' * (n > 1)} ({', '.join(names)}) where "
        f"min_sensors is {options.min_sensors}{why}; min_sensors {n} (--min-sensors {n}) {hint}"
    )


@dataclass(frozen=True)
class Prepared:
    """The method-independent stages of a run: sources tilt-corrected, aligned and referred."""

    __repr__ = brief_repr

    log: FlightLog
    sensors: list[Series]  # as aligned: tilt-corrected, each GPS moved by its lag
    aligned: Aligned
    referred: Referred
    dropped: dict[str, str]
    lags: dict[str, Lag]
    #: The sources referred on the datum's clock (DATUM_RATE_HZ), where ``aligned``'s rate is
    #: another: the clock the smoother decides its model on (:attr:`FusionInput.analysis`).
    analysis: Referred | None = None

    def without_inertial(self) -> Prepared:
        """The same without the log's IMU and attitude records, once :func:`fusion_input` has
        made the vertical acceleration of them: a run that fuses one method needs them no
        more (28 MB of a 300 MB log's, held through the smoother's passes)."""
        return replace(self, log=replace(self.log, imu=None, attitude=None))


def prepare(flight: FlightLog, options: FuseOptions) -> Prepared:
    """Screen, tilt-correct, align and refer the altitude sources of ``flight`` to take-off.
    A :class:`Refusal` raised on the way says the log's vehicle and firmware."""
    try:
        return _prepare(flight, options)
    except Refusal as exc:
        exc.vehicle, exc.firmware = flight.vehicle, flight.firmware
        raise


def _prepare(flight: FlightLog, options: FuseOptions) -> Prepared:
    name = Path(flight.path).name
    if flight.vehicle == "sub":
        raise UnsupportedLogError(
            f"{name}: an ArduSub log; its BARO is water depth, "
            "and altfuse fuses the altitude of aircraft"
        )
    flight = screen(flight)
    dropped = dict(flight.dropped_sources)
    _require_sensors(name, tuple(s.name for s in flight.sensors), options, dropped)
    started = time.perf_counter()
    progress.info("%s: aligning %d sources", name, len(flight.sensors))
    sensors = [tilt_correct(s, flight.attitude) for s in flight.sensors]
    sensors = [s for s in sensors if s.t.size]
    lags = _lags(flight, sensors) if options.referral == "full" else {}
    sensors = [shift(s, lags[s.name]) if s.name in lags else s for s in sensors]
    coarse = coarser_than_datum(options.rate_hz)
    aligned = align(sensors, options.rate_hz, options.max_gap_s, options.span, edge_cells=coarse)
    fine = aligned
    if not on_datum_clock(options.rate_hz):
        fine = align(sensors, DATUM_RATE_HZ, options.max_gap_s, options.span)
    aligned_at = time.perf_counter()
    referred = refer_to_takeoff(
        fine,
        options.ground_window_s,
        options.takeoff_climb_m,
        options.referral,
        clearances=ground_clearances(flight),
        splices=splices(fine, None if flight.imu is None else flight.imu.t),
        track=_track(flight),
        takeoffs=sorted((*flight.takeoffs, *detector_takeoffs(_samples(flight.landed)))),
    )
    analysis = None
    if fine is not aligned:
        analysis, referred = referred, on_clock(referred, aligned, fine.rate_hz)
    log.info(
        "%s: aligned %d ticks in %.2f s, datum in %.2f s",
        name,
        aligned.t.size,
        aligned_at - started,
        time.perf_counter() - aligned_at,
    )
    dropped.update(referred.dropped)
    _require_sensors(name, referred.names, options, dropped)
    return Prepared(flight, sensors, aligned, referred, dropped, lags, analysis)


def _lags(flight: FlightLog, sensors: list[Series]) -> dict[str, Lag]:
    """Each GPS's lag behind the barometer (:func:`altfuse.align.gps_lags`); the first GPS's
    (``gps``, whose vertical velocity the log has: :func:`fusion_input` moves it by that lag),
    checked against the accelerometer, or found there without a barometer or rangefinder
    (:func:`altfuse.align.inertial_lag`). Not where that GPS is gone (its velocity is no
    other's)."""
    lags = gps_lags(sensors)
    velocity, imu, attitude = flight.vertical_velocity, flight.imu, flight.attitude
    if (
        velocity is None
        or imu is None
        or attitude is None
        or "gps" not in {s.name for s in sensors}
    ):
        return lags
    integral = velocity_integral(imu, attitude)
    if integral is not None:
        alone = Lag("gps", "none", 0.0, None, "not estimated: no barometer or rangefinder")
        lags["gps"] = inertial_lag(lags.get("gps", alone), velocity, integral)
    return lags


def ground_clearances(flight: FlightLog) -> dict[str, float]:
    """What each raw rangefinder distance reads when landed [m] (``RNGFNDn_GNDCLEAR``)."""
    out = {}
    for s in flight.sensors:
        if s.is_raw_rangefinder:
            cm = rangefinder_param(flight.params, s.name, "GNDCLEAR")
            if cm is not None and cm >= 0:
                out[s.name] = cm / 100.0
    return out


def _samples(series: Series | None) -> Samples | None:
    return None if series is None else Samples(series.t, series.value)


def _track(flight: FlightLog) -> Track | None:
    """The GPS's ground speed and course, where the log has the speed."""
    speed = _samples(flight.ground_speed)
    return None if speed is None else Track(speed, _samples(flight.ground_course))


def _on_ground(referred: Referred) -> tuple[tuple[float, float], ...]:
    """The spans in which the vehicle stood at its take-off point: the main segment's, and
    each other segment's with its own ground."""
    if not referred.segments:
        return () if referred.on_ground_s is None else (referred.on_ground_s,)
    return tuple(s.on_ground_s for s in referred.segments if s.on_ground_s is not None)


def fusion_input(prepared: Prepared, chosen: Method[Any], name: str = "") -> FusionInput:
    """What the pipeline hands method ``chosen`` (named ``name`` in errors): the referred
    sensors on the clock and their own samples, and from the log what it ``uses``; where the
    clock is not the datum's, the same on the datum's clock too (:attr:`FusionInput.analysis`),
    the accelerometer's at-rest reading taken there for both.

    Raises
    ------
    NoUsableSensorsError
        The method requires the vertical acceleration and the log has no IMU or ATT records.
    """
    flight, analysis = prepared.log, prepared.analysis
    decided = prepared.referred if analysis is None else analysis
    rate = prepared.aligned.rate_hz if analysis is None else DATUM_RATE_HZ
    accel = None
    if "accel" in chosen.uses and flight.imu is not None and flight.attitude is not None:
        accel = referred_vertical_acceleration(
            flight.imu, flight.attitude, decided.t, rate, decided.ground_window_s
        )
        if flight.vibration is not None:  # how far to trust it, for the provenance
            vibration = vibration_record(flight.vibration)
            accel = replace(accel, record={**accel.record, "vibration": vibration})
    if "accel" in chosen.requires and accel is None:
        missing = [n for n, v in (("IMU", flight.imu), ("ATT", flight.attitude)) if v is None]
        others = ", ".join(m for m, f in METHODS.items() if "accel" not in f.requires)
        raise NoUsableSensorsError(
            f"{Path(flight.path).name}: method {name!r} needs the accelerometer, and "
            f"the log has no {' or '.join(missing)} records; {others} work without it"
        )
    inputs = _on_clock(prepared, decided, rate, accel)
    if analysis is None:
        return inputs
    referred, rate = prepared.referred, prepared.aligned.rate_hz
    output = None if accel is None else accel.on(referred.t, rate)
    return replace(_on_clock(prepared, referred, rate, output), analysis=inputs)


def _on_clock(
    prepared: Prepared, referred: Referred, rate_hz: float, accel: VerticalAcceleration | None
) -> FusionInput:
    """The :class:`FusionInput` of ``referred``, on its clock of ``rate_hz``."""
    flight = prepared.log
    temps = flight.temperatures
    velocity = _samples(flight.vertical_velocity)
    if velocity is not None and "gps" in prepared.lags:
        velocity = Samples(velocity.t - prepared.lags["gps"].lag_s, velocity.value)
    dt = 1.0 / rate_hz
    span = (referred.t[0] - dt, referred.t[-1] + dt)
    samples = tuple(_within(s, span) for s in referred_samples(prepared.sensors, referred))
    velocity = None if velocity is None else _within(velocity, span)
    return FusionInput(
        t=referred.t,
        z=referred.h,
        names=referred.names,
        kinds=referred.kinds,
        samples=samples,
        dt_s=dt,
        on_ground_s=_on_ground(referred),
        splices=tuple((s.start_s, s.grounded) for s in referred.segments[1:]),
        track=_track(flight),
        wind=referred.wind,
        temperatures=tuple(_samples(temps.get(n)) for n in referred.names),
        accel=accel,
        gps_velocity_up=velocity,
        datum_windows=referred.datum_windows,
        scale_unknown=tuple(o.scale_unknown for o in referred.offsets),
        scale_known=tuple(o.scale_known for o in referred.offsets),
        landed=_samples(flight.landed),
        ground_effect_s=() if referred.ground_effect_s is None else (referred.ground_effect_s,),
        steps=_jumps(referred, tentative=False),
        tentative=_jumps(referred, tentative=True),
    )


def _within(samples: Samples, span: tuple[float, float]) -> Samples:
    """``samples`` within ``span`` [s]."""
    keep = (samples.t >= span[0]) & (samples.t <= span[1])
    return Samples(samples.t[keep], samples.value[keep])


def _jumps(referred: Referred, *, tentative: bool) -> tuple[Jump, ...]:
    """The ``referred`` steps (:attr:`altfuse.steps.Step.tentative` or not) as a fusion method
    takes them: between the sensors of ``referred.names`` by their indices, or the one whose
    own heights jumped (:attr:`altfuse.steps.Step.jumped`) and its own jump."""
    names = referred.names
    return tuple(
        _jump(s, names)
        for s in referred.steps
        if s.tentative == tentative and s.first in names and s.second in names
    )


def _jump(step: Step, names: tuple[str, ...]) -> Jump:
    """``step`` as a fusion method takes it (:func:`_jumps`)."""
    pair = (names.index(step.first), names.index(step.second))
    jump = (step.time_s, pair, step.size_m, step.half_width_s, step.settle_m)
    return jump if step.jumped is None else own_jump(jump, names.index(step.jumped))


def run_method(
    prepared: Prepared, options: FuseOptions, inputs: FusionInput | None = None
) -> FuseRun:
    """Fuse prepared sources with ``options.method`` and its parameters; ``inputs``: its
    :func:`fusion_input`, where the caller made it (and let go of what only it needed:
    :meth:`Prepared.without_inertial`)."""
    flight = prepared.log
    chosen = method(options.method)
    if inputs is None:
        inputs = fusion_input(prepared, chosen, options.method)
    started = time.perf_counter()
    progress.info("%s: fusing with %s", Path(flight.path).name, options.method)
    guarded = guard(chosen(inputs, options.params_of()), inputs)
    result = guarded.result
    log.info(
        "%s: fused with %s in %.2f s",
        Path(flight.path).name,
        options.method,
        time.perf_counter() - started,
    )
    record = provenance(prepared, result)
    record["guard"] = guarded.record
    record["options"] = asdict(options)
    if "accel" in chosen.uses:
        record["vertical_acceleration"] = (
            {"source": None, "note": "no IMU or ATT records: altitude-only model"}
            if inputs.accel is None
            else inputs.accel.record
        )
    return FuseRun(
        log=flight,
        aligned=prepared.aligned,
        referred=prepared.referred,
        result=result,
        options=options,
        provenance=record,
    )


def prepare_log(path: str | Path | FlightLog, options: FuseOptions) -> Prepared:
    """Read the log at ``path`` and :func:`prepare` it; a log already read (:func:`read_log`'s,
    changed as an experiment wants: a sensor left out, a bias added) is prepared as it is."""
    if isinstance(path, FlightLog):
        return prepare(path, options)
    started = time.perf_counter()
    progress.info("%s: reading", Path(path).name)
    flight = read_log(path)
    log.info(
        "%s: read %d bytes in %.2f s",
        Path(path).name,
        flight.size_bytes,
        time.perf_counter() - started,
    )
    release_free_memory()  # what the reader's tables held
    prepared = prepare(flight, options)
    del flight  # the screened copy goes on (Prepared.log)
    release_free_memory()
    return prepared


def fuse_log(path: str | Path | FlightLog, options: FuseOptions | None = None) -> FuseRun:
    """Read the log at ``path`` (or take the one given) and fuse its altitude sources (the
    ``altfuse fuse`` job)."""
    options = options or FuseOptions()
    return run_method(prepare_log(path, options), options)


def offset_record(o: Offset) -> dict[str, Any]:
    """How a source was referred, for the provenance."""
    return {
        "sensor": o.name,
        "offset_m": o.offset_m,
        "method": o.method,
        "window_s": list(o.window_s) if o.window_s else None,
        "ticks": o.ticks,
        "scale": o.scale,
        "scale_std": o.scale_std,
        "scale_method": o.scale_method,
    }


def span_record(span: tuple[float, float] | None) -> list[float] | None:
    """A span [s] as the sidecar holds it."""
    return None if span is None else list(span)


def segment_record(segment: Segment) -> dict[str, Any]:
    """A segment of a spliced log, for the provenance: its span, datum and own offsets (none:
    the main segment's)."""
    return {**asdict(segment), "offsets": [offset_record(o) for o in segment.offsets]}


def wind_record(wind: Wind | None) -> dict[str, Any] | None:
    """The wind the datum found (:class:`altfuse.datum.scale.Wind`), for the provenance."""
    if wind is None:
        return None
    return {
        "north_m_s": round(wind.north_m_s, 3),
        "east_m_s": round(wind.east_m_s, 3),
        "north_std_m_s": None if wind.north_std_m_s is None else round(wind.north_std_m_s, 3),
        "east_std_m_s": None if wind.east_std_m_s is None else round(wind.east_std_m_s, 3),
        "meaning": str(wind),
    }


def step_record(step: Step) -> dict[str, Any]:
    """A step between two sensors' heights (:mod:`altfuse.steps`), for the provenance."""
    return {
        "time_s": round(step.time_s, 3),
        "between": [step.first, step.second],
        "size_m": round(step.size_m, 3),
        "sigmas": round(step.sigmas, 1),
        # found across a gap of one sensor's: anywhere within this of time_s [s] (else 0)
        "half_width_s": round(step.half_width_s, 3),
        # found only so, under 10 sigma: a jump only where a method's evidence says so
        "tentative": step.tentative,
        # the sensor whose own heights jumped by it while the other's held (else null)
        "jumped": step.jumped,
        # how far the difference moved back over the 20 s after it, where that stood out
        "settle_m": round(step.settle_m, 3),
    }


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
            "reader": flight.reader,
            "skipped_bytes": flight.skipped_bytes,
            "notes": list(flight.notes),
            "damaged": list(flight.damaged),
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
            "time": "seconds since the autopilot booted (DataFlash TimeUS, ULog timestamp: / 1e6)",
        },
        "datum": {
            "meaning": "height above the take-off point [m]",
            "reference": referred.reference,
            "takeoff_s": referred.takeoff_s,
            "liftoff_s": referred.liftoff_s,
            "ground_window_s": list(referred.ground_window_s),
            # where the smoother holds the vehicle still at the take-off point (None: nowhere)
            "still_s": span_record(referred.on_ground_s),
            # where the smoother offers the barometers an error in the rotors' wash (whether
            # it took it: the method's parameters, baro_wash)
            "wash_s": span_record(referred.ground_effect_s),
            "segments": [segment_record(s) for s in referred.segments],
            "offsets": [offset_record(o) for o in referred.offsets],
            # where two sensors' heights jump against each other (altfuse.steps)
            "steps": [step_record(st) for st in referred.steps],
            # the air's velocity the barometers' dynamic pressure told (None: none told)
            "wind": wind_record(referred.wind),
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
                **({"lag": asdict(prepared.lags[s.name])} if s.name in prepared.lags else {}),
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
