"""Many logs: ``altfuse batch`` as a library function.

:func:`run_batch` finds the logs under the given folders and files, fuses each with the same
options (optionally evaluating it and drawing its figure), writes each log's outputs under the
output folder mirroring the input tree, and a ``summary.csv``. One bad log never stops the batch:
its row says why it failed. Logs run in local processes (``jobs``) or on a Dask cluster
(``scheduler``); every log's outputs are the same bytes either way.

Resuming: temporary files left by an interrupted run are removed at the start; with
``skip_existing``, a log whose provenance sidecar exists, names the input's current
sha256 and the same options, and whose listed outputs all exist, is not run again. Each log's
outputs are written all-or-nothing with the sidecar renamed last, so an interrupted batch leaves
complete sets or nothing.
"""

from __future__ import annotations

import fnmatch
import json
import os
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal, get_args

import pandas as pd

from altfuse.errors import AltfuseError, LogReadError, ParameterError
from altfuse.io import sha256_of
from altfuse.job import Outputs, fuse_to_files
from altfuse.params import InvalidParameter
from altfuse.pipeline import FuseOptions
from altfuse.write import atomic_outputs

SUMMARY = "summary.csv"
#: Exit code of a batch in which some logs failed (0: all ok; 1/2: the batch itself could not run).
EXIT_PARTIAL = 4


PlotFormat = Literal["png", "svg"]
#: A log's outcome in the summary.
Outcome = Literal["ok", "skipped", "failed"]


@dataclass(frozen=True)
class BatchOptions:
    """What every log of a batch is run with; checked when built. With ``evaluate``, every
    method is evaluated with its parameters in ``fuse.params`` (or its defaults)."""

    fuse: FuseOptions = field(default_factory=FuseOptions)
    weights: bool = False
    plot: PlotFormat | None = None
    evaluate: bool = False
    skip_existing: bool = False
    force: bool = False

    def __post_init__(self) -> None:
        if self.plot is not None and self.plot not in get_args(PlotFormat):
            raise InvalidParameter("plot", f"must be one of png, svg, got {self.plot!r}")


@dataclass(frozen=True)
class Job:
    """One log: where it is, and where its outputs go (``stem`` + suffixes)."""

    log: Path
    relative: Path
    stem: Path

    def outputs(self, options: BatchOptions) -> Outputs:
        return Outputs(
            csv=self._with(".csv"),
            meta=self._with(".meta.json"),
            weights=self._with(".weights.csv") if options.weights else None,
            plot=self._with(f".{options.plot}") if options.plot else None,
            evaluation=self._with(".evaluation.json") if options.evaluate else None,
        )

    def _with(self, suffix: str) -> Path:
        return self.stem.with_name(self.stem.name + suffix)


@dataclass(frozen=True)
class LogResult:
    """One row of the summary."""

    log: str
    status: Outcome  # "skipped": complete outputs found
    error: str = ""
    duration_s: float = 0.0
    sensors: str = ""
    samples: int = 0
    diverged: int = 0  # ticks whose fused value left every sensor (altfuse.guard)
    truth: str = ""
    metrics: dict[str, float | None] = field(default_factory=dict)


def find_logs(paths: Sequence[str | Path], pattern: str = "*.bin") -> list[tuple[Path, Path]]:
    """(log, path relative to its input folder) for every file matching ``pattern``, without
    regard to case, under ``paths`` (folders searched recursively; files taken as given)."""
    found: dict[Path, Path] = {}
    seen: set[Path] = set()
    for raw in paths:
        root = Path(raw)
        if root.is_file():
            candidates: Iterable[tuple[Path, Path]] = [(root, Path(root.name))]
        elif root.is_dir():
            candidates = (
                (p, p.relative_to(root))
                for p in sorted(root.rglob("*"))
                if p.is_file()
                and not p.name.startswith(".")
                and fnmatch.fnmatch(p.name.lower(), pattern.lower())
            )
        else:
            raise LogReadError(f"{root}: no such file or folder")
        for log, relative in candidates:
            if log.resolve() in seen:
                continue
            seen.add(log.resolve())
            if relative in found:
                raise ParameterError(
                    f"{found[relative]} and {log} would write the same outputs ({relative}); "
                    "give the folders separately"
                )
            found[relative] = log
    return [(log, relative) for relative, log in sorted(found.items())]


def remove_stale_temporaries(out_dir: Path) -> int:
    """Delete the hidden ``.NAME.*.tmp`` files an interrupted run left behind; return the count."""
    stale = [p for p in out_dir.rglob(".*.tmp") if p.is_file()] if out_dir.is_dir() else []
    for path in stale:
        path.unlink(missing_ok=True)
    return len(stale)


def plan(paths: Sequence[str | Path], out_dir: str | Path, pattern: str = "*.bin") -> list[Job]:
    """The jobs of a batch: each log with its output stem under ``out_dir``."""
    out = Path(out_dir)
    return [
        Job(log, relative, out / relative.with_suffix(""))
        for log, relative in find_logs(paths, pattern)
    ]


