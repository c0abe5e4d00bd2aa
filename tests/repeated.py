"""DataFlash logs made from real ones: a long one, its data repeated with shifted times (the
benchmarks' big logs, and the tests of what only hours of flight show); one cut as real logs
are, ended early or begun late (:func:`cut_log`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from altfuse.io.fastdf import HEADER, index_file

#: The records written once, at the start: the formats, units and parameters.
ONCE = {"FMT", "FMTU", "UNIT", "MULT", "PARM"}


def repeated_log(source: Path, target: Path, megabytes: float) -> int:
    """Write a log of at least ``megabytes`` MB from ``source``; return its size in bytes."""
    index = index_file(source)
    data = index.data
    once, block, shift_at = [], [], []
    position = 0
    for offset, type_id in zip(index.offsets.tolist(), index.types.tolist(), strict=True):
        fmt = index.formats[type_id]
        record = data[offset : offset + fmt.length]
        if fmt.name in ONCE:
            once.append(record)
            continue
        if fmt.columns[:1] == ("TimeUS",) and fmt.format[:1] == "Q":
            shift_at.append(position + HEADER)
        block.append(record)
        position += fmt.length
    head = np.concatenate(once)
    body = np.concatenate(block)
    where = np.array(shift_at, dtype=np.int64)
    stamps = body[where[:, None] + np.arange(8)].copy().view("<u8").ravel()
    span = int(stamps.max() - stamps.min()) + 1_000_000
    copies = int(np.ceil(megabytes * 1e6 / body.size))
    with target.open("wb") as out:
        out.write(head.tobytes())
        for k in range(copies):
            shifted = (stamps + np.uint64(k * span)).view(np.uint8).reshape(-1, 8)
            body[where[:, None] + np.arange(8)] = shifted
            out.write(body.tobytes())
    return target.stat().st_size


def begun_late(source: Path, target: Path, fraction: float) -> None:
    """Write ``source`` without its data records before ``fraction`` of its time span (by
    ``TimeUS``, or an older log's ``TimeMS``, but GPS's: the GPS time of week there): the
    formats, units and parameters stay, every record from the first stamped at or after that
    time is kept."""
    index = index_file(source)
    data = index.data
    records = []  # (its bytes, its format's name, its TimeUS or -1)
    for offset, type_id in zip(index.offsets.tolist(), index.types.tolist(), strict=True):
        fmt = index.formats[type_id]
        record = data[offset : offset + fmt.length]
        stamp = -1
        if fmt.columns[:1] == ("TimeUS",) and fmt.format[:1] == "Q":
            stamp = int(record[HEADER : HEADER + 8].view("<u8")[0])
        elif fmt.columns[:1] == ("TimeMS",) and fmt.format[:1] == "I" and fmt.name != "GPS":
            stamp = 1000 * int(record[HEADER : HEADER + 4].view("<u4")[0])
        records.append((record, fmt.name, stamp))
    stamps = np.array([stamp for _, _, stamp in records])
    timed_stamps = stamps[stamps >= 0]
    cut = timed_stamps.min() + fraction * (timed_stamps.max() - timed_stamps.min())
    first = int(np.flatnonzero(stamps >= cut)[0])
    with target.open("wb") as out:
        for k, (record, name, _) in enumerate(records):
            if k >= first or name in ONCE:
                out.write(record.tobytes())


def cut_log(source: Path, target: Path, how: str, fraction: float) -> None:
    """Write ``source`` cut as a real log is: ``ended`` at ``fraction`` of its bytes (a crash, a
    flat battery), or ``begun`` at ``fraction`` of its span (:func:`begun_late`: a log rotated or
    started in flight)."""
    if how == "ended":
        data = source.read_bytes()
        target.write_bytes(data[: int(len(data) * fraction)])
    elif how == "begun":
        begun_late(source, target, fraction)
    else:
        raise ValueError(f"a log is cut 'ended' or 'begun', not {how!r}")
