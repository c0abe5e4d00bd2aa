"""DataFlash logs written as text (``.log``): read as the binary logs they were written from."""

from __future__ import annotations

import contextlib
import gzip
import hashlib
import json
import tempfile
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink import DFReader

from altfuse.cli import cli
from altfuse.errors import LogReadError
from altfuse.io import read_log
from altfuse.io.dataflash_text import is_text_log
from conftest import ROOT, SAMPLE_LOG, shared_log


def as_text(
    log: Path, out: Path, digits: int | None = None, newline: str = "\n", delimiter: str = ", "
) -> Path:
    """``log`` written as a DataFlash text log, from pymavlink's decoding of it (scaled fields
    in their units, as Mission Planner writes them); floats to ``digits`` significant digits
    where given (Mission Planner's are rounded), all of them otherwise."""
    lines = []
    # closing: a reader is a context manager itself only since pymavlink 2.4.50
    with contextlib.closing(DFReader.DFReader_binary(str(log), zero_time_base=False)) as reader:
        while (message := reader.recv_msg()) is not None:
            values = [getattr(message, column) for column in message.fmt.columns]
            if digits is not None:
                values = [f"{v:.{digits}g}" if isinstance(v, float) else v for v in values]
            lines.append(delimiter.join([message.get_type(), *map(str, values)]))
    out.write_text(newline.join(lines) + newline, newline="")
    return out


def records_in(text: Path) -> int:
    """The records pymavlink, the authority, reads in the text log ``text``."""
    with contextlib.closing(DFReader.DFReader_text(str(text))) as reader:
        return sum(reader.counts.values())


def fuse(log: Path, out: Path, *args: str) -> str:
    result = CliRunner().invoke(cli, ["fuse", str(log), "-o", str(out), *args])
    assert result.exit_code == 0, result.output
    return result.stderr


def test_the_authority_reads_the_text_written_here(tmp_path: Path) -> None:
    """The helper's text is a text log as pymavlink reads one: a record of every line."""
    text = as_text(SAMPLE_LOG, tmp_path / "mission.log")
    assert records_in(text) == len(text.read_text().splitlines()) > 10_000


def test_a_text_log_fuses_as_the_binary_it_was_written_from(tmp_path: Path) -> None:
    """To the byte; described as the text file (its name, size and sha256) and said so."""
    text = as_text(SAMPLE_LOG, tmp_path / "mission.log")
    fuse(SAMPLE_LOG, tmp_path / "binary.csv")
    fuse(text, tmp_path / "text.csv")
    assert (tmp_path / "text.csv").read_bytes() == (tmp_path / "binary.csv").read_bytes()
    flight = read_log(text)
    assert flight.path == str(text)
    assert flight.size_bytes == text.stat().st_size
    assert flight.sha256 == hashlib.sha256(text.read_bytes()).hexdigest()
    assert flight.reader.startswith("DataFlash text")
    assert f"{records_in(text)} of its {records_in(text)} lines converted" in " ".join(flight.notes)
    assert not flight.damaged


def test_an_older_logs_text_reads_as_its_binary(tmp_path: Path) -> None:
    """A Plane 3.3 log: GPS stamped in TimeMS with its boot time in T, legacy scaled fields."""
    log = shared_log("truth/plane_3.3.0a1_gitterbadger_autotest_climb386m_imunoise.BIN")
    text = as_text(log, tmp_path / "plane.log")
    for a, b in zip(read_log(log).sensors, read_log(text).sensors, strict=True):
        assert a.name == b.name
        np.testing.assert_array_equal(a.t, b.t)
        np.testing.assert_array_equal(a.value, b.value)


def test_mission_planners_and_apm_planners_text_reads_within_its_rounding(tmp_path: Path) -> None:
    """Floats to 7 significant digits, Windows line ends, flight modes by their names, and APM
    Planner's FMT line without its own "Columns": the fused heights within micrometres of the
    binary's, and no line left out."""
    text = as_text(SAMPLE_LOG, tmp_path / "mission.log", digits=7, newline="\r\n")
    lines = text.read_bytes().split(b"\r\n")
    assert lines[0] == b"FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns"
    lines[0] = b"FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format"
    lines[1:1] = [b"FMT, 201, 14, MODE, QMBB, TimeUS,Mode,ModeNum,Rsn"]
    lines[5000:5000] = [b"MODE, 55000000, Loiter, 5, 2", b"MODE, 55000001, QHover, 18, 2"]
    text.write_bytes(b"\r\n".join(lines))
    fuse(SAMPLE_LOG, tmp_path / "binary.csv")
    fuse(text, tmp_path / "text.csv")
    binary = np.genfromtxt(tmp_path / "binary.csv", delimiter=",", names=True)
    read = np.genfromtxt(tmp_path / "text.csv", delimiter=",", names=True)
    assert read.size == binary.size == 1200
    assert np.nanmax(np.abs(read["fused_alt_m"] - binary["fused_alt_m"])) < 1e-5
    flight = read_log(text)
    assert not flight.damaged
    assert flight.record_counts["MODE"] == 2


