"""Plausibility screening: impossible samples are dropped before alignment, counted by reason.

Real logs carry records no sensor can have produced (seen in public logs: a GPS record with
Status 6 and an altitude of 15,647,421 m, timestamps jumping by hours, a rangefinder reporting its
maximum whenever out of range, baro spikes). The reader's own filters (GPS Status, BARO health,
RFND Stat) come first; these checks come after, on each source:

- **time out of order**: a sample far (``max(1 s, 10 median steps)``) from the running median of
  its neighbours' times, or earlier than a sample logged before it (a lone stamp hours ahead
  would otherwise make every later sample look "backwards");
- **time far outside the log**: more than ``max(600 s, half the bulk's length)`` outside the span
  of the middle 98 % of all the sources' samples;
- **outside the plausible altitude envelope**: GPS outside -500..12,000 m AMSL, barometer outside
  -1,000..12,000 m, rangefinder outside 0..1,000 m;
- **rangefinder out-of-range codes**: exactly 0 or 655.35 m (the uint16 centimetre maximum);
- **rangefinder pinned at its maximum**: drivers that log their maximum range (or max + 1 m) when
  they see nothing, with ``Stat`` Good: when the log holds the instance's ``RNGFNDn_MAX_CM``,
  samples at or above that maximum; otherwise samples equal to the series' own maximum when that
  value repeats in at least ``PINNED_MIN_SAMPLES`` samples;
- **rangefinder below its minimum range**: a distance at or below the instance's
  ``RNGFNDn_MIN_CM`` is the driver's floor, not a measurement (a rangefinder on the ground
  reads 20 cm where its ``RNGFNDn_GNDCLEAR`` says 10 cm);
- **spikes**: a sample away from both neighbours in the same direction, more than ``SPIKE_MIN_M``
  and faster than ``MAX_VERTICAL_SPEED_M_S`` to reach from either, or further than an
  acceleration of ``MAX_VERTICAL_ACCEL_M_S2`` could take it and back and than the noise around
  it: no aircraft does that (a raw rangefinder's judged on its heights, with the attitude
  screened first: its slant distance in a quick bank is no spike);
- **stuck at one value**: the same value to the bit for ``STUCK_MIN_S`` seconds or more
  (``STUCK_MIN_SAMPLES`` samples) while another source moved more than its noise and
  ``MOTION_MIN_M``: a receiver that reports 0.00 m with a 3D fix, a frozen driver. A sensor at
  rest on the ground, as every source in a simulator, is not stuck while the others rest too;
  nor is one that thaws where it froze while the other ended the run elsewhere or came back
  (:func:`_thawed`): a simulator's GPS, one value to the bit while its copter hovered, beside a
  barometer flashed 3-10 m or stepped 1 m half-way through the truth logs (``tests/variants.py``)
  was dropped on 5 of the 13 (a rangefinder on 2), and the barometer's excursion was all
  that was left; now on one, its run lasting to the log's end.

The other inputs a method uses are screened too (:func:`screen_inputs`): the accelerometer,
the attitude, the vibration levels, the GPS's speeds and the barometers' temperatures lose
every sample that is not a finite number or is beyond what the instrument can report (a
specific force over ``MAX_SPECIFIC_FORCE_M_S2``, an angle over 2 pi, a speed over
``MAX_SPEED_M_S``), and the samples whose times are out of order or far outside the log. One
``IMU.AccZ`` of 1e6 m/s^2 once took the smoother 1.2e6 m away; one ``ATT.Roll`` of 1e38 scaled
the rangefinder by cos(1.7e36).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from altfuse.datum.tilt import MIN_COS_TILT, tilt_at
from altfuse.metrics import running_max, running_median, running_white_noise, white_noise_sigma
from altfuse.model import Attitude, FlightLog, FloatArray, Imu, Series, Vibration

Mask = npt.NDArray[np.bool_]

BACKWARDS = "time out of order"
OUTSIDE_LOG = "time far outside the log"
ENVELOPE = "outside the plausible altitude envelope"
CODE = "rangefinder out-of-range code (0 or 655.35 m)"
PINNED = "rangefinder pinned at its maximum"
SPIKE = "spike (out and back faster than an aircraft moves)"
BELOW_MINIMUM = "rangefinder at or below its minimum range"
STUCK = "stuck at one value while the others moved"
BEYOND_BOOT = "time beyond ten years since boot"
NO_PLAUSIBLE_SAMPLE = "no plausible sample"
REASONS = (
    BEYOND_BOOT, BACKWARDS, OUTSIDE_LOG, ENVELOPE, CODE, PINNED, SPIKE, BELOW_MINIMUM, STUCK,
)  # fmt: skip
#: A rangefinder beyond its range: the sensor at its limits (on the ground, above its reach),
#: which the readers' status filters drop unsaid where the log has a status (``RFND.Stat``);
#: dropped and counted per source, and no implausible sample (every simulated log warned of
#: some).
OUT_OF_RANGE = (CODE, PINNED, BELOW_MINIMUM)
IMPLAUSIBLE = tuple(r for r in REASONS if r not in OUT_OF_RANGE)

#: The largest specific force an autopilot's IMU reports [m/s^2]: +-16 g is the common range,
#: +-40 g the largest ArduPilot drives (ADIS16470); beyond 50 g a sample is corrupt.
MAX_SPECIFIC_FORCE_M_S2 = 50 * 9.80665
MAX_ANGLE_RAD = 2 * np.pi
#: Horizontal and vertical speeds [m/s] beyond any aircraft altfuse fuses (about Mach 1).
MAX_SPEED_M_S = 340.0
#: Temperatures [degC] a barometer can log: its operating range with a wide margin.
TEMPERATURE_RANGE_C = (-80.0, 150.0)

ENVELOPE_M = {
    "gps": (-500.0, 12_000.0),
    "baro": (-1_000.0, 12_000.0),
    "rangefinder": (0.0, 1_000.0),
}
RANGEFINDER_CODES_M = (0.0, 655.35)
PINNED_MIN_SAMPLES = 10
SPIKE_MIN_M = 10.0
MAX_VERTICAL_SPEED_M_S = 50.0
#: ... or one out and back faster than this [m/s^2] (10 g; a plane's pull into a dive is 3-4 g)
#: and beyond SPIKE_NOISE_SIGMAS of the noise over SPIKE_NOISE_WINDOW samples around it. Only
#: the first rule, 10 m at 50 m/s, let a barometer's and a GPS's 2-10 m spikes through: on the
#: simulators' logs with 2 % of their samples so spiked, the GPS's lag went unestimated, the
#: barometer's scale unapplied, and the smoother 0.07-0.75 m off where it is 0.002-0.03 m
#: (the 9 m sonar flight: GPS and rangefinder rejected 800 times each); with it, within 1 mm of
#: the clean logs' RMSE on 19 of 26, within 1 cm on all (the 92 m climb, its barometer 0.12 m
#: noisy: 0.037 m against 0.027, where it was 0.044 and 0.239).
MAX_VERTICAL_ACCEL_M_S2 = 100.0
SPIKE_NOISE_SIGMAS = 8.0
SPIKE_NOISE_WINDOW = 41
TIME_MARGIN_MIN_S = 600.0
TIME_JUMP_S = 86_400.0
#: Runs of samples apart by more than CLUSTER_GAP_S [s]; a run of fewer than
#: CLUSTER_MIN_SAMPLES, or than CLUSTER_MIN_SHARE of the largest, is stray (a barometer whose
#: stamps were a thousand times too large: one sample every 50 s over 33 h, 2,400 segments).
CLUSTER_GAP_S = 10.0
CLUSTER_MIN_SAMPLES = 10
CLUSTER_MIN_SHARE = 0.01
MAX_BOOT_S = 10 * 365.25 * 86_400.0
STUCK_MIN_S = 5.0
STUCK_MIN_SAMPLES = 10
MOTION_MIN_M = 1.0
#: Another source "moved" when its spread over the run exceeds this many times its noise.
MOTION_NOISES = 10.0
#: The spans [s] at a run's start and at its thaw over which another source's level is taken
#: (:func:`_thawed`).
THAW_WINDOW_S = 1.0


#: A GPS receiver's vertical accuracy [m] by which its fix has converged: ArduPilot's EKF3
#: uses a GPS only once its receiver reports at most this (and PX4's EKF2 5 m, EKF2_REQ_EPV).
#: A receiver just powered on reports 10 m or more and walks its height by metres meanwhile
#: (a shared log: GPA.VAcc 12.5 m falling to 7.5 in 2 s, its height 8 m below the barometer
#: and back; the smoother took 4 m of it, the autopilot's EKF none).
GPS_CONVERGED_VACC_M = 7.5
NOT_CONVERGED = f"GPS fix not yet converged (vertical accuracy over {GPS_CONVERGED_VACC_M:g} m)"


def not_converged(t: FloatArray, accuracy: FloatArray, at: FloatArray) -> Mask:
    """Which times ``at`` lie after a GPS receiver's first accuracy report (``accuracy`` [m],
    vertical, at times ``t``) and before its first within GPS_CONVERGED_VACC_M. A receiver
    that never reports one (or reports 0: unknown) loses nothing: a receiver poor all flight
    is the fusion's to weigh, not the reader's to drop."""
    known = np.isfinite(t) & np.isfinite(accuracy) & (accuracy > 0)
    good = known & (accuracy <= GPS_CONVERGED_VACC_M)
    if not good.any():
        return np.zeros(at.size, dtype=bool)
    return np.asarray((at >= t[known].min()) & (at < t[good].min()))


def rangefinder_param(params: dict[str, float], name: str, suffix: str) -> float | None:
    """A rangefinder instance's parameter (``RNGFND1_MIN_CM`` for ``rangefinder``,
    ``RNGFND2_...`` for ``rangefinder2``; Copter 3.x names the first ``RNGFND_...``), or None."""
    number = name.removeprefix("rangefinder") or "1"
    keys = [f"RNGFND{number}_{suffix}"] + ([f"RNGFND_{suffix}"] if number == "1" else [])
    return next((params[k] for k in keys if k in params), None)


def log_span(series: tuple[Series, ...]) -> tuple[float, float] | None:
    """The span of the bulk of all samples, widened by the far-outside margin."""
    times = np.concatenate([s.t for s in series]) if series else np.zeros(0)
    times = np.sort(times[np.isfinite(times) & (times <= MAX_BOOT_S)])
    if times.size < 10:
        return None
    cut = np.flatnonzero(np.diff(times) > CLUSTER_GAP_S) + 1
    parts = np.split(times, cut)
    sizes = np.array([p.size for p in parts])
    bulk = int(np.argmax(sizes))
    # out from the largest run of samples, the runs that are not stray ones, until a jump
    dense = sizes >= max(CLUSTER_MIN_SAMPLES, CLUSTER_MIN_SHARE * sizes[bulk])
    dense[bulk] = True  # the largest, however small
    first = last = bulk
    while first > 0 and parts[first][0] - parts[first - 1][-1] <= TIME_JUMP_S:
        first -= 1
    while last < len(parts) - 1 and parts[last + 1][0] - parts[last][-1] <= TIME_JUMP_S:
        last += 1
    times = np.concatenate([parts[i] for i in range(first, last + 1) if dense[i]])
    lo, hi = np.percentile(times, [1.0, 99.0])
    margin = max(TIME_MARGIN_MIN_S, 0.5 * (hi - lo))
    return float(lo - margin), float(hi + margin)


def _out_of_order(t: FloatArray) -> Mask:
    """Lone stamps far from their neighbours', then samples earlier than one logged before."""
    out = np.zeros(t.size, dtype=bool)
    if t.size >= 5:
        step = float(np.median(np.abs(np.diff(t))))
        local = running_median(t, 5)
        out = np.abs(t - local) > max(1.0, 10.0 * step)
    kept = np.flatnonzero(~out)
    earlier = np.maximum.accumulate(np.concatenate(([-np.inf], t[kept][:-1])))
    out[kept[t[kept] < earlier]] = True
    return out


