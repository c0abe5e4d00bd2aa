"""Readers: one module per input format behind :func:`read_log`, which picks by magic bytes."""

from __future__ import annotations

import contextlib
import hashlib
import io
import lzma
import stat
import sys
import tempfile
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import IO, Any, Literal, cast

from altfuse.errors import AltfuseError, LogReadError
from altfuse.files import Compression, compression_of, is_stream, stream_kind
from altfuse.io.framing import FMT_HEADER
from altfuse.model import FlightLog, counted

ULOG_MAGIC = b"ULog\x01\x12\x35"
#: The first bytes that tell what a log is (:func:`_kind`): as many as pymavlink reads to tell a
#: text log (an FMT line in its first 8,000 characters: old logs open with banner lines).
_SNIFF_BYTES = 8192
#: What a log is by its first bytes (:func:`_kind`): compressed, as fleets archive logs
#: (``flight.bin.gz``: decompressed into a temporary file, read from it, and described as the
#: file given, its name, size and sha256, what a later ``--skip-existing`` hashes), a ULog, a
#: DataFlash log, or one written as text (``flight.log``: converted into a temporary binary
#: log, :mod:`altfuse.io.dataflash_text`, and described as the file given).
Kind = Compression | Literal["ulog", "dataflash", "dataflash-text"]
#: A MAVLink telemetry log (``.tlog``, what a ground station records) is each packet after its
#: time of reception, microseconds since 1970 as a big-endian uint64: a time within these
#: years (2000-2100) and a packet's first byte (:func:`_is_telemetry_log`).
_TLOG_SPAN_US = (946_684_800_000_000, 4_102_444_800_000_000)
#: A MAVLink packet's first byte, and its length beyond the payload (header and checksum).
_MAVLINK_FRAMES = {0xFE: 8, 0xFD: 12}  # MAVLink 1, MAVLink 2 (13 more where signed)
#: Archives by their first bytes (a fleet's logs come zipped from a cloud or a ground
#: station): no log, nor a single compressed stream, and said so with what they hold.
_ARCHIVES = {b"PK\x03\x04": "zip", b"PK\x05\x06": "zip", b"7z\xbc\xaf\x27\x1c": "7z",
             b"Rar!\x1a\x07": "rar"}  # fmt: skip


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def appended_log(byte: int | None, size: int, clock: str = "") -> str:
    """The line a reader says of another log appended to the one it read (two files joined:
    ``cat a.bin b.bin``): where it begins, by its ``byte`` of the file's ``size`` (None: the
    file is another's decoded form, whose bytes are not the file's) and by ``clock`` (what
    the clocks say there, where the reader knows), and how to fuse it."""
    parts = [] if byte is None else [f"{size - byte:,} bytes"]
    told = "; ".join([*parts, clock] if clock else parts)
    where = "" if byte is None else f" from byte {byte:,}"
    how = "split the file where it begins" if byte is None else "cut the file there"
    return (
        f"another log is appended{where}{f' ({told})' if told else ''}: the first alone is "
        f"read; to fuse the other, {how}"
    )


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
    if str(path) == "-" or is_stream(path):  # the log flows in: standard input, a pipe
        return _read_piped(path)
    return _read_as(path, _kind(path, _head(path)))


def _read_as(path: Path, kind: Kind, decoded: bool = False) -> FlightLog:
    """The log at ``path``, read as what its first bytes say it is (:func:`_kind`);
    ``decoded``: it is another file's decoded form (decompressed, a text log converted), whose
    bytes are not that file's."""
    if isinstance(kind, Compression):
        return _read_compressed(path, kind)
    if kind == "ulog":
        from altfuse.io.ulog import read_ulog

        return read_ulog(path, decoded=decoded)
    if kind == "dataflash-text":
        return _read_text(path)
    from altfuse.io.dataflash import read_dataflash

    return read_dataflash(path, decoded=decoded)


