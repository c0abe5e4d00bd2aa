"""Earth-frame vertical acceleration from the log's IMU and attitude (ALGORITHMS.md 3.5).

Paper B subtracts the at-rest reading from the Z axis of an MPU6050. A Pixhawk log gives more:
the specific force ``f`` in the body frame (FRD, IMU.AccX/Y/Z) and the attitude (ATT), so::

    a_up = -(R_body_to_ned @ f)_z - g

with ``R`` from ZYX Euler angles; only its last row matters,
``(-sin(pitch), sin(roll) cos(pitch), cos(roll) cos(pitch))``. Level and at rest
``f = (0, 0, -g)`` and ``a_up = 0``. The IMU is logged faster than the fusion clock; its samples are
averaged into each tick's cell (a box filter that also blunts single-sample spikes).
"""

from __future__ import annotations

import numpy as np

from altfuse.align import cell_means
from altfuse.model import Attitude, FloatArray, Imu

G = 9.80665  # standard gravity [m/s²]


def vertical_acceleration(imu: Imu, attitude: Attitude) -> tuple[FloatArray, FloatArray]:
    """``a_up`` [m/s²] at the IMU's sample times within the attitude's time range."""
    inside = (imu.t >= attitude.t[0]) & (imu.t <= attitude.t[-1])
    t = imu.t[inside]
    f = imu.acc[inside]
    roll = np.interp(t, attitude.t, attitude.roll)
    pitch = np.interp(t, attitude.t, attitude.pitch)
    f_down = -np.sin(pitch) * f[:, 0] + np.sin(roll) * np.cos(pitch) * f[:, 1]
    f_down += np.cos(roll) * np.cos(pitch) * f[:, 2]
    return t, -f_down - G


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