def _spikes(t: FloatArray, v: FloatArray) -> Mask:
    out = np.zeros(v.size, dtype=bool)
    if v.size < 3:
        return out
    d_prev, d_next = v[1:-1] - v[:-2], v[1:-1] - v[2:]
    dt_prev = np.maximum(t[1:-1] - t[:-2], 1e-3)
    dt_next = np.maximum(t[2:] - t[1:-1], 1e-3)
    far = (np.abs(d_prev) > SPIKE_MIN_M) & (np.abs(d_next) > SPIKE_MIN_M)
    fast = (np.abs(d_prev) / dt_prev > MAX_VERTICAL_SPEED_M_S) & (
        np.abs(d_next) / dt_next > MAX_VERTICAL_SPEED_M_S
    )
    # out and back between its neighbours: a departure of d from both needs an acceleration of
    # about 2 d / (dt_prev dt_next); and beyond the noise around it (a barometer's grows in prop
    # wash), the largest nearby (where the noise grows, a window half in the quiet part reads
    # it too low)
    depart = np.minimum(np.abs(d_prev), np.abs(d_next))
    local = running_white_noise(v, SPIKE_NOISE_WINDOW)
    noise = running_max(local, SPIKE_NOISE_WINDOW)[1:-1]
    sharp = depart > np.maximum(
        MAX_VERTICAL_ACCEL_M_S2 * dt_prev * dt_next / 2, SPIKE_NOISE_SIGMAS * noise
    )
    out[1:-1] = ((far & fast) | sharp) & (np.sign(d_prev) == np.sign(d_next))
    return out


