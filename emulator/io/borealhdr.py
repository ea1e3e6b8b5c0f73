"""The BorealHDR recording layout: reader and writer.

Layout (BorealHDR, also written by ``synth``)::

    <sequence>/camera_left/<exposure_ms>/<timestamp_ns>.png    16-bit PNG, 12-bit Bayer DN
    <sequence>/camera_right/<exposure_ms>/<timestamp_ns>.png
    <sequence>/imu/imu.csv         optional IMU (gyro, accelerometer), :mod:`emulator.io.imu`
    <sequence>/exposim.json        optional metadata (white/black level, brackets) from synth
    <sequence>/calibration/response.txt or pcalib*.txt, or <sequence>/../calibration/pcalib*.txt,
    or <clone>/calibration_files/pcalib_inside1.txt   the inverse response (pcalib format);
                                   see emulator.io.layout for the search

:func:`load_sequence` scans the layout into the in-memory model of :mod:`emulator.core.dataset`
(cycles grouped by timestamp); images decode lazily through :func:`read_frame`.  The scan
reads through a :class:`FileSource`, so another container than a folder can be plugged in
without touching the scan; :class:`FolderSource` is the file system, :class:`ZipSource` a
BorealHDR trajectory zip read in place (members are read into memory, nothing is unpacked);
the three live in :mod:`emulator.io.sources`.

The camera's levels are properties of the recording: the BorealHDR sample saturates at
:data:`BOREALHDR_LEVELS` (black 0, white 4094 DN; one :class:`~emulator.core.levels.Levels`
value, defined in the leaf module :mod:`emulator.core.levels` so that :mod:`emulator.core.response`
can default to it without an import circle).  A recording's own ``exposim.json`` (written
by ``synth``) overrides them; these levels are the only fallback anywhere in exposim.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import re
from pathlib import Path

import numpy as np

from emulator.core.dataset import CAMERAS, Frame, Sequence, build_sequence
from emulator.errors import DatasetError
from emulator.io.files import parse_json_object, write_metadata
from emulator.io.framecache import FrameCacheEntryError, cached_frame_path, read_cached_frame, resolve_frame_cache, \
    write_cached_frame
from emulator.io.imu import read_imu
from emulator.io.layout import find_response_file
from emulator.io.pcalib import PCALIB_TABLE_TOP, read_response
from emulator.io.png import decode_png16, write_png16
from emulator.io.sources import CAMERA_FOLDERS, FileSource, FolderSource, ZipSource  # re-exported
from emulator.core.levels import BOREALHDR_LEVELS

__all__ = [
    "BOREALHDR_LEVELS",
    "CAMERA_FOLDERS",
    "METADATA_FILE",
    "FileSource",
    "FolderSource",
    "ZipSource",
    "is_recording",
    "load_sequence",
    "read_frame",
    "write_frame",
    "exposure_folder_name",
    "parse_exposure_folder",
    "read_recording_metadata",
    "write_recording_metadata",
    "find_response",
    "sequence_response",
    "png_size",
]

#: Optional metadata file of a recording (written by ``synth``).
METADATA_FILE = "exposim.json"
_TIMESTAMP_RE = re.compile(r"^(\d+)\.png$")


def is_recording(path: str | os.PathLike) -> bool:
    """Whether ``path`` looks like one recording: a folder with ``camera_left/`` or ``camera_right/``, or a ``.zip``."""
    path = Path(path)
    if path.is_file():
        return path.suffix.lower() == ".zip"
    return path.is_dir() and any((path / d).is_dir() for d in CAMERA_FOLDERS.values())


# ---------------------------------------------------------------------------- names
def exposure_folder_name(exposure_ms: float) -> str:
    """Folder name for an exposure: ``1.0``, ``32.0`` as BorealHDR; full precision otherwise.

    >>> exposure_folder_name(8), exposure_folder_name(0.125)
    ('8.0', '0.125')
    """
    v = float(exposure_ms)
    short = f"{v:.1f}"
    return short if float(short) == v else repr(v)


def parse_exposure_folder(folder: Path) -> float:
    """The exposure (ms) a folder name stands for; :class:`DatasetError` for anything else."""
    try:
        v = float(folder.name)
    except ValueError:
        raise DatasetError(
            f"{folder}: unknown folder name {folder.name!r} (expected an exposure in ms, e.g. '8.0')"
        ) from None
    if not math.isfinite(v) or v <= 0:
        raise DatasetError(f"{folder}: exposure folder {folder.name!r} is not a positive finite number of ms")
    return v


# ---------------------------------------------------------------------------- metadata
def read_recording_metadata(root: str | os.PathLike, source: FileSource | None = None) -> dict:
    """The recording's ``exposim.json`` (``{}`` when absent); :class:`DatasetError` if malformed."""
    root = Path(root)
    source = source or FolderSource(root)
    path = root / METADATA_FILE
    if not source.is_file(path):
        return {}
    return parse_json_object(source.read_bytes(path), path, DatasetError)


