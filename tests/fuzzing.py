"""Damaged variants of real logs, for the property test and the long fuzz run.

Every mutation takes a log's bytes and returns damaged bytes: truncation, byte flips, zeroed and
duplicated blocks, records shuffled, FMT records removed, garbage inserted. Record boundaries come
from altfuse's own index of the (undamaged) base log.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from altfuse.io.fastdf import FMT_TYPE, index_file

Mutation = Callable[[bytes, np.random.Generator, "Records"], bytes]


def _at(rng: np.random.Generator, data: bytes) -> int:
    """A position in ``data``, 0 to len(data) (an empty file has one: 0)."""
    return int(rng.integers(0, len(data) + 1))


class Records:
    """Where a base log's records are."""

    def __init__(self, path: Path) -> None:
        index = index_file(path)
        lengths = {t: f.length for t, f in index.formats.items()}
        self.starts = index.offsets.astype(np.int64)
        self.types = index.types
        self.ends = self.starts + np.array([lengths[t] for t in self.types.tolist()], np.int64)


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


MUTATIONS: dict[str, Mutation] = {
    "truncate": truncate,
    "flip": flip_bytes,
    "zero": zero_block,
    "duplicate": duplicate_block,
    "shuffle": shuffle_records,
    "remove-fmt": remove_fmt,
    "garbage": insert_garbage,
}


def variant(base: bytes, records: Records, names: list[str], seed: int) -> bytes:
    rng = np.random.default_rng(seed)
    data = base
    for name in names:
        data = MUTATIONS[name](data, rng, records)
    return data
