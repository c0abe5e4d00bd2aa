"""Fusion methods. ``FUSERS`` is the only registry: the CLI's ``--method`` choices and the
contract tests both come from it, so a method is added by registering it here.

Every fuser takes the heights of ``n`` sensors on one clock, shape (T, n) with NaN where a sensor
is absent, plus keyword-only parameters, and returns a :class:`FusionResult`. A fuser that needs
more from the log names it as a keyword in ``LOG_INPUTS``; the pipeline supplies it.
"""

from __future__ import annotations

from collections.abc import Callable

from altfuse.fuse.base import FusionResult
from altfuse.fuse.complementary import fuse_multilayer
from altfuse.fuse.delay import fuse_delay1, fuse_delay2
from altfuse.fuse.mean import fuse_mean
from altfuse.fuse.smoother import fuse_smoother
from altfuse.fuse.support import fuse_support

FUSERS: dict[str, Callable[..., FusionResult]] = {
    "mean": fuse_mean,
    "support": fuse_support,
    "delay1": fuse_delay1,
    "delay2": fuse_delay2,
    "multilayer": fuse_multilayer,
    "smoother": fuse_smoother,
}

#: Keyword arguments a fuser may take that come from the log, not from the user: the earth-frame
#: vertical acceleration on the clock [m/s²] (accel_up) or as samples (accel: times, values; None
#: without IMU/ATT), the clock's tick [s] (dt_s) and times (t), and each sensor's own referred
#: samples (samples), kinds and names, the span in which the vehicle stood at the take-off point
#: (on_ground), the horizontal speed samples (speed) and each sensor's temperature samples
#: (temperatures, a list in the sensors' order); None when the log cannot tell.
LOG_INPUTS = frozenset(
    {
        "accel_up", "dt_s", "accel", "t", "samples", "kinds", "names",
        "on_ground", "speed", "temperatures",
    }
)  # fmt: skip

__all__ = ["FUSERS", "LOG_INPUTS", "FusionResult"]
