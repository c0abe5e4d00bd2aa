"""Value objects passed between the stages. Times are float seconds on the log's clock
(``TimeUS / 1e6``), lengths are metres, angles radians, accelerations m/s²."""

from __future__ import annotations

import re
import reprlib
from dataclasses import dataclass, field, fields, is_dataclass, replace
from typing import Any, Literal, NamedTuple, get_args

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: The kinds of altitude source, in the order altfuse prefers them as a datum reference.
SensorKind = Literal["baro", "gps", "rangefinder"]
#: The orientation of a rangefinder that looks down, the one that measures a height: 25 in
#: ArduPilot's (``ROTATION_PITCH_270``, ``RNGFND1_ORIENT``'s default), PX4's and MAVLink's
#: (``MAV_SENSOR_ROTATION_PITCH_270``) rotation enums alike; one facing elsewhere (obstacle
#: avoidance, a ceiling) measures no altitude.
DOWNWARD = 25
SENSOR_KINDS: tuple[SensorKind, ...] = get_args(SensorKind)
#: What a series is: an altitude source, or a reference, speed or temperature beside them.
SeriesKind = Literal[
    SensorKind, "reference", "speed", "course", "velocity", "temperature", "landed"
]


def sensor_kind(kind: SeriesKind) -> SensorKind:
    """``kind`` as an altitude source's kind; ValueError for a reference, speed or temperature."""
    for k in SENSOR_KINDS:
        if kind == k:
            return k
    raise ValueError(f"{kind!r} is not an altitude source's kind")


def sensor_name(kind: str, instance: int) -> str:
    """The name every reader gives a sensor: its kind, numbered from the second of that kind
    on (instance 0: ``gps``, 1: ``gps2``)."""
    return kind if instance == 0 else f"{kind}{instance + 1}"


#: A name :func:`sensor_name` makes: what a per-sensor value (``--sigma gps2=0.5``) may name.
SENSOR_NAME = re.compile(rf"^(?:{'|'.join(SENSOR_KINDS)})(?:[2-9]|[1-9][0-9]+)?$")


class _Brief(reprlib.Repr):
    """The repr of a stage's value as a reader at a prompt wants it: an array as its first and
    last values and its shape, a long dict or tuple cut short, a value nested deeper than
    three levels as ``...``; where the dataclasses' own repr prints every sample of every
    sensor (a FlightLog: 126 kB; an evaluation: 420 kB)."""

    def __init__(self) -> None:
        super().__init__()
        self.maxlevel = 3
        self.maxdict = 4
        self.maxtuple = self.maxlist = 6
        self.maxstring = self.maxother = 200

    def repr_ndarray(self, x: npt.NDArray[Any], _level: int) -> str:
        shape = "x".join(map(str, x.shape)) or "scalar"
        if x.ndim != 1 or x.size == 0:
            return f"array({shape} {x.dtype})"
        show = (lambda v: f"{v:.6g}") if x.dtype.kind == "f" else repr
        head, tail = x[:2].tolist(), x[max(2, x.size - 2) :].tolist()
        ends = [*map(show, head), *(["..."] if x.size > 4 else []), *map(show, tail)]
        return f"array([{', '.join(ends)}], {shape} {x.dtype})"

    def repr_instance(self, x: object, level: int) -> str:
        if is_dataclass(x):
            names = [f.name for f in fields(x) if f.repr]
        elif isinstance(x, tuple) and hasattr(x, "_fields"):  # a NamedTuple
            names = list(x._fields)
        else:
            return super().repr_instance(x, level)
        if level <= 0:
            return f"{type(x).__name__}(...)"
        shown = (f"{n}={self.repr1(getattr(x, n), level - 1)}" for n in names)
        return f"{type(x).__name__}({', '.join(shown)})"


def counted(n: int, noun: str) -> str:
    """``n`` and ``noun``, plural but for one: ``"1 tick"``, ``"3 ticks"``, ``"0 ticks"``."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def brief_repr(self: object) -> str:
    """``__repr__`` for the values that hold samples: :class:`_Brief`'s."""
    return _BRIEF.repr(self)


_BRIEF = _Brief()


class Samples(NamedTuple):
    """A signal at its own sample times: time [s], value (SI units)."""

    t: FloatArray
    value: FloatArray

    def __repr__(self) -> str:
        return brief_repr(self)