def _pinned(v: FloatArray, configured_max_m: float | None) -> Mask:
    if configured_max_m is not None:
        out: Mask = v >= configured_max_m - 0.005
        return out
    top = np.max(v) if v.size else 0.0
    at_top = np.isclose(v, top, rtol=0.0, atol=0.005)
    return at_top if at_top.sum() >= PINNED_MIN_SAMPLES else np.zeros(v.size, dtype=bool)


def _rangefinder_codes(v: FloatArray, minimum_m: float | None) -> list[tuple[str, Mask]]:
    """A rangefinder's out-of-range codes, and its readings at or below its minimum range."""
    checks = [(CODE, np.isin(np.round(v, 2), RANGEFINDER_CODES_M))]
    if minimum_m is not None:
        checks.append((BELOW_MINIMUM, v <= minimum_m + 0.005))
    return checks


def screen_series(
    s: Series,
    span: tuple[float, float] | None,
    rangefinder_max_m: float | None = None,
    rangefinder_min_m: float | None = None,
    upright: FloatArray | None = None,
) -> Series:
    """``s`` without its impossible samples; ``dropped`` counts them by reason. ``upright``: a
    raw rangefinder's factor to the vertical at each sample (:func:`_upright`), with which its
    spikes are judged, as heights."""
    checks: list[tuple[str, Mask]] = [(BEYOND_BOOT, s.t > MAX_BOOT_S)]
    if span is not None:
        checks.append((OUTSIDE_LOG, (s.t < span[0]) | (s.t > span[1])))
    checks.append((BACKWARDS, _out_of_order(s.t)))
    lo, hi = ENVELOPE_M.get(s.kind, (-np.inf, np.inf))
    checks.append((ENVELOPE, (s.value < lo) | (s.value > hi)))
    if s.kind == "rangefinder":
        checks += _rangefinder_codes(s.value, rangefinder_min_m)
    keep = np.ones(s.t.size, dtype=bool)
    dropped = dict(s.dropped)
    for reason, bad in checks:
        hit = keep & bad
        if hit.any():
            dropped[reason] = dropped.get(reason, 0) + int(hit.sum())
        keep &= ~bad
    # the checks that look at the shape of the samples left
    later: list[tuple[str, Mask]] = []
    if s.kind == "rangefinder" and keep.any():
        later.append((PINNED, _pinned(s.value[keep], rangefinder_max_m)))
    for reason, bad_among_kept in later:
        idx = np.flatnonzero(keep)[bad_among_kept]
        if idx.size:
            dropped[reason] = dropped.get(reason, 0) + int(idx.size)
            keep[idx] = False
    # a spike is one of heights: a rangefinder's slant distance in a quick bank is none
    judged = keep if upright is None else keep & np.isfinite(upright)
    heights = s.value if upright is None else s.value * upright
    spikes = np.flatnonzero(judged)[_spikes(s.t[judged], heights[judged])]
    if spikes.size:
        dropped[SPIKE] = int(spikes.size)
        keep[spikes] = False
    if keep.all():
        return s
    return replace(s, t=s.t[keep], value=s.value[keep], dropped=dropped)


