"""Many logs: ``altfuse batch`` as a library function.

:func:`run_batch` finds the logs under the given folders and files, fuses each with the same
options (optionally evaluating it and drawing its figure), writes each log's outputs under the
output folder mirroring the input tree, and a ``summary.csv`` (and ``summary.parquet`` with
Parquet tables). One bad log never stops the batch:
its row says why it failed. Logs run in local processes (``jobs``) or on a Dask cluster
(``scheduler``); every log's outputs are the same bytes either way.

One batch at a time writes to an output folder (a lock on the folder); an existing
``summary.csv`` is merged with this run's rows unless ``force``. Workers end with their parent.

Resuming: altfuse's temporary files left by an interrupted run are removed at the start; with
``skip_existing``, a log whose provenance sidecar exists, names the input's current
sha256 and the same options, and whose listed outputs all exist, is not run again (outputs it
could neither keep nor overwrite refuse the batch whole, told from the sidecars). Each log's
outputs are written all-or-nothing with the sidecar renamed last, so an interrupted batch leaves
complete sets or nothing.
"""

from __future__ import annotations

import contextlib
import ctypes
import fnmatch
import json
import logging
import multiprocessing
import os
import signal
import sys
import time
from collections.abc import Callable, Generator, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, NoReturn, get_args

from threadpoolctl import threadpool_limits

from altfuse import __version__
from altfuse.errors import AltfuseError, LogReadError, ParameterError, Refusal, out_of_memory
from altfuse.files import COMPRESSIONS, compression_named, stream_kind
from altfuse.io import sha256_of
from altfuse.job import FileRun, Outputs, run_to_files
from altfuse.memory import one_heap
from altfuse.model import counted
from altfuse.params import InvalidParameter
from altfuse.pipeline import FuseOptions
from altfuse.signals import (
    EXIT_TERMINATED,
    Terminated,
    interruption,
    raise_on_termination,
    watch_signals,
)
from altfuse.write import (
    TableFormat,
    atomic_outputs,
    remove_stale_temporaries,
    write_json,
    write_table,
)

if TYPE_CHECKING:
    import pandas as pd

SUMMARY = "summary.csv"
#: The logs a batch takes by default, whatever their case: DataFlash and ULog, as they are or
#: compressed (:data:`altfuse.files.COMPRESSIONS`).
LOG_PATTERNS = tuple(
    f"*{log}{packed}"
    for log in (".bin", ".ulg")
    for packed in ("", *(c.suffix for c in COMPRESSIONS))
)
#: DataFlash logs written as text (:mod:`altfuse.io.dataflash_text`): not taken by default (a
#: folder may hold a log as ``.bin`` and as the ``.log`` converted from it, and other
#: programs' logs), but with ``--pattern``.
TEXT_PATTERN = "*.log"
#: Zip archives, which a batch names where it finds no log: their logs are to be extracted
#: (:func:`altfuse.io.read_log` refuses an archive, naming what it holds).
ZIP_PATTERN = "*.zip"
#: The summary as Parquet too, with ``--format parquet``.
PARQUET_SUMMARY = "summary.parquet"
_PR_SET_PDEATHSIG = 1
#: How the workers start: forked on Linux, so that the batch is their parent and a killed
#: batch's workers end with it (``PR_SET_PDEATHSIG``, :func:`_worker_start`). Python 3.14's
#: default there is a fork server, their parent instead: each worker ended at its start (its
#: parent not the batch), and a killed batch's server and workers ran on (CPython's own).
#: Elsewhere the platform's default (macOS and Windows spawn them).
START_METHOD = "fork" if sys.platform.startswith("linux") else None
#: Exit code of a batch in which some logs failed (0: all ok; 1/2: the batch itself could not run).
EXIT_PARTIAL = 4


PlotFormat = Literal["png", "svg"]
#: A log's outcome in the summary.
#: ``refused``: the log is valid but not fusable (too few altitude sources, an ArduSub depth
#: log), not a failure; ``failed``: an error (unreadable, damaged, an output in the way, a bug).
Outcome = Literal["ok", "refused", "skipped", "failed"]


@dataclass(frozen=True)
class BatchOptions:
    """What every log of a batch is run with; checked when built. With ``evaluate``, every
    method is evaluated with its parameters in ``fuse.params`` (or its defaults)."""

    fuse: FuseOptions = field(default_factory=FuseOptions)
    format: TableFormat = "csv"  # of the fused table and the weight traces
    weights: bool = False
    plot: PlotFormat | None = None
    evaluate: bool = False
    skip_existing: bool = False
    force: bool = False

    def __post_init__(self) -> None:
        if self.plot is not None and self.plot not in get_args(PlotFormat):
            raise InvalidParameter("plot", f"must be one of png, svg, got {self.plot!r}")
        if self.format not in get_args(TableFormat):
            raise InvalidParameter("format", f"must be one of csv, parquet, got {self.format!r}")


