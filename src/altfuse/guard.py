"""The divergence guard: a fused altitude that leaves every sensor is flagged, never silent.

At each tick with a valid sensor, the *excursion* is how far the fused value lies outside the
envelope of the valid sensors' heights (0 inside it)::

    excursion = max(min_i z_i - fused, fused - max_i z_i, 0)

(the sensors' columns, or on a clock coarser than the datum's their samples at the tick:
:func:`sensor_heights`). It is too far when it exceeds ``max(FLOOR_M, SIGMAS * sqrt(s^2 +
f^2))``, with ``s`` the white noise of the sensor at the envelope's nearer edge (from its own
samples' second differences) and ``f`` the method's own ``fused_std`` where it gives one. A run
of such ticks (through pauses shorter than ``BRIDGE_S``) lasting ``MIN_S`` or more, or with a
tick beyond ``GROSS_M`` (ten metres outside every sensor is no altitude to use, however brief:
a GPS's last samples 17-31 m off its barometer at a log's cut; nor however wide the method's
own band: a smoother 1.8 km off with a fused_std of 27 km after hours without a sample), gets
the status ``diverged``; so
does a tick where a sensor is valid and the method gave no value at all (NaN: the smoother's
state lost over a day's gap in a damaged log's stamps). The value is kept (it is what the
method said), the status says not to trust it, the provenance counts it and the command line
warns in one line.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from altfuse.datum import coarser_than_datum
from altfuse.fuse.base import DIVERGED, FusionInput, FusionResult
from altfuse.metrics import envelope, runs, white_noise_sigma
from altfuse.model import FloatArray, brief_repr

#: An excursion below this [m] is never a divergence, however quiet the sensors.
FLOOR_M = 1.0
#: Standard deviations of the combined uncertainty an excursion must exceed.
SIGMAS = 3.0
#: Shortest run of such ticks that is flagged [s]: a filter may overshoot a step for a moment.
MIN_S = 2.0
#: An excursion beyond this [m] is flagged whatever its length. At 100 m (before) it let pass
#: the smoother 17 m off every sensor over rima48's last 0.2 s; at 10 m it flags that, and on
#: 828 runs of every method over two seeds of every simulated flight, five more, each 1-3 ticks
#: of Paper B's filters with true errors of 5.6-35 m; no tick more on the other shared logs,
#: nor on 624 runs over the truth logs cut short or begun late.
GROSS_M = 10.0
#: A run of such ticks goes on through a pause shorter than this [s]: one noisy sample that
#: comes near the fused value does not cut a long excursion into two short ones (a method 1.1-1.8
#: m above GPS and rangefinder for 2.5 s on a PX4 log, cut by one tick at which a barometer
#: 0.49 m noisy came within 3 sigma, went unflagged).
BRIDGE_S = 0.5


@dataclass(frozen=True)
class Guarded:
    """A result with its diverged ticks flagged, and what the guard found."""

    __repr__ = brief_repr

    result: FusionResult
    record: dict[str, Any]


def excursion(fused: FloatArray, z: FloatArray) -> FloatArray:
    """How far [m] ``fused`` lies outside the envelope of the valid sensors ``z`` (T, n); NaN
    where no sensor is valid."""
    valid = np.isfinite(z).any(axis=1)
    lo, hi = envelope(z)
    out = np.maximum(np.maximum(lo - fused, fused - hi), 0.0)
    return np.where(valid & np.isfinite(fused), out, np.nan)


def sensor_heights(inputs: FusionInput) -> FloatArray:
    """The sensors' heights a method's value at each tick is held to, (T, n) or (T, 2n): their
    columns ``z``; on a clock coarser than the datum's (:data:`~altfuse.datum.DATUM_RATE_HZ`),
    where a column is its samples' mean over a cell seconds wide, also each sensor's own
    samples interpolated at the tick (where its column is valid, in the same order after the
    columns): a method fusing the columns gives a cell's mean, the smoother an estimate at the
    tick. Against the 5 s means alone at 0.2 Hz the smoother's estimates in the planes'
    climbing turns, within 0.3 m of the truth, lay up to 11 m outside every sensor; against
    the samples alone, mean's."""
    if not coarser_than_datum(1.0 / inputs.dt_s):
        return inputs.z
    at_ticks = np.full(inputs.z.shape, np.nan)
    for j, s in enumerate(inputs.samples):
        if s.t.size:
            valid = np.isfinite(inputs.z[:, j])
            at_ticks[valid, j] = np.interp(inputs.t[valid], s.t, s.value)
    return np.concatenate([inputs.z, at_ticks], axis=1)


def guard(result: FusionResult, inputs: FusionInput) -> Guarded:
    """``result`` with the ticks of every divergence (see the module doc) flagged ``diverged``."""
    z, fused = sensor_heights(inputs), result.fused
    away = excursion(fused, z)
    noise = np.array(
        [white_noise_sigma(s.value) if s.value.size > 2 else 0.0 for s in inputs.samples]
    )
    edge = _edge_sensor(fused, z)
    s = np.where(edge >= 0, noise[np.maximum(edge, 0) % noise.size], 0.0)
    f = result.tick_traces.get("fused_std", np.zeros(fused.size))
    limit = np.maximum(FLOOR_M, SIGMAS * np.sqrt(s**2 + np.nan_to_num(f) ** 2))
    gross = np.nan_to_num(away) > GROSS_M  # however wide the method's own band
    beyond = _bridged((np.nan_to_num(away) > limit) | gross, round(BRIDGE_S / inputs.dt_s))
    long_enough = max(1, round(MIN_S / inputs.dt_s))
    spans = [(a, b) for a, b in runs(beyond) if b - a >= long_enough or gross[a:b].any()]
    lost = np.isfinite(z).any(axis=1) & ~np.isfinite(fused)
    flagged = lost.copy()
    for a, b in spans:
        flagged[a:b] = True
    record = {
        "floor_m": FLOOR_M,
        "sigmas": SIGMAS,
        "min_s": MIN_S,
        "gross_m": GROSS_M,
        "diverged_ticks": int(flagged.sum()),
        "lost_ticks": int(lost.sum()),
        "max_excursion_m": float(np.nanmax(away)) if np.isfinite(away).any() else 0.0,
        "spans_s": [[float(inputs.t[a]), float(inputs.t[b - 1])] for a, b in spans],
    }
    if not flagged.any():
        return Guarded(result, record)
    status = np.where(flagged, DIVERGED, result.status)
    return Guarded(replace(result, status=status), record)


def _bridged(mask: np.ndarray, gap: int) -> np.ndarray:
    """``mask`` with each pause of fewer than ``gap`` False ticks between two runs of True
    filled."""
    out: np.ndarray = mask.copy()
    for (_, end), (start, _) in itertools.pairwise(runs(mask)):
        if start - end < gap:
            out[end:start] = True
    return out


def _edge_sensor(fused: FloatArray, z: FloatArray) -> np.ndarray:
    """The index of the valid sensor nearest to ``fused`` at each tick (-1: none)."""
    distance = np.where(np.isfinite(z), np.abs(z - fused[:, None]), np.inf)
    nearest = np.argmin(distance, axis=1)
    return np.where(np.isfinite(distance.min(axis=1)), nearest, -1)