def _range_limit(flight: FlightLog, s: Series, suffix: str) -> float | None:
    """A raw rangefinder distance's configured limit [m] (CTUN.SAlt is the autopilot's own)."""
    if not s.is_raw_rangefinder:
        return None
    cm = rangefinder_param(flight.params, s.name, suffix)
    return cm / 100.0 if cm and cm > 0 else None


def _stuck(s: Series, others: list[Series]) -> tuple[Mask, list[str]]:
    """The samples of ``s`` in runs of one value over ``STUCK_MIN_S`` while another moved, and
    a note on each run."""
    out = np.zeros(s.t.size, dtype=bool)
    notes: list[str] = []
    if s.t.size < STUCK_MIN_SAMPLES:
        return out, notes
    change = np.flatnonzero(np.diff(s.value) != 0) + 1
    starts = np.concatenate(([0], change))
    ends = np.concatenate((change, [s.t.size]))
    for a, b in zip(starts, ends, strict=True):
        if b - a < STUCK_MIN_SAMPLES or s.t[b - 1] - s.t[a] < STUCK_MIN_S:
            continue
        lo, hi = s.t[a], s.t[b - 1]
        for o in others:
            v = o.value[(o.t >= lo) & (o.t <= hi)]
            if v.size < 5:
                continue
            moved = float(np.ptp(np.percentile(v, [5, 95])))
            if moved > max(MOTION_MIN_M, MOTION_NOISES * white_noise_sigma(v)) and not _thawed(
                s, (a, b), o
            ):
                out[a:b] = True
                notes.append(
                    f"{s.name}: stuck at {s.value[a]:g} m from {lo:.1f} to {hi:.1f} s "
                    f"({b - a} samples, dropped) while {o.name} moved {moved:.1f} m"
                )
                break
    return out, notes