@dataclass(frozen=True)
class Job:
    """One log: where it is, and where its outputs go (``stem`` + suffixes)."""

    log: Path
    relative: Path
    stem: Path

    def outputs(self, options: BatchOptions) -> Outputs:
        return Outputs(
            csv=self._with(f".{options.format}"),
            meta=self._with(".meta.json"),
            weights=self._with(f".weights.{options.format}") if options.weights else None,
            plot=self._with(f".{options.plot}") if options.plot else None,
            evaluation=self._with(".evaluation.json") if options.evaluate else None,
        )

    def existing(self, options: BatchOptions) -> list[Path]:
        """Its outputs that are there already."""
        return [p for p in self.outputs(options).paths() if p.exists()]

    def _with(self, suffix: str) -> Path:
        return self.stem.with_name(self.stem.name + suffix)


@dataclass(frozen=True)
class LogResult:
    """One row of the summary (``docs/commands.md``, "batch")."""

    log: str
    status: Outcome  # "skipped": complete outputs found
    error: str = ""
    flight_s: float | None = None  # the sensors' span on the log's clock
    processing_s: float = 0.0  # this log's run, reading to writing
    vehicle: str = ""
    firmware: str = ""
    sensors: str = ""
    left_out: str = ""  # the sources with samples the datum could not refer (fuse warns)
    samples: int = 0  # ticks of the clock
    notes: int = 0  # the reader's notes on the log (damage, types not read, stuck runs)
    damaged: str = ""  # the reader's damage, as fuse warns of it ("; " between two)
    skipped_bytes: int = 0  # bytes not part of any decodable record
    takeoff_found: bool | None = None
    fused_share: float | None = None  # of the ticks, those with a fused value
    diverged: int = 0  # ticks whose fused value left every sensor (altfuse.guard)
    max_excursion_m: float | None = None  # the largest gap from the fused value to a sensor
    model_check: str = ""  # the smoother's check of its own noises: passed, or why not
    not_used: str = ""  # values given for sensors this log does not have (--sigma, ...)
    truth: str = ""
    metrics: dict[str, float | None] = field(default_factory=dict)

    def doubts(self) -> list[str]:
        """What puts this log's fused altitude in question, as ``fuse`` warns of it: sensors
        left out, damage the reader met (a corrupt ULog, another log appended), the ticks the
        guard flagged, the model's own check failed."""
        found = [f"{self.left_out} left out"] if self.left_out else []
        found += ["damaged"] if self.damaged else []
        found += [f"diverged on {counted(self.diverged, 'tick')}"] if self.diverged else []
        return found + (["model check failed"] if self.model_check.startswith("failed") else [])


def _fused_now(results: Sequence[LogResult]) -> list[LogResult]:
    """The logs fused by this run, by name (a log skipped now was said by the run that fused
    it)."""
    return sorted((r for r in results if r.status == "ok"), key=lambda r: r.log)


def doubted(results: Sequence[LogResult]) -> str | None:
    """One line naming the logs fused now whose outputs need a look (:meth:`LogResult.doubts`),
    the first three with why, for the end of a batch; None where there are none."""
    fused = _fused_now(results)
    named = [f"{r.log} ({', '.join(why)})" for r in fused if (why := r.doubts())]
    if not named:
        return None
    return (
        f"{counted(len(named), 'log')} of the {len(fused)} fused "
        f"{'needs' if len(named) == 1 else 'need'} a look (the summary's left_out, damaged, "
        f"diverged and model_check columns): {_first_three(named, '; ', '; ')}"
    )


def unused(results: Sequence[LogResult]) -> list[str]:
    """Lines for the end of a batch, one per set of values the logs fused now did not use as
    they lack the sensors (:func:`altfuse.fuse.smoother.not_used`), the set the most logs share
    first: how many logs, the first three by name. One option for a fleet fits some logs; the
    others are said once, not once per log."""
    fused = _fused_now(results)
    sets = {r.not_used for r in fused} - {""}
    by_values = {v: [r.log for r in fused if r.not_used == v] for v in sets}
    return [
        f"not used in {counted(len(logs), 'log')} of the {len(fused)} fused, for want of the "
        f"sensors (the summary's not_used column): {values} ({_first_three(logs)})"
        for values, logs in sorted(by_values.items(), key=lambda item: (-len(item[1]), item[0]))
    ]


