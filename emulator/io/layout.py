"""Where a recording's calibration lives: the dataset layouts people actually have.

Three layouts are read, all by walking up from the recording (a folder or a trajectory
zip), at most :data:`MAX_LEVELS_UP` folders, first along the path as given and then along
the path with symbolic links resolved (a zip symlinked into a dataset root finds the
files beside the link *and* beside its target):

* **synthetic** (written by ``synth``): ``<sequence>/calibration/response.txt`` or
  ``pcalib*.txt``, and ``<sequence>/calibration/left.yaml``, ``right.yaml``;
* **the shared BorealHDR sample**: ``<root>/calibration/pcalib_inside1.txt`` and
  ``<root>/calibration/<month>_<year>/left.yaml`` beside ``<root>/backpack_...``;
* **a clone of the BorealHDR repository**: ``BorealHDR/calibration_files/pcalib_inside1.txt``
  and ``BorealHDR/calibration_files/calibration_vo/<month>_<year>/left.yaml``, with the
  recordings under ``BorealHDR/data_sample/backpack_...`` (or any folder below the clone).

A stereo calibration folder is chosen by the recording's date: the date in its name
(``backpack_2023-09-25-15-05-03`` -> September 2023), else the date of its first
timestamp (UTC).  The folder named for that month (``september_2023``) wins; otherwise
the latest one dated before the recording; a folder with a suffix
(``september_2023_modified``) is only taken when no plain one fits.  Every choice is
returned with the reason and the alternatives, so runs can record it.
"""

from __future__ import annotations

import datetime as _dt
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

__all__ = [
    "MAX_LEVELS_UP",
    "RESPONSE_PREFERENCE",
    "CalibrationChoice",
    "search_roots",
    "recording_date",
    "find_response_file",
    "stereo_calibration_candidates",
    "choose_stereo_calibration",
]

#: How many parent folders above a recording are searched for calibration files.
MAX_LEVELS_UP = 3
#: Among several pcalib files in one folder, the one the BorealHDR reference emulator
#: loads (``scripts/classes/class_image_emulator.py``) comes first.
RESPONSE_PREFERENCE = ("response.txt", "pcalib_inside1.txt")
#: Folders that hold calibration files, relative to a search root, and where stereo
#: calibrations sit inside them (the upstream repository nests them in ``calibration_vo``).
_CALIBRATION_DIRS = (("calibration",), ("calibration_files",), ("calibration_files", "calibration_vo"))
_MONTHS = ("january", "february", "march", "april", "may", "june", "july", "august", "september",
           "october", "november", "december")
_MONTH_DIR_RE = re.compile(r"^(" + "|".join(_MONTHS) + r")_(\d{4})(?:_(.+))?$", re.IGNORECASE)
_NAME_DATE_RE = re.compile(r"(\d{4})-(\d{2})-(\d{2})[-_T]\d{2}[-:]\d{2}[-:]\d{2}")


def search_roots(recording: str | os.PathLike) -> list[Path]:
    """Folders searched for a recording's calibration, nearest first.

    The recording itself (a folder; not a zip), then up to :data:`MAX_LEVELS_UP` of its
    parents along the path as given, then the same along the resolved path when a
    symbolic link is involved.  Duplicates are dropped.

    >>> [p.as_posix() for p in search_roots("/d/BorealHDR/data_sample/backpack_x")][:3]
    ['/d/BorealHDR/data_sample/backpack_x', '/d/BorealHDR/data_sample', '/d/BorealHDR']
    """
    rec = Path(recording)
    out: list[Path] = []
    chains = [Path(os.path.abspath(rec))]
    try:
        resolved = rec.resolve()
    except OSError:
        resolved = chains[0]
    if resolved != chains[0]:
        chains.append(resolved)
    for chain in chains:
        start = [chain] if not chain.is_file() else []
        for p in start + list(chain.parents)[:MAX_LEVELS_UP]:
            if p not in out:
                out.append(p)
    return out


def recording_date(recording: str | os.PathLike, first_timestamp_ns: int | None = None) -> tuple[_dt.date | None, str]:
    """The recording's date and where it came from.

    From the name (``backpack_2023-09-25-15-05-03``, ``.zip`` or not), else from the
    first timestamp (nanoseconds since the Unix epoch, UTC); ``(None, reason)`` when
    neither gives one.

    >>> recording_date("/x/backpack_2023-09-25-15-05-03.zip")
    (datetime.date(2023, 9, 25), 'name backpack_2023-09-25-15-05-03.zip')
    >>> recording_date("/x/seq", 1695668703364771328)[0]
    datetime.date(2023, 9, 25)
    """
    name = Path(recording).name
    m = _NAME_DATE_RE.search(name)
    if m:
        try:
            return _dt.date(int(m.group(1)), int(m.group(2)), int(m.group(3))), f"name {name}"
        except ValueError:
            pass
    if first_timestamp_ns is not None and first_timestamp_ns > 0:
        d = _dt.datetime.fromtimestamp(first_timestamp_ns / 1e9, tz=_dt.timezone.utc).date()
        if d.year >= 2000:  # synthetic timestamps start near 0: not a date
            return d, f"first timestamp {first_timestamp_ns} ns (UTC)"
    return None, f"no date in the name {name!r} nor in the timestamps"


