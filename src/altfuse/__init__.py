"""altfuse: post-flight altitude fusion for ArduPilot DataFlash logs.

The library is a chain of pure stages, each taking the previous stage's value::

    read_log(path) -> FlightLog -> screen() -> align() -> Aligned -> refer_to_takeoff()
        -> Referred -> FusionInput -> METHODS[name](inputs, params) -> FusionResult
        -> write_outputs()

The public face is what ``__all__`` names::

    import altfuse
    table = altfuse.fuse_file("flight.bin", method="support", alpha_per_m2=0.5)

:func:`fuse_log` runs the chain and builds the provenance record, :func:`fuse_to_files` writes
what ``altfuse fuse`` writes, :func:`evaluate` measures every method against the truth;
:func:`simulate_flight` and :func:`write_simulated_log` make a log with its truth, as
``altfuse simulate`` does.
Names are imported on first use, so that ``import altfuse`` (and the command line's start-up)
does not pay for numpy, scipy and pandas until they are needed.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

#: Each public name and the module that defines it.
_PUBLIC = {
    "read_log": "altfuse.io",
    "fuse_log": "altfuse.pipeline",
    "FuseOptions": "altfuse.pipeline",
    "FuseRun": "altfuse.pipeline",
    "fuse_file": "altfuse.job",
    "fuse_to_files": "altfuse.job",
    "Outputs": "altfuse.job",
    "evaluate": "altfuse.evaluation",
    "METHODS": "altfuse.fuse",
    "Method": "altfuse.fuse",
    "FusionInput": "altfuse.fuse",
    "FusionResult": "altfuse.fuse",
    "FlightLog": "altfuse.model",
    "AltfuseError": "altfuse.errors",
    "simulate_flight": "altfuse.simulate",
    "write_simulated_log": "altfuse.simulate",
}

__all__ = [
    "METHODS",
    "AltfuseError",
    "FlightLog",
    "FuseOptions",
    "FuseRun",
    "FusionInput",
    "FusionResult",
    "Method",
    "Outputs",
    "__version__",
    "evaluate",
    "fuse_file",
    "fuse_log",
    "fuse_to_files",
    "read_log",
    "simulate_flight",
    "write_simulated_log",
]

if TYPE_CHECKING:
    from altfuse.errors import AltfuseError
    from altfuse.evaluation import evaluate
    from altfuse.fuse import METHODS, FusionInput, FusionResult, Method
    from altfuse.io import read_log
    from altfuse.job import Outputs, fuse_file, fuse_to_files
    from altfuse.model import FlightLog
    from altfuse.pipeline import FuseOptions, FuseRun, fuse_log
    from altfuse.simulate import simulate_flight, write_simulated_log


def __getattr__(name: str) -> Any:
    if name in _PUBLIC:
        value = getattr(importlib.import_module(_PUBLIC[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'altfuse' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
