"""Figures of a fusion run or an evaluation: the panels of Paper A's figures 3-5, and more.

1. the aligned sensors, referred to the take-off point;
2. the fused altitude over the sensors, with the truth or the reference when known;
3. each sensor's residual against the fused altitude, over the fused altitude's +-2 sigma band
   (where the method gives one): where a sensor goes wrong, the eye sees it here;
4. the share of the weight each sensor received over a window of ``WEIGHT_WINDOW_S`` (a method
   fusing one sample at a time gives it all per tick, and the raw weights alternate 0/1).

Each sensor instance and each method has one colour, the same in every figure (:func:`colour`).
Lines break where the data stops; a stretch of more than ``LONG_GAP_S`` (and a tenth of the
flight) with no sensor at all is shortened on the time axis to ``SHORT_GAP_SHARE`` of its width
and marked, so that the flight is not squeezed into a corner by a pause in the log. The heights'
axes span the sensors' range: a fused value beyond it is drawn at the edge, marked, and its
farthest excursion written there (a finding, as :mod:`altfuse.guard` flags it). The ticks the
guard flagged ``diverged`` are crossed on the fused curve: the status the CSV gives them, seen.

The format follows the file's extension (PNG or SVG). Figures are made with matplotlib's object
API, without pyplot: no backend, window or global state. matplotlib is imported on the first
figure, not with this module: it is a third of the command line's start-up time.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

from altfuse.fuse.base import DIVERGED
from altfuse.metrics import samples_in
from altfuse.model import FloatArray, counted
from altfuse.params import InvalidParameter

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from altfuse.evaluation import Truth
    from altfuse.pipeline import FuseRun

FORMATS = (".png", ".svg")
#: Each sensor kind's colours, one per instance in order (``gps``, ``gps2``, ...), then again.
_SENSOR_COLOURS = {
    "gps": ("#1f77b4", "#6baed6", "#08306b"),
    "baro": ("#ff7f0e", "#a65628", "#fdae6b"),
    "rangefinder": ("#2ca02c", "#74c476", "#00441b"),
}
#: Each method's colour, apart from the sensors' (blues, oranges, greens) and the truth (black).
_METHOD_COLOURS = {
    "mean": "#7f7f7f",
    "support": "#9467bd",
    "delay1": "#e377c2",
    "delay2": "#bcbd22",
    "multilayer": "#d62728",
    "smoother": "#17becf",
}
_OTHER = "#525252"
#: Window [s] of the weights' shares.
WEIGHT_WINDOW_S = 2.0
#: A stretch with no sensor longer than this [s] and than a tenth of the flight is shortened.
LONG_GAP_S = 30.0
SHORT_GAP_SHARE = 0.03
#: Margin of the heights' axes beyond the sensors' range, as a share of it (and at least 0.5 m).
Y_MARGIN = 0.08


def check_plot_path(path: str | Path) -> Path:
    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise InvalidParameter("plot", f"must end in {' or '.join(FORMATS)}, got {path.name}")
    return path


def colour(name: str) -> str:
    """The colour of a sensor (``gps``, ``baro2``, ``rangefinder``) or a method, the same in
    every figure."""
    if name in _METHOD_COLOURS:
        return _METHOD_COLOURS[name]
    for kind, colours in _SENSOR_COLOURS.items():
        if name.startswith(kind):
            number = name.removeprefix(kind)
            k = int(number) - 1 if number.isdigit() else 0
            return colours[k % len(colours)]
    return _OTHER


def figure(  # noqa: PLR0913 (keyword-only: each panel's data, by name)
    *,
    title: str,
    t: FloatArray,
    names: tuple[str, ...],
    heights: FloatArray,
    fused: Mapping[str, FloatArray],
    weights: FloatArray,
    weights_of: str,
    sigma: FloatArray | None = None,
    truth: FloatArray | None = None,
    truth_label: str = "truth",
    diverged: np.ndarray | None = None,
) -> Figure:
    """The four panels as a matplotlib figure (see :func:`writer` to save it). ``sigma`` is the
    standard deviation of ``fused[weights_of]`` (the residuals are against that curve);
    ``diverged`` the ticks where the guard flagged it."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 11), layout="constrained")
    axes = fig.subplots(4, 1, sharex=True, gridspec_kw={"height_ratios": [3, 3, 2, 2]})
    ax_sensors, ax_fused, ax_residual, ax_weights = axes
    low, high = _height_range(heights)
    shares = window_shares(t, weights, WEIGHT_WINDOW_S)
    main = fused.get(weights_of, next(iter(fused.values()), np.full(t.size, np.nan)))
    for i, name in enumerate(names):
        c = colour(name)
        ax_sensors.plot(t, heights[:, i], lw=0.8, color=c, label=name)
        ax_fused.plot(t, heights[:, i], lw=0.5, alpha=0.3, color=c, label=name)
        ax_residual.plot(t, heights[:, i] - main, lw=0.7, color=c, label=name)
        ax_weights.plot(t, shares[:, i], lw=0.9, color=c, label=name)
    for method, values in fused.items():
        _clipped(ax_fused, t, values, (low, high), f"fused: {method}", colour(method))
    if diverged is not None and diverged.any():
        ax_fused.plot(t[diverged], np.clip(main[diverged], low, high), "kx", ms=5,
                      label=f"diverged: {weights_of} outside every sensor "
                      f"({counted(int(diverged.sum()), 'tick')})")  # fmt: skip
    if truth is not None:
        ax_fused.plot(t, truth, "k--", lw=1.0, label=truth_label)
    if sigma is not None and np.isfinite(sigma).any():
        ax_residual.fill_between(t, -2 * sigma, 2 * sigma, color="0.6", alpha=0.35, lw=0,
                                 label=f"+-2 sigma of {weights_of}")  # fmt: skip
    ax_residual.axhline(0.0, color=colour(weights_of), lw=0.8)
    _residual_limits(ax_residual, heights - main[:, None], sigma)
    for ax in (ax_sensors, ax_fused):
        ax.set_ylim(low, high)
        ax.set_ylabel("height above take-off [m]")
    ax_sensors.set_title("aligned sensors")
    ax_fused.set_title("fused altitude over the sensors")
    ax_residual.set_title(f"each sensor less the fused altitude ({weights_of})")
    ax_residual.set_ylabel("residual [m]")
    ax_weights.set_title(f"weights ({weights_of}): each sensor's share over {WEIGHT_WINDOW_S:g} s")
    ax_weights.set_ylim(-0.02, 1.02)
    ax_weights.set_ylabel("share [-]")
    ax_weights.set_xlabel("time since boot [s]")
    gaps = long_gaps(t, np.asarray(np.isfinite(heights).any(axis=1)))
    _shorten(ax_weights, t, gaps)
    for ax in axes:
        for a, b in gaps:
            ax.axvspan(a, b, color="0.85", lw=0)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=8, frameon=False)
    for a, b in gaps:
        ax_sensors.annotate(f"no sensor\nfor {b - a:.0f} s", ((a + b) / 2, 0.98),
                            xycoords=("data", "axes fraction"), ha="center", va="top",
                            fontsize=7, color="0.35")  # fmt: skip
    fig.suptitle(title)
    return fig


