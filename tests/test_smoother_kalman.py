"""The smoother's Kalman and Rauch-Tung-Striebel passes against filterpy's (issue 15, item 8).

A linear-Gaussian toy with the smoother's own state layout (height, velocity, accelerometer
bias, two sensor offsets, the GPS's bounded, a barometer's scale error and drift rate),
irregular event times, one
scalar measurement of either sensor per event or none (a clock tick), the first events on the
ground (h = 0 and v = 0 held there) and the last landed elsewhere (v = 0 alone), no gate:
:func:`passes.run` must give filterpy's ``KalmanFilter.batch_filter`` and ``rts_smoother`` to
1e-9, in the states and in the variances it reports (of h at every event, of a sample's own row
``H x``). filterpy's smoother is Rauch-Tung-Striebel's, ours the modified Bryson-Frazier form
of the same estimate.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter, rts_smoother

from altfuse.fuse.smoother.events import TICK
from altfuse.fuse.smoother.evidence import HEIGHTS
from altfuse.fuse.smoother.model import (
    BARO_SHARED,
    GPS_CORRELATION_S,
    Q_DRIFT,
    RESET_DATUM,
    RESET_NONE,
    STILL_SIGMA,
    Events,
    Layout,
    Regressor,
    couplings,
    first_height,
    measurement_row,
    measurement_rows,
    prior,
    process_noise,
    reset_states,
    transition,
    wash_noise,
)
from altfuse.fuse.smoother.passes import FOR_EM, FOR_RESULT, Keep, likelihood, likelihoods, run

M = 2  # sensors: a GPS (its offset bounded) and a barometer, the barometer with a drift rate


def toy(
    seed: int, accel: bool, spliced: bool = False, count: int = 300, washed: bool = False
) -> tuple[Events, Layout, np.ndarray]:
    """Events of a simulated flight, the layout, and each event's measurement variance; with
    ``spliced``, a splice at event 150 (motion, offsets and drift rate back to the prior); with
    ``washed``, the barometer 0.4 m low in a wash over events 30-90 (its random walk's own
    density there, held to 0 at the first tick after)."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.01, 0.2, count))
    t[5] = t[4]  # two events at one instant: no prediction between them
    who = rng.integers(-1, M, count)
    truth = 3 * np.sin(t / 4)
    r = rng.uniform(0.05, 0.5, count) ** 2
    z = np.where(who >= 0, truth + (who == 1) * 0.3 + rng.normal(0, np.sqrt(r)), np.nan)
    span = np.zeros(count, dtype=bool)
    span[30:90] = washed
    z[span & (who == 1)] -= 0.4
    a = -3 / 16 * np.sin(t / 4) + rng.normal(0, 0.1, count) if accel else np.zeros(count)
    q_state = np.tile([0.01, 1e-4], (count, 1))
    cleared = np.zeros(count, dtype=bool)
    cleared[90 + int(np.argmax(who[90:] == TICK))] = washed
    still = np.zeros(count, dtype=bool)
    still[:20] = who[:20] == -1  # ticks on the ground at the datum
    landed = np.zeros(count, dtype=bool)
    landed[-count // 10 :] = who[-count // 10 :] == -1  # on the ground after landing: v = 0 alone
    q_accel = np.full(count, 0.05)
    reset = np.zeros(count, dtype=np.int64)
    reset[150] = RESET_DATUM if spliced else RESET_NONE
    events = Events(
        t, who, z, a, q_state, still, q_accel, True, np.inf, float(z[who >= 0][0]), landed,
        reset,
    )  # fmt: skip
    scale = Regressor("scale", 1, np.where(who == 1, truth, 0.0), 0.02)
    layout = Layout(np.ones(M), (scale,), drifting=(1,), bounded=(0,))
    if washed:  # its random walk over the intervals that end at events 30-89
        layout = replace(layout, shared=(1,), wash_spans=((float(t[29]), float(t[89])),))
    return replace(events, cleared=cleared), layout, r


def filterpy_passes(
    ev: Events, layout: Layout, r: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """filterpy's filtered and smoothed means and covariances over the same events (an event on
    the ground: its step, then the two holds as steps of their own with no time between)."""
    n, structure = layout.n, layout.structure(ev.use_bias)
    dts = np.diff(ev.t, prepend=ev.t[0])
    x0, p0 = prior(ev, layout)
    steps = []  # per filterpy step: (event, F, Q, u, H row, z, R)
    for k, dt in enumerate(dts):
        f, q = np.eye(n), np.zeros((n, n))
        transition(f, dt, structure)
        process_noise(
            q, dt, ev.q_accel[k], ev.q_state[k], structure, wash_noise(ev.t[k], structure)
        )
        u = np.array([[0.5 * ev.a[k] * dt * dt], [ev.a[k] * dt]])
        if ev.reset is not None and ev.reset[k]:
            # the prediction alone, then the splice: F = 0 and Q the prior's on the states
            # that return to it, their prior mean through the input (h's, from the segment's
            # first samples; the rest is 0)
            steps.append((k, f, q, u, np.zeros((1, n)), None, 1.0))
            back = reset_states(layout)[ev.reset[k]]
            f = np.diag(np.where(back, 0.0, 1.0))
            q = np.where(np.outer(back, back), p0, 0.0)
            h_guess = first_height(ev.who, ev.z, k, ev.h0)
            u = np.array([[h_guess if back[0] else 0.0], [x0[1] if back[1] else 0.0]])
        row = np.zeros((1, n))
        i = ev.who[k]
        if i >= 0:
            row[0, 0] = 1.0
            row[0, 3 + i] = 1.0
        if i == 1:  # the barometer's scale error, times its height, and its wash
            row[0, 3 + M] = layout.regressors[0].coef[k]
            if layout.washed:
                row[0, layout.wash] = 1.0
        steps.append((k, f, q, u, row, np.array([ev.z[k]]) if i >= 0 else None, r[k]))
        assert ev.landed is not None
        assert ev.cleared is not None
        held = [0, 1] if ev.still[k] else [1] if ev.landed[k] else []
        for j in held + ([layout.wash] if ev.cleared[k] else []):
            hold = np.zeros((1, n))
            hold[0, j] = 1.0
            steps.append((k, np.eye(n), np.zeros((n, n)), np.zeros((2, 1)), hold, np.zeros(1),
                          STILL_SIGMA**2))  # fmt: skip
    kf = KalmanFilter(dim_x=n, dim_z=1, dim_u=2)
    kf.P = p0
    kf.x = x0.reshape(n, 1)
    fs, qs = [st[1] for st in steps], [st[2] for st in steps]
    xf, pf, _, _ = kf.batch_filter(
        [st[5] for st in steps],
        Fs=fs,
        Qs=qs,
        Hs=[st[4] for st in steps],
        Rs=[np.array([[st[6]]]) for st in steps],
        Bs=[np.vstack([np.eye(2), np.zeros((n - 2, 2))])] * len(steps),
        us=[st[3] for st in steps],
    )
    xf = xf.reshape(-1, n)
    # filterpy's smoother steps k -> k + 1 with Fs[k] and no control input
    xs, ps, _, _ = rts_smoother(xf.copy(), pf.copy(), [*fs[1:], np.eye(n)], [*qs[1:], qs[0]])
    last = np.array([max(s for s, st in enumerate(steps) if st[0] == k) for k in range(dts.size)])
    return xf[last], pf[last], xs[last], ps[last]


def variances(ev: Events, layout: Layout, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Of covariances ``p`` per event: h's variance, and each sample's row's (NaN at ticks)."""
    rows = measurement_rows(layout, ev.who)
    h = np.zeros((ev.who.size, layout.n))
    for k, series in enumerate(ev.who):
        measurement_row(rows, int(series), k, h[k])
    return p[:, 0, 0], np.where(ev.who >= 0, np.einsum("ki,kij,kj->k", h, p, h), np.nan)


def assert_matches(ours: dict[str, np.ndarray], ev: Events, layout: Layout, x, p) -> None:  # type: ignore[no-untyped-def]
    var_h, var_row = variances(ev, layout, p)
    np.testing.assert_allclose(ours["x"], x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours["var_h"], var_h, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours["var_row"], var_row, rtol=0, atol=1e-9)


@pytest.mark.parametrize(("spliced", "washed"), [(False, False), (True, False), (False, True)])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_forward_filter_is_filterpys_kalman_filter(seed: int, spliced: bool, washed: bool) -> None:
    ev, layout, r = toy(seed, accel=True, spliced=spliced, washed=washed)
    ours = run(ev, r, layout, smooth=False)
    xf, pf, _, _ = filterpy_passes(ev, layout, r)
    assert ours["accepted"][ev.who >= 0].all()
    assert ev.still.sum() >= 3
    assert ev.landed is not None
    assert ev.landed.sum() >= 3
    assert_matches(ours, ev, layout, xf, pf)


@pytest.mark.parametrize(("spliced", "washed"), [(False, False), (True, False), (False, True)])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_smoother_is_filterpys_rts_smoother(seed: int, spliced: bool, washed: bool) -> None:
    # filterpy's rts_smoother takes no control input: the toy's accelerometer reads 0
    ev, layout, r = toy(seed, accel=False, spliced=spliced, washed=washed)
    ours = run(ev, r, layout)
    _, _, xs, ps = filterpy_passes(ev, layout, r)
    assert_matches(ours, ev, layout, xs, ps)
    if washed:  # the barometer's wash found where it was, and 0 where it was held
        wash = ours["x"][:, layout.wash]
        assert ev.cleared is not None
        assert wash[30:90].mean() < -0.02
        np.testing.assert_allclose(wash[ev.cleared], 0.0, atol=3 * STILL_SIGMA)
        np.testing.assert_allclose(wash[:30], 0.0, atol=3 * STILL_SIGMA)
    # and smoothing did something: the first state moved from its filtered value
    filtered = run(ev, r, layout, smooth=False)
    assert np.abs(ours["x"][0] - filtered["x"][0]).max() > 1e-3


def test_passes_over_many_blocks_are_filterpys() -> None:
    # the backward pass filters each block again from its checkpoint: four blocks, the span
    # on the ground at the end across the last block's start
    ev, layout, r = toy(3, accel=False, spliced=True, count=1000)
    block = 320
    assert ev.landed is not None
    assert ev.landed[: 3 * block].any()
    assert ev.landed[3 * block :].any()
    xf, pf, xs, ps = filterpy_passes(ev, layout, r)
    assert_matches(run(ev, r, layout, smooth=False, block=block), ev, layout, xf, pf)
    assert_matches(run(ev, r, layout, block=block), ev, layout, xs, ps)


@pytest.mark.parametrize("smooth", [True, False])
def test_blocks_change_nothing(smooth: bool) -> None:
    # a gate that rejects samples and lets the estimate loose (whose clocks the checkpoints
    # carry) and holds on the ground: every output the same to the bit whatever the block
    ev, layout, r = toy(4, accel=True, spliced=True, count=3000)
    ev = replace(ev, gate=1.5)
    whole = run(ev, r, layout, smooth, block=ev.t.size)
    assert (~whole["accepted"][ev.who >= 0]).sum() > 100
    for block in (1, 7, 256):
        ours = run(ev, r, layout, smooth, block=block)
        for key, value in whole.items():
            np.testing.assert_array_equal(ours[key], value, err_msg=f"{key}, block {block}")


@pytest.mark.parametrize("use_bias", [True, False])
@pytest.mark.parametrize(("drifting", "bounded"), [((), ()), ((1,), (0,)), ((0, 1), ())])
def test_the_kernels_know_every_entry_of_f_but_the_identitys(
    use_bias: bool, drifting: tuple[int, ...], bounded: tuple[int, ...]
) -> None:
    # the kernels multiply by F as the identity plus the entries couplings lists, times the
    # decays of the bounded states on the diagonal: one missing would be dropped silently
    layout = Layout(np.ones(M), (), drifting=drifting, bounded=bounded)
    structure = layout.structure(use_bias)
    _, drifts, states, _, _, _ = structure
    f = np.eye(layout.n)
    transition(f, 0.37, structure)
    changed = np.nonzero(f - np.eye(layout.n))
    off = {(int(i), int(k)) for i, k in zip(*changed, strict=True) if i != k}
    assert off == {(int(i), int(k)) for i, k in couplings(use_bias, drifts)}
    assert len(off) == 1 + 2 * use_bias + len(drifting)
    assert {int(i) for i, k in zip(*changed, strict=True) if i == k} == set(states.tolist())
    # a decaying state has no entry off the diagonal (the kernels take F = D (I + E))
    assert not {int(c) for c in states} & {c for pair in off for c in pair}
    # Q of a bounded offset: its random-walk density at short spans, q tau / 2 at long ones
    q = np.zeros((layout.n, layout.n))
    for dt, expected in [(1e-3, 0.01 * 1e-3), (1e6, 0.01 * GPS_CORRELATION_S / 2)]:
        process_noise(q, dt, 0.0, np.full(M, 0.01), structure, 0.0)
        for c in states:
            assert q[c, c] == pytest.approx(expected, rel=1e-3)


def test_the_barometers_share_their_wander_and_q_stays_positive_semi_definite() -> None:
    # a GPS and three barometers, the first two drifting, the third's offset let loose at a step
    layout = Layout(np.ones(4), (), drifting=(1, 2), bounded=(0,), shared=(1, 2, 3))
    q = np.zeros((layout.n, layout.n))
    dt = 0.2
    process_noise(q, dt, 0.05, np.array([0.01, 1e-4, 1e-4, 0.5]), layout.structure(True), 0.0)
    np.testing.assert_array_equal(q, q.T)
    assert np.linalg.eigvalsh(q).min() > -1e-18
    (gps, one, two, three), (rate_one, rate_two) = range(3, 7), layout.drift_pairs[:, 1]
    # their offsets' increments: the smaller density's share, plus the drifts' shared part
    assert q[one, two] == pytest.approx(BARO_SHARED * (1e-4 * dt + Q_DRIFT * dt**3 / 3))
    assert q[one, three] == pytest.approx(BARO_SHARED * 1e-4 * dt)
    assert q[one, rate_two] == q[rate_one, two] == pytest.approx(BARO_SHARED * Q_DRIFT * dt**2 / 2)
    assert q[rate_one, rate_two] == pytest.approx(BARO_SHARED * Q_DRIFT * dt)
    # the GPS's wander is its own, and the third barometer has no drift rate to share
    assert not q[gps, 4:].any()
    assert q[three, rate_one] == q[three, rate_two] == 0.0


def test_passes_run_at_once_give_the_passes_run_one_by_one() -> None:
    # the evidence tests run their two forward passes in threads: the same arrays read at once,
    # each pass its own outputs
    ev, layout, r = toy(0, accel=True)
    ev = replace(ev, gate=1.5)  # a gate that rejects some samples, differently per model
    plain = Layout(np.ones(M), ())
    # its regressors shared with ``layout``'s (their coefficients are), not its states' count
    steady = replace(layout, drifting=())
    models = [(ev, r, layout), (ev, r, plain), (ev, r * 4, plain), (ev, r, steady)]
    together = likelihoods(*models)
    alone = [likelihood(*model) for model in models]
    assert len({int(one["accepted"].sum()) for one in alone}) > 1
    for mine, theirs in zip(together, alone, strict=True):
        assert mine.keys() == theirs.keys()
        for key in mine:
            np.testing.assert_array_equal(mine[key], theirs[key])


def test_rows_of_h_refuse_another_layout_s_coefficients() -> None:
    ev, layout, _ = toy(0, accel=False)
    with pytest.raises(ValueError, match="coefficients"):
        measurement_rows(layout, ev.who, np.zeros((2, ev.who.size)))


@pytest.mark.parametrize("keep", [FOR_EM, FOR_RESULT, HEIGHTS], ids=["em", "result", "heights"])
def test_a_pass_keeps_what_it_is_asked_for_as_a_whole_one(keep: Keep) -> None:
    # the smoother's passes keep less than everything (the states at the ticks, a sample's row
    # as H x): the same numbers as the pass that keeps everything, over blocks, with rejections
    ev, layout, r = toy(4, accel=True, spliced=True, count=3000)
    ev = replace(ev, gate=1.5)
    whole = run(ev, r, layout, block=256)
    ours = run(ev, r, layout, block=256, keep=keep)
    at = ev.who == TICK if keep.ticks else np.ones(ev.who.size, dtype=bool)
    states = list(range(layout.n)) if keep.states is None else list(keep.states)
    assert ours["x"].shape == (at.sum(), len(states))
    np.testing.assert_array_equal(ours["x"], whole["x"][at][:, states])
    np.testing.assert_array_equal(ours["accepted"], whole["accepted"])
    assert set(ours) == {"x", "accepted", *keep.verdicts} | ({"var_h"} if keep.var_h else set()) | (
        {"hx", "var_row"} if keep.rows else set()
    )
    for name in keep.verdicts:
        np.testing.assert_array_equal(ours[name], whole[name])
    if keep.var_h:
        np.testing.assert_array_equal(ours["var_h"], whole["var_h"][at])
    if keep.rows:
        np.testing.assert_array_equal(ours["var_row"], whole["var_row"])
        rows = measurement_rows(layout, ev.who)
        h = np.zeros((ev.who.size, layout.n))
        for k, series in enumerate(ev.who):
            measurement_row(rows, int(series), k, h[k])
        expected = np.where(ev.who != TICK, np.einsum("ki,ki->k", h, whole["x"]), np.nan)
        np.testing.assert_allclose(ours["hx"], expected, rtol=0, atol=1e-12)
        assert np.isnan(ours["hx"][ev.who == TICK]).all()


def test_densities_the_same_at_every_event_may_be_one_row() -> None:
    # a flight without a rangefinder's terrain has one row of densities (12 MB an event's worth
    # on a 7.4-hour log): the same passes as with a row per event
    ev, layout, r = toy(2, accel=True, spliced=True, count=1000)
    assert (ev.q_state == ev.q_state[0]).all()
    one = replace(ev, q_state=ev.q_state[:1].copy())
    whole, ours = run(ev, r, layout, block=256), run(one, r, layout, block=256)
    for key, value in whole.items():
        np.testing.assert_array_equal(ours[key], value, err_msg=key)
