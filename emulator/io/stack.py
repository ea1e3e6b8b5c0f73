"""TUM monoVO ``times.txt`` and calibration stacks (static-scene exposure series).

``times.txt`` (the TUM monoVO format) lists one image per line::

    <name> <timestamp_s> <exposure_ms>

where ``name`` is the image's file stem.  Blank lines and lines starting with ``#`` are
skipped.  :func:`read_times` / :func:`write_times` are the one reader and writer; both a
calibration stack and the images of a run folder (:mod:`emulator.io.runfolder`, where the
name is the timestamp in ns) use them.

A calibration stack in the TUM layout::

    STACK/times.txt
    STACK/images/<name>.png      16-bit PNG, 12-bit DN
    STACK/exposim.json           optional: white_level, black_level

is read by :func:`read_stack` into a :class:`Stack` (images decode lazily) and written by
:func:`write_stack`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from collections.abc import Sequence as SequenceType
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from emulator.errors import CalibrationError
from emulator.io.files import atomic_write_bytes, read_metadata, write_metadata
from emulator.io.png import read_png16, write_png16
from emulator.core.levels import BOREALHDR_LEVELS, Levels

__all__ = [
    "TIMES_FILE",
    "IMAGES_DIR",
    "STACK_METADATA",
    "TimesEntry",
    "read_times",
    "write_times",
    "Stack",
    "read_stack",
    "write_stack",
]

TIMES_FILE = "times.txt"
IMAGES_DIR = "images"
STACK_METADATA = "exposim.json"


@dataclass(frozen=True)
class TimesEntry:
    """One line of ``times.txt``: image name (file stem), time (s), exposure (ms)."""

    name: str
    timestamp_s: float
    exposure_ms: float


def read_times(path: str | os.PathLike, error: type[Exception] = CalibrationError) -> list[TimesEntry]:
    """The entries of a ``times.txt``, in file order.

    Raises ``error`` naming the file and line for a line without three fields, a
    timestamp or exposure that is not a number, a non-positive exposure or a name listed
    twice, and FileNotFoundError for a missing file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: not found")
    entries: list[TimesEntry] = []
    seen: set[str] = set()
    for lineno, line in enumerate(path.read_text().splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        if len(parts) < 3:
            raise error(f"{path}:{lineno}: expected '<name> <timestamp_s> <exposure_ms>', got {s!r}")
        try:
            stamp, exp = float(parts[1]), float(parts[2])
        except ValueError:
            raise error(f"{path}:{lineno}: timestamp or exposure is not a number: {s!r}") from None
        if not (math.isfinite(exp) and exp > 0):
            raise error(f"{path}:{lineno}: exposure must be a positive number of ms, got {parts[2]!r}")
        if parts[0] in seen:
            raise error(f"{path}:{lineno}: image name {parts[0]!r} listed twice")
        seen.add(parts[0])
        entries.append(TimesEntry(parts[0], stamp, exp))
    return entries


def write_times(
    path: str | os.PathLike,
    names: SequenceType[str],
    timestamps_s: SequenceType[float | str],
    exposures_ms: SequenceType[float],
    *,
    overwrite: bool = False,
) -> Path:
    """Write a ``times.txt``; timestamps given as ``str`` are written verbatim (exact decimals).

    Floats are written at full precision (``repr``); exposures likewise.
    """
    if not len(names) == len(timestamps_s) == len(exposures_ms):
        raise CalibrationError(f"{path}: need one timestamp and one exposure per name")
    lines = []
    for n, t, e in zip(names, timestamps_s, exposures_ms):
        stamp = t if isinstance(t, str) else repr(float(t))
        lines.append(f"{n} {stamp} {float(e)!r}\n")
    return atomic_write_bytes(path, "".join(lines).encode(), overwrite=overwrite)


@dataclass
class Stack:
    """A static-scene exposure stack in the TUM monoVO layout.

    Attributes
    ----------
    path : Path
        The stack folder (holding ``times.txt`` and ``images/``).
    names : list of str
        Image names (file stems), in the order of ``times.txt``.
    timestamps_s : ndarray, float64, shape (N,)
        Capture times in seconds.
    exposures_ms : ndarray, float64, shape (N,)
        Exposure times in milliseconds.
    white_level, black_level : int
        Clip levels, DN (``exposim.json`` in the stack, else the BorealHDR levels).
    """

    path: Path
    names: list[str]
    timestamps_s: np.ndarray
    exposures_ms: np.ndarray
    white_level: int = BOREALHDR_LEVELS.white
    black_level: int = BOREALHDR_LEVELS.black
    _images: np.ndarray | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.names)

    def image_path(self, i: int) -> Path:
        return self.path / IMAGES_DIR / f"{self.names[i]}.png"

    def load(self, i: int) -> np.ndarray:
        """Decode image ``i`` (uint16, (H, W), DN)."""
        return read_png16(self.image_path(i), white_level=self.white_level)

    @property
    def images(self) -> np.ndarray:
        """All images as one uint16 array (N, H, W), decoded on first use; mixed sizes refused."""
        if self._images is None:
            first = None
            out = []
            for i in range(len(self)):
                img = self.load(i)
                if first is None:
                    first = img.shape
                elif img.shape != first:
                    raise CalibrationError(
                        f"{self.image_path(i)}: image size {img.shape[1]}x{img.shape[0]} differs from the "
                        f"first image's {first[1]}x{first[0]} (mixed sizes in one stack)"
                    )
                out.append(img)
            self._images = np.stack(out)
        return self._images