def is_complete(job: Job, options: BatchOptions) -> bool:
    """Whether ``job``'s outputs exist, complete, for the input as it is now and these options."""
    outputs = job.outputs(options)
    meta = outputs.meta_path
    if not all(p.exists() for p in outputs.paths()):
        return False
    try:
        record = json.loads(meta.read_text(encoding="utf-8"))
        same_input = record["input"]["sha256"] == sha256_of(job.log)
        same_options = record.get("options") == asdict(options.fuse)
        listed = [meta.parent / p for p in record["outputs"].values()]
    except (OSError, ValueError, KeyError, TypeError):
        return False
    return same_input and same_options and all(p.exists() for p in listed)


def process(job: Job, options: BatchOptions) -> LogResult:
    """Run one log and write its outputs; never raises for a bad log (its row says why)."""
    started = time.perf_counter()
    name = str(job.relative)
    if options.skip_existing and is_complete(job, options):
        return LogResult(name, "skipped", duration_s=time.perf_counter() - started)
    outputs = job.outputs(options)
    existing = [p for p in outputs.paths() if p.exists()]
    if existing and not options.force:
        message = (
            f"{existing[0]} exists; --force overwrites, --skip-existing keeps complete outputs"
        )
        return LogResult(name, "failed", message, time.perf_counter() - started)
    try:
        done = fuse_to_files(job.log, outputs, options.fuse, label=str(job.relative))
        metrics: dict[str, float | None] = {}
        label = ""
        if done.evaluation is not None:
            truth = done.evaluation.truth
            label = truth.source + (" (reference)" if truth.is_reference else "")
            for row in done.evaluation.rows:
                stats = row.overall.as_dict()
                metrics[f"{row.name}_rmse"] = stats["rmse"]
                metrics[f"{row.name}_max"] = stats["max_abs"]
            for method, found in done.evaluation.diverged().items():
                metrics[f"{method}_diverged"] = found["diverged_ticks"]
        run = done.run
        return LogResult(
            name,
            "ok",
            duration_s=time.perf_counter() - started,
            sensors=" ".join(run.referred.names),
            samples=int(run.referred.t.size),
            diverged=int(run.provenance["guard"]["diverged_ticks"]),
            truth=label,
            metrics=metrics,
        )
    except AltfuseError as exc:
        return LogResult(name, "failed", str(exc), time.perf_counter() - started)
    except Exception as exc:  # a bug must not stop the batch either; the row names it
        message = f"internal error: {type(exc).__name__}: {exc}"
        return LogResult(name, "failed", message, time.perf_counter() - started)


def _local(jobs: list[Job], options: BatchOptions, workers: int) -> Iterator[LogResult]:
    if workers <= 1:
        for job in jobs:
            yield process(job, options)
        return
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(process, job, options) for job in jobs]
        for future in as_completed(futures):
            yield future.result()


def _dask(jobs: list[Job], options: BatchOptions, scheduler: str) -> Iterator[LogResult]:
    try:
        from dask.distributed import Client
        from dask.distributed import as_completed as dask_completed
    except ImportError as exc:
        raise ParameterError(
            "--scheduler needs dask.distributed: pip install 'altfuse[dask]'"
        ) from exc
    try:
        client = Client(scheduler, timeout="10s")  # type: ignore[no-untyped-call]
    except (OSError, TimeoutError) as exc:
        raise ParameterError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from exc
    with client:
        futures = client.map(process, jobs, options=options, pure=False)
        for future in dask_completed(futures):  # type: ignore[no-untyped-call]
            yield future.result()


def write_summary(results: Iterable[LogResult], path: Path) -> None:
    """``summary.csv``: one row per log, sorted by log, metrics as columns."""
    rows = []
    for r in sorted(results, key=lambda r: r.log):
        row: dict[str, Any] = {k: v for k, v in asdict(r).items() if k != "metrics"}
        row["duration_s"] = round(r.duration_s, 3)
        row.update(r.metrics)
        rows.append(row)
    columns = ["log", "status", "error", "duration_s", "sensors", "samples", "diverged", "truth"]
    table = pd.DataFrame.from_records(rows)
    table = table.reindex(columns=columns + [c for c in table.columns if c not in columns])
    with atomic_outputs() as stage:
        stage(path, lambda f: table.to_csv(f, index=False, float_format="%.6f"))


def run_batch(  # noqa: PLR0913 (keyword-only beyond the first three: the CLI's options)
    paths: Sequence[str | Path],
    out_dir: str | Path,
    options: BatchOptions | None = None,
    *,
    pattern: str = "*.bin",
    jobs: int | None = None,
    scheduler: str | None = None,
    on_result: Callable[[LogResult, int], None] | None = None,
) -> list[LogResult]:
    """Run every log under ``paths`` into ``out_dir``; return one result per log.

    ``on_result(result, total)`` is called as each log finishes (for progress).
    """
    options = options or BatchOptions()
    workers = (os.cpu_count() or 1) if jobs is None else jobs
    if workers < 1:
        raise InvalidParameter("jobs", f"must be at least 1, got {workers}")
    todo = plan(paths, out_dir, pattern)
    if not todo:
        raise LogReadError(f"no file matching {pattern!r} under {', '.join(map(str, paths))}")
    out = Path(out_dir)
    remove_stale_temporaries(out)
    results = []
    stream = _dask(todo, options, scheduler) if scheduler else _local(todo, options, workers)
    for result in stream:
        results.append(result)
        if on_result is not None:
            on_result(result, len(todo))
    write_summary(results, out / SUMMARY)
    return results
