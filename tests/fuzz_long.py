"""The long fuzz run, outside the test suite: thousands of damaged variants through `fuse`.

Run on demand (about 2 minutes for 2,000 variants on 2 cores):

    python tests/fuzz_long.py [--variants 2000] [--seed 1] [--workers 2]

Each variant is a base log (every log in ../shared/logs/ardupilot and sample_logs/; the PX4
ULogs in ../shared/logs/px4, which take the byte-level mutations and damage to their values; and
those DataFlash logs of at most 1 MB written as text, as Mission Planner writes them, which take
the byte-level mutations and damage to their lines and fields) with one to three random
mutations (tests/fuzzing.py), fused by the command line (``altfuse fuse``, in
process) with a random method, in a worker process with a 30 s limit per variant and a 4 GiB
address-space limit. The allowed outcomes are a valid output or a documented error (exit 1 or 2
with one line on stderr and no file written). Anything else is a failure, printed with the seed
that reproduces it, and makes the exit code 1: exit 3 (a bug), a hang, runaway memory, a second
line on stderr (a success may print at most four warning lines: what reading left out, the
sensors the datum left out, a divergence, and the smoother's failed model check), a partial
output or a temporary file left behind, and in the CSV an infinite number, a missing fused value
where the status says fused, or a fused value more than the guard's ``GROSS_M`` (10 m) outside
every sensor (below the lowest or above the highest) at a tick not flagged ``diverged``.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import resource
import signal
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

import pandas as pd
from click.testing import CliRunner

from altfuse.cli import cli
from altfuse.guard import GROSS_M
from fuzzing import MUTATIONS, TEXT_MUTATIONS, ULOG_MUTATIONS, Records, variant
from test_dataflash_text import as_text

ROOT = Path(__file__).resolve().parents[1]
LIMIT_S = 30
MEMORY_BYTES = 4 << 30
METHODS = ("smoother", "support", "mean", "delay2", "multilayer")
_BASES: dict[str, tuple[bytes, Records | None]] = {}


class Hang(BaseException):  # past the command's own handling of Exception
    pass


def _alarm(*_: object) -> None:
    raise Hang


def _init() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_BYTES, MEMORY_BYTES))
    signal.signal(signal.SIGALRM, _alarm)


def run_one(base: str, names: list[str], seed: int, method: str) -> tuple[str, str]:
    """(outcome kind, detail) for one variant."""
    if base not in _BASES:
        records = Records(Path(base)) if _kind(base) == "bin" else None
        _BASES[base] = (Path(base).read_bytes(), records)
    data, records = _BASES[base]
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / f"damaged.{_kind(base)}"
        out = Path(tmp) / "out.csv"
        log.write_bytes(variant(data, records, names, seed))
        signal.alarm(LIMIT_S)
        try:
            result = CliRunner().invoke(cli, ["fuse", str(log), "-o", str(out), "-m", method])
        except Hang:
            return "FAIL hang", f"over {LIMIT_S} s"
        finally:
            signal.alarm(0)
        if isinstance(result.exception, MemoryError):
            return "FAIL memory", f"over {MEMORY_BYTES >> 30} GiB"
        left = sorted(p.name for p in Path(tmp).iterdir() if p != log)
        return judge(result.exit_code, result.stderr.strip().splitlines(), out, left)


def _kind(base: str) -> str:
    """The base log's kind, as its name's suffix: ``ulg``, ``log`` (DataFlash text), ``bin``."""
    suffix = Path(base).suffix.lower()
    return suffix[1:] if suffix in (".ulg", ".log") else "bin"


#: Each kind's mutations.
_MUTATIONS = {"bin": MUTATIONS, "ulg": ULOG_MUTATIONS, "log": TEXT_MUTATIONS}
#: The DataFlash logs also fuzzed as text (written by :func:`test_dataflash_text.as_text`, as
#: Mission Planner writes them): the sample logs and the small shared ones.
TEXT_MAX_BYTES = 1_000_000


def judge(code: int, lines: list[str], out: Path, left: list[str]) -> tuple[str, str]:
    """The outcome of one run of the command (see the module doc)."""
    last = lines[-1][:200] if lines else ""
    if code == 3:
        return "FAIL exit 3", last
    if code != 0:
        if code not in (1, 2):
            return f"FAIL exit {code}", last
        if len(lines) != 1 or not lines[0].startswith("altfuse: error: "):
            return "FAIL stderr lines", " | ".join(lines)[:200]
        if left:
            return "FAIL partial output", ", ".join(left)
        return f"error {code}", last
    if len(lines) > 4 or not all(line.startswith("altfuse: warning: ") for line in lines):
        return "FAIL stderr lines", " | ".join(lines)[:200]
    if left != ["out.csv", "out.meta.json"]:
        return "FAIL stray file", ", ".join(left)
    return check_csv(pd.read_csv(out))


def check_csv(table: pd.DataFrame) -> tuple[str, str]:
    """A written CSV's values: finite, and near a sensor unless flagged."""
    numbers = table.select_dtypes("number").to_numpy(dtype=float)
    if np.isinf(numbers).any():
        return "FAIL infinite value", ""
    fused = table["fused_alt_m"].to_numpy(dtype=float)
    status = table["status"].astype(str).to_numpy()
    said = np.isin(status, ("fused", "single", "equal"))
    if np.isnan(fused[said]).any():
        return "FAIL missing fused value", f"{int(np.isnan(fused[said]).sum())} ticks"
    sensors = table[[c for c in table.columns if c.startswith("alt_")]].to_numpy(dtype=float)
    seen = np.isfinite(sensors).any(axis=1)
    low = np.min(np.where(np.isfinite(sensors), sensors, np.inf), axis=1)
    high = np.max(np.where(np.isfinite(sensors), sensors, -np.inf), axis=1)
    outside = np.where(seen, np.maximum(low - fused, fused - high), np.nan)  # beyond every one
    away = (outside > GROSS_M) & (status != "diverged")
    if away.any():
        worst = float(np.max(outside[away]))
        return "FAIL unflagged excursion", f"{int(away.sum())} ticks, up to {worst:.0f} m"
    return "ok", ""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "logs")
    args = parser.parse_args()
    bases = sorted((ROOT / "sample_logs").glob("*.bin"))
    bases += sorted(p for p in (args.shared / "ardupilot").glob("*") if p.is_file())
    binary = list(bases)
    bases += sorted((args.shared / "px4").glob("*.ulg"))
    with tempfile.TemporaryDirectory() as texts:
        for log in binary:
            if log.stat().st_size <= TEXT_MAX_BYTES:
                # pymavlink may fail on a damaged log, and prints what it cannot read of it
                with contextlib.suppress(Exception), _silenced():
                    bases.append(as_text(log, Path(texts) / f"{log.stem}.log"))
        return fuzz(bases, args)