def _thawed(s: Series, run: tuple[int, int], other: Series) -> bool:
    """Whether ``s``, one value over its samples ``run`` (``a`` to ``b``, the first after it),
    thawed where it froze: its step at the thaw under half the larger of ``other``'s net change
    from the run's start to the thaw (medians over THAW_WINDOW_S at either end) and
    MOTION_MIN_M. A receiver frozen while the vehicle moved thaws where the vehicle went (or at
    a value it never had); one at rest beside another sensor's excursion (a barometer's flash
    of light, its glitch) thaws where it was, and the excursion was the other's. Kept, the two
    disagree before the fusion, which the accelerometer and the guard judge; dropped, the
    excursion is all that is left. A sensor frozen to the log's end never thaws."""
    a, b = run
    if b >= s.t.size:
        return False
    lo, thaw = s.t[a], s.t[b]
    start = other.value[(other.t >= lo) & (other.t <= lo + THAW_WINDOW_S)]
    end = other.value[(other.t >= thaw - THAW_WINDOW_S) & (other.t <= thaw)]
    if not (start.size and end.size):
        return False
    net = float(np.median(end) - np.median(start))
    return bool(abs(s.value[b] - s.value[a]) < max(abs(net), MOTION_MIN_M) / 2)


def screen(flight: FlightLog) -> FlightLog:
    """``flight`` with every source screened (see the module doc); empty sources dropped."""
    span = log_span(flight.sensors)
    flight = screen_inputs(flight, span)  # first: the attitude a rangefinder's spikes are seen by
    screened_all = [
        screen_series(
            s,
            span,
            _range_limit(flight, s, "MAX_CM"),
            _range_limit(flight, s, "MIN_CM"),
            _upright(s, flight.attitude),
        )
        for s in flight.sensors
    ]
    with_stuck, notes = [], list(flight.notes)
    for s in screened_all:
        stuck, said = _stuck(s, [o for o in screened_all if o.name != s.name])
        notes += said
        if stuck.any():
            dropped = dict(s.dropped, **{STUCK: int(stuck.sum())})
            s = replace(s, t=s.t[~stuck], value=s.value[~stuck], dropped=dropped)
        with_stuck.append(s)
    # the references are screened like the sensors: a truth with a splice in it is no truth
    references = tuple(r for r in (screen_series(r, span) for r in flight.references) if r.t.size)
    sensors, dropped_sources = [], dict(flight.dropped_sources)
    for s, screened in zip(flight.sensors, with_stuck, strict=True):
        if screened.t.size:
            sensors.append(screened)
        else:
            reasons = ", ".join(f"{n} {r}" for r, n in screened.dropped.items())
            dropped_sources[s.name] = f"{s.source}: {NO_PLAUSIBLE_SAMPLE} ({reasons})"
    return replace(
        flight,
        sensors=tuple(sensors),
        references=references,
        dropped_sources=dropped_sources,
        notes=tuple(notes),
    )


def _upright(s: Series, attitude: Attitude | None) -> FloatArray | None:
    """A raw rangefinder distance's factor to the vertical at each sample (``cos(roll)
    cos(pitch)``; NaN where it is tilted beyond MAX_TILT_DEG or the attitude does not cover it,
    :func:`altfuse.datum.tilt.tilt_correct` drops those); None for any other source, or without an
    attitude."""
    if not s.is_raw_rangefinder or attitude is None or attitude.t.size < 2:
        return None
    tilt = tilt_at(s, attitude)
    return np.where(tilt >= MIN_COS_TILT, tilt, np.nan)