def _height_range(heights: FloatArray) -> tuple[float, float]:
    """The heights' axis: the sensors' range with a margin (a unit range when they have none)."""
    valid = heights[np.isfinite(heights)]
    if not valid.size:
        return -1.0, 1.0
    lo, hi = float(valid.min()), float(valid.max())
    margin = max(Y_MARGIN * (hi - lo), 0.5)
    return lo - margin, hi + margin


def _clipped(
    ax: Axes, t: FloatArray, values: FloatArray, limits: tuple[float, float], label: str, c: str
) -> None:
    """``values`` within ``limits``; beyond them drawn at the edge, marked, and the farthest
    excursion written beside it."""
    lo, hi = limits
    ax.plot(t, np.clip(values, lo, hi), lw=1.3, color=c, label=label)
    for edge, beyond, marker in ((hi, values > hi, "^"), (lo, values < lo, "v")):
        if not beyond.any():
            continue
        ax.plot(t[beyond], np.full(int(beyond.sum()), edge), marker, ms=3, color=c, ls="none")
        k = int(np.argmax(np.abs(np.where(beyond, values - edge, 0.0))))
        ax.annotate(f"{label}: {values[k]:.1f} m off the axis", (t[k], edge), fontsize=7,
                    color=c, ha="center", va="top" if edge == hi else "bottom")  # fmt: skip


def _residual_limits(ax: Axes, residuals: FloatArray, sigma: FloatArray | None) -> None:
    """The residuals' axis: their 1-99 % range and the band, so that one spike does not
    flatten the rest."""
    parts = [residuals[np.isfinite(residuals)]]
    if sigma is not None:
        parts.append(2 * sigma[np.isfinite(sigma)])
        parts.append(-2 * sigma[np.isfinite(sigma)])
    values = np.concatenate(parts)
    if values.size:
        lo, hi = np.percentile(values, [1, 99])
        span = max(float(hi - lo), 0.1)
        ax.set_ylim(float(lo) - 0.1 * span, float(hi) + 0.1 * span)