def _described(name: str, done: FileRun, seconds: float) -> LogResult:
    """The summary row of a run written to files."""
    run = done.run
    record = run.provenance
    counts, clock, guarded = record["status_counts"], record["clock"], record["guard"]
    ticks = max(int(run.referred.t.size), 1)
    metrics: dict[str, float | None] = {}
    label = ""
    if done.evaluation is not None:
        truth = done.evaluation.truth
        label = truth.source + (" (reference)" if truth.is_reference else "")
        for row in done.evaluation.rows:
            stats = row.overall.as_dict()
            metrics[f"{row.name}_rmse"] = stats["rmse"]
            metrics[f"{row.name}_max"] = stats["max_abs"]
            if stats["within_2std"] is not None:  # a method with a standard deviation
                metrics[f"{row.name}_within_2std"] = stats["within_2std"]
        for method, found in done.evaluation.diverged().items():
            metrics[f"{method}_diverged"] = found["diverged_ticks"]
    valued = sum(counts.get(s, 0) for s in ("fused", "single", "equal", "inertial"))
    return LogResult(
        name,
        "ok",
        flight_s=round(float(clock["end_s"] - clock["start_s"]), 3),
        processing_s=seconds,
        vehicle=record["input"]["vehicle"],
        firmware=record["input"]["firmware"],
        sensors=" ".join(run.referred.names),
        left_out=" ".join(run.referred.dropped),
        samples=int(run.referred.t.size),
        notes=len(record["input"]["notes"]),
        damaged="; ".join(record["input"]["damaged"]),
        skipped_bytes=int(record["input"]["skipped_bytes"]),
        takeoff_found=record["datum"]["takeoff_s"] is not None,
        fused_share=round(valued / ticks, 4),
        diverged=int(guarded["diverged_ticks"]),
        max_excursion_m=guarded["max_excursion_m"],
        model_check=str(run.result.params.get("model_check", "")),
        not_used=str(run.result.params.get("not_used", "")),
        truth=label,
        metrics=metrics,
    )


def find_logs(
    paths: Sequence[str | Path], pattern: str | Sequence[str] = LOG_PATTERNS
) -> list[tuple[Path, Path]]:
    """(log, path relative to its input folder) for every file matching ``pattern`` (or any of
    several), without regard to case, under ``paths`` (folders searched recursively; files
    taken as given)."""
    return _matching(_listing(paths), pattern)


#: A file a batch may take: the file, its path relative to its input folder, and whether it
#: was named itself (taken whatever its name).
Listed = tuple[Path, Path, bool]


def _listing(paths: Sequence[str | Path]) -> list[Listed]:
    """Every file named in ``paths`` and every file not hidden under its folders, listed once
    (:func:`_files_under`): the logs are chosen from it, and a batch that chose none counts
    the text logs in it for its hint."""
    listed: list[Listed] = []
    for raw in paths:
        root = Path(raw)
        if root.is_file():
            listed.append((root, Path(root.name), True))
        elif kind := _not_a_file(root):
            raise LogReadError(f"{root}: {kind}, not a log file")
        elif root.is_dir():
            listed += [
                (p, p.relative_to(root), False)
                for p in _files_under(root)
                if not p.name.startswith(".")
            ]
        elif str(raw) == "-":
            raise LogReadError(
                "-: a batch takes files and folders, not standard input "
                "(altfuse fuse - -o f.csv reads one log from it)"
            )
        else:
            raise LogReadError(f"{root}: no such file or folder")
    return listed


def _matching(listed: Sequence[Listed], pattern: str | Sequence[str]) -> list[tuple[Path, Path]]:
    """:func:`find_logs` of a :func:`_listing`: the files named, and those under the folders
    that match ``pattern``, each once, sorted by their relative paths."""
    patterns = [p.lower() for p in _patterns(pattern)]
    found: dict[Path, Path] = {}
    seen: set[Path] = set()
    for log, relative, named in listed:
        if not (named or any(fnmatch.fnmatch(log.name.lower(), each) for each in patterns)):
            continue
        if kind := _not_a_file(log):
            logging.getLogger("altfuse").warning("%s: %s: not in this batch", log, kind)
            continue
        real = log.resolve()
        if real in seen:
            continue
        seen.add(real)
        if relative in found:
            above = os.path.commonpath([found[relative].absolute(), log.absolute()])
            raise ParameterError(
                f"{found[relative]} and {log} would write the same outputs ({relative}); "
                f"give the folder above both ({above}: its tree keeps them apart), or run "
                "separate batches into separate folders"
            )
        found[relative] = log
    return [(log, relative) for relative, log in sorted(found.items())]