def _keep_rows(
    t: FloatArray, values: FloatArray, low: float, high: float, span: tuple[float, float] | None
) -> tuple[Mask, int]:
    """The rows (samples) of ``values`` (n, k) at times ``t`` that are finite, within
    [``low``, ``high``] in every column, in time order and inside ``span``; the count of
    the others."""
    values = values.reshape(t.size, -1) if t.size else np.zeros((0, 1))
    keep = np.isfinite(t) & (t <= MAX_BOOT_S)
    # finite, whatever the range: an infinite vibration level passed an unbounded one, and its
    # record in the provenance was no JSON (a damaged text log's VIBE)
    keep &= (np.isfinite(values) & (values >= low) & (values <= high)).all(axis=1)
    if span is not None:
        keep &= (t >= span[0]) & (t <= span[1])
    kept = np.flatnonzero(keep)
    keep[kept[_out_of_order(t[kept])]] = False
    return keep, int(t.size - keep.sum())


def screen_inputs(flight: FlightLog, span: tuple[float, float] | None) -> FlightLog:
    """``flight`` without the impossible samples of its other inputs (see the module doc),
    counted in ``dropped_inputs`` by source; a source left with none is removed."""
    counts = dict(flight.dropped_inputs)
    force = MAX_SPECIFIC_FORCE_M_S2

    def rows(source: str, t: FloatArray, values: FloatArray, low: float, high: float) -> Mask:
        keep, n = _keep_rows(t, values, low, high, span)
        if n:
            counts[source] = counts.get(source, 0) + n
        return keep

    imu, att, vib = flight.imu, flight.attitude, flight.vibration
    if imu is not None:
        keep = rows(imu.source, imu.t, imu.acc, -force, force)
        imu = Imu(imu.source, imu.t[keep], imu.acc[keep]) if keep.any() else None
    if att is not None:
        angles = np.column_stack([att.roll, att.pitch, att.yaw])
        keep = rows(att.source, att.t, angles, -MAX_ANGLE_RAD, MAX_ANGLE_RAD)
        q = None if att.quaternion is None else att.quaternion[keep]
        roll, pitch, yaw = angles[keep].T
        att = Attitude(att.source, att.t[keep], roll, pitch, yaw, q) if keep.any() else None
    if vib is not None:
        both = np.column_stack([vib.level, vib.clips])
        keep = rows(vib.source, vib.t, both, 0.0, np.inf)
        vib = Vibration(vib.source, vib.t[keep], vib.level[keep], vib.clips[keep])
        vib = vib if keep.any() else None

    def series(s: Series | None, low: float, high: float) -> Series | None:
        if s is None:
            return None
        keep = rows(s.source, s.t, s.value, low, high)
        return replace(s, t=s.t[keep], value=s.value[keep]) if keep.any() else None

    speed = series(flight.ground_speed, 0.0, MAX_SPEED_M_S)
    climb = series(flight.vertical_velocity, -MAX_SPEED_M_S, MAX_SPEED_M_S)
    temperatures = {
        name: kept
        for name, s in flight.temperatures.items()
        if (kept := series(s, *TEMPERATURE_RANGE_C)) is not None
    }
    return replace(
        flight,
        imu=imu,
        attitude=att,
        vibration=vib,
        ground_speed=speed,
        vertical_velocity=climb,
        temperatures=temperatures,
        dropped_inputs=counts,
    )


def screened_out(flight: FlightLog) -> list[str]:
    """The altitude sources screening left without a sample."""
    return [name for name, why in flight.dropped_sources.items() if NO_PLAUSIBLE_SAMPLE in why]


def implausible_count(flight: FlightLog) -> dict[str, int]:
    """Samples dropped by screening as implausible, per altitude source (the reader's own
    filters and a rangefinder beyond its range, ``OUT_OF_RANGE``, excluded) and per other input
    (``IMU[0].Acc``, ``ATT``, ...)."""
    counts = {
        s.name: sum(n for r, n in s.dropped.items() if r in IMPLAUSIBLE) for s in flight.sensors
    }
    counts.update(flight.dropped_inputs)
    return {name: n for name, n in counts.items() if n}
