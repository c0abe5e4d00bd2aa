"""Equal-weight mean: Paper A's baseline."""

from __future__ import annotations

import numpy as np

from altfuse.fuse.base import FusionResult, combine
from altfuse.model import FloatArray


def fuse_mean(z: FloatArray) -> FusionResult:
    """Equal weights ``1/n`` over the sensors valid at each tick (Paper A's "average weighting").

    Parameters
    ----------
    z
        Heights [m] of ``n`` sensors on one clock, shape (T, n); NaN where a sensor is absent.
    """
    return combine(z, np.isfinite(z).astype(np.float64), "mean")
