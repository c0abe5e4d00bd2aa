"""ULog's data section read without a Python step per message: pyulog's decoding, its walk
compiled.

pyulog (PX4's own parser) stays the authority on the format. It reads the data section a
message at a time in Python: on a 290 MB ULog 12.6 of 13.3 s under cProfile were its loop over
4.9 M messages, for the few topics altfuse keeps. Here, on an intact file, compiled walks along
the message chain (each message's header, its size and type, says where the next begins; a
walk stops at a message the file ends inside, where pyulog's loop stops: a log cut short),
each releasing the file's pages as it passes them:

1. the first lists the messages that are not data, and stops at a type pyulog does not know.
   The definitions (flag bits, formats, info, parameters, back to back up to the first
   message of the data section: a subscription or a logged string, where pyulog's
   definitions loop stops) pyulog reads given those bytes alone; the data section's others
   (subscriptions, logged strings, info, parameters, dropouts, syncs: hundreds, where the
   data messages are millions) are parsed in order by pyulog's own message classes;
2. the second checks each data message as pyulog's loop would (a message id, a subscription
   before it, a kept topic's size) and counts the kept topics' bytes;
3. the third, the same loop, copies each kept topic's payloads into its own stretch of one
   buffer, which pyulog's own ``ULog.Data`` decodes, as it decodes the buffer its loop
   builds: one ``frombuffer`` per topic instance.

No array of every message is made: a 296 MB log's peak is the kept topics' data and the
file's pages of one chunk, 1.3x the file (an offset, type, size and id per message had taken a
290 MB log to 1.6x). Where the file holds anything pyulog's loop would take as damage or treat
in a way of its own (a type it does not know, other messages among the definitions, a data
message without a message id, of no earlier subscription or of another size than its topic's
format, a kept topic's message id subscribed again or its format of padding alone, a message
pyulog's classes cannot parse, data appended after the file's end, anything pyulog printed
reading the definitions), or where the pyulog installed lacks one of those classes,
:func:`decode` returns None and pyulog reads the file whole. Every value it returns is
pyulog's (``tests/test_fastulog.py`` compares every field with pyulog's whole parse).
"""

from __future__ import annotations

import contextlib
import io
import mmap
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from altfuse.compiled import compiled
from altfuse.io.fastdf import _CHUNK, _release, exit_on_sigbus

#: A message's header: its payload's size (uint16) and its type (a character).
HEADER = 3
#: The file's header: the magic bytes, the version and the start's timestamp.
FILE_HEADER = 16
#: The types that begin the data section (pyulog's definitions loop stops at the first), and
#: the definitions' (flag bits, formats, info, parameters): pyulog reads the definitions
#: alone only where they hold no other type. Another is skipped by its loop, or taken as damage
#: and stepped over a byte at a time, off the chain: where a message then claims more bytes
#: than are left, pyulog steps back and reads them again without end (a fuzzed log whose
#: definitions were zeroed in part).
DATA_SECTION = frozenset(b"ALC")
DEFINITIONS = frozenset(b"BFIMPQ")
#: Every type pyulog knows but data ("D"): the definitions', and the data section's others.
KNOWN = DEFINITIONS | frozenset(b"ALCOS")
_DATA = ord("D")
#: The classes of pyulog's that parse what the walk hands them (pyulog 1.0 to 1.3 have them).
PYULOG_CLASSES = (
    "_MessageHeader",
    "_MessageAddLogged",
    "_MessageInfo",
    "_MessageParameterDefault",
    "MessageLogging",
    "MessageLoggingTagged",
    "MessageDropout",
    "Data",
)
#: Why a walk stopped: to go on from there, the chain's end, or a message pyulog would not read
#: on from (a type it does not know; a data message it would take as damage or stop at).
GO_ON, ENDED, REFUSED = 0, 1, 2
_FOUND = 1 << 14  # messages other than data found per call of the walk


@dataclass
class Decoded:
    """What :func:`decode` read: the attributes of a ``pyulog.ULog`` that altfuse reads (the
    dropouts' durations are pyulog's, their times not)."""

    start_timestamp: int
    msg_info_dict: dict[str, Any]
    initial_parameters: dict[str, Any]
    data_list: list[Any] = field(default_factory=list)
    dropouts: list[Any] = field(default_factory=list)
    file_corruption: bool = False


