"""Damaged variants of real logs, for the property test and the long fuzz run.

Every mutation takes a log's bytes and returns damaged bytes: truncation, byte flips, zeroed and
duplicated blocks, records shuffled, FMT records removed, garbage inserted; and, record-aware
(issue 16): a type redefined mid-file, FMT records with absurd lengths and format characters,
Columns lists that do not match, a field's type changed, non-finite and extreme values in any
numeric field, 14 kinds of timestamp damage, and values frozen over a run of records. Record
boundaries and layouts come from altfuse's own index of the (undamaged) base log; the
record-aware mutations apply to the base log's bytes (run them first: a mutation before them
would move the records). A PX4 ULog takes the byte-level ones and damage to the values of the
topics altfuse reads (through pyulog, which writes it again); a DataFlash text log the
byte-level ones and damage to its lines, fields, FMT lines and delimiters.
"""

from __future__ import annotations

import contextlib
import io
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from altfuse.io.fastdf import FMT_TYPE, Format, index_file
from altfuse.io.framing import HEADER
from altfuse.io.ulog import TOPICS

Mutation = Callable[[bytes, np.random.Generator, "Records"], bytes]


def _at(rng: np.random.Generator, data: bytes) -> int:
    """A position in ``data``, 0 to len(data) (an empty file has one: 0)."""
    return int(rng.integers(0, len(data) + 1))


class Records:
    """Where a base log's records are."""

    def __init__(self, path: Path) -> None:
        index = index_file(path)
        lengths = {t: f.length for t, f in index.formats.items()}
        self.size = index.size
        self.starts = index.offsets.astype(np.int64)
        self.types = index.types
        self.ends = self.starts + np.array([lengths[t] for t in self.types.tolist()], np.int64)
        self.formats: dict[int, Format] = {
            t: f for t, f in index.formats.items() if t != FMT_TYPE and np.any(self.types == t)
        }

    def fields(self, rng: np.random.Generator, numeric: bool = True) -> tuple[Format, str]:
        """A random type of the log and one of its (numeric) fields."""
        choices = [
            (f, name)
            for f in self.formats.values()
            for name, char in zip(f.columns, f.format, strict=True)
            if not numeric or char not in "nNZa"
        ]
        return choices[int(rng.integers(len(choices)))]

    def offsets_of(self, fmt: Format, name: str) -> np.ndarray:
        """Where field ``name`` of every record of ``fmt`` starts in the file."""
        at = self.starts[(self.types == fmt.type_id) & (self.ends <= self.size)]
        return at + HEADER + int(fmt.dtype.fields[name][1])  # type: ignore[index]


def truncate(data: bytes, rng: np.random.Generator, _: Records) -> bytes:
    return data[: _at(rng, data)]


def flip_bytes(data: bytes, rng: np.random.Generator, _: Records) -> bytes:
    out = bytearray(data)
    for at in rng.integers(0, max(len(data), 1), int(rng.integers(1, 200)) if data else 0):
        out[at] ^= int(rng.integers(1, 256))
    return bytes(out)


def zero_block(data: bytes, rng: np.random.Generator, _: Records) -> bytes:
    start = _at(rng, data)
    length = int(rng.integers(1, 50_000))
    return data[:start] + bytes(min(length, len(data) - start)) + data[start + length :]


def duplicate_block(data: bytes, rng: np.random.Generator, _: Records) -> bytes:
    start = _at(rng, data)
    block = data[start : start + int(rng.integers(1, 50_000))]
    at = _at(rng, data)
    return data[:at] + block + data[at:]


def shuffle_records(data: bytes, rng: np.random.Generator, rec: Records) -> bytes:
    """Move a run of whole records elsewhere (timestamps then run backwards)."""
    n = rec.starts.size
    if n < 3:
        return data
    i = int(rng.integers(0, n - 1))
    j = min(n, i + int(rng.integers(1, 500)))
    block = data[rec.starts[i] : rec.ends[j - 1]]
    rest = data[: rec.starts[i]] + data[rec.ends[j - 1] :]
    k = int(rng.integers(0, n - (j - i)))
    at = int(rec.starts[k]) if rec.starts[k] < len(rest) else len(rest)
    return rest[:at] + block + rest[at:]


