"""Wall time of ``altfuse batch`` over 100 logs at --jobs 1 and --jobs 2.

Run on demand:  python benchmarks/batch_bench.py [--logs 100] [--shared ../shared/logs]

The 100 logs are copies of the sample logs and of the real logs that process (11 distinct files,
20 KB to 2 MB, 8 to 7,000 ticks), cycled; the three shared logs that fail are left out so that
the time is the time of work done. Each run writes to a fresh folder.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

from altfuse.batch import run_batch

ROOT = Path(__file__).resolve().parents[1]
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
    parser.add_argument("--logs", type=int, default=100)
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "logs")
    args = parser.parse_args()
    sources = sorted((ROOT / "sample_logs").glob("*.bin"))
    sources += [
        args.shared / "ardupilot" / n for n in REAL if (args.shared / "ardupilot" / n).exists()
    ]
    with tempfile.TemporaryDirectory() as tmp:
        logs = Path(tmp) / "logs"
        logs.mkdir()
        for i in range(args.logs):
            src = sources[i % len(sources)]
            shutil.copy(src, logs / f"{i:03d}_{src.name}")
        size = sum(p.stat().st_size for p in logs.iterdir())
        print(f"{args.logs} logs from {len(sources)} distinct files, {size / 1e6:.1f} MB")
        for jobs in (1, 2):
            started = time.perf_counter()
            results = run_batch([logs], Path(tmp) / f"out{jobs}", jobs=jobs)
            wall = time.perf_counter() - started
            failed = sum(r.status == "failed" for r in results)
            print(
                f"--jobs {jobs}: {wall:.1f} s wall, {wall / len(results) * 1000:.0f} ms per log, "
                f"{failed} failed"
            )


if __name__ == "__main__":
    main()