def write_recording_metadata(root: str | os.PathLike, metadata: dict, *, overwrite: bool = False) -> Path:
    """Write a recording's ``exposim.json`` (levels, brackets, camera, provenance)."""
    return write_metadata(Path(root) / METADATA_FILE, metadata, overwrite=overwrite)


# ---------------------------------------------------------------------------- reader
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: Signature (8) + IHDR length and type (8) + width and height (8).
_PNG_HEAD = 24


def png_size(head: bytes) -> tuple[int, int] | None:
    r"""(width, height) from the first 24 bytes of a PNG (its IHDR chunk); None if not a PNG.

    >>> png_size(b"\x89PNG\r\n\x1a\n" + b"\x00\x00\x00\rIHDR" + (1920).to_bytes(4, "big") + (1200).to_bytes(4, "big"))
    (1920, 1200)
    """
    if len(head) < _PNG_HEAD or head[:8] != _PNG_SIGNATURE or head[12:16] != b"IHDR":
        return None
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def _read_head(source: FileSource, path: Path) -> bytes:
    reader = getattr(source, "read_head", None)
    return reader(path, _PNG_HEAD) if reader is not None else source.read_bytes(path)[:_PNG_HEAD]


def _check_sizes(source: FileSource, per_camera: dict[str, list[Frame]], root: Path) -> None:
    """Refuse a recording whose PNGs do not all have one size, naming an odd file.

    Reads 24 bytes per file (the IHDR chunk); a file that is not a readable PNG is left to
    :func:`read_frame`, which names it when it is decoded.
    """
    sizes: dict[tuple[int, int], list[Path]] = {}
    for frames in per_camera.values():
        for fr in frames:
            size = png_size(_read_head(source, fr.path))
            if size is not None:
                sizes.setdefault(size, []).append(fr.path)
    if len(sizes) <= 1:
        return
    ranked = sorted(sizes.items(), key=lambda kv: (-len(kv[1]), min(kv[1])))
    (w, h), usual = ranked[0]
    (ow, oh), odd = ranked[1]
    odd = sorted(odd)
    more = sum(len(v) for _, v in ranked[1:]) - 1
    raise DatasetError(
        f"{odd[0]}: image is {ow}x{oh} pixels, but {len(usual)} other image(s) of {root} are {w}x{h} "
        f"(e.g. {min(usual)})" + (f"; {more} more image(s) differ" if more else "")
        + "; every image of a recording must have one size"
    )


def _scan_camera(source: FileSource, cam_dir: Path, camera: str, white_level: int) -> list[Frame]:
    frames: list[Frame] = []
    for entry in source.listdir(cam_dir):
        if entry.name.startswith("."):
            continue
        if not source.is_dir(entry):
            raise DatasetError(f"{entry}: unexpected file in {cam_dir.name}/ (expected exposure folders like '8.0/')")
        exposure_ms = parse_exposure_folder(entry)
        for f in source.listdir(entry):
            if f.name.startswith(".") or f.name.endswith(".part"):
                continue
            m = _TIMESTAMP_RE.match(f.name)
            if not m:
                raise DatasetError(f"{f}: unexpected file name (expected <timestamp_ns>.png)")
            frames.append(Frame(camera, exposure_ms, int(m.group(1)), f, white_level, source, reader=read_frame))
    if not frames:
        raise DatasetError(f"{cam_dir}: camera folder holds no images")
    return frames


