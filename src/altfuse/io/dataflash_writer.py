"""A small DataFlash writer: FMT, UNIT, MULT and FMTU records, then data records.

The record layout is ArduPilot's (``AP_Logger/LogStructure.h``): every record starts with the
bytes 0xA3 0x95 and its type id; FMT (type 128) declares each type's length, name, format string
and column names; UNIT and MULT define unit and multiplier ids; FMTU gives each type's units and
multipliers. pymavlink's format-character table is the authority on the binary layout, so what this
writes is what pymavlink reads.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, BinaryIO

from altfuse.io.framing import FMT_COLUMNS, FMT_FORMAT, FMT_TYPE, FORMAT_TO_STRUCT, HEADER, SYNC

#: Unit and multiplier ids as ArduPilot defines them (a subset).
UNITS = {
    "-": "",
    "s": "s",
    "m": "m",
    "n": "m/s",
    "o": "m/s/s",
    "d": "deg",
    "h": "degheading",
    "D": "deglatitude",
    "U": "deglongitude",
    "P": "Pa",
    "O": "degC",
    "#": "instance",
    "E": "rad/s",
    "S": "satellites",
}
MULTIPLIERS = {"-": 0.0, "?": 1.0, "0": 1.0, "B": 1e-2, "C": 1e-3, "F": 1e-6, "G": 1e-7}


@dataclass(frozen=True)
class RecordType:
    """A declared record type: its name, id and format, and how its fields, numbers in their
    units or their text, become its binary record (scaled fields divided by their scale and
    rounded, text encoded; pymavlink's layout). A format character pymavlink does not know:
    KeyError."""

    name: str
    type_id: int
    format: str
    packer: struct.Struct = field(init=False, repr=False)
    converters: tuple[Callable[[Any], object], ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        packer = struct.Struct("<" + "".join(FORMAT_TO_STRUCT[c][0] for c in self.format))
        object.__setattr__(self, "packer", packer)
        object.__setattr__(self, "converters", tuple(_converter(c) for c in self.format))

    @property
    def length(self) -> int:
        """A record's length, its header included: what its FMT record declares."""
        return HEADER + self.packer.size

    def record(self, values: Sequence[object]) -> bytes:
        """The record of ``values``, one per field."""
        fields = [f(v) for f, v in zip(self.converters, values, strict=True)]
        return SYNC + bytes([self.type_id]) + self.packer.pack(*fields)


def _converter(char: str) -> Callable[[Any], object]:
    _, scale, kind = FORMAT_TO_STRUCT[char]
    if kind is str:
        return lambda v: str(v).encode("utf-8")
    if scale is not None:
        return lambda v: round(float(v) / scale)
    return float if kind is float else _integer


def _integer(value: Any) -> int:
    """An integer field's value; a text's may be written as a float with nothing after its
    point ("3.0")."""
    try:
        return int(value)
    except ValueError:
        number = float(value)
        if not number.is_integer():
            raise
        return int(number)


class DataFlashWriter:
    """Write a DataFlash log to a binary stream.

    >>> import io
    >>> w = DataFlashWriter(io.BytesIO())
    >>> w.define("BARO", "QBf", "TimeUS,I,Alt", units="s#m", mults="F-0")
    >>> w.write("BARO", 1_000_000, 0, 12.5)
    """

    def __init__(self, stream: BinaryIO) -> None:
        self.stream = stream
        self.records = 0
        self._types: dict[str, RecordType] = {}
        self._next_type = 129
        self._declare("FMT", FMT_TYPE, FMT_FORMAT, FMT_COLUMNS)
        self.define("UNIT", "QbZ", "TimeUS,Id,Label")
        self.define("MULT", "Qbd", "TimeUS,Id,Mult")
        self.define("FMTU", "QBNN", "TimeUS,FmtType,UnitIds,MultIds")
        for uid, label in UNITS.items():
            self.write("UNIT", 0, ord(uid), label)
        for mid, mult in MULTIPLIERS.items():
            self.write("MULT", 0, ord(mid), mult)

    def _declare(self, name: str, type_id: int, fmt: str, columns: str) -> None:
        declared = self._types[name] = RecordType(name, type_id, fmt)
        self.write("FMT", type_id, declared.length, name, fmt, columns)

    def define(
        self, name: str, fmt: str, columns: str, units: str | None = None, mults: str | None = None
    ) -> None:
        """Declare a record type (FMT), with its units and multipliers (FMTU) when given."""
        if len(columns.split(",")) != len(fmt):
            raise ValueError(f"{name}: {len(fmt)} format characters for columns {columns}")
        type_id = self._next_type
        self._next_type += 1
        self._declare(name, type_id, fmt, columns)
        if units is not None and mults is not None:
            self.write("FMTU", 0, type_id, units, mults)

    def write(self, name: str, *values: object) -> None:
        """Write one record of type ``name``; scaled fields take their value in the real unit."""
        self.stream.write(self._types[name].record(values))
        self.records += 1
