"""Parity of the vectorised reader with pymavlink, the authority on the format.

For every log in ../shared/logs/ardupilot, every sample log and fresh simulator output (faults
included): the same records of every type as pymavlink's sequential parser (``recv_msg``, which
resynchronises on damage like altfuse), and for the types altfuse reads, every numeric field equal
to pymavlink's decoded value (NaN where pymavlink gives NaN).
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from pymavlink import DFReader

from altfuse.io.dataflash import WANTED_TYPES, _Records
from altfuse.io.fastdf import index_file
from altfuse.io.framing import FORMAT_TO_STRUCT
from altfuse.simulate import applicable_faults, simulate_flight, write_simulated_log
from conftest import ROOT, SHARED_LOGS, ardupilot_logs, shared_log


def pymavlink_pass(path: Path) -> tuple[Counter[str], dict[str, list[object]]]:
    reader = DFReader.DFReader_binary(str(path))
    counts: Counter[str] = Counter()
    wanted: dict[str, list[object]] = {}
    try:
        while (msg := reader.recv_msg()) is not None:
            counts[msg.get_type()] += 1
            if msg.get_type() in WANTED_TYPES:
                wanted.setdefault(msg.get_type(), []).append(msg)
    finally:
        reader.close()
    return counts, wanted


def assert_parity(path: Path) -> None:
    counts, messages = pymavlink_pass(path)
    rec = _Records(index_file(path))
    assert rec.counts == dict(counts)
    for type_name, msgs in messages.items():
        fmt = rec.formats[type_name]
        for col, char in zip(fmt.columns, fmt.format, strict=False):
            if char in "nNZa":
                if char == "Z" or char == "N":
                    assert rec.text(type_name, col) == [getattr(m, col) for m in msgs]
                continue
            ours = rec.raw(type_name, col)
            theirs = np.array([float(getattr(m, col)) for m in msgs])
            np.testing.assert_array_equal(ours, theirs, err_msg=f"{path.name} {type_name}.{col}")


@pytest.mark.parametrize("name", ardupilot_logs() or ["(shared logs missing)"])
def test_shared_logs(name: str) -> None:
    assert_parity(shared_log(f"ardupilot/{name}"))


@pytest.mark.parametrize("log", sorted((ROOT / "sample_logs").glob("*.bin")), ids=lambda p: p.name)
def test_sample_logs(log: Path) -> None:
    assert_parity(log)


def test_fresh_simulator_output_with_every_fault(tmp_path: Path) -> None:
    for scenario in ("hover", "paper-a"):
        path = tmp_path / f"{scenario}.bin"
        faults = applicable_faults(scenario)
        write_simulated_log(simulate_flight(scenario, seed=9, faults=faults), path)
        assert_parity(path)


def test_shared_logs_are_present() -> None:
    shared_log("ardupilot")
    assert len(ardupilot_logs()) == 11, SHARED_LOGS


def test_format_table_is_pymavlinks() -> None:
    # altfuse holds a copy of the authority's table (importing pymavlink's costs 25 ms a run)
    assert FORMAT_TO_STRUCT == DFReader.FORMAT_TO_STRUCT
