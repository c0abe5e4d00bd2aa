"""Readers: one module per input format behind :func:`read_log`, which picks by magic bytes."""

from __future__ import annotations

import bz2
import contextlib
import gzip
import hashlib
import io
import lzma
import tempfile
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

from altfuse.errors import LogReadError
from altfuse.io.framing import FMT_HEADER
from altfuse.model import FlightLog

ULOG_MAGIC = b"ULog\x01\x12\x35"
_SNIFF_BYTES = 4096
#: Logs kept compressed, as fleets archive them (``flight.bin.gz``), known by their first
#: bytes: gzip, bzip2, xz. Decompressed into a temporary file, read from it, and described as
#: the file given (its name, size and sha256: the file a later ``--skip-existing`` hashes).
COMPRESSIONS = {b"\x1f\x8b": "gzip", b"BZh": "bzip2", b"\xfd7zXZ\x00": "xz"}
#: Their names' last suffixes, which a batch finds and strips from its outputs' names.
COMPRESSED_SUFFIXES = (".gz", ".bz2", ".xz")


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


@contextlib.contextmanager
def hashing(path: Path) -> Iterator[Future[str]]:
    """The file's sha256, computed in a thread while a reader reads the file (hashlib lets go
    of the GIL, and so do the compiled loops: a separate pass was 0.22 s of 1.16 s on a 300 MB
    DataFlash log)."""
    with ThreadPoolExecutor(1, thread_name_prefix="altfuse-sha256") as pool:
        yield pool.submit(sha256_of, path)


def read_log(path: str | Path) -> FlightLog:
    """Read a flight log, choosing the reader by the file's first bytes, not its name.

    The log comes as it is written: screening impossible samples (:func:`altfuse.screen.screen`)
    is the pipeline's first stage.

    Raises
    ------
    LogReadError
        The file is missing, empty, unreadable, or not a format altfuse reads.
    """
    path = Path(path)
    if not path.exists():
        raise LogReadError(f"{path}: no such file")
    if path.is_dir():
        raise LogReadError(
            f"{path}: a folder, not a log; for its logs: altfuse batch {path} -o OUT"
        )
    if not path.is_file():
        raise LogReadError(f"{path}: not a file")
    try:
        with path.open("rb") as handle:
            head = handle.read(_SNIFF_BYTES)
    except OSError as exc:
        raise LogReadError(f"{path}: cannot read ({exc.strerror})") from exc
    if not head:
        raise LogReadError(f"{path}: the file is empty")
    for magic, kind in COMPRESSIONS.items():
        if head.startswith(magic):
            return _read_compressed(path, kind)
    if head.startswith(ULOG_MAGIC):
        from altfuse.io.ulog import read_ulog

        return read_ulog(path)
    if FMT_HEADER not in head:
        raise LogReadError(
            f"{path}: not a DataFlash log (no FMT record in its first bytes) nor a ULog"
        )
    from altfuse.io.dataflash import read_dataflash

    return read_dataflash(path)


def _decompressing(path: Path, kind: str) -> io.BufferedIOBase:
    """``path`` opened through its ``kind`` of compression (:data:`COMPRESSIONS`)."""
    if kind == "gzip":
        return gzip.GzipFile(path, "rb")
    if kind == "bzip2":
        return bz2.BZ2File(path, "rb")
    return lzma.LZMAFile(path, "rb")


def _read_compressed(path: Path, kind: str) -> FlightLog:
    """The log compressed in ``path`` (``kind``: gzip, bzip2, xz), decompressed into a
    temporary file and read from it; described as ``path``. A stream that ends early or goes
    bad is read as far as it decompresses (as a log cut short is), with a note; one that gives
    nothing is not a log."""
    with tempfile.TemporaryDirectory(prefix="altfuse-") as folder:
        plain = Path(folder) / path.with_suffix("").name
        cut = ""
        try:
            with _decompressing(path, kind) as stream, plain.open("wb") as out:
                try:  # a buffered read loses what it holds when the stream breaks: read1's don't
                    while chunk := stream.read1(1 << 20):
                        out.write(chunk)
                except (EOFError, OSError, lzma.LZMAError, ValueError) as exc:
                    if out.tell() == 0:
                        raise LogReadError(f"{path}: cannot decompress its {kind} ({exc})") from exc
                    cut = f"{kind} stream cut after {out.tell()} bytes ({exc}): read up to there"
        except OSError as exc:
            raise LogReadError(f"{path}: cannot decompress ({exc.strerror or exc})") from exc
        flight = read_log(plain)
    notes = (*flight.notes, f"read from its {kind} compression", *((cut,) if cut else ()))
    return replace(
        flight,
        path=str(path),
        sha256=sha256_of(path),
        size_bytes=path.stat().st_size,
        notes=notes,
        damaged=(*flight.damaged, cut) if cut else flight.damaged,
    )