def _kind(path: Path, head: bytes) -> Kind:
    """What a log whose first bytes are ``head`` is; a LogReadError where it is no log."""
    packed = compression_of(head)
    if packed is not None:
        return packed
    if head.startswith(ULOG_MAGIC):
        return "ulog"
    # before the DataFlash header is looked for: an archive may hold a log's bytes as they are
    archive = next((name for magic, name in _ARCHIVES.items() if head.startswith(magic)), None)
    if archive is not None or head[257:262] == b"ustar":
        holds = _members(path) if archive == "zip" else ""
        raise LogReadError(
            f"{path}: a {archive or 'tar'} archive{holds}, not a log: extract the log from it "
            "(altfuse reads one log compressed with gzip, bzip2 or xz as it is)"
        )
    if FMT_HEADER in head:
        return "dataflash"
    from altfuse.io.dataflash_text import is_text_log

    if is_text_log(head):
        return "dataflash-text"
    if _is_telemetry_log(head):
        raise LogReadError(
            f"{path}: a MAVLink telemetry log (.tlog, a ground station's recording), which "
            "altfuse does not read: fuse the autopilot's own log (a DataFlash .bin)"
        )
    raise LogReadError(
        f"{path}: not a DataFlash log (no FMT record in its first bytes, as binary or as "
        "text) nor a ULog"
    )


def _members(path: Path, shown: int = 3) -> str:
    """What the zip archive ``path`` holds, for the refusal: its first ``shown`` files' names
    (nothing for a zip that does not open)."""
    import zipfile  # only for this refusal

    try:
        with zipfile.ZipFile(path) as archive:
            names = [i.filename for i in archive.infolist() if not i.is_dir()]
    except (OSError, zipfile.BadZipFile):
        return ""
    more = f" and {len(names) - shown} more" if len(names) > shown else ""
    return f" of {counted(len(names), 'file')} ({', '.join(names[:shown])}{more})"


def _is_telemetry_log(head: bytes, packets: int = 3) -> bool:
    """Whether ``head``, a file's first bytes, holds MAVLink packets each after its time of
    reception (:data:`_TLOG_SPAN_US`): the first ``packets`` of them, as many as it holds."""
    at = seen = 0
    while seen < packets and at + 11 <= len(head):
        stamp = int.from_bytes(head[at : at + 8], "big")
        magic, length = head[at + 8], head[at + 9]
        if magic not in _MAVLINK_FRAMES or not _TLOG_SPAN_US[0] <= stamp <= _TLOG_SPAN_US[1]:
            return False
        signed = magic == 0xFD and head[at + 10] & 1  # MAVLink 2's incompatibility flags
        at += 8 + length + _MAVLINK_FRAMES[magic] + 13 * signed
        seen += 1
    return seen > 0


def _head(path: Path) -> bytes:
    """The first bytes of the file at ``path``, by which :func:`read_log` picks its reader."""
    try:
        mode = path.stat().st_mode
    except (FileNotFoundError, ValueError):  # ValueError: a NUL in the name
        raise LogReadError(f"{path}: no such file") from None
    except OSError as exc:  # a folder on the way that may not be entered
        raise LogReadError(f"{path}: cannot read ({exc.strerror})") from exc
    if stat.S_ISDIR(mode):
        raise LogReadError(
            f"{path}: a folder, not a log; for its logs: altfuse batch {path} -o OUT"
        )
    if not stat.S_ISREG(mode):
        raise LogReadError(f"{path}: not a file")
    try:
        with path.open("rb") as handle:
            head = handle.read(_SNIFF_BYTES)
    except OSError as exc:
        raise LogReadError(f"{path}: cannot read ({exc.strerror})") from exc
    if not head:
        raise LogReadError(f"{path}: the file is empty")
    return head


class _Hashed(io.RawIOBase):
    """A file read through, its sha256 and size taken on the way: a compressed log is read
    once (a second pass hashed it after its decompression)."""

    def __init__(self, raw: io.BufferedReader) -> None:
        self.raw, self.digest, self.size = raw, hashlib.sha256(), 0

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        n = self.raw.readinto(buffer)
        self.digest.update(memoryview(buffer)[:n])
        self.size += n
        return int(n)

    def drain(self) -> None:
        """Hash what the decompressor left unread (a stream cut short, trailing bytes)."""
        for _ in iter(lambda: self.read(1 << 20), b""):
            pass


def _read_compressed(path: Path, packed: Compression) -> FlightLog:
    """The log compressed in ``path``, decompressed and read (:func:`_read_through`)."""
    return _read_through(
        path, lambda raw: packed.open(raw, "rb"), f"its {packed.name} compression", "decompress"
    )


def _read_text(path: Path) -> FlightLog:
    """The DataFlash text log ``path``, each line converted into its binary record as it is
    read (:class:`~altfuse.io.dataflash_text.BinaryFromText`), and the binary log read
    (:func:`_read_through`). Lines left out are damage, said as a binary log's skipped bytes
    are."""
    from altfuse.io.dataflash_text import BinaryFromText

    converted: list[BinaryFromText] = []

    def convert(raw: IO[bytes]) -> io.BufferedIOBase:
        converted.append(BinaryFromText(raw))
        return io.BufferedReader(converted[0])

    flight = _read_through(path, convert, "its DataFlash text", "read")
    said = converted[0].note()
    return replace(
        flight,
        notes=(*flight.notes, said),
        damaged=(*flight.damaged, said) if converted[0].left_out else flight.damaged,
        reader=f"DataFlash text, converted to binary (altfuse.io.dataflash_text); {flight.reader}",
    )


