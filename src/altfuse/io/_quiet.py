"""Keep pymavlink's own prints off the terminal.

pymavlink reports damaged bytes with ``print()`` to Python's streams and, from its compiled
indexer, with C ``printf`` straight to file descriptors 1 and 2, below ``sys.stdout``. A CLI that
promises one clean line per problem has to catch both; the text is handed to ``logging`` at
DEBUG level so that ``-v -v`` still shows it.

File descriptors belong to the process: two threads redirecting them at once would each restore
the other's sink. A process-wide lock serialises the captured blocks (reading a log is a small part
of a run; threads are how a Dask worker runs tasks).
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import logging
import os
import sys
import tempfile
import threading
from collections.abc import Iterator

log = logging.getLogger(__name__)
_FD_LOCK = threading.Lock()


def _flush_c_stdio() -> None:
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).fflush(None)


@contextlib.contextmanager
def captured_output() -> Iterator[list[str]]:
    """Capture everything written to stdout/stderr, at Python and at file-descriptor level.

    Yields a list that holds the captured lines once the block has left.
    """
    with _FD_LOCK, _captured() as lines:
        yield lines


@contextlib.contextmanager
def _captured() -> Iterator[list[str]]:
    lines: list[str] = []
    py_buffer = io.StringIO()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    _flush_c_stdio()
    saved = [os.dup(1), os.dup(2)]
    with tempfile.TemporaryFile(mode="w+b") as sink:
        os.dup2(sink.fileno(), 1)
        os.dup2(sink.fileno(), 2)
        try:
            with contextlib.redirect_stdout(py_buffer), contextlib.redirect_stderr(py_buffer):
                yield lines
        finally:
            _flush_c_stdio()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            sink.seek(0)
            native = sink.read().decode("utf-8", errors="replace")
            lines.extend(line for line in (native + py_buffer.getvalue()).splitlines() if line)
            for line in lines[:50]:
                log.debug("pymavlink: %s", line)
            if len(lines) > 50:
                log.debug("pymavlink: ... %d more lines", len(lines) - 50)
