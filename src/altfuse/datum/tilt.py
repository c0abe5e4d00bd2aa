"""A rangefinder's distance along the body's down axis as a vertical height, with the logged
attitude (:func:`tilt_correct`), and where the tilt is too large for it to measure one."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from altfuse.model import Attitude, FloatArray, Series

#: A rangefinder tilted further than this from the vertical measures no height: PX4's EKF2
#: uses none (``range_cos_max_tilt``, 45 degrees), ArduPilot's Copter corrects for no more.
#: Beyond it a small error of the attitude (10 Hz, interpolated through a roll) is a large one
#: of ``d cos(tilt)``, and the beam meets ground far to the side.
MAX_TILT_DEG = 45.0
MIN_COS_TILT = math.cos(math.radians(MAX_TILT_DEG))
TILTED = f"tilted more than {MAX_TILT_DEG:.0f} degrees"


def tilt_at(series: Series, attitude: Attitude) -> FloatArray:
    """``cos(roll) cos(pitch)`` at each sample of ``series`` that ``attitude`` covers (at least
    two samples of it), NaN at the others."""
    tilt = np.full(series.t.size, np.nan)
    inside = (series.t >= attitude.t[0]) & (series.t <= attitude.t[-1])
    tilt[inside] = attitude.down_at(series.t[inside])[:, 2]
    return tilt


def tilt_correct(series: Series, attitude: Attitude | None) -> Series:
    """Vertical height from a downward rangefinder's distance [m]: ``d cos(roll) cos(pitch)``.

    Only for ``RFND``/``SONR`` distances, and only where the attitude covers the sample and the
    sensor is within ``MAX_TILT_DEG`` of the vertical (the other samples are dropped, counted in
    ``dropped``). Without attitude the series is returned unchanged, and its datum says so.
    """
    if not series.is_raw_rangefinder:
        return series
    if attitude is None or attitude.t.size < 2:
        return replace(series, datum=f"{series.datum} (not tilt-corrected: no attitude)")
    tilt = tilt_at(series, attitude)
    inside = np.isfinite(tilt)
    level = tilt >= MIN_COS_TILT
    dropped = dict(series.dropped)
    if (~inside).any():
        dropped["outside the attitude's time range"] = int((~inside).sum())
    if (inside & ~level).any():
        dropped[TILTED] = int((inside & ~level).sum())
    return replace(
        series,
        datum=f"{series.datum} (tilt-corrected with {attitude.source})",
        t=series.t[level],
        value=series.value[level] * tilt[level],
        dropped=dropped,
    )
