"""The figures (issue 19): one colour per sensor and method in every figure, lines that break
at gaps, a long gap shortened, axes a runaway curve does not flatten."""

from __future__ import annotations

import numpy as np
from matplotlib.lines import Line2D

from altfuse.evaluation import truth_or_none
from altfuse.pipeline import FuseOptions, fuse_log
from altfuse.plot import colour, figure, run_figure, window_shares
from conftest import SAMPLE_LOG, shared_log


def _lines(ax: object) -> dict[str, Line2D]:
    return {line.get_label(): line for line in ax.get_lines()}  # type: ignore[attr-defined]


def test_a_sensor_has_one_colour_in_the_figures_of_different_logs() -> None:
    """baro was orange beside gps in one log and beside gps2 in another, and baro3 shared it."""
    figures = []
    for log in (SAMPLE_LOG, shared_log("ardupilot/diaven_sample01.bin")):
        run = fuse_log(log)
        figures.append(run_figure(run, {}, truth_or_none(run.log, run.referred), log.name))
    one, two = (_lines(f.axes[0]) for f in figures)
    assert set(one) == {"gps", "baro", "rangefinder"}
    assert set(two) == {"gps", "gps2", "baro", "rangefinder"}
    for name in one:
        assert one[name].get_color() == two[name].get_color() == colour(name)
    assert len({colour(n) for n in ("gps", "gps2", "gps3", "baro", "baro2", "baro3")}) == 6
    assert colour("smoother") not in {colour(n) for n in two}  # methods apart from sensors
    fused = _lines(figures[0].axes[1])
    assert fused["fused: smoother"].get_color() == colour("smoother")


def _flight(gap: slice) -> dict[str, np.ndarray]:
    t = np.arange(0.0, 200.0, 0.1)
    h = np.column_stack([np.sin(t / 10), np.sin(t / 10) + 0.1])
    h[gap] = np.nan
    weights = np.tile([1.0, 0.0], (t.size, 1))
    weights[1::2] = [0.0, 1.0]  # one sample a tick, by turns
    return {"t": t, "heights": h, "weights": weights}


def test_a_gap_breaks_the_lines_and_a_long_one_is_shortened() -> None:
    d = _flight(slice(500, 1500))  # 100 s of the 200 s with no sensor
    fused = np.where(np.isnan(d["heights"][:, 0]), np.nan, d["heights"].mean(axis=1))
    fig = figure(title="gap", t=d["t"], names=("gps", "baro"), heights=d["heights"],
                 fused={"mean": fused}, weights=d["weights"], weights_of="mean")  # fmt: skip
    gps = _lines(fig.axes[0])["gps"]
    y = np.asarray(gps.get_ydata(), dtype=float)
    assert np.isnan(y[500:1500]).all()  # no segment drawn across the gap
    axis = fig.axes[-1].xaxis
    assert fig.axes[-1].get_xscale() == "function"
    start, end = axis.get_transform().transform([49.9, 150.0])
    assert end - start < 0.1 * (axis.get_transform().transform([199.9])[0] - start)
    assert any(text.get_text().startswith("no sensor\nfor 100 s") for text in fig.axes[0].texts)
    short = figure(title="no long gap", t=d["t"], names=("gps", "baro"), heights=_flight(
        slice(500, 520))["heights"], fused={"mean": fused}, weights=d["weights"],
        weights_of="mean")  # fmt: skip
    assert short.axes[-1].get_xscale() == "linear"


def test_a_runaway_curve_does_not_flatten_the_others() -> None:
    d = _flight(slice(0, 0))
    fused = np.nanmean(d["heights"], axis=1)
    fused[900:950] = 32_000.0  # 32 km: as a real log's smoother once wrote
    sigma = np.full(fused.size, 0.05)
    fig = figure(title="runaway", t=d["t"], names=("gps", "baro"), heights=d["heights"],
                 fused={"smoother": fused}, weights=d["weights"], weights_of="smoother",
                 sigma=sigma)  # fmt: skip
    low, high = fig.axes[1].get_ylim()
    assert -2 < low < -1
    assert 1 < high < 2
    notes = [text.get_text() for text in fig.axes[1].texts]
    assert notes == ["fused: smoother: 32000.0 m off the axis"]
    band = fig.axes[2].collections
    assert band  # the +-2 sigma band under the residuals


def test_the_ticks_the_guard_flagged_are_crossed_on_the_fused_curve() -> None:
    """The CSV's status ``diverged``, seen: the 3.3 plane's multilayer, 263 ticks in 8 spans
    (the figure showed nothing of them)."""
    run = fuse_log(shared_log("truth/plane_3.3.0a1_gitterbadger_autotest_climb386m_imunoise.BIN"),
                   FuseOptions(method="multilayer"))  # fmt: skip
    flagged = run.result.status == "diverged"
    assert flagged.sum() == 263
    fig = run_figure(run, {}, None, "plane")
    crosses = _lines(fig.axes[1])["diverged: multilayer outside every sensor (263 ticks)"]
    np.testing.assert_array_equal(crosses.get_xdata(), run.referred.t[flagged])
    assert crosses.get_marker() == "x"
    quiet = fuse_log(SAMPLE_LOG)
    labels = _lines(run_figure(quiet, {}, None, "sample").axes[1])
    assert not [label for label in labels if label.startswith("diverged")]


def test_the_weights_are_shown_as_shares_over_a_window() -> None:
    """Samples one at a time: weights 1/0 by turns, a share of one half each."""
    d = _flight(slice(0, 0))
    shares = window_shares(d["t"], d["weights"], 2.0)
    np.testing.assert_allclose(shares[100:-100], 0.5, atol=0.01)
    np.testing.assert_allclose(shares.sum(axis=1), 1.0)


def test_the_shares_of_a_flight_shorter_than_the_window() -> None:
    """8 ticks against a 2 s window at 10 Hz (a real log's): one share per tick."""
    t = np.arange(8) / 10.0
    shares = window_shares(t, np.tile([0.25, 0.75], (8, 1)), 2.0)
    assert shares.shape == (8, 2)
    np.testing.assert_allclose(shares, np.tile([0.25, 0.75], (8, 1)))
