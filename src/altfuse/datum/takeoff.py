"""Where the vehicle left the ground (the datum's first step, :mod:`altfuse.datum`): the source
whose rise marks the take-off, the take-off itself (a rise of the reference, or the autopilot's
land detector), where the rise began (the lift-off), and the ground window before it, where
the vehicle stood."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from altfuse.align import Aligned
from altfuse.errors import NoUsableSensorsError
from altfuse.metrics import running_median, runs
from altfuse.model import SENSOR_KINDS, FloatArray, Samples

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
#: its lift-off [s] to this long after its take-off [s]
#: (:attr:`altfuse.datum.Referred.ground_effect_s`): a copter's rotor wash raises the static
#: pressure under and around it as its motors spin up, and its barometers read low until it
#: climbs out of it (a real Copter 3.4 log's dipped 0.4 m as its motors spun up, and a PX4
#: log's as much). ArduPilot's EKF3 ignores the barometer's
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


def choose_reference(aligned: Aligned) -> int:
    """Index of the datum reference: the first kind in SENSOR_KINDS order with most valid ticks."""
    valid = np.isfinite(aligned.z).sum(axis=0)
    for kind in SENSOR_KINDS:
        candidates = [i for i, k in enumerate(aligned.kinds) if k == kind and valid[i] > 0]
        if candidates:
            return max(candidates, key=lambda i: (valid[i], -i))
    raise NoUsableSensorsError("no altitude source has a valid sample on the common clock")


def first_seconds(
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


def smoothed(h: FloatArray, rate_hz: float) -> FloatArray:
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
    """The take-off [s] of the first rise of ``h`` (``smooth``: :func:`smoothed`) ``climb_m``
    above its level over the log's first ``ground_s`` seconds; or, ``since`` the autopilot's
    land detector said the vehicle flies, above its level over the ``ground_s`` seconds before
    that and after it (a barometer warming on the ground rises as well: a copter's rose 1 m in
    30 s of the 72 s it stood before take-off). The take-off is where that rise last passed
    ``TAKEOFF_RISE_M`` (or ``climb_m``, where less) above the ground."""
    valid = np.isfinite(h)
    if since is None:
        start, after = first_seconds(valid, t, ground_s), valid
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


def ground_before(
    takeoff: float | None,
    clock: tuple[FloatArray, npt.NDArray[np.bool_], FloatArray, Sequence[FloatArray]],
    ground_s: float,
    climb_m: float,
) -> tuple[npt.NDArray[np.bool_], str, bool]:
    """The ground window before ``takeoff`` on the ``clock`` (its ticks, where the reference
    is valid, the reference smoothed: :func:`smoothed`, and the witnesses of :func:`_moving`),
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
    """Where the rise of the reference (``smooth``: :func:`smoothed`, NaN where it has no
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
    """Whether a height (``smooth``: :func:`smoothed`) changes by ``climb_m`` or more over the
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
