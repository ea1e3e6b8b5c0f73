"""BorealHDR recordings: reader and writer of the folder layout.

Layout (BorealHDR, also written by ``synth``)::

    <sequence>/camera_left/<exposure_ms>/<timestamp_ns>.png    16-bit PNG, 12-bit Bayer DN
    <sequence>/camera_right/<exposure_ms>/<timestamp_ns>.png
    <sequence>/exposim.json        optional metadata (white/black level, brackets) from synth

A sequence is a list of :class:`Cycle`; a cycle is one sweep of the brackets (1 -> 32 ms).
Shots are grouped into cycles by timestamp, never by file index: a new cycle starts when
the exposure stops increasing or when a whole sweep's time has passed.  Left and right
frames of one capture share a timestamp and are paired by it.  Images decode lazily.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from emulator.errors import DatasetError, OutputExistsError
from emulator.framecache import cached_frame_path, read_cached_frame, resolve_frame_cache

__all__ = [
    "CAMERAS",
    "CAMERA_FOLDERS",
    "BOREALHDR_WHITE_LEVEL",
    "BOREALHDR_BLACK_LEVEL",
    "Frame",
    "Cycle",
    "Sequence",
    "load_sequence",
    "read_png16",
    "write_png16",
    "write_frame",
    "exposure_folder_name",
    "find_response",
    "atomic_write_bytes",
    "sequence_response",
    "read_metadata",
]

CAMERAS = ("left", "right")
CAMERA_FOLDERS = {"left": "camera_left", "right": "camera_right"}
#: The BorealHDR sample saturates at 4094 and its black level is 0 (DESIGN.md).
BOREALHDR_WHITE_LEVEL = 4094
BOREALHDR_BLACK_LEVEL = 0
METADATA_FILE = "exposim.json"
_TIMESTAMP_RE = re.compile(r"^(\d+)\.png$")


# ---------------------------------------------------------------------------- PNG I/O
def read_png16(path: str | os.PathLike, *, white_level: int | None = None) -> np.ndarray:
    """Decode a 16-bit single-channel PNG holding 12-bit DN; clear errors for bad files."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: image not found")
    data = np.fromfile(path, dtype=np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None:
        raise DatasetError(f"{path}: cannot decode image (corrupt or truncated PNG, {data.size} bytes)")
    if img.dtype != np.uint16:
        raise DatasetError(
            f"{path}: expected a 16-bit PNG holding 12-bit DN, got {img.dtype} "
            f"({'8-bit' if img.dtype == np.uint8 else 'other'} image)"
        )
    if img.ndim != 2:
        raise DatasetError(f"{path}: expected a single-channel Bayer mosaic, got shape {img.shape}")
    if white_level is not None:
        top = int(img.max())
        if top > white_level:
            raise DatasetError(
                f"{path}: maximum DN {top} exceeds white_level {white_level} (not 12-bit data?)"
            )
    return img


def atomic_write_bytes(path: str | os.PathLike, data: bytes, *, overwrite: bool = False) -> Path:
    """Write ``data`` to ``path`` through a temporary file and a rename.

    An interrupted write never leaves a partial file under the final name.  Refuses to
    replace an existing file unless ``overwrite``.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path}: exists; refusing to overwrite (use --force / overwrite=True)")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_png16(path: str | os.PathLike, image: np.ndarray, *, overwrite: bool = False) -> Path:
    """Encode a uint16 (or uint8) 2-D image as PNG, atomically."""
    image = np.asarray(image)
    if image.dtype not in (np.uint16, np.uint8) or image.ndim != 2:
        raise DatasetError(f"{path}: can only write 2-D uint16/uint8 images, got {image.dtype} {image.shape}")
    ok, buf = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:  # pragma: no cover - OpenCV failure
        raise DatasetError(f"{path}: PNG encoding failed")
    return atomic_write_bytes(path, buf.tobytes(), overwrite=overwrite)


def exposure_folder_name(exposure_ms: float) -> str:
    """Folder name for an exposure: ``1.0``, ``32.0`` as BorealHDR; full precision otherwise."""
    v = float(exposure_ms)
    short = f"{v:.1f}"
    return short if float(short) == v else repr(v)


def write_frame(
    sequence_path: str | os.PathLike,
    camera: str,
    exposure_ms: float,
    timestamp_ns: int,
    raw: np.ndarray,
    *,
    overwrite: bool = False,
) -> Path:
    """Write one shot in the BorealHDR layout (atomic); returns its path."""
    if camera not in CAMERA_FOLDERS:
        raise DatasetError(f"camera must be one of {CAMERAS}, got {camera!r}")
    if raw.dtype != np.uint16:
        raise DatasetError(f"raw image must be uint16, got {raw.dtype}")
    path = (
        Path(sequence_path)
        / CAMERA_FOLDERS[camera]
        / exposure_folder_name(exposure_ms)
        / f"{int(timestamp_ns)}.png"
    )
    return write_png16(path, raw, overwrite=overwrite)


# ---------------------------------------------------------------------------- model
@dataclass(frozen=True)
class Frame:
    """One shot of one camera; the image is decoded on demand by :meth:`load`."""

    camera: str
    exposure_ms: float
    timestamp_ns: int
    path: Path
    white_level: int = BOREALHDR_WHITE_LEVEL
    #: Decoded-frame cache entry (emulator.framecache), read instead of the PNG when present.
    cache_path: Path | None = field(default=None, compare=False, repr=False)

    def load(self) -> np.ndarray:
        if self.cache_path is not None:
            img = read_cached_frame(self.cache_path, png_path=self.path, white_level=self.white_level)
            if img is not None:
                return img
        return read_png16(self.path, white_level=self.white_level)

    @property
    def exposure_name(self) -> str:
        return self.path.parent.name


@dataclass
class Cycle:
    """One bracket sweep: per camera, exposure_ms -> Frame."""

    index: int
    frames: dict[str, dict[float, Frame]]
    brackets: tuple[float, ...]

    @property
    def timestamp_ns(self) -> int:
        """Timestamp of the cycle's first shot."""
        return min(f.timestamp_ns for cam in self.frames.values() for f in cam.values())

    def missing(self, camera: str) -> list[float]:
        have = self.frames.get(camera, {})
        return [b for b in self.brackets if b not in have]

    @property
    def partial(self) -> bool:
        return any(self.missing(c) for c in self.frames) or len(self.frames) == 0

    def stereo_exposures(self) -> list[float]:
        """Exposures present for both cameras (with one timestamp each)."""
        if not all(c in self.frames for c in CAMERAS):
            return []
        return sorted(set(self.frames["left"]) & set(self.frames["right"]))

    def available(self, cameras: tuple[str, ...] = ("left",)) -> list[float]:
        """Exposures present for every camera in ``cameras``."""
        sets = [set(self.frames.get(c, {})) for c in cameras]
        return sorted(set.intersection(*sets)) if sets else []


@dataclass
class Sequence:
    """A recording: cycles of bracket sweeps from one or two cameras."""

    path: Path
    cycles: list[Cycle]
    cameras: tuple[str, ...]
    brackets: tuple[float, ...]
    white_level: int = BOREALHDR_WHITE_LEVEL
    black_level: int = BOREALHDR_BLACK_LEVEL
    metadata: dict = field(default_factory=dict)
    gaps: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.cycles)

    def __iter__(self):
        return iter(self.cycles)

    def __getitem__(self, i: int) -> Cycle:
        return self.cycles[i]

    @property
    def partial_cycles(self) -> list[int]:
        return [c.index for c in self.cycles if c.partial]

    def describe(self) -> dict:
        """JSON-ready summary (used by ``exposim info --json``)."""
        return {
            "path": str(self.path),
            "cameras": list(self.cameras),
            "brackets_ms": list(self.brackets),
            "white_level": self.white_level,
            "black_level": self.black_level,
            "n_cycles": len(self.cycles),
            "partial_cycles": self.partial_cycles,
            "gaps": list(self.gaps),
            "cycles": [
                {
                    "index": c.index,
                    "timestamp_ns": c.timestamp_ns,
                    "partial": c.partial,
                    **{
                        cam: {f.exposure_name: f.timestamp_ns for _, f in sorted(c.frames.get(cam, {}).items())}
                        for cam in self.cameras
                    },
                    "missing": {cam: c.missing(cam) for cam in self.cameras if c.missing(cam)},
                }
                for c in self.cycles
            ],
        }


