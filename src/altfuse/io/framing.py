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
