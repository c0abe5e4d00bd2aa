"""Writing a run's outputs: the fused CSV, the weight traces, the JSON provenance sidecar.

Every file is written to a temporary file beside its target and renamed into place only when all
of them are complete, all or none, so a failure never leaves a half-written output or an output
without its sidecar behind; no output may be an input of the run or another of its outputs
(:func:`check_paths`); SIGTERM and SIGHUP, like SIGINT, remove the temporary files
(:class:`altfuse.signals.Terminated`). A target that is a symbolic link stays one: its file is
written. A target that exists and is no regular file (``/dev/null``, a named pipe,
``/dev/stdout``: :func:`altfuse.files.is_stream`) is written into once the files are in place,
as standard output is (``-o -``), never replaced (a rename onto ``/dev/null`` made it a regular
file).
"""

from __future__ import annotations

import contextlib
import errno
import glob
import hashlib
import io
import json
import os
import socket
import sys
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Literal, cast

import numpy as np
import numpy.typing as npt

from altfuse.errors import AltfuseError, ParameterError
from altfuse.files import COMPRESSIONS, compression_named, is_stream
from altfuse.signals import signals_held

if TYPE_CHECKING:
    import pandas as pd

    from altfuse.pipeline import FuseRun

#: A table as altfuse writes it: columns by name, in order, each an array of one row per entry
#: (floats with NaN where there is no value, text, flags).
Columns = Mapping[str, Any]

#: The fused table's formats, by the output's suffix (any other suffix: CSV).
TableFormat = Literal["csv", "parquet"]
#: Decimals of every float in a CSV: micrometres, microseconds. Each value is rounded to them and
#: written in its shortest form (``1.5``, ``0.333333``; an empty field where there is none).
CSV_DECIMALS = 6


def table_format(path: Path) -> TableFormat:
    """``parquet`` for a ``.parquet`` name, else ``csv``."""
    return "parquet" if path.suffix.lower() == ".parquet" else "csv"


#: Suffixes of other formats, refused as a table's name (:func:`check_table_path`): whoever
#: names ``fused.json`` or ``fused.xlsx`` expects that format, and a CSV named as a log
#: (``fused.bin``, ``fused.log``) reads later as a damaged log, in a batch's folder too.
OTHER_FORMATS = (
    ".json", ".xlsx", ".xls", ".ods", ".feather", ".arrow", ".h5", ".hdf5", ".mat", ".nc",
    ".pkl", ".pickle", ".npy", ".npz", ".png", ".svg", ".pdf", ".bin", ".ulg", ".log", ".tlog",
)  # fmt: skip


def check_table_path(path: Path, parquet: bool = True) -> None:
    """Refuse a table's name (a fused table's, a weights', a report's) whose suffix, less a
    compression's, names another format (:data:`OTHER_FORMATS`; ``.parquet`` too where the
    table is written as CSV alone, ``parquet`` False): it was written as CSV."""
    suffix = _format_suffix(path)
    if (named := suffix.lower()) in OTHER_FORMATS or (named == ".parquet" and not parquet):
        formats = "as CSV, or as Parquet for a .parquet name" if parquet else "as CSV"
        raise ParameterError(
            f"{path}: this table is written {formats}, not as {suffix}: "
            f"name it .csv{' or .parquet' if parquet else ''}"
        )


def check_json_path(path: Path) -> None:
    """Refuse a JSON output's name (a sidecar's, a report's) whose suffix, less a
    compression's, names another format: a table's (``report.csv`` was JSON to whoever read it
    as the CSV it asked for) or one of :data:`OTHER_FORMATS` (a sidecar named ``.bin`` reads
    later as a damaged log)."""
    _check_written_as(path, "JSON", ".json")


def check_log_path(path: Path) -> None:
    """Refuse a written DataFlash log's name (a simulated flight's) whose suffix, less a
    compression's, names another format: ``hover.csv`` or ``hover.ulg`` held a binary
    DataFlash log, which a batch's patterns pass over."""
    _check_written_as(path, "a DataFlash log", ".bin")


def _check_written_as(path: Path, what: str, suffix: str) -> None:
    """Refuse ``path`` for a file written as ``what`` where its suffix (less a compression's)
    is a table's or one of :data:`OTHER_FORMATS` other than ``suffix``, the right one."""
    named = _format_suffix(path)
    if named.lower() in {*OTHER_FORMATS, ".csv", ".tsv", ".parquet"} - {suffix}:
        raise ParameterError(f"{path}: this is written as {what}, not as {named}: name it {suffix}")


