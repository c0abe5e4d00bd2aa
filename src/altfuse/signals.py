"""Signals as exceptions: SIGTERM and SIGHUP raise :class:`Terminated` as SIGINT raises
KeyboardInterrupt, so that temporary files are removed on the way out
(:func:`altfuse.write.atomic_outputs`); and a watchdog (:func:`watch_signals`) that ends the
process where the exception cannot. The standard library only: the command line imports it
before anything heavy."""

from __future__ import annotations

import contextlib
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from signal import _HANDLER  # typeshed's: what signal.signal takes and returns

#: The exit code after SIGTERM (128 + the signal, as a shell reports it).
EXIT_TERMINATED = 128 + signal.SIGTERM
#: SIGHUP: the terminal closed (an SSH session dropped, a terminal window shut) or ``kill -HUP``.
#: Its default ends the process where it is, leaving the temporary file being written
#: (measured: ``.altfuse-...-f.csv.*.tmp`` beside the output, exit 129). None on Windows.
SIGHUP: int | None = getattr(signal, "SIGHUP", None)
#: The signals that end a run: each handled, so that the run ends cleanly
#: (:func:`raise_on_termination`, :func:`watch_signals`).
ENDING_SIGNALS = frozenset(s for s in (signal.SIGTERM, signal.SIGINT, SIGHUP) if s is not None)


class Terminated(BaseException):
    """SIGTERM or SIGHUP (``signum``), raised where the process is (as SIGINT raises
    KeyboardInterrupt), so that the temporary files of :func:`atomic_outputs` are removed on
    the way out."""

    def __init__(self, signum: int = signal.SIGTERM) -> None:
        super().__init__(signum)
        self.signum = signum


def _terminated(signum: int, _frame: object) -> None:
    raise Terminated(signum)


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


def raise_on_termination(handler: Callable[[int, object], None] = _terminated) -> None:
    """Make SIGTERM and SIGHUP call ``handler`` in this process (its main thread), by default
    raising :class:`Terminated`; SIGHUP not where it is ignored (``nohup``: the run is meant
    to outlive its terminal)."""
    signal.signal(signal.SIGTERM, handler)
    if SIGHUP is not None and signal.getsignal(SIGHUP) is not signal.SIG_IGN:
        signal.signal(SIGHUP, handler)


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """The ending signals' handlers held back meanwhile, around file operations that must
    finish once begun (a temporary file made and recorded for removal, the renames that put a
    run's outputs in place all or none, the removal of the temporaries): a signal that comes
    meanwhile runs its handler after, or not at all where an exception is already on its way
    out (the process is ending: a second signal had cut the removal short, leaving a worker's
    temporary file when a closed terminal's SIGHUP was followed by the SIGTERM its dead
    parent sends). From the main thread, where Python runs handlers; elsewhere nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[int] = []
    before: dict[int, _HANDLER] = {}
    try:  # each handler put back, also where a signal comes while they are swapped
        for signum in ENDING_SIGNALS:
            if callable(signal.getsignal(signum)):  # not where ignored or at its default
                before[signum] = signal.signal(signum, lambda got, _frame: came.append(got))
        yield
    finally:
        for signum, handler in before.items():
            signal.signal(signum, handler)
    if came and sys.exc_info()[1] is None:
        handler = before[came[0]]
        if callable(handler):
            handler(came[0], None)


#: How long [s] an ending signal's exception may take to end the process before the
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
    """Call ``end(signum)`` (which ends the process) ``grace_s`` after one of the
    :data:`ENDING_SIGNALS` arrives, if the process is still there: a thread waits on the
    bytes Python's C-level handler writes for each signal (``signal.set_wakeup_fd``),
    whatever the main thread is doing. From the main thread; in a forked process again (its
    parent's watchdog is not there, and its own signals would wake the parent's)."""
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
        came = [signum for signum in received if signum in ENDING_SIGNALS]
    time.sleep(grace_s)
    end(came[0])
