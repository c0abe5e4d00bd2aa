"""Fusion methods. ``FUSERS`` is the only registry: the CLI's ``--method`` choices and the
contract tests both come from it, so a method is added by registering it here.

Every fuser takes the heights of ``n`` sensors on one clock, shape (T, n) with NaN where a sensor
is absent, plus keyword-only parameters, and returns a :class:`FusionResult`.
"""

from __future__ import annotations

from collections.abc import Callable

from altfuse.fuse.base import FusionResult
from altfuse.fuse.mean import fuse_mean
from altfuse.fuse.support import fuse_support

FUSERS: dict[str, Callable[..., FusionResult]] = {
    "mean": fuse_mean,
    "support": fuse_support,
}

__all__ = ["FUSERS", "FusionResult"]
