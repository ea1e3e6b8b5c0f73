"""Recordings in memory: :class:`Sequence` of :class:`Cycle` of :class:`Frame`.

A sequence is a list of cycles; a cycle is one sweep of the brackets (1 -> 32 ms).  Shots
are grouped into cycles by timestamp, never by file index (:func:`build_sequence`): a new
cycle starts when the exposure stops increasing or when a whole sweep's time has passed.
Left and right frames of one capture share a timestamp and are paired by it.

Reading and writing the BorealHDR folder layout is :mod:`emulator.io.borealhdr`'s job
(:func:`emulator.io.borealhdr.load_sequence`); a :class:`Frame` decodes its image on
demand through it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from emulator.errors import DatasetError
from emulator.core.levels import Levels

__all__ = ["CAMERAS", "Frame", "Cycle", "Sequence", "build_sequence", "group_cycles", "missing_text"]

#: Camera names of a stereo rig, the method (and selector) camera first.
CAMERAS = ("left", "right")


@dataclass(frozen=True)
class Frame:
    """One shot of one camera; the image is decoded on demand by :meth:`load`.

    Attributes
    ----------
    camera : str
        ``"left"`` or ``"right"``.
    exposure_ms : float
        Exposure time, ms.
    timestamp_ns : int
        Capture time, integer nanoseconds.
    path : pathlib.Path
        Where the image is (the name used in messages).
    white_level : int
        Highest valid DN; :meth:`load` refuses an image above it.
    source : object or None
        The file source the frame was found in (:class:`emulator.io.borealhdr.FileSource`);
        None for the file system.
    """

    camera: str
    exposure_ms: float
    timestamp_ns: int
    path: Path
    white_level: int
    source: object = field(default=None, compare=False, repr=False)
    #: Decoded-frame cache entry (:mod:`emulator.io.framecache`), read instead of the PNG when present.
    cache_path: Path | None = field(default=None, compare=False, repr=False)

    #: Decodes the frame (``reader(frame) -> ndarray``): set by the reader that found it
    #: (:func:`emulator.io.borealhdr.read_frame`), so the in-memory model imports no file format.
    reader: Callable[["Frame"], np.ndarray] | None = field(default=None, compare=False, repr=False)

    def load(self) -> np.ndarray:
        """The raw image: (H, W) ``uint16`` Bayer mosaic in DN."""
        if self.reader is None:
            raise DatasetError(f"{self.path}: frame has no reader (frames come from emulator.io.borealhdr."
                               "load_sequence)")
        return self.reader(self)

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

    def missing_by_camera(self, cameras=None) -> dict[str, list[float]]:
        """``{camera: [exposure_ms, ...]}`` of the brackets missing, cameras with none left out."""
        cams = self.frames if cameras is None else cameras
        return {cam: self.missing(cam) for cam in cams if self.missing(cam)}

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
    """A recording: cycles of bracket sweeps from one or two cameras.

    ``white_level`` and ``black_level`` are the camera's clip levels in DN (BorealHDR:
    4094 and 0, :data:`emulator.io.borealhdr.BOREALHDR_LEVELS`); :attr:`levels` gives both as one value.
    """

    path: Path
    cycles: list[Cycle]
    cameras: tuple[str, ...]
    brackets: tuple[float, ...]
    white_level: int
    black_level: int
    metadata: dict = field(default_factory=dict)
    gaps: list[str] = field(default_factory=list)
    #: The recording's IMU (:class:`emulator.io.imu.ImuData`), None without ``imu/imu.csv``.
    imu: object = field(default=None, compare=False, repr=False)

    @property
    def levels(self) -> Levels:
        """The clip levels as one :class:`~emulator.core.levels.Levels` value."""
        return Levels(self.black_level, self.white_level)

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


def group_cycles(shots: list[tuple[int, float]], n_brackets: int) -> list[list[tuple[int, float]]]:
    """Split time-sorted (timestamp_ns, exposure_ms) shots into sweeps.

    A new sweep starts when the exposure stops increasing, or when the sweep would last
    longer than ``n_brackets`` shot periods (the median time between shots).

    >>> group_cycles([(0, 1.0), (10, 2.0), (20, 1.0), (30, 2.0)], 2)
    [[(0, 1.0), (10, 2.0)], [(20, 1.0), (30, 2.0)]]
    """
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


def build_sequence(
    path: Path,
    per_camera: dict[str, list[Frame]],
    *,
    white_level: int,
    black_level: int,
    brackets_ms=(),
    metadata: dict | None = None,
    gaps: list[str] | None = None,
) -> Sequence:
    """Group the frames of each camera into cycles by timestamp.

    Parameters
    ----------
    path : pathlib.Path
        The recording (for messages and :attr:`Sequence.path`).
    per_camera : dict of str to list of Frame
        Every frame found, per camera.
    white_level, black_level : int
        The camera's clip levels, DN.
    brackets_ms : sequence of float
        Brackets the recording was made with, beyond those seen (from its metadata).
    metadata : dict, optional
        The recording's metadata, kept on the sequence.
    gaps : list of str, optional
        Gaps found while reading (e.g. a missing camera); missing brackets are added.

    Raises
    ------
    DatasetError
        When one timestamp is filed under two exposures, or one camera has the same shot
        twice (e.g. in folders ``8`` and ``8.0``).
    """
    gaps = list(gaps or [])
    shot_exposure: dict[int, tuple[float, Frame]] = {}
    for cam, frames in per_camera.items():
        seen: dict[int, Frame] = {}
        for fr in frames:
            twin = seen.setdefault(fr.timestamp_ns, fr)
            if twin is not fr:
                raise DatasetError(
                    f"{fr.path}: the same {cam} shot (timestamp {fr.timestamp_ns}) is also {twin.path}; "
                    "remove one copy"
                )
            prev = shot_exposure.setdefault(fr.timestamp_ns, (fr.exposure_ms, fr))
            if prev[0] != fr.exposure_ms:
                raise DatasetError(
                    f"{fr.path}: timestamp {fr.timestamp_ns} is filed under {fr.exposure_ms} ms here but "
                    f"{prev[0]} ms for another camera or folder"
                )
    brackets = tuple(sorted({e for e, _ in shot_exposure.values()} | {float(b) for b in brackets_ms}))
    shots = sorted((t, e) for t, (e, _) in shot_exposure.items())
    groups = group_cycles(shots, len(brackets))

    index_of: dict[int, int] = {t: i for i, g in enumerate(groups) for t, _ in g}
    cycles = [Cycle(i, {cam: {} for cam in per_camera}, brackets) for i in range(len(groups))]
    for cam, frames in per_camera.items():
        for fr in frames:
            cycles[index_of[fr.timestamp_ns]].frames[cam][fr.exposure_ms] = fr
    for c in cycles:
        for cam in per_camera:
            if c.missing(cam):
                gaps.append(f"cycle {c.index}: {missing_text({cam: c.missing(cam)})}")
    return Sequence(Path(path), cycles, tuple(per_camera), brackets, int(white_level), int(black_level),
                    dict(metadata or {}), gaps)


def missing_text(missing: dict) -> str:
    """``{camera: [exposure_ms, ...]}`` in words: ``left missing 1 ms; right missing 1, 2, 4 ms``."""
    return "; ".join(f"{cam} missing {', '.join(f'{float(m):g}' for m in ms)} ms" for cam, ms in missing.items() if ms)
