"""Signals as exceptions: SIGTERM raises :class:`Terminated` as SIGINT raises KeyboardInterrupt,
so that temporary files are removed on the way out (:func:`altfuse.write.atomic_outputs`); and a
watchdog (:func:`watch_signals`) that ends the process where the exception cannot. The standard
library only: the command line imports it before anything heavy."""

from __future__ import annotations

import signal
import socket
import threading
import time
from collections.abc import Callable

#: The exit code after SIGTERM (128 + the signal, as a shell reports it).
EXIT_TERMINATED = 128 + signal.SIGTERM


class Terminated(BaseException):
    """SIGTERM, raised where the process is (as SIGINT raises KeyboardInterrupt), so that the
    temporary files of :func:`atomic_outputs` are removed on the way out."""


def _terminated(_signum: int, _frame: object) -> None:
    raise Terminated


def interruption(exc: BaseException) -> BaseException | None:
    """The KeyboardInterrupt or :class:`Terminated` that ``exc`` is or hides: a signal that
    arrives inside a numba-compiled loop surfaces, when the loop returns, as a SystemError
    caused by the handler's exception."""
    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, KeyboardInterrupt | Terminated):
            return seen
        seen = seen.__cause__ if isinstance(seen, SystemError) else None
    return None


def raise_on_sigterm() -> None:
    """Make SIGTERM raise :class:`Terminated` in this process (its main thread)."""
    signal.signal(signal.SIGTERM, _terminated)


#: How long [s] a SIGTERM's or SIGINT's exception may take to end the process before the
#: watchdog ends it (:func:`watch_signals`). Python runs a signal's handler in the main thread,
#: between two of its bytecodes: a first run's compilation (numba's, in LLVM's C++ for seconds
#: at a time) held a first ``altfuse fuse`` 18-25 s after SIGTERM or SIGINT, and a batch's
#: worker that lost its parent went on for as long. No temporary file is open there: the
#: outputs are written after the compiled loops have run, in chunks between which the handler
#: runs.
GRACE_S = 2.0
#: Held by whatever ends the process after a signal, never released (the process is ending):
#: the handler's way out and the watchdog say so once between them.
ENDING = threading.Lock()


def watch_signals(end: Callable[[int], object], grace_s: float = GRACE_S) -> None:
    """Call ``end(signum)`` (which ends the process) ``grace_s`` after a SIGTERM or SIGINT
    arrives, if the process is still there: a thread waits on the bytes Python's C-level
    handler writes for each signal (``signal.set_wakeup_fd``), whatever the main thread is
    doing. From the main thread; in a forked process again (its parent's watchdog is not
    there, and its own signals would wake the parent's)."""
    reader, writer = socket.socketpair()
    writer.setblocking(False)
    signal.set_wakeup_fd(writer.fileno(), warn_on_full_buffer=False)
    threading.Thread(
        target=_watch, args=(reader, writer, end, grace_s), name="altfuse-signals", daemon=True
    ).start()


def _watch(
    reader: socket.socket, _writer: socket.socket, end: Callable[[int], object], grace_s: float
) -> None:
    """:func:`watch_signals`'s thread (``_writer``, held here, stays open while it waits)."""
    came: list[int] = []
    while not came:
        received = reader.recv(64)
        if not received:  # closed: nothing to watch
            return
        came = [signum for signum in received if signum in (signal.SIGTERM, signal.SIGINT)]
    time.sleep(grace_s)
    end(came[0])
