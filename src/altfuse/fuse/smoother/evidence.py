"""Model choice by the log's evidence: a barometer's temperature coefficient and drift rate are
kept only where they raise the samples' log-likelihood (a likelihood-ratio test)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from altfuse.fuse.smoother.model import Events, Layout
from altfuse.fuse.smoother.passes import likelihood
from altfuse.model import FloatArray

#: Log-likelihood gain that adds the drift rates: half the chi-square (1 dof) 0.1 % point. A
#: drift rate absorbs a warming as readily as a drift; at a Bayes factor of 20 (a gain of 3) it
#: was taken on a simulated climb that does not drift and took its warming (0.297 -> 0.400 m).
DRIFT_GAIN = 10.83 / 2
#: Log-likelihood gain that adds the temperature coefficients: a Bayes factor of 20, "strong"
#: evidence (Kass and Raftery 1995). The filter's likelihood integrates the coefficient over its
#: prior, so it already pays for the extra state; the chi-square point on top of that left a
#: real 1.2 m warming unmodelled at a gain of 5.3 (a simulated climb whose rangefinder is below
#: its minimum on the ground: 0.661 m, coverage 0.05). The simulators' logs, whose temperature
#: follows the height and must not be fitted, gain at most 1.3.
THERMAL_GAIN = 3.0
#: The richer model may reject this share more of the samples (the temperature model of the
#: sample mission rejects 2 of 5,371 more, and explains the rest by 25 in log-likelihood).
EVIDENCE_SLACK = 1e-3


def evidence_gain(without: dict[str, np.ndarray], richer: dict[str, np.ndarray]) -> float:
    """Log-likelihood gain of the richer model (barometer drift rates, temperature
    coefficients) over the one without, over the samples both accept; ``-inf`` if it accepts
    fewer samples in all, beyond ``EVIDENCE_SLACK`` of them.

    The comparison is over the same samples: counting a rejected sample at the gate's value
    would credit whichever model explains away a departure (Paper A's barometer excursion), and
    one whose offset drifts then lets ``h`` wander once no third sensor holds it. A model that
    explains the data better has no need to reject more of it: the drift model did, by up to
    94 samples of a rangefinder returning from a dropout, on flights where it had gone astray.
    """
    slack = EVIDENCE_SLACK * without["accepted"].sum()
    if richer["accepted"].sum() < without["accepted"].sum() - slack:
        return -math.inf
    both = without["accepted"] & richer["accepted"]
    return float(np.sum(richer["loglik"][both]) - np.sum(without["loglik"][both]))


def thermal_evidence(
    physical: Events, r: FloatArray, layout: Layout
) -> tuple[Layout, float, dict[str, np.ndarray] | None]:
    """``layout`` with the barometers' temperature coefficients where the log's evidence asks
    for them, that evidence (the log-likelihood gain, NaN without a temperature), and the
    forward pass of the layout chosen (None without a temperature).

    In a simulator's standard atmosphere the temperature follows the height, and a coefficient
    on it is a second, wrong scale (three climbs: 0.09-0.29 m RMSE with it, 0.01-0.04 m
    without). The test is made with the offsets' physical random walks (``physical``), not
    with a looser one a user gave: a barometer let wander absorbs the drift the temperature
    explains, and the test would drop a model the flight needs (the sample hover with
    ``--offset-noise baro=0.001``: 0.40 m RMSE without it, 0.06 m with).
    """
    if not layout.has("thermal"):
        return layout, math.nan, None
    plain = layout.without("thermal")
    without, richer = likelihood(physical, r, plain), likelihood(physical, r, layout)
    gain = evidence_gain(without, richer)
    return (layout, gain, richer) if gain > THERMAL_GAIN else (plain, gain, without)


def drift_evidence(
    ev: Events,
    r: FloatArray,
    layout: Layout,
    kinds: Sequence[str],
    stable: dict[str, np.ndarray] | None,
) -> tuple[Layout, float]:
    """``layout`` with a drift rate on each barometer's offset where the log's evidence asks
    for it, and that evidence (NaN without a barometer); ``stable`` is ``layout``'s forward pass
    if one was already run with these events."""
    if "baro" not in kinds:
        return layout, math.nan
    drifting = layout.with_drift(kinds)
    gain = evidence_gain(
        stable if stable is not None else likelihood(ev, r, layout),
        likelihood(ev, r, drifting),
    )
    return (drifting if gain > DRIFT_GAIN else layout), gain


def evidence_record(what: str, modelled: bool, gain: float) -> dict[str, float | str]:
    """A test's outcome for the metadata, ``baro_<what>`` and its log-likelihood gain (nothing
    where there was no test; no gain where the richer model rejected more samples)."""
    if math.isnan(gain):
        return {}
    if not math.isfinite(gain):
        return {f"baro_{what}": "not modelled (it rejected more samples than the model without)"}
    verdict = "modelled" if modelled else "not modelled (the log's evidence does not ask for it)"
    return {f"baro_{what}": verdict, f"baro_{what}_loglik_gain": gain}
