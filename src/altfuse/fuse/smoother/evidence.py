"""Model choice by the log's evidence: a GPS as stable as a barometer, a barometer's scale
error, temperature coefficient and drift rate are kept only where they raise the samples'
log-likelihood (a likelihood-ratio test)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from altfuse.datum.scale import Track, Wind, wind_beside
from altfuse.fuse.base import Jump, joined_jump, own_jump
from altfuse.fuse.smoother.model import (
    Events,
    Layout,
    Regressor,
    scale_regressors,
    scales_agree,
    scales_to_learn,
    scales_to_relearn,
    wash_depths,
)
from altfuse.fuse.smoother.noise import with_jumps
from altfuse.fuse.smoother.passes import Keep, likelihood, likelihoods, run
from altfuse.model import FloatArray

#: Log-likelihood gain that adds the drift rates: half the chi-square (1 dof) 0.1 % point. A
#: drift rate absorbs a warming as readily as a drift; at a Bayes factor of 20 (a gain of 3) it
#: was taken on a simulated climb that does not drift and took its warming (0.297 -> 0.400 m).
DRIFT_GAIN = 10.83 / 2
#: ... and the least share of the GPS's heights a pass accepts for them to witness the
#: barometers' drift (:func:`heard`).
HEARD_SHARE = 0.5
#: What the scale's test keeps of the pass without the scale: the height (the scale's regressor)
#: and the samples' log-likelihoods.
HEIGHTS = Keep(states=(0,), var_h=False, rows=False, verdicts=frozenset(("loglik",)))
#: ... and of the pass without the barometers (:func:`smoothed_wind`): the height alone.
HEIGHTS_ALONE = Keep(states=(0,), var_h=False, rows=False, verdicts=frozenset())
#: What the wash's test keeps of the pass with the wash: the wash's state and the samples'
#: log-likelihoods (:func:`wash_evidence`).
WASH = Keep(var_h=False, rows=False, verdicts=frozenset(("loglik",)))
#: A sample's variance [m^2] in a pass that does not hear its sensor (:func:`smoothed_wind`).
UNHEARD_M2 = 1e12
#: Log-likelihood gain that adds the temperature coefficients: a Bayes factor of 20, "strong"
#: evidence (Kass and Raftery 1995). The filter's likelihood integrates the coefficient over its
#: prior, so it already pays for the extra state; the chi-square point on top of that left a
#: real 1.2 m warming unmodelled at a gain of 5.3 (a simulated climb whose rangefinder is below
#: its minimum on the ground: 0.661 m, coverage 0.05). The simulators' logs, whose temperature
#: follows the height and must not be fitted, gain at most 1.3.
THERMAL_GAIN = 3.0
#: Log-likelihood gain that adds the barometers' dynamic-pressure coefficients: a Bayes factor of
#: 20, as THERMAL_GAIN.
DYNAMIC_GAIN = 3.0
#: Log-likelihood gain that adds the scale errors: a Bayes factor of 20, as THERMAL_GAIN (the
#: filter's likelihood integrates the scale over its prior). Measured: a simulated mission whose
#: barometer reads 7 % high over 15 m, which the datum cannot tell, gains 40-300; the
#: simulators' logs whose second barometer is noisy gain 12 and 191; the rest -6 to 0.5.
SCALE_GAIN = 3.0
#: Log-likelihood gain that takes the GPS's offset as stable as a barometer's: a Bayes factor of
#: 20, as THERMAL_GAIN (both models have the same states). Measured: the ArduPilot simulators'
#: copter logs, whose GPS lags but does not wander, gain 25-222 (their planes' none: the stable
#: model rejects more samples); PX4's simulator logs 0.1-22 (four of five take it); altfuse's
#: simulated flights, whose GPS wanders, -76 or none; the real logs 2.3 (pymavlink's test log)
#: or none.
STABLE_GAIN = 3.0
#: Log-likelihood gain by which a step between two sensors is the one's jump rather than the
#: other's (:func:`jump_evidence`), a Bayes factor of 20 as THERMAL_GAIN; and the most steps so
#: tested, the largest first (the others: either sensor's).
JUMP_GAIN = 3.0
JUMP_TESTS = 8
JUMP_TOGETHER_S = 1.0
#: Log-likelihood gain that adds the barometers' error in the rotors' wash (:func:`wash_evidence`):
#: a Bayes factor of 20, as THERMAL_GAIN.
WASH_GAIN = 3.0
#: ... over the flight up to this long after its span's end [s]: beyond it the two models read
#: the same (on the 300 MB log the test over the whole flight cost 0.9 s of 7.0).
WASH_EVIDENCE_S = 30.0
#: The richer model may reject this share more of the samples (the temperature model of the
#: sample mission rejects 2 of 5,371 more, and explains the rest by 25 in log-likelihood). At
#: 0.1 % a handful of samples at the gate's edge decided: the 9 m sonar flight with its GPS left
#: out, or as noisy as a real receiver's, lost its barometer's 8 % scale to 10 rangefinder
#: samples of 6,524 (0.698 and 0.648 m RMSE, against 0.020 and 0.039 with it); with each
#: barometer as noisy as a GPS, four flights lost the stable GPS (0.12-0.56 m, against
#: 0.02-0.04). At 0.5 % (0.2 % the same on the truth logs' variants, 1 % one step-gps variant
#: worse): the truth logs and the 192 simulated flights unchanged.
EVIDENCE_SLACK = 5e-3


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


@dataclass(frozen=True)
class Made:
    """A forward pass made already (:func:`.passes.likelihood`'s ``verdicts``) and the model
    it was made of: its ``events`` and ``layout``, each compared by identity (a test hands on
    the very objects it keeps). The tests in turn pass on the pass of the model each chose: the
    next compares its richer model with that one, which it need not filter again (on the 300
    MB log two of nine passes were the same model's; ``r``, the variances, are the same in
    every test)."""

    events: Events
    layout: Layout
    verdicts: dict[str, np.ndarray]


def _made_of(made: Made | None, events: Events, layout: Layout) -> dict[str, np.ndarray] | None:
    """The verdicts of ``made`` where it is the pass of ``events`` and ``layout``; else None."""
    if made is None or made.events is not events or made.layout is not layout:
        return None
    return made.verdicts


def gps_evidence(
    ev: Events, r: FloatArray, layout: Layout, stable: FloatArray, kinds: Sequence[str]
) -> tuple[Events, float, Made]:
    """``ev`` with its GPS offsets' random walks as stable as a barometer's (``stable``, the
    offsets' densities per event) where the log's evidence asks for it, that evidence, and the
    forward pass of the events chosen (its sensors' ``kinds``).

    A GPS's vertical error wanders by about a metre over minutes, and the default prefers the
    barometer's level to it; an RTK fix, or a simulator's GPS, is as stable as the barometer,
    and the preference then makes the fused height follow the barometer's errors (a simulator's
    noisy barometer: 0.045 m RMSE against 0.027 m with the GPS taken as stable, ``fused_std``
    half the true error). The offsets' wander is not split by the log otherwise: with two
    sensors it fixes only their sum (the module doc of :mod:`altfuse.fuse.smoother`). Tested
    first: the barometer's tests are made with the offsets chosen here.

    A barometer that drifts (a board warming) parts from a stable GPS: without its drift the
    stable GPS explains the log worse than a wandering one, whose offset then takes the
    drift, and the fused height follows the barometer. Each GPS model is therefore offered
    with the barometers' drift rates too, the stable one where they explain the log better
    than its receivers' own drift would (:func:`stable_gain`, as :func:`drift_evidence`
    keeps them); whether they drift is decided later, by :func:`drift_evidence`. The
    simulators' 9 m sonar flight with its barometer drifting 3 m in 10 minutes: the stable GPS
    alone -805, with the drift +101; the fused height had followed the barometer, 0.43 m RMSE.
    """
    trial = replace(ev, q_state=stable)
    models = [(ev, r, layout), (trial, r, layout)]
    barometers, receivers = _drifting(layout, kinds)
    if "baro" in kinds:
        models += [(ev, r, barometers), (trial, r, barometers), (trial, r, receivers)]
    default, richer, *drifted = likelihoods(*models)
    # whether the GPS witnesses the barometers' drift, and whether any sensor does where they
    # drift: asked only where a drift is offered
    gps_heard = bool(drifted) and heard(default, ev.who, receivers.drifting)
    seen = any(witnessed(d, ev.who, kinds) for d in drifted[:2])
    gain = stable_gain(default, richer, drifted, heard=gps_heard, witnessed=seen)
    chosen, verdicts = (trial, richer) if gain > STABLE_GAIN else (ev, default)
    return chosen, gain, Made(chosen, layout, verdicts)


def stable_gain(
    default: dict[str, np.ndarray],
    stable: dict[str, np.ndarray],
    drifted: Sequence[dict[str, np.ndarray]] = (),
    *,
    heard: bool = True,
    witnessed: bool = True,
) -> float:
    """The stable GPS's log-likelihood gain over the wandering one's (the passes ``default``
    and ``stable``); with ``drifted``, the same two passes with the barometers' drift rates
    and the stable one's with its receivers' drift instead, each GPS model's best against the
    other's: with the barometers' drift where it gains DRIFT_GAIN over the same model without,
    and in the stable model where the receivers' drift does not gain clearly more (more, where
    the GPS's heights are not ``heard``; never where no sensor's are ``witnessed``), as
    :func:`drift_evidence` keeps it. A barometer
    flashed 3 m (settling back over 15 s) beside the simulators' 305 m climb's GPS: the stable
    GPS with the barometer's drift won (109), and the drift test, which the GPS's own drift
    explained better, left it out: 0.254 m RMSE; 0.041 with the GPS wandering."""
    gain = evidence_gain(default, stable)
    if not drifted:
        return gain
    wandering, barometers, receivers = (evidence_gain(default, d) for d in drifted)
    best_wandering = wandering if _drift_kept(wandering, witnessed=witnessed) else 0.0
    kept = _drift_kept(barometers, receivers, gain, heard=heard, witnessed=witnessed)
    return (barometers if kept else gain) - best_wandering


def _drift_kept(
    drift: float,
    rival: float = -math.inf,
    without: float = 0.0,
    *,
    heard: bool = True,
    witnessed: bool = True,
) -> bool:
    """Whether the barometers' drift rates are kept, their model's log-likelihood gain
    ``drift`` (over some pass) DRIFT_GAIN above the model without's (``without``, over the same
    pass) and the receivers' own drift's (``rival``; -inf: not offered) not DRIFT_GAIN above it
    where the GPS's heights are ``heard`` (:func:`heard`), not above it where they are not;
    never where no sensor's heights are ``witnessed`` (:func:`witnessed`).

    Where the two explain the log alike, the barometers drift: a slow parting of barometer and
    GPS tells no more than that one drifts, and pressure does (the weather, a board warming),
    as both autopilots' estimators take it: ArduPilot's EKF3 corrects the barometer's datum
    for its drift by the GPS's height (``EK3_OGN_HGT_MASK``), PX4's EKF2 estimates a barometer
    bias against the GNSS height. Each barometer drifting 1 m in 10 minutes beside the
    simulators' 99 m autotest climb's GPS: gains of 54.3 and 54.5, the drift left out, 0.090 m
    RMSE (0.008 with it); 5 m beside the 3.3 plane's, 107.5 and 108.2: 0.843 m (0.080). A GPS
    whose heights are rejected is no such reference: a real log's receiver 15 m off its
    barometer, 4 % of its heights accepted (gains of 9.2 and 9.8), drifted the barometer by
    its vertical velocity alone, the fused height 1.8 m above the barometer and 10 m above
    the GPS for 28 s. The two gains were that close: at an output rate of 20 Hz (the
    accelerometer's input on a finer clock) 18.8 against 9.9, and the same log's fused height
    went 1.5 m above the barometer and 12 m above the GPS for 42 s. Where no other sensor's
    heights are accepted, the drift rests on the accelerometer's double integral and the GPS's
    vertical velocity, which hold no level: it is not modelled."""
    return (
        witnessed
        and drift > without + DRIFT_GAIN
        and rival < drift + (DRIFT_GAIN if heard else 0.0)
    )


def heard(verdicts: dict[str, np.ndarray], who: np.ndarray, receivers: Sequence[int]) -> bool:
    """Whether the GPS's heights witness the barometers' drift: at least HEARD_SHARE of the
    samples of the ``receivers`` (sensor columns) accepted by the pass ``verdicts`` of events
    ``who``."""
    theirs = np.isin(who, receivers)
    return bool(theirs.any()) and float(verdicts["accepted"][theirs].mean()) >= HEARD_SHARE


def witnessed(verdicts: dict[str, np.ndarray], who: np.ndarray, kinds: Sequence[str]) -> bool:
    """Whether a sensor other than the barometers (a GPS, a rangefinder) witnesses their drift:
    its heights :func:`heard` by the pass ``verdicts`` of events ``who``, one in which the
    barometers drift (without it, a barometer drifting 10 m in 10 minutes has its GPS
    rejected)."""
    return any(heard(verdicts, who, (i,)) for i, kind in enumerate(kinds) if kind != "baro")


def _drifting(layout: Layout, kinds: Sequence[str]) -> tuple[Layout, Layout]:
    """``layout`` with a drift rate on each barometer's offset, and on each GPS receiver's."""
    receivers = tuple(i for i, kind in enumerate(kinds) if kind == "gps")
    return layout.with_drift(kinds), replace(layout, drifting=receivers)


def scale_evidence(
    physical: Events, r: FloatArray, layout: Layout, unknown: Sequence[tuple[float, float] | None]
) -> tuple[Layout, float]:
    """``layout`` with a scale error on each barometer whose scale the datum half-knew
    (``unknown``: :func:`.model.scale_regressors`) where the log's evidence asks for it and the
    scale found agrees with the datum's (:func:`.model.scales_agree`), and that evidence (NaN
    without such a barometer, -inf where the scales disagree).

    The scale multiplies the height: its regressor is the height smoothed without it (the
    model is then linear). Tested before the temperature and the drift, which would otherwise
    take a scale error for themselves: a climb and a descent with a barometer 4.4 % high took a
    drift rate (a simulator's log: fused_std growing to 6 cm for 1 cm errors, coverage 1.00;
    with the scale 0.94, RMSE 0.013 -> 0.005 m). Made with the offsets' physical random walks
    (``physical``), as :func:`thermal_evidence`.
    """
    if not scales_to_learn(unknown):
        return layout, math.nan
    without = run(physical, r, layout, keep=HEIGHTS)
    richer = layout.adding(scale_regressors(physical.who, without["x"][:, 0], unknown))
    verdict = likelihood(physical, r, richer)
    gain = evidence_gain(without, verdict)
    if not scales_agree(richer, verdict["last"], unknown):
        gain = -math.inf
    return (richer if gain > SCALE_GAIN else layout), gain


def dynamic_evidence(
    physical: Events,
    r: FloatArray,
    layout: Layout,
    candidates: Sequence[Sequence[Regressor]],
    made: Made | None,
) -> tuple[Layout, float, int, Made | None]:
    """``layout`` with the barometers' dynamic-pressure coefficients where the log's evidence
    asks for them, that evidence (NaN without them), which of the ``candidates`` it took
    (their regressors, :func:`.model.dynamic_regressors`, at the airspeed the datum's wind
    leaves and at the ground speed; -1: none), and the pass of the layout chosen (``made``
    where none was offered): the likeliest taken where it gains DYNAMIC_GAIN over the model
    without (a wind the datum told wrong loses to the ground speed; its pass ``made`` where
    that is one already). Made with the offsets' physical random walks (``physical``), as
    :func:`thermal_evidence`, and before it and the drift, which would otherwise take the
    barometer's rise in each fast stretch for a warming or a drift."""
    offered = [k for k, c in enumerate(candidates) if c]
    if not offered:
        return layout, math.nan, -1, made
    richer = [layout.adding(candidates[k]) for k in offered]
    models = [(physical, r, model) for model in richer]
    without = _made_of(made, physical, layout)
    if without is None:
        models.insert(0, (physical, r, layout))
    # two passes at once, a third after: three at once put the 300 MB log's peak from 1.42x
    # the file to 1.55x
    verdicts = [*likelihoods(*models[:2]), *(likelihood(*model) for model in models[2:])]
    if without is None:
        without = verdicts.pop(0)
    gains = [evidence_gain(without, verdict) for verdict in verdicts]
    best = int(np.argmax(gains))
    if not gains[best] > DYNAMIC_GAIN:
        return layout, gains[best], -1, Made(physical, layout, without)
    return richer[best], gains[best], offered[best], Made(physical, richer[best], verdicts[best])


