"""Equal-weight mean: Paper A's baseline."""

from __future__ import annotations

import numpy as np

from altfuse.fuse.base import FusionInput, FusionResult, combine
from altfuse.params import Params


def fuse_mean(inputs: FusionInput, _params: Params) -> FusionResult:
    """Equal weights ``1/n`` over the sensors valid at each tick (Paper A's "average
    weighting") of ``inputs.z`` [m]; no parameters."""
    z = inputs.z
    return combine(z, np.isfinite(z).astype(np.float64), "mean")