def test_a_text_log_delimited_by_bare_commas_reads_the_same(tmp_path: Path) -> None:
    """pymavlink takes "," where the first FMT line has no ", "; a message's own commas stay
    in it (the simulator's MSG holds ", ", and names the firmware)."""
    text = as_text(SAMPLE_LOG, tmp_path / "mission.log", delimiter=",")
    assert text.read_text().startswith("FMT,128,89,FMT,BBnNZ,Type,Length,Name,Format,Columns\n")
    fuse(SAMPLE_LOG, tmp_path / "binary.csv")
    fuse(text, tmp_path / "text.csv")
    assert (tmp_path / "text.csv").read_bytes() == (tmp_path / "binary.csv").read_bytes()
    assert read_log(text).firmware == read_log(SAMPLE_LOG).firmware


def test_lines_that_hold_no_record_are_left_out_counted_and_said(tmp_path: Path) -> None:
    """A line of an undeclared type, one whose field is no number, one of too many fields, and
    a last line cut short: left out, counted, the first named (a warning, as a binary log's
    skipped bytes); banner and blank lines are no records."""
    text = as_text(SAMPLE_LOG, tmp_path / "mission.log").read_text()
    cut = text[: len(text) // 2]
    lines = cut.splitlines(keepends=True)
    lines[300:300] = [
        "ArduCopter V4.0.0 (a banner)\n",
        "\n",
        "XYZ, 1, 2\n",
        "BARO, 1, 0, x, 2, 3\n",
        "FMT, 200, 3, NONE, , \n",  # a type of no field
        "NONE, 1, 2\n",  # its line: too many
    ]
    damaged = tmp_path / "damaged.log"
    damaged.write_text("".join(lines))
    flight = read_log(damaged)
    assert 0 < flight.sensors[0].t.size < read_log(SAMPLE_LOG).sensors[0].t.size
    (said,) = flight.damaged
    assert "4 left out (the first: line 303: 'XYZ' is not declared by an FMT line)" in said
    stderr = fuse(damaged, tmp_path / "damaged.csv")
    assert "4 left out" in stderr
    info = json.loads(CliRunner().invoke(cli, ["info", str(damaged), "--json"]).stdout)
    assert info["reader"].startswith("DataFlash text, converted to binary")
    assert info["damaged"] == [said]


def test_a_compressed_or_piped_text_log_reads_as_the_text(tmp_path: Path) -> None:
    text = as_text(SAMPLE_LOG, tmp_path / "mission.log")
    packed = tmp_path / "mission.log.gz"
    packed.write_bytes(gzip.compress(text.read_bytes()))
    fuse(text, tmp_path / "text.csv")
    fuse(packed, tmp_path / "packed.csv")
    assert (tmp_path / "packed.csv").read_bytes() == (tmp_path / "text.csv").read_bytes()
    assert read_log(packed).sha256 == hashlib.sha256(packed.read_bytes()).hexdigest()
    piped = CliRunner().invoke(
        cli, ["fuse", "-", "-o", str(tmp_path / "piped.csv")], input=text.read_bytes()
    )
    assert piped.exit_code == 0, piped.output
    assert (tmp_path / "piped.csv").read_bytes() == (tmp_path / "text.csv").read_bytes()


def test_a_text_log_after_a_long_banner_is_known(tmp_path: Path) -> None:
    """pymavlink looks for the first FMT line in 8,000 characters (altfuse looked in 4,096)
    and starts the log there: the lines before it are no damage."""
    text = as_text(SAMPLE_LOG, tmp_path / "mission.log")
    banner = "".join(f"Init ArduCopter V4.0.0, step {k}\n" for k in range(200))
    assert 4096 < len(banner) < 7000
    text.write_text(banner + text.read_text())
    fuse(SAMPLE_LOG, tmp_path / "binary.csv")
    assert "left out" not in fuse(text, tmp_path / "text.csv")
    assert (tmp_path / "text.csv").read_bytes() == (tmp_path / "binary.csv").read_bytes()


def test_text_that_is_no_log_is_refused_in_one_line(tmp_path: Path) -> None:
    assert is_text_log(b"FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns\n")
    assert is_text_log(b"ArduCopter V3.1.5\r\nFMT, 129, 23, PARM, QNf, TimeUS,Name,Value\r\n")
    assert not is_text_log(b"2026-12-05 21:00:00 INFO mavproxy started\nFMT is fine\n")
    assert not is_text_log(b"FMT, 128, 89, \0\0\0")
    notes = tmp_path / "notes.log"
    notes.write_text("2026-12-05 21:00:00 INFO mavproxy started\n")
    with pytest.raises(LogReadError, match=r"notes\.log: not a DataFlash log"):
        read_log(notes)
    nothing = tmp_path / "nothing.log"
    nothing.write_text("FMT, 1, 2, 3\nGPS, 4, 5\n")
    with pytest.raises(LogReadError, match=r"nothing\.log: nothing came from its DataFlash text"):
        read_log(nothing)
    declared_only = tmp_path / "declared.log"
    declared_only.write_text("FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns\n")
    refused = CliRunner().invoke(cli, ["fuse", str(declared_only), "-o", str(tmp_path / "x.csv")])
    assert refused.exit_code == 1
    assert refused.stderr == (
        "altfuse: error: declared.log: no usable altitude source "
        "(looked for GPS, barometer, rangefinder)\n"
    )
    assert not (tmp_path / "x.csv").exists()


def test_a_batch_takes_text_logs_when_asked(tmp_path: Path) -> None:
    """Not by default (a folder may hold a log as .bin and as the .log converted from it, and
    other programs' logs); a batch that finds none of its patterns says where .log files are."""
    logs = tmp_path / "logs"
    logs.mkdir()
    as_text(SAMPLE_LOG, logs / "mission.log")
    found = CliRunner().invoke(cli, ["batch", str(logs), "-o", str(tmp_path / "a")])
    assert found.exit_code == 1
    assert "1 *.log there: --pattern '*.log' takes them" in found.stderr
    taken = CliRunner().invoke(
        cli, ["batch", str(logs), "-o", str(tmp_path / "b"), "--pattern", "*.log", "-j", "1"]
    )
    assert taken.exit_code == 0, taken.output
    assert (tmp_path / "b" / "mission.csv").exists()


@cache
def _paper_a_lines() -> tuple[bytes, ...]:
    with tempfile.TemporaryDirectory() as folder:
        text = as_text(ROOT / "sample_logs" / "paper_a.bin", Path(folder) / "paper_a.log")
        return tuple(text.read_bytes().splitlines(keepends=True))


@settings(
    max_examples=30, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(
    edits=st.lists(
        st.tuples(
            st.sampled_from(["delete", "insert", "flip", "cut", "delimiter", "swap"]),
            st.floats(0, 1),
            st.binary(max_size=40),
        ),
        min_size=1,
        max_size=20,
    ),
    end=st.floats(0.05, 1),
)
def test_damaged_text_logs_never_crash(edits: list[tuple[str, float, bytes]], end: float) -> None:
    """Property: a text log damaged line by line gives a valid output or one error line."""
    lines = list(_paper_a_lines())
    for what, where, junk in edits:
        i = int(where * (len(lines) - 1))
        if what == "delete":
            del lines[i]
        elif what == "insert":
            lines.insert(i, junk + b"\n")
        elif what == "flip" and junk:
            lines[i] = lines[i][: len(junk)] + junk[:1] + lines[i][len(junk) + 1 :]
        elif what == "cut":
            lines[i] = lines[i][: len(junk)]
        elif what == "delimiter":
            lines[i] = lines[i].replace(b", ", b",", 1)
        elif what == "swap":
            lines[i], lines[-1 - i] = lines[-1 - i], lines[i]
    data = b"".join(lines)
    with tempfile.TemporaryDirectory() as folder:
        log, out = Path(folder) / "damaged.log", Path(folder) / "out.csv"
        log.write_bytes(data[: int(end * len(data))])
        result = CliRunner().invoke(cli, ["fuse", str(log), "-o", str(out), "-m", "support"])
        assert result.exit_code in (0, 1), (edits, end, result.output)
        if result.exit_code == 1:
            assert result.stderr.count("\n") == 1, result.stderr
            assert result.stderr.startswith("altfuse: error: ")
            assert not out.exists()
