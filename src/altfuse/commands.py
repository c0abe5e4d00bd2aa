"""The ``altfuse`` commands (the group, its errors and its lazy loading are :mod:`altfuse.cli`'s):
each parses its options, calls the library and prints; nothing else prints."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import math
import os
import shutil
import sys
import time
import typing
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, Literal, get_args

import click
from click.core import ParameterSource

from altfuse.batch import (
    EXIT_PARTIAL,
    LOG_PATTERNS,
    BatchOptions,
    LogResult,
    Outcome,
    PlotFormat,
    doubted,
    run_batch,
    summary_name,
    unused,
)
from altfuse.evaluation import TRUTHS, Evaluation, TruthChoice, method_names
from altfuse.evaluation import evaluate as evaluate_log
from altfuse.files import is_stream
from altfuse.fuse import DEFAULT_METHOD, METHODS, params_by_method
from altfuse.info import as_text, damage, describe
from altfuse.io import read_log
from altfuse.job import Outputs, run_to_files
from altfuse.metrics import ErrorStats
from altfuse.model import counted
from altfuse.params import UNIT_SUFFIXES, InvalidParameter, fields, flag_of, hints, unit_of
from altfuse.pipeline import FuseOptions
from altfuse.plot import check_plot_path, run_figure, writer
from altfuse.simulate import FAULTS, SCENARIOS, simulate_flight, write_simulated_log
from altfuse.write import (
    STDOUT,
    TableFormat,
    atomic_outputs,
    check_json_path,
    check_paths,
    check_table_path,
    refuse_existing,
    write_json,
)


def flag_for(name: str) -> str:
    """The flag of the option a library parameter ``name`` comes from: a parameter field's, or
    the name less its unit (``duration_s``: ``--duration``)."""
    for cls in (FuseOptions, *(m.params for m in METHODS.values())):
        for f in fields(cls):
            if f.name == name:
                return flag_of(f)
    stem = next(
        (name.removesuffix(s) for s in UNIT_SUFFIXES.values() if s and name.endswith(s)), name
    )
    return "--" + stem.replace("_", "-")


class _AutoFloat(click.ParamType):  # type: ignore[type-arg]
    """A number, or ``auto`` (None: the library chooses it from the data)."""

    name = "auto|FLOAT"

    def convert(self, value: Any, param: Any, ctx: Any) -> float | None:
        if value is None or isinstance(value, float):
            return value
        if str(value).lower() == "auto":
            return None
        try:
            return float(value)
        except ValueError:
            self.fail(f"{value!r} is neither 'auto' nor a number", param, ctx)


class _Shard(click.ParamType):  # type: ignore[type-arg]
    """``I/N``: the I-th of N shards (1-based)."""

    name = "I/N"

    def convert(self, value: Any, param: Any, ctx: Any) -> tuple[int, int]:
        if isinstance(value, tuple):
            return value
        i, slash, n = str(value).partition("/")
        try:
            shard = int(i), int(n)
        except ValueError:
            shard = (0, 0)
        if not slash or not 1 <= shard[0] <= shard[1]:
            self.fail(f"{value!r} is not I/N with 1 <= I <= N (such as 2/8)", param, ctx)
        return shard


class _NameValue(click.ParamType):  # type: ignore[type-arg]
    """``NAME=NUMBER``, one value of a per-sensor parameter."""

    def __init__(self, unit: str) -> None:
        self.name = f"NAME={unit.upper() or 'NUMBER'}"

    def convert(self, value: Any, param: Any, ctx: Any) -> tuple[str, float]:
        if isinstance(value, tuple):
            return value
        name, _, number = str(value).partition("=")
        try:
            return name.strip(), float(number)
        except ValueError:
            self.fail(f"{value!r} is not {self.name}", param, ctx)


def _click_type(hint: Any, unit: str) -> tuple[Any, bool]:
    """The click type of a parameter field's type, and whether the option repeats."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is Literal:
        return click.Choice([str(a) for a in args]), False
    if origin in (Mapping, dict):
        return _NameValue(unit), True
    if type(None) in args:
        return _AutoFloat(), False
    return (click.INT if hint is int else click.FLOAT), False


