"""The GPS's vertical velocity as a measurement of ``v``, checked sample by sample against the
slope of the same receiver's heights.

A receiver's vertical velocity (from the carrier's Doppler) is an observation of ``v`` the
heights give only as a slope over seconds: it tells the accelerometer's error apart from a
sensor's within one sample interval (ArduPilot's EKF3 fuses it, ``EK3_SRC1_VELZ``, with the
GPS's delay).

Its timing matters as its precision does: the pipeline moves it by the lag of the receiver's
heights behind the barometer, which a steady climb leaves loose (0.52 s found on a simulated
hover whose GPS trails by 0.2 s: 0.03 m/s of error in the climb's accelerations, a metre of
height). What remains is a state (:func:`lag_regressor`): ``z = v(t - tau) = v - tau a``.

It is only as good as its receiver: a simulator's plane log reads +25.7 m/s in a 7 m/s climb
(7.4 m/s from its heights' slope at the median). So each sample is kept where it agrees with
the slope of the receiver's own heights (:func:`altfuse.fuse.smoother.noise.slope` over
``CHECK_SLOPE_S``) within ``CHECK_SIGMAS`` of that slope's error plus ``CHECK_FLOOR_M_S``; a
receiver whose velocity fails that on more than ``MAX_REFUSED_SHARE`` of its samples where
either says it climbs or sinks faster than that floor is not used at all (that plane's
receiver reads 0 on the ground, and agrees there). The floor is loose, the velocity being the
better of the two where they part: a real receiver's heights wander by 0.3 m/s for 15 s where
its velocity and the autopilot's EKF say level flight, and a plane's manoeuvres part a 2 s
slope from the velocity by up to 2.9 m/s.
"""

from __future__ import annotations

import numpy as np

from altfuse.align import LAG_BOX_S
from altfuse.fuse.base import FusionInput
from altfuse.fuse.smoother.events import VELOCITY
from altfuse.fuse.smoother.model import Regressor
from altfuse.fuse.smoother.noise import CHECK_SIGMAS, CHECK_SLOPE_S, slope
from altfuse.metrics import running_median, samples_in, white_noise_sigma
from altfuse.model import FloatArray, Samples

#: The sensor whose heights check the velocity: the receiver the reader took it from; and the
#: velocity's name in the metadata.
RECEIVER = "gps"
VELOCITY_NAME = "gps_velocity_up"
#: How far a sample may leave its heights' slope beyond CHECK_SIGMAS of the slope's error
#: [m/s], and the share of samples past which the velocity is refused as a whole.
CHECK_FLOOR_M_S = 3.0
MAX_REFUSED_SHARE = 0.5
#: The fewest samples worth a measurement stream.
MIN_SAMPLES = 10
#: Prior on the velocity's lag [s] beyond its receiver's heights' (GPS lags: 0.1-0.4 s).
LAG_PRIOR = 0.3


def checked_velocity(inputs: FusionInput) -> tuple[Samples | None, int]:
    """The GPS's vertical-velocity samples [m/s, up] of the records whose height was kept and
    that agree with the heights' slope (None: no velocity, no heights of its receiver to check
    it by, or most samples disagree), and how many samples the slope refused."""
    velocity = inputs.gps_velocity_up
    if velocity is None or RECEIVER not in inputs.names:
        return None, 0
    receiver = inputs.names.index(RECEIVER)
    # only the records whose height was kept: one the screen refused is refused whole
    own = np.isin(velocity.t, inputs.samples[receiver].t)
    velocity = Samples(velocity.t[own], velocity.value[own])
    if velocity.t.size < MIN_SAMPLES:
        return None, 0
    z = inputs.z[:, receiver]
    valid = np.isfinite(z)
    if valid.sum() < MIN_SAMPLES:
        return None, 0
    width = max(5, round(CHECK_SLOPE_S / inputs.dt_s))
    rate, sxx = slope(inputs.t, z, width)
    error = white_noise_sigma(z[valid]) / np.sqrt(sxx)
    at = np.searchsorted(inputs.t, velocity.t).clip(0, inputs.t.size - 1)
    bound = CHECK_SIGMAS * error[at] + CHECK_FLOOR_M_S
    # NaN (no slope there: the heights absent around the sample) refuses the sample too
    agrees = np.abs(velocity.value - rate[at]) <= bound
    refused = int((~agrees).sum())
    # judged where either says the vehicle climbs or sinks faster than the floor: on the ground
    # a receiver that reads 0 there agrees whatever it reads in flight
    moving = np.fmax(np.abs(velocity.value), np.abs(rate[at])) > CHECK_FLOOR_M_S
    if (~agrees[moving]).sum() > MAX_REFUSED_SHARE * moving.sum() or agrees.sum() < MIN_SAMPLES:
        return None, refused
    return Samples(velocity.t[agrees], velocity.value[agrees]), refused


def lag_regressor(who: np.ndarray, times: FloatArray, accel: Samples) -> Regressor:
    """The velocity's lag [s] beyond the one it was moved by, as a constant state: a sample
    of ``v`` ``tau`` late reads ``v(t - tau) = v(t) - tau a(t)``, ``coef`` minus the
    accelerometer's median over ``LAG_BOX_S`` around the sample (one IMU sample is noisier
    than the lag's effect, and an impact's or a clip's samples, 50-160 m/s^2, would set the
    lag by themselves: a simulated hover with a clip, 0.05 s found for 0.2 s), prior
    ``LAG_PRIOR``."""
    order = np.argsort(accel.t, kind="stable")
    t, a = accel.t[order], accel.value[order]
    step = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    width = max(1, samples_in(LAG_BOX_S, step, t.size)) if step > 0 else 1
    mine = who == VELOCITY
    coef = np.zeros(who.size)
    coef[mine] = -np.interp(times[mine], t, running_median(a, width))
    return Regressor("lag", VELOCITY, coef, LAG_PRIOR)
