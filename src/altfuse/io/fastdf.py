"""Vectorised DataFlash decoding: per-type column arrays straight from the file's bytes.

pymavlink stays the authority on the format: its format-character table (``FORMAT_TO_STRUCT``,
held in :mod:`.framing`, tested equal) gives every field's binary layout and scale, and the tests
compare every value with its decoding.
What this module changes is the *how*: instead of one Python object per record, it

1. memory-maps the file read-only and finds, in one compiled pass, the FMT records (type 128,
   89 bytes) that could define a type, and reads them to learn each type's length and layout;
2. walks the record chain as pymavlink's sequential parser does, in a compiled loop over the
   bytes: a header of a known type at offset ``p`` is a record, and the next is looked for from
   ``p + length``; any other byte is stepped over (the resync on the header bytes). Linear in
   the file: headers that happen to appear inside a payload, or in damaged bytes, are never
   looked at. (Pruning such candidates round after round was quadratic on adversarial input:
   10 MB of repeated header bytes after a log took 267 s; listing them all first still cost
   12x a clean log's time);
3. reads again the FMT records the chain holds, and walks again if they define otherwise than
   all the candidates did (a FMT-like pattern in a payload must define nothing);
4. decodes only the requested types, all records of a type at once: their bytes gathered by
   offset from a strided view of the file, then read through a structured dtype built from the
   type's format string.

Like pymavlink's parser, the walk stops at the first record that the file ends inside (where
every log ends that the autopilot stopped writing mid-record: ``Index.cut_at``), and a type is
known only from its FMT record on. A log read off a flash chip (ArduPilot's block logger) ends
in erased flash, 0xFF to the end of the file: where it begins after the last record is
``Index.erased_at`` (a record it cut short is one to pymavlink, and so here). The other bytes
not in any record are the skipped bytes.

A FMT record that cannot describe its records truthfully keeps its length (the walk steps over
its records as pymavlink's does) but gets a ``problem``, and the reader decodes none of its
records: a Columns list whose count differs from the format's (a leading comma shifted every
name by one: BARO's Alt read its Temp), or a second definition of the type that differs from
the first (pymavlink decodes the records after it with the new one; a table of the type
cannot hold both, so it is refused, with the reason).
"""

from __future__ import annotations

import ctypes
import mmap
import os
import signal
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.lib.stride_tricks import as_strided

from altfuse.compiled import compiled
from altfuse.io.framing import (
    FMT_COLUMNS,
    FMT_FORMAT,
    FMT_LENGTH,
    FMT_TYPE,
    FORMAT_TO_STRUCT,
    HEADER,
    SYNC,
)

HEAD1, HEAD2 = SYNC
#: What erased flash reads: the end of a log read off a flash chip, where writing stopped.
ERASED = 0xFF
_CHUNK = 1 << 24  # the file searched and walked in 16 MiB chunks: bounded temporaries
_BATCH = 1 << 20  # records found per call of the walk

#: numpy dtype of each struct code in FORMAT_TO_STRUCT (little-endian, as DataFlash is).
_NUMPY = {
    "b": "i1", "B": "u1", "h": "<i2", "H": "<u2", "i": "<i4", "I": "<u4", "q": "<i8",
    "Q": "<u8", "f": "<f4", "d": "<f8", "e": "<f2", "4s": "S4", "16s": "S16", "64s": "S64",
}  # fmt: skip


class FormatError(ValueError):
    """A FMT record whose format string altfuse cannot lay out."""


@dataclass(frozen=True)
class Format:
    """One record type as its FMT record declares it."""

    type_id: int
    name: str
    length: int
    format: str
    columns: tuple[str, ...]
    dtype: np.dtype[Any] = field(repr=False)
    problem: str | None = None  # why its records are not to be decoded

    @classmethod
    def build(cls, type_id: int, name: str, length: int, fmt: str, columns: str) -> Format:
        names = tuple(columns.split(",")) if columns else ()
        problem = None
        if len(names) != len(fmt):
            problem = f"its FMT names {len(names)} columns for {len(fmt)} fields ({fmt!r})"
        elif len(set(names)) != len(names) or not all(names):
            problem = f"its FMT column names are empty or repeated ({columns!r})"
        fields = []
        for i, char in enumerate(fmt):
            if char not in FORMAT_TO_STRUCT:
                raise FormatError(f"{name}: unknown format character {char!r}")
            struct_code = FORMAT_TO_STRUCT[char][0]
            np_type = "(32,)<i2" if char == "a" else _NUMPY[struct_code]
            fields.append((names[i] if problem is None else f"_{i}", np_type))
        dtype = np.dtype(fields)
        if dtype.itemsize != length - HEADER:
            raise FormatError(
                f"{name}: format {fmt!r} is {dtype.itemsize} bytes, FMT says {length}"
            )
        return cls(type_id, name, length, fmt, names if problem is None else (), dtype, problem)

    def same_layout(self, other: Format) -> bool:
        return (self.name, self.length, self.format, self.columns) == (
            other.name, other.length, other.format, other.columns
        )  # fmt: skip