# ---------------------------------------------------------------------------- reader
def read_metadata(path: str | os.PathLike, error: type[Exception] = DatasetError) -> dict:
    """The JSON object in an optional metadata file (``{}`` if absent); ``error`` if malformed."""
    path = Path(path)
    if not path.is_file():
        return {}
    try:
        meta = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise error(f"{path}: malformed JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise error(f"{path}: expected a JSON object, got {type(meta).__name__}")
    return meta


def _parse_exposure(folder: Path) -> float:
    try:
        v = float(folder.name)
    except ValueError:
        raise DatasetError(
            f"{folder}: unknown folder name {folder.name!r} (expected an exposure in ms, e.g. '8.0')"
        ) from None
    if not math.isfinite(v) or v <= 0:
        raise DatasetError(f"{folder}: exposure folder {folder.name!r} is not a positive finite number of ms")
    return v


def _scan_camera(cam_dir: Path, camera: str, white_level: int) -> list[Frame]:
    frames: list[Frame] = []
    for entry in sorted(cam_dir.iterdir()):
        if entry.name.startswith("."):
            continue
        if not entry.is_dir():
            raise DatasetError(f"{entry}: unexpected file in {cam_dir.name}/ (expected exposure folders like '8.0/')")
        exposure_ms = _parse_exposure(entry)
        for f in sorted(entry.iterdir()):
            if f.name.startswith(".") or f.name.endswith(".part"):
                continue
            m = _TIMESTAMP_RE.match(f.name)
            if not m:
                raise DatasetError(f"{f}: unexpected file name (expected <timestamp_ns>.png)")
            frames.append(Frame(camera, exposure_ms, int(m.group(1)), f, white_level))
    if not frames:
        raise DatasetError(f"{cam_dir}: camera folder holds no images")
    return frames


def _group_cycles(shots: list[tuple[int, float]], n_brackets: int) -> list[list[tuple[int, float]]]:
    """Split time-sorted (timestamp_ns, exposure_ms) shots into sweeps."""
    if len(shots) > 1:
        dt = np.diff([t for t, _ in shots])
        shot_period = float(np.median(dt))
    else:
        shot_period = 0.0
    sweep_ns = shot_period * n_brackets
    groups: list[list[tuple[int, float]]] = []
    for t, e in shots:
        if groups:
            cur = groups[-1]
            same_sweep = e > cur[-1][1] and (sweep_ns <= 0 or t - cur[0][0] < sweep_ns - 0.5 * shot_period)
            if same_sweep:
                cur.append((t, e))
                continue
        groups.append([(t, e)])
    return groups


def load_sequence(path: str | os.PathLike, *, white_level: int | None = None, black_level: int | None = None,
                  frame_cache=None) -> Sequence:
    """Read a recording in the BorealHDR layout into cycles (images decode lazily).

    White and black levels come from the arguments, else from ``exposim.json`` written by
    ``synth``, else the BorealHDR defaults (4094, 0).  Raises :class:`DatasetError` for an
    unknown folder, an empty camera folder, shots whose left/right exposures disagree at
    one timestamp, or a sequence without any camera folder; a missing second camera or
    missing brackets are reported in ``Sequence.gaps``.  ``frame_cache``: a decoded-frame
    cache folder (:mod:`emulator.framecache`), ``False`` for none, or None to use
    ``<sequence>/.exposim-frames`` when it exists.
    """
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: sequence folder not found")
    meta = read_metadata(root / METADATA_FILE)
    white = int(white_level if white_level is not None else meta.get("white_level", BOREALHDR_WHITE_LEVEL))
    black = int(black_level if black_level is not None else meta.get("black_level", BOREALHDR_BLACK_LEVEL))

    cache_dir = resolve_frame_cache(root, frame_cache)
    per_camera: dict[str, list[Frame]] = {}
    gaps: list[str] = []
    for cam, folder in CAMERA_FOLDERS.items():
        d = root / folder
        if d.is_dir():
            per_camera[cam] = _scan_camera(d, cam, white)
            if cache_dir is not None:
                per_camera[cam] = [dataclasses.replace(f, cache_path=cached_frame_path(cache_dir, root, f.path))
                                   for f in per_camera[cam]]
        else:
            gaps.append(f"{folder}/ missing: no {cam} camera")
    if not per_camera:
        raise DatasetError(f"{root}: no camera_left/ or camera_right/ folder (not a BorealHDR sequence)")

    # One exposure per capture instant, shared by both cameras.
    shot_exposure: dict[int, float] = {}
    for cam, frames in per_camera.items():
        for fr in frames:
            prev = shot_exposure.setdefault(fr.timestamp_ns, fr.exposure_ms)
            if prev != fr.exposure_ms:
                raise DatasetError(
                    f"{fr.path}: timestamp {fr.timestamp_ns} is filed under {fr.exposure_ms} ms here but "
                    f"{prev} ms for another camera or folder"
                )
    brackets = tuple(sorted(set(shot_exposure.values())))
    if "brackets_ms" in meta:
        brackets = tuple(sorted(set(brackets) | {float(b) for b in meta["brackets_ms"]}))
    shots = sorted(shot_exposure.items())
    groups = _group_cycles(shots, len(brackets))

    index_of: dict[int, int] = {t: i for i, g in enumerate(groups) for t, _ in g}
    cycles = [Cycle(i, {cam: {} for cam in per_camera}, brackets) for i in range(len(groups))]
    for cam, frames in per_camera.items():
        for fr in frames:
            cycles[index_of[fr.timestamp_ns]].frames[cam][fr.exposure_ms] = fr
    for c in cycles:
        for cam in per_camera:
            miss = c.missing(cam)
            if miss:
                gaps.append(f"cycle {c.index}: {cam} missing {', '.join(f'{m:g}' for m in miss)} ms")
    return Sequence(root, cycles, tuple(per_camera), brackets, white, black, meta, gaps)


def find_response(sequence_path: str | os.PathLike) -> Path | None:
    """Locate the inverse-response file of a recording, or None.

    Looks for ``<seq>/calibration/response.txt`` or ``pcalib*.txt`` (synthetic datasets),
    then ``<seq>/../calibration/pcalib*.txt`` (the BorealHDR sample layout).
    """
    seq = Path(sequence_path)
    for d in (seq / "calibration", seq.parent / "calibration"):
        if not d.is_dir():
            continue
        if (d / "response.txt").is_file():
            return d / "response.txt"
        found = sorted(d.glob("pcalib*.txt"))
        if found:
            return found[0]
    return None


def sequence_response(sequence: Sequence, path: str | os.PathLike | None = None):
    """The camera response of a recording, clipped to the recording's levels.

    ``path`` (a pcalib file) overrides discovery through :func:`find_response`.  The table
    spans DN 0..4095 (12 bits) as the pcalib format does; the sequence's white level
    (BorealHDR: 4094) and black level then bound emulation and saturation.
    """
    from emulator.response import CameraResponse

    resp_path = Path(path) if path is not None else find_response(sequence.path)
    if resp_path is None:
        raise DatasetError(
            f"{sequence.path}: no response file found (looked for calibration/response.txt or "
            f"pcalib*.txt in the sequence and beside it); pass one explicitly"
        )
    table_top = max(4095, sequence.white_level)
    response = CameraResponse.from_pcalib(resp_path, white_level=table_top)
    return response.with_levels(white_level=sequence.white_level, black_level=sequence.black_level)
