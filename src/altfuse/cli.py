"""The ``altfuse`` command line: the group, its global options, and one line per error.

Every error a user can cause ends as one line on stderr (``altfuse: error: ...``) and a non-zero
exit code: 1 for a log that cannot be processed, 2 for a usage or parameter error, 3 for a bug
(with ``--debug`` showing its traceback).

The commands live in :mod:`altfuse.commands` and are imported when one is run: ``altfuse
--help`` and ``--version`` load click and the standard library only (0.1 s, where numpy,
scipy, pandas and numba made them 0.7-1.8 s).
"""

from __future__ import annotations

import atexit
import contextlib
import importlib
import logging
import os
import signal
import sys
import traceback
import warnings
from typing import Any, NoReturn, cast

import click

from altfuse import __version__
from altfuse.errors import AltfuseError, out_of_memory, system_refused
from altfuse.memory import one_heap
from altfuse.params import InvalidParameter
from altfuse.signals import (
    ENDING,
    SIGHUP,
    Terminated,
    interruption,
    raise_on_termination,
    watch_signals,
)

EXIT_BUG = 3
#: Every command's exit codes, at the end of its help (batch adds its own 4).
EXIT_CODES = (
    "Exit codes: 0 done; 1 the log cannot be processed (missing, damaged beyond reading, too few "
    "altitude sources), an output cannot be written, the system refuses a file or memory runs "
    "out; 2 a usage or parameter error; 3 a bug (--debug shows it); 129 hung up, 130 "
    "interrupted, 143 terminated."
)
#: The group's options, taken after the command too (``altfuse fuse in.bin -o x.csv -v``).
GLOBAL_FLAGS = frozenset({"-v", "-vv", "-vvv", "--verbose", "-q", "--quiet", "--debug"})

#: Each command and the first sentence of its help (shown by ``altfuse --help`` without
#: importing it; tests/test_cli.py checks each against the command's own).
COMMANDS = {
    "fuse": "Fuse the altitude sensors of LOG into one altitude, written as a table (CSV or "
    "Parquet).",
    "evaluate": "Measure every method, every sensor and the onboard EKF against the truth in LOG.",
    "batch": "Fuse every log under PATHS (folders searched recursively) into OUTPUT, in parallel.",
    "info": "Show what LOG holds: vehicle, duration, altitude sources, references.",
    "simulate": "Write a simulated SCENARIO flight as a DataFlash log, with the truth in SIM "
    "records.",
}


class _OneLineFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        return f"altfuse: {record.levelname.lower()}: {record.getMessage()}"


def _fail(message: str, code: int) -> NoReturn:
    click.echo(f"altfuse: error: {message}", err=True)
    sys.exit(code)


def _log_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: object = None,  # noqa: ARG001
    line: str | None = None,  # noqa: ARG001
) -> None:
    """A Python warning (numpy on damaged data, a library's deprecation) is for developers:
    logged at debug level (``-vv`` shows it), never a second line on a user's stderr."""
    logging.getLogger("altfuse").debug(
        "%s: %s (%s:%d)", category.__name__, message, filename, lineno
    )


def _fail_signalled(exc: BaseException | None) -> None:
    """Exit as a signal asks when ``exc`` is one (:func:`_end_signalled`)."""
    if exc is not None:
        _end_signalled(exc.signum if isinstance(exc, Terminated) else signal.SIGINT)


def _end_signalled(signum: int) -> NoReturn:
    """Exit as the signal ``signum`` asks (128 + the signal: SIGINT 130, SIGTERM 143, SIGHUP
    129), at once, saying so on one line: the temporary files are gone (removed on the way
    here, or never made where the watchdog calls this: :func:`altfuse.signals.watch_signals`),
    and the interpreter's shutdown would run the destructors of what the signal cut short
    (llvmlite's, in a compilation: "Exception ignored in ObjectRef.__del__", a second stderr
    line)."""
    ENDING.acquire()  # the handler's way out or the watchdog: one of them says it
    said = {signal.SIGINT: "interrupted", SIGHUP: "hung up"}.get(signum, "terminated")
    try:  # a stderr whose reader is gone raises; the other way out waits on ENDING for ever
        click.echo(f"altfuse: error: {said}", err=True)
    finally:
        _exit(128 + signum)


