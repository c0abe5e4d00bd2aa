"""The smoother's state-space model: the state's layout, its transition ``F``, process noise
``Q``, measurement rows ``H``, prior, and the ground constraint (the module doc of
:mod:`altfuse.fuse.smoother` gives the equations)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from altfuse.model import FloatArray, Samples

#: Accelerometer bias random walk [m^2/s^5].
Q_BIAS = 1e-5
#: Prior on a barometer's temperature coefficient [m/degC] (a constant, learnt from the flight).
THERMAL_PRIOR = 0.5
#: A barometer's drift rate [m/s]: its prior at the start, and its random-walk density
#: [m^2/s^3] (the rate may change by about 0.03 m/s in 100 s).
DRIFT_PRIOR = 0.01
Q_DRIFT = 1e-5
#: How well "standing still at the take-off point" holds on the ground [m, m/s].
STILL_SIGMA = 0.02


def thermal_layout(
    temperatures: Sequence[Samples | None],
    samples: Sequence[Samples],
    who: np.ndarray,
    position: np.ndarray,
    m: int,
) -> tuple[np.ndarray, FloatArray]:
    """Each sensor's temperature-coefficient state index (-1: none) and each event's temperature
    less the sensor's first one [degC] (0 for the others)."""
    tstate = np.full(m, -1)
    dtemp = np.zeros(who.size)
    for i, temp in enumerate(temperatures):
        if temp is None or temp[0].size < 2 or not samples[i][0].size:
            continue
        order = np.argsort(temp[0], kind="stable")
        at_samples = np.interp(samples[i][0], temp[0][order], temp[1][order])
        tstate[i] = 3 + m + int((tstate >= 0).sum())
        mine = who == i
        dtemp[mine] = (at_samples - at_samples[0])[position[mine]]
    return tstate, dtemp


@dataclass(frozen=True)
class Layout:
    """The sensors' states in ``x`` and what their measurement rows need."""

    sign: FloatArray  # +1: the sensor measures h + c_i; -1: h - c_i (a rangefinder)
    thermal: np.ndarray  # each sensor's temperature-coefficient state; -1: none
    dtemp: FloatArray  # each event's temperature change of its sensor [degC]
    drift: np.ndarray  # each sensor's drift-rate state; -1: none

    @property
    def n(self) -> int:
        return 3 + self.sign.size + int((self.thermal >= 0).sum() + (self.drift >= 0).sum())

    @property
    def drift_pairs(self) -> np.ndarray:
        """(offset state, its drift-rate state) per drifting sensor, shape (k, 2)."""
        drifting = np.flatnonzero(self.drift >= 0)
        return np.column_stack([3 + drifting, self.drift[drifting]])

    def without_thermal(self) -> Layout:
        """The same without the temperature-coefficient states."""
        return Layout(self.sign, np.full(self.sign.size, -1), self.dtemp, self.drift)

    def with_drift(self, kinds: Sequence[str]) -> Layout:
        """The same with a drift-rate state for each barometer."""
        drift = np.full(self.sign.size, -1)
        baros = [i for i, k in enumerate(kinds) if k == "baro"]
        drift[baros] = self.n + np.arange(len(baros))
        return Layout(self.sign, self.thermal, self.dtemp, drift)


def transition(dt: float, n: int, use_bias: bool, drifts: np.ndarray) -> FloatArray:
    """F over ``dt``: h += v dt - b dt^2/2, v += -b dt, c_i += r_i dt for a sensor with a drift
    rate ``r_i`` (``drifts``: (offset, rate) state pairs); the rest random walks (identity)."""
    f = np.eye(n)
    f[0, 1] = dt
    if use_bias:
        f[0, 2], f[1, 2] = -0.5 * dt * dt, -dt
    if drifts.size:
        f[drifts[:, 0], drifts[:, 1]] = dt
    return f


@dataclass(frozen=True)
class Events:
    """What the forward pass steps through, one entry per event (a sample or a clock tick).

    ``who``: the sensor of a sample, -1 for a tick; ``z``: the sample's value; ``a``: the mean
    vertical acceleration over the interval ending at the event; ``q_state`` (events, m): the
    sensor states' random-walk densities over that interval; ``still``: the events at which the
    vehicle is known to stand at the take-off point; ``h0``: the first height guess.
    """

    t: FloatArray
    who: np.ndarray
    z: FloatArray
    a: FloatArray
    q_state: FloatArray
    still: np.ndarray
    q_accel: float
    use_bias: bool
    gate: float
    h0: float


def process_noise(ev: Events, k: int, dt: float, n: int, drifts: np.ndarray) -> FloatArray:
    """Q over the interval ``dt`` ending at event ``k``: white acceleration on (h, v), the bias's
    and the sensor states' random walks, and each drifting offset's integrated random walk."""
    m = ev.q_state.shape[1]
    q = np.zeros((n, n))
    q_accel = ev.q_accel
    q[0, 0], q[0, 1], q[1, 1] = q_accel * dt**3 / 3, q_accel * dt**2 / 2, q_accel * dt
    q[1, 0] = q[0, 1]
    q[2, 2] = Q_BIAS * dt if ev.use_bias else 0.0
    q[3 : 3 + m, 3 : 3 + m] = np.diag(ev.q_state[k] * dt)
    for c, rate in drifts:  # a drifting offset: an integrated random walk
        q[c, c] += Q_DRIFT * dt**3 / 3
        q[c, rate] = q[rate, c] = Q_DRIFT * dt**2 / 2
        q[rate, rate] = Q_DRIFT * dt
    return q


def measurement_row(layout: Layout, i: int, k: int) -> FloatArray:
    """H of sensor ``i``'s sample at event ``k``: h plus the sensor's offset (GPS, baro) or
    minus its ground height (rangefinder), plus its temperature term."""
    hrow = np.zeros(layout.n)
    hrow[0], hrow[3 + i] = 1.0, layout.sign[i]
    if layout.thermal[i] >= 0:
        hrow[layout.thermal[i]] = layout.dtemp[k]
    return hrow


def hold_still(x: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
    """On the ground before take-off: h = 0 and v = 0 (the datum's definition)."""
    for j in (0, 1):
        s = p[j, j] + STILL_SIGMA**2
        kg = p[:, j] / s
        x = x - kg * x[j]
        p = p - np.outer(kg, p[j])
    return x, p


def prior(ev: Events, layout: Layout) -> tuple[FloatArray, FloatArray]:
    """The state and covariance before the first event: ``h`` at the first height guess, every
    other state at 0; a loose height, velocity and offsets, the priors of the temperature
    coefficients and drift rates."""
    m, n = layout.sign.size, layout.n
    n_thermal = int((layout.thermal >= 0).sum())
    x = np.zeros(n)
    x[0] = ev.h0
    # without the accelerometer the bias is inert: a tiny fixed variance keeps P invertible
    p = np.diag(
        [10.0**2, 3.0**2, 0.1**2 if ev.use_bias else 1e-9]
        + [1.0**2] * m
        + [THERMAL_PRIOR**2] * n_thermal
        + [DRIFT_PRIOR**2] * (n - 3 - m - n_thermal)
    )
    return x, p
