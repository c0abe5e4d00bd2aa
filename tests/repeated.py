"""A long DataFlash log made from a real one: its data repeated with shifted times (the
benchmarks' big logs, and the tests of what only hours of flight show)."""

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