def _files_under(root: Path) -> list[Path]:
    """What is under ``root`` but folders (its links to folders not followed), sorted; a
    folder that cannot be listed is said, as a warning: its logs are not in the batch
    (``rglob`` passed over it in silence)."""
    found: list[Path] = []
    for folder, _, names in os.walk(root, onerror=_unlisted):
        found += [Path(folder, n) for n in names]
    return sorted(found)


def _not_a_file(path: Path) -> str:
    """What ``path`` is where it is there but not a file or a folder (a link to nothing, a
    named pipe that would hold the batch until something writes to it, a device); "" where it
    is a file or a folder."""
    if path.is_symlink() and not path.exists():
        return "a link to nothing"
    return stream_kind(path)


def _unlisted(exc: OSError) -> None:
    logging.getLogger("altfuse").warning(
        "%s: cannot list (%s): its logs are not in this batch", exc.filename, exc.strerror
    )


def _patterns(pattern: str | Sequence[str]) -> tuple[str, ...]:
    return (pattern,) if isinstance(pattern, str) else tuple(pattern)


def plan(
    paths: Sequence[str | Path], out_dir: str | Path, pattern: str | Sequence[str] = LOG_PATTERNS
) -> list[Job]:
    """The jobs of a batch: each log with its output stem under ``out_dir``. Two logs whose
    stems differ only in case or extension (``flight.bin``, ``flight.BIN``) would write one set
    of outputs (on a case-insensitive file system, or by suffix): refused, naming both. No log
    at all is refused too, saying how to take the text logs there if there are any."""
    listed = _listing(paths)
    found = _matching(listed, pattern)
    if not found:
        wanted = " or ".join(repr(p) for p in _patterns(pattern))
        texts = len(_matching(listed, TEXT_PATTERN))
        zips = len(_matching(listed, ZIP_PATTERN))
        hint = (
            f"; {texts} {TEXT_PATTERN} there: --pattern '{TEXT_PATTERN}' takes them"
            if texts
            else ""
        ) + (f"; {zips} {ZIP_PATTERN} there: extract the logs from them" if zips else "")
        raise LogReadError(f"no file matching {wanted} under {', '.join(map(str, paths))}{hint}")
    out = Path(out_dir)
    jobs: list[Job] = []
    taken: dict[str, Path] = {}
    for log, relative in found:
        stem = relative.with_suffix("")
        if compression_named(relative):  # flight.bin.gz: flight.csv, ...
            stem = stem.with_suffix("")
        key = str(stem).casefold()
        if key in taken:
            raise ParameterError(
                f"{taken[key]} and {log} would write the same outputs ({out / stem}.*); "
                "rename one, or give them separate batches"
            )
        taken[key] = log
        jobs.append(Job(log, relative, out / stem))
    return jobs


def _sidecar(job: Job, options: BatchOptions) -> dict[str, Any] | None:
    """The provenance record of ``job``'s earlier outputs; None where there is none, or it is
    damaged (its outputs then complete for nothing)."""
    meta = job.outputs(options).meta_path
    try:
        record = json.loads(meta.read_text(encoding="utf-8")) if meta is not None else None
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) else None


def is_complete(job: Job, options: BatchOptions) -> bool:
    """Whether ``job``'s outputs exist, complete, for the input as it is now and these options:
    nothing its sidecar says keeps them from being kept (:func:`unkept`), it names these very
    options and the input's sha256, and every output it lists is there."""
    record = _sidecar(job, options)
    if record is None or _unkept(job, options, record) is not None:
        return False
    try:
        same_input = record["input"]["sha256"] == sha256_of(job.log)
        same_options = record.get("options") == asdict(options.fuse)
        listed = [job.stem.parent / p for p in record["outputs"].values()]
    except (OSError, KeyError, TypeError, AttributeError):  # damaged: redo
        return False
    return same_input and same_options and all(p.exists() for p in listed)


def unkept(job: Job, options: BatchOptions) -> str | None:
    """Why ``job``'s outputs that are there would not be kept as complete for these options,
    told from their sidecar alone (whether the log changed since needs its hash): no sidecar,
    other fusion options (``method smoother, here mean``), an output these options add; None
    where none of these holds."""
    record = _sidecar(job, options)
    if record is None:
        return f"{job.existing(options)[0].name} without its sidecar"
    return _unkept(job, options, record)


def _unkept(job: Job, options: BatchOptions, record: dict[str, Any]) -> str | None:
    """:func:`unkept` given the sidecar's ``record``."""
    made, now = record.get("options"), asdict(options.fuse)
    if isinstance(made, dict) and made != now:
        return ", ".join(
            f"{key} {made.get(key)!r}, here {value!r}".replace("'", "")
            for key, value in now.items()
            if made.get(key) != value
        )
    missing = [p.name for p in job.outputs(options).paths() if not p.exists()]
    return f"no {missing[0]}" if missing else None


