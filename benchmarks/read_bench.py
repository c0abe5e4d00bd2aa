"""Reading a big log: altfuse's extraction against pymavlink and against a plain pass.

Run on demand:  python benchmarks/read_bench.py [--mb 300] [--source LOG] [--keep PATH]

Each figure is the median of ``--repeat`` runs (the pymavlink loop runs once). Builds a log of at
least ``--mb`` megabytes from a real one (default: beastayyg_log_0036, a
Copter 3.4 flight with GPS, BARO, IMU, ATT, NKF1, CTUN): its FMT/FMTU/UNIT/MULT/PARM records once,
then its data records repeated, each copy's TimeUS shifted past the previous one. Then, each in a
fresh process (so that peak memory is that of the measurement alone):

- ``altfuse``: ``read_dataflash``, split into the index, the decoding and the file's sha256;
- ``pymavlink``: a ``recv_match`` loop over the types altfuse reads;
- ``plain``: one numpy pass over the file's bytes (read them, count the 0xA3 bytes);
- ``altfuse fuse`` end to end as a user runs it, writing CSV and writing Parquet.

With ``--ulog-mb`` (issue 18), the ULog reader instead: a ULog of that size built from a shared
PX4 log (its data repeated with shifted times, written by pyulog), read by ``read_log`` (the
compiled walk and pyulog's classes, the sources, the sha256) against the plain pass, and fused
end to end.

With ``--adversarial-mb`` (issue 16), the reader's index on two hostile files beside a clean
one of the same size (built as above): the source log followed by repeated header bytes
(``A3 95 80``, FMT's header), and the clean log with a decoy header (``A3 95`` and the
record's own type) inside every record's payload.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from altfuse.io.fastdf import index_file

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from repeated import repeated_log  # noqa: E402

DEFAULT_SOURCE = (
    ROOT.parent / "shared" / "logs" / "ardupilot" / ("beastayyg_log_0036_mechanical_failure.bin")
)
SMALL = ROOT / "sample_logs" / "mission.bin"  # loads the compiled loops before a measurement
TYPES = ["GPS", "GPS2", "BARO", "BAR2", "RFND", "SONR", "CTUN", "IMU", "ATT", "XKF1", "NKF1",
         "ORGN", "AHR2", "POS", "SIM", "MSG", "VER", "FMTU"]  # fmt: skip


#: A PX4 simulator flight with GPS and barometer (a log that fuses: the quadrotor_local log
#: the benchmark was built from before has no GPS fix, and is refused).
ULOG_SOURCE = ROOT.parent / "shared" / "logs" / "px4" / "px4_sitl_yuneec_position.ulg"


def build_ulog(source: Path, target: Path, megabytes: float) -> int:
    """Write a ULog of about ``megabytes`` MB from ``source``; return its size in bytes."""
    from pyulog import ULog

    ulog = ULog(str(source))
    span = ulog.last_timestamp - ulog.start_timestamp + 1_000_000
    copies = int(np.ceil(megabytes * 1e6 / source.stat().st_size))
    for d in ulog.data_list:
        for key, v in d.data.items():
            if key in ("timestamp", "timestamp_sample"):  # 0: a sample time not filled
                shifts = [v + (v > 0) * v.dtype.type(k * span) for k in range(copies)]
                d.data[key] = np.concatenate(shifts)
            else:
                d.data[key] = np.tile(v, copies)
    ulog.write_ulog(str(target))
    return target.stat().st_size


def ulog_case(megabytes: float, repeat: int) -> None:
    """The ULog's figures; it is built by a child process, so that this one holds none of the
    1.4 GB that pyulog's writing takes, which a whole-process run's ``ru_maxrss`` would count
    (:func:`fuse_process`)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "big.ulg"
        build = (
            f"import sys; sys.path[:0] = [{str(ROOT / 'benchmarks')!r}, {str(ROOT / 'tests')!r}]\n"
            "from pathlib import Path\nfrom read_bench import ULOG_SOURCE, build_ulog\n"
            f"build_ulog(ULOG_SOURCE, Path({str(path)!r}), {megabytes!r})\n"
        )
        subprocess.run([sys.executable, "-c", build], check=True)
        size = path.stat().st_size
        plain = median_of(repeat, "plain", path)
        ours = median_of(repeat, "read_log", path)
        fuse = median_fuse(repeat, path, Path(tmp) / "fused.csv")
        print(
            f"{path.name} built from {ULOG_SOURCE.name}: {size / 1e6:.1f} MB; plain numpy pass "
            f"{plain['seconds']:.2f} s; read_log {ours['seconds']:.2f} s "
            f"({ours['seconds'] / plain['seconds']:.1f}x the plain pass, "
            f"{ours['seconds'] / size * 1e9:.1f} s per GB), peak {ours['peak_mb']:.0f} MB; "
            f"altfuse fuse -o fused.csv (whole process) {fuse['seconds']:.2f} s, peak "
            f"{fuse['peak_mb']:.0f} MB ({fuse['peak_mb'] / (size / 2**20):.2f}x the file)"
        )