def remove_fmt(data: bytes, rng: np.random.Generator, rec: Records) -> bytes:
    """Remove the FMT records of some types (or all of them)."""
    fmts = np.flatnonzero(rec.types == FMT_TYPE)
    if fmts.size == 0:
        return data
    doomed = fmts if rng.random() < 0.2 else rng.choice(fmts, int(rng.integers(1, fmts.size + 1)))
    keep = np.ones(len(data), dtype=bool)
    for r in np.unique(doomed):
        keep[rec.starts[r] : rec.ends[r]] = False
    return np.frombuffer(data, np.uint8)[keep].tobytes()


def insert_garbage(data: bytes, rng: np.random.Generator, _: Records) -> bytes:
    at = _at(rng, data)
    junk = rng.integers(0, 256, int(rng.integers(1, 5000)), dtype=np.uint8).tobytes()
    if rng.random() < 0.5:  # garbage that looks like headers
        junk = junk.replace(b"\x00", b"\xa3\x95")
    return data[:at] + junk + data[at:]


FMT_FIELDS = {"type": 3, "length": 4, "name": slice(5, 9), "format": slice(9, 25),
              "columns": slice(25, 89)}  # fmt: skip
_FORMATS_BY_SIZE = {1: "bB", 2: "hHc", 4: "iIfnLeE", 8: "qQd"}


def _fmt_at(data: bytes, rng: np.random.Generator, rec: Records) -> int | None:
    """The offset of a random FMT record of one of the log's types."""
    fmts = [
        int(s)
        for s in rec.starts[rec.types == FMT_TYPE].tolist()
        if data[s + 3] in rec.formats and s + 89 <= len(data)
    ]
    return fmts[int(rng.integers(len(fmts)))] if fmts else None


def _put(out: bytearray, at: int, where: slice, text: bytes) -> None:
    width = where.stop - where.start
    out[at + where.start : at + where.stop] = text.ljust(width, b"\0")[:width]


def _relabelled(record: bytes, rng: np.random.Generator) -> bytes:
    """A FMT record with its Columns list damaged as the audit saw."""
    out = bytearray(record)
    cols = bytes(out[25:89]).rstrip(b"\0").split(b",")
    kind = int(rng.integers(5))
    if kind == 0:
        cols = [b"", *cols]  # a leading comma
    elif kind == 1 and len(cols) > 1:
        cols[0], cols[1] = cols[1], cols[0]  # TimeUS and the next swapped
    elif kind == 2:
        cols = [*cols, b"Extra"]
    elif kind == 3 and len(cols) > 1:
        cols[-1] = cols[0]  # a repeated name
    else:
        cols = cols[: int(rng.integers(len(cols)))]
    _put(out, 0, FMT_FIELDS["columns"], b",".join(cols))  # type: ignore[arg-type]
    return bytes(out)


def fmt_columns(data: bytes, rng: np.random.Generator, rec: Records) -> bytes:
    at = _fmt_at(data, rng, rec)
    if at is None:
        return data
    return data[:at] + _relabelled(data[at : at + 89], rng) + data[at + 89 :]


def fmt_absurd(data: bytes, rng: np.random.Generator, rec: Records) -> bytes:
    """A FMT's Length a random byte, or its format string random characters."""
    at = _fmt_at(data, rng, rec)
    if at is None:
        return data
    out = bytearray(data)
    if rng.random() < 0.5:
        out[at + 4] = int(rng.integers(256))
    else:
        n = int(rng.integers(1, 17))
        chars = bytes(rng.integers(32, 127, n, dtype=np.uint8))
        _put(out, at, FMT_FIELDS["format"], chars)  # type: ignore[arg-type]
    return bytes(out)


def fmt_type_change(data: bytes, rng: np.random.Generator, rec: Records) -> bytes:
    """One format character replaced by another of the same size (a number declared as
    text, an integer as a float)."""
    at = _fmt_at(data, rng, rec)
    if at is None:
        return data
    out = bytearray(data)
    fmt = bytes(out[at + 9 : at + 25]).rstrip(b"\0").decode("latin-1")
    i = int(rng.integers(len(fmt))) if fmt else 0
    for chars in _FORMATS_BY_SIZE.values():
        if fmt and fmt[i] in chars:
            others = [c for c in chars if c != fmt[i]]
            fmt = fmt[:i] + others[int(rng.integers(len(others)))] + fmt[i + 1 :]
            break
    _put(out, at, FMT_FIELDS["format"], fmt.encode("latin-1"))  # type: ignore[arg-type]
    return bytes(out)