def process(job: Job, options: BatchOptions) -> LogResult:
    """Run one log and write its outputs; never raises for a bad log (its row says why)."""
    started = time.perf_counter()
    name = printable(str(job.relative))
    if options.skip_existing and is_complete(job, options):
        return LogResult(name, "skipped", processing_s=time.perf_counter() - started)
    outputs = job.outputs(options)
    existing = job.existing(options)
    if existing and not options.force:
        kept = "--skip-existing keeps complete outputs"
        if options.skip_existing:  # they were not: the log changed since, or some are missing
            kept = "not the complete outputs of this log as it is now (it changed since, or "
            kept += "outputs are missing)"
        message = f"{existing[0]} exists, {kept}: --force redoes it"
        return LogResult(name, "failed", message, processing_s=time.perf_counter() - started)
    try:
        done = run_to_files(job.log, outputs, options.fuse, label=str(job.relative))
        return _described(name, done, time.perf_counter() - started)
    except Refusal as exc:
        seconds = time.perf_counter() - started
        return LogResult(name, "refused", str(exc), processing_s=seconds, vehicle=exc.vehicle,
                         firmware=exc.firmware)  # fmt: skip
    except AltfuseError as exc:
        return LogResult(name, "failed", str(exc), processing_s=time.perf_counter() - started)
    except MemoryError as exc:
        return LogResult(
            name, "failed", out_of_memory(exc), processing_s=time.perf_counter() - started
        )
    except Exception as exc:  # a bug must not stop the batch either; the row names it
        signalled = interruption(exc)
        if signalled is not None:  # a signal inside compiled code: still a signal
            raise signalled from None
        message = f"internal error: {type(exc).__name__}: {exc}"
        return LogResult(name, "failed", message, processing_s=time.perf_counter() - started)


@dataclass
class _WorkerState:
    """What a worker process's SIGTERM (and SIGHUP) handler needs to know."""

    running: bool = False  # a log is being processed
    terminating: bool = False  # SIGTERM came (its exception can be lost in a C callback)
    started: Any = None  # where the worker says which job it starts (a multiprocessing queue)


_worker = _WorkerState()


def _worker_signal(_signum: int, _frame: object) -> None:
    if _worker.terminating:  # ending already (SIGHUP, then the SIGTERM of a parent gone)
        return
    _worker.terminating = True
    if _worker.running:
        raise Terminated  # out through atomic_outputs, which removes its temporary files
    os._exit(EXIT_TERMINATED)


def _worker_end(_signum: int) -> NoReturn:
    os._exit(EXIT_TERMINATED)


def _worker_start(parent: int, started: Any) -> None:
    """In each worker process: SIGTERM ends it, removing the temporary files of the log in
    hand (or, where its exception cannot, the watchdog ends it after a grace:
    :func:`altfuse.signals.watch_signals`), as SIGHUP does (a closed terminal sends it to the
    workers as to the batch), and on Linux the worker is sent SIGTERM when its
    parent dies (``PR_SET_PDEATHSIG``), so that a killed batch does not leave workers writing
    on. ``started`` is the queue on which it says which job it starts. Each worker computes on
    one thread (a BLAS pool forked from a parent that loaded numpy would spin beside the other
    workers: see ``altfuse.cli``), its threads from one C heap (:func:`altfuse.memory.one_heap`:
    a forked worker has it from the command line, one started anew not)."""
    one_heap()
    _worker.started = started
    threadpool_limits(1)
    raise_on_termination(_worker_signal)
    watch_signals(_worker_end)
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != parent:  # it died before the request above was made
        os._exit(EXIT_TERMINATED)


def _process_in_worker(job: Job, options: BatchOptions) -> LogResult:
    _worker.started.put(str(job.relative))
    _worker.running = True
    try:
        return process(job, options)
    except Terminated:
        os._exit(EXIT_TERMINATED)
    finally:
        _worker.running = False
        if _worker.terminating:  # the signal's exception was swallowed (numba's cache callback)
            os._exit(EXIT_TERMINATED)


def _local(jobs: list[Job], options: BatchOptions, workers: int) -> Iterator[LogResult]:
    """The jobs in ``workers`` processes. A worker that dies (SIGBUS: a log shrank while it was
    read) breaks the pool and every job in it: the jobs that had not started run again in a
    new pool, and those that were running, one of them the cause, each alone in a pool of its
    own, so that only a log that kills its worker fails."""
    if workers <= 1:
        for job in jobs:
            yield process(job, options)
        return
    pending = jobs
    while pending:
        running, waiting = yield from _pool(pending, options, workers)
        if not running and len(waiting) == len(pending):  # no worker got as far as a job
            running, waiting = waiting, []
        pending = waiting
        for job in running:
            began, before = yield from _pool([job], options, 1)
            for lost in began + before:  # alone: whichever, its worker died with it
                why = "not finished: its worker process died (a log that shrank while read?)"
                yield LogResult(printable(str(lost.relative)), "failed", why)


