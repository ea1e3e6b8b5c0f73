"""The run folder of ``exposim run``: its one writer (with resume and a lock) and its reader.

Layout (a contract with the feature / VO benchmark and the report)::

    RUN_DIR/run.json                     configuration, status, cycles done, timing, writer
    RUN_DIR/run.lock                     present while a process writes the folder
    RUN_DIR/<method>/exposures.csv       cycle,timestamp_ns,target_ms,bracket_ms,ratio,
                                         saturated_fraction,valid_fraction, then EXTRA_COLUMNS
    RUN_DIR/<method>/images/left/<timestamp_ns>.png    (--save png16 | png8)
    RUN_DIR/<method>/images/right/<timestamp_ns>.png
    RUN_DIR/<method>/images/times.txt    "<timestamp_ns> <timestamp_s> <exposure_ms>", by time
    RUN_DIR/exposure.png, RUN_DIR/results.json, RUN_DIR/report.md   (emulator.report.run)

``png16`` images are 12-bit DN in ``uint16`` RGGB Bayer mosaics; ``png8`` images are 8-bit
grey (:func:`emulator.core.gray.bayer_to_gray8`).  ``times.txt`` is the TUM monoVO format
(:mod:`emulator.io.stack`), the image name being its timestamp in ns.

**Writer** (:class:`RunWriter`): creates a new folder (refusing a non-empty one) or
resumes one, appends CSV rows (a row already recorded is checked against the replay, not
written twice), writes images and ``run.json`` atomically, and writes ``times.txt`` at the
end.  While it is open it holds the folder's **lock** (:class:`RunLock`): ``run.lock``
holds the writer's PID, host and start time, is created atomically (a complete temporary
file hard-linked into place, which fails when the lock exists) and is held with
``fcntl.flock`` for the writer's lifetime.  A second writer is refused
(:class:`RunLockedError`) while the holder lives; a lock left by a killed process (its
``flock`` released by the kernel and its PID dead) is recognised as stale and taken over,
so the interrupted run can be resumed.

**Reader** (:mod:`emulator.io.runread`, re-exported here): :func:`read_run_folder` (the saved
images per method, for the benchmarks), :func:`read_run_json`, :func:`read_tables` (the CSVs as arrays, for the report).
"""

from __future__ import annotations

import contextlib
import csv
import io
import os
import shutil
import threading
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from emulator.errors import OutputExistsError, RunFolderError
from emulator.io.files import format_timestamp_s, with_path, write_metadata
from emulator.io.png import write_png8, write_png16
from emulator.io.runcsv import (CSV_COLUMNS, CSV_FILE, EXTRA_COLUMNS, format_row, read_csv_rows, read_tables,
                                tables_from_rows)
from emulator.io.runlock import LOCK_FILE, RunLock, utc_now_iso
from emulator.io.runread import (  # re-exported: the reader lives in emulator.io.runread
    IMAGES_DIR,
    RUN_FILE,
    MethodRun,
    RunFolder,
    RunFrame,
    read_run_folder,
    read_run_json,
)
from emulator.io.stack import TIMES_FILE, write_times

__all__ = [
    "RUN_FILE",
    "LOCK_FILE",
    "CSV_FILE",
    "IMAGES_DIR",
    "CSV_COLUMNS",
    "EXTRA_COLUMNS",
    "SAVE_MODES",
    "format_row",
    "RunLock",
    "RunWriter",
    "read_run_json",
    "read_csv_rows",
    "read_tables",
    "tables_from_rows",
    "RunFrame",
    "MethodRun",
    "RunFolder",
    "read_run_folder",
]

#: What a run saves of its emulated images.
SAVE_MODES = ("none", "png16", "png8")