@dataclass
class Index:
    """Where the records are: offsets and type ids of the chain, the formats, where the record
    the file ends inside begins (None where it ends between records), where erased flash
    after the last record begins (None where there is none), and where another log appended
    to this one begins (None: none, or not looked for: :meth:`before`)."""

    data: npt.NDArray[np.uint8]
    offsets: npt.NDArray[np.integer[Any]]
    types: npt.NDArray[np.uint8]
    formats: dict[int, Format]
    size: int
    mapped: mmap.mmap | None = field(default=None, repr=False)  # the mapping ``data`` views
    cut_at: int | None = None
    erased_at: int | None = None
    appended_at: int | None = None  # where another log, appended to this one, begins

    def before(self, k: int) -> Index:
        """The chain up to its ``k``-th record, where another log appended to this one begins
        (``appended_at``, its byte): the rest is that log's."""
        return replace(
            self,
            offsets=self.offsets[:k],
            types=self.types[:k],
            cut_at=None,
            erased_at=None,
            appended_at=int(self.offsets[k]),
        )

    @cached_property
    def per_type(self) -> npt.NDArray[np.int64]:
        """The records of each type id, counted a megabyte of types at a time: ``bincount``
        takes its input as 8-byte integers (64 MB for the 8 million records of a 300 MB log,
        the reader's peak)."""
        out = np.zeros(256, dtype=np.int64)
        for start in range(0, self.types.size, 1 << 20):
            out += np.bincount(self.types[start : start + (1 << 20)], minlength=256)
        return out

    @property
    def decoded_bytes(self) -> int:
        return sum(int(self.per_type[t]) * f.length for t, f in self.formats.items())

    def counts(self) -> dict[str, int]:
        per_type = self.per_type
        return {f.name: int(per_type[t]) for t, f in self.formats.items() if per_type[t]}

    def records(self, type_id: int) -> npt.NDArray[Any]:
        """All records of ``type_id`` as a structured array (a copy), in file order."""
        return self.records_of([type_id])[type_id]

    def records_of(self, type_ids: Sequence[int]) -> dict[int, npt.NDArray[Any]]:
        """All records of each of ``type_ids`` (:meth:`records`), gathered in one pass over the
        file, a chunk at a time, each chunk's pages released once gathered: the records of
        every type lie all over the file, and a gather per type kept all its pages resident
        (the whole file: 381 MB of a 300 MB log after its GPS alone)."""
        at, out = {}, {}
        for type_id in type_ids:
            at[type_id] = self.offsets[self.types == type_id].astype(np.int64) + HEADER
            out[type_id] = np.zeros(at[type_id].size, dtype=self.formats[type_id].dtype)
        for start in range(0, self.size, 4 * _CHUNK):
            stop = start + 4 * _CHUNK
            for type_id, offsets in at.items():
                a, b = np.searchsorted(offsets, [start, stop])
                if b > a:
                    out[type_id][a:b] = self._gather(type_id, offsets[a:b])
            _release(self.mapped, start, stop)
        return out

    def _gather(self, type_id: int, offsets: npt.NDArray[np.int64]) -> npt.NDArray[Any]:
        """The records of ``type_id`` at the payload ``offsets``."""
        fmt = self.formats[type_id]
        width = fmt.dtype.itemsize
        # every byte offset as the start of a row of ``width`` bytes (a view, no copy); gathering
        # plain bytes is ~3x faster than gathering unaligned structured items
        windows = as_strided(self.data, shape=(self.data.size - width + 1, width), strides=(1, 1))
        rows: npt.NDArray[Any] = windows[offsets].view(fmt.dtype).reshape(-1)
        return rows


def _release(mapped: mmap.mmap | None, start: int, stop: int) -> None:
    """Drop the pages of ``mapped[start:stop]`` from the process (``MADV_DONTNEED``): they are
    the file's, read again where a record is decoded, and a 3 GB run of zeros after a log no
    longer stays in the process's memory (3.3 GB resident before)."""
    start -= start % mmap.PAGESIZE
    stop -= stop % mmap.PAGESIZE
    if mapped is not None and hasattr(mmap, "MADV_DONTNEED") and stop > start:
        mapped.madvise(mmap.MADV_DONTNEED, start, stop - start)


