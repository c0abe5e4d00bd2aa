"""The smoother's passes over the events: the forward Kalman filter, with its innovation gate and
lockout release (early where a pass before says so: :attr:`.model.Events.early`), and the
backward pass (the modified Bryson-Frazier smoother; steps from :mod:`.kalman`), each a
compiled loop over the events (:mod:`.compiled`).

The backward pass needs each event's filtered state and covariance; the forward pass keeps them
only at checkpoints, and the backward one filters again each block of events from its
checkpoint before going back through it (checkpointing, as in adjoint methods: memory per
block, not per flight, for one more forward pass that a second core hides)."""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from altfuse.fuse.smoother.compiled import compiled, compiled_loop, compiled_step
from altfuse.fuse.smoother.events import TICK, model_intervals
from altfuse.fuse.smoother.kalman import (
    Scratch,
    Transition,
    adjoint_predict,
    adjoint_restart,
    adjoint_update,
    assign,
    innovation,
    pack,
    predict,
    restart,
    scratch,
    smoothed_variance,
    unpack,
    update,
)
from altfuse.fuse.smoother.model import (
    Events,
    Layout,
    Rows,
    Structure,
    couplings,
    first_height,
    hold,
    measurement_row,
    measurement_rows,
    prior,
    process_noise,
    regressor_coefficients,
    reset_states,
    transition,
    wash_noise,
)
from altfuse.model import FloatArray

#: Longest time [s] every sensor's samples may be rejected before the estimate is let loose,
#: and a rangefinder's alone before its ground height is.
LOCKOUT_S = 2.0
#: ... and when two sensors are rejected on the same side: they agree against the estimate.
AGREED_LOCKOUT_S = 0.5
#: A sensor whose samples pass the gate agrees with one rejected for AGREED_LOCKOUT_S where
#: its innovations over that span lean to the rejected one's side by this many standard
#: errors of their mean, and their mean is within as many of the rejected innovation
#: (:func:`_leaning`): ArduPilot's EKF3 gates its heights at 5 sigma.
LEAN_SIGMAS = 5.0
#: What a rejected sample let loose (:func:`_release`): nothing, the height (where every
#: sensor was rejected for LOCKOUT_S, or another agreed; where two sensors the estimate
#: followed left it together: from their first rejection in the next pass; where one that
#: passed leant with it: from this sensor's first rejection in the next pass), a rangefinder's
#: ground.
LET_NOTHING, LET_LOST, LET_AGREED, LET_GROUND, LET_LEANT = 0, 1, 2, 3, 4
#: Whether another sensor agrees (:func:`_agreed`, :func:`_leaning`): one does; one the
#: estimate followed, whose rejections began with this one's; one that passed, leaning with it.
AGREED, AGREED_TOGETHER, LEANT = 1, 2, 3
#: Events between two of the forward filter's checkpoints (:func:`_backward`): what the backward
#: pass needs of a block's events, twice (one block is filtered again while the pass goes back
#: through the other), is 9.2 MB with six states, against 222 MB for a 7.4-hour log's events.
BLOCK = 16384


@dataclass(frozen=True)
class Keep:
    """What a pass keeps of each event, each array 6 MB on a 7.4-hour log's 791,616 events
    (the passes' peak, kept whole): ``states``, the smoothed states kept (their indices; None:
    all), at every event or, with ``ticks``, at the clock's ticks only; ``var_h``, the
    variance of h there; ``rows``, each sample's smoothed ``H x`` (``hx``) and its variance
    (``var_row``), NaN at a tick; and of the forward filter's verdicts, which samples it
    accepted (always) and those named in ``verdicts``: each one's gain on h (``gain_h``), its
    log-likelihood (``loglik``), its normalised innovation (``nu``) and, per sample, whether
    the height was let loose for the episode of rejections it began (``released``: the next
    pass lets it loose there, :attr:`.model.Events.early`)."""

    states: tuple[int, ...] | None = None
    ticks: bool = False
    var_h: bool = True
    rows: bool = True
    verdicts: frozenset[str] = frozenset(("gain_h", "loglik", "nu", "released"))

    def judged(self) -> tuple[bool, bool, bool, bool]:
        """Whether the forward filter keeps each sample's gain, log-likelihood, innovation,
        release."""
        return (
            "gain_h" in self.verdicts,
            "loglik" in self.verdicts,
            "nu" in self.verdicts,
            "released" in self.verdicts,
        )


#: Everything (the tests'); what an EM pass needs (h, v and the accelerometer's bias, each
#: sample's row, where the height was let loose); and the last pass (the result: the states and
#: h's variance at the ticks, the gains, the innovations).
EVERYTHING = Keep()
FOR_EM = Keep(states=(0, 1, 2), var_h=False, verdicts=frozenset(("released",)))
FOR_RESULT = Keep(ticks=True, rows=False, verdicts=frozenset(("gain_h", "nu")))
#: A response pass (:func:`altfuse.fuse.smoother.scale_response`): h at the ticks.
HEIGHT_ONLY = Keep(states=(0,), ticks=True, var_h=False, rows=False, verdicts=frozenset())
#: The verdicts of a forward pass alone (:func:`likelihood`).
LIKELIHOOD = Keep(verdicts=frozenset(("loglik",)))