def smoothed_wind(
    physical: Events, r: FloatArray, layout: Layout, kinds: Sequence[str], track: Track
) -> Wind | None:
    """The wind the barometers' readings tell against the height smoothed without them (from
    the GPS, the accelerometer, a rangefinder: :func:`altfuse.datum.scale.wind_beside`), the best
    told of theirs; None where none tells it, or without a sensor other than a barometer.
    Where the datum's fit against the GPS alone cannot tell it: a GPS 0.35 m noisy and
    wandering, altfuse's mission in a 2 m/s wind along its track (k 0.4), 0.28-0.43 m RMSE
    with the ground speed's head or none, 0.054-0.062 with the true wind's airspeed."""
    baro = np.isin(physical.who, [i for i, k in enumerate(kinds) if k == "baro"])
    if not ((physical.who >= 0) & ~baro).any():
        return None
    h = run(physical, np.where(baro, UNHEARD_M2, r), layout, keep=HEIGHTS_ALONE)["x"][:, 0]
    winds = []
    for i in np.unique(physical.who[baro]):
        mine = physical.who == i
        wind = wind_beside(physical.t[mine], physical.z[mine] - h[mine], track)
        if wind is not None:
            winds.append(wind)
    return max(winds, key=lambda w: w.sigmas, default=None)


