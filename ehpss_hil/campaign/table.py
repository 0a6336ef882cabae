"""The campaign table: one row per run (sampled parameters + every mode's metrics), in run-index
order, written as Parquet (``results.parquet``) and on request as CSV (``results.csv``).

Both are written to a temporary name and renamed, so a kill never leaves half a table.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from ..errors import OutputError
from .sampling import RunPlan

PARQUET_NAME = "results.parquet"
CSV_NAME = "results.csv"


def build_rows(plans: Sequence[RunPlan], records: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of the runs that finished (their record in ``records``), in index order."""
    rows = []
    for p in plans:
        rec = records.get(p.run_hash)
        if rec is not None:
            rows.append({**p.parameters(), **rec["metrics"]})
    return rows


def to_table(rows: list[dict[str, Any]]) -> pa.Table:
    """The rows as an Arrow table (columns in the order of the first row)."""
    return pa.Table.from_pylist(rows)


def _atomic(path: Path, write: Any) -> Path:
    tmp = path.with_name(path.name + ".tmp")
    try:
        write(str(tmp))
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
    return path


def write_table(table: pa.Table, out: Path, csv: bool = False) -> list[Path]:
    """Write ``results.parquet`` (and ``results.csv``) into ``out``."""
    paths = [_atomic(out / PARQUET_NAME, lambda p: pq.write_table(table, p))]
    if csv:
        paths.append(_atomic(out / CSV_NAME, lambda p: pacsv.write_csv(table, p)))
    return paths


def read_table(path: Path) -> pa.Table:
    """A campaign table written by :func:`write_table`."""
    return pq.read_table(path)