def run(
    ev: Events,
    r: FloatArray,
    layout: Layout,
    smooth: bool = True,
    block: int = BLOCK,
    keep: Keep = EVERYTHING,
) -> dict[str, np.ndarray]:
    """Forward filter and (if ``smooth``) the backward pass over the events: the states (``x``),
    the variance of ``h`` (``var_h``), each sample's own measurement row ``H x`` (``hx``) and its
    variance (``var_row``, NaN at a tick), smoothed (or filtered), and diagnostics, as much of
    them as ``keep`` says.

    ``r`` is each event's measurement variance. Also each accepted sample's log-likelihood (its
    innovation's density; NaN elsewhere): the evidence by which :func:`evidence_gain` compares two
    models. ``block``: the events between two checkpoints of the forward filter (:func:`_backward`).
    """
    model = _model(ev, r, layout)
    _, checkpoints, verdicts, kept = _forward(model, block, True, keep.judged())
    states = np.arange(layout.n) if keep.states is None else np.array(keep.states)
    smoothed = _backward(model, (checkpoints, kept), verdicts, (block, smooth), (states, keep))
    x, var_h, hx, var_row = smoothed
    out = {"x": x, "accepted": verdicts[1]}
    if keep.var_h:
        out["var_h"] = var_h
    if keep.rows:
        out.update(hx=hx, var_row=var_row)
    judged = {
        "gain_h": verdicts[0],
        "loglik": verdicts[2],
        "nu": verdicts[3],
        "released": verdicts[4],
    }
    return out | {name: judged[name] for name in sorted(keep.verdicts)}


def likelihood(ev: Events, r: FloatArray, layout: Layout) -> dict[str, np.ndarray]:
    """The forward filter's verdicts alone: which samples it accepted and their log-likelihood,
    and its state after the last event (``last``: a constant state's estimate from the whole
    flight); :func:`run` without the backward pass."""
    return _verdicts(_model(ev, r, layout))


def _verdicts(model: Model) -> dict[str, np.ndarray]:
    last, _, verdicts, _ = _forward(model, BLOCK, False, LIKELIHOOD.judged())
    return {"accepted": verdicts[1], "loglik": verdicts[2], "last": last}


def likelihoods(*models: tuple[Events, FloatArray, Layout]) -> list[dict[str, np.ndarray]]:
    """:func:`likelihood` of each model (events, variances, layout), the passes run in
    threads, as many at once as the process has cores: the compiled loop releases the GIL, so
    the two models a test compares cost one pass's time where two cores are free. Each model is
    built as its pass begins (its rows of H: 15 MB on the 300 MB log's 791,616 events), so no
    more are alive than run at once: the GPS test's five, all built first, put that log's peak
    at 1.53x the file. Models with the same regressors (a drift or the noises their only
    difference) share their coefficients at every event: each pass's own copy was 6 MB a
    regressor on the 300 MB log, three at once in the drift test."""
    shared: dict[tuple[int, int], FloatArray] = {}
    for ev, _, layout in models:
        key = (id(layout.regressors), ev.who.size)  # the tuple alive while the models are
        if key not in shared:
            shared[key] = regressor_coefficients(layout.regressors, ev.who.size)

    def verdicts(model: tuple[Events, FloatArray, Layout]) -> dict[str, np.ndarray]:
        ev, r, layout = model
        rows = measurement_rows(layout, ev.who, shared[(id(layout.regressors), ev.who.size)])
        return _verdicts(_model(ev, r, layout, rows))

    with ThreadPoolExecutor(min(len(models), _cores()), thread_name_prefix="altfuse-pass") as pool:
        return list(pool.map(verdicts, models))


def _cores() -> int:
    """The CPUs this process may run on (its affinity where the system tells it)."""
    affinity = getattr(os, "sched_getaffinity", None)
    return len(affinity(0)) if affinity is not None else (os.cpu_count() or 1)


def _model(ev: Events, r: FloatArray, layout: Layout, rows: Rows | None = None) -> Model:
    """The filter's arguments (:data:`Model`) for the events ``ev`` with variances ``r`` (and
    ``rows`` of H, where made already: :func:`.model.measurement_rows`)."""
    start = (*prior(ev, layout), *_resets(ev, layout))
    measured = _measured(ev, r, measurement_rows(layout, ev.who) if rows is None else rows)
    return measured, _dynamics(ev, layout), _marks(ev), ev.gate, start


def _measured(
    ev: Events, r: FloatArray, rows: Rows
) -> tuple[FloatArray, np.ndarray, FloatArray, FloatArray, Rows]:
    """The events' times, series, values, variances and rows of H, as the kernels take them."""
    who = np.asarray(ev.who, dtype=np.int64)  # no copy where it is one already
    return ev.t, who, ev.z, np.asarray(r, dtype=np.float64), rows