@compiled
def _size(data: npt.NDArray[np.uint8], at: int) -> int:
    """The payload's size of the message at ``at`` (its header's little-endian uint16)."""
    return int(data[at]) | (int(data[at + 1]) << 8)


@compiled
def _walk(  # noqa: PLR0913 (the bytes, where to walk, the types known, the two columns)
    data: npt.NDArray[np.uint8],
    start: int,
    limit: int,
    stop: int,
    known: npt.NDArray[np.bool_],
    offsets: npt.NDArray[np.int64],
    types: npt.NDArray[np.uint8],
) -> tuple[int, int, int]:
    """The chain of messages from byte ``start``, each at the end of the one before, as
    pyulog's loops walk it: the offset and type of each message but data messages (hundreds
    of them, where data messages are millions), into the first entries of ``offsets`` and
    ``types``, until ``limit`` or as many as they hold. Their count, where the walk is to go
    on from, and why it stopped there: GO_ON, ENDED (at ``stop``, or at a message the file
    ends inside: pyulog's loop stops there) or REFUSED (a type not ``known``: damage, where a
    zeroed stretch would list a message every 3 bytes)."""
    n = 0
    at = start
    while at < limit:
        if at + HEADER > stop:
            return n, at, ENDED
        size = _size(data, at)
        if at + HEADER + size > stop:
            return n, at, ENDED
        kind = data[at + 2]
        if kind != _DATA:
            if not known[kind]:
                return n, at, REFUSED
            if n == offsets.size:
                return n, at, GO_ON
            offsets[n] = at
            types[n] = kind
            n += 1
        at += HEADER + size
    return n, at, GO_ON


@compiled
def _payloads(  # noqa: PLR0913 (the bytes, where to walk, the subscriptions, where to copy)
    data: npt.NDArray[np.uint8],
    start: int,
    limit: int,
    end: int,
    since: npt.NDArray[np.int64],
    width: npt.NDArray[np.int64],
    cursor: npt.NDArray[np.int64],
    out: npt.NDArray[np.uint8],
) -> tuple[int, bool]:
    """The data messages of the chain from ``start`` until ``limit`` (or its ``end``): each
    kept topic's payload, its format's ``width`` bytes after the message id, copied into
    ``out`` at its id's ``cursor`` (not where ``out`` is empty: the bytes counted), which moves
    on by them. Where the walk is to go on from, and False where pyulog's loop would take a
    message as damage or stop at it: no message id, no subscription before it (``since``,
    each id's subscription's offset), or a kept topic's of another size than its format's
    (``width``, 0 for the topics not kept)."""
    at = start
    while at < limit and at < end:
        size = _size(data, at)
        if data[at + 2] == _DATA:
            if size < 2:
                return at, False
            msg_id = _size(data, at + HEADER)
            w = width[msg_id]
            if since[msg_id] > at or (w > 0 and size - 2 != w):
                return at, False
            c = cursor[msg_id]
            if out.size:
                for j in range(w):
                    out[c + j] = data[at + HEADER + 2 + j]
            cursor[msg_id] = c + w
        at += HEADER + size
    return at, True


@dataclass
class _File:
    """A mapped file: its bytes, its mapping (whose pages a walk releases as it passes) and
    where its chain of messages ends."""

    data: npt.NDArray[np.uint8]
    mapped: mmap.mmap
    end: int = 0

    def walk(self, start: int, step: Callable[[int, int], tuple[int, int]]) -> tuple[int, int]:
        """``step`` along the chain from ``start``, a chunk at a time, while it says GO_ON:
        given where to go on from and the chunk's end, it returns where it stopped and why
        (GO_ON, ENDED, REFUSED); each chunk's pages released once passed. Where and why the
        last step stopped."""
        at, state = start, GO_ON
        while state == GO_ON:
            stopped, state = step(at, (at // _CHUNK + 1) * _CHUNK)
            _release(self.mapped, at, stopped)
            at = stopped
        return at, state


def _others(file: _File, stop: int) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.uint8]] | None:
    """The offsets and types of the chain's messages but data messages (:func:`_walk`) from
    the file's header to ``stop``, walked a chunk at a time, the file's ``end`` set where the
    chain ends; None at a type pyulog does not know."""
    known = np.zeros(256, dtype=np.bool_)
    known[list(KNOWN)] = True
    offsets = np.empty(_FOUND, dtype=np.int64)
    types = np.empty(_FOUND, dtype=np.uint8)
    found = [(offsets[:0], types[:0])]

    def step(at: int, limit: int) -> tuple[int, int]:
        n, stopped, state = _walk(file.data, at, limit, stop, known, offsets, types)
        found.append((offsets[:n].copy(), types[:n].copy()))
        return stopped, state

    at, state = file.walk(FILE_HEADER, step)
    if state == REFUSED:
        return None
    file.end = at
    return np.concatenate([f[0] for f in found]), np.concatenate([f[1] for f in found])