@contextlib.contextmanager
def _silenced() -> Iterator[None]:
    """Standard output and error closed to everything, compiled code's writes too (pymavlink's
    indexer prints from C)."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    with open(os.devnull, "wb") as null:
        os.dup2(null.fileno(), 1)
        os.dup2(null.fileno(), 2)
    try:
        yield
    finally:
        for fd, copy in enumerate(saved, start=1):
            os.dup2(copy, fd)
            os.close(copy)


def fuzz(bases: list[Path], args: argparse.Namespace) -> int:
    """The run over ``bases`` (see the module doc); its exit code."""
    rng = np.random.default_rng(args.seed)
    jobs = []
    for _ in range(args.variants):
        base = str(bases[int(rng.integers(len(bases)))])
        kinds = sorted(_MUTATIONS[_kind(base)])
        names = list(rng.choice(kinds, int(rng.integers(1, 4))))
        jobs.append(
            (
                base,
                names,
                int(rng.integers(2**32)),
                str(rng.choice(METHODS)),
            )
        )
    started = time.perf_counter()
    outcomes: Counter[str] = Counter()
    by_mutation: dict[str, Counter[str]] = {m: Counter() for k in _MUTATIONS.values() for m in k}
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
        print(f"  {name:<16}" + ", ".join(f"{k} {v}" for k, v in counts.most_common()))
    for job, kind, detail in failures[:20]:
        print(
            f"{kind}: base={Path(job[0]).name} mutations={job[1]} seed={job[2]} "
            f"method={job[3]}: {detail}"
        )
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