def _marks(ev: Events) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The events marked, as the kernels take them: held on the ground at the datum (h = 0,
    v = 0) and elsewhere standing (v = 0), those at which the height is let loose early
    (empty: none), and those at which the barometers have left the rotors' wash (w = 0)."""
    still = ev.still.astype(np.bool_)
    landed = np.zeros_like(still) if ev.landed is None else ev.landed.astype(np.bool_)
    early = np.zeros(0, dtype=np.bool_) if ev.early is None else ev.early.astype(np.bool_)
    cleared = np.zeros_like(still) if ev.cleared is None else ev.cleared.astype(np.bool_)
    return still, landed, early, cleared


def _resets(ev: Events, layout: Layout) -> tuple[np.ndarray, np.ndarray, FloatArray]:
    """The events at which part of the state returns to its prior (a splice: 0 none, else the
    row of ``reset_states`` to return), those rows, and the height the prior takes there (the
    segment's :func:`first_height`; NaN at other events), as the kernels take them."""
    none = np.zeros(ev.t.size, dtype=np.int8)
    kinds = none if ev.reset is None else np.asarray(ev.reset, dtype=np.int8)
    # read at a splice only: none without one (an event's worth is 6 MB on a 7-hour log)
    heights = np.full(ev.t.size if kinds.any() else 0, np.nan)
    for k in np.flatnonzero(kinds):
        heights[k] = first_height(ev.who, ev.z, int(k), ev.h0)
    return kinds, reset_states(layout), heights


def _dynamics(
    ev: Events, layout: Layout
) -> tuple[FloatArray, FloatArray, FloatArray, Structure, np.ndarray]:
    """The events' accelerations and process-noise densities, and F's structure
    (:data:`.model.Structure`) and its entries off the diagonal, as the kernels take them.
    An event of the output's clock alone takes its model interval's sensor densities
    (``ev.model``); its acceleration and white-noise density are its interval's as made
    (:func:`.events.on_every_event`)."""
    q_state = ev.q_state
    if ev.model is not None and q_state.shape[0] > 1:
        q_state = q_state[model_intervals(ev.model)]
    q_state = np.ascontiguousarray(q_state, dtype=np.float64)
    structure = layout.structure(ev.use_bias)
    return ev.a, ev.q_accel, q_state, structure, couplings(ev.use_bias, structure[1])


#: A filter's whole state between two events (:func:`_carry`): ``x``, ``P``, per state its
#: sensor's last accepted sample [s] and that one's variance, its last rejection [s], its side,
#: its first rejection since the last accepted sample of any sensor [s] and the event of its
#: first since its own; per state the sums of its accepted samples' ``y / S`` and ``1 / S``
#: (:func:`_leaning`), then each state's sums at its sensor's first rejection since its own
#: last accepted sample; and the clocks (the last event's time, the last accepted sample's, the
#: holds so far, the first height rejected since that sample: its event, -1 none).
Carry = tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]
#: The same at every checkpoint: each with a leading axis.
Checkpoints = tuple[
    FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray
]
#: Per sample: the gain on h, whether it passed the gate, its log-likelihood, its normalised
#: innovation and whether the height was let loose for the rejections it began.
Verdicts = tuple[FloatArray, np.ndarray, FloatArray, FloatArray, np.ndarray]
#: What the backward pass needs of a block's events (:func:`_kept`).
Kept = tuple[FloatArray, FloatArray, FloatArray, FloatArray]
#: Two blocks' worth of records (:func:`_forward`, :func:`_refilter`).
Buffers = tuple[Kept, Kept]
#: The filter's arguments: the events' measurements, dynamics and holds on the ground, the gate,
#: the prior and the splices' resets (:func:`_forward`).
Model = tuple[
    tuple[FloatArray, np.ndarray, FloatArray, FloatArray, Rows],
    tuple[FloatArray, FloatArray, FloatArray, Structure, np.ndarray],
    tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    float,
    tuple[FloatArray, FloatArray, np.ndarray, np.ndarray, FloatArray],
]
#: The arrays a pass's loops work in (:func:`_arena`): F, Q, B u, the steps' scratch, an event's
#: row of H, state and covariance, and the rows of H of h, v and the wash.
Arena = tuple[
    Transition, FloatArray, FloatArray, Scratch, FloatArray, FloatArray, FloatArray, FloatArray
]