def _format_suffix(path: Path) -> str:
    """``path``'s suffix less a compression's (``.csv`` of ``out.csv.gz``)."""
    return (path.with_suffix("") if compression_named(path) is not None else path).suffix


_UNITS = {"velocity": "m/s", "accel_bias": "m/s^2", "accel_up": "m/s^2", "correction": "m"}


def column_unit(name: str) -> str:
    """A numeric column's unit (Parquet column metadata) in a fused, weights or summary table:
    ``m``, ``s``, ``m/s``, ``m/s^2``, ``m^2`` or ``1`` (a share or a count). Text and flags
    have none (:func:`write_table`)."""
    if name in _UNITS:
        return _UNITS[name]
    if name.endswith("_s"):
        return "s"
    if name.endswith(("_m", "_std", "_rmse", "_max")) or name.startswith(
        ("offset_", "temporal_estimate_")
    ):
        return "m"
    if "variance" in name:
        return "m^2"
    return "1"


#: Rows of a CSV formatted at a time.
CSV_ROWS = 1 << 16


def write_table(table: Columns, fmt: TableFormat, metadata: dict[str, Any]) -> Writer:
    """A binary writer of ``table``: Parquet (each column's unit in its metadata, ``metadata``
    as JSON in the file's key-value metadata under ``altfuse``), or CSV (see
    ``CSV_DECIMALS``), both by Arrow's C++ writers: pandas' CSV writer formats each float in
    Python (1.9 s of a 4 s run on a 300 MB log). NaN, and None in text, are written as no
    value (Parquet's null, an empty CSV field)."""
    import pyarrow as pa

    columns = {name: np.asarray(values) for name, values in table.items()}

    def arrow(rounded: bool, rows: slice = slice(None)) -> Any:
        def column(values: np.ndarray) -> Any:
            values = values[rows]
            if rounded and values.dtype.kind == "f":
                # + 0.0: no "-0" where a small negative value rounds to zero
                values = np.round(values, CSV_DECIMALS) + 0.0
            return arrow_column(values)

        return pa.table({name: column(values) for name, values in columns.items()})

    def write(handle: IO[Any]) -> None:
        if fmt == "parquet":
            import pyarrow.parquet as pq

            plain = arrow(rounded=False)
            fields = [
                f.with_metadata({"unit": column_unit(f.name) if _numeric(f.type) else ""})
                for f in plain.schema
            ]
            schema = pa.schema(fields, metadata={"altfuse": json.dumps(metadata, default=str)})
            # dictionaries for the columns that are not floats: a float's values are all
            # different, and trying one cost 50 MB of a 265,476-row table's write (63 MiB)
            coded = [f.name for f in plain.schema if not pa.types.is_floating(f.type)]
            pq.write_table(plain.cast(schema), handle, use_dictionary=coded)
            return
        import pyarrow.csv as pacsv

        # unquoted, as pandas writes them (Arrow quotes every name); none needs quotes
        handle.write((",".join(columns) + "\n").encode())
        options = pacsv.WriteOptions(include_header=False, quoting_style="none")
        count = len(next(iter(columns.values()))) if columns else 0
        # rounded CSV_ROWS rows at a time: a copy of the whole table was the write's peak
        chunks = [slice(start, start + CSV_ROWS) for start in range(0, count, CSV_ROWS)]
        first = arrow(rounded=True, rows=chunks[0] if chunks else slice(None))
        with pacsv.CSVWriter(handle, first.schema, write_options=options) as out:
            out.write_table(first)
            for rows in chunks[1:]:
                out.write_table(arrow(rounded=True, rows=rows))

    return write