def _default_text(f: dataclasses.Field[Any]) -> str:
    if f.metadata["default_text"]:
        return str(f.metadata["default_text"])
    return f"{f.default:g}" if isinstance(f.default, float) else str(f.default)


def _option_spec(
    f: dataclasses.Field[Any], hint: Any, help_text: str, defaults: bool
) -> tuple[list[str], dict[str, Any]]:
    """The declarations and attributes of a parameter field's option: with ``defaults``, it
    defaults to the field's default and shows it; without, it defaults to "not given"."""
    kind, repeats = _click_type(hint, unit_of(f))
    attrs: dict[str, Any] = {"type": kind, "multiple": repeats, "help": help_text}
    if defaults:
        attrs.update(default=() if repeats else f.default, show_default=True)
    return [flag_of(f), *f.metadata.get("aliases", ()), f.name], attrs


class _Option(click.Option):
    """An option whose help shows its first flag only: the others are older names, still
    taken (``--q`` for ``--process-noise``)."""

    def get_help_record(self, ctx: click.Context) -> tuple[str, str] | None:
        shown, self.opts = self.opts, self.opts[:1]
        try:
            return super().get_help_record(ctx)
        finally:
            self.opts = shown


def _method_parameter_options() -> list[click.Option]:
    """One option per parameter field of the registered methods (methods sharing a field share
    its option, the help naming each one's default); passed on only when given."""
    users: dict[str, list[tuple[str, dataclasses.Field[Any], Any]]] = {}
    for name, method in METHODS.items():
        types = hints(method.params)
        for f in fields(method.params):
            users.setdefault(f.name, []).append((name, f, types[f.name]))
    options: list[click.Option] = []
    for field_name, used in users.items():
        _, first, hint = used[0]
        if any(h != hint or unit_of(f) != unit_of(first) for _, f, h in used):
            raise TypeError(f"methods disagree on the type or unit of {field_name!r}")
        by_default: dict[str, list[str]] = {}
        for name, f, _ in used:
            by_default.setdefault(_default_text(f), []).append(name)
        unit = f" [{unit_of(first)}]" if unit_of(first) else ""
        (text, names), *rest = by_default.items()
        said = [f"{', '.join(names)}: {first.metadata['help']}{unit} [default: {text}]"]
        said += [f"{', '.join(names)} [default: {text}]" for text, names in rest]
        decls, attrs = _option_spec(first, hint, "; ".join(said) + ".", defaults=False)
        if attrs["multiple"]:
            attrs["help"] += " Repeatable."
        options.append(_Option(decls, **attrs))
    return options


