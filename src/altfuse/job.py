"""The jobs as library calls: a log to a table (:func:`fuse_file`), a log to its files
(:func:`fuse_to_files`; :func:`run_to_files`, what ``altfuse fuse`` and each log of ``altfuse
batch`` run)."""

from __future__ import annotations

import logging
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from altfuse.evaluation import Evaluation, evaluate_prepared, truth_or_none
from altfuse.fuse import DEFAULT_METHOD, method, params_for
from altfuse.memory import release_free_memory
from altfuse.model import FlightLog, brief_repr
from altfuse.params import fields
from altfuse.pipeline import (
    FuseOptions,
    FuseRun,
    fuse_log,
    fusion_input,
    prepare_log,
    progress,
    run_method,
)
from altfuse.plot import check_plot_path, run_figure, writer
from altfuse.write import (
    STDOUT,
    OutputError,
    Writer,
    check_json_path,
    check_paths,
    check_table_path,
    default_meta_path,
    fused_table,
    refuse_existing,
    write_json,
    write_outputs,
)

if TYPE_CHECKING:
    import pandas as pd

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Outputs:
    """Where one run's files go: the fused CSV, its provenance sidecar (default: beside the CSV
    as ``NAME.meta.json``) and, where given, the weight traces, the figure (``.png`` or
    ``.svg``) and the evaluation report (JSON)."""

    csv: Path
    meta: Path | None = None
    weights: Path | None = None
    plot: Path | None = None
    evaluation: Path | None = None

    def __post_init__(self) -> None:
        if self.plot is not None:
            check_plot_path(self.plot)

    @property
    def meta_path(self) -> Path | None:
        """The sidecar's path: ``meta``, else beside the table (none beside standard output)."""
        return self.meta or default_meta_path(self.csv)

    def paths(self) -> list[Path]:
        """Every file this run writes: not the table where it goes to standard output."""
        table = None if self.csv == STDOUT else self.csv
        optional = (table, self.meta_path, self.weights, self.plot, self.evaluation)
        return [p for p in optional if p is not None]

    def refuse(self, log_path: Path, force: bool = False, remedy: str = "--force") -> None:
        """Refuse outputs that would overwrite the input log or each other, tables named as
        another format (:func:`altfuse.write.check_table_path`), a sidecar named as one
        (:func:`altfuse.write.check_json_path`), existing files unless
        ``force`` (:func:`altfuse.write.check_paths`; ``remedy``: what sets it, for the
        message), and a table for a standard output that is closed (``-o - >&-``: Python's
        ``sys.stdout`` is None)."""
        if self.csv == STDOUT and sys.stdout is None:
            raise OutputError("-: standard output is closed; name a file with -o")
        check_paths(self.paths(), [log_path])
        for table in (self.csv, self.weights):
            if table is not None:
                check_table_path(table)
        if self.meta is not None:
            check_json_path(self.meta)
        refuse_existing(force, *self.paths(), remedy=remedy)


@dataclass(frozen=True)
class FileRun:
    """A run written to files: the run (its log without the samples beside the altitude
    sources where nothing drew or evaluated it: :meth:`FlightLog.sensors_only`), its evaluation
    (when asked for) and the files by role (``csv``, ``meta``, ``weights``, ``png``/``svg``,
    ``json``)."""

    __repr__ = brief_repr

    run: FuseRun
    evaluation: Evaluation | None
    written: dict[str, str]


def fuse_to_files(
    path: str | Path,
    outputs: Outputs,
    options: FuseOptions | None = None,
    label: str | None = None,
    overwrite: bool = True,
) -> FileRun:
    """Read, fuse and write one log: the CSV, the sidecar and the optional files, all or none
    (:func:`run_to_files`). Outputs that would overwrite the log or each other, and tables
    named as another format, are refused before the log is read (:meth:`Outputs.refuse`);
    existing files are replaced unless ``overwrite`` is False."""
    outputs.refuse(Path(path), force=overwrite, remedy="overwrite=True")
    return run_to_files(path, outputs, options, label)


def run_to_files(
    path: str | Path,
    outputs: Outputs,
    options: FuseOptions | None = None,
    label: str | None = None,
) -> FileRun:
    """:func:`fuse_to_files` for a caller that has refused its outputs itself: ``altfuse fuse``
    (:meth:`Outputs.refuse`, before its warnings) and each log of a batch (whose outputs it
    names and checks as a whole).

    ``label`` names the log in the figure's title (default: its file name). With
    ``outputs.evaluation``, every method is evaluated too (the run made here is reused for its
    own method).
    """
    options = options or FuseOptions()
    prepared = prepare_log(path, options)
    inputs = None
    if outputs.evaluation is None:  # no other method to run: the raw IMU and attitude go
        inputs = fusion_input(prepared, method(options.method), options.method)
        prepared = prepared.without_inertial()
    run = run_method(prepared, options, inputs)
    del inputs
    extra: dict[Path, tuple[Writer, bool]] = {}
    evaluation = None
    if outputs.evaluation is not None:
        evaluation = evaluate_prepared(prepared, options=options, done=[run])
        extra[outputs.evaluation] = (write_json(evaluation.as_dict()), False)
    if outputs.plot is not None:
        truth = evaluation.truth if evaluation else truth_or_none(run.log, run.referred)
        title = f"{label or Path(path).name}: {options.method}"
        fig = run_figure(run, {options.method: run.result.fused}, truth, title)
        extra[outputs.plot] = (writer(fig, outputs.plot), True)
    if outputs.evaluation is None and outputs.plot is None:
        run = replace(run, log=run.log.sensors_only())  # nothing reads the rest again
    del prepared
    release_free_memory()  # what the method freed, before the writers (pyarrow: 25 MB itself)
    started = time.perf_counter()
    progress.info("writing %s", outputs.csv.name)
    written = write_outputs(run, outputs.csv, outputs.weights, outputs.meta, extra)
    log.info("wrote the outputs in %.2f s", time.perf_counter() - started)
    return FileRun(run, evaluation, written)


def fuse_file(
    path: str | Path | FlightLog,
    method: str = DEFAULT_METHOD,
    *,
    time_index: bool = False,
    **values: Any,
) -> pd.DataFrame:
    """The fused table of the log at ``path`` (or of the one given, already read), as ``altfuse
    fuse`` writes it to CSV.

    ``values`` are the pipeline's options (:class:`FuseOptions`: ``rate_hz``, ``max_gap_s``, ...)
    and the method's parameters (``alpha_per_m2`` for ``support``, ...), by name. Columns:
    ``time_s`` [s since boot], ``alt_<sensor>_m``, ``fused_alt_m``, ``status``, ``weight_<sensor>``
    and the method's own (see :func:`altfuse.write.fused_table`). With ``time_index`` the rows
    are also indexed by that time as a ``TimedeltaIndex`` named ``time``, for pandas' resampling
    and time-based selection.
    """
    import pandas as pd

    pipeline = {f.name for f in fields(FuseOptions)}
    params = params_for(method, {k: v for k, v in values.items() if k not in pipeline})
    options = FuseOptions(
        method=method,
        params={method: params},
        **{k: v for k, v in values.items() if k in pipeline},
    )
    table = fused_table(fuse_log(path, options))
    if time_index:
        table.index = pd.TimedeltaIndex(pd.to_timedelta(table["time_s"], unit="s"), name="time")
    return table
