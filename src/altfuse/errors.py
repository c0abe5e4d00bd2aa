"""Errors a user can cause. The CLI prints each as one line and exits non-zero."""


class AltfuseError(Exception):
    """Base of every error caused by the input or the options, never by a bug."""

    exit_code = 1


class LogReadError(AltfuseError):
    """The file cannot be read as a flight log (missing, empty, not a log, cut before any data)."""


class Refusal(AltfuseError):
    """The log is valid but cannot be fused: a refusal, not a failure (a batch's ``refused``).
    What the log is, where it was read before the refusal: its vehicle and firmware."""

    vehicle = ""
    firmware = ""


class NoUsableSensorsError(Refusal):
    """The log holds too few altitude sources for the job."""


class UnsupportedLogError(Refusal):
    """The log is readable but its content is outside what altfuse fuses (e.g. ArduSub depth)."""


class ParameterError(AltfuseError):
    """An option value is outside its meaningful range."""

    exit_code = 2


def out_of_memory(exc: MemoryError) -> str:
    """What a run that ran out of memory says: not a bug (``internal error``, exit 3, as it
    said before), the machine's limit for this log and these options (``altfuse fuse`` of a
    7.4-hour log at ``--rate 100``: 2.65 M ticks, 1.26 GB; ``simulate --duration 1e9``), and
    the options that ask less of it."""
    return (
        f"out of memory ({exc or 'no detail'}); less at once needs less: a lower --rate, fewer "
        "--jobs, a shorter --duration"
    )


def system_refused(exc: OSError) -> str:
    """What a run says where the system refused it a file or folder that altfuse's own checks
    did not foresee (a batch's output folder it may not create, an input folder it may not
    list, a full disk): the path and the system's reason, not a bug (``internal error``, exit
    3, as it said before)."""
    if exc.filename is None:
        return f"the system refused: {exc.strerror or exc}"
    paths = f"{exc.filename}" + (f" -> {exc.filename2}" if exc.filename2 is not None else "")
    return f"{paths}: {exc.strerror or exc}"