#: Largest DN of the 12-bit data a stack holds (16-bit PNGs carrying 12-bit values).
MAX_DN_12BIT = 4095  # (the bound Levels(bit_depth=12) checks)


def read_stack(path: str | os.PathLike, *, white_level: int | None = None, black_level: int | None = None) -> Stack:
    """Read a TUM-layout stack: ``STACK/times.txt`` and ``STACK/images/<name>.png``.

    Images decode lazily (:meth:`Stack.load`, :attr:`Stack.images`).  Raises
    :class:`CalibrationError` naming the file and line for a malformed or empty
    ``times.txt`` (see :func:`read_times`) or a missing image, and FileNotFoundError for a
    missing folder.  Levels: the arguments, else ``exposim.json``, else the BorealHDR levels.
    """
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: stack folder not found")
    times = root / TIMES_FILE
    if not times.is_file():
        raise CalibrationError(f"{root}: no {TIMES_FILE} (expected the TUM layout: times.txt and images/)")
    meta = read_metadata(root / STACK_METADATA, CalibrationError)
    white = int(white_level if white_level is not None else meta.get("white_level", BOREALHDR_LEVELS.white))
    black = int(black_level if black_level is not None else meta.get("black_level", BOREALHDR_LEVELS.black))
    where = "white_level" if white_level is not None else f"{root / STACK_METADATA} white_level"
    # a white level above the 12-bit range would make saturated pixels look valid to the fit
    Levels.checked(black, white, bit_depth=12, where=where, error=CalibrationError)
    entries = read_times(times, CalibrationError)
    if not entries:
        raise CalibrationError(f"{times}: lists no images")
    for e in entries:
        p = root / IMAGES_DIR / f"{e.name}.png"
        if not p.is_file():
            raise CalibrationError(f"{p}: image listed in {TIMES_FILE} not found")
    return Stack(root, [e.name for e in entries], np.asarray([e.timestamp_s for e in entries], float),
                 np.asarray([e.exposure_ms for e in entries], float), white, black)


def write_stack(
    path: str | os.PathLike,
    images: Iterable[np.ndarray],
    exposures_ms: SequenceType[float],
    names: SequenceType[str] | None = None,
    *,
    timestamps_s: SequenceType[float] | None = None,
    white_level: int | None = None,
    black_level: int | None = None,
    overwrite: bool = False,
) -> Path:
    """Write a stack in the TUM layout (``images/<name>.png`` 16-bit, ``times.txt``).

    Parameters
    ----------
    images : iterable of ndarray, uint16, (H, W)
        DN images (12-bit data in uint16), all of one size.
    exposures_ms : sequence of float
        Exposure time of each image in milliseconds.
    names : sequence of str, optional
        File stems; default ``00000``, ``00001``, ...
    timestamps_s : sequence of float, optional
        Capture times in seconds; default 0.1 s apart.
    white_level, black_level : int, optional
        Written to ``exposim.json`` beside ``times.txt`` when given (the other one then
        gets the BorealHDR level).
    overwrite : bool
        Replace existing files (else :class:`~emulator.errors.OutputExistsError`).
    """
    root = Path(path)
    images = list(images)
    exposures = [float(e) for e in exposures_ms]
    if len(images) != len(exposures):
        raise CalibrationError(f"{root}: {len(images)} images but {len(exposures)} exposure times")
    if names is None:
        names = [f"{i:05d}" for i in range(len(images))]
    names = [str(n) for n in names]
    if len(names) != len(images) or len(set(names)) != len(names):
        raise CalibrationError(f"{root}: need one distinct name per image")
    stamps = [0.1 * i for i in range(len(images))] if timestamps_s is None else [float(s) for s in timestamps_s]
    for img, name in zip(images, names):
        if not isinstance(img, np.ndarray) or img.dtype != np.uint16 or img.ndim != 2:
            raise CalibrationError(f"{root}: image {name!r} must be a 2-D uint16 array")
        write_png16(root / IMAGES_DIR / f"{name}.png", img, overwrite=overwrite)
    write_times(root / TIMES_FILE, names, stamps, exposures, overwrite=overwrite)
    if white_level is not None or black_level is not None:
        meta = {"white_level": int(white_level if white_level is not None else BOREALHDR_LEVELS.white),
                "black_level": int(black_level if black_level is not None else BOREALHDR_LEVELS.black)}
        write_metadata(root / STACK_METADATA, meta, overwrite=overwrite)
    return root
