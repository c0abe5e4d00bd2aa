"""Fusion methods. ``METHODS`` is the only registry: the CLI's ``--method`` choices, each
method's options and the contract tests all come from it, so a method is added by writing its
module and registering it here.

Every method is a :class:`Method`: a function ``(FusionInput, Params) -> FusionResult``, its frozen
parameter type, and the log inputs it asks the pipeline for (``uses``, ``requires``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from altfuse.errors import ParameterError
from altfuse.fuse.base import FusionInput, FusionResult, Method
from altfuse.fuse.complementary import MultilayerParams, fuse_multilayer
from altfuse.fuse.delay import DelayParams, fuse_delay1, fuse_delay2
from altfuse.fuse.mean import fuse_mean
from altfuse.fuse.smoother import SmootherParams, fuse_smoother
from altfuse.fuse.support import SupportParams, fuse_support
from altfuse.params import InvalidParameter, Params, fields

METHODS: dict[str, Method[Any]] = {
    "mean": Method(fuse_mean, Params, "equal weights (Paper A's baseline)"),
    "support": Method(fuse_support, SupportParams, "observation-support weighting (Paper A)"),
    "delay1": Method(fuse_delay1, DelayParams, "one-step delay fusion (Paper B's baseline)"),
    "delay2": Method(fuse_delay2, DelayParams, "two-step delay fusion (Paper B, layer 1)"),
    "multilayer": Method(
        fuse_multilayer,
        MultilayerParams,
        "two-step delay and a complementary filter with the accelerometer (Paper B)",
        uses=frozenset({"accel"}),
        requires=frozenset({"accel"}),
    ),
    "smoother": Method(
        fuse_smoother,
        SmootherParams,
        "offline Kalman smoother over the whole flight",
        uses=frozenset({"accel"}),
    ),
}

#: The method run when none is named: chosen by measurement, the worst case per log over the
#: simulators' 13 truth logs and altfuse's simulated flights (docs/accuracy.md). The smoother
#: is the lowest RMSE on 198 of 198 simulated flights, within the project's bar on RMSE and
#: maximum error on all 13 truth logs (support: 9), the only method with a fused_std, and
#: 1.7-2.0x support's time on a 300 MB log, three interleaved pairs (4.9-5.3 s against 2.6-2.8 s
#: whole process; docs/reading.md).
DEFAULT_METHOD = "smoother"


def method(name: str) -> Method[Any]:
    """The registered method ``name``, or a :class:`ParameterError` naming the choices."""
    if name not in METHODS:
        raise ParameterError(f"unknown method {name!r}; choose one of {', '.join(METHODS)}")
    return METHODS[name]


def params_for(name: str, values: Mapping[str, Any]) -> Params:
    """Method ``name``'s parameters from ``values`` by field name, the others at their
    defaults; a name the method does not take is refused, saying which it takes."""
    params_type = method(name).params
    taken = [f.name for f in fields(params_type)]
    unknown = sorted(set(values) - set(taken))
    if unknown:
        takes = f"it takes {', '.join(taken)}" if taken else "it takes none"
        raise InvalidParameter(unknown[0], f"is not a parameter of method {name!r}; {takes}")
    params: Params = params_type(**values)
    return params


def params_by_method(values: Mapping[str, Any], names: Iterable[str]) -> dict[str, Params]:
    """The parameters of each method in ``names`` that takes any of ``values`` (by field
    name; every such method gets the value), the rest at their defaults; a value none of them
    takes is refused."""
    names = list(names)
    taken = {n: {f.name for f in fields(method(n).params)} for n in names}
    unused = sorted(v for v in values if not any(v in t for t in taken.values()))
    if unused:
        which = f"method {names[0]!r}" if len(names) == 1 else f"any of {', '.join(names)}"
        raise InvalidParameter(unused[0], f"does not apply to {which}")
    given = {n: {k: v for k, v in values.items() if k in taken[n]} for n in names}
    return {n: params_for(n, mine) for n, mine in given.items() if mine}


__all__ = [
    "METHODS",
    "FusionInput",
    "FusionResult",
    "Method",
    "method",
    "params_by_method",
    "params_for",
]