def window_shares(t: FloatArray, weights: FloatArray, window_s: float) -> FloatArray:
    """Each sensor's share of the weight over a centred triangular window of half-width
    ``window_s`` (ticks with no weight count as none); NaN where no tick in it has any."""
    step = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    # triangular: a box counts 4 or 5 samples of a 5 Hz sensor by turns (a comb in the shares)
    half = min(max(1, samples_in(window_s, step, t.size)), max(1, (t.size - 1) // 2))  # <= t
    kernel = np.bartlett(2 * half + 1)
    w = np.nan_to_num(weights)
    sums = np.column_stack([np.convolve(w[:, i], kernel, mode="same") for i in range(w.shape[1])])
    total = sums.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, sums / total, np.nan)


def long_gaps(t: FloatArray, valid: np.ndarray) -> list[tuple[float, float]]:
    """The stretches of the clock with no valid tick longer than ``LONG_GAP_S`` and a tenth of
    the span: (last tick before, first tick after)."""
    at = t[valid]
    if at.size < 2:
        return []
    least = max(LONG_GAP_S, 0.1 * float(at[-1] - at[0]))
    return [(float(a), float(b)) for a, b in itertools.pairwise(at) if b - a > least]


def _shorten(ax: Axes, t: FloatArray, gaps: list[tuple[float, float]]) -> None:
    """Shorten each gap on the (shared) time axis to ``SHORT_GAP_SHARE`` of the flight shown."""
    if not gaps:
        return
    kept = float(t[-1] - t[0]) - sum(b - a for a, b in gaps)
    short = SHORT_GAP_SHARE * max(kept, 1.0)
    knots_t, knots_x, x = [float(t[0])], [0.0], 0.0
    for a, b in gaps:
        x += a - knots_t[-1]
        knots_t += [a, b]
        knots_x += [x, x + short]
        x += short
    knots_t.append(float(t[-1]))
    knots_x.append(x + float(t[-1]) - knots_t[-2])
    real, shown = np.array(knots_t), np.array(knots_x)

    def forward(v: Any) -> Any:
        return _piecewise(v, real, shown)

    def inverse(v: Any) -> Any:
        return _piecewise(v, shown, real)

    ax.set_xscale("function", functions=(forward, inverse))
    # ticks per stretch shown (the default locator spaces them in seconds, crowding the gaps)
    from matplotlib.ticker import MaxNLocator

    edges = [float(t[0]), *itertools.chain.from_iterable(gaps), float(t[-1])]
    ticks: list[float] = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        bins = max(1, round(10 * (b - a) / max(kept, 1.0)))
        ticks += [v for v in MaxNLocator(bins).tick_values(a, b) if a <= v <= b]
    ax.set_xticks(ticks)


def _piecewise(v: Any, xs: FloatArray, ys: FloatArray) -> Any:
    """The piecewise-linear map through the knots ``(xs, ys)``, of slope 1 beyond them (an
    axis' margins lie outside the clock)."""
    v = np.asarray(v, dtype=float)
    return np.interp(v, xs, ys) + np.minimum(v - xs[0], 0.0) + np.maximum(v - xs[-1], 0.0)


def run_figure(
    run: FuseRun, fused: Mapping[str, FloatArray], truth: Truth | None, title: str
) -> Figure:
    """The figure of a run: its sensors and weights, the ``fused`` curves, the truth if known.
    With several curves, the weights and residuals shown are ``run``'s (say which in
    ``title``)."""
    method = run.result.method
    curves = {name: values for name, values in fused.items() if name != method}
    curves[method] = run.result.fused  # drawn last: on top of the others
    return figure(
        title=title,
        t=run.referred.t,
        names=run.referred.names,
        heights=run.referred.h,
        fused=curves,
        weights=run.result.weights,
        weights_of=run.result.method,
        sigma=run.result.tick_traces.get("fused_std"),
        truth=None if truth is None else truth.h,
        truth_label="truth" if truth is None else truth.label,
        diverged=run.result.status == DIVERGED,
    )


def writer(fig: Figure, path: Path) -> Callable[[IO[Any]], None]:
    """Save ``fig`` in the format of ``path``'s extension, reproducibly (no date, fixed ids)."""
    fmt = check_plot_path(path).suffix.lower().lstrip(".")

    def save(handle: IO[Any]) -> None:
        import matplotlib

        with matplotlib.rc_context({"svg.hashsalt": "altfuse"}):
            fig.savefig(
                handle, format=fmt, dpi=110, metadata={"Date": None} if fmt == "svg" else {}
            )

    return save
