"""The compiled walk of a ULog's data section (``altfuse.io.fastulog``) against pyulog's own
parse: every value of every topic altfuse reads, the info and parameters, the dropouts; on
the shared logs, on logs cut anywhere, with a message pyulog parses in its loop added; and the
damage that must send the file to pyulog whole."""

from __future__ import annotations

import contextlib
import io
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pyulog import ULog

from altfuse.io import fastulog
from altfuse.io.ulog import TOPICS
from conftest import shared_log

#: The shared ULogs the walk reads; pyulog reads the others whole (two corrupt, one with data
#: appended).
INTACT = [
    "px4_sitl_stifael_14_19_29.ulg",
    "px4_sitl_yuneec_parameterchange.ulg",
    "px4_sitl_yuneec_position.ulg",
    "px4ulogrs_6ba1abc7-b433-4029-b8f5-3b2bb12d3b6c.ulg",
    "px4ulogrs_esc_status_log.ulg",
    "px4ulogrs_quadrotor_local.ulg",
    "pyulog_sample_log_small.ulg",
    "pyulog_sample_logging_tagged_and_default_params.ulg",
    "pyulog_sample_px4_events.ulg",
]
WHOLE = [
    "px4ulogrs_corrupt_actuator_armed_wrong_size.ulg",
    "px4ulogrs_corrupt_unregistered_msg_id.ulg",
    "pyulog_sample_appended_multiple.ulg",
]
#: A small intact log, whose bytes the tests below change.
BASE = "px4ulogrs_esc_status_log.ulg"


def _pyulog(path: Path) -> ULog:
    with contextlib.redirect_stdout(io.StringIO()):
        return ULog(str(path), list(TOPICS))


def _assert_pyulog_s(path: Path) -> fastulog.Decoded:
    """The walk's decoding of ``path``, asserted equal to pyulog's in everything altfuse
    reads."""
    decoded = fastulog.decode(path, TOPICS)
    assert decoded is not None
    ulog = _pyulog(path)
    assert not ulog.file_corruption
    assert decoded.start_timestamp == ulog.start_timestamp
    assert decoded.msg_info_dict == ulog.msg_info_dict
    assert decoded.initial_parameters == ulog.initial_parameters
    assert [d.duration for d in decoded.dropouts] == [d.duration for d in ulog.dropouts]
    ours = [(d.name, d.multi_id) for d in decoded.data_list]
    assert ours == [(d.name, d.multi_id) for d in ulog.data_list]
    assert ours  # topics were read
    for mine, its in zip(decoded.data_list, ulog.data_list, strict=True):
        assert list(mine.data) == list(its.data)
        for column, values in mine.data.items():
            assert values.dtype == its.data[column].dtype
            assert values.tobytes() == its.data[column].tobytes(), (mine.name, column)
    return decoded


@pytest.mark.parametrize("name", INTACT)
def test_an_intact_log_decodes_to_pyulog_s_values(name: str) -> None:
    _assert_pyulog_s(shared_log(f"px4/{name}"))


@pytest.mark.parametrize("name", WHOLE)
def test_a_damaged_or_appended_log_is_left_to_pyulog(name: str) -> None:
    assert fastulog.decode(shared_log(f"px4/{name}"), TOPICS) is None


def test_the_shared_logs_are_named() -> None:
    assert sorted(p.name for p in shared_log("px4").glob("*.ulg")) == sorted(INTACT + WHOLE)


def _chain(raw: bytes) -> list[int]:
    """The offset of every message of a ULog's bytes, walked as pyulog does."""
    at, out = fastulog.FILE_HEADER, []
    while at + 3 <= len(raw):
        (size,) = struct.unpack_from("<H", raw, at)
        out.append(at)
        at += 3 + size
    return out


def _message(kind: str, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), ord(kind)) + payload


def _first(raw: bytes, kind: str, after: int = 0) -> int:
    """The offset of the first message of ``kind`` at or after ``after``."""
    return next(at for at in _chain(raw) if at >= after and raw[at + 2] == ord(kind))


def _write(tmp_path: Path, raw: bytes) -> Path:
    path = tmp_path / "changed.ulg"
    path.write_bytes(raw)
    return path


