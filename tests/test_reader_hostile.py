"""The reader on hostile bytes (issue 16): header patterns everywhere, runs of zeros; the
records it finds are the log's, in time linear in the file (measured in
``benchmarks/read_bench.py --adversarial-mb``, not asserted here)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from altfuse.io import read_log
from altfuse.io.fastdf import FMT_TYPE, index_file
from conftest import SAMPLE_LOG


def same_sensors(a: Path, b: Path) -> None:
    x, y = read_log(a), read_log(b)
    assert [s.name for s in x.sensors] == [s.name for s in y.sensors]
    for s, t in zip(x.sensors, y.sensors, strict=True):
        np.testing.assert_array_equal(s.t, t.t)
        np.testing.assert_array_equal(s.value, t.value)


def test_a_log_followed_by_repeated_header_bytes_reads_as_the_log(tmp_path: Path) -> None:
    # A3 95 80: FMT's header, a candidate every 3 bytes; the prune loop took 267 s on 10 MB
    path = tmp_path / "headers.bin"
    path.write_bytes(SAMPLE_LOG.read_bytes() + b"\xa3\x95\x80" * 300_000)
    index = index_file(path)
    clean = index_file(SAMPLE_LOG)
    np.testing.assert_array_equal(index.offsets[: clean.offsets.size], clean.offsets)
    # beyond the log, every record the walk finds is one of those FMT-like patterns
    assert set(index.types[clean.offsets.size :].tolist()) <= {FMT_TYPE}
    same_sensors(path, SAMPLE_LOG)
    assert read_log(path).skipped_bytes > 0


def test_decoy_headers_inside_every_payload_change_nothing(tmp_path: Path) -> None:
    clean = index_file(SAMPLE_LOG)
    data = np.fromfile(SAMPLE_LOG, dtype=np.uint8)
    lengths = np.array([clean.formats[t].length for t in clean.types.tolist()])
    at = clean.offsets[(clean.types != FMT_TYPE) & (lengths >= 12)].astype(np.int64)
    data[at + 5], data[at + 6], data[at + 7] = 0xA3, 0x95, data[at + 2]
    path = tmp_path / "decoys.bin"
    data.tofile(path)
    index = index_file(path)
    np.testing.assert_array_equal(index.offsets, clean.offsets)
    np.testing.assert_array_equal(index.types, clean.types)


def test_a_run_of_zeros_after_the_log_is_skipped_bytes(tmp_path: Path) -> None:
    path = tmp_path / "sparse.bin"
    path.write_bytes(SAMPLE_LOG.read_bytes())
    os.truncate(path, 200 * 2**20)  # a hole: 200 MiB of zeros, on disk nothing
    flight = read_log(path)
    assert flight.skipped_bytes == 200 * 2**20 - SAMPLE_LOG.stat().st_size
    same_sensors(path, SAMPLE_LOG)


def test_a_log_that_shrinks_while_mapped_is_one_line_not_a_silent_death(tmp_path: Path) -> None:
    path = tmp_path / "shrinking.bin"
    path.write_bytes(SAMPLE_LOG.read_bytes() * 40)
    code = (
        "import os, sys\n"
        "from altfuse.io.fastdf import index_file\n"
        f"index = index_file({str(path)!r})\n"
        f"os.truncate({str(path)!r}, 4096)  # another process cuts the log\n"
        "print(int(index.data[-1000:].sum()))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 1, done
    assert done.stderr == (
        "altfuse: error: the log shrank while it was being read (SIGBUS); read it again\n"
    )
    assert done.stdout == ""
