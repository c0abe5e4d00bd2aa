"""Paper B, layer 2: an adaptive complementary filter of layer 1 with the accelerometer.

The paper names ``a`` (vertical acceleration), ``v`` (vertical velocity), ``x`` (vertical
position), ``z`` (the layer-1 result), ``T`` (time constant), ``e`` (the correction), ``k`` (the
adaptive switch, 0 or 1) and ``F`` (the output); the equations themselves are **reconstructed**
(ALGORITHMS.md 3.5) as a second-order complementary filter with the paper's gate, written here
as a prediction by the accelerometer and a correction by layer 1::

    v-(n) = v(n-1) + a(n) dt,   x-(n) = x(n-1) + v-(n) dt     (predict)
    e(n) = z(n) - x-(n)
    k(n) = 1 if |e(n)| <= e_max else 0         (a spike in z: keep integrating)
    v(n) = v-(n) + k(n) e(n) / T**2 dt
    x(n) = x-(n) + k(n) 2 e(n) / T dt
    F(n) = x(n),    x(0) = z(0), v(0) = 0

Large ``T`` trusts the accelerometer more, small ``T`` layer 1 more. The error dynamics are those
of a critically damped second-order system with natural frequency ``1/T``.

Departures, each because the reconstruction or the paper's form fails on real logs:

- The correction is taken against the predicted position ``x-(n)``. ALGORITHMS.md's
  ``e(n) = z(n) - x(n-1)`` compares layer 1 with the position one tick old: in a steady climb
  the filter then settles one tick ahead of it (measured 93 ms ahead of the truth on the
  simulator's 305 m climb: RMSE 0.144 m where the sensors' mean has 0.013 m).
- The gate (``gate_form="consensus"``, the default) does not stay shut against the sensors'
  consensus: where every valid sensor has stayed more than ``e_max``
  from the filter on one side for ``AGAINST_CONSENSUS_S``, it is the accelerometer's
  integration that is wrong (a clipped sample, an impact), and the filter is
  reset to layer 1: ``x = z``, ``v`` the slope of ``z`` over the last ``VELOCITY_SPAN_S``; the
  accelerometer is then set aside for ``ACCEL_DISTRUST_S`` (the gate open: nothing to coast
  on). The paper's gate, coasting on the
  accelerometer against agreeing sensors, made excursions of 40-60 m on real logs (the 3.3
  plane's: 43.6 m, 4.6 m with the reset). ``gate_form="paper"`` keeps the reconstructed gate
  alone.
- The gate reopens after it has stayed shut for ``reopen_s`` seconds, and stays open until
  ``|e| <= e_max`` again (the filter re-acquires layer 1). The paper's gate alone, once the
  integration has drifted beyond ``e_max`` (an accelerometer bias, a long climb), would stay shut
  and integrate the drift for ever. Where the sensors do not agree the filter cannot tell which
  of layer 1 and the accelerometer is wrong, and keeps its velocity: resetting it to layer 1's
  slope there followed a GPS glitch (13.8 m off on a simulated mission, 2.5 m without).
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
from typing import Literal

import numpy as np

from altfuse.fuse.base import INERTIAL, FusionInput, FusionResult
from altfuse.fuse.delay import DelayParams, layer1, process_noise
from altfuse.metrics import envelope
from altfuse.model import FloatArray
from altfuse.params import InvalidParameter, param

#: Longest stretch [s] the filter integrates the accelerometer with no layer-1 value.
MAX_COAST_S = 2.0
#: A reset's velocity is layer 1's slope over this span [s] before it.
VELOCITY_SPAN_S = 1.0
#: The filter is reset to the sensors' consensus when it has stayed beyond ``e_max`` of it this
#: long [s]: a spike in layer 1 is shorter, an accelerometer's error integrates and persists.
#: Measured: one 0.1 s tick reset the seeded hovers' noisy starts onto a 5.7 m error; 0.3 s let
#: the 3.3 plane's accelerometer carry the filter 8.1 m off (0.2 s: 5.5 m), before the gate was
#: held open while the accelerometer is set aside (4.6 m).
AGAINST_CONSENSUS_S = 0.2
#: After a reset against the sensors' consensus the accelerometer is set aside (``a = 0``) for
#: this long [s]: EKF3 raises its acceleration noise for 10 s on bad IMU data.
ACCEL_DISTRUST_S = 10.0
#: The filter's loop is stable only on ticks shorter than this share of its time constant T:
#: with the gate open its error ``(eps, delta dt)`` steps by ``[[1 - 2r, 1 - 2r], [-r^2,
#: 1 - r^2]]`` (r = dt / T; predict, then correct by ``2e/T dt`` and ``e/T^2 dt``), whose
#: determinant is 1 - 2r and trace 2 - 2r - r^2: Jury's test holds for r < 2 (sqrt 2 - 1). At
#: 1 Hz with T = 1 s the hover sample's RMSE was 1.65 m against 0.62 m at 5 Hz, the spliced
#: mission's at 0.5 Hz 3.6 m (10 m off every sensor) against 0.71 m.
STABLE_TICK_SHARE = 2.0 * (math.sqrt(2.0) - 1.0)
GateForm = Literal["consensus", "paper"]


@dataclass(frozen=True, kw_only=True)
class MultilayerParams(DelayParams):
    """Layer 1's (as ``delay2``'s) and the complementary filter's parameters.

    Defaults measured on the seeded hover of tests/conftest.py (8 seeds) and the sample log:
    layer 1 with q >= 5 m²/s (0.5 m² per 0.1 s tick) leaves the smoothing to layer 2, which has
    the accelerometer (hover RMSE 0.367 m at 5 m²/s against 0.446 m at 0.5 m²/s); T = 1 s beat
    0.5, 2, 3 and 5 s on the hover (0.373, 0.384, 0.425, 0.623 m) and tied on the moving sample
    flight (re-measured with the correction against the prediction).
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
    gate_form: GateForm = param(
        "consensus",
        help="'consensus' (reset to layer 1 where every sensor lies beyond e_max on one "
        "side: the accelerometer is wrong) or 'paper' (shut, coast, re-acquire)",
    )

    def check_tick(self, tick_s: float) -> None:
        """The filter's loop is stable only on ticks shorter than STABLE_TICK_SHARE of T."""
        if tick_s >= STABLE_TICK_SHARE * self.time_constant_s:
            raise InvalidParameter(
                "time_constant_s",
                f"{self.time_constant_s:g} s makes the complementary filter's loop unstable on "
                f"a clock of {1.0 / tick_s:g} Hz: it needs a tick under {STABLE_TICK_SHARE:.2f} "
                f"T (a clock over {1.0 / (STABLE_TICK_SHARE * self.time_constant_s):.3g} Hz, or "
                f"a time constant over {tick_s / STABLE_TICK_SHARE:.3g} s)",
            )


