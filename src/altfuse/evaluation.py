"""Measuring every method, every single sensor and the onboard EKF against the truth.

The truth is the simulator's ``SIM.Alt`` when the log has it. Otherwise the autopilot's own EKF
height (``XKF1``/``NKF1``, else ``CTUN.Alt``, the EKF's altitude above home) stands in, labelled
as a *reference*: it is itself an estimate, and a method can be right where it differs. Either is
referred to the take-off point exactly as the sensors are (its median over the same ground window
is removed), so that a constant datum difference is not counted as error.
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, get_args

import numpy as np

from altfuse.datum import Referred
from altfuse.errors import AltfuseError, NoUsableSensorsError
from altfuse.fuse import METHODS, method
from altfuse.metrics import ErrorStats, error_stats
from altfuse.model import FlightLog, FloatArray, Series, brief_repr
from altfuse.params import InvalidParameter
from altfuse.pipeline import FuseOptions, FuseRun, Prepared, prepare_log, run_method

if TYPE_CHECKING:
    import pandas as pd

#: What to measure against: the simulator's truth, the EKF's estimate, or the first of them.
TruthChoice = Literal["auto", "sim", "ekf"]
TRUTHS: tuple[TruthChoice, ...] = get_args(TruthChoice)


@dataclass(frozen=True)
class Truth:
    """The series every estimate is measured against, on the clock and referred to take-off."""

    __repr__ = brief_repr

    name: Literal["sim", "ekf"]
    is_reference: bool  # True: an estimate standing in for the truth
    source: str
    h: FloatArray
    refused: str = ""  # why the simulator's truth was not used, where the log has one

    @property
    def label(self) -> str:
        what = "reference (the autopilot's estimate, not truth)" if self.is_reference else "truth"
        return f"{self.source} as {what}" + (f"; {self.refused}" if self.refused else "")


@dataclass(frozen=True)
class Row:
    """One estimate's errors, overall and per segment."""

    __repr__ = brief_repr

    name: str
    kind: Literal["method", "sensor", "onboard"]
    estimate: FloatArray
    overall: ErrorStats
    segments: dict[str, ErrorStats] = field(default_factory=dict)


@dataclass(frozen=True)
class Evaluation:
    """What :func:`evaluate` measured: the truth, a row per method, sensor and the onboard EKF,
    each method's run, the methods that could not run (with why) and the segments."""

    __repr__ = brief_repr

    prepared: Prepared
    truth: Truth
    rows: tuple[Row, ...]
    runs: dict[str, FuseRun]
    failed: dict[str, str]
    segments: dict[str, tuple[float, float]]

    def best(self) -> str:
        """The method run with the lowest overall RMSE."""
        scores = {r.name: r.overall.rmse for r in self.rows if r.kind == "method"}
        return min(self.runs, key=lambda m: scores[m] if math.isfinite(scores[m]) else math.inf)

    def as_dict(self) -> dict[str, Any]:
        return {
            "log": Path(self.prepared.log.path).name,
            "sha256": self.prepared.log.sha256,
            "truth": {
                "name": self.truth.name,
                "source": self.truth.source,
                "is_reference": self.truth.is_reference,
                "label": self.truth.label,
                "refused": self.truth.refused or None,
            },
            "segments": {k: list(v) for k, v in self.segments.items()},
            "rows": [
                {
                    "name": r.name,
                    "kind": r.kind,
                    "overall": r.overall.as_dict(),
                    "segments": {k: s.as_dict() for k, s in r.segments.items()},
                }
                for r in self.rows
            ],
            "failed": self.failed,
            "diverged": self.diverged(),
            # what the text report says under its table, as the sidecar of each run holds it
            "sensors_dropped": self.prepared.dropped,
            **{
                key: {
                    m: r.result.params[key] for m, r in self.runs.items() if key in r.result.params
                }
                for key in ("model_check", "not_used")
            },
        }

    def table(self) -> pd.DataFrame:
        """One row per estimate (method, sensor, the onboard EKF) and segment (``all`` for the
        whole flight): how many ticks were measured (``n``), its RMSE, MAE, maximum error and
        bias [m], and the share of its errors within its own ±2σ (NaN where it gives no σ)."""
        import pandas as pd

        records = [
            {"name": row.name, "kind": row.kind, "segment": segment, **stats.as_dict()}
            for row in self.rows
            for segment, stats in {"all": row.overall, **row.segments}.items()
        ]
        table: pd.DataFrame = pd.DataFrame.from_records(records)
        return table

    def diverged(self) -> dict[str, dict[str, Any]]:
        """Each method run whose fused value left every sensor (:mod:`altfuse.guard`): its
        flagged ticks and largest excursion [m]."""
        out = {}
        for name, run in self.runs.items():
            record = run.provenance["guard"]
            if record["diverged_ticks"]:
                out[name] = {k: record[k] for k in ("diverged_ticks", "max_excursion_m")}
        return out


