"""Writing a run's outputs: the fused CSV, the weight traces, the JSON provenance sidecar.

Every file is written to a temporary file beside its target and renamed into place only when all
of them are complete, so a failure never leaves a half-written output behind.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from altfuse.errors import ParameterError

if TYPE_CHECKING:
    from altfuse.pipeline import FuseRun

FLOAT_FORMAT = "%.6f"


def fused_table(run: FuseRun) -> pd.DataFrame:
    """One row per tick: time, each sensor's referred height, the fused height, weights, support.

    Columns: ``time_s``; ``alt_<sensor>_m`` for each sensor (height above take-off);
    ``fused_alt_m``; ``fused_std_m`` (its standard deviation, where the method gives one);
    ``status`` (``fused``/``equal``/``single``/``none``); ``n_sensors``;
    ``weight_<sensor>`` (summing to 1); ``support_<sensor>`` (Paper A's r_i, where the method
    computes it).
    """
    ref, res = run.referred, run.result
    columns: dict[str, Any] = {"time_s": ref.t}
    for i, name in enumerate(ref.names):
        columns[f"alt_{name}_m"] = ref.h[:, i]
    columns["fused_alt_m"] = res.fused
    if "fused_std" in res.tick_traces:
        columns["fused_std_m"] = res.tick_traces["fused_std"]
    columns["status"] = res.status
    columns["n_sensors"] = np.isfinite(ref.h).sum(axis=1)
    for i, name in enumerate(ref.names):
        columns[f"weight_{name}"] = res.weights[:, i]
    if "support" in res.traces:
        for i, name in enumerate(ref.names):
            columns[f"support_{name}"] = res.traces["support"][:, i]
    table: pd.DataFrame = pd.DataFrame(columns)
    return table


def weights_table(run: FuseRun) -> pd.DataFrame:
    """The weight traces: normalised weights and every method-specific trace, per sensor."""
    ref, res = run.referred, run.result
    columns: dict[str, Any] = {"time_s": ref.t}
    for i, name in enumerate(ref.names):
        columns[f"weight_{name}"] = res.weights[:, i]
    for key, trace in res.traces.items():
        for i, name in enumerate(ref.names):
            columns[f"{key}_{name}"] = trace[:, i]
    columns.update(res.tick_traces)
    table: pd.DataFrame = pd.DataFrame(columns)
    return table


def default_meta_path(csv_path: Path) -> Path:
    """``out.csv`` -> ``out.meta.json``."""
    return csv_path.with_suffix(".meta.json")


Writer = Callable[[IO[Any]], None]


@contextlib.contextmanager
def atomic_outputs() -> Iterator[Callable[..., None]]:
    """Collect writes into temporary files; rename them into place, in staging order, on success
    only. ``stage(target, write, binary=False)`` hands ``write`` an open text (or binary) file."""
    staged: list[tuple[str, Path]] = []

    def stage(target: Path, write: Writer, binary: bool = False) -> None:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
        staged.append((tmp, target))
        if binary:
            with os.fdopen(fd, "wb") as raw:
                write(raw)
        else:
            with os.fdopen(fd, "w", newline="", encoding="utf-8") as text:
                write(text)

    try:
        yield stage
    except BaseException:
        for tmp, _ in staged:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        raise
    for tmp, target in staged:
        os.replace(tmp, target)


def refuse_existing(force: bool, *paths: Path | None) -> None:
    """An existing output is never overwritten without ``force`` (``--force``)."""
    for path in paths:
        if not force and path is not None and path.exists():
            raise ParameterError(f"{path} exists; --force overwrites it")


def write_json(data: Any) -> Writer:
    """A writer of strict JSON (no NaN)."""
    return lambda f: json.dump(data, f, indent=2, allow_nan=False, default=str)


def write_outputs(
    run: FuseRun,
    csv_path: str | Path,
    weights_path: str | Path | None = None,
    meta_path: str | Path | None = None,
    extra: dict[Path, tuple[Writer, bool]] | None = None,
) -> dict[str, str]:
    """Write the CSV, the optional weight traces and ``extra`` files (path: (writer, binary)),
    then the provenance sidecar, all or none. The sidecar is renamed into place last: a sidecar
    whose listed outputs all exist marks a complete set. Returns the files written, by role."""
    csv_path = Path(csv_path)
    meta = Path(meta_path) if meta_path else default_meta_path(csv_path)
    outputs = {"csv": csv_path, "meta": meta}
    if weights_path:
        outputs["weights"] = Path(weights_path)
    for path in extra or {}:
        outputs[path.suffix.lstrip(".") or path.name] = path
    # the sidecar names its siblings relative to itself: the same bytes wherever they are written
    listed = {role: os.path.relpath(path, meta.parent) for role, path in outputs.items()}
    provenance = dict(run.provenance, outputs=listed)
    with atomic_outputs() as stage:
        stage(
            csv_path, lambda f: fused_table(run).to_csv(f, index=False, float_format=FLOAT_FORMAT)
        )
        if weights_path:
            stage(
                Path(weights_path),
                lambda f: weights_table(run).to_csv(f, index=False, float_format=FLOAT_FORMAT),
            )
        for path, (write, binary) in (extra or {}).items():
            stage(path, write, binary)
        stage(meta, write_json(provenance))
    return {role: str(path) for role, path in outputs.items()}