def _definers(data: npt.NDArray[np.uint8], mapped: mmap.mmap | None) -> npt.NDArray[np.int64]:
    """Offsets of the headers that could be FMT records defining a type (see :func:`_scan`),
    searched in chunks whose pages are released once searched."""
    last = data.size - FMT_LENGTH + 1  # the first offset a FMT record does not fit at
    buffer = np.empty(min(_CHUNK, max(last, 0)), dtype=np.int64)
    found = [buffer[:0]]
    for start in range(0, max(last, 0), _CHUNK):
        stop = min(start + _CHUNK, last)
        found.append(buffer[: _scan(data, start, stop, buffer)].copy())
        _release(mapped, start, stop)
    return np.concatenate(found)


@compiled
def _scan(data: npt.NDArray[np.uint8], start: int, stop: int, out: npt.NDArray[np.int64]) -> int:
    """The definers starting in ``data[start:stop]`` into the first entries of ``out``; their
    count. A definer is a FMT header whose Length leaves a payload and whose Name starts with a
    capital or a digit, as every type's does: only those are read as FMT records (a file of
    FMT-like bytes holds millions of FMT headers, and each costs a Python step there)."""
    n = 0
    for i in range(start, stop):
        if data[i] != HEAD1:
            continue
        if data[i + 1] != HEAD2 or data[i + 2] != FMT_TYPE:
            continue
        name0 = data[i + HEADER + 2]
        if data[i + HEADER + 1] > HEADER and (
            (name0 >= ord("A") and name0 <= ord("Z")) or (name0 >= ord("0") and name0 <= ord("9"))
        ):
            out[n] = i
            n += 1
    return n


def _text(raw: bytes) -> str:
    raw = raw.split(b"\0", 1)[0]
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("ISO-8859-1")


def _formats(
    data: npt.NDArray[np.uint8], at: npt.NDArray[np.integer[Any]]
) -> tuple[dict[int, Format], dict[int, int]]:
    """The well-formed FMT records among the definers at ``at`` (see :func:`_scan`): formats by
    type id, and where each was defined."""
    fmt_dtype = Format.build(FMT_TYPE, "FMT", FMT_LENGTH, FMT_FORMAT, FMT_COLUMNS).dtype
    formats: dict[int, Format] = {
        FMT_TYPE: Format.build(FMT_TYPE, "FMT", FMT_LENGTH, FMT_FORMAT, FMT_COLUMNS)
    }
    first: dict[int, int] = {FMT_TYPE: -1}
    if at.size == 0:
        return formats, first
    count = data.size - fmt_dtype.itemsize + 1
    # each distinct record is read once, at its first offset: a file of repeated FMT records
    # holds millions, and the Python loop below is what each costs
    raw = np.ndarray(shape=(count,), dtype=f"V{fmt_dtype.itemsize}", buffer=data, strides=(1,))
    _, first_of = np.unique(raw[at + HEADER], return_index=True)
    at = at[np.sort(first_of)]
    rows = np.ndarray(shape=(count,), dtype=fmt_dtype, buffer=data, strides=(1,))[at + HEADER]
    for offset, row in zip(at.tolist(), rows, strict=True):
        type_id, length = int(row["Type"]), int(row["Length"])
        if type_id == FMT_TYPE:
            continue
        try:
            found = Format.build(
                type_id, _text(row["Name"]), length, _text(row["Format"]), _text(row["Columns"])
            )
        except (FormatError, ValueError, KeyError):
            continue
        known = formats.get(type_id)
        if known is None:
            formats[type_id] = found
            first[type_id] = offset
        elif known.problem is None and not known.same_layout(found):
            why = f"it is defined again at byte {offset} with another layout ({found.format!r})"
            formats[type_id] = replace(known, problem=why)
    return formats, first


