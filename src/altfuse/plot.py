"""Figures of a fusion run or an evaluation: the panels of Paper A's figures 3-5.

1. the aligned sensors, referred to the take-off point;
2. the fused altitude over the sensors, with the truth or the reference when known;
3. the weight each sensor received over time.

The format follows the file's extension (PNG or SVG). Figures are made with matplotlib's object API,
without pyplot: no backend, window or global state. matplotlib is imported on the first figure, not
with this module: it is a third of the command line's start-up time.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from altfuse.model import FloatArray
from altfuse.params import InvalidParameter

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from altfuse.evaluation import Truth
    from altfuse.pipeline import FuseRun

FORMATS = (".png", ".svg")
_SENSOR_COLOURS = {"gps": "tab:blue", "baro": "tab:orange", "rangefinder": "tab:green"}


def check_plot_path(path: str | Path) -> Path:
    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise InvalidParameter("plot", f"must end in {' or '.join(FORMATS)}, got {path.name}")
    return path


def _colour(name: str) -> str | None:
    for kind, colour in _SENSOR_COLOURS.items():
        if name == kind:
            return colour
    return None


def figure(  # noqa: PLR0913 (keyword-only: each panel's data, by name)
    *,
    title: str,
    t: FloatArray,
    names: tuple[str, ...],
    heights: FloatArray,
    fused: Mapping[str, FloatArray],
    weights: FloatArray,
    weights_of: str,
    truth: FloatArray | None = None,
    truth_label: str = "truth",
) -> Figure:
    """The three panels as a matplotlib figure (see :func:`writer` to save it)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 9), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True, gridspec_kw={"height_ratios": [3, 3, 2]})
    ax_sensors, ax_fused, ax_weights = axes
    for i, name in enumerate(names):
        ax_sensors.plot(t, heights[:, i], lw=0.8, color=_colour(name), label=name)
        ax_fused.plot(t, heights[:, i], lw=0.5, alpha=0.3, color=_colour(name), label=name)
        ax_weights.plot(t, weights[:, i], lw=0.8, color=_colour(name), label=name)
    ax_sensors.set_title("aligned sensors")
    for method, values in fused.items():
        ax_fused.plot(t, values, lw=1.3, label=f"fused: {method}")
    if truth is not None:
        ax_fused.plot(t, truth, "k--", lw=1.0, label=truth_label)
    ax_fused.set_title("fused altitude over the sensors")
    ax_weights.set_title(f"weights ({weights_of})")
    ax_weights.set_ylim(-0.02, 1.02)
    ax_sensors.set_ylabel("height above take-off [m]")
    ax_fused.set_ylabel("height above take-off [m]")
    ax_weights.set_ylabel("weight [-]")
    ax_weights.set_xlabel("time since boot [s]")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=8, frameon=False)
    fig.suptitle(title)
    return fig


def run_figure(
    run: FuseRun, fused: Mapping[str, FloatArray], truth: Truth | None, title: str
) -> Figure:
    """The figure of a run: its sensors and weights, the ``fused`` curves, the truth if known.
    With several curves, the weights shown are ``run``'s (say which in ``title``)."""
    return figure(
        title=title,
        t=run.referred.t,
        names=run.referred.names,
        heights=run.referred.h,
        fused=fused,
        weights=run.result.weights,
        weights_of=run.result.method,
        truth=None if truth is None else truth.h,
        truth_label="truth" if truth is None else truth.label,
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
