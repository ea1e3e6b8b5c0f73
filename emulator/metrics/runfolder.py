"""Read the run folder written by ``exposim run`` (only what the benchmarks need).

Layout (contract with :mod:`emulator.playback`; this reader does not import it)::

    RUN_DIR/run.json                        "sequence", "methods", "save", ... (optional
                                            "white_level", "black_level" in DN)
    RUN_DIR/<method>/exposures.csv          per-cycle log (not needed here)
    RUN_DIR/<method>/images/times.txt       "<timestamp_ns> <timestamp_s> <exposure_ms>"
    RUN_DIR/<method>/images/left/<timestamp_ns>.png
    RUN_DIR/<method>/images/right/<timestamp_ns>.png

``png16`` images are 12-bit DN in ``uint16`` RGGB Bayer mosaics; ``png8`` images are
8-bit grey, already converted.  The format is read from each PNG's dtype, so a folder
needs no further description.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from emulator.dataset import read_metadata
from emulator.metrics.errors import RunFolderError

__all__ = [
    "RunFrame",
    "MethodRun",
    "RunFolder",
    "read_run_folder",
    "DEFAULT_WHITE_LEVEL",
    "DEFAULT_BLACK_LEVEL",
]

#: White level (DN) used when ``run.json`` does not state one: 12-bit full scale.
DEFAULT_WHITE_LEVEL = 4095
#: Black level (DN) used when ``run.json`` does not state one (BorealHDR: 0).
DEFAULT_BLACK_LEVEL = 0


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
        Sensor clip levels in DN for the 12-bit to 8-bit conversion.
    """

    path: Path
    meta: dict
    methods: dict[str, MethodRun] = field(default_factory=dict)
    sequence: Path | None = None
    white_level: int = DEFAULT_WHITE_LEVEL
    black_level: int = DEFAULT_BLACK_LEVEL


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


def _read_times(path: Path) -> dict[int, float | None]:
    times: dict[int, float | None] = {}
    for n, line in enumerate(path.read_text().splitlines(), start=1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        try:
            ts = int(parts[0])
            exposure = float(parts[2]) if len(parts) >= 3 else None
        except ValueError:
            raise RunFolderError(
                f"{path}, line {n}: expected '<timestamp_ns> <timestamp_s> <exposure_ms>', got {line!r}"
            ) from None
        times[ts] = exposure
    return times


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
    images = mdir / "images"
    lefts = _png_timestamps(images / "left")
    if not lefts:
        raise RunFolderError(
            f"{images / 'left'}: no images for method {name!r}; run `exposim run` with --save png16 (or png8)"
        )
    rights = _png_timestamps(images / "right")
    times_path = images / "times.txt"
    if times_path.is_file():
        times = _read_times(times_path)
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
    run_dir: str | Path, methods: list[str] | None = None, *, require_right: bool = False
) -> RunFolder:
    """Read a run folder written by ``exposim run``.

    Parameters
    ----------
    run_dir : str or pathlib.Path
        The run folder (holds ``run.json``).
    methods : list of str, optional
        Restrict to these methods (default: all of ``run.json``'s ``"methods"``).
    require_right : bool
        Refuse frames without a right image (stereo VO).

    Returns
    -------
    RunFolder

    Raises
    ------
    RunFolderError
        When the folder or ``run.json`` is missing, the run saved no images
        (``"save": "none"``), a method has no left images, or a listed image is missing.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunFolderError(f"{run_dir}: run folder does not exist")
    run_json = run_dir / "run.json"
    if not run_json.is_file():
        raise RunFolderError(f"{run_dir}: not a run folder (no run.json); expected the output of `exposim run`")
    meta = read_metadata(run_json, RunFolderError)
    if meta.get("save") == "none":
        raise RunFolderError(
            f"{run_json}: the run saved no images (save = 'none'); rerun `exposim run` with --save png16"
        )
    listed = meta.get("methods")
    if listed is None:
        listed = sorted(p.name for p in run_dir.iterdir() if (p / "images").is_dir())
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
    white = _level(meta, "white_level", DEFAULT_WHITE_LEVEL, run_json)
    black = _level(meta, "black_level", DEFAULT_BLACK_LEVEL, run_json)
    if not 0 <= black < white <= 65535:
        raise RunFolderError(f"{run_json}: need 0 <= black_level < white_level <= 65535, got {black}, {white}")
    return RunFolder(
        path=run_dir,
        meta=meta,
        methods={m: _read_method(run_dir, m, require_right) for m in listed},
        sequence=_resolve_sequence(meta.get("sequence"), run_dir),
        white_level=white,
        black_level=black,
    )
