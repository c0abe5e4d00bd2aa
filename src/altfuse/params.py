"""Typed parameters: frozen dataclasses whose fields say their unit, their help and their checks.

A field made with :func:`param` ends its name in its unit (``time_constant_s``, ``e_max_m``,
``alpha_per_m2``; :data:`UNIT_SUFFIXES`), and the dataclass checks every field when it is built
(:class:`Params`, :func:`validate`): its type (numbers, a ``Literal``'s choices, a mapping of
sensor names to numbers) and its range. A bad value raises :class:`InvalidParameter`, which names
the field, as the library knows it; the command line renders it as the flag of that field
(:func:`flag_of`), so one definition gives the library's check, the CLI option and its help.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from altfuse.errors import ParameterError

#: The unit a field is measured in, and the suffix its name ends in.
UNIT_SUFFIXES = {
    "s": "_s",
    "m": "_m",
    "Hz": "_hz",
    "m^2/s": "_m2_s",
    "m^2/s^3": "_m2_s3",
    "1/m^2": "_per_m2",
    "sigma": "_sigma",
    "": "",
}

Check = Literal["positive", "non-negative", "at least 1", "any"]
_CHECKS: dict[Check, tuple[Callable[[float], bool], str]] = {
    "positive": (lambda v: v > 0, "a positive number"),
    "non-negative": (lambda v: v >= 0, "a number >= 0"),
    "at least 1": (lambda v: v >= 1, "a whole number >= 1"),
    "any": (lambda _v: True, "a number"),
}


#: The largest number any parameter takes, in its unit, where its own ``maximum`` is not
#: lower. None means anything beyond it (1e9 s is 31 years, 1e9 m beyond the Moon), and some
#: overflowed long before a float does, an internal error where a usage error belongs: a
#: support window of 1e100 s was more ticks than an integer holds, a multilayer time constant
#: of 1e308 s squared to infinity, an acceleration noise of 1e308 m^2/s^3 or a sensor's noise
#: of 1e308 m left NaN and infinity in the metadata. Every method ran on each of its fields at
#: 1e15, on three logs (an ArduPilot sample, a PX4 log, a log without IMU).
LARGEST = 1e9


class InvalidParameter(ParameterError):
    """A parameter value that means nothing, named as the library names it (``beta``)."""

    def __init__(self, name: str, problem: str) -> None:
        super().__init__(f"{name} {problem}")
        self.name = name
        self.problem = problem


def param(  # noqa: PLR0913 (keyword-only: a field's metadata, by name)
    default: Any,
    *,
    help: str,
    unit: str = "",
    check: Check = "any",
    maximum: float = LARGEST,
    default_text: str | None = None,
    flag: str | None = None,
    aliases: tuple[str, ...] = (),
) -> Any:
    """A dataclass field with its metadata: ``help``, ``unit`` (its name ends in the unit's
    suffix), ``check`` and ``maximum`` on numbers (:data:`LARGEST` unless lower),
    ``default_text`` for a default chosen at run time (a ``None`` default: "from the data"),
    and the command line's ``flag`` where the name does not make one that says what it is,
    with older ``aliases`` still taken (not shown). A mapping default is copied per
    instance."""
    metadata = {
        "help": help,
        "unit": unit,
        "check": check,
        "maximum": maximum,
        "default_text": default_text,
        "flag": flag,
        "aliases": aliases,
    }
    if isinstance(default, Mapping):
        return dataclasses.field(default_factory=lambda: dict(default), metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def fields(cls: type[Any] | Any) -> tuple[dataclasses.Field[Any], ...]:
    """The :func:`param` fields of a parameter dataclass (or instance)."""
    return tuple(f for f in dataclasses.fields(cls) if "help" in f.metadata)


def unit_of(f: dataclasses.Field[Any]) -> str:
    return str(f.metadata["unit"])


def flag_of(f: dataclasses.Field[Any]) -> str:
    """The command line's flag of a field: its ``flag``, else its name less the unit's suffix
    (``time_constant_s`` -> ``--time-constant``)."""
    if f.metadata.get("flag"):
        return str(f.metadata["flag"])
    stem = f.name.removesuffix(UNIT_SUFFIXES[unit_of(f)]) if unit_of(f) else f.name
    return "--" + stem.replace("_", "-")


def hints(cls: type[Any]) -> dict[str, Any]:
    """The resolved type of each field (the annotations are strings here)."""
    return typing.get_type_hints(cls)


def is_number(value: Any) -> bool:
    """A real number, not a truth value: Python's and numpy's (``np.float32(1)``, ``np.int64``,
    which are no ``float`` nor ``int``: refused as "must be a positive number" before)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _check_value(f: dataclasses.Field[Any], hint: Any, value: Any) -> Any:
    """``value`` checked against the field's type and range; returned as stored (floats as
    float, mappings as a new dict)."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is Literal:
        if value not in args:
            choices = ", ".join(map(str, args))
            raise InvalidParameter(f.name, f"must be one of {choices}, got {value!r}")
        return value
    if origin in (Mapping, dict) or hint is Mapping:
        if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
            raise InvalidParameter(f.name, f"must map sensor names to numbers, got {value!r}")
        return {k: _check_value(f, args[1], v) for k, v in value.items()}
    if type(None) in args:
        if value is None:
            return None
        hint = next(a for a in args if a is not type(None))
    test, wanted = _CHECKS[f.metadata["check"]]
    whole = hint is int
    if not is_number(value) or (whole and not float(value).is_integer()):
        raise InvalidParameter(f.name, f"must be {wanted}, got {value!r}")
    if not (math.isfinite(value) and test(value)):
        raise InvalidParameter(f.name, f"must be {wanted}, got {value!r}")
    if value > f.metadata["maximum"]:
        limit = f.metadata["maximum"]
        raise InvalidParameter(f.name, f"must be at most {limit:g}, got {value!r}")
    return int(value) if whole else float(value)


def validate(obj: Any) -> None:
    """Check every :func:`param` field of the frozen dataclass ``obj``, storing each value in
    its canonical form (an ``int`` given for a float field becomes a float)."""
    types = hints(type(obj))
    for f in fields(obj):
        checked = _check_value(f, types[f.name], getattr(obj, f.name))
        object.__setattr__(obj, f.name, checked)


@dataclass(frozen=True)
class Params:
    """Base of every method's parameters: checked when built. A method without parameters
    takes ``Params()`` itself."""

    def __post_init__(self) -> None:
        validate(self)

    def check_tick(self, tick_s: float) -> None:
        """Refuse a clock of ticks ``tick_s`` [s] apart that the method cannot run on
        (:class:`InvalidParameter`); every clock is one for most."""
