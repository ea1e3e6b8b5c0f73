"""The reader of an ``exposim run`` folder (layout in :mod:`emulator.io.runfolder`, whose writer makes it).

:func:`read_run_json` reads ``run.json``; :func:`read_run_folder` lists the saved images of
each method (:class:`RunFolder` of :class:`MethodRun` of :class:`RunFrame`), for the benchmarks
and the export.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from emulator.errors import RunFolderError
from emulator.io.files import read_metadata
from emulator.io.stack import TIMES_FILE, read_times
from emulator.core.levels import BOREALHDR_LEVELS, Levels

__all__ = [
    "RUN_FILE",
    "IMAGES_DIR",
    "read_run_json",
    "RunFrame",
    "MethodRun",
    "RunFolder",
    "read_run_folder",
]

RUN_FILE = "run.json"
IMAGES_DIR = "images"


def read_run_json(run_dir: str | os.PathLike) -> dict:
    """The ``run.json`` of a run folder; :class:`RunFolderError` when missing or malformed."""
    run_dir = Path(run_dir)
    path = run_dir / RUN_FILE
    if not path.is_file():
        raise RunFolderError(f"{run_dir}: not a run folder ({RUN_FILE} missing); expected the output of `exposim run`")
    return read_metadata(path, RunFolderError)


@dataclass(frozen=True)
class RunFrame:
    """One saved stereo frame of a method's run.

    Attributes
    ----------
    timestamp_ns : int
        Capture time of the frame, integer nanoseconds (file name of the PNG).
    exposure_ms : float or None
        Exposure time the frame was emulated at, in milliseconds (from ``times.txt``).
    left, right : pathlib.Path or None
        The left and right PNGs; ``right`` is None when the right image was not saved.
    """

    timestamp_ns: int
    exposure_ms: float | None
    left: Path
    right: Path | None


@dataclass(frozen=True)
class MethodRun:
    """The saved images of one AE method in a run folder, sorted by time."""

    name: str
    directory: Path
    frames: tuple[RunFrame, ...]

    @property
    def timestamps_ns(self) -> list[int]:
        """Frame timestamps in integer nanoseconds."""
        return [f.timestamp_ns for f in self.frames]


@dataclass(frozen=True)
class RunFolder:
    """A run folder: its metadata and the images of each method.

    Attributes
    ----------
    path : pathlib.Path
        The run folder.
    meta : dict
        The parsed ``run.json``.
    methods : dict of str to MethodRun
        Methods in the order of ``run.json``'s ``"methods"`` (or folder order).
    sequence : pathlib.Path or None
        The recording the run played back (``run.json`` ``"sequence"``), resolved against
        the run folder then the working directory; None when absent or not found.
    white_level, black_level : int
        The recording's clip levels in DN (``run.json``; the BorealHDR levels if absent).
    """

    path: Path
    meta: dict
    methods: dict[str, MethodRun] = field(default_factory=dict)
    sequence: Path | None = None
    white_level: int = BOREALHDR_LEVELS.white
    black_level: int = BOREALHDR_LEVELS.black

    @property
    def levels(self) -> Levels:
        """The clip levels as one :class:`~emulator.core.levels.Levels` value."""
        return Levels(self.black_level, self.white_level)


def _level(meta: dict, key: str, default: int, run_json: Path) -> int:
    value = meta.get(key)
    if value is None and isinstance(meta.get("camera"), dict):
        value = meta["camera"].get(key)
    if value is None:
        return default
    try:
        return int(value)
    except (TypeError, ValueError):
        raise RunFolderError(f"{run_json}: {key} must be an integer DN, got {value!r}") from None


def _resolve_sequence(value, run_dir: Path) -> Path | None:
    if not value:
        return None
    p = Path(value)
    if p.is_absolute():
        return p if p.exists() else None
    for base in (run_dir, Path.cwd()):
        if (base / p).exists():
            return (base / p).resolve()
    return None


def _png_timestamps(folder: Path) -> dict[int, Path]:
    out: dict[int, Path] = {}
    if not folder.is_dir():
        return out
    for p in folder.glob("*.png"):
        try:
            out[int(p.stem)] = p
        except ValueError:
            raise RunFolderError(f"{p}: image name is not an integer timestamp in ns") from None
    return out


def _read_method(run_dir: Path, name: str, require_right: bool) -> MethodRun:
    mdir = run_dir / name
    if not mdir.is_dir():
        raise RunFolderError(f"{run_dir}: method {name!r} is listed in run.json but {mdir} does not exist")
    images = mdir / IMAGES_DIR
    lefts = _png_timestamps(images / "left")
    if not lefts:
        raise RunFolderError(
            f"{images / 'left'}: no images for method {name!r}; run `exposim run` with --save png16 (or png8)"
        )
    rights = _png_timestamps(images / "right")
    times_path = images / TIMES_FILE
    if times_path.is_file():
        times = {}
        for e in read_times(times_path, RunFolderError):
            try:
                times[int(e.name)] = e.exposure_ms
            except ValueError:
                raise RunFolderError(f"{times_path}: image name {e.name!r} is not an integer timestamp in ns") from None
        missing = sorted(set(times) - set(lefts))
        if missing:
            raise RunFolderError(
                f"{times_path}: {len(missing)} timestamp(s) have no left image, first {missing[0]} "
                f"(expected {images / 'left' / (str(missing[0]) + '.png')})"
            )
        stamps = sorted(times)
    else:
        times = {}
        stamps = sorted(lefts)
    frames = []
    for ts in stamps:
        right = rights.get(ts)
        if require_right and right is None:
            raise RunFolderError(
                f"{images / 'right'}: no right image for timestamp {ts} of method {name!r}; stereo VO needs both"
            )
        frames.append(RunFrame(timestamp_ns=ts, exposure_ms=times.get(ts), left=lefts[ts], right=right))
    return MethodRun(name=name, directory=mdir, frames=tuple(frames))


def read_run_folder(
    run_dir: str | os.PathLike, methods: list[str] | None = None, *, require_right: bool = False
) -> RunFolder:
    """Read the saved images of a run folder written by ``exposim run``.

    Parameters
    ----------
    run_dir : str or pathlib.Path
        The run folder (holds ``run.json``).
    methods : list of str, optional
        Restrict to these methods (default: all of ``run.json``'s ``"methods"``).
    require_right : bool
        Refuse frames without a right image (stereo VO).

    Raises
    ------
    RunFolderError
        When the folder or ``run.json`` is missing, the run saved no images
        (``"save": "none"``), a method has no left images, or a listed image is missing.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunFolderError(f"{run_dir}: run folder does not exist")
    meta = read_run_json(run_dir)
    run_json = run_dir / RUN_FILE
    if meta.get("save") == "none":
        raise RunFolderError(
            f"{run_json}: the run saved no images (save = 'none'); rerun `exposim run` with --save png16"
        )
    listed = meta.get("methods")
    if listed is None:
        listed = sorted(p.name for p in run_dir.iterdir() if (p / IMAGES_DIR).is_dir())
    if isinstance(listed, dict):
        listed = list(listed)
    if not listed:
        raise RunFolderError(f"{run_dir}: no methods in run.json and no <method>/images folders")
    listed = [str(m) for m in listed]
    if methods:
        unknown = [m for m in methods if m not in listed]
        if unknown:
            raise RunFolderError(f"{run_dir}: method(s) {unknown} not in this run; it has {listed}")
        listed = [m for m in listed if m in methods]
    white = _level(meta, "white_level", BOREALHDR_LEVELS.white, run_json)
    black = _level(meta, "black_level", BOREALHDR_LEVELS.black, run_json)
    Levels.checked(black, white, where=str(run_json), error=RunFolderError)
    return RunFolder(
        path=run_dir,
        meta=meta,
        methods={m: _read_method(run_dir, m, require_right) for m in listed},
        sequence=_resolve_sequence(meta.get("sequence"), run_dir),
        white_level=white,
        black_level=black,
    )
