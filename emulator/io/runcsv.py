"""The per-method CSV of a run folder, ``<method>/exposures.csv``: its columns, rows and tables.

Part of the run-folder layout (:mod:`emulator.io.runfolder`, which re-exports these names).
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from emulator.errors import RunFolderError

__all__ = ["CSV_FILE", "CSV_COLUMNS", "EXTRA_COLUMNS", "NATIVE_COLUMNS", "format_row", "read_csv_rows", "read_tables",
           "tables_from_rows"]

CSV_FILE = "exposures.csv"
#: Fixed leading columns of ``<method>/exposures.csv`` (the contract).
CSV_COLUMNS = ("cycle", "timestamp_ns", "target_ms", "bracket_ms", "ratio", "saturated_fraction", "valid_fraction")
#: Columns appended after the contract's: the proposal, guards, and per-camera figures.
EXTRA_COLUMNS = (
    "next_ms",
    "proposed_ms",
    "guarded",
    "clamped",
    "bracket_saturated_fraction",
    "saturated_fraction_right",
    "valid_fraction_right",
    "missing_left_ms",
    "missing_right_ms",
)
#: Columns a native-rate run appends (``exposim run --rate native``; ``cycle`` is then the frame index):
#: the frame's recorder cycle, 1 where the benchmarks use the frame (its cycle's first shot), the source
#: frame's offset (frames; 0: its own bracket) and timestamp, and the rotation the warp undid (degrees;
#: empty where a neighbour was used without a warp).
NATIVE_COLUMNS = ("recorder_cycle", "benchmarked", "source_offset", "source_timestamp_ns", "warp_deg")
_INT_COLUMNS = frozenset({"cycle", "timestamp_ns", "guarded", "clamped", "recorder_cycle", "benchmarked",
                          "source_offset", "source_timestamp_ns"})
_LIST_COLUMNS = frozenset({"missing_left_ms", "missing_right_ms"})


def format_row(step) -> list[str]:
    """The CSV row of a step: every column of :data:`CSV_COLUMNS` + :data:`EXTRA_COLUMNS`.

    ``step`` has an attribute per column.  Integers and flags as integers, floats at full
    precision (``repr``), None as an empty cell, exposure lists as ``;``-joined ``%g``.  A native-rate
    step (``step.native`` set) adds :data:`NATIVE_COLUMNS`.
    """
    out = []
    native = step.native
    for col in CSV_COLUMNS + EXTRA_COLUMNS + (NATIVE_COLUMNS if native is not None else ()):
        v = getattr(native, col) if col in NATIVE_COLUMNS else getattr(step, col)
        if v is None or (col == "warp_deg" and math.isnan(v)):
            out.append("")
        elif col in _INT_COLUMNS:
            out.append(str(int(v)))
        elif col in _LIST_COLUMNS:
            out.append(";".join(f"{x:g}" for x in v))
        else:
            out.append(repr(float(v)))
    return out


def read_csv_rows(path: str | os.PathLike, *, repair: bool = False) -> list[list[str]]:
    """Rows of an ``exposures.csv`` after its header (checked); ``[]`` for a missing file.

    A torn last line (a run killed mid-write) is ignored, and cut off the file when
    ``repair`` (the writer resuming it).
    """
    path = Path(path)
    if not path.is_file():
        return []
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        cut = data.rfind(b"\n") + 1
        if repair:
            with open(path, "r+b") as fh:
                fh.truncate(cut)
        data = data[:cut]
    rows = list(csv.reader(io.StringIO(data.decode())))
    if not rows:
        return []
    header = tuple(rows[0])
    if header[: len(CSV_COLUMNS)] != CSV_COLUMNS:
        raise RunFolderError(f"{path}: unexpected header {','.join(header)}")
    return rows[1:]


def tables_from_rows(rows: dict[str, list[list[str]]]) -> dict[str, dict[str, np.ndarray]]:
    """Each method's rows (as :func:`format_row` makes them) as the columns :func:`read_tables` gives."""
    columns = CSV_COLUMNS + EXTRA_COLUMNS + NATIVE_COLUMNS
    return {name: _columns([dict(zip(columns, r)) for r in method_rows]) for name, method_rows in rows.items()}


def _columns(rows: list[dict]) -> dict[str, np.ndarray]:
    cols = {}
    native = NATIVE_COLUMNS if rows and all(r.get(NATIVE_COLUMNS[0]) not in (None, "") for r in rows) else ()
    for col in CSV_COLUMNS + EXTRA_COLUMNS + native:
        if col in _LIST_COLUMNS:
            continue
        vals = [r.get(col) or "" for r in rows]
        if col in _INT_COLUMNS:
            cols[col] = np.array([int(v) if v else 0 for v in vals], dtype=np.int64)
        else:
            cols[col] = np.array([float(v) if v else math.nan for v in vals], dtype=np.float64)
    return cols


def read_tables(run_dir: str | os.PathLike, methods: Iterable[str]) -> dict[str, dict[str, np.ndarray]]:
    """Each method's ``exposures.csv`` as columns: int64 for counters and flags, float64 else.

    Empty cells read as 0 (integers) or NaN (floats); exposure-list columns are left out.
    """
    run_dir = Path(run_dir)
    tables = {}
    for name in methods:
        path = run_dir / name / CSV_FILE
        if not path.is_file():
            raise RunFolderError(f"{path}: missing; not a complete run folder")
        with open(path, newline="") as fh:
            tables[name] = _columns(list(csv.DictReader(fh)))
    return tables
