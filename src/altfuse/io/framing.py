"""DataFlash's record framing, shared by the reader, the writer and the format sniffer.

Every record starts with the two bytes ``SYNC`` and its type id; FMT records (type ``FMT_TYPE``)
declare every type, and a log starts with them (ArduPilot's ``AP_Logger/LogStructure.h``).
"""

SYNC = b"\xa3\x95"
FMT_TYPE = 0x80
#: The FMT record's own declaration: its length, format string and columns.
FMT_LENGTH = 89
FMT_FORMAT = "BBnNZ"
FMT_COLUMNS = "Type,Length,Name,Format,Columns"
#: Bytes before a record's payload: the sync bytes and the type id.
HEADER = len(SYNC) + 1
#: What a DataFlash log's first bytes hold: an FMT record's header.
FMT_HEADER = SYNC + bytes([FMT_TYPE])
#: Each field format character's struct code, scale and Python type: pymavlink's
#: ``DFReader.FORMAT_TO_STRUCT``, the authority, copied (tests/test_parity.py holds them equal):
#: importing it imports pymavlink's mavutil and dialects, 25 ms of a small log's run.
FORMAT_TO_STRUCT: dict[str, tuple[str, float | None, type]] = {
    "a": ("64s", None, str),
    "b": ("b", None, int),
    "B": ("B", None, int),
    "g": ("e", None, float),
    "h": ("h", None, int),
    "H": ("H", None, int),
    "i": ("i", None, int),
    "I": ("I", None, int),
    "f": ("f", None, float),
    "n": ("4s", None, str),
    "N": ("16s", None, str),
    "Z": ("64s", None, str),
    "c": ("h", 0.01, float),
    "C": ("H", 0.01, float),
    "e": ("i", 0.01, float),
    "E": ("I", 0.01, float),
    "L": ("i", 1e-07, float),
    "d": ("d", None, float),
    "M": ("b", None, int),
    "q": ("q", None, int),
    "Q": ("Q", None, int),
}
