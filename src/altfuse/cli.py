"""The ``altfuse`` command line. Parses options, calls the library, prints; nothing else prints.

Every error a user can cause ends as one line on stderr (``altfuse: error: ...``) and a non-zero
exit code: 1 for a log that cannot be processed, 2 for a usage or parameter error, 3 for a bug
(with ``--debug`` showing its traceback).
"""

from __future__ import annotations

import json
import logging
import math
import sys
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

import click

from altfuse import __version__
from altfuse.errors import AltfuseError, ParameterError
from altfuse.fuse import FUSERS
from altfuse.fuse.complementary import (
    DEFAULT_E_MAX_M,
    DEFAULT_LAYER1_Q,
    DEFAULT_REOPEN_S,
    DEFAULT_T_S,
)
from altfuse.fuse.delay import DEFAULT_Q, FORMS
from altfuse.fuse.support import DEFAULT_BETA, DEFAULT_WINDOW
from altfuse.info import describe
from altfuse.io import read_log
from altfuse.pipeline import FuseOptions, fuse_log
from altfuse.write import default_meta_path, write_outputs

EXIT_BUG = 3
#: Options that are parameters of a fusion method (passed on only when given).
METHOD_OPTIONS = ("alpha", "beta", "window", "form", "q", "time_constant", "e_max", "reopen")


class _OneLineFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        return f"altfuse: {record.levelname.lower()}: {record.getMessage()}"


def _fail(message: str, code: int) -> NoReturn:
    click.echo(f"altfuse: error: {message}", err=True)
    sys.exit(code)


class _Cli(click.Group):
    """A group whose errors are one line each, whatever raised them."""

    def main(self, *args: Any, **kwargs: Any) -> Any:
        kwargs["standalone_mode"] = False
        argv = kwargs.get("args", args[0] if args else None)
        debug = "--debug" in (sys.argv[1:] if argv is None else list(argv))
        try:
            code = super().main(*args, **kwargs)
        except click.exceptions.Abort:
            _fail("interrupted", 130)
        except click.ClickException as exc:
            _fail(exc.format_message().replace("\n", " "), exc.exit_code)
        except AltfuseError as exc:
            _fail(str(exc), exc.exit_code)
        except KeyboardInterrupt:
            _fail("interrupted", 130)
        except Exception as exc:
            if debug:
                traceback.print_exc()
            _fail(f"internal error: {type(exc).__name__}: {exc} (rerun with --debug)", EXIT_BUG)
        sys.exit(code if isinstance(code, int) else 0)


class _AlphaType(click.ParamType):  # type: ignore[type-arg]
    name = "auto|FLOAT"

    def convert(self, value: Any, param: Any, ctx: Any) -> float | None:
        if value is None or isinstance(value, float):
            return value
        if str(value).lower() == "auto":
            return None
        try:
            alpha = float(value)
        except ValueError:
            self.fail(f"{value!r} is neither 'auto' nor a number", param, ctx)
        if not (math.isfinite(alpha) and alpha > 0):
            self.fail(f"{value!r} is not a positive number", param, ctx)
        return alpha


@click.group(cls=_Cli, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="altfuse")
@click.option("-v", "--verbose", count=True, help="More detail on stderr (-v info, -vv debug).")
@click.option("-q", "--quiet", is_flag=True, help="Only errors on stderr.")
@click.option("--debug", is_flag=True, help="Show the traceback of an internal error.")
def cli(verbose: int, quiet: bool, debug: bool) -> None:  # noqa: ARG001 (read in main)
    """Fuse the altitude sensors of ArduPilot DataFlash logs after the flight.

    \b
    Example:
      altfuse fuse flight.bin -o flight.csv
      altfuse info flight.bin
    """
    level = logging.ERROR if quiet else [logging.WARNING, logging.INFO][min(verbose, 1)]
    if verbose >= 2:
        level = logging.DEBUG
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_OneLineFormatter())
    root = logging.getLogger("altfuse")
    root.handlers[:] = [handler]
    root.setLevel(level)
    root.propagate = False


