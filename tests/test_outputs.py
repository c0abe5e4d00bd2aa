"""Outputs under attack (issue 16): a run never writes onto its input or twice onto one file,
commits all of its files or none, reports a failed write in one line, honours the umask, and
cleans only its own temporary files, on SIGINT, SIGTERM and SIGHUP alike; a batch's outputs and
summary likewise."""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import re
import shutil
import signal
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from click.testing import CliRunner, Result

from altfuse import batch as batch_module
from altfuse import write
from altfuse.batch import BatchOptions, LogResult, run_batch, write_summary
from altfuse.cli import cli
from altfuse.errors import ParameterError
from altfuse.signals import GRACE_S, SIGHUP, Terminated, raise_on_termination
from altfuse.write import TEMP_PREFIX, OutputError, atomic_outputs
from conftest import SAMPLE_LOG
from test_cli import assert_one_line_error, sha

SAMPLES = SAMPLE_LOG.parent


def run(*args: str | Path) -> Result:
    return CliRunner().invoke(cli, [str(a) for a in args])


def temporaries(folder: Path) -> list[Path]:
    return sorted(folder.rglob(f"{TEMP_PREFIX}*"))


def test_a_compressed_name_is_written_compressed(tmp_path: Path) -> None:
    """An output named ``.gz``, ``.bz2`` or ``.xz`` is written so (a ``flight.csv.gz`` was
    plain CSV, which pandas, reading it as gzip by its name, refused): the same table read
    back, the gzip bytes the same run to run."""
    import bz2
    import lzma

    plain = run("fuse", SAMPLE_LOG, "-o", tmp_path / "plain.csv")
    assert plain.exit_code == 0
    for name in ("a", "b"):
        result = run(
            "fuse", SAMPLE_LOG, "-o", tmp_path / f"{name}.csv.gz",
            "--weights", tmp_path / f"{name}.w.csv.bz2", "--meta", tmp_path / f"{name}.json.xz",
        )  # fmt: skip
        assert result.exit_code == 0, result.output
    assert (tmp_path / "a.csv.gz").read_bytes() == (tmp_path / "b.csv.gz").read_bytes()
    assert (tmp_path / "a.csv.gz").read_bytes()[:2] == b"\x1f\x8b"
    assert pd.read_csv(tmp_path / "a.csv.gz").equals(pd.read_csv(tmp_path / "plain.csv"))
    assert (
        len(pd.read_csv(io.BytesIO(bz2.decompress((tmp_path / "a.w.csv.bz2").read_bytes()))))
        == 1200
    )
    meta = json.loads(lzma.decompress((tmp_path / "a.json.xz").read_bytes()))
    assert meta["outputs"]["csv"] == "a.csv.gz"


@pytest.mark.parametrize(
    ("args", "fragment"),
    [(["-o", "x.parquet.gz"], "Parquet is compressed already"),
     (["-o", "x.csv.zst"], "a .zst file is not written"),
     (["-o", "y.csv", "--meta", "y.json.zip"], "a .zip file is not written")],
)  # fmt: skip
def test_a_compression_not_written_is_refused(
    tmp_path: Path, args: list[str], fragment: str
) -> None:
    paths = [str(tmp_path / a) if "." in a else a for a in args]
    assert_one_line_error(run("fuse", SAMPLE_LOG, *paths), 2, fragment)
    assert list(tmp_path.iterdir()) == []


def test_a_named_pipe_is_written_into_not_replaced(tmp_path: Path) -> None:
    """An output that exists and is no regular file (a named pipe here; ``/dev/null``,
    ``/dev/stdout`` on a pipe) is written into, as standard output is: never renamed onto (a
    run with ``-o /dev/null --force`` made /dev/null a regular file and wrote
    /dev/null.meta.json), no sidecar beside it, no --force asked for."""
    fifo = tmp_path / "table.csv"
    os.mkfifo(fifo)
    received: list[bytes] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()  # blocks until the run opens the pipe
    try:
        result = run("fuse", SAMPLE_LOG, "-o", fifo)
    finally:  # a run that never opened it: the reader sees an empty pipe
        with contextlib.suppress(OSError):
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        reader.join(timeout=30)
    assert result.exit_code == 0, result.output
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert len(pd.read_csv(io.StringIO(received[0].decode()))) == 1200
    assert "without its provenance" in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.csv"]