def _pool(
    jobs: list[Job], options: BatchOptions, workers: int
) -> Generator[LogResult, None, tuple[list[Job], list[Job]]]:
    """The results of the jobs one pool of ``workers`` processes finished; returns the jobs
    lost when a worker died, those that had started and those that had not. No more processes
    than jobs: a pool that forks starts them all at once (``-j 99999`` over 4 logs forked
    until the system killed the batch, exit 137)."""
    context = multiprocessing.get_context(START_METHOD)
    started = context.SimpleQueue()
    lost: list[Job] = []
    with ProcessPoolExecutor(
        max_workers=min(workers, len(jobs)),
        mp_context=context,
        initializer=_worker_start,
        initargs=(os.getpid(), started),
    ) as pool:
        futures = {pool.submit(_process_in_worker, job, options): job for job in jobs}
        for future in as_completed(futures):
            try:
                yield future.result()
            except BrokenProcessPool:
                lost.append(futures[future])
    begun = set()
    while not started.empty():
        begun.add(started.get())
    started.close()
    return [j for j in lost if str(j.relative) in begun], [
        j for j in lost if str(j.relative) not in begun
    ]


def _dask_client(scheduler: str) -> Any:
    """A client of the Dask scheduler at ``scheduler`` (a ``dask.distributed.Client``),
    connected before the batch makes its output folder: an address that is none, or a
    scheduler out of reach, leaves nothing behind."""
    try:
        from dask.distributed import Client
    except ImportError as exc:
        raise ParameterError(
            "--scheduler needs dask.distributed: pip install 'altfuse[dask]'"
        ) from exc
    try:
        return Client(scheduler, timeout="10s")  # type: ignore[no-untyped-call]
    except ValueError as exc:  # no port, an unknown scheme
        raise InvalidParameter(
            "scheduler", f"must be an address such as tcp://host:8786, got {scheduler!r} ({exc})"
        ) from exc
    except (OSError, TimeoutError) as exc:
        raise ParameterError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from exc


def _dask(jobs: list[Job], options: BatchOptions, client: Any) -> Iterator[LogResult]:
    """The jobs on the Dask cluster of ``client``. :func:`process` never raises for a log: a
    job that ends in an error ended on the cluster and fails its own row, not the batch (an
    internal error, no summary, for a fleet's every log). A job whose workers died each time
    it ran (dask's KilledWorker: out of memory) may have died with another on the worker: those
    run again one at a time, so that only a log that kills its worker fails (as
    :func:`_local`'s)."""
    from dask.distributed import KilledWorker

    killed = []
    for job, outcome in _on_cluster(client, jobs, options):
        if isinstance(outcome, KilledWorker) and len(jobs) > 1:
            killed.append(job)
        else:
            yield _finished(job, outcome)
    for job in killed:
        for alone, outcome in _on_cluster(client, [job], options):
            yield _finished(alone, outcome)


def _on_cluster(
    client: Any, jobs: list[Job], options: BatchOptions
) -> Iterator[tuple[Job, LogResult | BaseException]]:
    """Each job with its result, or the exception it ended in on the cluster, as they end."""
    from dask.distributed import as_completed as dask_completed

    futures = client.map(process, jobs, options=options, pure=False)
    job_of = {future.key: job for future, job in zip(futures, jobs, strict=True)}
    for future in dask_completed(futures):  # type: ignore[no-untyped-call]
        failed = future.status == "error"
        yield job_of[future.key], future.exception() if failed else future.result()


def _finished(job: Job, outcome: LogResult | BaseException) -> LogResult:
    if isinstance(outcome, LogResult):
        return outcome
    why = f"not finished on the Dask cluster: {type(outcome).__name__}: {outcome}"
    return LogResult(printable(str(job.relative)), "failed", why)


def printable(text: str) -> str:
    """``text`` with the bytes of a non-UTF-8 file name (decoded by Python as surrogates) as
    ``\\xNN`` escapes: any name can go into the summary and on the terminal."""
    return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


def _previous_summary(path: Path) -> pd.DataFrame | None:
    """The rows of an existing ``summary.csv``, to merge this run's into; None when there is
    none. A file that is not a summary is refused: it is not altfuse's to replace."""
    import pandas as pd

    if not path.exists():
        return None
    try:
        table = pd.read_csv(path, dtype={"log": str, "error": str, "sensors": str, "truth": str})
    except (OSError, ValueError) as exc:
        raise ParameterError(
            f"{path} exists and cannot be read as a summary ({exc}); --force replaces it"
        ) from exc
    if not {"log", "status"} <= set(table.columns):
        raise ParameterError(f"{path} exists and is not a batch summary; --force replaces it")
    return table