@pytest.mark.parametrize("share", [0.2, 0.35, 0.5, 0.65, 0.8, 0.95, 0.9999])
def test_a_log_cut_anywhere_decodes_to_pyulog_s_values(share: float, tmp_path: Path) -> None:
    """Cut inside a message (a flight's log when the battery went): the walk stops where
    pyulog's loop does, at the message the file ends inside."""
    raw = shared_log(f"px4/{BASE}").read_bytes()
    cut = int(len(raw) * share)
    assert cut not in _chain(raw)  # inside a message, not between two
    _assert_pyulog_s(_write(tmp_path, raw[:cut]))


def test_info_and_dropouts_in_the_data_section_are_pyulog_s(tmp_path: Path) -> None:
    """An info message and a dropout among the data messages: pyulog's loop takes the info
    into its dictionary and counts the dropout; so does the walk."""
    raw = shared_log(f"px4/{BASE}").read_bytes()
    at = _first(raw, "D", len(raw) // 2)
    key = b"char[5] added"
    info = _message("I", bytes([len(key)]) + key + b"hello")
    dropout = _message("O", struct.pack("<H", 250))
    decoded = _assert_pyulog_s(_write(tmp_path, raw[:at] + info + dropout + raw[at:]))
    assert decoded.msg_info_dict["added"] == "hello"
    assert [d.duration for d in decoded.dropouts] == [250]


def _subscriptions(raw: bytes) -> list[tuple[int, int, str]]:
    """Each subscription's offset, message id and topic."""
    out = []
    for at in _chain(raw):
        if raw[at + 2] == ord("A"):
            (size,) = struct.unpack_from("<H", raw, at)
            (msg_id,) = struct.unpack_from("<H", raw, at + 4)
            out.append((at, msg_id, raw[at + 6 : at + 3 + size].decode()))
    return out


def _data_of(raw: bytes, msg_id: int) -> bytes:
    """The first data message of ``msg_id``."""
    for at in _chain(raw):
        if raw[at + 2] == ord("D") and struct.unpack_from("<H", raw, at + 3)[0] == msg_id:
            return raw[at : at + 3 + struct.unpack_from("<H", raw, at)[0]]
    raise AssertionError(msg_id)


def _damaged(raw: bytes, how: str) -> bytes:
    """``raw`` with a message changed or added as pyulog's loop takes as damage, or treats
    in a way of its own."""
    middle = _first(raw, "D", len(raw) // 2)
    subscriptions = _subscriptions(raw)
    kept = [s for s in subscriptions if s[2] in TOPICS]
    if how == "unknown type":
        return raw[:middle] + _message("z", b"\x00" * 8) + raw[middle:]
    if how == "data without a message id":
        # one byte, and the next message's first (its size's low byte, 0) would make the id
        # of a topic subscribed and not kept: pyulog's loop stops at such a message
        _, msg_id, _ = next(s for s in subscriptions if s[2] not in TOPICS and s[1] < 256)
        text = _message("L", b"\x06" + bytes(8) + b"x" * 247)
        return raw[:middle] + _message("D", bytes([msg_id])) + text + raw[middle:]
    if how == "data one byte longer":
        (size,) = struct.unpack_from("<H", raw, middle)
        longer = struct.pack("<H", size + 1) + raw[middle + 2 : middle + 3 + size] + b"\x00"
        return raw[:middle] + longer + raw[middle + 3 + size :]
    if how == "a kept topic's id subscribed again to another":
        # pyulog keeps the kept topic's subscription and takes the id as filtered too
        at, msg_id, _ = kept[0]
        other = next(name for _, _, name in subscriptions if name not in TOPICS)
        again = _message("A", raw[at + 3 : at + 6] + other.encode())
        (size,) = struct.unpack_from("<H", raw, at)
        return raw[: at + 3 + size] + again + raw[at + 3 + size :]
    if how == "data before its subscription":
        first = subscriptions[0][0]
        _, msg_id, _ = next(s for s in kept if s[0] > first)
        (size,) = struct.unpack_from("<H", raw, first)
        return raw[: first + 3 + size] + _data_of(raw, msg_id) + raw[first + 3 + size :]
    if how == "a kept topic's format of padding alone":
        name = kept[0][2].encode() + b":"
        formats = [a for a in _chain(raw) if raw[a + 2] == ord("F")]
        at = next(a for a in formats if raw[a + 3 : a + 3 + len(name)] == name)
        (size,) = struct.unpack_from("<H", raw, at)
        padding = _message("F", name + b"uint8_t[8] _padding0;")
        return raw[:at] + padding + raw[at + 3 + size :]
    if how == "data among the definitions":
        at = _first(raw, "F")
        return raw[:at] + _data_of(raw, kept[0][1]) + raw[at:]
    if how == "a definition after the data began":
        fmt = _first(raw, "F")
        (size,) = struct.unpack_from("<H", raw, fmt)
        return raw[:middle] + raw[fmt : fmt + 3 + size] + raw[middle:]
    assert how == "another log joined"
    return raw + raw


@pytest.mark.parametrize(
    "how",
    [
        "unknown type",
        "data without a message id",
        "data one byte longer",
        "a kept topic's id subscribed again to another",
        "data before its subscription",
        "a kept topic's format of padding alone",
        "data among the definitions",
        "a definition after the data began",
        "another log joined",
    ],
)
def test_what_pyulog_takes_as_damage_is_left_to_it(how: str, tmp_path: Path) -> None:
    raw = shared_log(f"px4/{BASE}").read_bytes()
    assert fastulog.decode(_write(tmp_path, _damaged(raw, how)), TOPICS) is None


def test_a_log_read_up_to_another_joined_to_it_is_the_first_alone(tmp_path: Path) -> None:
    raw = shared_log(f"px4/{BASE}").read_bytes()
    path = _write(tmp_path, raw + shared_log("px4/pyulog_sample_log_small.ulg").read_bytes())
    first = tmp_path / "first.ulg"
    first.write_bytes(raw)
    joined = fastulog.decode(path, TOPICS, end=len(raw))
    alone = fastulog.decode(first, TOPICS)
    assert joined is not None
    assert alone is not None
    assert [(d.name, d.multi_id) for d in joined.data_list] == [
        (d.name, d.multi_id) for d in alone.data_list
    ]
    for a, b in zip(joined.data_list, alone.data_list, strict=True):
        for column in a.data:
            np.testing.assert_array_equal(a.data[column], b.data[column])


@pytest.mark.parametrize("where", ["in the file's header", "in the definitions"])
def test_a_log_cut_before_its_data_is_left_to_pyulog(where: str, tmp_path: Path) -> None:
    raw = shared_log(f"px4/{BASE}").read_bytes()
    cut = 17 if where == "in the file's header" else _first(raw, "A") // 2
    assert fastulog.decode(_write(tmp_path, raw[:cut]), TOPICS) is None


#: Fuzzed variants (``tests/fuzzing.py``'s base, mutations and seed) whose definitions the
#: damage left holding other types: given them alone, pyulog stepped a byte at a time off the
#: chain and back over the same bytes without end (each ran ``fuzz_long.py`` past its 30 s).
OFF_THE_CHAIN = [
    ("px4ulogrs_corrupt_actuator_armed_wrong_size.ulg", "zero truncate ulog-values", 40017283),
    ("pyulog_sample_appended_multiple.ulg", "duplicate truncate flip", 4289618775),
    ("px4ulogrs_corrupt_actuator_armed_wrong_size.ulg", "garbage zero garbage", 331599789),
    ("pyulog_sample_px4_events.ulg", "garbage zero duplicate", 3762536897),
    ("px4ulogrs_corrupt_unregistered_msg_id.ulg", "ulog-values duplicate duplicate", 1724032410),
]


def test_definitions_off_the_chain_are_left_to_pyulog_whole(tmp_path: Path) -> None:
    """Run apart, so that a walk that hangs fails the test rather than the suite."""
    script = f"""
import sys
from pathlib import Path
sys.path.insert(0, {str(Path(__file__).parent)!r})
from fuzzing import variant
from altfuse.io.fastulog import decode
from altfuse.io.ulog import TOPICS
for base, names, seed in {OFF_THE_CHAIN!r}:
    path = Path({str(tmp_path)!r}) / "damaged.ulg"
    data = Path({str(shared_log("px4"))!r}, base).read_bytes()
    path.write_bytes(variant(data, None, names.split(), seed))
    print(decode(path, TOPICS))
"""
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=True
    )
    assert done.stdout.split() == ["None"] * len(OFF_THE_CHAIN)


@pytest.mark.parametrize("name", fastulog.PYULOG_CLASSES)
def test_a_pyulog_without_a_class_the_walk_uses_is_left_to_read_whole(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The walk parses with pyulog's own classes, which are not its API: where a release
    renamed one, pyulog reads the file whole, rather than the walk failing."""
    log = shared_log(f"px4/{BASE}")
    assert fastulog.decode(log, TOPICS) is not None
    monkeypatch.delattr(ULog, name)
    assert fastulog.decode(log, TOPICS) is None
