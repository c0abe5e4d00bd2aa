"""FMT records that lie about their records (issue 16): each is refused for its type, with the
reason, and the rest of the log is read; never a crash, never a barometer that reads
temperatures."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from altfuse.cli import cli
from altfuse.io import read_log
from altfuse.io.fastdf import FMT_TYPE, index_file
from conftest import SAMPLE_LOG

FMT_LENGTH = 89
NAME, FORMAT, COLUMNS = slice(5, 9), slice(9, 25), slice(25, 89)  # within a FMT record


def fmt_record(data: bytes, name: str) -> int:
    """The offset of the FMT record that defines ``name``."""
    index = index_file(SAMPLE_LOG)
    for at in index.offsets[index.types == FMT_TYPE].tolist():
        if data[at + NAME.start : at + NAME.stop].rstrip(b"\0") == name.encode():
            return int(at)
    raise AssertionError(f"no FMT of {name}")


def patched(data: bytes, at: int, field: slice, text: str) -> bytearray:
    out = bytearray(data)
    width = field.stop - field.start
    out[at + field.start : at + field.stop] = text.encode().ljust(width, b"\0")[:width]
    return out


def fused(tmp_path: Path, data: bytes) -> tuple[dict[str, object], str]:
    log = tmp_path / "damaged.bin"
    log.write_bytes(data)
    out = tmp_path / "out.csv"
    result = CliRunner().invoke(cli, ["-v", "fuse", str(log), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "Traceback" not in result.output
    return json.loads(out.with_suffix(".meta.json").read_text()), result.stderr


def baro_columns() -> tuple[bytes, int, str]:
    data = SAMPLE_LOG.read_bytes()
    at = fmt_record(data, "BARO")
    columns = data[at + COLUMNS.start : at + COLUMNS.stop].rstrip(b"\0").decode()
    return data, at, columns


def test_a_columns_list_that_does_not_match_its_format_is_not_read(tmp_path: Path) -> None:
    data, at, columns = baro_columns()
    assert columns == "TimeUS,I,Alt,Temp,Health"
    meta, stderr = fused(tmp_path, bytes(patched(data, at, COLUMNS, "," + columns)))
    names = [s["name"] for s in meta["sensors_used"]]  # type: ignore[attr-defined]
    assert "baro" not in names
    assert "gps" in names
    why = meta["sensors_dropped"]["BARO"]  # type: ignore[index]
    assert "6 columns for 5 fields" in why
    assert "BARO: not read" in stderr


def test_a_number_declared_as_text_is_not_read(tmp_path: Path) -> None:
    data, at, _ = baro_columns()
    fmt = data[at + FORMAT.start : at + FORMAT.stop].rstrip(b"\0").decode()
    assert fmt == "QBffB"
    meta, _ = fused(tmp_path, bytes(patched(data, at, FORMAT, "QBnfB")))  # Alt as char[4]
    assert "baro" not in [s["name"] for s in meta["sensors_used"]]  # type: ignore[attr-defined]
    assert "declared as text ('n')" in meta["sensors_dropped"]["BARO.Alt"]  # type: ignore[index]


def test_an_instance_field_of_thousands_of_values_is_not_thousands_of_sensors(
    tmp_path: Path,
) -> None:
    data, at, _ = baro_columns()
    swapped = patched(data, at, COLUMNS, "I,TimeUS,Alt,Temp,Health")  # 24,002 sensors, once
    meta, _ = fused(tmp_path, bytes(swapped))
    names = [s["name"] for s in meta["sensors_used"]]  # type: ignore[attr-defined]
    assert not any(n.startswith("baro") for n in names)
    assert "distinct instance numbers" in meta["sensors_dropped"]["BARO.I"]  # type: ignore[index]
    assert len(json.dumps(meta["sensors_dropped"])) < 1000


def test_a_type_redefined_mid_file_is_refused_not_misread(tmp_path: Path) -> None:
    data, at, _ = baro_columns()
    # the same record layout, Alt and Temp's names exchanged, inserted at a record boundary
    again = bytes(patched(data[at : at + FMT_LENGTH], 0, COLUMNS, "TimeUS,I,Temp,Alt,Health"))
    index = index_file(SAMPLE_LOG)
    middle = int(index.offsets[index.offsets.size // 2])
    meta, _ = fused(tmp_path, data[:middle] + again + data[middle:])
    assert "baro" not in [s["name"] for s in meta["sensors_used"]]  # type: ignore[attr-defined]
    why = meta["sensors_dropped"]["BARO"]  # type: ignore[index]
    assert f"defined again at byte {middle}" in why
    # an identical second definition (a log joined to another of the same firmware) is fine
    same = data[:middle] + data[at : at + FMT_LENGTH] + data[middle:]
    log = tmp_path / "joined.bin"
    log.write_bytes(same)
    flight = read_log(log)
    baro = next(s for s in flight.sensors if s.name == "baro")
    assert baro.value.max() > 5  # heights, not the 25-32 degC of its temperatures
    assert np.isfinite(baro.value).all()


@pytest.mark.parametrize("other", [200, 201])
def test_two_types_of_one_name_are_neither_read(tmp_path: Path, other: int) -> None:
    data, at, _ = baro_columns()
    copy = bytearray(data[at : at + FMT_LENGTH])
    copy[3] = other  # the same name and layout under another type id
    meta, _ = fused(tmp_path, data[: at + FMT_LENGTH] + bytes(copy) + data[at + FMT_LENGTH :])
    assert "baro" not in [s["name"] for s in meta["sensors_used"]]  # type: ignore[attr-defined]
    assert "both name it" in meta["sensors_dropped"]["BARO"]  # type: ignore[index]