def test_a_device_is_written_into_not_replaced(tmp_path: Path) -> None:
    """As a named pipe (above): a null device of the test's own (mknod: as root, as CI runs;
    never the system's /dev/null, which a failing run would replace)."""
    device = tmp_path / "null"
    try:
        os.mknod(device, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("mknod needs root")
    result = run("fuse", SAMPLE_LOG, "-o", device, "--weights", device)
    assert result.exit_code == 0, result.output
    assert stat.S_ISCHR(os.lstat(device).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["null"]


def test_a_linked_output_stays_a_link(tmp_path: Path) -> None:
    """An output path that is a symbolic link is written through: the link stays, its file
    gets the table (a rename onto the link replaced it: ``-o /dev/stdout --force`` with
    standard output in a file would have made /dev/stdout a regular file)."""
    real = tmp_path / "runs" / "42.csv"
    real.parent.mkdir()
    real.write_text("old\n")
    link = tmp_path / "latest.csv"
    link.symlink_to(real)
    result = run("fuse", SAMPLE_LOG, "-o", link, "--force")
    assert result.exit_code == 0, result.output
    assert link.is_symlink()
    assert link.resolve() == real
    assert len(pd.read_csv(real)) == 1200
    assert real.with_suffix(".meta.json").is_file()  # beside the file it describes
    assert temporaries(tmp_path) == []


@pytest.mark.parametrize("flag", ["-o", "--csv"])
def test_evaluate_never_replaces_its_input(tmp_path: Path, flag: str) -> None:
    log = tmp_path / "in.bin"
    shutil.copy(SAMPLE_LOG, log)
    before = sha(log)
    result = run("evaluate", log, "--methods", "mean", flag, log, "--force")
    assert_one_line_error(result, 2, "is the input log")
    assert sha(log) == before


def test_an_output_hard_linked_to_the_input_is_refused(tmp_path: Path) -> None:
    log = tmp_path / "in.bin"
    shutil.copy(SAMPLE_LOG, log)
    os.link(log, tmp_path / "alias.csv")
    result = run("fuse", log, "-o", tmp_path / "alias.csv", "--force")
    assert_one_line_error(result, 2, "is the input log")
    assert sha(log) == sha(SAMPLE_LOG)


@pytest.mark.parametrize(
    "args",
    [
        ["fuse", "{log}", "-o", "{d}/a.csv", "--meta", "{d}/a.csv"],
        ["fuse", "{log}", "-o", "{d}/a.csv", "--weights", "{d}/a.csv"],
        ["fuse", "{log}", "-o", "{d}/a.csv", "--weights", "{d}/./a.csv"],
        ["evaluate", "{log}", "--methods", "mean", "-o", "{d}/r.json", "--csv", "{d}/r.json"],
    ],
)
def test_two_outputs_on_one_path_are_refused(tmp_path: Path, args: list[str]) -> None:
    argv = [a.format(log=SAMPLE_LOG, d=tmp_path) for a in args]
    result = run(*argv)
    assert_one_line_error(result, 2, "are the same file")
    assert list(tmp_path.iterdir()) == []


def test_a_directory_where_the_sidecar_goes_writes_nothing(tmp_path: Path) -> None:
    (tmp_path / "out.meta.json").mkdir()
    result = run("fuse", SAMPLE_LOG, "-o", tmp_path / "out.csv", "--force")
    assert_one_line_error(result, 2, "is a directory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.meta.json"]


def test_a_run_renames_all_of_its_files_or_none(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    first, second = tmp_path / "a.csv", tmp_path / "b.json"
    first.write_text("the earlier a\n")
    replace = os.replace
    calls = []

    def failing(src: str, dst: str) -> None:
        calls.append(dst)
        if Path(dst) == second:
            raise OSError(errno.ENOSPC, "No space left on device", dst)
        replace(src, dst)

    def both() -> None:
        with atomic_outputs() as stage:
            stage(first, lambda f: f.write("the new a\n"))
            stage(second, lambda f: f.write("{}"))

    monkeypatch.setattr(write.os, "replace", failing)
    with pytest.raises(OutputError, match=r"cannot write .*b\.json: No space left"):
        both()
    assert second in map(Path, calls)
    assert first.read_text() == "the earlier a\n"  # put back
    assert not second.exists()
    assert temporaries(tmp_path) == []


@pytest.mark.parametrize("error", [errno.EROFS, errno.ENOSPC, errno.EACCES])
def test_a_failed_write_is_one_line_exit_1(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, error: int
) -> None:
    def refused(*_args: object, **_kwargs: object) -> None:
        raise OSError(error, os.strerror(error))

    monkeypatch.setattr(write.os, "fchmod", refused)
    result = run("fuse", SAMPLE_LOG, "-o", tmp_path / "out.csv")
    assert_one_line_error(result, 1, f"cannot write {tmp_path / 'out.csv'}: {os.strerror(error)}")
    assert list(tmp_path.iterdir()) == []


def test_a_symlink_loop_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    result = run("fuse", SAMPLE_LOG, "-o", tmp_path / "loop" / "out.csv")
    assert_one_line_error(result, 1, "cannot write")
    (tmp_path / "self.csv").symlink_to(tmp_path / "self.csv")
    assert_one_line_error(run("fuse", SAMPLE_LOG, "-o", tmp_path / "self.csv"), 2, "exists")


def test_outputs_follow_the_umask(tmp_path: Path) -> None:
    old = os.umask(0o027)
    try:
        assert run("fuse", SAMPLE_LOG, "-o", tmp_path / "out.csv").exit_code == 0
    finally:
        os.umask(old)
    assert {p.name: p.stat().st_mode & 0o777 for p in tmp_path.iterdir()} == {
        "out.csv": 0o640,
        "out.meta.json": 0o640,
    }


def dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_only_altfuses_own_dead_temporaries_are_cleaned(tmp_path: Path) -> None:
    host = write._HOST
    stale = tmp_path / f"{TEMP_PREFIX}{host}-{dead_pid()}-out.csv.abc123.tmp"
    alive = tmp_path / f"{TEMP_PREFIX}{host}-{os.getpid()}-out.csv.def456.tmp"
    elsewhere = tmp_path / f"{TEMP_PREFIX}otherhost-{dead_pid()}-out.csv.ghi789.tmp"
    mine = tmp_path / ".out.csv.notes.tmp"
    for path in (stale, alive, elsewhere, mine):
        path.write_text("x")
    assert run("fuse", SAMPLE_LOG, "-o", tmp_path / "out.csv").exit_code == 0
    assert not stale.exists()
    assert [alive.exists(), elsewhere.exists(), mine.exists()] == [True, True, True]


def test_a_target_named_near_the_limit_is_written(tmp_path: Path) -> None:
    """A temporary's name holds its target's: ``fuse -o`` to a name of 249 bytes was refused
    ("File name too long") although the name itself is within the limit. Written, and written
    over (the old file set aside meanwhile), the sidecar beside it (255 bytes); a killed run's
    temporary for it is cleaned as any other."""
    target = tmp_path / ("a" * 245 + ".csv")
    stem = write.temp_stem(target.name)
    stale = tmp_path / f"{TEMP_PREFIX}{write._HOST}-{dead_pid()}-{stem}.abcdefgh.tmp"
    stale.write_text("x")
    assert run("fuse", SAMPLE_LOG, "-o", target).exit_code == 0
    assert run("fuse", SAMPLE_LOG, "-o", target, "--force").exit_code == 0
    assert {p.name for p in tmp_path.iterdir()} == {target.name, f"{target.stem}.meta.json"}
    assert target.read_text().startswith("time_s,")


def test_a_long_names_temporary_stem_is_its_start_and_a_digest() -> None:
    room = write.NAME_MAX - len(os.fsencode(f"{TEMP_PREFIX}{write._HOST}")) - write._TEMP_EXTRA
    assert write.temp_stem("out.csv") == "out.csv"
    fits = "x" * room
    assert write.temp_stem(fits) == fits
    long = "é" * room  # two bytes each: whole characters kept
    stem = write.temp_stem(long)
    assert len(os.fsencode(stem)) <= room
    start, digest = stem.split("~")
    assert set(start) == {"é"}
    assert len(digest) == write._DIGEST
    assert write.temp_stem(long) == stem != write.temp_stem(long[:-1] + "e")


def test_what_windows_lacks_is_not_asked_of_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Windows has no flock (the batch module imported fcntl: every command an internal
    error), no os.fchmod before Python 3.13, and os.kill(pid, 0) sends Ctrl+C there: the
    outputs are written without them, the batch folder unlocked, a temporary left."""
    stale = tmp_path / f"{TEMP_PREFIX}{write._HOST}-{dead_pid()}-out.csv.abc123.tmp"
    stale.write_text("x")
    monkeypatch.setattr(sys, "platform", "win32")
    monkeypatch.setitem(sys.modules, "fcntl", None)  # import fcntl: ImportError
    monkeypatch.delattr(os, "fchmod")

    def kill(pid: int, signum: int) -> None:
        raise AssertionError(f"os.kill({pid}, {signum}) on Windows")

    monkeypatch.setattr(os, "kill", kill)
    with atomic_outputs() as stage:
        stage(tmp_path / "out.csv", lambda f: f.write("time_s\n"))
    assert (tmp_path / "out.csv").read_text() == "time_s\n"
    assert stale.exists()
    with batch_module._locked(tmp_path / "out"), batch_module._locked(tmp_path / "out"):
        assert (tmp_path / "out").is_dir()


#: The signals that end a run as SIGTERM does (SIGHUP: none on Windows).
TERMINATING = [signal.SIGTERM, *([SIGHUP] if SIGHUP is not None else [])]
SAID = {signal.SIGTERM: "terminated", signal.SIGINT: "interrupted", SIGHUP: "hung up"}


@contextlib.contextmanager
def handled_as(signum: int, handler: Any) -> Iterator[None]:
    """``signum``'s handler in this process is ``handler`` meanwhile (a program started here
    inherits SIG_DFL or SIG_IGN)."""
    before = signal.signal(signum, handler)
    try:
        yield
    finally:
        signal.signal(signum, before)


@contextlib.contextmanager
def as_from_a_terminal() -> Iterator[None]:
    """SIGINT handled and SIGHUP at its default in this process meanwhile, so that a program
    started here gets both at their defaults, as from a terminal: a shell starts a job in the
    background (``pytest &``) with SIGINT ignored, ``nohup pytest`` ignores SIGHUP, a program
    inherits that, and Python then leaves it ignored (altfuse too, as ``nohup`` means it)."""
    with contextlib.ExitStack() as stack:
        stack.enter_context(handled_as(signal.SIGINT, signal.default_int_handler))
        if SIGHUP is not None:
            stack.enter_context(handled_as(SIGHUP, signal.SIG_DFL))
        yield


@pytest.mark.parametrize("signum", TERMINATING)
def test_a_terminating_signal_removes_the_temporaries(tmp_path: Path, signum: int) -> None:
    def interrupted() -> None:
        with atomic_outputs() as stage:
            stage(tmp_path / "a.csv", lambda f: f.write("a"))
            stage(tmp_path / "b.csv", lambda _: os.kill(os.getpid(), signum))

    with handled_as(signal.SIGTERM, signal.SIG_DFL), handled_as(signum, signal.SIG_DFL):
        raise_on_termination()
        with pytest.raises(Terminated) as raised:
            interrupted()
    assert raised.value.signum == signum
    assert list(tmp_path.iterdir()) == []


def signalling_at(monkeypatch: pytest.MonkeyPatch, name: str, call: int = 1) -> None:
    """``os.<name>`` sends this process SIGTERM at its ``call``-th call, just before it does
    its work."""
    original = getattr(os, name)
    calls: list[object] = []

    def signalled(*args: Any) -> Any:
        calls.append(args)
        if len(calls) == call:
            os.kill(os.getpid(), signal.SIGTERM)
        return original(*args)

    monkeypatch.setattr(os, name, signalled)


def test_a_second_signal_does_not_cut_the_removal_short(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A signal while the temporaries are being removed (a batch's worker gets the closed
    terminal's SIGHUP, then the SIGTERM its dead parent sends) had ended the removal, leaving
    a temporary file: it waits until they are gone, and the first signal ends the run."""

    def interrupted() -> None:
        with atomic_outputs() as stage:
            stage(tmp_path / "a.csv", lambda f: f.write("a"))
            signalling_at(monkeypatch, "unlink")
            stage(tmp_path / "b.csv", lambda _: os.kill(os.getpid(), signal.SIGTERM))

    with handled_as(signal.SIGTERM, signal.SIG_DFL):
        raise_on_termination()
        with pytest.raises(Terminated):
            interrupted()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("call", [1, 2, 3])
def test_a_signal_while_the_outputs_are_renamed_leaves_them_all(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, call: int
) -> None:
    """All or none: a signal between two renames (1: a.csv's, 2: setting the old b.csv
    aside, 3: b.csv's) had left the new a.csv beside the old b.csv, or beside none (the old
    one set aside under a temporary name); the renames finish, then the signal ends the run."""
    (tmp_path / "b.csv").write_text("before")

    def committed() -> None:
        with atomic_outputs() as stage:
            stage(tmp_path / "a.csv", lambda f: f.write("a"))
            stage(tmp_path / "b.csv", lambda f: f.write("b"))
            signalling_at(monkeypatch, "replace", call)

    with handled_as(signal.SIGTERM, signal.SIG_DFL):
        raise_on_termination()
        with pytest.raises(Terminated):
            committed()
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == {"a.csv": "a", "b.csv": "b"}


def fuse_of_a_long_log(
    log: Path, tmp_path: Path, hangup: Any = signal.SIG_DFL
) -> tuple[subprocess.Popen[str], Path]:
    """``altfuse fuse`` of the 900 s flight ``log`` into ``tmp_path``, started as from a
    terminal with SIGHUP's handler ``hangup``, once it has mapped the log (past start-up,
    reading), and its output's folder."""
    out = tmp_path / "out"
    with contextlib.ExitStack() as stack:
        stack.enter_context(as_from_a_terminal())
        if SIGHUP is not None:
            stack.enter_context(handled_as(SIGHUP, hangup))
        proc = subprocess.Popen(
            [sys.executable, "-m", "altfuse", "fuse", str(log), "-o", str(out / "f.csv")],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
    maps = Path(f"/proc/{proc.pid}/maps")
    deadline = time.monotonic() + 60
    while proc.poll() is None and time.monotonic() < deadline and str(log) not in maps.read_text():
        time.sleep(0.005)
    return proc, out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/PID/maps")
@pytest.mark.parametrize("signum", TERMINATING)
def test_a_terminating_signal_to_the_command_is_one_line(
    long_log: Path, tmp_path: Path, signum: int
) -> None:
    """SIGTERM, or SIGHUP (a closed terminal, a dropped SSH session), ends a run on one line,
    with 128 + the signal and no file (SIGHUP's default had left the temporary file being
    written)."""
    proc, out = fuse_of_a_long_log(long_log, tmp_path)
    proc.send_signal(signum)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signum, stderr
    assert stderr.strip() == f"altfuse: error: {SAID[signum]}"
    assert temporaries(tmp_path) == []
    assert not out.exists() or list(out.iterdir()) == []


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/PID/maps")
@pytest.mark.skipif(SIGHUP is None, reason="no SIGHUP")
def test_a_run_started_with_hangups_ignored_outlives_its_terminal(
    long_log: Path, tmp_path: Path
) -> None:
    """``nohup altfuse ...``: SIGHUP stays ignored, and the run finishes."""
    assert SIGHUP is not None
    proc, out = fuse_of_a_long_log(long_log, tmp_path, signal.SIG_IGN)
    proc.send_signal(SIGHUP)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    assert "error" not in stderr
    assert sorted(p.name for p in out.iterdir()) == ["f.csv", "f.meta.json"]


@contextlib.contextmanager
def compiling(tmp_path: Path) -> Iterator[subprocess.Popen[str]]:
    """``altfuse -v fuse`` of the sample log where nothing is compiled yet (a cache folder of
    its own), from when it says it compiles the smoother's loops; killed on the way out if it
    is still there."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    out = tmp_path / "out" / "f.csv"
    command = [sys.executable, "-m", "altfuse", "-v", "fuse", str(SAMPLE_LOG), "-o", str(out)]
    with (
        as_from_a_terminal(),
        subprocess.Popen(command, stderr=subprocess.PIPE, text=True, env=env) as proc,
    ):
        try:
            assert proc.stderr is not None
            for line in proc.stderr:
                if "compiling altfuse.fuse.smoother" in line:
                    break
            yield proc
        finally:
            if proc.poll() is None:
                proc.kill()


@pytest.mark.parametrize("signum", [*TERMINATING, signal.SIGINT])
def test_a_signal_ends_a_first_run_while_it_compiles(tmp_path: Path, signum: int) -> None:
    """A first run compiles the loops (numba: LLVM's C++ for seconds at a time, in which
    Python cannot run a signal's handler): SIGTERM or SIGINT there ended ``altfuse fuse`` only
    when the compilation did, 18-25 s later. The watchdog ends it within GRACE_S, on one
    line, with the signal's exit code and no output."""
    with compiling(tmp_path) as proc:
        assert proc.stderr is not None
        sent = time.monotonic()
        proc.send_signal(signum)
        rest = proc.stderr.read()
        proc.wait(timeout=60)
    assert time.monotonic() - sent < GRACE_S + 5
    assert proc.returncode == 128 + signum
    assert rest.strip().splitlines()[-1] == f"altfuse: error: {SAID[signum]}"
    out = tmp_path / "out"
    assert not out.exists() or list(out.iterdir()) == []


def test_a_signal_ends_a_run_whose_stderr_is_closed(tmp_path: Path) -> None:
    """SIGTERM where nothing reads stderr any more (a job cancelled after its log's reader
    went): the watchdog's line met the closed pipe, its thread died holding the lock that says
    the process is ending, and the main thread, out of the compilation, waited on that lock
    for ever (two such runs were found still there 20 minutes on). It ends within GRACE_S."""
    with compiling(tmp_path) as proc:
        assert proc.stderr is not None
        proc.stderr.close()
        sent = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
    assert time.monotonic() - sent < GRACE_S + 5
    assert proc.returncode == 128 + signal.SIGTERM
    out = tmp_path / "out"
    assert not out.exists() or list(out.iterdir()) == []


def copies(folder: Path, *names: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        shutil.copy(SAMPLES / "paper_a.bin", folder / name)
    return folder


def test_batch_refuses_stems_that_differ_only_in_case_or_extension(tmp_path: Path) -> None:
    logs = copies(tmp_path / "logs", "flight.bin", "flight.BIN", "other.Bin")
    with pytest.raises(ParameterError, match=r"flight\.BIN and .*flight\.bin would write"):
        run_batch([logs], tmp_path / "out", jobs=1)
    assert not (tmp_path / "out").exists()
    with pytest.raises(ParameterError, match="would write the same outputs"):
        run_batch([copies(tmp_path / "two", "x.bin"), tmp_path / "logs" / "flight.bin",
                   copies(tmp_path / "three", "flight.bin")], tmp_path / "out", jobs=1)  # fmt: skip


def test_batch_keeps_the_users_hidden_files(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / ".draft.tmp").write_text("mine")
    stale = out / "sub" / f"{TEMP_PREFIX}{write._HOST}-{dead_pid()}-a.csv.zz.tmp"
    stale.parent.mkdir()
    stale.write_text("left by a killed run")
    run_batch([copies(tmp_path / "logs", "a.bin")], out, jobs=1)
    assert (out / ".draft.tmp").read_text() == "mine"
    assert not stale.exists()


def test_batch_summary_is_merged_not_replaced(tmp_path: Path) -> None:
    out = tmp_path / "out"
    [first] = run_batch([copies(tmp_path / "one", "a.bin")], out, jobs=1)
    assert first.status == "ok"
    run_batch([copies(tmp_path / "two", "b.bin")], out, jobs=1)
    summary = pd.read_csv(out / "summary.csv")
    assert summary["log"].tolist() == ["a.bin", "b.bin"]
    assert (summary["status"] == "ok").all()
    # a skipped log keeps its earlier row and metrics
    again = BatchOptions(skip_existing=True)
    run_batch([tmp_path / "two"], out, again, jobs=1)
    summary = pd.read_csv(out / "summary.csv").set_index("log")
    assert summary.loc["b.bin", "status"] == "skipped"
    assert summary.loc["b.bin", "samples"] > 0
    # --force starts the summary afresh
    run_batch([tmp_path / "two"], out, BatchOptions(force=True), jobs=1)
    assert pd.read_csv(out / "summary.csv")["log"].tolist() == ["b.bin"]
    (out / "summary.csv").write_text("not,a\nsummary,at all\n")
    with pytest.raises(ParameterError, match="not a batch summary"):
        run_batch([tmp_path / "two"], out, again, jobs=1)


def test_a_merged_summary_keeps_its_number_format_where_the_new_rows_are_empty(
    tmp_path: Path,
) -> None:
    """The earlier rows' numbers stay at 6 decimals where every log run now was refused (its
    metrics empty): pandas 3 typed such a column by the empty values too, and wrote the earlier
    flight's span as 119.9 and its share fused with all its digits."""
    out = tmp_path / "out"
    run_batch([copies(tmp_path / "one", "a.bin")], out, jobs=1)
    refused = LogResult("b.bin", "refused", error="an ArduSub log; its BARO is water depth")
    write_summary([refused], out / "summary.csv", previous=pd.read_csv(out / "summary.csv"))
    row = next(r for r in (out / "summary.csv").read_text().splitlines() if r.startswith("a.bin,"))
    decimals = [len(v.partition(".")[2]) for v in row.split(",") if re.fullmatch(r"-?\d+\.\d+", v)]
    assert len(decimals) >= 3  # flight_s, processing_s, fused_share, max_excursion_m
    assert set(decimals) == {6}


def test_a_damaged_sidecar_means_redo_that_log(tmp_path: Path) -> None:
    out = tmp_path / "out"
    logs = copies(tmp_path / "logs", "a.bin")
    run_batch([logs], out, jobs=1)
    (out / "a.meta.json").write_text('{"input": {"sha256": "x"}, "outputs": ["a.csv"]}')
    [result] = run_batch([logs], out, BatchOptions(skip_existing=True, force=True), jobs=1)
    assert result.status == "ok"


def test_two_batches_on_one_folder_cannot_race(tmp_path: Path) -> None:
    out = tmp_path / "out"
    logs = copies(tmp_path / "logs", "a.bin")
    with (
        batch_module._locked(out),
        pytest.raises(ParameterError, match="another altfuse batch is writing"),
    ):
        run_batch([logs], out, jobs=1)
    assert run_batch([logs], out, jobs=1)[0].status == "ok"


def test_any_file_name_goes_into_the_summary(tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    logs.mkdir()
    raw = os.fsencode(logs) + b"/caf\xe9.bin"  # Latin-1, not UTF-8
    shutil.copy(SAMPLES / "paper_a.bin", raw)
    [result] = run_batch([logs], tmp_path / "out", jobs=1)
    assert result.status == "ok"
    assert result.log == "caf\\xe9.bin"
    assert pd.read_csv(tmp_path / "out" / "summary.csv")["log"].tolist() == ["caf\\xe9.bin"]


def children(pid: int) -> set[int]:
    found = set()
    for task in Path(f"/proc/{pid}/task").glob("*/children"):
        found |= {int(c) for c in task.read_text().split()}
    return found


def still_running(pids: set[int], within_s: float = 10) -> list[int]:
    """Those of ``pids`` still running ``within_s`` on (a zombie, not yet reaped by init, is
    gone too; a live process has /proc/PID/status "State: R/S")."""
    deadline = time.monotonic() + within_s
    while any(Path(f"/proc/{p}").exists() for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return [p for p in pids if _alive(p)]


def _alive(pid: int) -> bool:
    try:
        return "zombie" not in Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:  # gone
        return False


@pytest.mark.skipif(SIGHUP is None, reason="no SIGHUP")
def test_a_batch_whose_terminal_closes_ends_clean(long_log: Path, tmp_path: Path) -> None:
    """A closed terminal sends SIGHUP to the batch and its workers alike (one process group):
    the workers remove the temporary files of their logs, the batch says so on one line and
    exits 129, no worker is left."""
    assert SIGHUP is not None
    logs = tmp_path / "logs"
    logs.mkdir()
    for i in range(4):
        shutil.copy(long_log, logs / f"{i}.bin")
    out = tmp_path / "out"
    command = [sys.executable, "-m", "altfuse", "batch", str(logs), "-o", str(out), "-j", "2"]
    with as_from_a_terminal():
        proc = subprocess.Popen(command, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 60
    workers: set[int] = set()
    while not temporaries(tmp_path) and time.monotonic() < deadline and proc.poll() is None:
        workers |= children(proc.pid)
        time.sleep(0.002)
    assert workers, "no workers seen"
    os.killpg(proc.pid, SIGHUP)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 128 + SIGHUP, stderr
    assert stderr.strip() == "altfuse: error: hung up"
    assert still_running(workers) == []
    assert temporaries(tmp_path) == []


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
@pytest.mark.parametrize("cache", ["warm", "cold"])
def test_batch_workers_die_with_their_parent(tmp_path: Path, cache: str) -> None:
    """A killed batch leaves no worker running on, also where the workers compile the loops
    (a first run: the signal waits for the compilation but for the watchdog, 20 s)."""
    logs = copies(tmp_path / "logs", *(f"{i}.bin" for i in range(8)))
    command = [sys.executable, "-m", "altfuse", "batch", str(logs), "-o", str(tmp_path / "out")]
    env = dict(os.environ)
    if cache == "cold":
        env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba")
    proc = subprocess.Popen([*command, "--jobs", "2"], stderr=subprocess.DEVNULL, env=env)
    deadline = time.monotonic() + 60
    workers: set[int] = set()
    while len(workers) < 2 and time.monotonic() < deadline and proc.poll() is None:
        workers = children(proc.pid)
        time.sleep(0.05)
    assert len(workers) >= 2, "no workers seen"
    proc.kill()
    proc.wait()
    assert still_running(workers) == []


def test_a_python_warning_is_never_a_second_stderr_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import warnings

    from altfuse import commands as cli_module

    original = cli_module.run_to_files

    def noisy(*args: object, **kwargs: object) -> object:
        warnings.warn("invalid value encountered in divide", RuntimeWarning, stacklevel=1)
        return original(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(cli_module, "run_to_files", noisy)
    result = run("fuse", SAMPLE_LOG, "-o", tmp_path / "out.csv")
    assert result.exit_code == 0
    assert "RuntimeWarning" not in result.stderr
    assert len(result.stderr.strip().splitlines()) <= 1  # the sample log's one warning line
    debug = run("-vv", "fuse", SAMPLE_LOG, "-o", tmp_path / "again.csv")
    assert "RuntimeWarning: invalid value encountered in divide" in debug.stderr


_PROCESS_IN_WORKER = batch_module._process_in_worker


def dying(job: batch_module.Job, options: BatchOptions) -> batch_module.LogResult:
    """A worker's job that ends its process while it reads ``b.bin``, as the SIGBUS handler
    would, after the others' first second (so that they are running when the pool breaks)."""
    if job.log.name == "b.bin":
        batch_module._worker.started.put(str(job.relative))
        time.sleep(1.0)
        os._exit(1)
    return _PROCESS_IN_WORKER(job, options)


def test_a_worker_that_dies_fails_its_log_alone(tmp_path: Path) -> None:
    """The pool breaks, and every job in it: those running run again each alone, the others
    in a new pool; only the log that kills its worker fails (all unfinished ones did)."""
    logs = copies(tmp_path / "logs", "a.bin", "b.bin", "c.bin", "d.bin", "e.bin")
    with pytest.MonkeyPatch.context() as monkey:
        monkey.setattr(batch_module, "_process_in_worker", dying)
        results = run_batch([logs], tmp_path / "out", jobs=2)
    by_log = {r.log: r for r in results}
    assert set(by_log) == {"a.bin", "b.bin", "c.bin", "d.bin", "e.bin"}  # a row each
    assert by_log["b.bin"].status == "failed"
    assert "its worker process died" in by_log["b.bin"].error
    assert {r.status for name, r in by_log.items() if name != "b.bin"} == {"ok"}
    assert pd.read_csv(tmp_path / "out" / "summary.csv")["log"].tolist() == sorted(by_log)


def dying_at_start(job: batch_module.Job, options: BatchOptions) -> batch_module.LogResult:
    """A worker's job that ends its process on ``b.bin`` before it says it started."""
    if job.log.name == "b.bin":
        time.sleep(1.0)
        os._exit(1)
    return _PROCESS_IN_WORKER(job, options)


def test_a_log_whose_worker_dies_before_it_starts_still_has_a_row(tmp_path: Path) -> None:
    """Run alone after the pool broke, a job lost before its worker said it started was
    dropped without a row."""
    logs = copies(tmp_path / "logs", "a.bin", "b.bin", "c.bin")
    with pytest.MonkeyPatch.context() as monkey:
        monkey.setattr(batch_module, "_process_in_worker", dying_at_start)
        results = run_batch([logs], tmp_path / "out", jobs=2)
    by_log = {r.log: r.status for r in results}
    assert by_log == {"a.bin": "ok", "b.bin": "failed", "c.bin": "ok"}
