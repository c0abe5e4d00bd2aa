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
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

import click

from altfuse import __version__
from altfuse.batch import EXIT_PARTIAL, SUMMARY, BatchOptions, LogResult, run_batch
from altfuse.errors import AltfuseError, ParameterError
from altfuse.evaluate import TRUTHS, evaluation_table, truth_or_none
from altfuse.evaluate import evaluate as evaluate_log
from altfuse.fuse import FUSERS
from altfuse.fuse.complementary import (
    DEFAULT_E_MAX_M,
    DEFAULT_LAYER1_Q,
    DEFAULT_REOPEN_S,
    DEFAULT_T_S,
)
from altfuse.fuse.delay import DEFAULT_Q, FORMS
from altfuse.fuse.smoother import DEFAULT_GATE, Q_ACCEL_NO_IMU
from altfuse.fuse.support import DEFAULT_BETA, DEFAULT_WINDOW
from altfuse.info import damage, describe
from altfuse.io import read_log
from altfuse.metrics import ErrorStats
from altfuse.pipeline import FuseOptions, fuse_log
from altfuse.plot import check_plot_path, run_figure, writer
from altfuse.simulate import FAULTS, SCENARIOS, simulate_flight, write_simulated_log
from altfuse.write import atomic_outputs, default_meta_path, write_json, write_outputs

EXIT_BUG = 3
#: Options that are parameters of a fusion method (passed on only when given).
METHOD_OPTIONS = (
    "alpha", "beta", "window", "form", "q", "time_constant", "e_max", "reopen", "gate",
    "accel_noise", "sigmas", "offset_noises",
)  # fmt: skip


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
      altfuse batch logs/ -o results/
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
_PATH = click.Path(dir_okay=False, path_type=Path)
_METHOD = click.option(
    "-m",
    "--method",
    type=click.Choice(list(FUSERS)),
    default="support",
    show_default=True,
    help="Fusion method.",
)