@dataclass(frozen=True)
class Series:
    """One altitude source or reference as read from the log: samples at the log's own times.

    Attributes
    ----------
    name
        Column name in the output, e.g. ``gps``, ``gps2``, ``baro``, ``rangefinder``.
    kind
        ``gps``, ``baro`` or ``rangefinder`` for sensors; ``reference`` for references,
        ``speed`` and ``temperature`` for the series beside them.
    source
        Where it came from in the log, e.g. ``GPS.Alt[I=0]`` or ``CTUN.SAlt``.
    datum
        What zero means for the raw values: ``amsl`` (GPS), ``baro calibration``,
        ``ground below the vehicle`` (rangefinder), ``EKF origin``, ...
    t
        Sample times [s], sorted, on the log's clock.
    value
        Samples [m], height positive up.
    dropped
        Samples the reader left out, by reason (e.g. ``{"GPS Status < 3": 12}``).
    """

    __repr__ = brief_repr

    name: str
    kind: SeriesKind
    source: str
    datum: str
    t: FloatArray
    value: FloatArray
    dropped: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.t.shape != self.value.shape:
            raise ValueError(f"{self.name}: {self.t.shape} times for {self.value.shape} values")

    @property
    def is_raw_rangefinder(self) -> bool:
        """A rangefinder's own distance along the body's down axis (``RFND``, ``SONR``, PX4's
        ``distance_sensor``), not the autopilot's tilt-corrected ``CTUN.SAlt``: its driver's
        limits and clearance apply."""
        return self.kind == "rangefinder" and self.source.startswith(
            ("RFND", "SONR", "distance_sensor")
        )


#: A rangefinder's valid readings count in runs of three or more: one or two among readings out
#: of range (its noise crossing its minimum range on the ground) are the tail of that noise,
#: biased (dropped, the simulated hover's rangefinder RMSE went 0.044 -> 0.037 m). Copter trusts
#: its rangefinder from the third good reading in a row (``RANGEFINDER_HEALTH_MAX``).
RANGEFINDER_HEALTHY_READINGS = 3
FEW_IN_A_ROW = f"fewer than {RANGEFINDER_HEALTHY_READINGS} valid readings in a row"
#: A record without a time of its own logged before the first record that has one (Copter up
#: to 3.1 logs times in GPS and IMU records alone: ``altfuse.io.dataflash``) has none.
NO_TIME = "no time (logged before the first record with one)"


def usable_series(
    name: str,
    kind: SensorKind,
    source: str,
    datum: str,
    samples: Samples,
    invalid: dict[str, npt.NDArray[np.bool_]],
) -> Series | str:
    """A reader's altitude source: ``samples`` less those not finite, those in each ``invalid``
    mask, and a rangefinder's in runs of fewer than ``RANGEFINDER_HEALTHY_READINGS`` valid ones
    between invalid ones (each counted by reason in ``dropped``); or, where none is left, why."""
    t, value = samples
    timed, finite = np.isfinite(t), np.isfinite(value)
    keep = timed & finite
    dropped = {NO_TIME: int((~timed).sum())} if (~timed).any() else {}
    if (timed & ~finite).any():
        dropped["not a finite number"] = int((timed & ~finite).sum())
    for reason, mask in invalid.items():
        if (hit := keep & mask).any():
            dropped[reason] = int(hit.sum())
        keep &= ~mask
    if kind == "rangefinder":  # the runs the log begins and ends with may go on beyond it
        step = np.diff(np.concatenate(([0], keep.astype(np.int8), [0])))
        starts, stops = np.flatnonzero(step == 1), np.flatnonzero(step == -1)
        short = (stops - starts < RANGEFINDER_HEALTHY_READINGS) & (starts > 0)
        short &= stops < keep.size
        few = np.zeros(keep.size, dtype=bool)
        few[keep] = np.repeat(short, stops - starts)  # the runs, in turn, are what is kept
        if few.any():
            dropped[FEW_IN_A_ROW] = int(few.sum())
        keep &= ~few
    if not keep.any():
        detail = ", ".join(f"{n} {r}" for r, n in dropped.items()) or "no records"
        return f"{source}: no usable sample ({detail})"
    return Series(name, kind, source, datum, t[keep], value[keep], dropped)


@dataclass(frozen=True)
class Imu:
    """Specific force in the body frame (FRD) [m/s²] of the first IMU."""

    __repr__ = brief_repr

    source: str
    t: FloatArray
    acc: FloatArray  # shape (n, 3)