#: A reference is not interpolated across a pause in its samples longer than this [s], or five
#: of its sampling intervals (a log's pause: drawn and scored straight across 628 s before).
REFERENCE_MAX_GAP_S = 1.0


def _on_clock(series: Series, referred: Referred) -> FloatArray:
    """``series`` on the clock (linear, no extrapolation, no bridging of a pause in it),
    referred over the ground window; in a spliced log, each segment with a ground of its own
    over that ground, as the sensors are (:func:`altfuse.datum.refer_to_takeoff`): at the
    ticks of the clock the datum was found on (:meth:`~altfuse.datum.Referred.datum_ticks`),
    which a coarser output's may miss (at 0.2 Hz the 4.5 plane's first tick came 2 s after
    its ground window: its truth referred over the whole flight, 27 m off)."""
    order = np.argsort(series.t, kind="stable")
    ts, values = series.t[order], series.value[order]
    raw = _interpolated(ts, values, referred.t)
    ground = _interpolated(ts, values, referred.datum_ticks(referred.ground_window_s))
    ground = ground[np.isfinite(ground)]
    if not ground.size:
        ground = raw[np.isfinite(raw)]
    if not ground.size:
        return raw
    level = np.median(ground)
    h = raw - level
    t = referred.t
    for segment in referred.segments:
        if segment.on_ground_s in (None, referred.on_ground_s):
            continue  # none of its own, or the main segment's ground (referred above)
        own = _interpolated(ts, values, referred.datum_ticks(segment.on_ground_s))
        own = own[np.isfinite(own)]
        part = (t >= segment.start_s) & (t <= segment.end_s)
        if own.size:
            h[part] -= np.median(own - level)
    return h


def _interpolated(ts: FloatArray, values: FloatArray, t: FloatArray) -> FloatArray:
    """A reference's samples (``ts`` sorted) at the times ``t``: linear, no extrapolation, NaN
    across a pause in them."""
    inside = (t >= ts[0]) & (t <= ts[-1])
    if ts.size > 1:
        longest = max(REFERENCE_MAX_GAP_S, 5 * float(np.median(np.diff(ts))))
        after = np.clip(np.searchsorted(ts, t), 1, ts.size - 1)
        inside &= ts[after] - ts[after - 1] <= longest
    out: FloatArray = np.where(inside, np.interp(t, ts, values), np.nan)
    return out


#: A simulator's truth is checked against the sensors where either moves: its heights must
#: correlate with the sensors' median at least this much. Two PX4 simulator logs (v1.7.3,
#: v1.8.0) have a groundtruth altitude that moves opposite to GPS and barometer (correlation
#: -1.00): Gazebo's GPS plugin subtracted the height from the home altitude until
#: PX4-SITL_gazebo-classic#260 (Dec 2018); every other truth log correlates at +1.000.
TRUTH_MIN_CORRELATION = 0.5
#: ... where the sensors' median or the truth moves by this much [m, standard deviation]; a
#: vehicle that stays on the ground gives nothing to check (its truth is flat, its sensors noise).
TRUTH_CHECK_MOTION_M = 0.2