def load_sequence(
    path: str | os.PathLike,
    *,
    white_level: int | None = None,
    black_level: int | None = None,
    source: FileSource | None = None,
    frame_cache=None,
    imu_warning: bool = True,
) -> Sequence:
    """Read a recording in the BorealHDR layout into cycles (images decode lazily).

    White and black levels come from the arguments, else from ``exposim.json`` written by
    ``synth``, else the BorealHDR levels (4094, 0).  Raises :class:`DatasetError` for an
    unknown folder, an empty camera folder, shots whose left/right exposures disagree at
    one timestamp, the same shot twice, or a sequence without any camera folder; a missing
    second camera or missing brackets are reported in ``Sequence.gaps``.  ``source``
    replaces the file system (default: :class:`ZipSource` when ``path`` is a file (a
    trajectory zip), else :class:`FolderSource` of ``path``).  ``frame_cache``:
    a decoded-frame cache folder (:mod:`emulator.io.framecache`), ``False`` for none, or
    None to use ``<sequence>/.exposim-frames`` when it exists (folders only).  ``imu_warning``:
    warn (once, :class:`~emulator.io.imu.ImuMissingWarning`) when there is no ``imu/imu.csv``;
    False for a reader that does not need the IMU (a run without ``blur="consistent"``).
    """
    root = Path(path)
    if source is None:
        if root.is_file():
            source = ZipSource(root)
        elif not root.is_dir():
            raise FileNotFoundError(f"{root}: sequence folder not found (nor a trajectory .zip); give the path of a "
                                    "recording folder in the BorealHDR layout (camera_left/<ms>/<ns>.png)")
        else:
            source = FolderSource(root)
    meta = read_recording_metadata(root, source)
    white = int(white_level if white_level is not None else meta.get("white_level", BOREALHDR_LEVELS.white))
    black = int(black_level if black_level is not None else meta.get("black_level", BOREALHDR_LEVELS.black))

    cache_dir = resolve_frame_cache(root, frame_cache) if isinstance(source, FolderSource) else None
    per_camera: dict[str, list[Frame]] = {}
    gaps: list[str] = []
    for cam in CAMERAS:
        folder = CAMERA_FOLDERS[cam]
        d = root / folder
        if source.is_dir(d):
            per_camera[cam] = _scan_camera(source, d, cam, white)
            if cache_dir is not None:
                per_camera[cam] = [dataclasses.replace(f, cache_path=cached_frame_path(cache_dir, root, f.path))
                                   for f in per_camera[cam]]
        else:
            gaps.append(f"{folder}/ missing: no {cam} camera")
    if not per_camera:
        raise DatasetError(f"{root}: no camera_left/ or camera_right/ folder (not a BorealHDR sequence)")
    _check_sizes(source, per_camera, root)
    seq = build_sequence(root, per_camera, white_level=white, black_level=black,
                         brackets_ms=meta.get("brackets_ms", ()), metadata=meta, gaps=gaps)
    seq.imu = read_imu(root, source, warn=imu_warning)  # None (and one ImuMissingWarning) without imu/imu.csv
    return seq


def read_frame(frame: Frame) -> np.ndarray:
    """Decode one frame's image (uint16 (H, W) DN), checked against its white level.

    A frame with a decoded-frame cache entry reads it instead of the PNG (same bytes).
    """
    bad_entry = False
    if frame.cache_path is not None:
        try:
            img = read_cached_frame(frame.cache_path, png_path=frame.path, white_level=frame.white_level)
        except FrameCacheEntryError:  # never used: decoded from the PNG and written again
            img, bad_entry = None, True
        if img is not None:
            return img
    source = frame.source if frame.source is not None else FolderSource(frame.path.parent)
    img = decode_png16(source.read_bytes(frame.path), frame.path, white_level=frame.white_level)
    if bad_entry:
        with contextlib.suppress(OSError):  # a read-only cache: the PNG's pixels are used anyway
            write_cached_frame(frame.cache_path, img)
    return img


# ---------------------------------------------------------------------------- writer
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
    path = Path(sequence_path) / CAMERA_FOLDERS[camera] / exposure_folder_name(exposure_ms) / f"{int(timestamp_ns)}.png"
    return write_png16(path, raw, overwrite=overwrite)


# ---------------------------------------------------------------------------- response
def find_response(sequence_path: str | os.PathLike) -> Path | None:
    """Locate the inverse-response file of a recording, or None.

    Walks up from the recording (:func:`emulator.io.layout.find_response_file`):
    ``<seq>/calibration/response.txt`` or ``pcalib*.txt`` (synthetic datasets),
    ``<seq>/../calibration/pcalib*.txt`` (the BorealHDR sample layout),
    ``<clone>/calibration_files/pcalib_inside1.txt`` (a clone of the BorealHDR repository,
    recordings under ``<clone>/data_sample/``), up to three folders up, beside a symlinked
    zip and beside its target.
    """
    return find_response_file(sequence_path)


def sequence_response(sequence: Sequence, path: str | os.PathLike | None = None):
    """The camera response of a recording, clipped to the recording's levels.

    ``path`` (a pcalib file) overrides discovery through :func:`find_response`.  The table
    spans DN 0..4095 (12 bits) as the pcalib format does; the sequence's white level
    (BorealHDR: 4094) and black level then bound emulation and saturation.
    """
    resp_path = Path(path) if path is not None else find_response(sequence.path)
    if resp_path is None:
        raise DatasetError(
            f"{sequence.path}: no response file found (looked for response.txt or pcalib*.txt in calibration/ "
            f"and calibration_files/ of the recording and of up to 3 folders above it); pass the inverse response "
            f"with --response FILE (a pcalib*.txt of the camera, or one made by 'exposim calibrate')"
        )
    response = read_response(resp_path, white_level=max(PCALIB_TABLE_TOP, sequence.white_level),
                             black_level=sequence.black_level)
    return response.with_levels(white_level=sequence.white_level, black_level=sequence.black_level)