def arrow_column(values: np.ndarray) -> Any:
    """``values`` as an Arrow array, NaN (and None in text) as null. Numbers, flags and text
    are built from their buffers: ``pyarrow.array`` imports pandas (0.2 s) to look for its
    types, where a fused table has none; any other column (a summary's mixed objects) goes
    through it."""
    import pyarrow as pa

    n = values.size
    kind = values.dtype.kind
    if kind == "f":
        data = np.ascontiguousarray(values, dtype=np.float64)
        missing = np.isnan(data)
        nulls = int(missing.sum())
        validity = pa.py_buffer(np.packbits(~missing, bitorder="little")) if nulls else None
        return pa.Array.from_buffers(pa.float64(), n, [validity, pa.py_buffer(data)], nulls)
    if kind in "iu":
        data = np.ascontiguousarray(values, dtype=np.int64)
        return pa.Array.from_buffers(pa.int64(), n, [None, pa.py_buffer(data)])
    if kind == "b":
        bits = np.packbits(values.astype(bool), bitorder="little")
        return pa.Array.from_buffers(pa.bool_(), n, [None, pa.py_buffer(bits)])
    if kind == "U":
        # a column of a few labels (a fused table's status): each distinct label encoded once,
        # then taken per row in C (265,476 rows: 0.35 s encoded row by row, 0.13 s so)
        labels, which = np.unique(values, return_inverse=True)
        return _strings(list(labels), which.ravel())
    if kind == "O" and all(isinstance(v, str) or v is None for v in values):
        return _strings(list(values), np.arange(n))
    return pa.array(values, from_pandas=True)


def _strings(labels: list[str | None], which: npt.NDArray[np.intp]) -> Any:
    """Text as an Arrow string array, row ``i`` being ``labels[which[i]]`` (None: null), built
    from its buffers by numpy (Arrow's ``take`` would import pyarrow.compute: 37 ms of a small
    log's run)."""
    import pyarrow as pa

    encoded = [b"" if v is None else str(v).encode() for v in labels]
    lengths = np.array([len(e) for e in encoded], dtype=np.int32)
    width = max(int(lengths.max(initial=0)), 1)
    table = np.array(encoded, dtype=f"S{width}").view(np.uint8).reshape(len(encoded), width)
    row_lengths = lengths[which]
    offsets = np.zeros(which.size + 1, dtype=np.int32)
    np.cumsum(row_lengths, out=offsets[1:])
    data = table[which][np.arange(width) < row_lengths[:, None]].tobytes()
    missing = np.array([v is None for v in labels], dtype=bool)[which]
    nulls = int(missing.sum())
    validity = pa.py_buffer(np.packbits(~missing, bitorder="little")) if nulls else None
    buffers = [validity, pa.py_buffer(offsets), pa.py_buffer(data)]
    return pa.Array.from_buffers(pa.string(), which.size, buffers, nulls)


def _numeric(kind: Any) -> bool:
    """Whether an Arrow type is a number (a unit applies), not text or a flag."""
    import pyarrow as pa

    return bool(pa.types.is_integer(kind) or pa.types.is_floating(kind))


def fused_table(run: FuseRun) -> pd.DataFrame:
    """:func:`fused_columns` as a pandas DataFrame (for the library's :func:`fuse_file`)."""
    import pandas as pd

    table: pd.DataFrame = pd.DataFrame(fused_columns(run))
    return table


def fused_columns(run: FuseRun) -> dict[str, Any]:
    """One row per tick: time, each sensor's referred height, the fused height, weights, support.

    Columns: ``time_s``; ``alt_<sensor>_m`` for each sensor (height above take-off);
    ``fused_alt_m``; ``fused_std_m`` (its standard deviation, where the method gives one);
    ``status`` (``fused``/``equal``/``single``/``none``); ``n_sensors``;
    ``weight_<sensor>`` (summing to 1); ``support_<sensor>`` (Paper A's r_i, where the method
    computes it).
    """
    ref, res = run.referred, run.result
    columns: dict[str, Any] = {"time_s": ref.t}
    for i, name in enumerate(ref.names):
        columns[f"alt_{name}_m"] = ref.h[:, i]
    columns["fused_alt_m"] = res.fused
    if "fused_std" in res.tick_traces:
        columns["fused_std_m"] = res.tick_traces["fused_std"]
    columns["status"] = res.status
    columns["n_sensors"] = np.isfinite(ref.h).sum(axis=1)
    for i, name in enumerate(ref.names):
        columns[f"weight_{name}"] = res.weights[:, i]
    if "support" in res.traces:
        for i, name in enumerate(ref.names):
            columns[f"support_{name}"] = res.traces["support"][:, i]
    return columns


def weights_columns(run: FuseRun) -> dict[str, Any]:
    """The weight traces: normalised weights and every method-specific trace, per sensor."""
    ref, res = run.referred, run.result
    columns: dict[str, Any] = {"time_s": ref.t}
    for i, name in enumerate(ref.names):
        columns[f"weight_{name}"] = res.weights[:, i]
    for key, trace in res.traces.items():
        for i, name in enumerate(ref.names):
            columns[f"{key}_{name}"] = trace[:, i]
    columns.update(res.tick_traces)
    return columns


