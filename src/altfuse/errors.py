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
