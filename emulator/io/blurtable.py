"""``blur.csv`` of a run folder (``exposim run --blur consistent``): the blur of each emulated image.

One row per emulated image (cycle, camera, source bracket, target):

=====================  =========================================================================
column                 meaning
=====================  =========================================================================
cycle, camera          which shot
timestamp_ns           the source bracket's timestamp
bracket_ms, target_ms  source and target exposure, ms
source_blur_px         predicted blur of the source bracket (largest over the image), px
target_blur_px         predicted blur of a capture at the target, px
excess_blur_px         blur the emulated image has beyond a capture at the target (>= 0; 0 where
                       the target is longer: the extra blur was added), px
added                  1 where blur was added (target longer than the bracket), else 0
=====================  =========================================================================

Methods' rows in ``<method>/exposures.csv`` join on (cycle, bracket_ms, target_ms).
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

from emulator.io.files import atomic_write_bytes

__all__ = ["BLUR_FILE", "BLUR_COLUMNS", "write_blur_table", "read_blur_table"]

BLUR_FILE = "blur.csv"
BLUR_COLUMNS = ("cycle", "camera", "timestamp_ns", "bracket_ms", "target_ms", "source_blur_px", "target_blur_px",
                "excess_blur_px", "added")


def write_blur_table(run_dir: str | os.PathLike, rows: list[dict]) -> Path:
    """Write (replace) ``<run_dir>/blur.csv``, rows sorted by cycle, camera, bracket, target."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(BLUR_COLUMNS)
    for r in sorted(rows, key=lambda r: (r["cycle"], r["camera"], r["bracket_ms"], r["target_ms"])):
        w.writerow([int(r["cycle"]), r["camera"], int(r["timestamp_ns"]), repr(float(r["bracket_ms"])),
                    repr(float(r["target_ms"])), repr(float(r["source_blur_px"])), repr(float(r["target_blur_px"])),
                    repr(float(r["excess_blur_px"])), int(bool(r["added"]))])
    return atomic_write_bytes(Path(run_dir) / BLUR_FILE, buf.getvalue().encode(), overwrite=True)


def read_blur_table(run_dir: str | os.PathLike) -> list[dict]:
    """The rows of ``<run_dir>/blur.csv`` (numbers as int/float)."""
    with open(Path(run_dir) / BLUR_FILE, newline="") as fh:
        rows = list(csv.DictReader(fh))
    out = []
    for r in rows:
        out.append({"cycle": int(r["cycle"]), "camera": r["camera"], "timestamp_ns": int(r["timestamp_ns"]),
                    **{k: float(r[k]) for k in BLUR_COLUMNS[3:8]}, "added": bool(int(r["added"]))})
    return out