def write_summary(
    results: Iterable[LogResult],
    path: Path,
    previous: pd.DataFrame | None = None,
    parquet: Path | None = None,
) -> None:
    """``summary.csv``: one row per log, sorted by log, metrics as columns. With ``previous``
    (an earlier summary) its rows of logs not run now are kept, and a log skipped now keeps its
    earlier row, status ``skipped``. With ``parquet``, the same table there too (each column's
    unit in its metadata, the altfuse version in the file's), written with the CSV, both or
    neither."""
    import pandas as pd  # not at import: 0.3 s that fuse does without

    rows = []
    for r in results:
        row: dict[str, Any] = {
            k: printable(v) if isinstance(v, str) else v
            for k, v in asdict(r).items()
            if k != "metrics"
        }
        row["processing_s"] = round(r.processing_s, 3)
        row.update(r.metrics)
        rows.append(row)
    columns = [f.name for f in fields(LogResult) if f.name != "metrics"]
    table = pd.DataFrame.from_records(rows, columns=columns if not rows else None)
    if previous is not None and not previous.empty:
        earlier = previous.drop_duplicates("log", keep="last").set_index("log", drop=False)
        skipped = table.loc[table["status"] == "skipped", "log"]
        kept = earlier.loc[earlier.index.isin(skipped)].assign(status="skipped")
        others = earlier.loc[~earlier.index.isin(table["log"])]
        parts = [table[table["status"] != "skipped"], kept, others]
        names = list(dict.fromkeys(c for part in parts for c in part.columns))
        # each column typed by the parts that hold values in it, as pandas 2 did (it warned
        # that pandas 3 would type it by its empty and all-missing parts too)
        held = [part.dropna(axis=1, how="all") for part in parts if not part.empty]
        table = pd.concat(held, ignore_index=True).reindex(columns=names)
    table = table.reindex(columns=columns + [c for c in table.columns if c not in columns])
    table = table.sort_values("log", kind="stable")
    with atomic_outputs() as stage:
        stage(path, lambda f: table.to_csv(f, index=False, float_format="%.6f"))
        if parquet is not None:
            record = {"altfuse_version": __version__}
            by_name = {str(c): table[c].to_numpy() for c in table.columns}
            stage(parquet, write_table(by_name, "parquet", record), binary=True)