def hostile(clean: Path, source: Path, folder: Path) -> dict[str, Path]:
    """The two hostile files of ``clean``'s size (see the module doc)."""
    size = clean.stat().st_size
    log = source.read_bytes()[: size // 2]
    headers = folder / "headers.bin"
    headers.write_bytes(log + b"\xa3\x95\x80" * ((size - len(log)) // 3))
    index = index_file(clean)
    data = np.fromfile(clean, dtype=np.uint8)
    lengths = np.zeros(256, dtype=np.int64)
    for type_id, fmt in index.formats.items():
        lengths[type_id] = fmt.length
    at = index.offsets.astype(np.int64)
    at = at[(index.types != 128) & (lengths[index.types] >= 12)]
    data[at + 5], data[at + 6], data[at + 7] = 0xA3, 0x95, data[at + 2]
    decoys = folder / "decoys.bin"
    data.tofile(decoys)
    return {"repeated header bytes": headers, "decoy headers in payloads": decoys}


_WARM = """
import time, numpy as np
from altfuse.io.fastdf import index_file
from altfuse.io import read_log
index_file(SMALL)  # load the compiled scan and walk first: not the file's time
"""

CHILD = {
    "index": _WARM
    + """
t0 = time.perf_counter(); index = index_file(PATH)
RESULT = {"seconds": time.perf_counter() - t0, "records": int(index.offsets.size)}
""",
    "read_log": _WARM
    + """
t0 = time.perf_counter(); flight = read_log(PATH)
RESULT = {"seconds": time.perf_counter() - t0, "sources": len(flight.sensors)}
""",
    "altfuse": """
import time, hashlib
from altfuse.io.fastdf import index_file
from altfuse.io.dataflash import read_dataflash, _Records
from altfuse.io import sha256_of
t0 = time.perf_counter(); index = index_file(PATH); t1 = time.perf_counter()
rec = _Records(index)
for name in TYPES:
    if rec.n(name): rec.table(name)
t2 = time.perf_counter()
RESULT = {"index_s": t1 - t0, "decode_s": t2 - t1, "records": int(index.offsets.size)}
""",
    "read_dataflash": """
import time
from altfuse.io.dataflash import read_dataflash
t0 = time.perf_counter(); flight = read_dataflash(PATH); t1 = time.perf_counter()
RESULT = {"seconds": t1 - t0}
""",
    "sha256": """
import time, pathlib
from altfuse.io import sha256_of
t0 = time.perf_counter()
sha256_of(pathlib.Path(PATH))
RESULT = {"seconds": time.perf_counter() - t0}
""",
    "pymavlink": """
import time
from pymavlink import mavutil
t0 = time.perf_counter()
conn = mavutil.mavlink_connection(PATH)
n = 0
while conn.recv_match(type=TYPES) is not None:
    n += 1
RESULT = {"seconds": time.perf_counter() - t0, "records": n}
""",
    "plain": """
import time, numpy as np
t0 = time.perf_counter()
data = np.fromfile(PATH, dtype=np.uint8)
count = int(np.count_nonzero(data == 0xA3))
RESULT = {"seconds": time.perf_counter() - t0, "a3_bytes": count}
""",
}


def fuse_process(log: Path, out: Path) -> dict[str, float]:
    """``altfuse fuse LOG -o OUT`` as a user runs it: wall time and peak memory [MB] (its
    ``ru_maxrss``: at least this benchmark's own resident memory when it starts the command,
    164-170 MB after building the DataFlash log, below any fuse's; see :data:`_PEAK`)."""
    command = [str(Path(sys.executable).with_name("altfuse")), "fuse", str(log), "-o", str(out)]
    started = time.perf_counter()
    child = subprocess.Popen([*command, "--force"], stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)
    if status:
        raise RuntimeError(f"{' '.join(command)} failed ({status})")
    return {"seconds": time.perf_counter() - started, "peak_mb": usage.ru_maxrss / 1024}


def median_fuse(runs: int, log: Path, out: Path) -> dict[str, float]:
    """The whole-process run with the median time of ``runs``."""
    results = sorted((fuse_process(log, out) for _ in range(runs)), key=lambda r: r["seconds"])
    return results[len(results) // 2]


def median_of(runs: int, kind: str, path: Path) -> dict[str, float]:
    """The run with the median total time of ``runs`` fresh-process runs."""
    results = [measure(kind, path) for _ in range(runs)]
    key = "seconds" if "seconds" in results[0] else "index_s"
    return sorted(results, key=lambda r: r[key] + r.get("decode_s", 0.0))[runs // 2]


#: The child's own peak resident memory [MB]: Linux's ``VmHWM``, the high-water mark of the
#: process's memory since it began the program. Its ``ru_maxrss`` also counts the parent's
#: resident memory when it was started (Linux keeps the larger across ``exec``): a ULog's
#: children reported the 1.4 GB of the benchmark that had just built the ULog, where
#: ``read_log`` itself peaked at 0.3 GB.
_PEAK = """
import json, resource
def peak_mb():
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
"""


def measure(kind: str, path: Path) -> dict[str, float]:
    code = (
        f"PATH = {str(path)!r}\nTYPES = {TYPES!r}\nSMALL = {str(SMALL)!r}\n"
        + CHILD[kind]
        + _PEAK
        + "RESULT['peak_mb'] = peak_mb()\nprint(json.dumps(RESULT))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    result: dict[str, float] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mb", type=float, default=300.0)
    parser.add_argument("--source", type=Path, default=DEFAULT_SOURCE)
    parser.add_argument("--keep", type=Path, help="write the big log here and keep it")
    parser.add_argument("--skip-pymavlink", action="store_true")
    parser.add_argument("--repeat", type=int, default=3, help="runs per measurement (median)")
    parser.add_argument(
        "--adversarial-mb", type=float, help="only the hostile files of this size (and a clean one)"
    )
    parser.add_argument("--ulog-mb", type=float, help="only a ULog of this size")
    args = parser.parse_args()
    if args.ulog_mb:
        ulog_case(args.ulog_mb, args.repeat)
        return
    if args.adversarial_mb:
        adversarial(args.source, args.adversarial_mb, args.repeat)
        return
    with tempfile.TemporaryDirectory() as tmp:
        path = args.keep or Path(tmp) / "big.bin"
        started = time.perf_counter()
        if path.exists() and path.stat().st_size >= args.mb * 1e6:
            size = path.stat().st_size
            print(f"using {path}: {size / 1e6:.1f} MB")
        else:
            size = repeated_log(args.source, path, args.mb)
            print(
                f"built {path.name}: {size / 1e6:.1f} MB in {time.perf_counter() - started:.1f} s"
            )
        plain = median_of(args.repeat, "plain", path)
        ours = median_of(args.repeat, "altfuse", path)
        whole = median_of(args.repeat, "read_dataflash", path)
        digest = median_of(args.repeat, "sha256", path)
        extraction = ours["index_s"] + ours["decode_s"]
        file_mb = size / 2**20
        print(f"plain numpy pass: {plain['seconds']:.2f} s, peak {plain['peak_mb']:.0f} MB")
        print(
            f"altfuse extraction: index {ours['index_s']:.2f} s + decode {ours['decode_s']:.2f}"
            f" s = {extraction:.2f} s ({extraction / plain['seconds']:.2f}x the plain pass), "
            f"{ours['records']:,} records, peak {ours['peak_mb']:.0f} MB "
            f"({ours['peak_mb'] / file_mb:.2f}x the file)"
        )
        print(
            f"read_dataflash (extraction, series, references, sha256): "
            f"{whole['seconds']:.2f} s, peak {whole['peak_mb']:.0f} MB "
            f"({whole['peak_mb'] / file_mb:.2f}x the file); sha256 alone {digest['seconds']:.2f} s"
        )
        for suffix in ("csv", "parquet"):
            fuse = median_fuse(args.repeat, path, Path(tmp) / f"fused.{suffix}")
            print(
                f"altfuse fuse -o fused.{suffix} (whole process): {fuse['seconds']:.2f} s "
                f"({fuse['seconds'] / plain['seconds']:.1f}x the plain pass), peak "
                f"{fuse['peak_mb']:.0f} MB ({fuse['peak_mb'] / file_mb:.2f}x the file)"
            )
        if not args.skip_pymavlink:
            theirs = measure("pymavlink", path)
            print(
                f"pymavlink recv_match loop: {theirs['seconds']:.1f} s, "
                f"{theirs['records']:,} records, peak {theirs['peak_mb']:.0f} MB; altfuse "
                f"extraction is {theirs['seconds'] / extraction:.0f}x faster"
            )


def adversarial(source: Path, megabytes: float, repeat: int) -> None:
    """The index's time on the hostile files beside a clean file of the same size."""
    with tempfile.TemporaryDirectory() as tmp:
        clean = Path(tmp) / "clean.bin"
        size = repeated_log(source, clean, megabytes)
        base = median_of(repeat, "index", clean)
        whole = median_of(repeat, "read_log", clean)
        print(
            f"clean {size / 1e6:.1f} MB: index {base['seconds']:.3f} s, read_log "
            f"{whole['seconds']:.3f} s, {base['records']:,} records, peak {whole['peak_mb']:.0f} MB"
        )
        for label, path in hostile(clean, source, Path(tmp)).items():
            got = median_of(repeat, "index", path)
            read = median_of(repeat, "read_log", path)
            print(
                f"{label} {path.stat().st_size / 1e6:.1f} MB: index {got['seconds']:.3f} s "
                f"({got['seconds'] / base['seconds']:.1f}x clean), read_log "
                f"{read['seconds']:.3f} s ({read['seconds'] / whole['seconds']:.1f}x), "
                f"{got['records']:,} records, peak {read['peak_mb']:.0f} MB"
            )


if __name__ == "__main__":
    main()
