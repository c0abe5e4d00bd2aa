"""Steps between two sensors: an instant at which one sensor's heights jump against another's.

A GPS's height jumps by metres when its fix changes (satellites lost or gained, a correction
stream dropped); a barometer's when its driver resets or its port is shaded. Such a step is
neither noise nor wander: a model that has each sensor's offset wander slowly takes a 1 m step
as a fault of whichever sensor it trusts less, and a level fit (a barometer's scale against the
GPS) takes it as a scale. Measured on the simulators' truth logs with one sensor's heights 1 m
higher from half-way (``tests/variants.py``, ``step-baro``): the barometer's scale 5 % to 1.5 +-
4.4 %, refused, and the smoothed height on the barometer, its GPS gated out, 1.06 m off.

A step is found in the difference ``d`` of two sensors' heights on the clock (GPS and
barometers: a rangefinder's ground changes under it). At each boundary between two ticks, a
straight line is fitted to ``d`` over the ``n`` ticks on either side (``STEP_WINDOWS_S``); the
step is the right line's value at the boundary less the left's::

    step(k) = R_k(t_b) - L_k(t_b),   Var = 2 sigma^2 (1/n + 3 n / (n^2 - 1))

(``sigma`` the white noise of ``d``, :func:`altfuse.metrics.white_noise_sigma`; each line's
end value has variance ``sigma^2 (1/n + (n/2)^2 / S_xx)``, ``S_xx = n (n^2 - 1) / 12``). A ramp
(a scale error in a climb, a drift) meets itself at the boundary and cancels; a step does not.
Its significance is the step over the larger of that error and the spread of the steps over the
whole flight (``1.4826 MAD``): a real GPS's wander makes steps of decimetres everywhere, and only
one far beyond them counts. A step is kept where it is ``STEP_SIGMAS`` of that and at least
``STEP_MIN_M``.

Measured: none on the 13 truth logs; none on the real logs shared but in one crash's last
seconds (rima48: 1.5 and 4.0 m); on altfuse's sample flights a GPS glitch (13.6 and 14.0 m in
and out: the size is read on the clock, where the spline smears a 5 Hz GPS's 15 m jump) and Paper
A's scattering GPS (2.9 m). A 1 m step injected half-way: found on 12 of the 13 truth logs
(barometer, and GPS): the 3.3 plane's barometer is 0.62 m noisy, not 10 sigma; the 4.5
plane's, 5 % high in a climb whose rate swings, only on the heights its scale refers, as
:func:`altfuse.datum.refer_to_takeoff` seeks them again (on the heights referred by offsets,
0.76 m, with steps of 0.17 m all along); the 137 m flight's two barometers step
2.8 s into a 13 s loss of its GPS, found across it (``Step.half_width_s``: anywhere in the
gap; :func:`jump_instant`, where a sensor's own heights say when). Across a gap of one sensor
of up to
``STEP_GAP_S`` (a GPS lost and regained elsewhere) the lines are drawn to its middle: with one
sensor lost for 10 s from half-way and 2 m higher after (``regain-gps``, ``regain-baro``),
found on 13 and 12 of the 13 truth logs, the smoother within the bar on 13 and 12, where it
was 11 and 6 before lines were drawn across gaps. Such a step, a sensor lost and regained
elsewhere, is a candidate from REGAIN_SIGMAS (:attr:`Step.tentative`), which the smoother
makes a jump only where the likelihood says one is likelier than none: the 3.3 plane's
barometer, 0.62 m noisy, regained 2 m higher is 6.2 sigma (its smoother 1.39 -> 0.09 m), and a
real receiver's GPS (``noisy-gps+regain-gps``) 5-10 sigma on 6 of the 13 (the 4.5 plane
0.159 -> 0.023 m, the 305 m climb 0.94 -> 0.72; the quadplane's jump the likelihood does not
take: 0.96 m as before). The same 2 m without the gap is no step below STEP_SIGMAS: a GPS's
wander makes such steps anywhere, its loss and return are where a receiver's fix moves. Not
across a
pause of the log (both lost): a real flight logged 18 times over, its crash's last seconds
and the next copy's start read as 17 steps of 3.6 m, and the smoother took them for the GPS's
jumps, 25,446 ticks diverged.

Each step also tells, where it can, which sensor jumped (:attr:`Step.jumped`: its own heights
part at the instant, the other's hold, :func:`_jumped`) and how far the two settle back over
the next STEP_SETTLE_S (:attr:`Step.settle_m`, :func:`_settling`: a barometer flashed by light
jumps and settles back over 15 s).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from altfuse.metrics import MAD_TO_SIGMA, mad_sigma, white_noise_sigma
from altfuse.model import FloatArray, SensorKind

#: Spans [s] of the lines either side of a boundary.
STEP_WINDOWS_S = (2.0, 5.0, 10.0)
#: A step's least significance [sigma] and size [m].
STEP_SIGMAS = 10.0
STEP_MIN_M = 0.5
#: A step across a gap of one sensor's (it was lost and regained) is a candidate from this
#: significance [sigma] (:attr:`Step.tentative`): a fusion method takes it where the log's
#: evidence says a jump is likelier than none.
REGAIN_SIGMAS = 5.0
#: The longest gap [s] across which a step is sought (a GPS lost for a few seconds; longer, its
#: wander is all a step would measure).
STEP_GAP_S = 20.0
#: At most this many steps between two sensors (a log whose sensors disagree everywhere has
#: no steps to speak of).
STEP_MOST = 20
#: A step at a known instant is the sensor's whose own heights part there by at least
#: OWN_JUMPED of it, the other's by at most OWN_HELD (:func:`_jumped`).
OWN_JUMPED = 0.5
OWN_HELD = 0.25
#: A step's settling: how far the difference moves back over this span [s] after it (its means
#: over STEP_WINDOWS_S[0] at either end), where that is at least SETTLE_SHARE of the step and
#: SETTLE_SIGMAS times the difference's own moves over the span away from steps
#: (:func:`_settling`).
STEP_SETTLE_S = 20.0
SETTLE_SIGMAS = 3.0
SETTLE_SHARE = 0.5


#: A step as :func:`_steps` finds it: time [s], size [m], significance [sigma], half its gap [s].
_Found = tuple[float, float, float, float]


@dataclass(frozen=True)
class Step:
    """``second``'s heights less ``first``'s jump by ``size_m`` at ``time_s``, at most
    ``half_width_s`` from it (half a gap of one sensor's, across which it was found: the jump
    lies anywhere in the gap)."""

    time_s: float
    first: str
    second: str
    size_m: float
    sigmas: float
    half_width_s: float = 0.0
    jumped: str | None = None  # the sensor whose own heights jumped, where they tell
    settle_m: float = 0.0  # the difference's move back over STEP_SETTLE_S, where it stands out

    @property
    def settling_s(self) -> tuple[float, float]:
        """The span [s] from the step (its gap's start) to STEP_SETTLE_S after it."""
        return self.time_s - self.half_width_s, self.time_s + self.half_width_s + STEP_SETTLE_S

    @property
    def tentative(self) -> bool:
        """Found across a gap below STEP_SIGMAS (from REGAIN_SIGMAS): a jump, or none."""
        return self.sigmas <= STEP_SIGMAS


def find_steps(
    t: FloatArray, h: FloatArray, names: Sequence[str], kinds: Sequence[SensorKind]
) -> tuple[Step, ...]:
    """Every step between two of the GPS and barometer heights ``h`` (ticks ``t``, one column
    per sensor), by time."""
    steady = [i for i, kind in enumerate(kinds) if kind != "rangefinder"]
    found: list[Step] = []
    for i, j in itertools.combinations(steady, 2):
        d = h[:, j] - h[:, i]
        pair = _steps(t, d, _either(h[:, i], h[:, j]))
        found += [
            Step(time, names[i], names[j], size, sigmas, half,
                 _jumped(t, h, (i, j), names, time, size), settle)
            for (time, size, sigmas, half), settle in zip(pair, _settling(t, d, pair), strict=True)
        ]  # fmt: skip
    return tuple(sorted(found, key=lambda s: s.time_s))


def _settling(t: FloatArray, d: FloatArray, found: Sequence[_Found]) -> list[float]:
    """How far the difference ``d`` of two sensors' heights moves back over STEP_SETTLE_S after
    each of its steps ``found`` (by time; up to the next one, or the log's end): its mean over
    the last STEP_WINDOWS_S[0] less its mean over the first, where that undoes at least
    SETTLE_SHARE of the step (at most all of it) and is SETTLE_SIGMAS times the difference's
    own moves over the span away from the steps (1.4826 MAD of its means that far apart); else
    0 (a crash's last seconds part two sensors further), and 0 across a gap (its size drawn
    out over the gap; the 92 m climb's regained GPS, 2 m read as 2.9, "settled" 2.1 m in its
    climb, and its barometer's scale fit lost those 20 s: 0.035 -> 0.123 m). Where a sensor
    is lost before the span or the log ends, the whole step back: it may settle unseen. A
    barometer flashed by light jumps and settles back over 15 s; a GPS's new fix holds, and a
    GPS's wander moves the difference as much everywhere.

    Its offset let settle as far (:func:`altfuse.fuse.smoother.noise.with_jumps`), the
    smoother follows the other sensor while it does: a barometer's flash of 1-10 m, its jump
    moved out of its samples, had left them as far below once settled back, and the height
    followed them or the gate shut them out for the rest of the flight (the 8 m flight's 3 m
    flash: 1.64 m RMSE where its GPS's is 0.01). Settling by the whole step after every jump
    let a barometer stepped 1 m settle along a GPS's wander instead (0.29 m off, where 0.03)."""
    if not found or t.size < 2:
        return [0.0] * len(found)
    n = _ticks(STEP_WINDOWS_S[0], float(t[1] - t[0]))
    valid = np.isfinite(d)
    sums = np.convolve(np.where(valid, d, 0.0), np.ones(n), "valid")
    full = np.convolve(valid.astype(np.float64), np.ones(n), "valid") == n
    means = np.where(full, sums / n, np.nan)  # over ticks k .. k + n - 1
    wander = _quiet_wander(t, means, found, n)
    ends = [time - half for time, _, _, half in found[1:]] + [math.inf]
    out = []
    for (time, size, _, half), end in zip(found, ends, strict=True):
        if half > float(t[1] - t[0]):  # across a gap: no instant to settle from, nor a size
            out.append(0.0)
            continue
        first = int(np.searchsorted(t, time + half))
        last = min(
            int(np.searchsorted(t, min(time + half + STEP_SETTLE_S, end))) - n, means.size - 1
        )
        if last < first + n:  # the next step, or the log's end, comes first
            out.append(0.0)
            continue
        seen = np.flatnonzero(np.isfinite(means[first + n : last + 1])) + first + n
        if not (np.isfinite(means[first]) and seen.size and seen[-1] >= last - n):
            out.append(-size)  # a sensor lost meanwhile
            continue
        move = float(means[seen[-1]] - means[first])
        back = -move * np.sign(size)  # towards the level before the step
        settles = back >= SETTLE_SHARE * abs(size) and back > SETTLE_SIGMAS * wander
        out.append(float(np.clip(move, -abs(size), abs(size))) if settles else 0.0)
    return out


def _quiet_wander(t: FloatArray, means: FloatArray, found: Sequence[_Found], n: int) -> float:
    """The spread (1.4826 MAD) of the difference's moves over STEP_SETTLE_S (its ``means``
    over ``n`` ticks that far apart) away from the steps ``found`` and their settling; 0 where
    fewer than ten are left."""
    span = round(STEP_SETTLE_S / float(t[1] - t[0]))
    if means.size <= span:
        return 0.0
    moves = means[span:] - means[:-span]
    near = np.zeros(t.size, dtype=bool)
    for time, _, _, half in found:
        near[(t >= time - half) & (t <= time + half + STEP_SETTLE_S)] = True
    across = np.convolve(near, np.ones(span + n), "valid")[: moves.size] > 0
    moves = moves[np.isfinite(moves) & ~across]
    if moves.size < 10:
        return 0.0
    return mad_sigma(moves)


def _jumped(
    t: FloatArray,
    h: FloatArray,
    pair: tuple[int, int],
    names: Sequence[str],
    time: float,
    size: float,
) -> str | None:
    """Which of the ``pair`` of sensors (columns of ``h``, the first and the second) jumped by
    the step ``size`` between them (the second's heights against the first's) at ``time``, as
    their own heights tell: the lines over STEP_WINDOWS_S[0] either side of the instant part by at
    least OWN_JUMPED of it on the one, by at most OWN_HELD on the other. None where they do not
    tell, or the step lies in a gap (it has no instant): the vehicle's own motion parts both
    alike, and a jerk there (3 m/s^2 from rest: 1 m between lines over 2 s) leaves the step
    to the fusion method's evidence.

    A barometer flashed 10 m beside a simulator's GPS parts its own lines by 9.6 m, the GPS's
    by 3 mm; tried as either's jump, the smoother's evidence (the barometer's settling back
    rejected alike in both readings) gave it to the GPS, and the fused height ran 1.9 m off
    both over the next two minutes."""
    n = _ticks(STEP_WINDOWS_S[0], float(t[1] - t[0]))
    k = int(np.searchsorted(t, time))
    i, j = pair
    first, second = _step_at(h[:, i], k, n, 0), _step_at(h[:, j], k, n, 0)
    for own, other, jump, who in ((second, first, size, j), (first, second, -size, i)):
        if own * jump >= OWN_JUMPED * jump**2 and abs(other) <= OWN_HELD * abs(jump):
            return names[who]
    return None


def _either(a: FloatArray, b: FloatArray) -> npt.NDArray[np.bool_]:
    """The ticks at which either of two sensors has a height."""
    return np.asarray(np.isfinite(a) | np.isfinite(b), dtype=bool)


def _steps(t: FloatArray, d: FloatArray, either: npt.NDArray[np.bool_]) -> list[_Found]:
    """The steps of ``d`` on the clock ``t``: (time [s], size [m], significance [sigma], half
    the gap it lies in [s]); gaps are bridged where ``either`` sensor kept measuring. The most
    significant is taken out of ``d`` and the rest sought again: the lines over the longer
    spans see a step from seconds away, and a glitch out and back is two steps."""
    if t.size < 2 or np.isfinite(d).sum() < 10:
        return []
    dt = float(t[1] - t[0])
    d = d.copy()
    valid = np.flatnonzero(np.isfinite(d))
    gaps = _gaps(d, dt, either)  # taking a step out of d leaves where it is NaN
    least = np.full(d.size, STEP_SIGMAS)
    least[[k for k, _ in gaps]] = REGAIN_SIGMAS
    found: list[_Found] = []
    for _ in range(STEP_MOST):
        best, size = _significance(d, dt, gaps)
        candidate = (best > least) & (np.abs(size) >= STEP_MIN_M)
        if not candidate.any():
            break
        k = int(np.argmax(np.where(candidate, best, 0.0)))
        # its size over the span that reads it best and has it (:func:`_sizes`)
        jump = next(x for x in (*_sizes(d, dt, k), size[k]) if math.isfinite(x))
        # the boundary: half-way from the last valid tick before k (a gap's middle)
        before = valid[np.searchsorted(valid, k) - 1] if valid[0] < k else k - 1
        if abs(jump) >= STEP_MIN_M:
            span = float(t[k] - t[before])
            found.append((float(t[before]) + 0.5 * span, float(jump), float(best[k]), 0.5 * span))
        d[k:] -= jump
    return _merged(sorted(found))


def jump_instant(t: FloatArray, h: FloatArray, span: tuple[float, float]) -> float | None:
    """Where within ``span`` [s] one sensor's own heights ``h`` (on the clock ``t``) jump the
    most: the boundary at which the lines over STEP_WINDOWS_S[0] either side differ the most
    (a climb's ramp meets itself); None where the span holds no whole pair of lines. A step
    found across another sensor's gap lies anywhere in the gap (:func:`find_steps`); where this
    sensor jumped, its own heights tell when."""
    if t.size < 2:
        return None
    n = _ticks(STEP_WINDOWS_S[0], float(t[1] - t[0]))
    lo, hi = np.searchsorted(t, span[0]), np.searchsorted(t, span[1], side="right")
    first = max(int(lo) - n, 0)
    part = h[first : int(hi) + n]
    step = _line_steps(part, n)
    inside = np.zeros(part.size, dtype=bool)
    inside[lo - first : hi - first] = True
    inside &= np.isfinite(step)
    if not inside.any():
        return None
    k = first + int(np.flatnonzero(inside)[np.argmax(np.abs(step[inside]))])
    return 0.5 * float(t[k - 1] + t[k]) if k else float(t[0])


def _merged(found: list[_Found]) -> list[_Found]:
    """``found`` (by time) with the steps closer than STEP_WINDOWS_S[0] to the one before
    taken as one, at the first's time and in its gap, of their sum: a spike out and back (a
    GPS's 1.2 m for 0.3 s in a simulator's log with 2 % of its samples spiked) is no step, and
    one in two parts is one."""
    out: list[_Found] = []
    for time, size, sigmas, half in found:
        if out and time - out[-1][0] < STEP_WINDOWS_S[0]:
            first, total, most, first_half = out.pop()
            time, size, sigmas, half = first, total + size, max(most, sigmas), first_half
        out.append((time, size, sigmas, half))
    return [step for step in out if abs(step[1]) >= STEP_MIN_M]


def _significance(
    d: FloatArray, dt: float, gaps: list[tuple[int, int]]
) -> tuple[FloatArray, FloatArray]:
    """At each boundary, the most significant step over STEP_WINDOWS_S: its significance
    [sigma] and its size [m]. Across each of the ``gaps`` (:func:`_gaps`: at most STEP_GAP_S,
    one sensor kept measuring, the other lost and regained: a GPS's fix comes back elsewhere)
    the lines are drawn to its middle; not across a pause of the log, which ends one flight's
    excursion as often as it starts a level (a crash's last seconds, and the same flight
    logged again)."""
    sigma = white_noise_sigma(d[np.isfinite(d)])
    best, size = np.zeros(d.size), np.zeros(d.size)
    for window_s in STEP_WINDOWS_S:
        n = _ticks(window_s, dt)
        if 2 * n > d.size:
            continue
        step = _line_steps(d, n)
        known = np.isfinite(step)
        if not known.any():
            continue
        spread = MAD_TO_SIGMA * float(np.median(np.abs(step[known])))
        error = np.full(d.size, sigma * _end_error(n, 0))
        for k, gap in gaps:
            step[k] = _step_at(d, k, n, gap)
            # lines drawn out to the gap's middle, and a wander over the window and the gap
            error[k] = max(sigma * _end_error(n, gap), spread * math.sqrt(1 + gap * dt / window_s))
        known = np.isfinite(step)
        significance = np.where(known, np.abs(step) / np.maximum(error, max(spread, 1e-3)), 0.0)
        better = significance > best
        best[better], size[better] = significance[better], step[better]
    return best, size


def _gaps(d: FloatArray, dt: float, either: npt.NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Each gap of ``d`` no longer than STEP_GAP_S in which ``either`` sensor kept measuring:
    the tick after it, and its missing ticks."""
    valid = np.flatnonzero(np.isfinite(d))
    missing = np.diff(valid) - 1
    inside = (missing > 0) & (missing * dt <= STEP_GAP_S)
    return [
        (int(k), int(g))
        for k, g in zip(valid[1:][inside], missing[inside], strict=True)
        if either[k - g : k].all()
    ]


def _sizes(d: FloatArray, dt: float, k: int) -> list[float]:
    """The step at boundary ``k`` over each of STEP_WINDOWS_S (NaN where the span is not whole),
    across the gap before it if there is one: the shortest first, whose lines reach no other
    step; across a gap the longest first, whose lines are drawn out the least (across 10 s,
    the step's standard error is 3.3 times the noise over 2 s, 0.5 times over 10 s)."""
    gap = 0
    while gap < k and not np.isfinite(d[k - 1 - gap]):
        gap += 1
    sizes = [_step_at(d, k, _ticks(w, dt), gap) for w in STEP_WINDOWS_S]
    return sizes[::-1] if gap else sizes


def _step_at(d: FloatArray, k: int, n: int, gap: int) -> float:
    """The right line less the left at the middle of the ``gap`` missing ticks before ``k``,
    over the ``n`` ticks either side; NaN where they are not whole."""
    left, right = d[max(0, k - gap - n) : k - gap], d[k : k + n]
    if left.size < n or right.size < n:
        return math.nan
    ahead, behind = _weights(n, right=True, gap=gap), _weights(n, right=False, gap=gap)
    return float(ahead @ right - behind @ left)


def _end_error(n: int, gap: int) -> float:
    """The standard deviation of a step between two lines of ``n`` ticks, each drawn to the
    middle of the ``gap`` between them, per unit of the ticks' white noise:
    ``sqrt(2 (1/n + ((n + gap) / 2)^2 / S_xx))``."""
    return math.sqrt(2.0 * (1.0 / n + ((n + gap) / 2.0) ** 2 / (n * (n * n - 1.0) / 12.0)))


def _ticks(window_s: float, dt: float) -> int:
    """The ticks a line spans over ``window_s`` [s] of a clock ``dt`` apart (at least 5)."""
    return max(5, round(window_s / dt))


def _line_steps(d: FloatArray, n: int) -> FloatArray:
    """At each boundary, the line over the ``n`` ticks after it less the line over the ``n``
    before, both at the boundary (:func:`_line_ends`)."""
    return _line_ends(d, n, right=True) - _line_ends(d, n, right=False)


def _line_ends(d: FloatArray, n: int, *, right: bool) -> FloatArray:
    """At each boundary ``k`` (between ticks ``k - 1`` and ``k``): the least-squares line
    through the ``n`` ticks after it (``right``) or before it, at the boundary; NaN where one of
    them is NaN or missing. The line's value at ``x*`` is ``sum_m y_m (1/n + (x_m - xbar)
    (x* - xbar) / S_xx)``: one convolution."""
    valid = np.isfinite(d)
    # sums[j]: over samples j-n+1 .. j
    sums = np.convolve(np.where(valid, d, 0.0), _weights(n, right=right)[::-1])
    counts = np.convolve(valid.astype(np.float64), np.ones(n))
    out = np.full(d.size, np.nan)
    if right:  # samples k .. k+n-1: index k+n-1
        ends = np.arange(n - 1, d.size)
        full = counts[ends] == n
        out[: d.size - n + 1] = np.where(full, sums[ends], np.nan)
    else:  # samples k-n .. k-1: index k-1
        ends = np.arange(n - 1, d.size - 1)
        full = counts[ends] == n
        out[n:] = np.where(full, sums[ends], np.nan)
    return out


def _weights(n: int, *, right: bool, gap: int = 0) -> FloatArray:
    """The weights of ``n`` samples (one tick apart) in their least-squares line's value at
    the boundary before them (``right``) or after them: in the middle of the ``gap`` missing
    ticks there."""
    m = np.arange(n, dtype=np.float64)
    xbar, sxx = (n - 1) / 2.0, n * (n * n - 1.0) / 12.0
    at = -(gap + 1) / 2.0 if right else n - 1 + (gap + 1) / 2.0
    weights: FloatArray = 1.0 / n + (m - xbar) * (at - xbar) / sxx
    return weights
