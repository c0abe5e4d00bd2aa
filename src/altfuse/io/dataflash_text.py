"""DataFlash logs written as text (``.log``: Mission Planner's "convert to text", APM Planner's
downloads), read as the binary logs they were written from.

A text log has one line per record: the type's name, then its fields separated by ", "
(``GPS, 105431690, 3, ... , 584.27``), each type declared first by an FMT line as in the binary
layout (``FMT, 130, 45, GPS, QBIHBcLLeffffB, TimeUS,Status,...``). pymavlink's
``DFReader_text`` is the authority: the same delimiter, scaled fields (``c``, ``e``, ``L``, ...)
written in their units, a line whose type is undeclared or whose fields are too few left out.
:class:`BinaryFromText` packs each line into its binary record as
:class:`~altfuse.io.dataflash_writer.DataFlashWriter` does (one
:class:`~altfuse.io.dataflash_writer.RecordType`), so that one reader
(:mod:`altfuse.io.dataflash`) reads both forms, with the same checks and the same damage
accounting; a line that does not pack (a field that is no number, a value out of its field's
range, a partial last line) is left out and counted. A flight mode (format ``M``) written by
its name, as Mission Planner's "convert to text" and Copter 3.0-3.1's own text dumps write it
("Stabilize"), is no damage: its number, which the name alone does not give (each vehicle
numbers its modes), is packed as :data:`NAMED_MODE` (altfuse reads no ``MODE`` record).
"""

from __future__ import annotations

import io
import re
import struct
from typing import IO

from altfuse.io.dataflash_writer import RecordType
from altfuse.io.framing import FMT_COLUMNS, FMT_FORMAT, FMT_TYPE

#: The fields' delimiter: ", ", or "," where the first FMT line has no space (pymavlink's).
DELIMITER = ", "
#: The number packed for a flight mode written by its name: no mode's (they count from 0).
NAMED_MODE = "-1"
#: A text log's first bytes hold an FMT line (pymavlink looks for "FMT," in the first 8,000).
_FMT_LINE = re.compile(rb"(?:^|\n)FMT, ?\d+, ?\d+, ?")


def is_text_log(head: bytes) -> bool:
    """Whether ``head``, a file's first bytes, begins a DataFlash text log."""
    return b"\0" not in head and _FMT_LINE.search(head) is not None


class BinaryFromText(io.RawIOBase):
    """The binary DataFlash log whose records ``text`` (a text log's bytes) holds, line by
    line, as a stream; what was converted and left out counted as it goes (:meth:`note`)."""

    def __init__(self, text: IO[bytes]) -> None:
        self.text = text
        self.types = {"FMT": RecordType("FMT", FMT_TYPE, FMT_FORMAT)}
        self.delimiter: str | None = None  # from the first FMT line
        self.line = self.records = self.left_out = 0
        self.first_left_out = ""
        self._pending = b""

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: bytearray | memoryview) -> int:  # type: ignore[override]
        parts, size = [self._pending], len(self._pending)
        while size < len(buffer):
            line = self.text.readline()
            if not line:
                break
            self.line += 1
            parts.append(self._record(line))
            size += len(parts[-1])
        self._pending = b"".join(parts)
        n = min(len(buffer), size)
        buffer[:n] = self._pending[:n]
        self._pending = self._pending[n:]
        return n

    def note(self) -> str:
        """What the conversion met, for the log's notes."""
        said = f"{self.records} of its {self.line} lines converted to binary records"
        if self.left_out:
            said += f", {self.left_out} left out (the first: {self.first_left_out})"
        return said

    def _record(self, line: bytes) -> bytes:
        """The binary record of one text line (empty where it holds none)."""
        text = line.rstrip(b"\r\n").decode("utf-8", "replace")
        if self.delimiter is None:  # as pymavlink: the log starts at its first FMT line
            if not text.startswith("FMT,"):
                return b""  # a banner before it
            self.delimiter = DELIMITER if text.startswith("FMT, ") else ","
        delimiter = self.delimiter
        name, found, rest = text.partition(delimiter)
        if not found:  # a blank line, a line of free text: no record
            return b""
        kind = self.types.get(name.strip())
        if kind is None:
            return self._leave_out(f"{name.strip()!r} is not declared by an FMT line")
        width = len(kind.format)
        # a last field of text (FMT's columns, MSG's message) may hold the delimiter
        last_is_text = kind.format.endswith(("n", "N", "Z"))
        values = [v.strip() for v in rest.split(delimiter, width - 1 if last_is_text else -1)]
        if len(values) == width - 1 and values[-1].endswith(","):
            values = [*values[:-1], values[-1][:-1], ""]  # an empty last field, its space cut
        if values[:3] == ["128", "89", "FMT"] and values[4:] in ([], ["Type,Length,Name,Format"]):
            values = [*values[:4], FMT_COLUMNS]  # APM Planner leaves out FMT's own "Columns"
        if len(values) != width:
            return self._leave_out(f"{len(values)} fields where {kind.name} has {width}")
        if "M" in kind.format:
            values = [
                NAMED_MODE if char == "M" and v.isidentifier() else v
                for char, v in zip(kind.format, values, strict=True)
            ]
        try:
            record = self._declare(values) if kind.name == "FMT" else kind.record(values)
        except (ValueError, struct.error, OverflowError, KeyError) as exc:
            return self._leave_out(f"{kind.name}: {exc}")
        self.records += 1
        return record

    def _declare(self, values: list[str]) -> bytes:
        """The FMT record of an FMT line, its type declared for the lines after (its length
        the one its format packs to: the binary reader checks the two agree)."""
        type_id, _length, name, fmt, columns = values
        declared = RecordType(name, int(type_id), fmt)
        if not 0 <= declared.type_id <= 255:
            raise ValueError(f"type id {type_id} is not a byte")
        self.types[name] = declared
        return self.types["FMT"].record([type_id, str(declared.length), name, fmt, columns])

    def _leave_out(self, why: str) -> bytes:
        self.left_out += 1
        if not self.first_left_out:
            self.first_left_out = f"line {self.line}: {why}"
        return b""