def _exit(code: int) -> NoReturn:
    """End the process with ``code`` now (``os._exit``), its standard streams flushed."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):  # a closed pipe: nothing left to say
            stream.flush()
    os._exit(code)


class _EndOfInput(Exception):
    """An EOFError out of a command (a library's, reading a damaged file): altfuse asks the
    user nothing, so it is no Ctrl+D at a prompt, as click takes it ("interrupted", exit 130;
    a damaged numba cache ended every run so)."""


class _Cli(click.Group):
    """A group whose errors are one line each, whatever raised them, and whose commands are
    imported only when one is run."""

    def list_commands(self, ctx: click.Context) -> list[str]:  # noqa: ARG002 (click's)
        return list(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:  # noqa: ARG002
        if cmd_name not in COMMANDS:
            return None
        command: click.Command = getattr(importlib.import_module("altfuse.commands"), cmd_name)
        if not command.epilog or EXIT_CODES not in command.epilog:
            command.epilog = EXIT_CODES + (f" {command.epilog}" if command.epilog else "")
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:  # noqa: ARG002
        with formatter.section("Commands"):
            formatter.write_dl(list(COMMANDS.items()))

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except EOFError as exc:  # click would take it for a prompt's Ctrl+D: "interrupted"
            raise _EndOfInput from exc

    def main(self, *args: Any, **kwargs: Any) -> Any:
        kwargs["standalone_mode"] = False
        given = kwargs.pop("args", args[0] if args else None)
        argv = _global_flags_first(list(sys.argv[1:] if given is None else given))
        debug = "--debug" in argv
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("always")  # each to the debug log
                warnings.showwarning = _log_warning
                code = super().main(argv, *args[1:], **kwargs)
        except click.exceptions.NoArgsIsHelpError as exc:  # bare altfuse: the help, as --help
            click.echo(exc.ctx.get_help() if exc.ctx else exc.format_message())
            code = 0
        except _EndOfInput as exc:
            _fail_for(cast(EOFError, exc.__cause__), debug)
        except (click.exceptions.Abort, KeyboardInterrupt, Terminated) as exc:
            _fail_signalled(exc)
        except click.ClickException as exc:
            _fail(exc.format_message().replace("\n", " "), exc.exit_code)
        except Exception as exc:
            _fail_for(exc, debug)
        sys.exit(code if isinstance(code, int) else 0)


def _fail_for(exc: Exception, debug: bool) -> NoReturn:
    """End the run that ``exc`` ended, in one line: what altfuse found wrong (the library
    names a parameter, the command line its flag), memory or a file the system refused (not
    bugs), a signal's exit, or an internal error (a bug: exit 3, its traceback with
    ``--debug``)."""
    if isinstance(exc, InvalidParameter):
        from altfuse.commands import flag_for

        _fail(f"{flag_for(exc.name)} {exc.problem}", exc.exit_code)
    if isinstance(exc, AltfuseError):
        _fail(str(exc), exc.exit_code)
    if isinstance(exc, MemoryError):
        _fail(out_of_memory(exc), 1)
    _fail_signalled(interruption(exc))
    if debug:
        traceback.print_exc()
    if isinstance(exc, OSError):
        _fail(system_refused(exc), 1)
    _fail(f"internal error: {type(exc).__name__}: {exc} (rerun with --debug)", EXIT_BUG)


def _global_flags_first(argv: list[str]) -> list[str]:
    """``argv`` with the group's flags found after the command (before any ``--``) moved in
    front of it, where click takes them."""
    command = next((i for i, a in enumerate(argv) if a in COMMANDS), None)
    if command is None:
        return argv
    rest = argv[command:]
    end = rest.index("--") if "--" in rest else len(rest)
    moved = [a for a in rest[:end] if a in GLOBAL_FLAGS]
    kept = [a for a in rest[:end] if a not in GLOBAL_FLAGS]
    return argv[:command] + moved + kept + rest[end:]


@click.group(cls=_Cli, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="altfuse")
@click.option("-v", "--verbose", count=True, help="More detail on stderr (-v info, -vv debug).")
@click.option("-q", "--quiet", is_flag=True, help="Only errors on stderr.")
@click.option("--debug", is_flag=True, help="Show the traceback of an internal error.")
def cli(verbose: int, quiet: bool, debug: bool) -> None:  # noqa: ARG001 (read in main)
    """Fuse the altitude sensors of ArduPilot DataFlash logs and PX4 ULogs after the flight.

    \b
    Example:
      altfuse fuse flight.bin -o flight.csv
      altfuse batch logs/ -o results/
      altfuse info flight.bin
    """
    level = logging.ERROR if quiet else [logging.WARNING, logging.INFO][min(verbose, 1)]
    if verbose >= 2:
        level = logging.DEBUG
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_OneLineFormatter())
    root = logging.getLogger("altfuse")
    root.handlers[:] = [handler]
    root.setLevel(level)
    root.propagate = False


#: The thread pools of numpy's BLAS (OpenBLAS, MKL) and of OpenMP, each held to one thread in
#: altfuse's processes unless the user set otherwise. altfuse computes on long vectors and small
#: matrices, where a pool's threads only spin between calls: a fuse of a 30 MB log took 3.1 s
#: (3.4 s of CPU) with OpenBLAS's threads and 2.8 s (2.8 s) without, and a batch of 8 such
#: logs took as long at two jobs as at one on 2 cores (1.6x faster without). A batch's
#: parallelism is its processes.
THREAD_POOLS = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")


#: The exit code of a run of the console command (:func:`main`), for :func:`_exit_now`; empty
#: in a run that is not one (the tests' ``CliRunner``, a library caller).
_EXIT_CODE: list[int] = []


def _exit_now() -> None:
    """Registered by :func:`main` before anything else it runs, so the last exit handler: end
    the process with the command's exit code once every other handler has run (the thread
    pools joined, a batch's workers stopped, dask's client closed), without the interpreter
    tearing its modules down object by object, which takes 0.12-0.2 s on numba's, numpy's and
    pyarrow's (of 0.7-0.9 s for ``altfuse fuse`` on the sample log). The outputs are in place
    by then: written to temporary files, renamed. As a signal's exit does
    (:func:`_end_signalled`)."""
    if not _EXIT_CODE:
        return
    logging.shutdown()  # registered before this handler, so run after it: not at all
    _exit(_EXIT_CODE[0])


def main() -> None:
    one_heap()  # before any thread allocates
    atexit.register(_exit_now)
    for name in THREAD_POOLS:  # before numpy is loaded: it sizes its pool then
        os.environ.setdefault(name, "1")
    raise_on_termination()
    watch_signals(_end_signalled)
    try:
        cli()
    except SystemExit as exc:
        _EXIT_CODE.append(exc.code if isinstance(exc.code, int) else int(exc.code is not None))
        raise