@contextlib.contextmanager
def _locked(out: Path, shared: bool = False) -> Iterator[None]:
    """Hold a lock on the output folder itself (``flock`` on its descriptor: no lock file left
    behind) for the batch, or refuse when another batch holds it. The shards of one batch
    (``shared``) hold it together, each writing its own logs and summary. Windows has neither
    ``flock`` nor a descriptor of a folder: there the folder is not locked (``docs/install.md``)."""
    out.mkdir(parents=True, exist_ok=True)
    if sys.platform == "win32":
        yield
        return
    import fcntl

    fd = os.open(out, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
        except BlockingIOError as exc:
            raise ParameterError(
                f"another altfuse batch is writing to {out}; wait for it, or choose another -o"
            ) from exc
        yield
    finally:
        os.close(fd)


def run_batch(  # noqa: PLR0913 (keyword-only beyond the first three: the CLI's options)
    paths: Sequence[str | Path],
    out_dir: str | Path,
    options: BatchOptions | None = None,
    *,
    pattern: str | Sequence[str] = LOG_PATTERNS,
    jobs: int | None = None,
    scheduler: str | None = None,
    on_result: Callable[[LogResult, int], None] | None = None,
    shard: tuple[int, int] | None = None,
) -> list[LogResult]:
    """Run every log under ``paths`` into ``out_dir``; return one result per log.

    ``on_result(result, total)`` is called as each log finishes (for progress). With ``shard``
    ``(i, n)``, only every n-th log of the sorted list from the i-th (1-based): the n shards of
    a job array cover every log once, side by side in one ``out_dir``, each with its own
    summary (:func:`summary_name`).
    """
    options = options or BatchOptions()
    workers = (os.cpu_count() or 1) if jobs is None else jobs
    if workers < 1:
        raise InvalidParameter("jobs", f"must be at least 1, got {workers}")
    if shard is not None and not 1 <= shard[0] <= shard[1]:
        raise InvalidParameter("shard", f"must be I/N with 1 <= I <= N, got {shard[0]}/{shard[1]}")
    todo = plan(paths, out_dir, pattern)
    if shard is not None:
        todo = todo[shard[0] - 1 :: shard[1]]
    out = Path(out_dir)
    if not options.force:
        _refuse_rerun(todo, options, out)
    summary = out / summary_name(shard)
    client = None if scheduler is None else _dask_client(scheduler)
    with (
        contextlib.nullcontext() if client is None else client,
        _locked(out, shared=shard is not None),
    ):
        previous = None if options.force else _previous_summary(summary)
        remove_stale_temporaries(out, recursive=True)
        results = []
        stream = _local(todo, options, workers) if client is None else _dask(todo, options, client)
        for result in stream:
            results.append(result)
            if on_result is not None:
                on_result(result, len(todo))
        parquet = (
            out / summary_name(shard, PARQUET_SUMMARY) if options.format == "parquet" else None
        )
        write_summary(results, summary, previous, parquet)
        write_index(results, todo, options, out / summary_name(shard, "index.json"))
    return results


def _refuse_rerun(jobs: Sequence[Job], options: BatchOptions, out: Path) -> None:
    """A batch run again without ``--force`` on logs whose outputs are there is refused as a
    whole, its summary untouched (each log failing alone, "exists", gave the summary's rows of
    the earlier run, every metric, away to those failures): without ``--skip-existing``, any
    such log; with it, one whose outputs it would neither keep nor may overwrite
    (:func:`unkept`: no log is hashed here)."""
    if options.skip_existing:
        why = {job: unkept(job, options) for job in jobs if job.existing(options)}
        held = [job for job, reason in why.items() if reason is not None]
        if held:
            raise ParameterError(
                f"{out} holds outputs of {len(held)} of these {len(jobs)} logs "
                f"({_named(held)}) that --skip-existing cannot keep ({why[held[0]]}): "
                "--force redoes them, or write to another folder"
            )
        return
    held = [job for job in jobs if job.existing(options)]
    if held:
        raise ParameterError(
            f"{out} holds the outputs of {len(held)} of these {len(jobs)} logs "
            f"({_named(held)}): --skip-existing keeps the complete ones, --force redoes them"
        )


def _named(jobs: Sequence[Job]) -> str:
    """The first three of ``jobs``' logs, and how many more."""
    return _first_three([printable(str(job.relative)) for job in jobs])


def _first_three(names: Sequence[str], sep: str = ", ", more_sep: str = " ") -> str:
    """The first three ``names`` joined by ``sep``, and how many more (after ``more_sep``)."""
    more = f"{more_sep}and {len(names) - 3} more" if len(names) > 3 else ""
    return sep.join(names[:3]) + more


def summary_name(shard: tuple[int, int] | None = None, name: str = SUMMARY) -> str:
    """A batch's own file ``name`` (``summary.csv``, ``index.json``), or a shard's
    (``summary.shard-I-of-N.csv``)."""
    if shard is None:
        return name
    stem, dot, suffix = name.partition(".")
    return f"{stem}.shard-{shard[0]}-of-{shard[1]}{dot}{suffix}"


def write_index(
    results: Sequence[LogResult], jobs: Sequence[Job], options: BatchOptions, path: Path
) -> None:
    """``index.json`` beside the summary: the altfuse version and the batch's options, and per
    log the version and fusion options its outputs (relative to the folder) were made with and
    its status. Logs of an earlier index not run now keep their entries, and so do logs that
    fail now, their failure under ``rerun``: the index describes the files there, and a later
    run (or a person) tells from it what must be redone."""
    folder = path.parent
    by_name = {printable(str(job.relative)): job for job in jobs}
    run_with = {"altfuse_version": __version__, "fuse": asdict(options.fuse)}
    logs: dict[str, Any] = {}
    if not options.force:  # as the summary: --force replaces it
        with contextlib.suppress(OSError, ValueError, TypeError, KeyError):  # none, or damaged
            logs.update(json.loads(path.read_text(encoding="utf-8"))["logs"])
    for r in results:
        if r.status in ("ok", "skipped"):
            outputs = [os.path.relpath(o, folder) for o in by_name[r.log].outputs(options).paths()]
            logs[r.log] = {**run_with, "status": r.status, "outputs": outputs}
        elif r.log in logs:  # its earlier outputs are still there: said, with this failure
            logs[r.log]["rerun"] = {**run_with, "status": r.status, "error": r.error}
        else:
            logs[r.log] = {**run_with, "status": r.status, "error": r.error, "outputs": []}
    record = {
        "altfuse_version": __version__,
        "options": asdict(options),
        "logs": dict(sorted(logs.items())),
    }
    with atomic_outputs() as stage:
        stage(path, write_json(record))