def _method_option(
    flag: str, kind: Any, help_text: str
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """A fusion-method parameter: passed on to the method only when given."""
    return click.option(flag, type=kind, default=None, help=help_text)


def _output_option(help_text: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    return click.option("-o", "--output", type=_PATH, required=True, help=help_text)


def _pipeline_options(command: Callable[..., Any]) -> Callable[..., Any]:
    """The options every fusion run shares: clock, datum and the sensors required."""
    for option in reversed(
        [
            click.option(
                "--rate",
                "rate_hz",
                type=float,
                default=10.0,
                show_default=True,
                help="Rate of the common clock [Hz].",
            ),
            click.option(
                "--max-gap",
                "max_gap_s",
                type=float,
                default=1.0,
                show_default=True,
                help="Longest gap in a sensor's data the spline may bridge [s].",
            ),
            click.option(
                "--span",
                type=click.Choice(["union", "overlap"]),
                default="union",
                show_default=True,
                help="Clock over the union or the overlap of the sensors.",
            ),
            click.option(
                "--ground-window",
                "ground_s",
                type=float,
                default=5.0,
                show_default=True,
                help="Seconds on the ground used to find each sensor's datum.",
            ),
            click.option(
                "--takeoff-climb",
                "climb_m",
                type=float,
                default=1.0,
                show_default=True,
                help="Rise [m] that marks take-off.",
            ),
            click.option(
                "--min-sensors",
                type=int,
                default=2,
                show_default=True,
                help="Fail unless at least this many altitude sources are usable.",
            ),
        ]
    ):
        command = option(command)
    return command


def _force_option(command: Callable[..., Any]) -> Callable[..., Any]:
    return click.option("--force", is_flag=True, help="Overwrite existing outputs.")(command)


def _refuse_existing(force: bool, *paths: Path | None) -> None:
    """An existing output is never overwritten without --force."""
    for path in paths:
        if not force and path is not None and path.exists():
            raise ParameterError(f"{path} exists; --force overwrites it")


def _parse_per_sensor(values: tuple[str, ...], hint: str, unit: str) -> dict[str, float] | None:
    if not values:
        return None
    out = {}
    for item in values:
        name, _, number = item.partition("=")
        try:
            out[name.strip()] = float(number)
        except ValueError:
            raise click.BadParameter(f"{item!r} is not NAME={unit}", param_hint=hint) from None
    return out


def _per_sensor_option(
    flag: str, dest: str, unit: str, text: str
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """A repeatable smoother option NAME=VALUE, one value per sensor."""
    return click.option(
        flag,
        dest,
        multiple=True,
        callback=lambda _ctx, _param, value: _parse_per_sensor(value, flag, unit),
        help=f"smoother: {text} NAME={unit}, repeatable.",
    )


def _plot_option(command: Callable[..., Any]) -> Callable[..., Any]:
    return click.option(
        "--plot",
        "plot_path",
        type=_PATH,
        help="Also draw the sensors, the fused altitude and the weights (.png or .svg).",
    )(command)


@cli.command()
@_LOG_ARG
@_output_option("The fused CSV to write; the provenance goes beside it as NAME.meta.json.")
@_METHOD
@_pipeline_options
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
    "delay1/delay2/multilayer: temporal recursion, 'practical' (random walk, "
    "default) or 'paper' (constant altitude).",
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
@_method_option("--gate", float, f"smoother: innovation gate [sigmas] [default {DEFAULT_GATE:g}].")
@_method_option(
    "--accel-noise",
    float,
    "smoother: white acceleration noise density [m^2/s^3] "
    f"[default: from the accelerometer's noise, {Q_ACCEL_NO_IMU:g} without IMU].",
)
@_per_sensor_option(
    "--sigma", "sigmas", "METRES", "a sensor's measurement noise [default: from the log]."
)
@_per_sensor_option(
    "--offset-noise",
    "offset_noises",
    "M2_PER_S",
    "random-walk density of a sensor's offset (a rangefinder's ground height) [default: gps "
    "0.01, baro 1e-4; rangefinder from the terrain and the speed].",
)
@click.option(
    "--weights",
    "weights_path",
    type=_PATH,
    help="Also write the weight traces (the weights and each method's diagnostics).",
)
@click.option(
    "--meta",
    "meta_path",
    type=_PATH,
    help="Where to write the provenance JSON [default: beside the CSV].",
)
@_plot_option
@_force_option
def fuse(
    log: Path,
    output: Path,
    method: str,
    weights_path: Path | None,
    meta_path: Path | None,
    plot_path: Path | None,
    force: bool,
    **options: Any,
) -> None:
    """Fuse the altitude sensors of LOG into one altitude, written to a CSV.

    \b
    Example:
      altfuse fuse flight.bin -o flight.csv
      altfuse fuse flight.bin -o flight.csv --method mean --rate 20
      altfuse fuse flight.bin -o flight.csv --alpha 0.5 --beta 10 --weights w.csv
      altfuse fuse flight.bin -o flight.csv --method multilayer --plot flight.png
      altfuse fuse flight.bin -o flight.csv --method smoother --sigma gps=0.8
    """
    params = {k: options.pop(k) for k in METHOD_OPTIONS}
    params = {k: v for k, v in params.items() if v is not None}
    opts = FuseOptions(method=method, params=params, **options)
    opts.check()
    if plot_path is not None:
        check_plot_path(plot_path)
    targets = [output, weights_path, meta_path or default_meta_path(output), plot_path]
    for target in targets:
        if target is not None and log.exists() and target.resolve() == log.resolve():
            raise ParameterError(f"{target} is the input log; choose another output path")
    _refuse_existing(force, *targets)
    run = fuse_log(log, opts)
    for note in run.log.notes:
        logging.getLogger("altfuse").info("%s", note)
    warning = damage(run.log)
    if warning:
        logging.getLogger("altfuse").warning("%s", warning)
    extra = {}
    if plot_path is not None:
        truth = truth_or_none(run.log, run.referred)
        fig = run_figure(run, {method: run.result.fused}, truth, f"{log.name}: {method}")
        extra[plot_path] = (writer(fig, plot_path), True)
    started = time.perf_counter()
    outputs = write_outputs(run, output, weights_path, meta_path, extra)
    logging.getLogger("altfuse").info("wrote the outputs in %.2f s", time.perf_counter() - started)
    counts = run.provenance["status_counts"]
    click.echo(
        f"{output}: {run.referred.t.size} rows, method {method}, "
        f"sensors {', '.join(run.referred.names)}; "
        + ", ".join(f"{k} {v}" for k, v in counts.items())
        + f" (provenance: {outputs['meta']})"
    )


def _stats_line(name: str, kind: str, s: ErrorStats) -> str:
    return (
        f"{name:<13}{kind:<9}{s.rmse:>9.3f}{s.mae:>9.3f}{s.max_abs:>9.3f}{s.bias:>+10.3f}{s.n:>7}"
    )


@cli.command()
@_LOG_ARG
@click.option(
    "--truth",
    type=click.Choice(TRUTHS),
    default="auto",
    show_default=True,
    help="Measure against the simulator's SIM truth, or the EKF as a reference.",
)
@click.option(
    "--methods", default=",".join(FUSERS), show_default=True, help="Comma-separated methods to run."
)
@click.option(
    "--segments",
    help="Also per segment: a length in seconds (30) or boundaries on the log's clock (50.5,62.3).",
)
@click.option("-o", "--output", "json_path", type=_PATH, help="Write the report as JSON.")
@click.option("--csv", "csv_path", type=_PATH, help="Write the report as CSV.")
@_pipeline_options
@_plot_option
@_force_option
def evaluate(
    log: Path,
    truth: str,
    methods: str,
    segments: str | None,
    json_path: Path | None,
    csv_path: Path | None,
    plot_path: Path | None,
    force: bool,
    **options: Any,
) -> None:
    """Measure every method, every sensor and the onboard EKF against the truth in LOG.

    The truth is the simulator's SIM altitude when the log has it; otherwise the autopilot's EKF
    height stands in, labelled as a reference. Errors are in metres: RMSE, mean absolute error,
    maximum absolute error and bias (mean of estimate - truth).

    \b
    Example:
      altfuse evaluate sim.bin
      altfuse evaluate flight.bin --methods support,mean --segments 30 -o report.json
      altfuse evaluate flight.bin --plot flight.png --csv report.csv
    """
    if plot_path is not None:
        check_plot_path(plot_path)
    _refuse_existing(force, json_path, csv_path, plot_path)
    chosen = [m.strip() for m in methods.split(",") if m.strip()]
    result = evaluate_log(log, chosen, FuseOptions(**options), truth, segments)
    t = result.prepared.referred.t
    click.echo(
        f"{log.name}: measured against {result.truth.label}, {t.size} ticks "
        f"({t[0]:.1f}-{t[-1]:.1f} s), errors in m"
    )
    header = f"{'name':<13}{'kind':<9}{'RMSE':>9}{'MAE':>9}{'max':>9}{'bias':>10}{'n':>7}"
    click.echo(header)
    for row in result.rows:
        click.echo(_stats_line(row.name, row.kind, row.overall))
    for label in result.segments:
        click.echo(f"segment {label}:")
        for row in result.rows:
            click.echo(_stats_line(row.name, row.kind, row.segments[label]))
    for method, why in result.failed.items():
        click.echo(f"not run: {method}: {why}")
    with atomic_outputs() as stage:
        if json_path is not None:
            stage(json_path, write_json(result.as_dict()))
        if csv_path is not None:
            stage(csv_path, lambda f: evaluation_table(result).to_csv(f, index=False))
        if plot_path is not None and result.runs:
            fused = {m: r.result.fused for m, r in result.runs.items()}
            best = result.best()
            title = f"{log.name}: {', '.join(fused)} (weights: {best}, the lowest RMSE)"
            fig = run_figure(result.runs[best], fused, result.truth, title)
            stage(plot_path, writer(fig, plot_path), binary=True)


class _Progress:
    """done / failed / remaining / ETA on one line of stderr, only when stderr is a terminal."""

    def __init__(self) -> None:
        self.enabled = sys.stderr.isatty()
        self.started = time.monotonic()
        self.done = self.failed = 0

    def __call__(self, result: LogResult, total: int) -> None:
        self.done += 1
        self.failed += result.status == "failed"
        if not self.enabled:
            return
        elapsed = time.monotonic() - self.started
        left = total - self.done
        eta = elapsed / self.done * left
        click.echo(
            f"\rdone {self.done}/{total}, failed {self.failed}, remaining {left}, "
            f"ETA {int(eta) // 60}:{int(eta) % 60:02d}  ",
            err=True,
            nl=left == 0,
        )


@cli.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="The folder for every log's outputs (mirroring the input tree) and summary.csv.",
)
@click.option(
    "--pattern",
    default="*.bin",
    show_default=True,
    help="File names to take, whatever their case (.bin and .BIN).",
)
@click.option(
    "-j",
    "--jobs",
    type=int,
    default=None,
    help="Logs run at once in local processes [default: the number of cores].",
)
@click.option("--scheduler", help="Run on this Dask scheduler (tcp://host:8786) instead.")
@click.option(
    "--skip-existing",
    is_flag=True,
    help="Skip logs whose outputs are complete for this input and these options.",
)
@_METHOD
@_pipeline_options
@click.option("--weights", is_flag=True, help="Also write each log's weight traces.")
@click.option(
    "--plot",
    "plot_format",
    type=click.Choice(["png", "svg"]),
    help="Also draw each log's figure in this format.",
)
@click.option(
    "--evaluate",
    "with_evaluation",
    is_flag=True,
    help="Also evaluate every method on each log (metrics in the summary).",
)
@_force_option
def batch(
    paths: tuple[Path, ...],
    output: Path,
    pattern: str,
    jobs: int | None,
    scheduler: str | None,
    skip_existing: bool,
    method: str,
    weights: bool,
    plot_format: str | None,
    with_evaluation: bool,
    force: bool,
    **options: Any,
) -> None:
    """Fuse every log under PATHS (folders searched recursively) into OUTPUT, in parallel.

    Each log's outputs go under OUTPUT, mirroring the input tree; OUTPUT/summary.csv has one row
    per log: status (ok, skipped, failed), the error, duration, sensors, samples, and with
    --evaluate each method's RMSE and maximum error. Exit code 0 when every log succeeded, 4 when
    some failed.

    \b
    Example:
      altfuse batch logs/ -o results/
      altfuse batch logs/ more/flight.bin -o results/ --jobs 2 --evaluate --plot png
      altfuse batch logs/ -o results/ --skip-existing
      altfuse batch logs/ -o results/ --scheduler tcp://10.0.0.5:8786
    """
    settings = BatchOptions(
        fuse=FuseOptions(method=method, **options),
        weights=weights,
        plot=plot_format,
        evaluate=with_evaluation,
        skip_existing=skip_existing,
        force=force,
    )
    progress = _Progress()
    results = run_batch(
        paths, output, settings, pattern=pattern, jobs=jobs, scheduler=scheduler, on_result=progress
    )
    counts = {s: sum(r.status == s for r in results) for s in ("ok", "skipped", "failed")}
    click.echo(
        f"{output / SUMMARY}: {len(results)} logs, "
        + ", ".join(f"{k} {v}" for k, v in counts.items())
    )
    if counts["failed"]:
        sys.exit(EXIT_PARTIAL)


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
    click.echo(
        f"dropped samples: {summary['samples_dropped_total']} (by the reader's filters and as "
        f"implausible: {sum(summary['implausible_samples'].values())})"
    )
    for note in summary["notes"]:
        click.echo(f"note: {note}")


@cli.command()
@click.argument("scenario", type=click.Choice(list(SCENARIOS)))
@_output_option("The DataFlash log to write.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
@click.option(
    "--duration",
    "duration_s",
    type=float,
    default=None,
    help="Flight duration [s] [default: the scenario's].",
)
@click.option(
    "--fault",
    "faults",
    type=click.Choice(FAULTS),
    multiple=True,
    help="Add a fault (repeatable).",
)
@_force_option
def simulate(
    scenario: str,
    output: Path,
    seed: int,
    duration_s: float | None,
    faults: tuple[str, ...],
    force: bool,
) -> None:
    """Write a simulated SCENARIO flight as a DataFlash log, with the truth in SIM records.

    \b
    Scenarios:
      paper-a  Paper A's experiment: level flight near 15 m, the barometer
               departing, then every sensor scattering (75 s)
      hover    Paper B's experiment: a climb to 240 m and a hover (180 s)
      mission  take-off, climb, cruise over hills, landing (120 s)

    GPS (5 Hz, 0.2 s lag, AMSL), barometer (20 Hz, drifting with temperature), rangefinder
    (20 Hz, Stat and out-of-range codes), IMU (50 Hz, biased) and attitude (10 Hz).

    \b
    Example:
      altfuse simulate mission -o mission.bin --seed 1 --duration 180
      altfuse simulate hover -o hover.bin --fault gps-glitch --fault lose-baro
    """
    _refuse_existing(force, output)
    flight = simulate_flight(scenario, seed=seed, duration_s=duration_s, faults=faults)
    n = write_simulated_log(flight, output)
    click.echo(f"{output}: {scenario}, {n} records, {flight.duration_s:g} s, seed {seed}")


def main() -> None:
    cli()