#: ``-o -``: the fused table (CSV) goes to standard output.
STDOUT = Path("-")


def default_meta_path(csv_path: Path) -> Path | None:
    """``out.csv`` -> ``out.meta.json``, beside the file a link names (no
    ``/dev/stdout.meta.json``); none beside standard output or another stream
    (:func:`is_stream`: no ``/dev/null.meta.json``), nor beside a path without a file's name
    (``.``, ``/``: folders, refused as outputs by :func:`check_paths`; pathlib raised here)."""
    if csv_path == STDOUT or is_stream(csv_path) or not csv_path.name:
        return None
    if os.path.islink(csv_path):
        csv_path = Path(os.path.realpath(csv_path))
    return csv_path.with_suffix(".meta.json")


Writer = Callable[[IO[Any]], None]

#: Every temporary file altfuse writes is named ``.altfuse-HOST-PID-NAME.XXXX.tmp`` beside its
#: target ``NAME``: only such files are ever cleaned, and only once the process of that id on
#: this host has gone (a run killed by SIGKILL or a power cut leaves them; the next run to the
#: same folder removes them). A user's own ``.*.tmp`` files are never touched.
TEMP_PREFIX = ".altfuse-"
_HOST = socket.gethostname().replace("-", "_") or "host"
#: The longest file name [bytes] file systems take (Linux's NAME_MAX, and macOS's and Windows'
#: in characters). A temporary's name holds its target's, and a target set aside while the
#: others are renamed (:func:`_set_aside`) a temporary's: ``NAME`` stands in them as its start
#: and a digest of it where they would be longer (a 249-byte ``NAME`` was refused, "File name
#: too long", the target's own name within the limit).
NAME_MAX = 255
#: What the names add to ``NAME``: a process id of up to 7 digits, two "-", and mkstemp's
#: ``.XXXXXXXX.tmp`` twice (the temporary's, then the set-aside's).
_TEMP_EXTRA = 7 + 2 + 2 * len(".XXXXXXXX.tmp")
_DIGEST = 8


def temp_stem(name: str) -> str:
    """``name`` as it stands in the names of its temporary files: itself, or where those would
    be longer than NAME_MAX bytes, as much of its start as fits, "~" and the first _DIGEST hex
    digits of its sha256 (the same for every run on this host: a killed run's are found)."""
    room = NAME_MAX - len(os.fsencode(f"{TEMP_PREFIX}{_HOST}")) - _TEMP_EXTRA
    encoded = os.fsencode(name)
    if len(encoded) <= room:
        return name
    digest = hashlib.sha256(encoded).hexdigest()[:_DIGEST]
    start = encoded[: max(room - _DIGEST - 1, 0)].decode(errors="ignore")  # whole characters
    return f"{start}~{digest}"


class OutputError(AltfuseError):
    """An output cannot be written: a read-only file system, a full disk, no permission, a
    symlink loop, a directory in the way."""


def _cannot(path: Path, exc: OSError) -> OutputError:
    return OutputError(f"cannot write {path}: {exc.strerror or exc}")


def _pid_alive(pid: int) -> bool:
    """Whether the process ``pid`` of this host is there (signal 0 asks). On Windows that signal
    is Ctrl+C, sent to the process group ``pid``, and nothing is asked: taken as alive, its
    temporary files are left (``docs/install.md``)."""
    if sys.platform == "win32":
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process: alive
        return True
    return True