def truth_check(truth: FloatArray, referred: Referred) -> str:
    """Why the simulator's heights ``truth`` (on the clock) cannot be the truth: its motion
    does not follow the sensors' (their median over the ticks both have); "" when it does."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a tick no sensor has: NaN
        consensus = np.nanmedian(referred.h, axis=1)
    both = np.isfinite(truth) & np.isfinite(consensus)
    if both.sum() < 3:
        return "too few ticks beside the sensors to check it"
    a, b = truth[both], consensus[both]
    if max(float(np.std(a)), float(np.std(b))) < TRUTH_CHECK_MOTION_M:
        return ""
    with np.errstate(all="ignore"):  # one of them flat: NaN, refused
        r = float(np.corrcoef(a, b)[0, 1])
    if r >= TRUTH_MIN_CORRELATION:
        return ""
    if math.isnan(r):  # one of them constant
        moves = f"(standard deviation {max(float(np.std(a)), float(np.std(b))):.2f} m)"
        if np.ptp(a) == 0:
            return f"its heights stay constant where the sensors' median moves {moves}"
        return f"the sensors' median stays constant where its heights move {moves}"
    why = f"its heights do not follow the sensors' (correlation {r:+.2f})"
    if r <= -TRUTH_MIN_CORRELATION:
        why += ": it moves opposite to them, a sign error (PX4's simulator groundtruth had one "
        why += "until PX4-SITL_gazebo-classic#260, Dec 2018)"
    return why


def choose_truth(flight: FlightLog, referred: Referred, which: TruthChoice = "auto") -> Truth:
    """The simulator's truth (checked: :func:`truth_check`), else the EKF as a reference
    (``which``: auto, sim or ekf)."""
    if which not in TRUTHS:
        raise InvalidParameter("truth", f"must be one of {', '.join(TRUTHS)}, got {which!r}")
    refs = {r.name: r for r in flight.references}
    name = Path(flight.path).name
    candidates: tuple[tuple[str, Literal["sim", "ekf"]], ...] = (
        ("sim", "sim"), ("ekf", "ekf"), ("ctun", "ekf"), ("inav", "ekf"),
    )  # fmt: skip
    refused = ""
    for candidate, kind in candidates:
        if which in ("auto", kind) and candidate in refs:
            series = refs[candidate]
            h = _on_clock(series, referred)
            if kind == "sim" and (why := truth_check(h, referred)):
                refused = f"{series.source} refused as truth: {why}"
                if which == "sim":
                    raise NoUsableSensorsError(f"{name}: {refused}")
                continue
            return Truth(kind, kind == "ekf", series.source, h, refused)
    wanted = {
        "auto": "simulator truth or EKF estimate",
        "sim": "simulator truth (SIM, or PX4's groundtruth topics)",
        "ekf": "EKF estimate (XKF1/NKF1, CTUN.Alt, INAV.IAlt, or PX4's vehicle_global/local_"
        "position)",
    }[which]
    raise NoUsableSensorsError(
        f"{name}: no {wanted} to measure against" + (f"; {refused}" if refused else "")
    )


def truth_or_none(flight: FlightLog, referred: Referred) -> Truth | None:
    """:func:`choose_truth` (auto), or None when the log holds neither SIM nor an EKF."""
    try:
        return choose_truth(flight, referred)
    except NoUsableSensorsError:
        return None


def parse_segments(spec: str | None, t: FloatArray) -> dict[str, tuple[float, float]]:
    """Segments of the clock ``t`` from ``spec``: a length in seconds (``30``) for equal windows,
    at least the clock's tick, or boundaries on the log's clock (``50.5,62.3``). Labelled by
    their bounds, with the decimals that tell them apart (:func:`_told_apart`; one mostly)."""
    if not spec:
        return {}
    try:
        values = [float(v) for v in spec.split(",") if v.strip()]
    except ValueError as exc:
        raise InvalidParameter("segments", f"takes seconds or boundaries, got {spec!r}") from exc
    if not values:  # "," or " , ": no boundary, where one whole-log segment went unremarked
        raise InvalidParameter("segments", f"takes seconds or boundaries, got {spec!r}")
    start, end = float(t[0]), float(t[-1])
    if len(values) == 1 and "," not in spec:
        tick = float(t[1] - t[0]) if t.size > 1 else 0.0
        # a tick of 0.1 s is 0.10000000000000142 on a clock from 30 s
        if not (math.isfinite(values[0]) and values[0] > 0 and values[0] >= tick * (1 - 1e-9)):
            raise InvalidParameter(
                "segments",
                f"length must be at least the clock's tick ({tick:g} s) and finite, "
                f"got {values[0]:g}",
            )
        edges = [*np.arange(start, end, values[0]).tolist(), end]
    else:
        outside = [v for v in values if not start < v < end]
        if outside:
            listed = ", ".join(f"{v:g}" for v in outside)
            raise InvalidParameter(
                "segments", f"{listed} s outside the log's clock ({start:.1f}-{end:.1f} s)"
            )
        edges = [start, *sorted(values), end]
    spans = [(float(a), float(b)) for a, b in itertools.pairwise(edges) if b > a]
    digits = 1
    while not _told_apart(spans, digits):
        digits += 1
    return {_label(span, digits): span for span in spans}


def _label(span: tuple[float, float], digits: int) -> str:
    return f"{span[0]:.{digits}f}-{span[1]:.{digits}f}s"


def _told_apart(spans: Sequence[tuple[float, float]], digits: int) -> bool:
    """Whether the bounds written with ``digits`` decimals give each span its own label, none
    with its two bounds alike."""
    bounds = [(f"{a:.{digits}f}", f"{b:.{digits}f}") for a, b in spans]
    return len(set(bounds)) == len(bounds) and all(a != b for a, b in bounds)


def _row(  # noqa: PLR0913 (an estimate, its standard deviation, the truth, its clock, spans)
    name: str,
    kind: Literal["method", "sensor", "onboard"],
    estimate: FloatArray,
    truth: FloatArray,
    t: FloatArray,
    segments: dict[str, tuple[float, float]],
    std: FloatArray | None = None,
) -> Row:
    """The errors of ``estimate`` (and the share of them its standard deviation ``std``
    covers, where it has one) over the whole clock ``t`` and over each segment: the ticks
    from its start up to its end, the last one's end included (a slice of the sorted clock:
    thousands of segments of a long log in one pass over it)."""
    per_segment = {}
    for label, (a, b) in segments.items():
        first = int(np.searchsorted(t, a, side="left"))
        stop = int(np.searchsorted(t, b, side="left" if b < t[-1] else "right"))
        part = None if std is None else std[first:stop]
        per_segment[label] = error_stats(estimate[first:stop], truth[first:stop], std=part)
    return Row(name, kind, estimate, error_stats(estimate, truth, std=std), per_segment)


def evaluate(
    path: str | Path | FlightLog,
    methods: str | Sequence[str] | None = None,
    options: FuseOptions | None = None,
    truth: TruthChoice = "auto",
    segments: str | None = None,
) -> Evaluation:
    """Run every method (or those named, or the one named) on the log at ``path`` (or the one
    given, already read), each with its parameters in ``options.params`` or its defaults, and
    measure it, each sensor and the EKF.

    A method that cannot run on the log (``multilayer`` without IMU) is listed in ``failed``.
    """
    options = options or FuseOptions()
    names = method_names(methods)  # before the log is read
    return evaluate_prepared(prepare_log(path, options), names, options, truth, segments)


def method_names(methods: str | Sequence[str] | None) -> list[str]:
    """The methods ``methods`` names (a string: one; None: every method), each once in the
    order given; an unknown name is refused, as is a list of none (``--methods ,`` ran every
    method, unsaid)."""
    if methods is None:
        names = list(METHODS)
    elif isinstance(methods, str):
        names = [methods]
    else:
        names = list(dict.fromkeys(methods))
    if not names:
        raise InvalidParameter("methods", f"names no method; choose from {', '.join(METHODS)}")
    for name in names:
        method(name)
    return names


def evaluate_prepared(
    prepared: Prepared,
    methods: str | Sequence[str] | None = None,
    options: FuseOptions | None = None,
    truth: TruthChoice = "auto",
    segments: str | None = None,
    done: Sequence[FuseRun] = (),
) -> Evaluation:
    """:func:`evaluate` on sources already prepared (read, aligned, referred).

    ``done``: runs already made on ``prepared``, each reused for its method where its options
    are those the evaluation would run it with.
    """
    options = options or FuseOptions()
    methods = method_names(methods)
    reference = choose_truth(prepared.log, prepared.referred, truth)
    t = prepared.referred.t
    spans = parse_segments(segments, t)
    rows, runs, failed = [], {}, {}
    for name in methods:
        try:  # a method the clock does not suit fails alone
            wanted = replace(options, method=name)
            run = next((r for r in done if r.options == wanted), None) or run_method(
                prepared, wanted
            )
        except AltfuseError as exc:
            failed[name] = str(exc)
            continue
        runs[name] = run
        rows.append(_row(name, "method", run.result.fused, reference.h, t, spans, run.result.std))
    for i, name in enumerate(prepared.referred.names):
        rows.append(_row(name, "sensor", prepared.referred.h[:, i], reference.h, t, spans))
    ekf = next((r for r in prepared.log.references if r.name == "ekf"), None)
    if ekf is not None and reference.name != "ekf":
        rows.append(
            _row("ekf", "onboard", _on_clock(ekf, prepared.referred), reference.h, t, spans)
        )
    return Evaluation(prepared, reference, tuple(rows), runs, failed, spans)