def fmt_redefine(data: bytes, rng: np.random.Generator, rec: Records) -> bytes:
    """A type's FMT again, changed, at a record boundary later in the file."""
    at = _fmt_at(data, rng, rec)
    if at is None:
        return data
    again = _relabelled(data[at : at + 89], rng)
    later = rec.starts[rec.starts > at]
    where = int(later[int(rng.integers(later.size))]) if later.size else len(data)
    return data[:where] + again + data[where:]


_EXTREMES = (np.nan, np.inf, -np.inf, 1e38, -1e38, 3.4e38, 1e6, 0.0)


def extreme_values(data: bytes, rng: np.random.Generator, rec: Records) -> bytes:
    """A numeric field of one, some or all records of a type set to a non-finite or extreme
    value (for an integer field, its extremes)."""
    if not rec.formats:
        return data
    fmt, name = rec.fields(rng)
    where = rec.offsets_of(fmt, name)
    if where.size == 0:
        return data
    share = (1.0, 0.1, 0.0)[int(rng.integers(3))]
    hit = where[rng.random(where.size) < share] if share else where[[int(rng.integers(where.size))]]
    dtype = fmt.dtype.fields[name][0]  # type: ignore[index]
    if dtype.kind == "f":
        value = np.array(_EXTREMES[int(rng.integers(len(_EXTREMES)))]).astype(dtype)
    else:
        info = np.iinfo(dtype)
        value = np.array((info.max, info.min)[int(rng.integers(2))], dtype=dtype)
    out = np.frombuffer(data, np.uint8).copy()
    raw = np.frombuffer(value.tobytes(), np.uint8)
    out[hit[:, None] + np.arange(raw.size)] = raw
    return out.tobytes()


_DAY_US = np.uint64(86_400_000_000)
_U = np.uint64


def _wrap32(t: np.ndarray, k: int) -> np.ndarray:
    out = t.copy()
    out[k:] = (t[k:] + _U(2**32 - int(t[k]) % 2**32)) % _U(2**32)
    return out


def _suffix(t: np.ndarray, k: int, value: np.ndarray | np.uint64) -> np.ndarray:
    out = t.copy()
    out[k:] = value
    return out