def wash_evidence(
    ev: Events,
    r: FloatArray,
    layouts: tuple[Layout, Layout],
    kinds: Sequence[str],
    spans: Sequence[tuple[float, float]],
) -> tuple[Layout, dict[str, float | str]]:
    """The first of ``layouts``, or the second, with the barometers' error in the rotors' wash
    in ``spans`` (:attr:`.model.Layout.washed`), and the test's record for the metadata
    (nothing where the second is the first: no barometer, no span).

    The wash is modelled where the log's evidence asks for it, another sensor's heights
    witness it (:func:`witnessed`) and the barometers read low in it (:func:`.model.wash_depths`:
    the wash's dip below its ends deeper than its rise above them; a rise is the air of a
    plane's take-off run, or a climb's). The samples it lets in that the model without it
    rejects count (:func:`evidence_gain` leaves them out, where two models' rejections would
    credit the one that explains a departure away): each one at least what it gains over a
    sample at the gate's edge. Without them the test cannot see a wash the model without it
    rejects: of five truth logs whose barometers read 0.5 m low (``tests/variants.py``,
    ``wash-0.5``) it lost two (four at a spread of 1 m; the 10 m sonar flight's gain -39, with
    them 65)."""
    plain, washing = layouts
    if washing is plain:
        return plain, {}
    end = max(hi for _, hi in spans) + WASH_EVIDENCE_S
    ev, r, (plain_until, washing_until) = _until(ev, r, layouts, end)
    without = likelihood(ev, r, plain_until)
    richer = run(ev, r, washing_until, keep=replace(WASH, states=(washing.wash,)))
    gain = evidence_gain(without, richer)
    if math.isfinite(gain):
        alone = richer["accepted"] & ~without["accepted"]
        edge = -0.5 * (np.log(2.0 * np.pi * r[alone]) + ev.gate**2)
        gain += float(np.sum(richer["loglik"][alone] - edge))
    dip, rise = wash_depths(ev.t, richer["x"][:, 0], spans)
    asked = gain > WASH_GAIN
    seen = witnessed(richer, ev.who, kinds)
    modelled = asked and seen and dip > rise
    record = evidence_record("wash", modelled, gain, unwitnessed=asked and not seen)
    if asked and seen and not modelled:
        record["baro_wash"] = "not modelled (the barometers read high there, not low)"
    if modelled:
        record["baro_wash_m"] = -dip
    return (washing if modelled else plain), record