def remove_stale_temporaries(folder: Path, name: str = "*", recursive: bool = False) -> int:
    """Delete altfuse's temporary files for ``name`` (a glob) in ``folder`` (and below it, with
    ``recursive``) whose writer, a process on this host, has gone; return the count."""
    pattern = f"{TEMP_PREFIX}{glob.escape(_HOST)}-*-{name}.*.tmp"
    try:
        found = list(folder.rglob(pattern) if recursive else folder.glob(pattern))
    except OSError:
        return 0
    removed = 0
    for path in found:
        pid = path.name[len(TEMP_PREFIX) + len(_HOST) + 1 :].split("-", 1)[0]
        if pid.isdigit() and not _pid_alive(int(pid)) and path.is_file():
            with contextlib.suppress(OSError):
                path.unlink()
                removed += 1
    return removed


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def check_paths(outputs: Sequence[Path | None], inputs: Sequence[Path] = ()) -> None:
    """Refuse a run whose outputs include one of its inputs, name one file twice, are
    directories, or are ``-`` (standard output: the fused table's alone, which is not among
    ``outputs``): every check before anything is written."""
    seen: dict[str, Path] = {}
    for target in (p for p in outputs if p is not None):
        if target == STDOUT:  # else a file named "-"
            raise ParameterError(
                "'-' is standard output, which takes the fused table alone (altfuse fuse -o -): "
                "name a file for this output (/dev/stdout writes one there)"
            )
        real = os.path.realpath(target)
        for source in inputs:
            if real == os.path.realpath(source) or _same_file(target, source):
                same = "" if str(target) == str(source) else f" ({source})"
                raise ParameterError(f"{target} is the input log{same}; choose another output path")
        if real in seen and not is_stream(target):  # a device takes every output given it
            raise ParameterError(
                f"{seen[real]} and {target} are the same file; give each output its own path"
            )
        if os.path.isdir(target):
            raise ParameterError(f"{target} is a directory; an output must be a file path")
        _check_compression(target)
        seen[real] = target


def _check_compression(target: Path) -> None:
    """Refuse a name that asks for a compression altfuse does not write (:data:`_UNWRITTEN`),
    or for one of Parquet, which is compressed already."""
    last = target.suffix.lower()
    if last in _UNWRITTEN:
        written = ", ".join(c.suffix for c in COMPRESSIONS)
        raise ParameterError(
            f"{target}: a {last} file is not written; {written} compress an output"
        )
    if compression_named(target) and Path(target.stem).suffix.lower() == ".parquet":
        raise ParameterError(f"{target}: Parquet is compressed already; name it {target.stem}")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


@contextlib.contextmanager
def atomic_outputs() -> Iterator[Callable[..., None]]:
    """Collect writes into temporary files; on success rename them all into place, or, if one
    rename fails, none (the files they replace are put back). ``stage(target, write,
    binary=False)`` hands ``write`` an open text (or binary) file. Files get the user's umask;
    an ``OSError`` becomes an :class:`OutputError` naming the path. A target that is a link is
    written through it (the link stays); one that is a stream (:func:`is_stream`) is written
    into once the others are in place."""
    staged: list[tuple[str, Path]] = []
    streams: list[tuple[Path, Writer, bool]] = []
    mode = 0o666 & ~_umask()

    def stage(target: Path, write: Writer, binary: bool = False) -> None:
        if is_stream(target):
            streams.append((target, write, binary))
            return
        target = Path(os.path.realpath(target))  # a rename onto a link would replace the link
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            stem = temp_stem(target.name)
            remove_stale_temporaries(target.parent, glob.escape(stem))
            prefix = f"{TEMP_PREFIX}{_HOST}-{os.getpid()}-{stem}."
            with signals_held():  # a file made is a file recorded for removal
                fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=prefix, suffix=".tmp")
                staged.append((tmp, target))
        except OSError as exc:
            raise _cannot(target, exc) from exc
        try:
            if hasattr(os, "fchmod"):  # not on Windows before Python 3.13: no such bits there
                os.fchmod(fd, mode)
            _write_into(fd, write, binary, target)
        except OSError as exc:
            raise _cannot(target, exc) from exc

    try:
        yield stage
        with signals_held():  # all renamed or none
            _commit(staged)
    except BaseException:
        with signals_held():
            for tmp, _ in staged:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
        raise
    for target, write, binary in streams:
        try:
            _write_into(target, write, binary, target)
        except OSError as exc:
            raise _cannot(target, exc) from exc


#: Compressions an output's name may ask for that altfuse does not write (those it does:
#: :data:`altfuse.files.COMPRESSIONS`; ``flight.csv.gz`` was plain CSV under a name that every
#: reader takes for gzip): refused (:func:`check_paths`).
_UNWRITTEN = (".zip", ".zst", ".tar", ".tgz", ".lz4", ".7z")


def _write_into(file: int | Path, write: Writer, binary: bool, target: Path) -> None:
    """``write`` into ``file`` (a descriptor, closed after, or a path), as bytes or UTF-8 text,
    compressed as the ``target``'s name asks (:func:`altfuse.files.compression_named`)."""
    packed = compression_named(target)
    with open(file, "wb") as raw, contextlib.ExitStack() as layers:
        out: IO[Any] | io.IOBase = raw
        if packed is not None:
            out = layers.enter_context(packed.open(raw, "wb"))
        if not binary:
            out = layers.enter_context(
                io.TextIOWrapper(cast(IO[bytes], out), encoding="utf-8", newline="")
            )
        write(cast(IO[Any], out))