@dataclass(frozen=True)
class Vibration:
    """The accelerometer's quality as the autopilot logs it (VIBE) for the first IMU: the
    vibration levels [m/s²] (the standard deviation of the high-passed acceleration per axis)
    and the cumulative count of samples that clipped at the sensor's range."""

    __repr__ = brief_repr

    source: str
    t: FloatArray
    level: FloatArray  # shape (n, 3): X, Y, Z
    clips: FloatArray  # cumulative count


@dataclass(frozen=True)
class Attitude:
    """Vehicle attitude [rad], ZYX Euler angles as ArduPilot logs them in ATT; where the log gives
    the rotation as a quaternion (PX4's ``vehicle_attitude.q``: w, x, y, z, body FRD to NED),
    that too, and the rotation comes from it (no Euler round trip)."""

    __repr__ = brief_repr

    source: str
    t: FloatArray
    roll: FloatArray
    pitch: FloatArray
    yaw: FloatArray
    quaternion: FloatArray | None = None  # shape (n, 4), unit

    def down_at(self, t: FloatArray) -> FloatArray:
        """The last row of the body-to-NED rotation at times ``t`` (shape (n, 3)): a body
        vector's component down is its dot product with it, and its last element,
        ``cos(roll) cos(pitch)``, is the body's down axis against the vertical.

        From Euler angles ``(-sin(pitch), sin(roll) cos(pitch), cos(roll) cos(pitch))``,
        interpolated on the unwrapped angles (a roll from +179 deg to -179 deg turns 2 deg, not
        358 deg back through level); from a quaternion ``(2(xz - wy), 2(yz + wx), 1 - 2(x^2 +
        y^2))``, each component interpolated after the samples are put on one hemisphere
        (``q`` and ``-q`` are one rotation) and renormalised."""
        if self.quaternion is None:
            roll = np.interp(t, self.t, np.unwrap(self.roll))
            pitch = np.interp(t, self.t, np.unwrap(self.pitch))
            return np.column_stack(
                [-np.sin(pitch), np.sin(roll) * np.cos(pitch), np.cos(roll) * np.cos(pitch)]
            )
        q = self.quaternion.copy()
        flips = np.cumsum(np.concatenate(([False], np.sum(q[1:] * q[:-1], axis=1) < 0)))
        q[flips % 2 == 1] *= -1.0
        q = np.column_stack([np.interp(t, self.t, q[:, i]) for i in range(4)])
        w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
        return np.column_stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])


@dataclass(frozen=True)
class FlightLog:
    """Everything altfuse uses from one log, decoded and in SI units.

    ``sensors`` are the altitude inputs; ``references`` (EKF, AHRS, simulator truth) are
    never fused, only reported and compared against.
    """

    __repr__ = brief_repr

    path: str
    sha256: str
    size_bytes: int
    vehicle: str
    firmware: str
    sensors: tuple[Series, ...]
    references: tuple[Series, ...]
    imu: Imu | None
    attitude: Attitude | None
    record_counts: dict[str, int]
    skipped_bytes: int
    notes: tuple[str, ...] = ()
    dropped_sources: dict[str, str] = field(default_factory=dict)
    params: dict[str, float] = field(default_factory=dict)
    ground_speed: Series | None = None  # horizontal speed [m/s], kind "speed"
    ground_course: Series | None = None  # course over the ground [deg from north], "course"
    vertical_velocity: Series | None = None  # a GPS's vertical velocity up [m/s], "velocity"
    vibration: Vibration | None = None
    landed: Series | None = None  # the autopilot's own verdict: 1 on the ground, 0 flying
    # where the log has no verdict but its changes (Copter's EV records): the times [s] at
    # which the autopilot's land detector said the vehicle left the ground
    takeoffs: tuple[float, ...] = ()
    temperatures: dict[str, Series] = field(default_factory=dict)  # [degC] by sensor name
    # samples of the inputs beside the altitudes (IMU, ATT, ...) dropped by screening, by source
    dropped_inputs: dict[str, int] = field(default_factory=dict)
    # damage the reader met but could not count in bytes (a ULog's corruption flag), one line each
    damaged: tuple[str, ...] = ()
    reader: str = "DataFlash (altfuse.io.fastdf, pymavlink's formats)"  # what read the file

    def sensors_only(self) -> FlightLog:
        """The same without the samples beside the altitude sources (IMU, attitude, references,
        speeds, vibration, the landed flag, temperatures): all a fused run still reads of its
        log where it draws no figure and evaluates nothing (50 MB of a 300 MB log's)."""
        return replace(
            self, references=(), imu=None, attitude=None, ground_speed=None,
            ground_course=None, vertical_velocity=None, vibration=None, landed=None,
            temperatures={},
        )  # fmt: skip