def decode(path: Path, topics: tuple[str, ...], end: int | None = None) -> Decoded | None:
    """pyulog's decoding of ``topics`` in the ULog at ``path`` up to byte ``end`` (None: all
    of it), for an intact file; None where pyulog must read it (see the module doc), or
    where the pyulog installed lacks a class the walk parses with (its parsing classes are
    its own, not its API: a release may rename them)."""
    from pyulog import ULog

    if not all(hasattr(ULog, name) for name in PYULOG_CLASSES):
        return None
    exit_on_sigbus()
    with path.open("rb") as handle:
        size = handle.seek(0, 2)
        if size < FILE_HEADER + HEADER:
            return None
        mapped = mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ)
    file = _File(np.frombuffer(mapped, dtype=np.uint8), mapped)
    chain = _others(file, size if end is None else min(end, size))
    if chain is None:
        return None
    offsets, types = chain
    begins = np.flatnonzero(np.isin(types, list(DATA_SECTION)))
    if not begins.size or not _definitions_only(file.data, offsets[: begins[0] + 1], types):
        return None  # no data to walk, or definitions pyulog must read in the whole file
    first = int(begins[0])
    head = _definitions(bytes(file.data[: offsets[first]]))
    if head is None:
        return None
    result, formats = head
    subscribed = _parse(file.data, offsets[first:], result, formats, topics)
    if subscribed is None:
        return None
    buffers = _data(file, int(offsets[first]), subscribed)
    if buffers is None:
        return None
    for sub, buffer in buffers:
        sub.buffer = buffer
        result.data_list.append(ULog.Data(sub))
    result.data_list.sort(key=lambda d: (d.name, d.multi_id))
    return result


def _definitions_only(
    data: npt.NDArray[np.uint8], offsets: npt.NDArray[np.int64], types: npt.NDArray[np.uint8]
) -> bool:
    """Whether the messages up to the data section's first (the last of ``offsets``) are
    definitions (``types``), one after the other from the file's header: no other message,
    not even a data message, between them."""
    before = offsets[:-1]
    sizes = data[before].astype(np.int64) | data[before + 1].astype(np.int64) << 8
    return bool(
        offsets[0] == FILE_HEADER
        and (before + HEADER + sizes == offsets[1:]).all()
        and np.isin(types[: before.size], list(DEFINITIONS)).all()
    )


def _definitions(head: bytes) -> tuple[Decoded, dict[str, Any]] | None:
    """pyulog's reading of the header and definitions ``head`` (the file's bytes up to its
    data section), and the formats it defines; None where pyulog found damage, printed
    anything or must read appended data."""
    from pyulog import ULog

    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):
            ulog = ULog(io.BytesIO(head), [])
    except Exception:  # whatever pyulog raises, it raises again on the whole file
        return None
    if ulog.file_corruption or printed.getvalue() or ulog.has_data_appended:
        return None
    decoded = Decoded(ulog.start_timestamp, dict(ulog.msg_info_dict), ulog.initial_parameters)
    return decoded, ulog.message_formats