def _until(
    ev: Events, r: FloatArray, layouts: tuple[Layout, Layout], end_s: float
) -> tuple[Events, FloatArray, tuple[Layout, Layout]]:
    """The events up to ``end_s`` [s], their variances, and ``layouts`` with their regressors'
    coefficients at those events alone (all of them where no event is later)."""
    k = int(np.searchsorted(ev.t, end_s, side="right"))
    if k >= ev.t.size:
        return ev, r, layouts

    def head(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a[:k]

    def cut(layout: Layout) -> Layout:
        kept = tuple(replace(g, coef=g.coef[:k]) for g in layout.regressors)
        return replace(layout, regressors=kept)

    events = replace(
        ev, t=ev.t[:k], who=ev.who[:k], z=ev.z[:k], a=ev.a[:k], still=ev.still[:k],
        q_state=ev.q_state if ev.q_state.shape[0] == 1 else ev.q_state[:k],
        q_accel=ev.q_accel[:k], landed=head(ev.landed), reset=head(ev.reset),
        early=head(ev.early), model=head(ev.model), cleared=head(ev.cleared),
    )  # fmt: skip
    return events, r[:k], (cut(layouts[0]), cut(layouts[1]))


def thermal_evidence(
    physical: Events, r: FloatArray, layout: Layout, kinds: Sequence[str], made: Made | None
) -> tuple[Layout, dict[str, float | str], Made | None]:
    """``layout`` with the barometers' temperature coefficients where the log's evidence asks
    for them, the test's record for the metadata (nothing without a temperature), and the
    forward pass of the layout chosen (``made`` without a temperature; ``made`` is also
    ``layout``'s where it is that pass).

    In a simulator's standard atmosphere the temperature follows the height, and a coefficient
    on it is a second, wrong scale (three climbs: 0.09-0.29 m RMSE with it, 0.01-0.04 m
    without). The test is made with the offsets' physical random walks (``physical``), not
    with a looser one a user gave: a barometer let wander absorbs the drift the temperature
    explains, and the test would drop a model the flight needs (the sample hover with
    ``--offset-noise baro=0.001``: 0.40 m RMSE without it, 0.06 m with). Kept only where
    another sensor's heights witness it (:func:`witnessed`), as a drift: rima48, its GPS 15 m
    off and 3 % of its heights accepted, took -0.043 m/degC at 10 Hz and -0.019 at 20 (the
    accelerometer's input on the clock), the two heights 0.5 m apart; without it, 0.09 m.
    """
    if not layout.has("thermal"):
        return layout, {}, made
    plain = layout.without("thermal")
    richer = _made_of(made, physical, layout)
    if richer is None:
        without, richer = likelihoods((physical, r, plain), (physical, r, layout))
    else:
        without = likelihood(physical, r, plain)
    gain = evidence_gain(without, richer)
    asked = gain > THERMAL_GAIN
    seen = witnessed(richer, physical.who, kinds)
    record = evidence_record("thermal", asked and seen, gain, unwitnessed=asked and not seen)
    if asked and seen:
        return layout, record, Made(physical, layout, richer)
    return plain, record, Made(physical, plain, without)


def drift_evidence(
    ev: Events,
    r: FloatArray,
    layout: Layout,
    kinds: Sequence[str],
    made: Made | None,
) -> tuple[Layout, dict[str, float | str]]:
    """``layout`` with a drift rate on each barometer's offset where the log's evidence asks
    for it, and the test's record for the metadata (nothing without a barometer); ``made``
    may be ``layout``'s forward pass with these events, made already.

    A barometer and a GPS that part slowly tell no more than that one of them drifts. Where the
    log has a GPS, the drift is offered to its receivers instead, too, and the barometers'
    is modelled unless theirs explains the log clearly better (:func:`_drift_kept`): a receiver
    powered on before its fix settled climbed 20 m in 150 s against a barometer, a second GPS
    and a rangefinder that agreed with each other, and the barometer's drift (a gain of 7.4)
    took the fused height 2 m above all three (the GPS's own: a gain of 214)."""
    if "baro" not in kinds:
        return layout, {}
    drifting, receivers = _drifting(layout, kinds)
    models = [(ev, r, drifting)]
    if receivers.drifting:
        models.append((ev, r, receivers))
    stable = _made_of(made, ev, layout)
    if stable is None:
        stable, *passes = likelihoods((ev, r, layout), *models)
    else:
        passes = likelihoods(*models)
    gain = evidence_gain(stable, passes[0])
    rival = evidence_gain(stable, passes[1]) if receivers.drifting else -math.inf
    seen = witnessed(passes[0], ev.who, kinds)  # by the pass in which the barometers drift
    gps_heard = heard(stable, ev.who, receivers.drifting)
    modelled = _drift_kept(gain, rival, heard=gps_heard, witnessed=seen)
    record = evidence_record("drift", modelled, gain, unwitnessed=_drift_kept(gain) and not seen)
    if math.isfinite(rival):
        record["gps_drift_loglik_gain"] = rival  # the rival's, never modelled itself
    if _drift_kept(gain) and seen and not modelled:
        record["baro_drift"] = "not modelled (the GPS's own drift explains the log better)"
    return (drifting if modelled else layout), record


#: Why a richer model lost outright (a gain of -inf), per test.
LOST = {"scale": "its scale disagreed with the datum's, or it rejected more samples"}
#: Why a barometer's slow error that the log's evidence asked for was not modelled.
UNWITNESSED = "not modelled (no other sensor's heights witness it)"


def evidence_record(
    what: str, modelled: bool, gain: float, sensor: str = "baro", *, unwitnessed: bool = False
) -> dict[str, float | str]:
    """A test's outcome for the metadata, ``<sensor>_<what>`` and its log-likelihood gain
    (nothing where there was no test; no gain where the richer model lost outright: it rejected
    more samples, or for ``LOST``'s tests, what they say); ``unwitnessed``: left out for want
    of a witness (:func:`witnessed`)."""
    if math.isnan(gain):
        return {}
    key = f"{sensor}_{what}"
    if not math.isfinite(gain):
        why = LOST.get(what, "it rejected more samples than the model without")
        return {key: f"not modelled ({why})"}
    verdict = "modelled" if modelled else "not modelled (the log's evidence does not ask for it)"
    return {key: UNWITNESSED if unwitnessed else verdict, f"{key}_loglik_gain": gain}


def relearnt_scales(
    ev: Events,
    physical: Events,
    r: FloatArray,
    layout: Layout,
    unknown: Sequence[tuple[float, float] | None],
    known: Sequence[tuple[float, float] | None],
) -> tuple[Layout, float, Events, Events]:
    """:func:`scale_evidence` on the scales the datum did not apply (``unknown``), and first,
    where it applied one with a standard error above LEARN_SCALE_STD (``known``: per sensor the
    scale applied and its error), also on the readings of every barometer whose scale it
    applied, referred by their offset only (``z - c = scale h``;
    :func:`.model.scales_to_relearn`): where the log's evidence learns every such scale, the
    smoother takes them and those readings (``ev`` and ``physical`` with them); elsewhere the
    datum's scales stay. The datum sees the GPS alone, the smoother the accelerometer too: the
    datum's 1.074 +- 0.013 on altfuse's hovers whose barometer reads 7 % high left 0.48-0.71 m
    RMSE and +-2 sigma coverage 0.12-0.17 (see LEARN_SCALE_STD)."""
    again = scales_to_relearn(known)
    if again:
        z = physical.z.copy()
        for i, (scale, _) in again.items():
            z[physical.who == i] *= scale
        asked = [again.get(i, u) for i, u in enumerate(unknown)]
        found, gain = scale_evidence(replace(physical, z=z), r, layout, asked)
        if {reg.sensor for reg in found.regressors if reg.name == "scale"} >= again.keys():
            raw = replace(ev, z=z)
            return found, gain, raw, raw if physical is ev else replace(physical, z=z)
    found, gain = scale_evidence(physical, r, layout, unknown)
    return found, gain, ev, physical


def jump_evidence(
    ev: Events,
    model: tuple[FloatArray, Layout],
    steps: Sequence[Jump],
    windowed: Callable[[Jump], Jump],
) -> tuple[Jump, ...]:
    """The ``steps`` between two sensors (by time), each given to the one sensor that jumped
    where the log's evidence tells (``ev``'s offsets' densities without the jumps).

    Either sensor's offset may jump at a step, and the accelerometer, which holds the height
    through it, would tell which: but while both offsets are loose the height is held by the
    accelerometer alone, and a simulator's 305 m climb with its GPS stepped 1 m took 0.096 m
    RMSE (0.012 with the step the GPS's; 0.018 with the GPS gated out after it). Steps within
    JUMP_TOGETHER_S of each other are one event: a GPS's jump is a step against each barometer
    (tried one at a time, the first went to the GPS and the second then to a barometer, whose
    samples were moved 1.9 m). Each event (the JUMP_TESTS largest) is tried as the jump of the
    sensor its steps share, or of each step's other sensor (for one step, of either), the
    other events as they stand, and goes to the one whose samples' log-likelihood is JUMP_GAIN
    higher (:func:`evidence_gain`: over the samples both accept, and no more of them
    rejected), each sensor with its own jump; else, several steps to the sensor they share
    (the others agree it moved), one step to both its sensors. ``model``: the samples'
    variances and the layout; ``windowed``: a jump as :func:`altfuse.steps.find_steps` gives
    it (half the gap it was found across last) with the window it lies in instead
    (:func:`.noise.with_jumps`).
    """
    events = _together(steps)
    chosen = [[windowed(steps[k]) for k in event] for event in events]
    order = sorted(range(len(events)), key=lambda e: -max(abs(steps[k][2]) for k in events[e]))
    for e in order[:JUMP_TESTS]:
        raw = _options([steps[k] for k in events[e]])
        options = [[windowed(jump) for jump in option] for option in raw]
        if not options:
            continue
        before = [jump for jumps in chosen[:e] for jump in jumps]
        after = [jump for jumps in chosen[e + 1 :] for jump in jumps]
        trials = (_jumping(ev, model, [*before, *option, *after]) for option in options)
        chosen[e] = _reading(likelihoods(*trials), options, chosen[e])
    return tuple(jump for jumps in chosen for jump in jumps)


def _jumping(
    ev: Events, model: tuple[FloatArray, Layout], jumps: Sequence[Jump]
) -> tuple[Events, FloatArray, Layout]:
    """The model of ``ev`` with its offsets let jump at ``jumps`` (:func:`.noise.with_jumps`),
    as :func:`.passes.likelihoods` takes it (``model``: the variances and the layout)."""
    r, layout = model
    return replace(ev, q_state=with_jumps(ev.q_state, jumps, ev.t, settling=False)), r, layout


def _reading(
    verdicts: Sequence[dict[str, np.ndarray]],
    readings: Sequence[list[Jump]],
    raw: list[Jump],
) -> list[Jump]:
    """The one of an event's two ``readings`` whose samples' log-likelihood (``verdicts``, in
    their order) is JUMP_GAIN above the other's; undecided, its ``raw`` steps (each loose on
    both its sensors), or between several steps the one sensor they share, which the others
    agree moved (a GPS's 2 m step beside a second GPS and a barometer, loose on all three: the
    fused height 0.30 m off; on the GPS, 0.002)."""
    a, b = verdicts
    if evidence_gain(a, b) > JUMP_GAIN:
        return readings[1]
    if evidence_gain(b, a) > JUMP_GAIN or len(raw) > 1:
        return readings[0]
    return raw


def regain_evidence(
    ev: Events,
    model: tuple[FloatArray, Layout],
    taken: Sequence[Jump],
    tentative: Sequence[Jump],
    windowed: Callable[[Jump], Jump],
) -> tuple[Jump, ...]:
    """The ``tentative`` steps (found only across a sensor's gap, below the sure steps'
    significance: :attr:`altfuse.steps.Step.tentative`) that the log's evidence takes, each
    event (as :func:`jump_evidence` groups them) tried as no jump and as each of its two
    readings (:func:`_options`), with the jumps ``taken`` and those taken before it: a reading
    is taken where its samples' log-likelihood is JUMP_GAIN above no jump's (the other's
    where that one's is JUMP_GAIN above it; undecided, as :func:`jump_evidence` leaves an
    event). A GPS lost for 10 s and regained 2 m higher beside a barometer is 5-10 sigma where
    the GPS is a real one (0.3 m noisy, wandering): not found, the 4.5 plane's simulated
    height followed it, 0.159 m RMSE (0.023 with its jump)."""
    out: list[Jump] = []
    for event in _together(tentative):
        steps = [tentative[k] for k in event]
        readings = [[windowed(jump) for jump in option] for option in _options(steps)]
        if not readings:
            continue
        trials = (_jumping(ev, model, [*taken, *out, *option]) for option in ([], *readings))
        none, a, b = likelihoods(*trials)
        if max(evidence_gain(none, a), evidence_gain(none, b)) > JUMP_GAIN:
            out.extend(_reading((a, b), readings, [windowed(jump) for jump in steps]))
    return tuple(out)


def _options(event: Sequence[Jump]) -> list[list[Jump]]:
    """The two readings of an event's steps (each between two sensors): one step as its first
    sensor's jump or its second's; several (sharing one sensor) as one jump of the sensor they
    share (their mean, once: a GPS's jump against two barometers is one jump) or each other
    sensor's; none where a step was already given."""
    pairs = [step[1] for step in event]
    if any(len(p) != 2 for p in pairs):
        return []
    if len(event) == 1:
        return [[own_jump(event[0], pairs[0][0])], [own_jump(event[0], pairs[0][1])]]
    (one,) = set.intersection(*(set(p) for p in pairs))  # one shared (:func:`_together`)
    common = joined_jump([own_jump(step, one) for step in event], (one,), max(s[3] for s in event))
    return [[common], [own_jump(step, next(s for s in step[1] if s != one)) for step in event]]


def _together(steps: Sequence[Jump]) -> list[list[int]]:
    """The ``steps`` (by time) grouped into events: each within JUMP_TOGETHER_S of the last,
    where they share one sensor; otherwise each its own (two GPS receivers stepped 1 s apart
    beside a barometer: against each other and against the barometer, no sensor in all
    three)."""
    events: list[list[int]] = []
    for k, step in enumerate(steps):
        if events and step[0] - steps[events[-1][-1]][0] <= JUMP_TOGETHER_S:
            events[-1].append(k)
        else:
            events.append([k])
    out: list[list[int]] = []
    for e in events:
        shared = set.intersection(*(set(steps[k][1]) for k in e))
        out.extend([e] if len(shared) == 1 else [[k] for k in e])
    return out