_LOG_ARG = click.argument("log", type=click.Path(dir_okay=False, path_type=Path))


def _method_option(
    flag: str, kind: Any, help_text: str
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """A fusion-method parameter: passed on to the method only when given."""
    return click.option(flag, type=kind, default=None, help=help_text)


def _output_option(help_text: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    return click.option(
        "-o",
        "--output",
        type=click.Path(dir_okay=False, path_type=Path),
        required=True,
        help=help_text,
    )


@cli.command()
@_LOG_ARG
@_output_option("The fused CSV to write; the provenance goes beside it as NAME.meta.json.")
@click.option(
    "-m",
    "--method",
    type=click.Choice(list(FUSERS)),
    default="support",
    show_default=True,
    help="Fusion method.",
)
@click.option(
    "--rate",
    "rate_hz",
    type=float,
    default=10.0,
    show_default=True,
    help="Rate of the common clock [Hz].",
)
@click.option(
    "--max-gap",
    "max_gap_s",
    type=float,
    default=1.0,
    show_default=True,
    help="Longest gap in a sensor's data the spline may bridge [s].",
)
@click.option(
    "--span",
    type=click.Choice(["union", "overlap"]),
    default="union",
    show_default=True,
    help="Clock over the union or the overlap of the sensors.",
)
@_method_option(
    "--alpha", _AlphaType(), "support: kernel scale [1/m^2], or 'auto' (from the data; default)."
)
@_method_option(
    "--beta", float, f"support: penalty on the support's variance [default {DEFAULT_BETA:g}]."
)
@_method_option(
    "--window", int, f"support: k, previous ticks in the window [default {DEFAULT_WINDOW}]."
)
@_method_option(
    "--form",
    click.Choice(FORMS),
    "delay1/delay2/multilayer: temporal recursion, 'practical' (random walk, default) or "
    "'paper' (constant altitude).",
)
@_method_option(
    "--q",
    float,
    "delay1/delay2/multilayer: process noise [m^2 per tick] "
    f"[default {DEFAULT_Q:g}; multilayer {DEFAULT_LAYER1_Q:g}].",
)
@_method_option(
    "--time-constant",
    float,
    f"multilayer: complementary filter time constant T [s] [default {DEFAULT_T_S:g}].",
)
@_method_option(
    "--e-max",
    float,
    f"multilayer: gate threshold on the correction [m] [default {DEFAULT_E_MAX_M:g}].",
)
@_method_option(
    "--reopen",
    float,
    f"multilayer: seconds before a shut gate reopens [default {DEFAULT_REOPEN_S:g}].",
)
@click.option(
    "--ground-window",
    "ground_s",
    type=float,
    default=5.0,
    show_default=True,
    help="Seconds on the ground used to find each sensor's datum.",
)
@click.option(
    "--takeoff-climb",
    "climb_m",
    type=float,
    default=1.0,
    show_default=True,
    help="Rise [m] that marks take-off.",
)
@click.option(
    "--min-sensors",
    type=int,
    default=2,
    show_default=True,
    help="Fail unless at least this many altitude sources are usable.",
)
@click.option(
    "--weights",
    "weights_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the weight traces (lambda, r, their window mean and variance).",
)
@click.option(
    "--meta",
    "meta_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Where to write the provenance JSON [default: beside the CSV].",
)
def fuse(
    log: Path,
    output: Path,
    method: str,
    weights_path: Path | None,
    meta_path: Path | None,
    **options: Any,
) -> None:
    """Fuse the altitude sensors of LOG into one altitude, written to a CSV.

    \b
    Example:
      altfuse fuse flight.bin -o flight.csv
      altfuse fuse flight.bin -o flight.csv --method mean --rate 20
      altfuse fuse flight.bin -o flight.csv --alpha 0.5 --beta 10 --weights w.csv
      altfuse fuse flight.bin -o flight.csv --method multilayer --time-constant 2
    """
    params = {k: options.pop(k) for k in METHOD_OPTIONS}
    params = {k: v for k, v in params.items() if v is not None}
    opts = FuseOptions(method=method, params=params, **options)
    opts.check()
    targets = [output, weights_path, meta_path or default_meta_path(output)]
    for target in targets:
        if target is not None and log.exists() and target.resolve() == log.resolve():
            raise ParameterError(f"{target} is the input log; choose another output path")
    run = fuse_log(log, opts)
    for note in run.log.notes:
        logging.getLogger("altfuse").info("%s", note)
    if run.log.skipped_bytes:
        logging.getLogger("altfuse").warning(
            "%s: %d bytes were not part of any decodable record and were skipped",
            log.name,
            run.log.skipped_bytes,
        )
    outputs = write_outputs(run, output, weights_path, meta_path)
    counts = run.provenance["status_counts"]
    click.echo(
        f"{output}: {run.referred.t.size} rows, method {method}, "
        f"sensors {', '.join(run.referred.names)}; "
        + ", ".join(f"{k} {v}" for k, v in counts.items())
        + f" (provenance: {outputs['meta']})"
    )


@cli.command()
@_LOG_ARG
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def info(log: Path, as_json: bool) -> None:
    """Show what LOG holds: vehicle, duration, altitude sources, references.

    \b
    Example:
      altfuse info flight.bin
      altfuse info flight.bin --json
    """
    summary = describe(read_log(log))
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    click.echo(
        f"{summary['file']}: {summary['vehicle']} ({summary['firmware']}), "
        f"{summary['size_bytes']} bytes, sensors over {summary['duration_s']:.1f} s"
    )
    click.echo("altitude sources:")
    for s in summary["sensors"]:
        rate = f"{s['rate_hz']:.1f} Hz" if s["rate_hz"] else "? Hz"
        dropped = ", ".join(f"{n} {r}" for r, n in s["samples_dropped"].items())
        click.echo(
            f"  {s['name']:<12} {s['source']:<14} {rate:>8} {s['samples']:>7} samples "
            f"{s['min_m']:9.2f} .. {s['max_m']:9.2f} m  {s['start_s']:.1f}-{s['end_s']:.1f} s  "
            f"gaps>1s {s['gaps_over_1s']} (longest {s['longest_gap_s']:.1f} s)"
            + (f"  dropped: {dropped}" if dropped else "")
        )
    if not summary["sensors"]:
        click.echo("  none")
    for name, why in summary["sensors_dropped"].items():
        click.echo(f"  {name:<12} not used: {why}")
    click.echo(
        "references (never fused): "
        + (
            ", ".join(f"{r['name']} ({r['source']}, {r['datum']})" for r in summary["references"])
            or "none"
        )
    )
    click.echo(
        "IMU: "
        + (f"{summary['imu']['samples']} samples" if summary["imu"] else "none")
        + "; attitude: "
        + (f"{summary['attitude']['samples']} samples" if summary["attitude"] else "none")
    )
    click.echo(f"skipped bytes: {summary['skipped_bytes']}")
    for note in summary["notes"]:
        click.echo(f"note: {note}")


@cli.command()
@_output_option("The DataFlash log to write.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
@click.option(
    "--duration",
    "duration_s",
    type=float,
    default=120.0,
    show_default=True,
    help="Flight duration [s] (at least 60).",
)
def simulate(output: Path, seed: int, duration_s: float) -> None:
    """Write a simulated flight as a DataFlash log, with the true altitude in SIM records.

    GPS (5 Hz, 0.2 s lag, AMSL), barometer (20 Hz, drifting), rangefinder (20 Hz, over uneven
    ground, out of range above 20 m), IMU (50 Hz) and attitude (10 Hz).

    \b
    Example:
      altfuse simulate -o sim.bin --seed 1 --duration 180
    """
    from altfuse.simulate import simulate_flight, write_simulated_log

    flight = simulate_flight(seed=seed, duration_s=duration_s)
    n = write_simulated_log(flight, output)
    click.echo(f"{output}: {n} records, {duration_s:g} s, seed {seed}")


def main() -> None:
    cli()