@compiled
def _forward(
    model: Model, block: int, keep: bool, judged: tuple[bool, bool, bool, bool]
) -> tuple[FloatArray, Checkpoints, Verdicts, tuple[Buffers, int]]:
    """The forward filter over every event (:func:`_filter`): its state after the last, its
    whole state before every ``block``-th event (the backward pass runs it again from there),
    per sample whether it passed the gate and, where ``judged`` says (else empty), its gain on
    h, its log-likelihood, its normalised innovation ``y / sqrt(S)`` and whether the height was
    let loose for the rejections it began; and two buffers for the backward pass to filter a
    block again into (:func:`_refilter`), of a block's size with ``keep`` (else of one event),
    the last block's records already in its own (a flight of one block is filtered once), and
    how many of its events were held on the ground.

    ``model``: the events' times, series (:mod:`.events`), values, variances and rows of H;
    their dynamics: the mean acceleration over the interval ending at each event, the white
    acceleration density there, the sensor states' densities, F's structure and its entries
    off the diagonal; the events held at the datum (h = 0 and v = 0) and standing elsewhere
    on the ground (v = 0), and those at which the height is let loose early (empty: none); the
    gate; the prior, and per event the row of the states (row 0: none) that return to it there
    (a splice) and the height they return to.
    """
    t, who = model[0][0], model[0][1]
    count, n = t.size, model[4][0].size
    carry = _carry(model[4], t, who, n)
    blocks = -(-count // block)
    checkpoints = (
        np.zeros((blocks, n)), np.zeros((blocks, n, n)), np.zeros((blocks, n)),
        np.zeros((blocks, n)), np.zeros((blocks, n, 4)), np.zeros((blocks, n, 2 + 2 * n)),
        np.zeros((blocks, 4)),
    )  # fmt: skip
    verdicts = (
        np.zeros(count if judged[0] else 0), np.zeros(count, dtype=np.bool_),
        np.full(count if judged[1] else 0, np.nan), np.full(count if judged[2] else 0, np.nan),
        np.zeros(count if judged[3] else 0, dtype=np.bool_),
    )  # fmt: skip
    size = min(count, block) if keep else 1  # else only a hold's scratch
    buffers = (_kept(size, n, size), _kept(size, n, size))
    held = 0
    for b in range(blocks):
        _save(carry, checkpoints, b)
        span = (b * block, min((b + 1) * block, count))
        held = _held(model, span, carry, (buffers[b % 2], keep and b == blocks - 1), verdicts)
    return carry[0], checkpoints, verdicts, (buffers, held)


@compiled
def _carry(
    start: tuple[FloatArray, FloatArray, np.ndarray, np.ndarray, FloatArray],
    t: FloatArray,
    who: np.ndarray,
    n: int,
) -> Carry:
    """The filter's state (:data:`Carry`) before the first event: the prior; per state its
    sensor's first sample as its last accepted one, no variance, no rejection, no sums."""
    return (
        start[0].copy(),
        start[1].copy(),
        _first_samples(t, who, n),
        np.full(n, np.inf),
        np.full((n, 4), np.nan),
        np.zeros((n, 2 + 2 * n)),
        np.array([t[0], t[0], 0.0, -1.0]),
    )


@compiled
def _save(carry: Carry, checkpoints: Checkpoints, b: int) -> None:
    """The filter's state ``carry`` into checkpoint ``b``."""
    checkpoints[0][b], checkpoints[1][b], checkpoints[2][b] = carry[0], carry[1], carry[2]
    checkpoints[3][b], checkpoints[4][b], checkpoints[5][b] = carry[3], carry[4], carry[5]
    checkpoints[6][b] = carry[6]


@compiled
def _restored(checkpoints: Checkpoints, b: int) -> Carry:
    """The filter's state at checkpoint ``b``, a copy."""
    return (
        checkpoints[0][b].copy(), checkpoints[1][b].copy(), checkpoints[2][b].copy(),
        checkpoints[3][b].copy(), checkpoints[4][b].copy(), checkpoints[5][b].copy(),
        checkpoints[6][b].copy(),
    )  # fmt: skip


@compiled_loop
def _filter(  # noqa: C901, PLR0915 (one loop: its steps as a helper taking tuples ran 2.4x slower)
    model: Model,
    span: tuple[int, int],
    carry: Carry,
    kept: tuple[Kept, bool],
    verdicts: Verdicts,
    arena: Arena,
) -> None:
    """The forward filter over the events ``span[0]`` to ``span[1] - 1`` from its state
    ``carry`` (updated in place), each sample's verdicts into ``verdicts``; with ``kept[1]``,
    what the backward pass needs of each event into ``kept[0]``, from its first slot: the
    posterior state and covariance, the sample's ``P H'``, ``S`` and innovation (``S`` 0 where
    it was not fused), and per event held on the ground the same of its holds. ``model``:
    :func:`_forward`'s arguments; ``arena``: the arrays it works in (:func:`_arena`)."""
    (t, who, z, r, rows), (a, q_accel, q_state, structure, _), marks = model[:3]
    still, landed, early, cleared = marks
    gate, start = model[3], model[4]
    x, p, sensor_accepted, sensor_r, refused, support, clock = carry
    (xf, pf, updates, holds), keep = kept
    gain_h, accepted, loglik, nu, released = verdicts
    reset, returning = start[2], start[3]
    n = x.size
    previous, last_accepted, held, episode = clock[0], clock[1], int(clock[2]), int(clock[3])
    first_held = held
    fl, q, u, work, hk, _, _, unit = arena
    ph = work[4]  # an event's P H' (and hk its row of H)
    y = s = 0.0
    for k in range(span[0], span[1]):
        dt = t[k] - previous
        previous = t[k]
        if dt > 0:
            # the accelerometer as the control input: B u = [a dt^2 / 2, a dt, 0, ...]
            u[0], u[1] = 0.5 * a[k] * dt * dt, a[k] * dt
            transition(fl[0], dt, structure)
            q_row = q_state[min(k, q_state.shape[0] - 1)]
            process_noise(q, dt, q_accel[k], q_row, structure, wash_noise(t[k], structure))
            predict(x, p, fl, q, u, work)
        if reset[k] > 0:
            # a splice: part of the state returns to the prior (h and v in every row), h at
            # the segment's own first guess
            restart(x, p, (start[0], start[1]), returning[reset[k]])
            x[0] = start[4][k]
        i = who[k]
        slot = k - span[0]
        if keep:
            updates[slot, n] = 0.0  # S 0: no sample fused here (a slot is used again)
        if i != TICK:
            measurement_row(rows, i, k, hk)
            y, s = innovation(x, p, z[k], hk, r[k], ph)
            # a height shut: has the estimate, or a ground, gone astray? (a vertical velocity
            # is gated too, and never a reason to let loose: it says nothing of h)
            if i >= 0 and y * y > gate * gate * s:
                if episode < 0:  # the first height rejected since the last accepted
                    episode = k
                if not refused[3 + i, 0] > last_accepted:  # its first since then
                    refused[3 + i, 2] = t[k]
                if not refused[3 + i, 0] > sensor_accepted[3 + i]:  # its first since its own
                    refused[3 + i, 3] = k
                    for j in range(n):  # every state's sums so far
                        support[3 + i, 2 + 2 * j] = support[j, 0]
                        support[3 + i, 3 + 2 * j] = support[j, 1]
                refused[3 + i, 0], refused[3 + i, 1] = t[k], math.copysign(1.0, y)
                seen = (t[k], r[k], s, hk[3 + i], last_accepted, sensor_accepted, sensor_r)
                let = _release(3 + i, y, (seen, refused, support), p, early.size > 0 and early[k])
                if let:  # the innovation is the same, its variance grown
                    y, s = innovation(x, p, z[k], hk, r[k], ph)
                if released.size and let in (LET_AGREED, LET_LEANT):
                    # the next pass lets the height loose at the episode's first rejection:
                    # of any sensor, or where another leant with it, of this one
                    released[episode if let == LET_AGREED else int(refused[3 + i, 3])] = True
            if nu.size:
                nu[k] = y / math.sqrt(s)
        # the innovation gate: |y| <= gate sqrt(S)
        if i != TICK and y * y <= gate * gate * s:
            if keep:
                assign(updates[slot, :n], ph)
                updates[slot, n], updates[slot, n + 1] = s, y
            gain = update(x, p, y, s, ph)
            if gain_h.size:
                gain_h[k] = abs(gain)
            accepted[k] = True
            if i >= 0:  # a height: the lockout's clocks
                last_accepted = sensor_accepted[3 + i] = t[k]
                episode = -1
                sensor_r[3 + i] = r[k]
                support[3 + i, 0] += y / s
                support[3 + i, 1] += 1.0 / s
            if loglik.size:  # log N(y; 0, S)
                loglik[k] = -0.5 * (math.log(2 * math.pi * s) + y * y / s)
        if still[k] or landed[k] or cleared[k]:
            pins = (still[k], still[k] or landed[k], cleared[k])
            hold(x, p, holds[held - first_held if keep else 0], pins, unit)
            held += 1
        if keep:
            assign(xf[slot], x)
            pack(p, pf[slot])
    clock[0], clock[1], clock[2], clock[3] = previous, last_accepted, held, episode


@compiled
def _first_samples(t: FloatArray, who: np.ndarray, n: int) -> FloatArray:
    """Per state: the time of its sensor's first sample [s]; NaN for the other states."""
    first = np.full(n, np.nan)
    for k in range(t.size - 1, -1, -1):
        if who[k] >= 0:
            first[3 + who[k]] = t[k]
    return first


@compiled
def _kept(kept: int, n: int, held: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """What :func:`_forward` keeps for the backward pass: ``kept`` states and covariances, the
    ``P H'``, ``S`` and ``y`` of ``kept`` events' samples and of ``held`` events' three holds
    (:func:`.model.hold`)."""
    states, covariances = np.zeros((kept, n)), np.zeros((kept, n * (n + 1) // 2))
    return states, covariances, np.zeros((kept, n + 2)), np.zeros((held, 3, n + 2))


@compiled_step
def _agreed(c: int, y: float, seen: tuple[float, FloatArray, FloatArray]) -> int:
    """Whether another sensor than state ``c``'s was rejected on the side of the innovation
    ``y`` since the last accepted sample: AGREED_TOGETHER where one the estimate followed
    until then was, its rejections beginning within AGREED_LOCKOUT_S of ``c``'s; AGREED where
    only others were; else 0. ``seen``: the last accepted sample's time, per state its
    sensor's last accepted sample [s], and its rejections (:data:`Carry`, ``c``'s present one
    among them)."""
    last_accepted, accepted, refused = seen
    first = refused[c, 2]
    agreed = 0
    for j in range(3, refused.shape[0]):
        if j != c and refused[j, 0] > last_accepted and refused[j, 1] * y > 0.0:
            if (
                accepted[j] >= last_accepted - LOCKOUT_S
                and abs(refused[j, 2] - first) <= AGREED_LOCKOUT_S
            ):
                return AGREED_TOGETHER
            agreed = AGREED
    return agreed


@compiled_step
def _leaning(
    c: int, innovation: tuple[float, float], now: float, accepted: FloatArray, support: FloatArray
) -> int:
    """LEANT where a sensor other than state ``c``'s, accepted within AGREED_LOCKOUT_S, leans
    with ``c``'s rejected sample (its innovation ``y`` and the variance ``S`` of it): over
    ``c``'s rejections since its own last accepted sample, the other's accepted innovations
    have a mean beyond LEAN_SIGMAS of its standard error on ``y``'s side, and within
    LEAN_SIGMAS of ``y``; else 0. ``accepted``: per state its sensor's last accepted sample
    [s]; ``support``: :data:`Carry`'s sums.

    Where the estimate holds, each accepted innovation is ``N(0, S)``: the information-weighted
    mean ``sum(y / S) / sum(1 / S)`` has the variance ``1 / sum(1 / S)``. Where it has gone
    astray by ``d``, every sensor's innovations lean by ``d``: a barometer too noisy to fail the
    gate says so over a handful of samples (a PX4 simulator's landing the logged IMU missed:
    the estimate 0.18 m under a GPS and a barometer for 3 s, the GPS rejected throughout, the
    barometer's samples passing, ``fused_std`` 0.024 m; now 0.12 m at most, on them again 0.6 s
    after the touchdown)."""
    y, s = innovation
    for j in range(3, accepted.size):
        if j == c or now - accepted[j] > AGREED_LOCKOUT_S:
            continue
        # the other's sums over c's episode of rejections
        total = support[j, 0] - support[c, 2 + 2 * j]
        weight = support[j, 1] - support[c, 3 + 2 * j]
        if weight <= 0.0:
            continue
        mean = total / weight
        leans = math.copysign(1.0, y) * mean * math.sqrt(weight) > LEAN_SIGMAS
        if leans and (y - mean) ** 2 <= LEAN_SIGMAS**2 * (s + 1.0 / weight):
            return LEANT
    return 0


@compiled_step
def _silent(now: float, last_accepted: float, accepted: FloatArray, refused: FloatArray) -> bool:
    """Whether every sensor the estimate followed until the last accepted sample (``accepted``,
    per state its sensor's last accepted sample [s], within LOCKOUT_S of ``last_accepted``)
    has given no sample, accepted or rejected (``refused[:, 0]``), for LOCKOUT_S."""
    for j in range(3, accepted.size):
        if accepted[j] >= last_accepted - LOCKOUT_S:
            heard = (
                max(accepted[j], refused[j, 0]) if not math.isnan(refused[j, 0]) else accepted[j]
            )
            if now - heard <= LOCKOUT_S:
                return False
    return True


@compiled_step
def _release(
    c: int,
    y: float,
    seen: tuple[
        tuple[float, float, float, float, float, FloatArray, FloatArray], FloatArray, FloatArray
    ],
    p: FloatArray,
    early: bool,
) -> int:
    """A sample of the sensor with state ``c`` fails the gate by the innovation ``y``: let
    loose what has gone astray, in place on the prior's covariance ``p``, and say what was
    (LET_NOTHING, LET_LOST, LET_AGREED, LET_GROUND, LET_LEANT). ``seen``: the sample's time,
    variance and innovation's variance ``S``, its row of H at ``c``, the last accepted sample's
    time, per state its sensor's last accepted sample [s] and that one's variance; and per
    state its sensor's rejections and its accepted samples' sums (:data:`Carry`, this one
    among them). ``early``: the sample began an episode of rejections that a pass before
    ended by letting the height loose where two sensors left it together (or this one left it
    and another leant its way): it is let loose here, at the episode's first rejection, where
    its sensor was followed (the episode's samples then count: a landing the logged IMU missed
    left the smoothed height 0.6 m under its sensors for the 1.2 s they were rejected, its band
    0.09 m)."""
    (now, r, s, sign, last_accepted, sensor_accepted, sensor_r), refused, support = seen
    y2 = y * y
    waited = now - last_accepted
    # only a sensor the estimate followed until it went astray can say where it went: one
    # rejected since long before (a GPS 15 m off the barometer for 130 s) is astray itself,
    # unless every sensor followed has gone silent (a barometer lost): it is all there is
    followed = sensor_accepted[c] >= last_accepted - LOCKOUT_S or _silent(
        now, last_accepted, sensor_accepted, refused
    )
    agreed = 0
    if waited > AGREED_LOCKOUT_S:
        agreed = _agreed(c, y, (last_accepted, sensor_accepted, refused))
    if not agreed and followed and now - sensor_accepted[c] > AGREED_LOCKOUT_S:
        agreed = _leaning(c, (y, s), now, sensor_accepted, support)
    if followed and (early or agreed or waited > LOCKOUT_S):
        # no sample of any sensor passed the gate for LOCKOUT_S, or for AGREED_LOCKOUT_S where
        # two sensors failed it on one side, or one failed it and another leant its way: the
        # estimate, not every sensor, has gone astray
        # (ArduPilot's EKF3 resets its height after 5 s); its height and velocity become as
        # uncertain as this sample says. Two sensors agreeing against a confident estimate
        # for 2.5 s left it 1.4 m under both after a PX4 simulator's landing (the touchdown
        # absent from the logged IMU)
        p[0, 0] += y2
        p[1, 1] += y2 / LOCKOUT_S**2
        if agreed == LEANT and not early:
            return LET_LEANT
        return LET_AGREED if early or agreed == AGREED_TOGETHER else LET_LOST
    if sign < 0.0 and now - sensor_accepted[c] > LOCKOUT_S:
        # a rangefinder alone has failed the gate for LOCKOUT_S while a sensor at least as
        # precise passed (the estimate holds): the ground under it has stepped (an edge, a
        # roof); its ground height, not h, becomes as uncertain as this sample says. Where
        # only less precise sensors held the estimate, a rangefinder back from a dropout
        # followed the estimate's drift instead of correcting it (Paper A: 0.138 -> 0.170 m).
        for j in range(3, sensor_r.size):
            if j != c and now - sensor_accepted[j] <= LOCKOUT_S and sensor_r[j] <= r:
                p[c, c] += y2
                return LET_GROUND
    return LET_NOTHING


def _backward(
    model: Model,
    forward: tuple[Checkpoints, tuple[Buffers, int]],
    verdicts: Verdicts,
    passes: tuple[int, bool],
    kept_of: tuple[np.ndarray, Keep],
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The smoothed (or, without ``smooth``, the filtered) states at every event, the variance
    of ``h``, and each sample's own row ``H x`` and its variance (NaN at a tick), as much of
    them as ``kept_of`` says (the states' indices, and :class:`Keep`): back over the blocks of
    :func:`_forward`, last first, each one filtered again from its checkpoint (the same steps
    on the same numbers: the same result) and then gone back through (:func:`_back`).

    Keeping what the backward pass needs of every event (its state, covariance and updates)
    cost 280 bytes an event with six states: 222 MB, the peak of a 7.4-hour log's run; a
    block's is ``block`` (``passes[0]``, :func:`_forward`'s) times that, for one more forward
    pass, run in a thread a block ahead of the backward one (two cores: about the time it
    cost before). ``passes[1]``: whether to smooth. ``model``: :func:`_forward`'s arguments,
    ``forward`` its checkpoints and buffers."""
    (t, who, _, _, rows), dynamics, (still, landed, _, cleared) = model[:3]
    block, smooth = passes
    # a block is filtered again into one buffer while the pass goes back through the other
    checkpoints, (buffers, last_held) = forward
    count, n = t.size, model[4][0].size
    blocks = checkpoints[0].shape[0]
    events = (t, who, rows, still | landed | cleared, model[4][2:4])
    states, keep = kept_of
    kept = int(np.count_nonzero(who == TICK)) if keep.ticks else count
    smoothed = (
        np.zeros((kept, states.size)), np.zeros(kept if keep.var_h else 0),
        np.full(count if keep.rows else 0, np.nan), np.full(count if keep.rows else 0, np.nan),
    )  # fmt: skip
    # with ticks, the row of the next tick back (the backward pass goes from the last)
    at = (states, keep.ticks, np.array([kept]))
    adjoint = (np.zeros(n), np.zeros((n, n)))  # after the last event: nothing to come

    def refilter(b: int) -> tuple[tuple[int, int], Kept, int]:
        span = (b * block, min((b + 1) * block, count))
        buffer = buffers[b % 2]
        return span, buffer, _refilter(model, (checkpoints, b), verdicts, span, buffer)

    # the last block as the forward pass kept it
    span = ((blocks - 1) * block, count)
    filtered = (span, buffers[(blocks - 1) % 2], last_held)
    arena = _arena(n, dynamics)  # the refilter's own are its _held's
    with ThreadPoolExecutor(1, thread_name_prefix="altfuse-pass") as pool:
        for b in range(blocks - 1, -1, -1):
            ahead = pool.submit(refilter, b - 1) if b else None
            _back(events, filtered, dynamics, adjoint, (smoothed, smooth, at), arena)
            if ahead is not None:
                filtered = ahead.result()
    return smoothed


@compiled_step
def _kept_row(k: int, tick: bool, ticks: bool, cursor: np.ndarray) -> int:
    """The row event ``k``'s smoothed state is kept in: its own, or with ``ticks`` the next
    from the end (``cursor[0]``, counted down) at a tick and none (-1) elsewhere."""
    if not ticks:
        return k
    if not tick:
        return -1
    cursor[0] -= 1
    return int(cursor[0])


@compiled_step
def _row_value(h: FloatArray, x: FloatArray) -> float:
    """``H x`` of a row ``h``, its entries in order, those that are 0 left out (a lost state's
    NaN stays out, as in the row of a sensor it is not)."""
    value = 0.0
    for i in range(h.size):
        if h[i] != 0.0:
            value += h[i] * x[i]
    return value


@compiled
def _refilter(
    model: Model,
    checkpoint: tuple[Checkpoints, int],
    verdicts: Verdicts,
    span: tuple[int, int],
    kept: Kept,
) -> int:
    """The events of ``span`` filtered again from their block's checkpoint (``checkpoint``:
    the checkpoints and the block's), what the backward pass needs of them into ``kept``;
    how many were held on the ground."""
    return _held(model, span, _restored(*checkpoint), (kept, True), verdicts)


@compiled
def _held(
    model: Model, span: tuple[int, int], carry: Carry, kept: tuple[Kept, bool], verdicts: Verdicts
) -> int:
    """:func:`_filter` over ``span``; how many of its events were held on the ground."""
    first_held = int(carry[6][2])
    _filter(model, span, carry, kept, verdicts, _arena(carry[0].size, model[1]))
    return int(carry[6][2]) - first_held


@compiled
def _arena(
    n: int, dynamics: tuple[FloatArray, FloatArray, FloatArray, Structure, np.ndarray]
) -> Arena:
    """The arrays the loops of a pass over ``n`` states work in (:data:`Arena`), F's entries
    off the diagonal and its decaying states from ``dynamics`` (:data:`Model`'s)."""
    unit = np.zeros((3, n))  # the rows of H of h, v and the wash (:func:`.model.hold`)
    unit[0, 0] = unit[1, 1] = 1.0
    if dynamics[3][5][0] >= 0:
        unit[2, dynamics[3][5][0]] = 1.0
    fl: Transition = (np.eye(n), dynamics[4], dynamics[3][2])
    q, u, hk, xk, p = np.zeros((n, n)), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros((n, n))
    return fl, q, u, scratch(n), hk, xk, p, unit


@compiled_loop
def _back(  # noqa: C901 (one loop: as _filter's, its steps as a helper ran 1.7x slower)
    events: tuple[FloatArray, np.ndarray, Rows, np.ndarray, tuple[np.ndarray, np.ndarray]],
    filtered: tuple[tuple[int, int], Kept, int],
    dynamics: tuple[FloatArray, FloatArray, FloatArray, Structure, np.ndarray],
    adjoint: tuple[FloatArray, FloatArray],
    out: tuple[
        tuple[FloatArray, FloatArray, FloatArray, FloatArray],
        bool,
        tuple[np.ndarray, bool, np.ndarray],
    ],
    arena: Arena,
) -> None:
    """The modified Bryson-Frazier pass (:mod:`.kalman`) back over one block of filtered
    events, into ``out``'s states and variances; the adjoint (``lambda``, ``Lambda``) carried
    in from the events after the block and out to those before it, in place. Without
    ``out[1]`` (smooth) the adjoint stays 0: the filtered states and variances. ``out[2]``:
    the states kept, whether at the ticks only (each a row of ``out[0][0]`` and of h's
    variances, the last first from ``cursor[0]``, counted down, else every event's), and
    ``cursor``; an empty output array is not written.

    ``events``: the events' times, series, rows of H, which were held on the ground, and per
    event the row of the states that returned to the prior there, and those rows;
    ``filtered``: the block's span, :func:`_filter`'s records of it and its count of events
    held; ``arena``: the arrays it works in (:func:`_arena`). The covariances are left
    filtered: only the variances asked for are made of the smoothed ones."""
    t, who, rows, held_at, resets = events
    span, (xf, pf, updates, holds), held = filtered
    (xs, var_h, hx, var_row), smooth, (states, ticks, cursor) = out
    structure = dynamics[3]
    n = xf.shape[1]
    # each event's row of H, smoothed state and filtered covariance (unpacked) in the arena's
    fl, _, _, work, hk, xk, p, unit = arena
    lam = adjoint[0]
    for k in range(span[1] - 1, span[0] - 1, -1):
        slot = k - span[0]
        unpack(pf[slot], p)
        row = _kept_row(k, who[k] == TICK, ticks, cursor)
        # smoothed at k: x_s = x - P lambda;  var = H P H' - (P H')' Lambda (P H')
        if row >= 0 and var_h.size:
            var_h[row] = smoothed_variance(p, adjoint[1], unit[0], work)
        if who[k] != TICK:
            measurement_row(rows, who[k], k, hk)
            if var_row.size:
                var_row[k] = smoothed_variance(p, adjoint[1], hk, work)
        for i in range(n):
            total = 0.0
            for j in range(n):
                total += p[i, j] * lam[j]
            xk[i] = xf[slot, i] - total
        if row >= 0:
            for c in range(states.size):
                xs[row, c] = xk[states[c]]
        if hx.size and who[k] != TICK:
            hx[k] = _row_value(hk, xk)
        if not smooth:
            continue
        # back through the event's updates, last first: its holds, then its sample
        if held_at[k]:
            held -= 1
            for j in (2, 1, 0):
                record = holds[held, j]
                if record[n] > 0.0:  # S 0: no hold of this state here
                    adjoint_update(adjoint, unit[j], (record[:n], record[n], record[n + 1]), work)
        if updates[slot, n] > 0.0:
            record = updates[slot]
            adjoint_update(adjoint, hk, (record[:n], record[n], record[n + 1]), work)
        if resets[0][k] > 0:  # the states that returned to the prior owe nothing to before
            adjoint_restart(adjoint, resets[1][resets[0][k]])
        # and through the transition into k
        dt = t[k] - t[k - 1] if k > 0 else 0.0
        if dt > 0:
            transition(fl[0], dt, structure)
            adjoint_predict(adjoint, fl, work)
