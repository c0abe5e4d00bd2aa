"""Offline Kalman smoother: a forward filter and a backward pass to the Rauch-Tung-Striebel
estimate (in the modified Bryson-Frazier form, :mod:`.kalman`).

The papers' methods, like the autopilot's EKF, are causal. Offline, the whole flight is known;
this method uses it. Beyond the papers (issue 8); textbook references: Rauch, Tung & Striebel,
AIAA J. 3(8), 1965, doi:10.2514/3.3166; Bar-Shalom, Li & Kirubarajan, *Estimation with
Applications to Tracking and Navigation*, 2001, ch. 5 and 8.

State (``n = 3 +`` one per sensor ``+`` one per barometer with a logged temperature, or with
a scale to learn, or drifting ``+`` one for the GPS velocity's lag ``+`` one for the
barometers' wash, where the log asks for it)::

    x = [h, v, b, c_1 .. c_m, k_1 .., w]
    h  height above take-off [m]            v  vertical velocity [m/s]
    b  accelerometer bias [m/s^2]          c_i  for a GPS or barometer: its offset [m];
                                                 for a rangefinder: the ground height under the
                                                 vehicle above take-off [m]
    k_j  a barometer's temperature coefficient [m/degC] (a constant, learnt from the flight)
    tau  the GPS velocity's lag [s] (a constant, learnt from the flight)
    w  the barometers' error in the rotors' wash around the take-off [m] (one for all of them)

Process, between consecutive events ``dt`` apart, driven by the mean earth-frame vertical
acceleration ``a`` over the interval (the IMU integrated exactly between events, so the filter
steps at the measurements' rate, not the IMU's)::

    h += v dt + (a - b) dt^2 / 2        v += (a - b) dt
    b, c_i: random walks                noise: white acceleration q_a, and q_b, q_c per state
    but a GPS's offset, bounded:        c_i += -c_i dt / tau  (first-order Gauss-Markov)
    w: a random walk in the datum's span around the take-off, 0 before it, held to 0 at its end

Measurements, each fused at its own sample time (no resampling before fusion)::

    GPS:  z_i = h + c_i + n_i       barometer:  z_i = h + c_i + k_j (T - T_0) + w + n_i
    rangefinder:  z_i = h - c_i + n_i
    the first GPS's vertical velocity:  z_v = v - tau a + n_v

A GPS's heights' lag is not modelled here: the pipeline moves each GPS's samples (and the
velocity with the first's) earlier by the lag it measures against the barometer
(:func:`altfuse.align.estimate_lag`; 0.1-0.4 s on the simulators' logs, not estimated on
altfuse's own simulated flights, whose GPS noise hides it), or the first's, by its velocity,
against the accelerometer (:func:`altfuse.align.inertial_lag`). The velocity's lag beyond that,
``tau``, is a constant state (``a`` the accelerometer's median around the sample): a steady
climb leaves the heights' lag loose, and the velocity is precise enough for 0.3 s to matter
(:mod:`.velocity`, which also checks it against its receiver's heights: a simulator's plane
log whose velocity is noise). Its noise is learnt as a sensor's, never below
``MIN_SIGMA_VELOCITY_M_S`` (0.1 m/s): its errors are correlated over seconds, which the spread
between samples does not show, and EM took the simulators' to 9 mm/s (0.003 m/s of bias in a
climb then cost a 305 m climb 0.013 -> 0.042 m RMSE). It tells the accelerometer's errors from
the heights' within a sample: Paper A's flight with an attitude error 0.479 -> 0.038 m RMSE,
simulated barometer drifts and losses 0.30-0.58 -> 0.07-0.31 m (measured before the simulated
sensors lagged; since, 0.035-0.062 m and 0.02-0.34 m); the simulators' own logs, whose
heights are precise, move by at most 1 mm (the Solo's maximum error 0.143 -> 0.100 m). Its
samples never let the gate loose (:func:`.passes._release`): they say nothing of ``h``.

On the ground before take-off (the datum's ground window, ending ``STILL_MARGIN_S`` before the
detected take-off) the vehicle stands at the take-off point: ``h = 0`` and ``v = 0`` there. This
pins what the sensors alone leave free (all offsets and ``h`` can shift together) and makes
``fused_std`` an uncertainty about the height above take-off. A log that starts less than
``STILL_MARGIN_S`` before take-off (or none: a log with no take-off is referred to its first
seconds) has no such span; there each offset measured on that datum window has the standard
error of that measurement as its prior (:func:`.model.datum_priors`),
not the 1 m of an offset the flight says nothing about (the 4.5 plane: fused_std 0.58 m, for
errors of 2-7 cm, coverage 1.00; now 0.027 m, 0.97).

A spliced log (the datum's segments, :func:`altfuse.datum.refer_to_takeoff`) starts afresh at
each later segment's first event (:func:`.kalman.restart`; the backward pass carries nothing
back across it): ``h`` and ``v`` return to their prior, nothing saying where the vehicle went
meanwhile (``h`` centred on the segment's own first samples, :func:`.model.first_height`: on
the log's first guess, a plane resumed at 300 m had every sample gated 30 sigma away), and
where the segment was referred to a ground (its own or the main one's) every sensor's offset
and drift rate too, each 0 at that ground, where ``h = 0`` and ``v = 0`` hold as on the main
one. The accelerometer's bias and the regressors are the sensors' own, and kept.
Bridged by the model instead, a real log's barometer drift rate carried 1.8 m over a 10-minute
pause, and the fused height sat that far above both sensors after it (0.10 m since).

Without IMU or ATT records the model falls back to altitude only: ``a = 0``, ``b`` frozen at 0,
and a larger acceleration noise (a constant-velocity random walk), raised where the sensors'
slopes change together beyond their errors (:func:`.noise.accel_refused` against ``a = 0``) and
per second by EM where the smoothed flight asks for it (:func:`.noise.em_accel`); the metadata
says so. EM alone cannot see a change the gate refused: the 3.3 plane without its IMU, pulled
from a 7 m/s climb into a 29 m/s dive (36 m/s^2), held the climb 0.8 s with its GPS and
barometer gated out, 16 m above both (0.694 m RMSE; 0.078 m since).

From the log itself:

- measurement noise: each sensor's local spread of second differences over ``NOISE_WINDOW_S``
  (``sigma = 1.4826 MAD(d2 z) / sqrt(6)``: white noise survives where a smooth flight cancels;
  sensors get noisier and quieter within a flight), scaled by EM (``EM_PASSES`` smoother passes,
  each followed by the M-step ``s_i = mean((residual^2 + H P H^T) / sigma^2)`` over the sensor's
  accepted samples);
- the acceleration noise, from the accelerometer's own sample-to-sample spread
  (:func:`.noise.accel_psd`), raised over each spike (an impact, a clipped sample: a
  departure from its neighbours beyond five times the flight's spread, :func:`.noise.accel_spikes`)
  by the spike's excess, so that one sample worth 20 m/s no longer locks every sensor out for
  the 2 s of ``LOCKOUT_S`` (40 m away; now within 0.1 m); and raised over each second in
  which a GPS and a barometer agree against it (:func:`.noise.accel_refused`: a plane's
  attitude error, 6-30 m/s^2 in the vertical at large bank angles, took the height 90 m away
  between lockouts; now within 0.9 m); then, each EM pass, raised per second to what the
  smoothed flight asks of it (:func:`.noise.em_accel`: the velocity's change beyond the
  accelerometer's; that plane 0.143 -> 0.116 m RMSE; the metadata's
  ``accel_noise_raised_s`` says for how long), unless ``--accel-noise`` gives it;
- each barometer's temperature coefficient (a state, above), where a sensor other than a
  barometer is there to tell it: barometers alone share their temperature, and a coefficient
  learnt against the accelerometer took two of them 0.5 m further from the truth than either
  (the simulators' 4.5 plane with its GPS left out: 2.58 m RMSE against 2.08 and 2.11);
- a barometer's scale error ``s`` (``z = h + c + s h``, a constant state), where the datum
  estimated the scale to within ``SCALE_PRIOR`` but could not apply it, the log's likelihood
  asks for it and the scale found agrees with the datum's (:func:`.evidence.scale_evidence`):
  a simulated mission 15 m high with its barometer 7 % high, 0.93 m RMSE (it followed the
  barometer) -> 0.05 m; a simulator's log with a noisy second barometer 4.4 % high, which
  the drift test had taken for a drift, 0.013 -> 0.005 m and coverage 1.00 -> 0.94; and
  where the datum applied a scale with a standard error above ``LEARN_SCALE_STD``, relearnt
  from that barometer's readings referred by their offset only, kept where the log's evidence
  takes it (:func:`.evidence.relearnt_scales`; measured there);
- a barometer's dynamic-pressure coefficient ``k`` (``z = h + c + k V^2 / 2g``, ``V`` the
  GPS's ground speed: air flowing past lowers the static pressure it reads), in a flight fast
  enough to tell it, where the log's likelihood asks for it (:func:`.evidence.dynamic_evidence`,
  after the scale, before the temperature and the drift). The simulators' logs have none and
  never take it (gains -12 to -3); of the five real logs that reach 3 m/s, two ArduPilot
  copters' barometers 0.8 and 1.2 (gains 71 and 55: 1.0-1.5 m high at 5 m/s, which one of them
  had given to a temperature coefficient), a PX4 log's with 11 % of its GPS left -0.5 (gain
  14), the other two none; the simulators' fast copters with ``V^2 / 2g`` added to their
  barometers, 0.23-0.65 -> 0.013-0.019 m RMSE (with :func:`altfuse.datum.scale.dynamic_head` in the
  datum's scale fit too). In a wind the two legs of a flight out and back feel different
  airspeeds at one ground speed: where the datum's fit found a steady wind ``W`` beside the
  head (:class:`altfuse.datum.scale.Wind`, from the GPS's course), the head at the airspeed
  ``|V - W|`` is offered beside the one at the ground speed, and the likelier taken
  (``baro_dynamic_speed``): the truth logs' copters in a 3 m/s wind (``windy-3``), the hexa
  0.662 -> 0.005 m; handed a wind the air did not blow, the ground speed is taken. Where the
  datum cannot tell the wind against a noisy GPS, one more pass without the barometers gives
  a height they are regressed against (:func:`.evidence.smoothed_wind`, ``baro_dynamic_wind``):
  altfuse's mission in a 2 m/s wind along its track (``baro-airflow``, k 0.40), the wind
  told 1.4-2.0 m/s, 0.28-0.43 -> 0.06-0.13 m on seeds 0-2; the hexa in a 3 m/s wind with a
  real receiver's noisy GPS 0.545 -> 0.422 m, k 1.87 -> 0.95. (Tried:
  ``k |V - W|^2 / 2g`` as ``k V^2 / 2g - V . kW / g`` and a constant,
  with two more states per barometer offered beside the head alone: that mission in a 2-5
  m/s wind 0.06-0.32 m; not kept, as the extra per-event coefficients put the 300 MB log's
  peak at 1.59x the file, and the 45-minute repeated flight's fused_std grew to 1.4 m.)
- the terrain's roughness under a rangefinder, per metre flown (:func:`terrain_noise`, with the
  horizontal speed from ``GPS.Spd``): over flat ground, or hovering, the rangefinder is an
  absolute reference; over hills it tells only short-term changes. Where the speed ends (a GPS
  lost in flight) the last known speed is held: taking the ground as free instead cost Paper
  A's flight without GPS 0.74 m against 0.03 m;
- whether a barometer drifts: a second forward pass with a drift rate ``r`` on each barometer's
  offset (``c += r dt``, ``r`` a random walk of density ``Q_DRIFT``), kept if it raises the
  log-likelihood of the samples both passes accept by more than ``DRIFT_GAIN`` (a likelihood-ratio
  test at 0.1 %) and rejects no more samples (beyond ``EVIDENCE_SLACK``, 0.5 % of them:
  :func:`.evidence.evidence_gain`). A ramp
  (0.05 m/s) is then told from the GPS's wander even with no third sensor (hover RMSE 2.36 m
  -> 0.23 m), and a barometer that does not drift keeps its stable offset (a drift rate it does
  not need lets the height wander where GPS and barometer are alone). A third pass gives the
  drift to the GPS receivers instead; where that explains the log at least as well, the
  barometer's is not modelled (:func:`.evidence.drift_evidence`).

The offsets' random-walk densities are physical defaults (``Q_OFFSET``: a GPS's vertical error
wanders by about 1 m over 100 s, and no further than its bound, ``GPS_CORRELATION_S``: over hours
nothing else holds the height's common mode; a barometer, once its temperature is modelled, by
centimetres),
not estimates: with two drifting sensors the log fixes only the sum of their densities, and
splitting it evenly (the method of moments, and EM, which did not move from there) gave the
barometer the GPS's wander (hover RMSE 0.35 m against 0.07 m with the defaults). What the log
does tell is which of two physical models fits it: a GPS that wanders, or one as stable as a
barometer (``Q_OFFSET_STABLE_GPS``: an RTK fix, a simulator's GPS), kept where it raises the
samples' log-likelihood by ``STABLE_GAIN`` (:func:`.evidence.gps_evidence`; recorded as
``gps_stable``), each model with the barometers' drift rates where they gain (a barometer
drifting from a stable GPS made the stable model lose alone). Every ArduPilot copter simulator
log here gains 25-222 from it (the 92 m climb, its barometer noisy: 0.045 -> 0.027 m RMSE; the
9 m sonar flight with its barometer drifting 3 m in 10 minutes 0.432 -> 0.001 m), altfuse's
simulated flights and the real logs nothing. A vehicle's barometers read one air: their
offsets' increments, and their drift rates', are correlated by ``BARO_SHARED`` (0.9,
:func:`.model.process_noise`), so that two are not two independent witnesses against a GPS.
:class:`SmootherParams` overrides (``--sigma``, ``--offset-noise``, ``--accel-noise``, ``--gate``).

Innovation gating: a sample whose innovation exceeds ``gate`` standard deviations (3.5) is
rejected, counted per sensor and traced. When no sample of any sensor has passed for
``LOCKOUT_S`` (2 s), the estimate, not every sensor, has gone astray: the height's and the
velocity's variances grow by what the next sample says, which then passes (ArduPilot's EKF3
resets its height after 5 s), where that sample's sensor was accepted until the estimate went
astray: one rejected since long before is astray itself (a real log's GPS, 15 m off its
barometer for 130 s, took the estimate 15 m down with it when the barometer alone was
rejected for 2 s). Without it one bad stretch locked every later sample out (a
simulator's log: 47 s and 706 of 706 samples rejected, 415 m below the ground). Where two
sensors fail the gate on the same side, they agree against the estimate: it is let loose after
``AGREED_LOCKOUT_S`` (0.5 s; a PX4 simulator's landing that the logged IMU did not show left it
1.4 m under GPS and barometer for 2.5 s, 0.46 m for 0.6 s since). That decision is the forward
filter's, made on the past alone; the whole flight revisits it: where two sensors the estimate
followed left it together (their rejections beginning within ``AGREED_LOCKOUT_S`` of each
other) and it was let loose, each later EM pass lets it loose at the first rejection of that
episode (:attr:`.model.Events.early`), and its samples count (that landing, made again: 0.43
m under both sensors for 1 s -> 0.03 m; the Solo's truth log with its sensors at 2 Hz, whose
logged IMU missed the touchdown: 0.62 m under the truth at most, its band 0.09 m -> 0.092 m,
inside the bar). Only there: where the other sensor was rejected since long before (a real
crash log's GPS, 15 m off its barometer) or began a second apart (a GPS stepped 2 m after a
real PX4 log's barometer excursion), the height would jump to the episode's first sample.
A sensor too noisy to fail the gate agrees too, where its accepted samples lean the rejected
one's way (:func:`.passes._leaning`: over the span of the rejections, their innovations' mean
``LEAN_SIGMAS``, 5, of its standard errors to that side and within 5 of the rejected
innovation): the height is let loose after ``AGREED_LOCKOUT_S``, and in the EM passes at that
sensor's first rejection (the PX4 landing again, on pyulog's sample log: the GPS rejected, its
barometer passing, the height 0.18 m under both for 3 s with a band of 0.024 m; now 0.12 m at
most, on them again 0.6 s after the touchdown; the Solo's truth log with a barometer 0.3 m
noisy: 0.246 -> 0.088 m RMSE).

At 5 sigma, Paper A's barometer excursion was accepted long enough to bend the barometer's
temperature coefficient (0.24 m/degC against 0.12), and every height after the rangefinder was
lost with it (0.73 m RMSE against 0.17 m at 3.5 sigma).

Steps: where two sensors' heights jump against each other (:mod:`altfuse.steps`, found on the
clock before referral), neither a random walk nor the gate takes it: the smoother followed a
barometer stepped 1 m beside a GPS it holds to wander (the simulators' hexacopter: 1.06 m RMSE
against the GPS's 0.008), or gated a stepped GPS out for the rest of the flight. A step whose
sensor its own heights tell (:attr:`altfuse.steps.Step.jumped`: they jump there, the other's
hold) is that sensor's; each other step (or the steps at one instant, as one event) is tried as
either sensor's jump (:func:`.evidence.jump_evidence`: the accelerometer holds the height
through it, and any third sensor); the one whose samples are the likelier is taken, its samples
after the step moved back by it and its offset let jump (``JUMP_SIGMAS`` times the step over
``JUMP_HALF_WIDTH_S``) and settle (as far as the two sensors' difference moves back over the
next 20 s, :attr:`altfuse.steps.Step.settle_m`: a barometer flashed by light settles back);
where neither is, both offsets may jump. A
tentative step (a sensor regained elsewhere, found below the sure steps' significance:
:attr:`altfuse.steps.Step.tentative`) is tried as no jump as well, and made one only where the
likelihood says so (:func:`.evidence.regain_evidence`). Recorded as ``steps`` (time, the jump,
whose). On the truth logs with one sensor stepped 1 m half-way, within the bar on 11 and 13
of 13 (barometer, GPS) where it was 7 and 12; lost for 10 s and regained 2 m higher, 13 and 13
where it was 6 and 11; flashed 1, 3, -3 and 10 m (settling back over 15 s), 12, 11, 13 and 11
where 6, 5, 6 and 2 before the jumps settled and their sensors were told by their own heights
(9 at 10 m before a tie of drifts went to the barometer, :func:`.evidence.drift_evidence`);
the logs without a step unchanged.

The model is decided on the datum's 10 Hz clock whatever the output's rate
(``FusionInput.analysis``): the noises, the tests, the accelerometer's refusals and the holds on
the ground; the filter steps through the output's ticks too, each splitting the interval it
falls in and taking that interval's acceleration and noise (:func:`.events.model_intervals`),
so that it reads the state there and moves none (at 0.2-100 Hz the heights of 33 of 34 logs
within 0.11 mm of their 10 Hz ones, where they moved by up to 1.4 m, 8.8 m in a crash).

Outputs: the smoothed height at the clock's ticks, its standard deviation (``fused_std``: the
model's, and the sensors' common latency behind the log's timestamps, ``TIMING_SIGMA_S``, times
the smoothed climb rate; also the barometers' scale error that nothing pins,
:func:`.model.unpinned_scales`, in a log without GPS or where the fit against the GPS cannot
tell it to within 5 %, as far as the smoothed height follows it, :func:`scale_response`), the
velocity, bias and each sensor's offset (or ground height), and each sensor's contribution: the
share, per tick, of the total Kalman gain on ``h`` that its accepted samples carried around it
(over whole cycles of the slowest sensor's sampling, :func:`.events.contributions`). In the
metadata, the model's own check per sensor: ``nis_<sensor>``, the mean squared normalised
innovation ``y^2 / S`` of its accepted samples (1 where the model's noises are right), and
``model_check``: failed where one averages above ``NIS_CHECK`` (the commands warn). It does
not see every error: a random-walk offset absorbs a slow one (on the simulators' logs the
check reads 0.1-1.3 where the +-2 sigma coverage runs from 0.63 to 1.00; the velocity's
0.01-0.3, its floor above its noise there). And ``not_used``, where given: the per-sensor
values for sensors this log does not have (:func:`not_used`; the commands warn).

Measured (``benchmarks/smoother_accuracy.py``, 210 simulated flights): the lowest RMSE of all
methods on every one (the closest: the climb with seed 1 and its barometer 7 % high, 0.84 of
support's); 95.4 % of the true errors within +-2 ``fused_std`` over all, 0.31
to 1.00 per flight (the lowest on that climb), 88 of the flights within 0.90-0.99; with the
barometer in the airflow in a 2 m/s wind along the track (``baro-airflow``) 0.05-0.13 m (the
mission's wind told against the height smoothed without the barometer, 1.4-2.0 m/s; the
climb flies one way, where no wind can be told apart from the head), 0.41-0.55 for the
best other method. On the
simulators' 13 truth logs (``benchmarks/truth_accuracy.py``, ``docs/accuracy.md``): RMSE and
maximum error within the project's bar on all 13; the coverage 0.901-1.000, within 0.90-0.99
on 8 (0.994-1.000 on five, among them those whose sensors lag the truth least:
``TIMING_SIGMA_S``; the quadplane's, whose scale the smoother learns, 0.994).
Where GPS and barometer are alone through Paper A's
excursion, part of it is followed and ``fused_std`` is too small.

Implementation: one module per part. :mod:`.kalman` holds the textbook steps (predict,
innovation, update, the smoother's adjoint steps; filterpy's symbols, the equations as
comments), in place;
:mod:`.model` the state-space model (``F``, ``Q``, ``H``, prior, the ground constraint);
:mod:`.passes` the forward filter over the events (gate, lockout release) and the backward
pass, each one loop compiled by numba (:mod:`.compiled`); :mod:`.noise` the noises learnt from
the log; :mod:`.evidence` the model choice; :mod:`.events` the events and the contributions.
The passes are checked against filterpy's ``KalmanFilter.batch_filter`` and ``rts_smoother``
on a linear-Gaussian toy to 1e-9 (``tests/test_smoother_kalman.py``). filterpy itself is not
used here: each step carries one scalar measurement of any sensor, or none (a clock tick),
gated, and the gains per sensor are needed for the contributions. Cost is linear in the
number of events: 3-4 us an event over all its passes on a 1-hour flight with its 400 Hz IMU
and the GPS's velocity (``benchmarks/smoother_bench.py``; 6 us while numba counted the
references of the arrays its loops held, :mod:`altfuse.compiled`; 12 us with
Rauch-Tung-Striebel's O(n^3) gain), 1.7-2.0x ``support``'s time on a 300 MB log end to end
(5.0 s against 2.8 s; 3.6x before, 3.3x before the compiled passes), 403-408 MiB against
384-386 MiB, 1.40-1.42x the log (the backward pass filters each block of ``passes.BLOCK``
events again from a checkpoint, and each pass keeps only what its caller reads,
:class:`.passes.Keep`: 822 MiB when every event's covariance was kept).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from altfuse.datum.scale import Wind
from altfuse.fuse.base import FUSED, NONE, SINGLE, FusionInput, FusionResult, Jump, joined_jump
from altfuse.fuse.smoother.events import (
    TICK,
    VELOCITY,
    contributions,
    interval_mean,
    merge_events,
    on_every_event,
)
from altfuse.fuse.smoother.evidence import (
    JUMP_TOGETHER_S,
    STABLE_GAIN,
    Made,
    drift_evidence,
    dynamic_evidence,
    evidence_record,
    gps_evidence,
    jump_evidence,
    regain_evidence,
    relearnt_scales,
    smoothed_wind,
    thermal_evidence,
    wash_evidence,
)
from altfuse.fuse.smoother.model import (
    GPS_CORRELATION_S,
    STILL_SIGMA,
    Events,
    Layout,
    Regressor,
    cleared_events,
    datum_priors,
    dynamic_regressors,
    first_height,
    landed_events,
    reset_events,
    sensed_climb,
    sharing_air,
    still_events,
    thermal_regressors,
    unpinned_scales,
    wash_density,
)
from altfuse.fuse.smoother.noise import (
    JUMP_HALF_WIDTH_S,
    Q_ACCEL_NO_IMU,
    Q_OFFSET,
    Q_OFFSET_STABLE_GPS,
    Noise,
    accel_psd,
    accel_refused,
    accel_spikes,
    em_accel,
    em_scale,
    measurement_noise,
    offset_noise,
    state_noise,
    with_jumps,
)
from altfuse.fuse.smoother.passes import FOR_EM, FOR_RESULT, HEIGHT_ONLY, run
from altfuse.fuse.smoother.velocity import VELOCITY_NAME, checked_velocity, lag_regressor
from altfuse.memory import release_free_memory
from altfuse.model import SENSOR_KINDS, SENSOR_NAME, FloatArray, Samples
from altfuse.params import InvalidParameter, Params, fields, flag_of, param
from altfuse.steps import jump_instant

progress = logging.getLogger("altfuse.progress")  # as altfuse.pipeline.progress

#: EM iterations (each a forward and a backward pass) after the first pass.
EM_PASSES = 3
#: The model's check fails where a sensor's squared normalised innovations average more than
#: this: its innovations vary twice as much as the model says, and fused_std understates the
#: error where that sensor is fused. On the simulators' 16 truth logs the largest is 1.15; on
#: the real logs shared 1.98 but for two GPSs: 5.1 (a log whose GPS drifts 24 m from its EKF)
#: and 8.0 (a PX4 log whose GPS is up to 2 m off its EKF in 6 s).
NIS_CHECK = 2.0
#: The sensors' common latency behind the log's timestamps, unknown to the log [s], one
#: standard deviation: a sample is stamped when its driver delivers it, after the sensor
#: sampled (and averaged) the air or the ground. Where every sensor lags alike, nothing in the
#: log tells: against the accelerometer the fit is flat in the lag (a 305 m SITL climb: RMS
#: 0.024 m at 0 and at the best lag). Measured against the ArduPilot simulators' truth, the
#: fused height lags by -7 to +12 ms (0.9 on the Solo's, 7-12 on nine copters): at 2.5 m/s,
#: 1.7 cm, beyond the model's 2 sigma of 1.5 cm (the 305 m climb's climbs were covered 0.35). It
#: adds ``(v sigma)^2`` to the height's variance (``v`` the smoothed vertical velocity); the
#: estimate is unchanged. 5 ms, the least that leaves no truth log's band overconfident, by
#: the worst log of the 13 (``docs/accuracy.md``; ``benchmarks/timing_sigma.py``, as measured
#: since the sensors' agreement is also measured on blocks' means, :func:`.noise.wander_bound`):
#: coverage 0.627-0.994 with 0 (7 of 13 within 0.90-0.99), 0.863-0.995 with 4 ms (8 of 13:
#: 0.863 and 0.895 below, where the fused height lags 8-9 ms), 0.901-1.000 with 5 ms (8 of 13,
#: the five others 0.994-1.000: at most 0.010 out of the window, against 0.037), 0.913-1.000
#: with 6 ms (5 of 13). On altfuse's 210 flights, whose sensors lag 5-12 ms, the band is within
#: 0.90-0.99 on 88 with 5 ms, below on 23 (101 and 39 with 4 ms).
TIMING_SIGMA_S = 0.005
#: A refused sample's variance in :func:`scale_response`'s pass, whose gate is open: no weight.
REFUSED_VARIANCE = 1e30


#: The fields of :class:`SmootherParams` that hold a value per sensor, by its name.
PER_SENSOR = ("sigma_m", "offset_noise_m2_s")


@dataclass(frozen=True, kw_only=True)
class SmootherParams(Params):
    """What the smoother takes from the user; everything else it learns from the log."""

    gate_sigma: float = param(3.5, help="innovation gate", unit="sigma", check="positive")
    timing_sigma_s: float = param(
        TIMING_SIGMA_S,
        help="the sensors' common latency behind the log's timestamps, unknown: its standard "
        "deviation, which adds |v| times it to fused_std (0: timestamps exact)",
        unit="s",
        check="non-negative",
        maximum=1.0,
    )
    gps_correlation_s: float = param(
        GPS_CORRELATION_S,
        help="a GPS's vertical error's correlation time: its offset a Gauss-Markov process that "
        "wanders at its random walk's rate over shorter spans and is bounded over longer ones",
        unit="s",
        check="positive",
        maximum=1e6,
    )
    accel_noise_m2_s3: float | None = param(
        None,
        help="white acceleration noise density",
        unit="m^2/s^3",
        check="positive",
        default_text=f"from the accelerometer's noise, {Q_ACCEL_NO_IMU:g} without IMU",
    )
    sigma_m: Mapping[str, float] = param(
        {},
        help="a sensor's measurement noise",
        unit="m",
        check="positive",
        default_text="from the log",
    )
    offset_noise_m2_s: Mapping[str, float] = param(
        {},
        help="random-walk density of a sensor's offset (a rangefinder's ground height; a "
        "GPS's at spans short against its bound)",
        unit="m^2/s",
        check="positive",
        default_text=f"gps {Q_OFFSET['gps']:g} ({Q_OFFSET_STABLE_GPS['gps']:g} where the log shows "
        f"it stable), baro {Q_OFFSET['baro']:g}; rangefinder from the terrain and the speed",
    )

    def __post_init__(self) -> None:
        """A per-sensor value names a sensor as the readers name them
        (:data:`altfuse.model.SENSOR_NAME`),
        whether or not a log has it: ``lidar`` never fuses, ``rangefinder`` where a log has one
        (a batch's logs differ)."""
        super().__post_init__()
        for name in PER_SENSOR:
            if bad := sorted(k for k in getattr(self, name) if not SENSOR_NAME.match(k)):
                raise InvalidParameter(
                    name,
                    f"names no sensor altfuse reads: {', '.join(map(repr, bad))}; sensors are "
                    f"named {', '.join(SENSOR_KINDS)}, from the second of a kind on gps2, ...",
                )


def fuse_smoother(inputs: FusionInput, params: SmootherParams) -> FusionResult:
    """Kalman filter + fixed-interval smoother over the whole flight (see the module doc).

    From ``inputs``: each sensor's own referred ``samples`` (fused at their own times), its
    ``kinds`` and ``names``; ``z`` on the clock marks the ticks where no sensor is valid and gives
    the noise densities of the sensors' states; the clock ``t`` at which the result is reported;
    ``accel`` (None: the altitude-only random-walk model), ``track`` (the GPS's speed and
    course), ``wind`` (the datum's), ``temperatures`` (a barometer with them gets a temperature
    coefficient) and ``on_ground_s`` (there ``h = 0`` and ``v = 0``) when the log has them.
    All of them but ``t`` from ``analysis`` where it is given: the model is decided on the
    datum's clock, whatever the output's (at 20 Hz rather than 10, a 628 s copter log's
    barometer drift was modelled or not, and its height moved by 0.15 m).
    """
    clock, ticks = _clocks(inputs)
    names, kinds, samples = clock.names, clock.kinds, clock.samples
    m = len(samples)
    accel = None if clock.accel is None else clock.accel.samples
    use_imu = accel is not None and accel.t.size >= 2
    q_accel = Q_ACCEL_NO_IMU
    if params.accel_noise_m2_s3 is not None:
        q_accel = params.accel_noise_m2_s3
    elif use_imu and accel is not None:
        q_accel = accel_psd(*accel)
    velocity, velocity_refused = checked_velocity(clock)
    times, who, values, position = merge_events(samples, ticks, velocity)
    # the events the model is decided on: the samples and the analysis clock's ticks (None:
    # every event); the output's other ticks only read the state there
    model = None if clock is inputs else ~((who == TICK) & ~np.isin(times, clock.t))
    # each sample's variance: the local noise of its sensor times a scale refined by EM
    noise = measurement_noise(clock, params.sigma_m, (who, position), velocity)
    still = still_events(times, who, clock.on_ground_s, model)
    a, q_added = _accelerometer(clock, times, model)
    layout, ground = _layout(
        clock,
        (times, who, position),
        bool(still.any()),
        accel if use_imu else None,
        params.gps_correlation_s,
    )
    q_events, terrain = state_noise(clock, times, params.offset_noise_m2_s)
    climb = None if clock.landed is None else sensed_climb(clock.t, clock.z, clock.dt_s)
    landed = landed_events(times, who, clock.landed, clock.speed, climb, model) & ~still
    ev = Events(
        times, who, values, a, q_events, still, q_accel + q_added, use_imu, params.gate_sigma,
        first_height(who, values),
        landed, reset_events(times, clock.splices), model=model,
        cleared=cleared_events(times, who, clock.ground_effect_s, model),
    )  # fmt: skip
    del position, q_added  # in the noises, the layout and the events now
    r = noise.r(who)  # before EM: the local noises as they are
    steps, ev = _jumps(clock, ev, r, layout)
    ev, stable_gain, made = _gps_stability(clock, (ev, steps), r, layout, params.offset_noise_m2_s)
    physical = ev
    if params.offset_noise_m2_s:
        physical = replace(ev, q_state=with_jumps(state_noise(clock, times, {})[0], steps, times))
    layout, scale_gain, ev, physical = relearnt_scales(
        ev, physical, r, layout, clock.scale_unknown, clock.scale_known
    )
    # each test hands on the forward pass of the model it chose (``made``), which the next
    # reads where it is its own model's (the same events and layout) rather than filter again
    layout, dynamic_gain, airspeed, wind, made = _dynamic(
        clock, (physical, r, layout), ground, made
    )
    layout, thermal, made = thermal_evidence(physical, r, layout, kinds, made)
    layout, drifts = drift_evidence(ev, r, layout, kinds, made)
    layout, wash = _wash(clock, (ev, r), layout, steps)
    del made, r, ground
    release_free_memory()  # the tests' passes, before the smoothing ones
    floor = ev.q_accel
    ev, out = _smoothed(ev, layout, noise, floor if params.accel_noise_m2_s3 is None else None)

    # the states at the output's ticks (of the ticks of both clocks, where the model's are others)
    at = slice(None) if clock is inputs else np.searchsorted(ticks, inputs.t)
    xs, var_h, gain_h = out["x"][at], out["var_h"][at], out["gain_h"]
    series = [*enumerate(names)] + ([(VELOCITY, VELOCITY_NAME)] if velocity is not None else [])
    nis, rejected = _innovation_checks(out, who, series)
    # the barometers' scale error nothing in the log pins, as the smoothed height follows it
    scales = unpinned_scales(kinds, clock.scale_known, clock.scale_unknown, layout)
    if scales.any():
        var_h = var_h + scale_response(ev, noise.r(who), layout, out["accepted"], scales)[at] ** 2
    del out  # the events' states, before the result's arrays
    release_free_memory()
    weights, valid = contributions((times, who, gain_h), inputs.t, inputs.z, inputs.dt_s)
    n_valid = np.isfinite(inputs.z).sum(axis=1)
    status = np.where(n_valid == 1, SINGLE, np.where(valid, FUSED, NONE))
    return FusionResult(
        method="smoother",
        fused=np.where(valid, xs[:, 0], np.nan),
        weights=weights,
        status=status,
        # the states where a sensor is (in a pause of every sensor they are the model's guess)
        traces={"offset": np.where(valid[:, None], xs[:, 3 : 3 + m], np.nan)},
        tick_traces={
            "fused_std": np.where(valid, fused_std(var_h, xs[:, 1], params.timing_sigma_s), np.nan),
            "velocity": np.where(valid, xs[:, 1], np.nan),
            "accel_bias": np.where(valid, xs[:, 2], np.nan),
        },
        params={
            "model": "accelerometer-driven" if use_imu else "altitude-only random walk (no IMU)",
            "accel_noise_m2_s3": q_accel,
            # held at v = 0 where the autopilot said it had landed [s]
            "landed_held_s": float(landed.sum() * clock.dt_s),
            # where the smoothed flight asked for more than the accelerometer's own noise [s]
            "accel_noise_raised_s": float(
                np.diff(times, prepend=times[0])[ev.q_accel > floor].sum()
            ),
            "gate_sigma": params.gate_sigma,
            "timing_sigma_s": params.timing_sigma_s,
            "gps_correlation_s": params.gps_correlation_s,
            **evidence_record("stable", stable_gain > STABLE_GAIN, stable_gain, sensor="gps"),
            **wash,
            **evidence_record("scale", layout.has("scale"), scale_gain),
            **evidence_record("dynamic", layout.has("dynamic"), dynamic_gain),
            **({"baro_dynamic_speed": _SPEEDS[airspeed]} if layout.has("dynamic") else {}),
            **({} if wind is None else {"baro_dynamic_wind": f"{wind}, {_SMOOTHED_WIND}"}),
            **drifts,
            **thermal,
            **_fitted(names, ev, noise, layout, xs[-1]),
            **{f"q_terrain_{name}_m2_m": value for name, value in terrain.items()},
            # the GPS's vertical velocity: its samples fused, and refused by its heights' slope
            f"{VELOCITY_NAME}_samples": int((who == VELOCITY).sum()),
            f"{VELOCITY_NAME}_refused": velocity_refused,
            **rejected,
            **nis,
            "model_check": model_check(nis),
            **({"not_used": unused} if (unused := not_used(params, names)) else {}),
            # each step between two sensors (altfuse.steps) and whose jump the smoother made it:
            # "t s: +x m, gps" (the GPS jumped x), "t s: +x m, gps or baro" (the barometer's
            # heights less the GPS's jumped x, either may have)
            "steps": "; ".join(
                f"{time:.2f} s: {size:+.2f} m, {' or '.join(names[i] for i in sensors)}"
                for time, sensors, size, *_ in steps
            ),
        },
    )


def _smoothed(
    ev: Events, layout: Layout, noise: Noise, floor: FloatArray | None
) -> tuple[Events, dict[str, np.ndarray]]:
    """The smoothing passes with EM: each series' noise scale (in ``noise``, in place) and the
    acceleration noise, never below ``floor`` (None: a density the user gave, kept), refined
    by ``EM_PASSES`` M-steps, each followed by a pass; the events as refined, and the last
    pass."""
    keep = FOR_EM if EM_PASSES else FOR_RESULT
    out = run(ev, noise.r(ev.who), layout, keep=keep)
    for k in range(EM_PASSES):
        progress.info("smoother: noise pass %d of %d (%d events)", k + 1, EM_PASSES, ev.t.size)
        em_scale(ev, noise, out)
        # the height let loose where each episode of rejections that ended so began
        released = out["released"]
        ev = replace(ev, early=released if released.any() else None)
        states = out["x"]
        del out, released  # but its states, before em_accel's arrays
        if floor is not None:
            ev = em_accel(ev, states, floor)
        del states  # before the next pass's
        release_free_memory()
        keep = FOR_RESULT if k == EM_PASSES - 1 else FOR_EM
        out = run(ev, noise.r(ev.who), layout, keep=keep)
    return ev, out


def scale_response(
    ev: Events, r: FloatArray, layout: Layout, accepted: np.ndarray, scales: FloatArray
) -> FloatArray:
    """How far the smoothed height at each tick moves for the barometers' scale errors
    ``scales`` (per sensor, 0 for the others; each barometer reading ``(1 + e) h``): the
    smoother's response to their samples' heights times them alone, every other sample and the
    accelerometer 0, with the variances ``r``, the model ``layout`` and the samples
    ``accepted`` of the pass it answers for (given them the filter and the smoother are linear:
    one more pass). One error for every barometer: most of a barometer's scale error is the
    air's (its temperature against the standard atmosphere's), the same for each of them.

    A scale error is a slow one, and the smoothed height's level follows the sensors whose
    offsets the model holds steadiest, not those with the largest gain on it: beside a GPS
    sampled at 5 Hz a barometer's share of the gain is a tenth, while the height follows its
    level (a real log, its barometer 1.3 m above its GPS at 9 m: response 0.6 of it)."""
    sensors = np.maximum(ev.who, 0)
    perturbed = replace(
        ev,
        z=np.where(ev.who >= 0, scales[sensors] * ev.z, 0.0),
        a=np.zeros_like(ev.a),
        gate=math.inf,
        h0=0.0,
    )
    # a sample the pass refused says nothing here either
    variances = np.where(accepted | (ev.who == TICK), r, REFUSED_VARIANCE)
    return np.asarray(run(perturbed, variances, layout, keep=HEIGHT_ONLY)["x"][:, 0])


def _innovation_checks(
    out: dict[str, np.ndarray], who: np.ndarray, series: list[tuple[int, str]]
) -> tuple[dict[str, float], dict[str, int]]:
    """Per series of ``out``'s pass: the mean squared normalised innovation of its accepted
    samples (the model's check: 1 where its noise and the estimate's uncertainty are right;
    below, too pessimistic), and how many of its samples were rejected."""
    accepted = out["accepted"]
    nis = {
        f"nis_{name}": float(np.mean(out["nu"][(who == i) & accepted] ** 2))
        for i, name in series
        if ((who == i) & accepted).any()
    }
    return nis, {f"rejected_{name}": int(((who == i) & ~accepted).sum()) for i, name in series}


def fused_std(var_h: FloatArray, v: FloatArray, timing_sigma_s: float) -> FloatArray:
    """The height's standard deviation: the model's, and the sensors' unknown common latency
    (``timing_sigma_s``) at the smoothed vertical velocity ``v``: a height read ``tau`` late is
    ``v tau`` off."""
    return np.asarray(np.sqrt(np.maximum(var_h, 0.0) + (v * timing_sigma_s) ** 2))


def _layout(
    inputs: FusionInput,
    events: tuple[FloatArray, np.ndarray, np.ndarray],
    standing: bool,
    accel: Samples | None,
    correlation_s: float,
) -> tuple[Layout, list[Regressor]]:
    """The model's states before the tests: the offsets (their priors from the datum where no
    span stands still, ``standing``; a GPS's bounded, of correlation time ``correlation_s``),
    each barometer's temperature coefficient (with a sensor other than a barometer), and the
    vertical velocity's lag where the accelerometer (``accel``) tells it; and the barometers'
    dynamic-pressure coefficients at the ground speed (with a sensor other than a barometer),
    offered to a test of their own (:func:`_dynamic`)."""
    times, who, position = events
    samples = inputs.samples
    # barometers alone: nothing tells a temperature or a dynamic head from the height
    alone = set(inputs.kinds) == {"baro"}
    regressors = [] if alone else thermal_regressors(inputs.temperatures, samples, who, position)
    if accel is not None and (who == VELOCITY).any():
        regressors.append(lag_regressor(who, times, accel))
    layout = Layout(
        np.array([-1.0 if k == "rangefinder" else 1.0 for k in inputs.kinds]),
        tuple(regressors),
        offset_prior=None if standing else datum_priors(samples, inputs.datum_windows),
        bounded=tuple(i for i, k in enumerate(inputs.kinds) if k == "gps"),
        correlation_s=correlation_s,
        shared=sharing_air(inputs.kinds),
    )
    if alone or inputs.speed is None:
        return layout, []
    return layout, dynamic_regressors(inputs.speed, inputs.kinds, (times, who))


def _wash(
    inputs: FusionInput, model: tuple[Events, FloatArray], layout: Layout, steps: Sequence[Jump]
) -> tuple[Layout, dict[str, float | str]]:
    """``layout`` with the barometers' error in the rotors' wash in the datum's spans
    (:attr:`FusionInput.ground_effect_s`) where the log's evidence asks for it
    (:func:`.evidence.wash_evidence`, with ``model``'s events and variances), and the test's
    record. The wash's prior at the first event is STILL_SIGMA, or where the log begins in a
    span, what its random walk has gathered since the span began. Not offered where one of the
    ``steps`` between sensors lies in a span: the sensor that jumped is told there, and a wash
    beside the jump explains its step too (a real log's second GPS stepped 2 m at its take-off
    moved the fused height 0.073 m RMSE with it, 0.017 without; mid-flight, 0.006 either way).
    A barometer 1 m low in the wash is such a step, and made a jump (``wash-1``).

    The last test, when the rest of the model is chosen. First, the barometers' scale and
    airflow in the climb out of the span were taken for a wash on five of altfuse's simulated
    missions and climbs (0.040-0.126 m RMSE, up to 0.069 where 0.046); first and again last,
    the tests between chose beside a wash the last one then dropped (a real log's barometer
    stepped at its take-off: its drift, 0.845 -> 1.041 m from its EKF). Last, the 10 m sonar
    flight with its barometers 0.5 m low keeps a GPS that the stable model refuses beside the
    unmodelled wash: 0.088 m RMSE (0.020 first)."""
    ev, r = model
    spans = inputs.ground_effect_s
    if not (layout.shared and spans):
        return layout, {}
    if any(lo <= step[0] <= hi for step in steps for lo, hi in spans):
        return layout, {"baro_wash": "not tested (a step between sensors lies in its span)"}
    first = float(ev.t[0])
    walked = sum(wash_density(s) * (first - s[0]) for s in spans if s[0] < first <= s[1])
    prior = math.sqrt(STILL_SIGMA**2 + walked)
    washing = replace(layout, wash_spans=tuple(spans), wash_prior=prior)
    return wash_evidence(ev, r, (layout, washing), inputs.kinds, spans)


def _dynamic(
    inputs: FusionInput,
    model: tuple[Events, FloatArray, Layout],
    ground: list[Regressor],
    made: Made | None,
) -> tuple[Layout, float, int, Wind | None, Made | None]:
    """:func:`.evidence.dynamic_evidence` on the barometers' dynamic pressure at the ground
    speed (``ground``: :func:`_layout`'s) and, where the log has the GPS's course and a steady
    wind is known, at the airspeed it leaves (in ``_SPEEDS``' order); ``model``: the events,
    their variances and the layout, ``made`` a pass made already. The wind is the datum's
    (``inputs.wind``) or, where it found none, the one the barometers' readings tell against
    the height smoothed without them (:func:`.evidence.smoothed_wind`), returned (None: none,
    or the datum's), before the pass of the layout chosen."""
    ev, r, layout = model
    track = inputs.track
    if track is None or track.course is None or not ground:
        found, gain, taken, made = dynamic_evidence(ev, r, layout, [[], ground], made)
        return found, gain, taken, None, made
    wind, told = inputs.wind, None
    if wind is None:
        wind = told = smoothed_wind(ev, r, layout, inputs.kinds, track)
        release_free_memory()  # that pass's, before the test's
    airspeed = (
        []
        if wind is None
        else dynamic_regressors(track.airspeed(wind), inputs.kinds, (ev.t, ev.who))
    )
    found, gain, taken, made = dynamic_evidence(ev, r, layout, [airspeed, ground], made)
    return found, gain, taken, told, made


def _jumps(
    inputs: FusionInput, ev: Events, r: FloatArray, layout: Layout
) -> tuple[tuple[Jump, ...], Events]:
    """The steps between two sensors (``inputs.steps``), each given to the one that jumped
    where the log's evidence tells (:func:`.evidence.jump_evidence`), and ``ev`` (its offsets'
    densities without jumps) with them: that sensor's samples after it moved back by its
    jump. Its offset may still jump (the step's size is measured on
    the clock, not on its samples), but a GPS's offset is bounded (``gps_correlation_s``) and
    returns to its mean: left to its offset, a simulator's GPS stepped 1 m drew the height 0.12
    m off both sensors over the next two minutes."""
    if not inputs.steps and not inputs.tentative:
        return (), ev
    windowed = partial(_windowed, inputs)
    steps = jump_evidence(ev, (r, layout), inputs.steps, windowed) if inputs.steps else ()
    steps = _once(steps + regain_evidence(ev, (r, layout), steps, inputs.tentative, windowed))
    z = ev.z.copy()
    for time, sensors, size, *_ in steps:
        if len(sensors) == 1:
            z[(ev.who == sensors[0]) & (ev.t > time)] -= size
    return steps, replace(ev, z=z, q_state=with_jumps(ev.q_state, steps, ev.t))


def _once(jumps: Sequence[Jump]) -> tuple[Jump, ...]:
    """``jumps`` with one sensor's own jumps within JUMP_TOGETHER_S of each other made one, at
    the first's instant, of their mean size. A GPS's jump is a step against each barometer;
    against one that lost its samples around it, the step lies in that gap's middle, seconds
    away, and is another event: both went to the GPS, placed at the instant of its own jump
    (:func:`_windowed`), and its samples were moved back twice (a 2 m jump made 4 m)."""
    groups: list[list[Jump]] = []
    for jump in sorted(jumps, key=lambda j: j[0]):
        one = len(jump[1]) == 1
        same = [
            g for g in groups if one and g[0][1] == jump[1] and jump[0] - g[0][0] <= JUMP_TOGETHER_S
        ]
        if same:
            same[-1].append(jump)
        else:
            groups.append([jump])
    return tuple(joined_jump(g, g[0][1], g[0][3]) for g in groups)


def _windowed(inputs: FusionInput, jump: Jump) -> Jump:
    """``jump`` (half the gap it was found across last: :func:`altfuse.steps.find_steps`)
    with the half-width of the window its jump lies in instead (:func:`.noise.with_jumps`):
    JUMP_HALF_WIDTH_S about the step; where it was found across another sensor's gap (it lies
    anywhere in the gap, placed in its middle) and is one sensor's, within a clock tick of
    the instant that sensor's own heights jump the most (:func:`altfuse.steps.jump_instant`).
    Two barometers stepped 1 m 2.8 s after a GPS's 13 s gap began: their jump placed in the
    gap's middle could not explain their step, the GPS's jump unseen in its gap could, and
    they were followed, 0.663 m RMSE (0.004 with their jump at their step; the GPS's 0.005).
    """
    time, sensors, size, half, settle = jump
    if len(sensors) == 1 and half > JUMP_HALF_WIDTH_S:
        instant = jump_instant(inputs.t, inputs.z[:, sensors[0]], (time - half, time + half))
        if instant is not None:
            return instant, sensors, size, inputs.dt_s, settle
    return time, sensors, size, JUMP_HALF_WIDTH_S, settle


def _gps_stability(
    inputs: FusionInput,
    events: tuple[Events, Sequence[Jump]],
    r: FloatArray,
    layout: Layout,
    given: Mapping[str, float],
) -> tuple[Events, float, Made | None]:
    """``ev`` with the GPS offsets as stable as a barometer's (their jumps at ``steps`` kept)
    where the log's evidence asks for it (:func:`.evidence.gps_evidence`), that evidence and
    the forward pass of the events chosen; no test (NaN, None) without a GPS, or where the user
    gave the offsets' random walks."""
    ev, steps = events
    if given or "gps" not in inputs.kinds:
        return ev, math.nan, None
    # GPS and barometers take the stable densities (each bounded anew by their agreement); a
    # rangefinder's ground height keeps its own
    steady = np.array([kind != "rangefinder" for kind in inputs.kinds])
    stable = ev.q_state.copy()
    offsets = offset_noise(inputs, {}, Q_OFFSET_STABLE_GPS)[np.newaxis, :]
    stable[:, steady] = with_jumps(offsets, steps, ev.t)[:, steady]
    return gps_evidence(ev, r, layout, stable, inputs.kinds)


def model_check(nis: Mapping[str, float]) -> str:
    """The model's own check of its noises: "passed", or "failed: " and the sensors whose
    squared normalised innovations (``nis``, by ``nis_<sensor>``) average above NIS_CHECK."""
    failed = [f"{k[4:]} {v:.2f}" for k, v in nis.items() if v > NIS_CHECK]
    if not failed:
        return "passed"
    return (
        f"failed: mean squared normalised innovation {', '.join(failed)} (1 where the model "
        "holds): fused_std understates the error there"
    )


def _clocks(inputs: FusionInput) -> tuple[FusionInput, FloatArray]:
    """The inputs the model is decided on (``inputs.analysis``, else ``inputs``) and the
    ticks the filter steps through: theirs, and the output's among them."""
    if inputs.analysis is None:
        return inputs, inputs.t
    return inputs.analysis, np.union1d(inputs.analysis.t, inputs.t)


def _accelerometer(
    inputs: FusionInput, times: FloatArray, model: np.ndarray | None
) -> tuple[FloatArray, FloatArray]:
    """The mean vertical acceleration over each event interval (0 without the IMU), and the
    acceleration noise density [m^2/s^3] its spikes and the sensors' refusals add there
    (without the IMU, the sensors' refusals of a constant velocity). Both over the intervals
    between the ``model`` events (None: all), the others taking their interval's
    (:func:`.events.model_intervals`)."""
    if model is not None:
        a, added = _accelerometer(inputs, times[model], None)
        return on_every_event(a, model), on_every_event(added, model)
    vertical = inputs.accel
    on_clock = np.zeros(inputs.t.size) if vertical is None else np.nan_to_num(vertical.on_clock)
    added = interval_mean(Samples(inputs.t, accel_refused(inputs, on_clock)), times)
    if vertical is None or vertical.samples.t.size < 2:
        return np.zeros(times.size), np.nan_to_num(added)
    accel = vertical.samples
    added += interval_mean(Samples(accel.t, accel_spikes(*accel)), times)
    return np.nan_to_num(interval_mean(accel, times)), np.nan_to_num(added)


#: The speeds a barometer's dynamic pressure is offered at (:func:`_layout`), as recorded.
_SPEEDS = (
    "the airspeed: the ground velocity less a steady wind (the datum's, or baro_dynamic_wind)",
    "the ground speed (the air taken as still)",
)
_SMOOTHED_WIND = "told by the barometers against the height smoothed without them"

#: How each regressor is recorded: the key's pattern and unit.
_RECORD = {
    "thermal": "thermal_{}_m_per_degC",
    "scale": "scale_error_{}",
    "lag": "lag_{}_s",
    "dynamic": "dynamic_pressure_{}",
}


def _fitted(
    names: Sequence[str], ev: Events, noise: Noise, layout: Layout, last: FloatArray
) -> dict[str, float]:
    """What the smoother learnt of each sensor, for the record: its noise (the median over its
    samples; the vertical velocity's too), its offset's random walk (the median over the
    flight) and its regressors (a barometer's temperature coefficient, ...)."""
    sensor_q = np.median(ev.q_state, axis=0)
    who, sigma = ev.who, np.sqrt(noise.r(ev.who))
    keys = [(i, f"sigma_{name}_m") for i, name in enumerate(names)]
    return {
        **{
            key: float(np.median(sigma[who == i]))
            for i, key in [*keys, (VELOCITY, f"sigma_{VELOCITY_NAME}_m_s")]
            if (who == i).any()
        },
        **{f"q_offset_{name}_m2_s": float(sensor_q[i]) for i, name in enumerate(names)},
        **{
            f"offset_prior_{name}_m": float(layout.offset_prior[i])
            for i, name in enumerate(names)
            if layout.offset_prior is not None
        },
        **{
            _RECORD[r.name].format(
                VELOCITY_NAME if r.sensor == VELOCITY else names[r.sensor]
            ): float(last[layout.index(j)])
            for j, r in enumerate(layout.regressors)
        },
    }


def not_used(params: SmootherParams, names: Sequence[str]) -> str:
    """The per-sensor values given for sensors this log does not have (``names``: its
    sensors'), not used: ``"sigma_m (--sigma): rangefinder"``, one such part per field, ``""``
    where every value was used. They were an error, which failed every log of a batch without
    the sensor (``--sigma rangefinder=0.05`` over a fleet's logs: 5 of 8 failed); the metadata
    records them, and the commands say so with the log's name."""
    per_sensor = [f for f in fields(SmootherParams) if f.name in PER_SENSOR]
    unused = {f: sorted(set(getattr(params, f.name)) - set(names)) for f in per_sensor}
    return "; ".join(f"{f.name} ({flag_of(f)}): {', '.join(u)}" for f, u in unused.items() if u)
