"""The fused table's files (issue 17): Parquet beside CSV, the CSV's float format, both readable
without altfuse."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from altfuse import write
from altfuse.batch import BatchOptions, run_batch
from altfuse.write import CSV_DECIMALS, arrow_column, column_unit
from conftest import SAMPLE_LOG, shared_log
from test_cli import run


def test_the_parquet_table_reads_back_to_the_csv_s_values(tmp_path: Path) -> None:
    """Acceptance 4: the same run as CSV and as Parquet, read by pandas; Parquet keeps every
    float whole, the CSV to CSV_DECIMALS decimals."""
    for suffix in ("csv", "parquet"):
        out, weights = tmp_path / f"flight.{suffix}", tmp_path / f"w.{suffix}"
        result = run("fuse", SAMPLE_LOG, "-o", out, "--weights", weights, "--meta", f"{out}.json")
        assert result.exit_code == 0, result.output
    for name in ("flight", "w"):
        csv = pd.read_csv(tmp_path / f"{name}.csv")
        parquet = pd.read_parquet(tmp_path / f"{name}.parquet")
        assert list(parquet.columns) == list(csv.columns)
        assert parquet.columns[0] == "time_s"
        assert len(parquet) == len(csv) == 1200
        for column in csv.columns:
            if csv[column].dtype.kind == "f":
                np.testing.assert_allclose(
                    parquet[column], csv[column], atol=0.5 * 10**-CSV_DECIMALS, rtol=0
                )
                assert (parquet[column].isna() == csv[column].isna()).all()
            else:
                assert (parquet[column] == csv[column]).all(), column
    assert set(pd.read_parquet(tmp_path / "flight.parquet")["status"]) <= {
        "fused",
        "single",
        "equal",
        "none",
        "diverged",
    }


def test_the_parquet_file_carries_units_and_the_provenance(tmp_path: Path) -> None:
    out = tmp_path / "flight.parquet"
    assert run("fuse", SAMPLE_LOG, "-o", out).exit_code == 0
    table = pq.read_table(out)
    units = {f.name: (f.metadata or {}).get(b"unit", b"?").decode() for f in table.schema}
    assert units["time_s"] == "s"
    assert units["fused_alt_m"] == units["fused_std_m"] == units["alt_gps_m"] == "m"
    assert units["weight_gps"] == units["n_sensors"] == "1"
    assert units["status"] == ""
    provenance = json.loads(table.schema.metadata[b"altfuse"])
    sidecar = json.loads((tmp_path / "flight.meta.json").read_text())
    assert provenance == sidecar
    assert sidecar["outputs"] == {"parquet": "flight.parquet", "meta": "flight.meta.json"}


def test_the_csv_float_format_is_documented_and_byte_stable(tmp_path: Path) -> None:
    """Each float rounded to CSV_DECIMALS and written in its shortest form, empty where there
    is none, no "-0", names unquoted; two runs write the same bytes."""
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    for out in (a, b):
        assert (
            run("fuse", SAMPLE_LOG, "-o", out, "--meta", tmp_path / f"{out.stem}.json").exit_code
            == 0
        )
    assert a.read_bytes() == b.read_bytes()
    text = a.read_text()
    header, first = text.splitlines()[:2]
    assert header.startswith("time_s,alt_gps_m,")
    assert '"' not in text
    assert first.startswith("30,,")  # 30.0 s, no GPS yet
    numbers = re.findall(r"-?\d+\.(\d+)", text)
    assert numbers
    assert max(len(d) for d in numbers) <= CSV_DECIMALS
    assert not re.search(r"(^|,)-0(,|$)", text, flags=re.MULTILINE)


@pytest.mark.parametrize(
    ("name", "unit"),
    [
        ("time_s", "s"),
        ("alt_baro2_m", "m"),
        ("fused_std", "m"),
        ("offset_gps", "m"),
        ("velocity", "m/s"),
        ("accel_bias", "m/s^2"),
        ("accel_up", "m/s^2"),
        ("correction", "m"),
        ("layer1_m", "m"),
        ("temporal_variance_baro", "m^2"),
        ("support_var_baro", "1"),
        ("variance_gps", "m^2"),
        ("weight_rangefinder", "1"),
        ("support_gps", "1"),
        ("support_rmse", "m"),
        ("baro_max", "m"),
        ("smoother_diverged", "1"),
    ],
)
def test_column_units(name: str, unit: str) -> None:
    assert column_unit(name) == unit


def test_a_batch_writes_parquet_and_resumes_on_it(tmp_path: Path) -> None:
    options = BatchOptions(format="parquet", weights=True)
    first = run_batch([SAMPLE_LOG], tmp_path / "out", options)
    assert [r.status for r in first] == ["ok"]
    written = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert written == ["index.json", "mission.meta.json", "mission.parquet",
                       "mission.weights.parquet", "summary.csv", "summary.parquet"]  # fmt: skip
    again = run_batch([SAMPLE_LOG], tmp_path / "out", BatchOptions(format="parquet", weights=True,
                                                                  skip_existing=True))  # fmt: skip
    assert [r.status for r in again] == ["skipped"]
    result = run("batch", SAMPLE_LOG, "-o", tmp_path / "cli", "--format", "xlsx")
    assert result.exit_code == 2
    assert "'xlsx' is not one of 'csv', 'parquet'" in result.output


def test_a_parquet_batch_writes_its_summary_as_parquet_too(tmp_path: Path) -> None:
    """summary.parquet holds summary.csv's rows and columns (a refused log's too), with units on
    the numbers (the flight's span in s, the metrics in m) and the altfuse version."""
    refused = shared_log("ardupilot") / "pfcFlightData_center_0003.bin"
    options = BatchOptions(format="parquet", evaluate=True)
    results = run_batch([SAMPLE_LOG, refused], tmp_path / "out", options, jobs=1)
    assert sorted(r.status for r in results) == ["ok", "refused"]
    csv = pd.read_csv(tmp_path / "out" / "summary.csv", keep_default_na=False)
    table = pq.read_table(tmp_path / "out" / "summary.parquet")
    parquet = table.to_pandas()
    assert list(parquet.columns) == list(csv.columns)
    assert list(parquet.log) == list(csv.log) == ["mission.bin", refused.name]
    assert list(parquet.status) == ["ok", "refused"]
    assert parquet.error[1] == csv.error[1] != ""
    assert parquet.smoother_rmse[0] == pytest.approx(float(csv.smoother_rmse[0]), abs=1e-6)
    units = {f.name: (f.metadata or {}).get(b"unit", b"?").decode() for f in table.schema}
    assert units["flight_s"] == units["processing_s"] == "s"
    assert units["smoother_rmse"] == units["max_excursion_m"] == "m"
    assert units["samples"] == units["fused_share"] == "1"
    assert units["log"] == units["status"] == ""
    assert json.loads(table.schema.metadata[b"altfuse"])["altfuse_version"]


@pytest.mark.parametrize(
    "values",
    [
        np.array([1.5, np.nan, -np.inf, 0.0]),
        np.array([3, -1, 2**40]),
        np.array([True, False, True] * 5),
        np.array(["fused", "single", "none", "diverged"]),
        np.array(["höhe", "m²", "höhe", "", "m²"]),  # labels repeated, taken per row
        np.zeros(0, dtype="U1"),
        np.array(["höhe", None, "", "m²"], dtype=object),
        np.array(["ok", np.nan, None], dtype=object),  # a summary's text, NaN where none
        np.zeros(0),
    ],
)
def test_an_arrow_column_is_pyarrows_from_pandas_array(values: np.ndarray) -> None:
    # built from its buffers (pyarrow.array would import pandas): the same array
    expected = pa.array(values, from_pandas=True)
    got = arrow_column(values)
    assert got.type == expected.type
    assert got.equals(expected)


def test_fuse_imports_neither_pandas_nor_scipy(tmp_path: Path) -> None:
    """Their imports were 0.5 s of the 1.3 s fuse took on the sample log (issue 17); pymavlink's
    and pyarrow.compute's 60 ms of 1.0 s since."""
    code = (
        "import sys\n"
        "from altfuse.cli import main\n"
        f"sys.argv = ['altfuse', '-q', 'fuse', {str(SAMPLE_LOG)!r}, '-o', "
        f"{str(tmp_path / 'o.csv')!r}]\n"
        "try:\n    main()\nexcept SystemExit as exc:\n    assert exc.code == 0, exc.code\n"
        "loaded = [m for m in ('pandas', 'scipy.interpolate', 'matplotlib', 'pymavlink', "
        "'pyarrow.compute') if m in sys.modules]\n"
        "print('loaded:', ','.join(loaded))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.splitlines()[-1] == "loaded: ", done.stdout
    assert (tmp_path / "o.csv").exists()


def test_a_csv_in_chunks_keeps_each_column_s_type(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The CSV is formatted CSV_ROWS rows at a time with one schema: a summary's column of
    None in its first rows and numbers or text later (a metric or a note only of a later
    log) writes as one column."""
    monkeypatch.setattr(write, "CSV_ROWS", 2)
    table = {
        "log": np.array(["a", "b", "c", "d", "e"], dtype=object),
        "reason": np.array([None, None, None, "no GPS", None], dtype=object),
        "rmse_m": np.array([0.1234567, np.nan, 0.5, -1e-9, 2.0]),
        "ticks": np.array([1, 2, 3, 4, 5]),
        "flight_s": np.array([None, None, 12.5, None, 3], dtype=object),
    }
    out = tmp_path / "summary.csv"
    with out.open("wb") as handle:
        write.write_table(table, "csv", {})(handle)
    assert out.read_text().splitlines() == [
        "log,reason,rmse_m,ticks,flight_s",
        "a,,0.123457,1,",
        "b,,,2,",
        "c,,0.5,3,12.5",
        "d,no GPS,0,4,",
        "e,,2,5,3",
    ]
