"""The long fuzz run, outside the test suite: thousands of damaged variants through `fuse`.

Run on demand (about 2 minutes for 2,000 variants on 2 cores):

    python tests/fuzz_long.py [--variants 2000] [--seed 1] [--workers 2]

Each variant is a base log (every log in ../shared/logs/ardupilot and sample_logs/) with one to
three random mutations (tests/fuzzing.py), fused with a random method and written out, in a worker
process with a 30 s limit per variant and a 4 GiB address-space limit. The allowed outcomes are a
valid output or a documented error (an ``AltfuseError``); anything else — an unhandled exception,
a hang, runaway memory — is counted as a failure, printed with the seed that reproduces it, and
makes the exit code 1.
"""

from __future__ import annotations

import argparse
import resource
import signal
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from altfuse.errors import AltfuseError
from altfuse.pipeline import FuseOptions, fuse_log
from altfuse.write import write_outputs
from fuzzing import MUTATIONS, Records, variant

ROOT = Path(__file__).resolve().parents[1]
LIMIT_S = 30
MEMORY_BYTES = 4 << 30
METHODS = ("support", "mean", "delay2", "multilayer")
_BASES: dict[str, tuple[bytes, Records]] = {}


class Hang(Exception):
    pass


def _alarm(*_: object) -> None:
    raise Hang


def _init() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_BYTES, MEMORY_BYTES))
    signal.signal(signal.SIGALRM, _alarm)


def run_one(base: str, names: list[str], seed: int, method: str) -> tuple[str, str]:
    """(outcome kind, detail) for one variant."""
    if base not in _BASES:
        _BASES[base] = (Path(base).read_bytes(), Records(Path(base)))
    data, records = _BASES[base]
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "damaged.bin"
        log.write_bytes(variant(data, records, names, seed))
        signal.alarm(LIMIT_S)
        try:
            run = fuse_log(log, FuseOptions(method=method))
            write_outputs(run, Path(tmp) / "out.csv")
            return "ok", ""
        except AltfuseError as exc:
            return f"error: {type(exc).__name__}", str(exc)[:120]
        except Hang:
            return "FAIL hang", f"over {LIMIT_S} s"
        except MemoryError:
            return "FAIL memory", f"over {MEMORY_BYTES >> 30} GiB"
        except Exception as exc:
            return f"FAIL {type(exc).__name__}", str(exc)[:200]
        finally:
            signal.alarm(0)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "logs")
    args = parser.parse_args()
    bases = sorted((ROOT / "sample_logs").glob("*.bin"))
    bases += sorted(p for p in (args.shared / "ardupilot").glob("*") if p.is_file())
    rng = np.random.default_rng(args.seed)
    jobs = []
    for _ in range(args.variants):
        names = list(rng.choice(sorted(MUTATIONS), int(rng.integers(1, 4))))
        jobs.append(
            (
                str(bases[int(rng.integers(len(bases)))]),
                names,
                int(rng.integers(2**32)),
                str(rng.choice(METHODS)),
            )
        )
    started = time.perf_counter()
    outcomes: Counter[str] = Counter()
    by_mutation: dict[str, Counter[str]] = {m: Counter() for m in MUTATIONS}
    failures = []
    with ProcessPoolExecutor(args.workers, initializer=_init) as pool:
        for job, (kind, detail) in zip(
            jobs, pool.map(run_one, *zip(*jobs, strict=True), chunksize=8), strict=True
        ):
            outcomes[kind] += 1
            for name in set(job[1]):
                by_mutation[name]["ok" if kind == "ok" else kind.split(":")[0]] += 1
            if kind.startswith("FAIL"):
                failures.append((job, kind, detail))
    elapsed = time.perf_counter() - started
    print(
        f"{args.variants} variants of {len(bases)} logs in {elapsed:.0f} s "
        f"({elapsed / args.variants * 1000:.0f} ms each), seed {args.seed}"
    )
    for kind, n in outcomes.most_common():
        print(f"  {n:6d}  {kind}")
    print("by mutation (a variant has 1-3):")
    for name, counts in by_mutation.items():
        print(f"  {name:<11}" + ", ".join(f"{k} {v}" for k, v in counts.most_common()))
    for job, kind, detail in failures[:20]:
        print(
            f"{kind}: base={Path(job[0]).name} mutations={job[1]} seed={job[2]} "
            f"method={job[3]}: {detail}"
        )
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