class _MethodCommand(click.Command):
    """A command whose method options come from ``METHODS`` as it is when the command runs:
    a method registered after import gets its ``--method`` choice and its options."""

    def __init__(self, *args: Any, choose: Literal["one", "many"], **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.choose = choose

    def get_params(self, ctx: click.Context) -> list[click.Parameter]:
        *own, help_option = super().get_params(ctx)
        chooser: list[click.Parameter] = []
        if self.choose == "one":
            chooser.append(
                click.Option(
                    ["-m", "--method"],
                    type=click.Choice(list(METHODS)),
                    default=DEFAULT_METHOD,
                    show_default=True,
                    help="Fusion method.",
                )
            )
        arguments = [p for p in own if isinstance(p, click.Argument)]
        options = [p for p in own if not isinstance(p, click.Argument)]
        return [*arguments, *chooser, *options, *_method_parameter_options(), help_option]


def _method_values(options: dict[str, Any]) -> dict[str, Any]:
    """Pop the method parameters from a command's ``options``: those given, by field name."""
    ctx = click.get_current_context()
    values = {}
    for option in _method_parameter_options():
        name = str(option.name)
        value = options.pop(name, None)
        if ctx.get_parameter_source(name) not in (ParameterSource.DEFAULT, None):
            values[name] = _once_each(name, value) if option.multiple else value
    return values


def _once_each(name: str, pairs: tuple[tuple[str, float], ...]) -> dict[str, float]:
    """A repeated ``NAME=NUMBER`` option's values by name; a name given two values is
    refused (the last silently won)."""
    out: dict[str, float] = {}
    for key, number in pairs:
        if out.setdefault(key, number) != number:
            raise InvalidParameter(name, f"gives {key} twice ({out[key]:g} and {number:g})")
    return out


class _GivenPath(click.Path):
    """A path that names something: an empty one (``-o "$OUT"`` with OUT unset) was the current
    folder, and ``batch -o ""`` wrote its outputs there; ``fuse -o ""`` failed inside."""

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        if not str(value).strip():
            self.fail("an empty path; name a file or folder", param, ctx)
        return super().convert(value, param, ctx)


class _OutputPath(_GivenPath):
    """An output's path, refused where it is an option: ``--weights --force`` wrote the weights
    to a file named ``--force`` and left the table it meant to overwrite (click takes the next
    word as the value, whatever it is). A file whose name begins with a dash: ``./-name``. A
    file's path that ends in a separator names a folder: ``-o results/`` wrote a file named
    ``results``."""

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        text = str(value)
        if text.startswith("-") and len(text) > 1 and (text[1].isalpha() or text[1] == "-"):
            self.fail(
                f"{text!r} is an option, not a file name (a file so named: ./{text})", param, ctx
            )
        if not self.dir_okay and text.endswith(("/", os.sep)):
            self.fail(f"{text!r} names a folder; name the file in it", param, ctx)
        return super().convert(value, param, ctx)


# a folder is taken: read_log says it is one, and points to batch
_LOG_ARG = click.argument("log", type=_GivenPath(path_type=Path))
_PATH = _OutputPath(dir_okay=False, path_type=Path)


def _output_option(help_text: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    return click.option("-o", "--output", type=_PATH, required=True, help=help_text)


def _pipeline_options(command: Callable[..., Any]) -> Callable[..., Any]:
    """The options every fusion run shares, from :class:`FuseOptions`' fields: clock, datum
    and the sensors required."""
    types = hints(FuseOptions)
    for f in reversed(fields(FuseOptions)):
        text = str(f.metadata["help"])
        unit = f" [{unit_of(f)}]" if unit_of(f) else ""
        decls, attrs = _option_spec(f, types[f.name], f"{text[0].upper()}{text[1:]}{unit}.", True)
        command = click.option(*decls, **attrs)(command)
    return command


def _force_option(command: Callable[..., Any]) -> Callable[..., Any]:
    return click.option("--force", is_flag=True, help="Overwrite existing outputs.")(command)


def _plot_option(command: Callable[..., Any]) -> Callable[..., Any]:
    return click.option(
        "--plot",
        "plot_path",
        type=_PATH,
        help="Also draw the sensors, the fused altitude and the weights (.png or .svg).",
    )(command)


@click.command(cls=_MethodCommand, choose="one")
@_LOG_ARG
@_output_option(
    "The fused table to write: CSV, or Parquet for a .parquet name (a CSV named .gz, .bz2 or "
    ".xz: compressed so); the provenance goes beside it as NAME.meta.json. '-': the CSV to "
    "standard output."
)
@_pipeline_options
@click.option(
    "--weights",
    "weights_path",
    type=_PATH,
    help="Also write the weight traces (the weights and each method's diagnostics): CSV, or "
    "Parquet for a .parquet name.",
)
@click.option(
    "--meta",
    "meta_path",
    type=_PATH,
    help="Where to write the provenance JSON [default: beside the fused table].",
)
@_plot_option
@_force_option
def fuse(
    log: Path,
    output: Path,
    weights_path: Path | None,
    meta_path: Path | None,
    plot_path: Path | None,
    force: bool,
    **options: Any,
) -> None:
    """Fuse the altitude sensors of LOG into one altitude, written as a table (CSV or Parquet).

    Each method's options apply to the methods their help names.

    \b
    Example:
      altfuse fuse flight.bin -o flight.csv
      altfuse fuse flight.bin -o flight.csv --method mean --rate 20
      altfuse fuse flight.bin -o flight.csv -m support --alpha 0.5 --beta 10 --weights w.csv
      altfuse fuse flight.bin -o flight.csv --method multilayer --plot flight.png
      altfuse fuse flight.bin -o flight.csv --method smoother --sigma gps=0.8
      altfuse fuse flight.bin -o flight.parquet --weights weights.parquet
    """
    method = options.pop("method")
    params = params_by_method(_method_values(options), [method])
    opts = FuseOptions(method=method, params=params, **options)
    outputs = Outputs(output, meta_path, weights_path, plot_path)
    outputs.refuse(log, force)
    streamed = output == STDOUT or is_stream(output)  # the table written into a stream
    say = logging.getLogger("altfuse")
    if outputs.meta_path is None:
        say.warning(
            "%s: the table goes to %s, without its provenance (--meta names a file)",
            log.name, "standard output" if output == STDOUT else output,
        )  # fmt: skip
    with _progress_line():
        done = run_to_files(log, outputs, opts)
    run = done.run
    for note in run.log.notes:
        say.info("%s", note)
    warning = damage(run.log)
    if warning:
        say.warning("%s", warning)
    if run.referred.dropped:
        say.warning("%s: %s", log.name, _left_out(run.referred.dropped))
    record = run.provenance["guard"]
    if record["diverged_ticks"]:
        lost = f", {record['lost_ticks']} of them without a value" if record["lost_ticks"] else ""
        say.warning(
            "%s: %s left every sensor on %s (by up to %.1f m%s): status 'diverged'",
            log.name, method, counted(record["diverged_ticks"], "tick"), record["max_excursion_m"],
            lost,
        )  # fmt: skip
    check = run.result.params.get("model_check", "passed")
    if check != "passed":
        say.warning("%s: %s's model check %s", log.name, method, check)
    if unused_here := run.result.params.get("not_used"):
        say.warning(
            "%s: not used, as this log does not have the sensors (its sensors: %s): %s",
            log.name, ", ".join(run.referred.names), unused_here,
        )  # fmt: skip
    counts = run.provenance["status_counts"]
    sidecar = done.written.get("meta", "none")
    if streamed and not say.isEnabledFor(logging.WARNING):
        return  # -q: only errors on stderr, where this line goes beside a streamed table
    click.echo(
        f"{'standard output' if output == STDOUT else output}: {run.referred.t.size} rows, "
        f"method {method}, sensors {', '.join(run.referred.names)}; "
        + ", ".join(f"{k} {v}" for k, v in counts.items())
        + f" (provenance: {sidecar})",
        err=streamed,  # the table itself may be on standard output (-, /dev/stdout)
    )


class _ProgressLine(logging.Handler):
    """The run's latest step on one line of stderr, overwritten by the next and cleared at the
    end (``altfuse.progress`` messages); none after the terminal is gone (:func:`_on_terminal`)."""

    def __init__(self) -> None:
        super().__init__()
        self.shown = True

    def emit(self, record: logging.LogRecord) -> None:
        if self.shown:
            text = f"altfuse: {record.getMessage()} ..."[: shutil.get_terminal_size().columns - 1]
            self.shown = _on_terminal(f"\r\033[K{text}")

    def close(self) -> None:
        if self.shown:
            _on_terminal("\r\033[K")
        super().close()


def _stderr_is_terminal() -> bool:
    """Whether stderr is a terminal: not where it is piped, nor where the process began with it
    closed (``2>&-``, a daemon's job: Python's ``sys.stderr`` is None)."""
    return sys.stderr is not None and sys.stderr.isatty()


def _on_terminal(text: str) -> bool:
    """Write a progress ``text`` to stderr, a terminal, at once; False where the terminal is
    gone. A job left running when its shell exited (``altfuse batch ... &``, then ``exit``: no
    SIGHUP) writes into a hung-up terminal, which fails (EIO): the progress line had ended the
    run there, a batch without its summary (its workers finishing every log) and a ``fuse``
    without its outputs, exit 1. Progress is no reason to stop."""
    try:
        sys.stderr.write(text)
        sys.stderr.flush()
    except OSError:
        return False
    return True


@contextlib.contextmanager
def _progress_line() -> Iterator[None]:
    """A progress line while a run lasts, where stderr is a terminal and neither -v (its steps
    are lines then) nor -q asks otherwise; nothing when stderr is piped."""
    shown = logging.getLogger("altfuse").getEffectiveLevel() == logging.WARNING
    if not (shown and _stderr_is_terminal()):
        yield
        return
    logger, handler = logging.getLogger("altfuse.progress"), _ProgressLine()
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(logging.NOTSET)
        logger.propagate = True
        handler.close()


_STATS_HEADER = ("name", "kind", "RMSE", "MAE", "max", "bias", "+-2std", "n")


def _stats_cells(name: str, kind: str, s: ErrorStats) -> list[str]:
    within = "-" if math.isnan(s.within_2std) else f"{s.within_2std:.3f}"
    return [name, kind, f"{s.rmse:.3f}", f"{s.mae:.3f}", f"{s.max_abs:.3f}", f"{s.bias:+.3f}",
            within, str(s.n)]  # fmt: skip


def _aligned(rows: list[list[str]]) -> list[str]:
    """Rows of cells as lines, each column as wide as its widest cell and two spaces apart at
    any magnitude: names to the left, numbers to the right."""
    widths = [max(len(r[j]) for r in rows) for j in range(len(rows[0]))]
    return [
        "  ".join(
            c.ljust(w) if j < 2 else c.rjust(w)
            for j, (c, w) in enumerate(zip(r, widths, strict=True))
        ).rstrip()
        for r in rows
    ]


@click.command(cls=_MethodCommand, choose="many")
@_LOG_ARG
@click.option(
    "--truth",
    type=click.Choice(TRUTHS),
    default="auto",
    show_default=True,
    help="Measure against the simulator's SIM truth, or the EKF as a reference.",
)
@click.option("--methods", help="Comma-separated methods to run [default: every method].")
@click.option(
    "--segments",
    help="Also per segment: a length in seconds (30) or boundaries on the log's clock (50.5,62.3).",
)
@click.option("-o", "--output", "json_path", type=_PATH, help="Write the report as JSON.")
@click.option("--csv", "csv_path", type=_PATH, help="Write the report as CSV.")
@_pipeline_options
@_plot_option
@_force_option
def evaluate(  # noqa: PLR0913 (one argument per option: click's way)
    log: Path,
    truth: TruthChoice,
    methods: str | None,
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
    maximum absolute error and bias (mean of estimate - truth); +-2std is the share of a
    method's errors within twice its own standard deviation (about 0.95 where that is right).

    \b
    Example:
      altfuse evaluate sim.bin
      altfuse evaluate flight.bin --methods support,mean --segments 30 -o report.json
      altfuse evaluate flight.bin --methods support --alpha 0.5
      altfuse evaluate flight.bin --plot flight.png --csv report.csv
    """
    if plot_path is not None:
        check_plot_path(plot_path)
    check_paths([json_path, csv_path, plot_path], [log])
    if csv_path is not None:
        check_table_path(csv_path, parquet=False)
    if json_path is not None:
        check_json_path(json_path)
    refuse_existing(force, json_path, csv_path, plot_path)
    named = None if methods is None else [m.strip() for m in methods.split(",") if m.strip()]
    chosen = method_names(named)
    params = params_by_method(_method_values(options), chosen)
    with _progress_line():
        result = evaluate_log(log, chosen, FuseOptions(params=params, **options), truth, segments)
    t = result.prepared.referred.t
    click.echo(
        f"{log.name}: measured against {result.truth.label}, {t.size} ticks "
        f"({t[0]:.1f}-{t[-1]:.1f} s), errors in m"
    )
    labels = [None, *result.segments]  # None: over the whole log
    cells = [list(_STATS_HEADER)] + [
        _stats_cells(r.name, r.kind, r.segments[label] if label else r.overall)
        for label in labels
        for r in result.rows
    ]
    header, *lines = _aligned(cells)  # one width per column across every section
    click.echo(header)
    n = len(result.rows)
    for k, label in enumerate(labels):
        if label:
            click.echo(f"segment {label}:")
        click.echo("\n".join(lines[k * n : (k + 1) * n]))
    for line in _verdicts(result):
        click.echo(line)
    with atomic_outputs() as stage:
        if json_path is not None:
            stage(json_path, write_json(result.as_dict()))
        if csv_path is not None:
            stage(csv_path, lambda f: result.table().to_csv(f, index=False))
        if plot_path is not None and result.runs:
            fused = {m: r.result.fused for m, r in result.runs.items()}
            best = result.best()
            title = f"{log.name}: {', '.join(fused)} (weights: {best}, the lowest RMSE)"
            fig = run_figure(result.runs[best], fused, result.truth, title)
            stage(plot_path, writer(fig, plot_path), binary=True)


def _left_out(dropped: dict[str, str]) -> str:
    """The altitude sources the log has with samples that could not be referred to the
    take-off, and why (a GPS of 5 Hz has no sample in a ground window of 0.2 s): a sensor
    gone from the table, which the summary line alone said."""
    return "left out: " + "; ".join(f"{name}: {why}" for name, why in dropped.items())


def _verdicts(result: Evaluation) -> list[str]:
    """What the table does not say: the sensors left out, the methods not run, those that
    diverged, those whose own model check failed, and values given for sensors this log does
    not have."""
    dropped = result.prepared.referred.dropped
    lines = [_left_out(dropped)] if dropped else []
    lines += [f"not run: {method}: {why}" for method, why in result.failed.items()]
    lines += [
        f"diverged: {method} left every sensor on {counted(found['diverged_ticks'], 'tick')} "
        f"(by up to {found['max_excursion_m']:.1f} m)"
        for method, found in result.diverged().items()
    ]
    checks = {m: r.result.params.get("model_check", "passed") for m, r in result.runs.items()}
    lines += [f"model check: {m} {c}" for m, c in checks.items() if c != "passed"]
    return lines + [
        f"not used by {m}, as this log does not have the sensors: {r.result.params['not_used']}"
        for m, r in result.runs.items()
        if "not_used" in r.result.params
    ]


class _Progress:
    """done / failed / remaining / ETA on one line of stderr, only when stderr is a terminal
    (and while it is there: :func:`_on_terminal`)."""

    def __init__(self) -> None:
        self.enabled = _stderr_is_terminal()
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
        self.enabled = _on_terminal(
            f"\rdone {self.done}/{total}, failed {self.failed}, remaining {left}, "
            f"ETA {int(eta) // 60}:{int(eta) % 60:02d}  " + ("\n" if left == 0 else "")
        )


@click.command(cls=_MethodCommand, choose="one")
@click.argument("paths", nargs=-1, required=True, type=_GivenPath(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=_OutputPath(file_okay=False, path_type=Path),
    required=True,
    help="The folder for every log's outputs (mirroring the input tree) and summary.csv.",
)
@click.option(
    "--pattern",
    multiple=True,
    default=LOG_PATTERNS,
    show_default=True,
    help="File names to take, whatever their case (.bin and .BIN); repeat it for several.",
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
@_pipeline_options
@click.option(
    "--shard",
    type=_Shard(),
    help="Only every N-th log of the sorted list, from the I-th: the N shards of a job array "
    "cover every log once (each writes summary.shard-I-of-N.csv).",
)
@click.option(
    "--format",
    "table_format",
    type=click.Choice(["csv", "parquet"]),
    default="csv",
    show_default=True,
    help="Format of each log's fused table (and weight traces); parquet writes "
    "summary.parquet beside summary.csv too.",
)
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
def batch(  # noqa: PLR0913 (one argument per option: click's way)
    paths: tuple[Path, ...],
    output: Path,
    pattern: tuple[str, ...],
    jobs: int | None,
    scheduler: str | None,
    skip_existing: bool,
    shard: tuple[int, int] | None,
    table_format: TableFormat,
    weights: bool,
    plot_format: PlotFormat | None,
    with_evaluation: bool,
    force: bool,
    **options: Any,
) -> None:
    """Fuse every log under PATHS (folders searched recursively) into OUTPUT, in parallel.

    Each log's outputs go under OUTPUT, mirroring the input tree; OUTPUT/summary.csv has one row
    per log: status (ok; refused: valid but not fusable, with the reason; skipped; failed: an
    error), the flight's and the processing's seconds, vehicle, sensors, the reader's notes,
    the share of ticks fused, divergences, and with --evaluate each method's RMSE and maximum
    error; the logs whose fused altitude left every sensor or failed its model check are named
    in one warning at the end. The method options are fuse's; with --evaluate they apply to
    every method evaluated that takes them. Run again over logs whose outputs are there, it asks
    for --skip-existing or --force. Exit code 0 when no log failed (refusals are not failures),
    4 when some failed, 1 or 2 when the batch itself cannot run.

    \b
    Example:
      altfuse batch logs/ -o results/
      altfuse batch logs/ more/flight.bin -o results/ --jobs 2 --evaluate --plot png
      altfuse batch logs/ -o results/ --skip-existing
      altfuse batch logs/ -o results/ --format parquet
      altfuse batch logs/ -o results/ --shard 3/8     # job 3 of an array of 8
      altfuse batch logs/ -o results/ -m support --alpha 0.5
      altfuse batch logs/ -o results/ --scheduler tcp://10.0.0.5:8786
    """
    method = options.pop("method")
    evaluated = list(METHODS) if with_evaluation else [method]
    params = params_by_method(_method_values(options), evaluated)
    settings = BatchOptions(
        fuse=FuseOptions(method=method, params=params, **options),
        format=table_format,
        weights=weights,
        plot=plot_format,
        evaluate=with_evaluation,
        skip_existing=skip_existing,
        force=force,
    )
    progress = _Progress()
    results = run_batch(
        paths,
        output,
        settings,
        pattern=pattern,
        jobs=jobs,
        scheduler=scheduler,
        on_result=progress,
        shard=shard,
    )
    counts = {s: sum(r.status == s for r in results) for s in get_args(Outcome)}
    look = doubted(results)
    for line in ([look] if look else []) + unused(results):
        logging.getLogger("altfuse").warning("%s", line)
    click.echo(
        f"{output / summary_name(shard)}: {counted(len(results), 'log')}, "
        + ", ".join(f"{k} {v}" for k, v in counts.items())
    )
    if counts["failed"]:
        sys.exit(EXIT_PARTIAL)


@click.command()
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
    for line in as_text(summary):
        click.echo(line)


@click.command()
@click.argument("scenario", type=click.Choice(list(SCENARIOS)))
@_output_option("The DataFlash log to write.")
@click.option(
    "--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Random seed (>= 0)."
)
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
      climb    a plane's: a climb to 300 m at up to 18 m/s, banked turns, a
               descent (150 s)

    GPS (5 Hz, 0.1-0.25 s lag, AMSL), barometer (20 Hz, drifting with temperature),
    rangefinder (20 Hz, Stat and out-of-range codes), IMU (50 Hz, biased, clipped at
    16 g) and attitude (10 Hz), every one 5-12 ms behind the truth (SIM); the lags are
    drawn per flight from the seed.

    \b
    Example:
      altfuse simulate mission -o mission.bin --seed 1 --duration 180
      altfuse simulate hover -o hover.bin --fault gps-glitch --fault lose-baro
    """
    check_paths([output])
    refuse_existing(force, output)
    flight = simulate_flight(scenario, seed=seed, duration_s=duration_s, faults=faults)
    n = write_simulated_log(flight, output)
    click.echo(f"{output}: {scenario}, {n} records, {flight.duration_s:g} s, seed {seed}")
