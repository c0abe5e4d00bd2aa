"""Files as altfuse meets them on either side of a run: a path that is a stream rather than a
file (:func:`is_stream`), and the compressions a log may come in and an output be written in,
one table for both (:data:`COMPRESSIONS`). The standard library only."""

from __future__ import annotations

import bz2
import gzip
import io
import lzma
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Literal


def is_stream(path: Path) -> bool:
    """Whether ``path`` exists and is no regular file or directory, as it resolves: a device
    (``/dev/null``; ``/dev/stdout`` on a terminal), a named pipe (``/dev/stdout`` on a pipe).
    Such an output is written into, never replaced (:func:`altfuse.write.atomic_outputs`);
    such a log is read as it flows (:func:`altfuse.io.read_log`)."""
    return bool(stream_kind(path))


def stream_kind(path: Path) -> str:
    """What ``path`` is where :func:`is_stream`: "a pipe" (named or not), "a device" or "a socket";
    "" where it is a file, a folder or nothing."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return ""
    if stat.S_ISFIFO(mode):
        return "a pipe"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "" if stat.S_ISREG(mode) or stat.S_ISDIR(mode) else "a device"


@dataclass(frozen=True)
class Compression:
    """A compression by its name, the suffix a file's name ends in, and the bytes it starts
    with: Python's own stream of it, for reading (a log: ``flight.bin.gz``, by its first bytes)
    and writing (an output: ``flight.csv.gz``, by its name; byte-stable, gzip's header holding
    no time and no name)."""

    name: str
    suffix: str
    magic: bytes

    def open(self, raw: IO[bytes], mode: Literal["rb", "wb"]) -> io.BufferedIOBase:
        """``raw`` through this compression (closed by the caller; ``raw`` stays open)."""
        if self.name == "gzip":
            return gzip.GzipFile(filename="", mode=mode, fileobj=raw, mtime=0, compresslevel=6)
        if self.name == "bzip2":
            return bz2.BZ2File(raw, mode)
        return lzma.LZMAFile(raw, mode)


COMPRESSIONS = (
    Compression("gzip", ".gz", b"\x1f\x8b"),
    Compression("bzip2", ".bz2", b"BZh"),
    Compression("xz", ".xz", b"\xfd7zXZ\x00"),
)


def compression_named(path: Path) -> Compression | None:
    """The compression ``path``'s last suffix names, if one."""
    return next((c for c in COMPRESSIONS if c.suffix == path.suffix.lower()), None)


def compression_of(head: bytes) -> Compression | None:
    """The compression whose first bytes ``head`` begins with, if one."""
    return next((c for c in COMPRESSIONS if head.startswith(c.magic)), None)