def _response_in(folder: Path) -> Path | None:
    if not folder.is_dir():
        return None
    for name in RESPONSE_PREFERENCE:
        if (folder / name).is_file():
            return folder / name
    found = sorted(folder.glob("pcalib*.txt"))
    return found[0] if found else None


def find_response_file(recording: str | os.PathLike) -> Path | None:
    """The inverse-response (pcalib) file of a recording, or None.

    In each search root (:func:`search_roots`, nearest first): ``calibration/`` then
    ``calibration_files/``; in a folder ``response.txt``, then ``pcalib_inside1.txt``, then
    the first ``pcalib*.txt`` by name.
    """
    for root in search_roots(recording):
        for sub in (("calibration",), ("calibration_files",)):
            found = _response_in(root.joinpath(*sub))
            if found is not None:
                return found
    return None


def _is_stereo_folder(folder: Path) -> bool:
    return (folder / "left.yaml").is_file() and (folder / "right.yaml").is_file()


def stereo_calibration_candidates(recording: str | os.PathLike) -> list[Path]:
    """Every stereo calibration folder (``left.yaml`` + ``right.yaml``) found for a recording.

    ``<recording>/calibration`` itself, and the month folders (``<month>_<year>[_suffix]``)
    under ``calibration/``, ``calibration_files/`` and ``calibration_files/calibration_vo/``
    of each search root, nearest root first.
    """
    out: list[Path] = []
    for root in search_roots(recording):
        for sub in _CALIBRATION_DIRS:
            folder = root.joinpath(*sub)
            if not folder.is_dir():
                continue
            if _is_stereo_folder(folder) and folder not in out:
                out.append(folder)
            for child in sorted(folder.iterdir()):
                if child.is_dir() and _MONTH_DIR_RE.match(child.name) and _is_stereo_folder(child) \
                        and child not in out:
                    out.append(child)
    return out


@dataclass(frozen=True)
class CalibrationChoice:
    """A stereo calibration folder chosen for a recording, and why.

    Attributes
    ----------
    folder : pathlib.Path or None
        None when nothing fits (see ``reason``).
    reason : str
        The rule that picked it, in words.
    date : str or None
        The recording's date (ISO), and ``date_source`` where it came from.
    candidates : list of str
        Every folder that was considered.
    """

    folder: Path | None
    reason: str
    date: str | None = None
    date_source: str = ""
    candidates: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        return {"folder": None if self.folder is None else str(self.folder), "reason": self.reason,
                "recording_date": self.date, "date_source": self.date_source, "candidates": self.candidates}


def _folder_month(folder: Path) -> tuple[int, int, str] | None:
    m = _MONTH_DIR_RE.match(folder.name)
    if not m:
        return None
    return int(m.group(2)), _MONTHS.index(m.group(1).lower()) + 1, m.group(3) or ""


def choose_stereo_calibration(recording: str | os.PathLike, first_timestamp_ns: int | None = None) -> CalibrationChoice:
    """Choose the stereo calibration of a recording from the layout and its date.

    Rules, in order: the recording's own ``calibration/`` folder (synthetic sequences);
    the month folder of the recording's month and year, without suffix, then with one;
    the latest month folder before the recording's month (plain before suffixed); the
    only candidate when there is one.  Otherwise ``folder`` is None and ``reason`` says
    what was found.
    """
    date, date_source = recording_date(recording, first_timestamp_ns)
    candidates = stereo_calibration_candidates(recording)
    iso = None if date is None else date.isoformat()
    names = [str(c) for c in candidates]
    own = Path(os.path.abspath(recording)) / "calibration"
    for c in candidates:
        if c == own or (Path(recording) / "calibration") == c:
            return CalibrationChoice(c, "the recording's own calibration/ folder", iso, date_source, names)
    if not candidates:
        roots = ", ".join(str(r) for r in search_roots(recording))
        return CalibrationChoice(None, f"no folder with left.yaml and right.yaml under calibration/, "
                                 f"calibration_files/ or calibration_files/calibration_vo/ of {roots}",
                                 iso, date_source, names)
    dated = [(c, _folder_month(c)) for c in candidates]
    dated = [(c, m) for c, m in dated if m is not None]
    if date is not None and dated:
        key = (date.year, date.month)
        for want_plain in (True, False):
            for c, (y, mo, suffix) in dated:
                if (y, mo) == key and (suffix == "") == want_plain:
                    return CalibrationChoice(
                        c, f"named for the recording's month ({date_source})"
                        + ("" if want_plain else f"; the only {c.name.split('_')[0]} folder has a suffix"),
                        iso, date_source, names)
        before = [(c, m) for c, m in dated if (m[0], m[1]) <= key]
        if before:
            best = max(before, key=lambda cm: (cm[1][0], cm[1][1], cm[1][2] == ""))
            return CalibrationChoice(best[0], f"the latest calibration before the recording ({date_source}); none "
                                     "is named for its month", iso, date_source, names)
    if len(candidates) == 1:
        return CalibrationChoice(candidates[0], "the only calibration found", iso, date_source, names)
    return CalibrationChoice(None, f"{len(candidates)} calibrations found and the recording's date does not choose "
                             f"one ({date_source})", iso, date_source, names)