def _records(
    data: npt.NDArray[np.uint8],
    mapped: mmap.mmap | None,
    formats: dict[int, Format],
    first: dict[int, int],
) -> tuple[npt.NDArray[np.integer[Any]], npt.NDArray[np.uint8], int | None]:
    """The record chain under ``formats`` (see :func:`_walk`): offsets (int32 below 2 GiB) and
    types, walked a chunk of the file at a time, each chunk's pages released once passed; and
    where the record the file ends inside begins (None where there is none)."""
    known = np.zeros((2, 256), dtype=np.int64)  # each type's length, and where it is defined
    known[1] = np.iinfo(np.int64).max
    for type_id, fmt in formats.items():
        known[:, type_id] = fmt.length, first[type_id]
    dtype = np.int32 if data.size < 2**31 - 1024 else np.int64
    offsets = np.empty(min(_BATCH, data.size), dtype=dtype)
    types = np.empty(offsets.size, dtype=np.uint8)
    found = [(offsets[:0], types[:0])]
    at, released, cut = 0, 0, False
    while not cut and at <= data.size - HEADER:
        limit = (at // _CHUNK + 1) * _CHUNK
        n, at, cut = _walk(data, known, at, limit, offsets, types)
        found.append((offsets[:n].copy(), types[:n].copy()))
        _release(mapped, released, at)
        released = at
    chain = np.concatenate([f[0] for f in found]), np.concatenate([f[1] for f in found])
    return *chain, at if cut else None


@compiled
def _walk(
    data: npt.NDArray[np.uint8],
    known: npt.NDArray[np.int64],
    start: int,
    limit: int,
    offsets: npt.NDArray[np.integer[Any]],
    types: npt.NDArray[np.uint8],
) -> tuple[int, int, bool]:
    """pymavlink's sequential parse from byte ``start``: a header of a known type (its length
    in ``known[0]`` not 0, defined before it: ``known[1]``) is a record, and the next is looked
    for at its end; any other byte is stepped over. Stops at ``limit``, when ``offsets`` is
    full, or at a record the file ends inside (not a record either: the parse stops there, as
    pymavlink's does). Returns the records found, the offset to go on from, and whether the
    file ended inside a record. Linear in the bytes: header-like bytes inside a payload are
    never looked at (listing them first cost 12x a clean log's time on 50 MB of repeated
    header bytes; pruning them round after round, before that, was quadratic)."""
    size = data.size
    end = min(limit, size - HEADER + 1)
    n = 0
    at = start
    while at < end and n < offsets.size:
        while at < end and data[at] != HEAD1:  # the tight loop that skips damaged bytes
            at += 1
        if at == end:
            break
        if data[at + 1] == HEAD2:
            kind = data[at + 2]
            length = known[0, kind]
            if length > 0 and at > known[1, kind]:
                if at + length > size:
                    return n, at, True
                offsets[n] = at
                types[n] = kind
                n += 1
                at += length
                continue
        at += 1
    return n, at, False


#: SIGBUS comes when a mapped file shrinks under the reader (a log truncated while it is read):
#: the page is gone and the access cannot complete. Python cannot handle it (its handlers run
#: after the faulting access, which repeats), so a C-level handler says so in one line and ends
#: the process with exit 1, where it died silently before.
_SIGBUS_LINE = b"altfuse: error: the log shrank while it was being read (SIGBUS); read it again\n"
_HANDLER = ctypes.CFUNCTYPE(None, ctypes.c_int)
_installed: list[Any] = []  # the handler, kept alive once installed


def _on_sigbus(_signum: int) -> None:
    os.write(2, _SIGBUS_LINE)
    os._exit(1)


def exit_on_sigbus() -> None:
    """Install the SIGBUS handler (see ``_SIGBUS_LINE``), once per process, where libc has one."""
    if _installed or not hasattr(signal, "SIGBUS"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.signal.restype = ctypes.c_void_p
        libc.signal.argtypes = [ctypes.c_int, _HANDLER]
    except (OSError, AttributeError):
        return
    handler = _HANDLER(_on_sigbus)
    libc.signal(signal.SIGBUS, handler)
    _installed.append(handler)


def _erased(data: npt.NDArray[np.uint8], start: int) -> bool:
    """Whether every byte from ``start`` to the end is erased flash, compared a chunk at a time
    (a sparse file's hole of zeros is given up after its first chunk, not compared whole)."""
    return all((data[a : a + _CHUNK] == ERASED).all() for a in range(start, data.size, _CHUNK))


def index_file(path: str | Path) -> Index:
    """Map ``path`` read-only and find its records as pymavlink's sequential parser would."""
    exit_on_sigbus()
    with Path(path).open("rb") as handle:
        size = handle.seek(0, 2)
        if size == 0:
            return Index(np.zeros(0, np.uint8), np.zeros(0, np.int64), np.zeros(0, np.uint8), {}, 0)
        mapped = mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ)
    data = np.frombuffer(mapped, dtype=np.uint8)
    definers = _definers(data, mapped)
    # FMT records define the types; a pattern inside a payload that looks like one must not. The
    # first walk trusts every FMT candidate, the next only those on the chain, until the
    # definitions they make are stable.
    formats, first = _formats(data, definers)
    for _ in range(3):
        offsets, types, cut_at = _records(data, mapped, formats, first)
        fmt_at = offsets[types == FMT_TYPE]  # both sorted: np.isin's hashing took 0.8 s
        where = np.minimum(np.searchsorted(fmt_at, definers), max(fmt_at.size - 1, 0))
        on_chain = fmt_at[where] == definers if fmt_at.size else np.zeros(definers.size, bool)
        chained = _formats(data, definers[on_chain])
        if chained == (formats, first):
            break
        formats, first = chained
    erased_at = None
    if cut_at is None and offsets.size:  # the file may end inside the header of a record too
        tail = int(offsets[-1]) + formats[int(types[-1])].length
        if 0 < size - tail < HEADER and bytes(data[tail:]) == SYNC[: size - tail]:
            cut_at = tail
        elif size > tail and _erased(data, tail):
            erased_at = tail
    return Index(data, offsets, types, formats, size, mapped, cut_at, erased_at)