#: How pyulog's loop parses each of the data section's types that are neither data nor a
#: subscription (its class, given the payload and the header): a message that its class
#: cannot parse is damage to pyulog, or where its loop stops.
_PARSE: dict[str, Callable[[Any, bytes, Any], Any]] = {
    "I": lambda ulog, payload, header: ulog._MessageInfo(payload, header),
    "M": lambda ulog, payload, header: ulog._MessageInfo(payload, header, True),
    "P": lambda ulog, payload, header: ulog._MessageInfo(payload, header),
    "Q": lambda ulog, payload, header: ulog._MessageParameterDefault(payload, header),
    "L": lambda ulog, payload, header: ulog.MessageLogging(payload, header),
    "C": lambda ulog, payload, header: ulog.MessageLoggingTagged(payload, header),
    "O": lambda ulog, payload, header: ulog.MessageDropout(payload, header, 0),
    "S": lambda *_: None,  # a sync sequence: pyulog counts it
}


def _parse(
    data: npt.NDArray[np.uint8],
    offsets: npt.NDArray[np.int64],
    decoded: Decoded,
    formats: dict[str, Any],
    topics: tuple[str, ...],
) -> dict[int, tuple[Any, int]] | None:
    """Parse the data section's messages that are not data (at ``offsets``), in order, as
    pyulog's loop does (its info and dropouts into ``decoded``); every subscription by its
    message id, with its offset (None for a topic not in ``topics``); None where pyulog's
    loop would take a message as damage or stop at it, or meets a type it does not know."""
    from pyulog import ULog

    header = ULog._MessageHeader()  # pyulog's own parsing, for its own values
    subscribed: dict[int, tuple[Any, int]] = {}
    for at in offsets.tolist():
        try:
            header.initialize(bytes(data[at : at + HEADER]))
            payload = bytes(data[at + HEADER : at + HEADER + header.msg_size])
            kind = chr(header.msg_type)
            if kind != "A":
                parsed = _PARSE[kind](ULog, payload, header)
                if kind == "I":
                    decoded.msg_info_dict[parsed.key] = parsed.value
                elif kind == "O":
                    decoded.dropouts.append(parsed)
                continue
            sub = ULog._MessageAddLogged(payload, header, formats)
        except Exception:  # pyulog's loop takes it as damage or stops there, or an unknown type
            return None
        if sub.msg_id in subscribed:
            return None  # pyulog keeps the last subscription: the data before it is lost
        kept = sub.message_name in topics
        if kept and not sub.dtype.itemsize:
            return None  # a format of no field (padding alone): each message is damage
        subscribed[sub.msg_id] = (sub if kept else None, at)
    return subscribed


def _data(
    file: _File, start: int, subscribed: dict[int, tuple[Any, int]]
) -> list[tuple[Any, npt.NDArray[np.uint8]]] | None:
    """Each kept subscription that has data, with the payloads of its data messages from
    ``start`` on (its format's bytes after the message id) one after the other; None where
    pyulog's loop would take a data message as damage or stop at it (:func:`_payloads`)."""
    since = np.full(1 << 16, np.iinfo(np.int64).max, dtype=np.int64)
    width = np.zeros(1 << 16, dtype=np.int64)  # a kept topic's data size; 0: not kept
    for msg_id, (sub, at) in subscribed.items():
        since[msg_id] = at
        if sub is not None:
            width[msg_id] = sub.dtype.itemsize

    def walk(cursor: npt.NDArray[np.int64], out: npt.NDArray[np.uint8]) -> bool:
        """One walk along the data messages (:func:`_payloads`) with ``cursor`` and ``out``;
        whether it reached the chain's end."""

        def step(at: int, limit: int) -> tuple[int, int]:
            stopped, intact = _payloads(file.data, at, limit, file.end, since, width, cursor, out)
            return stopped, (GO_ON if stopped < file.end else ENDED) if intact else REFUSED

        return file.walk(start, step)[1] == ENDED

    sizes = np.zeros(1 << 16, dtype=np.int64)  # the bytes of each kept topic's payloads
    if not walk(sizes, np.empty(0, dtype=np.uint8)):
        return None
    first = np.concatenate(([0], np.cumsum(sizes)[:-1]))
    out = np.empty(int(sizes.sum()), dtype=np.uint8)
    walk(first.copy(), out)
    return [
        (sub, out[first[msg_id] : first[msg_id] + sizes[msg_id]])
        for msg_id, (sub, _) in subscribed.items()
        if sub is not None and sizes[msg_id]
    ]
