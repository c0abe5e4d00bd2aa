"""altfuse: post-flight altitude fusion for ArduPilot DataFlash logs.

The library is a chain of pure stages, each taking the previous stage's value::

    read_log(path) -> FlightLog -> align() -> Aligned -> refer_to_takeoff() -> Referred
        -> FUSERS[method](...) -> FusionResult -> write_outputs()

:func:`altfuse.pipeline.fuse_log` runs the chain and builds the provenance record.
"""

__version__ = "0.1.0"