@dataclass(frozen=True)
class Complementary:
    """The filter's output and its gate, per tick."""

    x: FloatArray  # F(n) = x(n), fused height [m]
    v: FloatArray  # vertical velocity [m/s]
    e: FloatArray  # correction e(n) [m]; NaN where z is absent
    k: FloatArray  # gate k(n), 0 or 1
    resets: int  # times the filter was reset to layer 1 (gate_form="consensus")


def _slope(z: FloatArray, i: int, span: int, dt: float) -> float:
    """Layer 1's slope [m/s] over the ``span`` ticks before tick ``i``; 0 where it cannot tell."""
    j = i - span
    if j < 0 or not math.isfinite(z[j]):
        return 0.0
    return float(z[i] - z[j]) / (span * dt)


def complementary_filter(
    z: FloatArray,
    a: FloatArray,
    dt: float,
    params: MultilayerParams | None = None,
    sensors: tuple[FloatArray, FloatArray] | None = None,
) -> Complementary:
    """Run the adaptive complementary filter (3.5) over ``z`` [m] and ``a`` [m/s², up] with
    ``params``' time constant, gate and ``e_max`` (its defaults without).

    ``sensors``: per tick the lowest and highest valid sensor (NaN where none is); with
    ``gate_form="consensus"`` the filter is reset to layer 1 where they all lie more than
    ``e_max`` from it on one side for ``AGAINST_CONSENSUS_S``. One kind of sensor alone is a
    consensus too: two barometers read one air, yet with no second opinion a wrong sensor
    costs its own error, and a wrong integration grows without bound (the 3.3 plane with its
    GPS frozen, its barometer alone: 6.1 m RMSE coasting).
    """
    p = params or MultilayerParams()
    T, e_max_m, reopen_s = p.time_constant_s, p.e_max_m, p.reopen_s
    n = z.size
    x, v, e, k = (np.full(n, np.nan) for _ in range(4))
    acc = np.where(np.isfinite(a), a, 0.0)
    lo, hi = (np.full(n, np.nan),) * 2 if sensors is None or p.gate_form == "paper" else sensors
    x_prev = v_prev = math.nan  # not started
    shut_for = 0.0
    coasting, max_coast = 0, round(MAX_COAST_S / dt)  # in ticks
    span = max(1, round(VELOCITY_SPAN_S / dt))
    distrust, distrust_ticks = 0, round(ACCEL_DISTRUST_S / dt)
    against, against_ticks = 0, max(1, round(AGAINST_CONSENSUS_S / dt))
    reacquiring = False
    resets = 0
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
        distrust = max(distrust - 1, 0)
        # v-(n) = v(n-1) + a(n) dt,  x-(n) = x(n-1) + v-(n) dt
        v_pred = v_prev + (0.0 if distrust else acc[i]) * dt
        x_pred = x_prev + v_pred * dt
        # e(n) = z(n) - x-(n), with z(n) within the sensors (layer 1 lags them where its
        # variances carry the motion: 80 m behind a barometer alone in a descent)
        e_i = min(max(z[i], lo[i]), hi[i]) - x_pred if has_z and lo[i] <= hi[i] else z[i] - x_pred
        if not has_z:
            k_i, e_i = 0.0, 0.0
        else:
            inside = abs(e_i) <= e_max_m
            beyond = lo[i] - x_pred > e_max_m or x_pred - hi[i] > e_max_m
            against = against + 1 if beyond else 0
            if against >= against_ticks:
                # the accelerometer against the sensors: x = z (within them), v its slope
                x_prev, v_prev = x_pred + e_i, _slope(z, i, span, dt)
                shut_for, resets, distrust, against = 0.0, resets + 1, distrust_ticks, 0
                x[i], v[i], e[i], k[i] = x_prev, v_prev, e_i, 1.0
                continue
            reacquiring = (reacquiring or shut_for >= reopen_s) and not inside
            # k(n) = 1 if |e(n)| <= e_max, or while re-acquiring after a long shut, or while the
            # accelerometer is set aside (there is nothing to coast on)
            k_i = 1.0 if inside or reacquiring or distrust else 0.0
            shut_for = shut_for + dt if k_i == 0.0 else 0.0
        # v(n) = v-(n) + k e / T^2 dt,  x(n) = x-(n) + k 2 e / T dt
        v_prev = v_pred + k_i * e_i / T**2 * dt
        x_prev = x_pred + k_i * 2.0 * e_i / T * dt
        x[i], v[i], k[i] = x_prev, v_prev, k_i
        e[i] = e_i if has_z else np.nan
    return Complementary(x, v, e, k, resets)


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
        params,
        envelope(inputs.z),
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
            "gate_form": params.gate_form,
            "resets": cf.resets,
        },
    )