# ============================================================================ the writer
class RunWriter:
    """The one writer of a run folder.

    Parameters
    ----------
    out_dir : path
        The run folder.
    resume : bool
        Continue the run in ``out_dir`` (its ``run.json`` must exist) instead of creating one
        (``out_dir`` must be absent or empty, else :class:`OutputExistsError`).

    Opening (``with RunWriter(...) as w`` or :meth:`open`) takes the lock and, when
    resuming, reads ``run.json`` into :attr:`run_json`; :meth:`start` then records the
    configuration and opens the CSVs, reading the rows already there (:meth:`recorded`).
    """

    def __init__(self, out_dir: str | os.PathLike, *, resume: bool = False, png_level: int = 1) -> None:
        self.path = Path(os.path.abspath(out_dir))  # absolute from the start: a chdir later changes nothing
        self.png_level = int(png_level)  # zlib level of the saved images (emulator.io.png.encode_png)
        self.resume = bool(resume)
        self.run_json: dict = {}
        self.lock: RunLock | None = None
        self.save = "none"
        self._recorded: dict[str, dict[int, list[str]]] = {}
        self._csv: dict[str, tuple] = {}

    # ------------------------------------------------------------------ lifetime
    def open(self) -> "RunWriter":
        out = self.path
        if self.resume:
            if not (out / RUN_FILE).is_file():
                raise RunFolderError(f"{out / RUN_FILE}: no run to resume (run.json missing)")
            self.lock = RunLock.acquire(out)
            try:
                self.run_json = read_run_json(out)
            except BaseException:
                self.lock.release()
                raise
        else:
            if out.exists() and (not out.is_dir() or any(out.iterdir())):
                raise OutputExistsError(f"{out}: run folder exists and is not empty; refusing to overwrite (use "
                                        "--resume to continue an interrupted run, or choose another folder)")
            out.mkdir(parents=True, exist_ok=True)
            self.lock = RunLock.acquire(out)
        return self

    def __enter__(self) -> "RunWriter":
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Close the CSVs and release the lock (idempotent)."""
        for fh, _ in self._csv.values():
            fh.close()
        self._csv = {}
        if self.lock is not None:
            self.lock.release()
            self.lock = None

    # ------------------------------------------------------------------ content
    def start(self, run_json: dict, methods: Sequence[str], cameras: Sequence[str], save: str,
              cycles: Sequence[int] | None = None, columns: Sequence[str] = ()) -> None:
        """Record ``run_json`` with status "running" and this writer; open every method's CSV.

        Resuming, each CSV is validated before anything is appended: its rows must be, in
        order and once each, a prefix of ``cycles`` (the recording's cycle indices, less the
        cycles the interrupted run recorded as skipped); without ``cycles``, strictly
        increasing.  Rows from the first one that breaks this on (a missing middle row, a
        duplicate, a row out of order, a row of another recording) are cut off and computed
        again; ``run.json`` records what was cut under ``resume_repairs``.
        """
        if save not in SAVE_MODES:
            raise RunFolderError(f"save must be one of {', '.join(SAVE_MODES)}, got {save!r}")
        self.save = save
        skipped = {int(s["cycle"]) for s in (self.run_json.get("skipped_cycles") or []) if isinstance(s, dict)
                   and isinstance(s.get("cycle"), int)}
        expected = None if cycles is None else [int(c) for c in cycles if int(c) not in skipped]
        repairs = []
        if self.resume:
            for name in methods:
                note = _repair_prefix(self.path / name / CSV_FILE, expected)
                if note:
                    repairs.append(f"{name}: {note}")
        self.run_json = run_json
        if repairs:
            self.run_json["resume_repairs"] = list(self.run_json.get("resume_repairs", [])) + repairs
        self.update(status="running", writer=self.lock.owner if self.lock else None)
        for name in methods:
            mdir, path = self.path / name, self.path / name / CSV_FILE
            try:
                for cam in cameras if save != "none" else ():
                    (mdir / IMAGES_DIR / cam).mkdir(parents=True, exist_ok=True)
                self._recorded[name] = {int(r[0]): r for r in (read_csv_rows(path, repair=True) if self.resume else [])}
                mdir.mkdir(parents=True, exist_ok=True)
                new = not path.exists() or path.stat().st_size == 0
                fh = open(path, "a", newline="")
                self._csv[name] = (fh, csv.writer(fh, lineterminator="\n"))
                if new:
                    self._csv[name][1].writerow(CSV_COLUMNS + EXTRA_COLUMNS + tuple(columns))  # native: NATIVE_COLUMNS
                    fh.flush()
            except OSError as exc:  # a full disk while writing a header: name the file, and run.json says so
                named = with_path(exc, path)
                with contextlib.suppress(OSError):
                    self.update(status="failed", error=f"{type(named).__name__}: {named}")
                raise named from None

    def update(self, **fields) -> None:
        """Set fields of ``run.json`` (and the time of the update) and write it atomically."""
        self.run_json.update(fields, updated=utc_now_iso())
        write_metadata(self.path / RUN_FILE, self.run_json, overwrite=True)

    def recorded(self, method: str, cycle: int) -> list[str] | None:
        """The CSV row of ``cycle`` found when resuming, or None."""
        return self._recorded.get(method, {}).get(int(cycle))

    def append_row(self, method: str, row: list[str]) -> None:
        """Append one CSV row (flushed: a killed run keeps every finished row)."""
        fh, writer = self._csv[method]
        try:
            writer.writerow(row)
            fh.flush()
        except OSError as exc:  # a full disk: name the file
            raise with_path(exc, self.path / method / CSV_FILE) from None

    def image_path(self, method: str, camera: str, timestamp_ns: int) -> Path:
        return self.path / method / IMAGES_DIR / camera / f"{int(timestamp_ns)}.png"

    def write_image(self, method: str, camera: str, timestamp_ns: int, image: np.ndarray) -> Path:
        """Write one emulated image as the run saves them (``uint16`` for png16, ``uint8`` grey for png8)."""
        path = self.image_path(method, camera, timestamp_ns)
        if self.save == "png16":
            return write_png16(path, image, overwrite=True, level=self.png_level)
        if self.save == "png8":
            return write_png8(path, image, overwrite=True, level=self.png_level)
        raise RunFolderError(f"{self.path}: this run saves no images (save = {self.save!r})")

    def share_image(self, source: Path, method: str, camera: str, timestamp_ns: int) -> Path:
        """Give ``method`` the image already written at ``source`` (same bytes): a hard link where
        the file system allows, else a copy; atomic."""
        dest = self.image_path(method, camera, timestamp_ns)
        tmp = dest.with_name(f".{dest.name}.{os.getpid()}.{threading.get_ident()}.tmp")
        try:
            os.link(source, tmp)
        except OSError:
            shutil.copyfile(source, tmp)
        os.replace(tmp, dest)
        return dest

    def write_times(self, methods: Iterable[str], rows: dict | None = None) -> None:
        """Write each method's ``images/times.txt`` (sorted by time) from its CSV rows: ``rows[name]``
        when given (the run's rows in memory), else read from the CSV."""
        for name in methods:
            rows_of = rows[name] if rows is not None else read_csv_rows(self.path / name / CSV_FILE)
            lines = sorted((int(r[1]), float(r[2])) for r in rows_of)
            write_times(self.path / name / IMAGES_DIR / TIMES_FILE, [str(ns) for ns, _ in lines],
                        [format_timestamp_s(ns) for ns, _ in lines], [ms for _, ms in lines], overwrite=True)


def _repair_prefix(path: Path, expected: list[int] | None) -> str | None:
    """Cut ``path``'s rows back to the longest valid prefix (see :meth:`RunWriter.start`);
    returns what was cut, or None when the table was valid."""
    rows = read_csv_rows(path, repair=True)
    keep = 0
    why = None
    last = None
    for i, row in enumerate(rows):
        try:
            cycle = int(row[0])
        except (ValueError, IndexError):
            why = f"row {i + 1} has no cycle number"
            break
        if expected is not None:
            if i >= len(expected) or cycle != expected[i]:
                want = expected[i] if i < len(expected) else None
                why = (f"row {i + 1} is cycle {cycle}, expected "
                       f"{'no further row' if want is None else f'cycle {want}'}")
                break
        elif last is not None and cycle <= last:
            why = f"row {i + 1} is cycle {cycle} after cycle {last}"
            break
        last = cycle
        keep = i + 1
    header = read_csv_header(path) if path.is_file() else []
    if why is None:
        # valid rows, but written otherwise than the writer writes them (CRLF line ends, an
        # editor's quoting): put back in the writer's form, so the table equals an
        # uninterrupted run's byte for byte
        if not header or path.read_bytes() == _csv_bytes(header, rows):
            return None
        why = "rows written in another form (line ends or quoting)"
    tmp = path.with_name(path.name + ".repair")
    with open(tmp, "wb") as fh:
        fh.write(_csv_bytes(header, rows[:keep]))
    os.replace(tmp, path)
    return f"{why}; kept the first {keep} of {len(rows)} rows, the rest is computed again"


def _csv_bytes(header, rows) -> bytes:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue().encode()


def read_csv_header(path: Path) -> list[str]:
    with open(path, newline="") as fh:
        return next(csv.reader(fh))
