"""Signals as exceptions: SIGTERM raises :class:`Terminated` as SIGINT raises KeyboardInterrupt,
so that temporary files are removed on the way out (:func:`altfuse.write.atomic_outputs`). The
standard library only: the command line imports it before anything heavy."""

from __future__ import annotations

import signal

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