def _read_through(
    path: Path, through: Callable[[IO[bytes]], io.BufferedIOBase], source: str, verb: str
) -> FlightLog:
    """The log that the file ``path`` gives ``through`` a decoder (a decompression, the text
    form's conversion), read from a copy (:func:`_read_copied`); described as the file given,
    its size and sha256 taken as it is decoded (the file is read once)."""
    try:
        with path.open("rb") as raw:
            hashed = _Hashed(raw)
            with through(cast(IO[bytes], io.BufferedReader(hashed))) as stream:
                flight = _read_copied(path, stream, source, decoded=True)
            hashed.drain()
    except OSError as exc:
        raise LogReadError(f"{path}: cannot {verb} ({exc.strerror or exc})") from exc
    return replace(flight, sha256=hashed.digest.hexdigest(), size_bytes=hashed.size)


def _read_piped(path: Path) -> FlightLog:
    """The log flowing through ``path`` (``-``: standard input; a named pipe, ``<(zcat x)``,
    ``/dev/stdin``), copied and read (:func:`_read_copied`): its size and sha256 are the bytes
    that came."""
    if str(path) == "-":
        if sys.stdin is None:  # closed: altfuse fuse - <&-
            raise LogReadError("-: standard input is closed; pipe a log in")
        _refuse_terminal(path, sys.stdin.buffer)
        return _read_copied(path, cast(io.BufferedReader, sys.stdin.buffer), "standard input")
    try:
        with path.open("rb") as stream:
            _refuse_terminal(path, stream)
            return _read_copied(path, stream, stream_kind(path) or "a pipe")
    except OSError as exc:
        raise LogReadError(f"{path}: cannot read ({exc.strerror or exc})") from exc


def _refuse_terminal(path: Path, stream: IO[bytes]) -> None:
    """A terminal gives no log, only what is typed into it: ``altfuse fuse - -o f.csv`` without
    a pipe waited for it in silence, as if the command hung."""
    if stream.isatty():
        raise LogReadError(
            f"{path}: a terminal, not a log; pipe one in (altfuse fuse - -o f.csv < flight.bin)"
        )


def _read_copied(
    path: Path, stream: io.BufferedIOBase, source: str, decoded: bool = False
) -> FlightLog:
    """The log in ``stream`` (from ``source``: a compression, a pipe; ``decoded``: not the
    file's own bytes), copied into a temporary file (the readers map a file) and read from it;
    its path ``path``, the copy noted. A stream that ends early or goes bad is read as far as
    it came (as a log cut short is), the damage said; one that gives nothing, or whose first
    bytes are no log's (``/dev/zero``), is not a log, and is not copied on."""
    with tempfile.TemporaryDirectory(prefix="altfuse-") as folder:
        copy = Path(folder) / (path.with_suffix("").name or "log")
        cut, head, kind = "", b"", None
        with copy.open("wb") as out:
            try:  # a buffered read loses what it holds when the stream breaks: read1's don't
                while chunk := stream.read1(1 << 20):
                    if kind is None:
                        head += chunk[: _SNIFF_BYTES - len(head)]
                        if len(head) == _SNIFF_BYTES:
                            kind = _kind(path, head)  # no log's first bytes: the rest not copied
                    out.write(chunk)
            except (EOFError, OSError, lzma.LZMAError, ValueError) as exc:
                if not head:
                    raise LogReadError(f"{path}: cannot read {source} ({exc})") from exc
                cut = f"{source} cut after {out.tell()} bytes ({exc}): read up to there"
        if not head:
            raise LogReadError(f"{path}: nothing came from {source}")
        try:
            flight = _read_as(copy, _kind(path, head) if kind is None else kind, decoded)
        except AltfuseError as exc:  # said of the log given, not of its copy
            exc.args = (str(exc).replace(str(copy), str(path)), *exc.args[1:])
            raise
    return replace(
        flight,
        path=str(path),
        notes=(*flight.notes, f"read from {source}", *((cut,) if cut else ())),
        damaged=(*flight.damaged, cut) if cut else flight.damaged,
    )
