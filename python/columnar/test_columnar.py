"""`thermode simulate` and `thermode render` with `--out` ending in `.arrow`, `.feather` or `.parquet`, read with
pyarrow (as pandas, polars and R read them) and compared with the CSV of the same run: the same column names in the
same order, the same number of rows, and every value the one its CSV field holds (floats exactly, an empty field
null).

Needs `pyarrow`; skipped without it unless `THERMODE_REQUIRE_PYTHON_TESTS=1` (CI), where a missing module is a
failure.
"""

from __future__ import annotations

import csv
import math
import os
import subprocess
from pathlib import Path
from typing import List

import pytest

if os.environ.get("THERMODE_REQUIRE_PYTHON_TESTS") == "1":
    import pyarrow  # noqa: F401  (a missing module fails the run in CI)
else:
    pytest.importorskip("pyarrow", reason="`python3 -m pip install pyarrow` to run the Arrow/Parquet tests")

import pyarrow.feather as feather  # noqa: E402
import pyarrow.parquet as parquet  # noqa: E402

from conftest import thermode_binary  # noqa: E402

RUNS = {
    "simulate": ["simulate", "--material", "aluminium", "--material", "wood", "--duration", "3", "--dt", "0.01"],
    "render": ["render", "--material", "aluminium", "--controller", "both", "--duration", "3", "--pre-contact", "0.5"],
}


def run(args: List[str]) -> None:
    done = subprocess.run([thermode_binary(), *args], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"thermode {args}: {done.stderr}"


def same(csv_field: str, value: object) -> bool:
    if value is None:
        return csv_field == ""
    if isinstance(value, float):
        parsed = float(csv_field)
        return parsed == value or (math.isnan(parsed) and math.isnan(value))
    return csv_field == str(value)


@pytest.mark.parametrize("command", sorted(RUNS))
@pytest.mark.parametrize("extension", ["arrow", "feather", "parquet"])
def test_a_columnar_output_holds_the_csvs_columns_and_values(tmp_path: Path, command: str, extension: str) -> None:
    csv_path, columnar_path = tmp_path / f"{command}.csv", tmp_path / f"{command}.{extension}"
    run(RUNS[command] + ["--out", str(csv_path)])
    run(RUNS[command] + ["--out", str(columnar_path)])
    table = parquet.read_table(columnar_path) if extension == "parquet" else feather.read_table(columnar_path)
    with csv_path.open(newline="") as f:
        rows = list(csv.reader(f))
    header, rows = rows[0], rows[1:]
    assert table.column_names == header
    assert table.num_rows == len(rows) > 100
    for index, name in enumerate(header):
        values = table.column(name).to_pylist()
        for row, (fields, value) in enumerate(zip(rows, values)):
            assert same(fields[index], value), f"{name} row {row}: CSV {fields[index]!r}, {extension} {value!r}"


@pytest.mark.parametrize("extension", ["arrow", "parquet"])
def test_a_recording_to_a_columnar_file_holds_the_sessions_csv(tmp_path: Path, extension: str) -> None:
    target = tmp_path / f"session.{extension}"
    state = tmp_path / "state"
    run(["serve", "--port", "0", "--no-osc", "--duration", "1.5", "--state-dir", str(state), "--record", str(target)])
    sessions = [p for p in tmp_path.glob("session_*.csv") if not p.name.endswith(".events.csv")]
    assert len(sessions) == 1, sessions
    table = parquet.read_table(target) if extension == "parquet" else feather.read_table(target)
    with sessions[0].open(newline="") as f:
        rows = list(csv.reader(f))
    header, rows = rows[0], rows[1:]
    assert table.column_names == header
    assert table.num_rows == len(rows) > 100
    for index, name in enumerate(header):
        for row, (fields, value) in enumerate(zip(rows, table.column(name).to_pylist())):
            assert same(fields[index], value), f"{name} row {row}: CSV {fields[index]!r}, {extension} {value!r}"
