"""Earth-frame vertical acceleration from the log's IMU and attitude (ALGORITHMS.md 3.5).

Paper B subtracts the at-rest reading from the Z axis of an MPU6050. A Pixhawk log gives more:
the specific force ``f`` in the body frame (FRD, IMU.AccX/Y/Z) and the attitude (ATT), so::

    a_up = -(R_body_to_ned @ f)_z - g

with ``R`` from ZYX Euler angles or the logged quaternion; only its last row matters
(:meth:`~altfuse.model.Attitude.down_at`), from Euler angles
``(-sin(pitch), sin(roll) cos(pitch), cos(roll) cos(pitch))``. Level and at rest
``f = (0, 0, -g)`` and ``a_up = 0``. The IMU is logged faster than the fusion clock; its samples are
averaged into each tick's cell (a box filter that also blunts single-sample spikes).

Paper B subtracts the at-rest reading; here it is the median of ``a_up`` over the datum's ground
window (the vehicle still, on the ground or in a steady hover). The median, because that window
can end in the first second of a gentle take-off.

How far to trust the accelerometer, as the autopilot logged it (VIBE), goes into the record
beside it (:func:`vibration_record`): ArduPilot's guidance ("Measuring Vibration") takes
vibration levels below ``VIBE_ACCEPTABLE_M_S2`` as normally acceptable and above
``VIBE_PROBLEM_M_S2`` as nearly always a problem for altitude hold, and clipping (a sample at
the sensor's 16 g) as acceptable in small numbers at a hard landing, a serious problem where it
keeps rising.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from altfuse.align import cell_means
from altfuse.metrics import cumulative_integral
from altfuse.model import Attitude, FloatArray, Imu, Samples, Series, Vibration, brief_repr

G = 9.80665  # standard gravity [m/s²]
#: ArduPilot's bounds on the logged vibration levels [m/s²] (VIBE.VibeX/Y/Z, the standard
#: deviation of the accelerometer's output): below the first normally acceptable, above the
#: second nearly always a problem for position and altitude hold.
VIBE_ACCEPTABLE_M_S2 = 30.0
VIBE_PROBLEM_M_S2 = 60.0
#: The instants of clipping the record lists (the first of them).
CLIPPED_LISTED = 10


@dataclass(frozen=True)
class VerticalAcceleration:
    """Earth-frame vertical acceleration [m/s², up, gravity removed], less its at-rest reading.

    Attributes
    ----------
    samples
        At the IMU's sample times within the attitude's time range.
    on_clock
        Averaged into the cells of the fusion clock's ticks; NaN for a tick with no IMU sample.
    record
        Where it came from and the at-rest reading removed, for the provenance.
    """

    __repr__ = brief_repr

    samples: Samples
    on_clock: FloatArray
    record: dict[str, Any]

    def on(self, clock: FloatArray, rate_hz: float) -> VerticalAcceleration:
        """The same samples, at-rest reading and record, averaged into another clock's cells
        (``k / rate_hz``)."""
        a_clock = on_clock(*self.samples, clock, rate_hz)
        missing = int((~np.isfinite(a_clock)).sum())
        return VerticalAcceleration(
            self.samples, a_clock, {**self.record, "ticks_without_imu": missing}
        )


def referred_vertical_acceleration(
    imu: Imu, attitude: Attitude, clock: FloatArray, rate_hz: float, still_s: tuple[float, float]
) -> VerticalAcceleration:
    """:func:`vertical_acceleration` less its at-rest reading: the median over the ticks of
    ``clock`` in ``still_s`` (the datum's ground window), 0 where none has a sample."""
    t, a = vertical_acceleration(imu, attitude)
    a_clock = on_clock(t, a, clock, rate_hz)
    lo, hi = still_s
    still = (clock >= lo) & (clock <= hi) & np.isfinite(a_clock)
    bias = float(np.median(a_clock[still])) if still.any() else 0.0
    record = {
        "source": f"{imu.source} rotated by {attitude.source}",
        "at_rest_bias_m_s2": bias,
        "bias_window_s": [lo, hi],
        "ticks_without_imu": int((~np.isfinite(a_clock)).sum()),
    }
    return VerticalAcceleration(Samples(t, a - bias), a_clock - bias, record)


def vertical_acceleration(imu: Imu, attitude: Attitude) -> tuple[FloatArray, FloatArray]:
    """``a_up`` [m/s²] at the IMU's sample times within the attitude's time range."""
    inside = (imu.t >= attitude.t[0]) & (imu.t <= attitude.t[-1])
    t = imu.t[inside]
    f = imu.acc[inside]
    f_down = np.einsum("ij,ij->i", attitude.down_at(t), f)
    return t, -f_down - G


def velocity_integral(imu: Imu, attitude: Attitude) -> Series | None:
    """The vertical acceleration integrated over time (trapezoids): the vertical velocity [m/s]
    less its unknown initial value, with the accelerometer's bias as a slow ramp. Its changes
    over a second are the velocity's (:func:`altfuse.align.inertial_lag` matches a GPS's
    vertical velocity to them). None with fewer than two samples."""
    t, a = vertical_acceleration(imu, attitude)
    keep = np.isfinite(a)
    t, a = t[keep], a[keep]
    if t.size < 2:
        return None
    order = np.argsort(t, kind="stable")
    t, a = t[order], a[order]
    integral = cumulative_integral(t, a)
    source = f"{imu.source} rotated by {attitude.source}, integrated"
    return Series("accelerometer", "reference", source, "velocity up to a constant", t, integral)


def on_clock(t: FloatArray, a: FloatArray, grid: FloatArray, rate_hz: float) -> FloatArray:
    """Average samples into the cells of the clock's ticks; NaN for a tick with no sample.

    ``grid`` is the uniform clock ``k / rate_hz`` of :func:`altfuse.align.make_grid`.
    """
    order = np.argsort(t, kind="stable")
    tc, ac = cell_means(t[order], a[order], rate_hz)
    out = np.full(grid.shape, np.nan)
    tick = np.floor(tc * rate_hz + 0.5).astype(np.int64)
    first = int(np.floor(grid[0] * rate_hz + 0.5))
    idx = tick - first
    keep = (idx >= 0) & (idx < grid.size)
    out[idx[keep]] = ac[keep]
    return out


def vibration_record(vibration: Vibration) -> dict[str, Any]:
    """The accelerometer's health over the log for the provenance: its largest vibration level
    [m/s²] (of the three axes), how long [s] it stood above VIBE_ACCEPTABLE_M_S2 and above
    VIBE_PROBLEM_M_S2 (each sample counting until the next, at most twice the median interval:
    a pause of the log is no time above; the last, the median interval),
    how many of its samples clipped (the rise of the cumulative count, which a reboot resets:
    only the rises count) and when (the first CLIPPED_LISTED samples at which the count rose).
    ``vibration`` as screened: one sample at least (:func:`altfuse.screen.screen`)."""
    t, level = vibration.t, np.max(vibration.level, axis=1)
    step = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    held = np.minimum(np.diff(t, append=t[-1] + step), 2.0 * step)
    rises = np.diff(vibration.clips, prepend=vibration.clips[0])
    clipped = t[rises > 0]
    return {
        "source": vibration.source,
        "max_level_m_s2": float(level.max()),
        "above_acceptable_s": float(held[level > VIBE_ACCEPTABLE_M_S2].sum()),
        "above_problem_s": float(held[level > VIBE_PROBLEM_M_S2].sum()),
        "clipped_samples": int(rises[rises > 0].sum()),
        "clipped_at_s": [round(float(x), 3) for x in clipped[:CLIPPED_LISTED]],
    }