def _commit(staged: Sequence[tuple[str, Path]]) -> None:
    """Rename every staged file onto its target, all or none."""
    done: list[tuple[str, Path, str | None]] = []
    current = Path()
    try:
        for _, current in staged:
            if os.path.isdir(current):
                raise IsADirectoryError(errno.EISDIR, "it is a directory")
        for tmp, current in staged:
            done.append((tmp, current, _set_aside(current, tmp)))
            os.replace(tmp, current)
    except OSError as exc:
        _undo(done)
        raise _cannot(current, exc) from exc
    for _, _, backup in done:
        if backup is not None:
            with contextlib.suppress(OSError):
                os.unlink(backup)


def _set_aside(target: Path, tmp: str) -> str | None:
    """Move an existing ``target`` to a temporary name beside it, to be put back by
    :func:`_undo` if a later rename fails; its new name, or None when it does not exist."""
    if not os.path.lexists(target):
        return None
    fd, backup = tempfile.mkstemp(
        dir=target.parent, prefix=f"{os.path.basename(tmp)}.", suffix=".tmp"
    )
    os.close(fd)
    os.replace(target, backup)
    return backup


def _undo(done: Sequence[tuple[str, Path, str | None]]) -> None:
    for tmp, target, backup in reversed(done):
        with contextlib.suppress(OSError):
            if not os.path.exists(tmp):  # its rename happened
                os.unlink(target)
            if backup is not None:
                os.replace(backup, target)


def refuse_existing(force: bool, *paths: Path | None, remedy: str = "--force") -> None:
    """An existing output is never overwritten without ``force`` (``--force``, or the
    ``remedy`` the caller offers); a stream (:func:`is_stream`) is written into, not
    overwritten."""
    for path in paths:
        if not force and path is not None and os.path.lexists(path) and not is_stream(path):
            raise ParameterError(f"{path} exists; {remedy} overwrites it")


def write_json(data: Any) -> Writer:
    """A writer of strict JSON (no NaN)."""
    return lambda f: json.dump(data, f, indent=2, allow_nan=False, default=str)


def write_outputs(
    run: FuseRun,
    csv_path: str | Path,
    weights_path: str | Path | None = None,
    meta_path: str | Path | None = None,
    extra: dict[Path, tuple[Writer, bool]] | None = None,
) -> dict[str, str]:
    """Write the CSV, the optional weight traces and ``extra`` files (path: (writer, binary)),
    then the provenance sidecar, all or none. The sidecar is renamed into place last: a sidecar
    whose listed outputs all exist marks a complete set. Returns the files written, by role.

    A ``csv_path`` of ``-`` (:data:`STDOUT`) writes the CSV to standard output once the files
    are in place, and the sidecar only where ``meta_path`` names one."""
    csv_path = Path(csv_path)
    meta = Path(meta_path) if meta_path else default_meta_path(csv_path)
    outputs: dict[str, Path] = {table_format(csv_path): csv_path}
    if meta is not None:
        outputs["meta"] = meta
    if weights_path:
        outputs["weights"] = Path(weights_path)
    for path in extra or {}:
        outputs[path.suffix.lstrip(".") or path.name] = path
    # the sidecar names its siblings relative to itself: the same bytes wherever they are written
    here = Path.cwd() if meta is None else meta.parent
    listed = {
        role: str(path) if path == STDOUT else os.path.relpath(path, here)
        for role, path in outputs.items()
    }
    provenance = dict(run.provenance, outputs=listed)
    fused = write_table(fused_columns(run), table_format(csv_path), provenance)
    with atomic_outputs() as stage:
        if csv_path != STDOUT:
            stage(csv_path, fused, binary=True)
        if weights_path:
            weights = Path(weights_path)
            stage(
                weights, write_table(weights_columns(run), table_format(weights), provenance), True
            )
        for path, (write, binary) in (extra or {}).items():
            stage(path, write, binary)
        if meta is not None:
            stage(meta, write_json(provenance))
    if csv_path == STDOUT:
        fused(sys.stdout.buffer)
        sys.stdout.flush()
    return {role: str(path) for role, path in outputs.items()}
