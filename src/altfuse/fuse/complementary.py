"""Paper B, layer 2: an adaptive complementary filter of layer 1 with the accelerometer.

The paper names ``a`` (vertical acceleration), ``v`` (vertical velocity), ``x`` (vertical
position), ``z`` (the layer-1 result), ``T`` (time constant), ``e`` (the correction), ``k`` (the
adaptive switch, 0 or 1) and ``F`` (the output); the equations themselves are **reconstructed**
(ALGORITHMS.md 3.5) as a second-order complementary filter with the paper's gate::

    e(n) = z(n) - x(n-1)
    k(n) = 1 if |e(n)| <= e_max else 0         (a spike in z: keep integrating)
    v(n) = v(n-1) + (a(n) + k(n) e(n) / T**2) dt
    x(n) = x(n-1) + (v(n) + k(n) 2 e(n) / T) dt
    F(n) = x(n),    x(0) = z(0), v(0) = 0

Large ``T`` trusts the accelerometer more, small ``T`` layer 1 more. The error dynamics are those
of a critically damped second-order system with natural frequency ``1/T``.

Departures, each because the paper's form fails on real logs:

- The gate reopens after it has stayed shut for ``reopen_s`` seconds, and stays open until
  ``|e| <= e_max`` again (the filter re-acquires layer 1). The paper's gate, once the integration
  has drifted beyond ``e_max`` (an accelerometer bias, a long climb), would stay shut and
  integrate the drift for ever.
- Where layer 1 has no value (no sensor), ``k = 0``: the filter integrates the accelerometer alone,
  for at most ``MAX_COAST_S`` seconds; after that, or at once where the accelerometer has no value
  either, the output is NaN and the filter starts again (``x = z``, ``v = 0``) when layer 1
  returns. Unbounded, a velocity error integrates into metres per second of gap (a log's
  disarmed pause of 628 s put the output 64 m off). Where only the accelerometer has no value (an
  IMU gap), ``a = 0``: the filter follows layer 1 alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from altfuse.fuse.base import INERTIAL, FusionInput, FusionResult
from altfuse.fuse.delay import DelayParams, layer1, process_noise
from altfuse.model import FloatArray
from altfuse.params import param

#: Longest stretch [s] the filter integrates the accelerometer with no layer-1 value.
MAX_COAST_S = 2.0


@dataclass(frozen=True, kw_only=True)
class MultilayerParams(DelayParams):
    """Layer 1's (as ``delay2``'s) and the complementary filter's parameters.

    Defaults measured on the seeded hover of tests/conftest.py (8 seeds) and the sample log:
    layer 1 with q >= 5 m²/s (0.5 m² per 0.1 s tick) leaves the smoothing to layer 2, which has
    the accelerometer (hover RMSE 0.370 m at 5 m²/s against 0.444 m at 0.5 m²/s); T = 1 s beat
    0.5, 2, 3 and 5 s on the hover and tied on the moving sample flight.
    """

    q_m2_s: float = process_noise(5.0)
    time_constant_s: float = param(
        1.0, help="time constant T of the complementary filter", unit="s", check="positive"
    )
    e_max_m: float = param(
        3.0, help="gate threshold on the correction e", unit="m", check="positive"
    )
    reopen_s: float = param(
        2.0,
        help="how long a shut gate stays shut before it reopens",
        unit="s",
        check="non-negative",
    )


@dataclass(frozen=True)
class Complementary:
    """The filter's output and its gate, per tick."""

    x: FloatArray  # F(n) = x(n), fused height [m]
    v: FloatArray  # vertical velocity [m/s]
    e: FloatArray  # correction e(n) [m]; NaN where z is absent
    k: FloatArray  # gate k(n), 0 or 1


def complementary_filter(
    z: FloatArray,
    a: FloatArray,
    dt: float,
    time_constant_s: float = 1.0,
    e_max_m: float = 3.0,
    reopen_s: float = 2.0,
) -> Complementary:
    """Run the adaptive complementary filter (3.5) over ``z`` [m] and ``a`` [m/s², up]."""
    T = time_constant_s
    n = z.size
    x, v, e, k = (np.full(n, np.nan) for _ in range(4))
    acc = np.where(np.isfinite(a), a, 0.0)
    x_prev = v_prev = math.nan  # not started
    shut_for = 0.0
    coasting, max_coast = 0, round(MAX_COAST_S / dt)  # in ticks
    reacquiring = False
    for i in range(n):
        has_z = math.isfinite(z[i])
        if math.isnan(x_prev):
            if has_z:  # x(0) = z(0), v(0) = 0
                x_prev, v_prev, coasting = float(z[i]), 0.0, 0
                x[i], v[i], e[i], k[i] = x_prev, 0.0, 0.0, 1.0
            continue
        if not has_z:
            coasting += 1
            if coasting > max_coast or not math.isfinite(a[i]):
                x_prev = v_prev = math.nan  # stop; start again when layer 1 returns
                continue
        else:
            coasting = 0
        # e(n) = z(n) - x(n-1)
        e_i = z[i] - x_prev
        if not has_z:
            k_i, e_i = 0.0, 0.0
        else:
            inside = abs(e_i) <= e_max_m
            reacquiring = (reacquiring or shut_for >= reopen_s) and not inside
            # k(n) = 1 if |e(n)| <= e_max, or while re-acquiring after a long shut
            k_i = 1.0 if inside or reacquiring else 0.0
            shut_for = shut_for + dt if k_i == 0.0 else 0.0
        # v(n) = v(n-1) + (a(n) + k e / T^2) dt
        v_prev = v_prev + (acc[i] + k_i * e_i / T**2) * dt
        # x(n) = x(n-1) + (v(n) + k 2 e / T) dt
        x_prev = x_prev + (v_prev + k_i * 2.0 * e_i / T) * dt
        x[i], v[i], k[i] = x_prev, v_prev, k_i
        e[i] = e_i if has_z else np.nan
    return Complementary(x, v, e, k)


def fuse_multilayer(inputs: FusionInput, params: MultilayerParams) -> FusionResult:
    """Paper B's full method: layer 1 (``delay2``: 3.3 then 3.4), then layer 2 (3.5) with
    ``inputs.accel``'s vertical acceleration on the clock.

    The weights are layer 1's spatial weights ``W_i``: layer 2 mixes the accelerometer into their
    combination and has no per-sensor weight of its own.
    """
    if inputs.accel is None:
        raise ValueError("multilayer needs the vertical acceleration (inputs.accel)")
    accel_up = inputs.accel.on_clock
    first = layer1(inputs, 2, params)
    cf = complementary_filter(
        first.fused,
        accel_up,
        inputs.dt_s,
        params.time_constant_s,
        params.e_max_m,
        params.reopen_s,
    )
    status = np.where(np.isnan(first.fused) & np.isfinite(cf.x), INERTIAL, first.status)
    return FusionResult(
        method="multilayer",
        fused=cf.x,
        weights=first.weights,
        status=status,
        traces=first.traces,
        tick_traces={
            **first.tick_traces,
            "layer1_m": first.fused,
            "accel_up": accel_up,
            "velocity": cf.v,
            "correction": cf.e,
            "gate": cf.k,
        },
        params={
            **first.params,
            "time_constant_s": params.time_constant_s,
            "e_max_m": params.e_max_m,
            "reopen_s": params.reopen_s,
        },
    )