def _one_ahead(t: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    out = t.copy()
    out[k] += _U(3_600_000_000 * int(rng.integers(1, 48)))
    return out


#: 14 kinds of damage to a type's TimeUS values (uint64 microseconds): (t, k, rng) -> t, with
#: k a random record.
TIME_DAMAGE: tuple[Callable[[np.ndarray, int, np.random.Generator], np.ndarray], ...] = (
    lambda t, k, rng: _suffix(t, k, t[k:] + _DAY_US * _U(rng.integers(1, 30))),  # days ahead
    lambda t, k, _: _suffix(t, k, t[k:] // _U(1000)),  # back before the log
    lambda t, _k, _: np.zeros_like(t),  # all zero
    lambda t, _k, _: t + _U(2**63),  # near 2^63
    lambda t, k, _: _suffix(t, k, _U(2**64 - 1)),  # the maximum
    lambda t, _k, rng: rng.integers(0, 2**62, t.size, dtype=np.uint64),  # random
    lambda t, _k, _: t[::-1].copy(),  # reversed
    _one_ahead,  # one record hours ahead
    lambda t, k, _: np.full_like(t, t[k]),  # frozen
    lambda t, _k, _: t // _U(1000),  # milliseconds where microseconds belong
    lambda t, _k, _: t * _U(1000),  # a thousand times too large
    lambda t, _k, rng: np.maximum(
        t.astype(np.int64) + rng.integers(-1_000_000, 1_000_000, t.size), 0
    ).astype(np.uint64),  # a second of jitter
    lambda t, k, _: _wrap32(t, k),  # a 32-bit wrap
    lambda t, _k, _: np.repeat(t[::2], 2)[: t.size],  # every other stamp repeated
)


def timestamps(data: bytes, rng: np.random.Generator, rec: Records) -> bytes:
    timed = [f for f in rec.formats.values() if f.columns[:1] == ("TimeUS",) and f.format[0] == "Q"]
    if not timed:
        return data
    fmt = timed[int(rng.integers(len(timed)))]
    where = rec.offsets_of(fmt, "TimeUS")
    if where.size == 0:
        return data
    out = np.frombuffer(data, np.uint8).copy()
    cells = where[:, None] + np.arange(8)
    t = out[cells].copy().view("<u8").ravel()
    damage = TIME_DAMAGE[int(rng.integers(len(TIME_DAMAGE)))]
    out[cells] = damage(t, int(rng.integers(t.size)), rng).view(np.uint8).reshape(-1, 8)
    return out.tobytes()


def frozen(data: bytes, rng: np.random.Generator, rec: Records) -> bytes:
    """A numeric field holding one value over a run of records (a frozen driver)."""
    if not rec.formats:
        return data
    fmt, name = rec.fields(rng)
    if name == "TimeUS":
        return data
    where = rec.offsets_of(fmt, name)
    if where.size < 2:
        return data
    a = int(rng.integers(where.size - 1))
    b = int(rng.integers(a + 1, where.size + 1))
    width = fmt.dtype.fields[name][0].itemsize  # type: ignore[index]
    out = np.frombuffer(data, np.uint8).copy()
    first = out[where[a] : where[a] + width].copy()
    out[where[a:b, None] + np.arange(width)] = first
    return out.tobytes()


def ulog_values(data: bytes, rng: np.random.Generator, _: Records) -> bytes:
    """A PX4 ULog's numeric field of a topic altfuse reads, over a run of its samples: set to
    a non-finite or extreme value (an integer field's extremes), 0, negated, frozen, reversed
    or shuffled; the log written again by pyulog (the topics altfuse reads alone)."""
    from pyulog import ULog

    try:  # its warnings on a corrupt base said once by the run itself, not per variant
        with contextlib.redirect_stdout(io.StringIO()):
            ulog = ULog(io.BytesIO(data), list(TOPICS))
    except Exception:  # not a ULog pyulog parses: left as it is
        return data
    fields = [(d, k) for d in ulog.data_list for k, v in d.data.items() if v.dtype.kind in "fiu"]
    if not fields:
        return data
    topic, name = fields[int(rng.integers(len(fields)))]
    v = topic.data[name].copy()
    a = int(rng.integers(v.size))
    run = slice(a, int(rng.integers(a + 1, v.size + 1)))
    how = ("extreme", "zero", "negated", "frozen", "reversed", "shuffled")[int(rng.integers(6))]
    if how == "extreme" and v.dtype.kind == "f":
        v[run] = np.array(_EXTREMES[int(rng.integers(len(_EXTREMES)))]).astype(v.dtype)
    elif how == "extreme":
        info = np.iinfo(v.dtype)
        v[run] = (info.max, info.min)[int(rng.integers(2))]
    elif how == "zero":
        v[run] = 0
    elif how == "negated":
        v[run] = -v[run] if v.dtype.kind != "u" else v[run][::-1]
    elif how == "frozen":
        v[run] = v[a]
    elif how == "reversed":
        v[run] = v[run][::-1].copy()
    else:
        rng.shuffle(v[run])
    topic.data[name] = v
    with tempfile.TemporaryDirectory() as folder:  # pyulog 1.0 writes to a path alone
        out = Path(folder) / "written.ulg"
        try:
            ulog.write_ulog(str(out))
        except Exception:  # pyulog 1.0 cannot write every log it reads (an info's array type)
            return data
        return out.read_bytes()


#: What a text log's field may become (:func:`text_fields`).
_TEXT_VALUES = (b" nan", b" inf", b" -inf", b" 1e308", b" -1e308", b" 99999999999999999999",
                b" ", b"", b" abc", b" 0x10", b" 1,5", b" 1e", b" --1")  # fmt: skip


def _text_lines(data: bytes, rng: np.random.Generator) -> tuple[list[bytes], int, int]:
    """A text log's lines and a random run of them (its first line and its end)."""
    lines = data.split(b"\n")
    i = int(rng.integers(0, len(lines)))
    return lines, i, min(len(lines), i + int(rng.integers(1, 300)))


def text_lines(data: bytes, rng: np.random.Generator, _: Records) -> bytes:
    """A run of a text log's lines dropped, repeated, moved or made blank."""
    lines, i, j = _text_lines(data, rng)
    run, rest = lines[i:j], lines[:i] + lines[j:]
    how = int(rng.integers(4))
    if how == 0:
        lines = rest
    elif how == 1:
        lines[i:i] = run * int(rng.integers(1, 4))
    elif how == 2:
        at = int(rng.integers(0, len(rest) + 1))
        lines = rest[:at] + run + rest[at:]
    else:
        lines[i:j] = [b""] * len(run)
    return b"\n".join(lines)


def text_fields(data: bytes, rng: np.random.Generator, _: Records) -> bytes:
    """In a run of a text log's lines, one field each cut short, dropped, doubled or replaced
    (non-finite, huge, empty, a word)."""
    lines, i, j = _text_lines(data, rng)
    for k in range(i, j):
        parts = lines[k].split(b",")
        if len(parts) < 2:
            continue
        f = int(rng.integers(1, len(parts)))
        how = int(rng.integers(4))
        if how == 0:
            parts[f] = parts[f][: int(rng.integers(0, len(parts[f]) + 1))]
        elif how == 1:
            del parts[f]
        elif how == 2:
            parts.insert(f, parts[f])
        else:
            parts[f] = _TEXT_VALUES[int(rng.integers(len(_TEXT_VALUES)))]
        lines[k] = b",".join(parts)
    return b"\n".join(lines)


def text_fmt(data: bytes, rng: np.random.Generator, _: Records) -> bytes:
    """A text log's FMT lines, some of them, with a field replaced (its type, length, name,
    format or columns)."""
    lines = data.split(b"\n")
    fmts = [k for k, line in enumerate(lines) if line.startswith(b"FMT")]
    for k in rng.choice(fmts, int(rng.integers(1, 4))) if fmts else ():
        parts = lines[k].split(b",")
        if len(parts) > 2:
            f = int(rng.integers(1, len(parts)))
            parts[f] = (b" 0", b" 255", b" X", b" QQQQQQ", b" ", b" BARO", b" Alt,Alt")[
                int(rng.integers(7))
            ]
            lines[k] = b",".join(parts)
    return b"\n".join(lines)


def text_delimiters(data: bytes, rng: np.random.Generator, _: Records) -> bytes:
    """A run of a text log's lines with other delimiters, or other line ends."""
    lines, i, j = _text_lines(data, rng)
    new = (b",", b";", b"\t", b" ,", b",,", b", \r")[int(rng.integers(6))]
    lines[i:j] = [line.replace(b", ", new) for line in lines[i:j]]
    return b"\n".join(lines)


#: The mutations that need the base log's record layout untouched (applied first).
RECORD_AWARE = ("extreme", "timestamps", "frozen", "fmt-type", "fmt-absurd", "fmt-columns",
                "fmt-redefine", "ulog-values")  # fmt: skip

MUTATIONS: dict[str, Mutation] = {
    "truncate": truncate,
    "flip": flip_bytes,
    "zero": zero_block,
    "duplicate": duplicate_block,
    "shuffle": shuffle_records,
    "remove-fmt": remove_fmt,
    "garbage": insert_garbage,
    "extreme": extreme_values,
    "timestamps": timestamps,
    "frozen": frozen,
    "fmt-type": fmt_type_change,
    "fmt-absurd": fmt_absurd,
    "fmt-columns": fmt_columns,
    "fmt-redefine": fmt_redefine,
}


#: The mutations a PX4 ULog takes: those that know nothing of a format's records, and its own
#: fields' values.
ULOG_MUTATIONS: dict[str, Mutation] = {
    **{n: MUTATIONS[n] for n in ("truncate", "flip", "zero", "duplicate", "garbage")},
    "ulog-values": ulog_values,
}
#: ... and a DataFlash text log: the byte-level ones, and damage to its lines and fields.
TEXT_MUTATIONS: dict[str, Mutation] = {
    **{n: MUTATIONS[n] for n in ("truncate", "flip", "zero", "duplicate", "garbage")},
    "text-lines": text_lines,
    "text-fields": text_fields,
    "text-fmt": text_fmt,
    "text-delimiters": text_delimiters,
}
_EVERY = {**MUTATIONS, **ULOG_MUTATIONS, **TEXT_MUTATIONS}


def variant(base: bytes, records: Records | None, names: list[str], seed: int) -> bytes:
    """``base`` with the mutations ``names`` (the record-aware first), drawn from ``seed``;
    ``records``: the base's (None for a ULog, which takes ``ULOG_MUTATIONS`` alone, and for a
    text log, which takes ``TEXT_MUTATIONS``)."""
    rng = np.random.default_rng(seed)
    data = base
    order = sorted(
        names,
        key=lambda n: (n not in RECORD_AWARE, RECORD_AWARE.index(n) if n in RECORD_AWARE else 0),
    )
    for name in order:
        data = _EVERY[name](data, rng, records)  # type: ignore[arg-type]
    return data
