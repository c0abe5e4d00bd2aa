"""Wall time of ``altfuse batch`` at --jobs 1 and --jobs 2 over 100 small logs and 8 big ones.

Run on demand:  python benchmarks/batch_bench.py [--logs 100] [--big 8] [--big-mb 30]
[--repeat 3] [--shared ../shared/logs]

The small logs are copies of the sample logs and of the real logs that process (12 distinct
files, 20 KB to 2 MB, 8 to 7,000 ticks), cycled; the three shared logs that are refused are
left out so that the time is the time of work done. The big ones are built as
``read_bench.py`` builds its log (a shared log's data repeated with shifted times), ``--big-mb``
each, every one its own file. Each run writes to a fresh folder; the runs at 1 and 2 jobs
alternate, and each figure is the median of ``--repeat``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

from altfuse.cli import THREAD_POOLS

for _pool in THREAD_POOLS:  # as the command does, before numpy is loaded: --jobs 1 runs here
    os.environ.setdefault(_pool, "1")

from altfuse.batch import run_batch  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests"))

from read_bench import DEFAULT_SOURCE  # noqa: E402
from repeated import repeated_log  # noqa: E402

REAL = (
    "beastayyg_log_0036_mechanical_failure.bin",
    "beastayyg_log_0038_mechanical_failure.bin",
    "beastayyg_log_0039_mechanical_failure.bin",
    "beastayyg_sample.bin",
    "diaven_sample01.bin",
    "pymavlink_test.BIN",
    "rima48_test_cascade.BIN",
    "spark404_log.bin",
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", type=int, default=100, help="small logs")
    parser.add_argument("--big", type=int, default=8, help="big logs")
    parser.add_argument("--big-mb", type=float, default=30.0, help="size of each big log [MB]")
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "logs")
    parser.add_argument("--repeat", type=int, default=3, help="runs per measurement (median)")
    args = parser.parse_args()
    sources = sorted((ROOT / "sample_logs").glob("*.bin"))
    sources += [
        args.shared / "ardupilot" / n for n in REAL if (args.shared / "ardupilot" / n).exists()
    ]
    with tempfile.TemporaryDirectory() as tmp:
        small = Path(tmp) / "small"
        small.mkdir()
        for i in range(args.logs):
            src = sources[i % len(sources)]
            shutil.copy(src, small / f"{i:03d}_{src.name}")
        describe(small, f"{args.logs} small logs from {len(sources)} distinct files")
        race(small, Path(tmp), args.repeat)
        big = Path(tmp) / "big"
        big.mkdir()
        for i in range(args.big):
            repeated_log(DEFAULT_SOURCE, big / f"{i:02d}_big.bin", args.big_mb)
        describe(big, f"{args.big} big logs built from {DEFAULT_SOURCE.name}")
        race(big, Path(tmp), args.repeat)


def describe(folder: Path, what: str) -> None:
    size = sum(p.stat().st_size for p in folder.iterdir())
    print(f"{what}, {size / 1e6:.1f} MB", flush=True)


def race(logs: Path, tmp: Path, repeat: int) -> None:
    """The batch over ``logs`` at --jobs 1 and 2, interleaved ``repeat`` times: the median wall
    times and their ratio."""
    walls: dict[int, list[float]] = {1: [], 2: []}
    for k in range(repeat):
        for jobs in (1, 2):
            out = tmp / f"{logs.name}-out{jobs}-{k}"
            started = time.perf_counter()
            results = run_batch([logs], out, jobs=jobs)
            walls[jobs].append(time.perf_counter() - started)
            failed = sum(r.status == "failed" for r in results)
            shutil.rmtree(out)
            if failed:
                print(f"--jobs {jobs}: {failed} of {len(results)} logs failed", flush=True)
    for jobs, times in walls.items():
        wall = statistics.median(times)
        print(
            f"--jobs {jobs}: {wall:.1f} s wall (median of {repeat}), "
            f"{wall / len(results) * 1000:.0f} ms per log",
            flush=True,
        )
    ratio = statistics.median(walls[1]) / statistics.median(walls[2])
    print(f"2 jobs against 1: {ratio:.2f}x", flush=True)


if __name__ == "__main__":
    main()
