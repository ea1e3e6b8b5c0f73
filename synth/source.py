"""The radiance source of a capture (:func:`synth.sequence.capture_sequence`): how a shot's radiance and pose
are asked for, checked and described.

A source is a callable ``source(timestamp_s, camera[, exposure_ms]) -> (radiance, pose)`` or a list of
precomputed frames (one ``(radiance, pose)`` or ``{"left": ..., "right": ...}`` per shot):
:func:`frame_getter` gives one way to ask both, :func:`source_frame` checks what comes back (the pose by
:func:`synth.pose.check_pose`), :func:`check_rig` the stereo rig, and :func:`describe_source` what
``exposim.json`` records of it.
"""

from __future__ import annotations

import numpy as np

from synth.errors import SourceError
from synth.pose import check_pose

__all__ = ["RIG_TOL", "frame_getter", "describe_source", "source_frame", "check_rig"]

#: Tolerances of the stereo-rig check on the source's poses (m, and rotation entries).
RIG_TOL = 1e-6


def frame_getter(source, stereo: bool):
    """``get(shot, side) -> (radiance, pose)`` and the number of frames (None: unbounded)."""
    if callable(source):
        if getattr(source, "exposure_aware", False):  # integrates over each shot's own exposure window
            return (lambda shot, side, exposure_ms=None: source(
                shot.time_s, side, shot.exposure_ms if exposure_ms is None else exposure_ms)), None
        return (lambda shot, side, exposure_ms=None: source(shot.time_s, side)), None
    if isinstance(source, (list, tuple)):
        frames = source

        def get(shot, side, exposure_ms=None):
            item = frames[shot.index]
            if isinstance(item, dict):
                if side not in item:
                    raise SourceError(f"frame {shot.index} has no {side!r} entry (keys: {', '.join(map(str, item))})")
                item = item[side]
            elif stereo:
                raise SourceError(
                    f"frame {shot.index}: a stereo capture needs {{'left': (radiance, pose), 'right': ...}} "
                    f"per frame, got {type(item).__name__}"
                )
            return item

        return get, len(frames)
    raise SourceError(
        f"source must be a callable (timestamp_s, camera) -> (radiance, pose) or a list of frames, "
        f"got {type(source).__name__}"
    )


def describe_source(source, description) -> object:
    """What ``exposim.json`` records of the source: ``description``, else ``source.describe()``, else its kind."""
    if description is not None:
        return description
    describe = getattr(source, "describe", None)
    if callable(describe):
        return describe()
    if isinstance(source, (list, tuple)):
        return {"type": "precomputed frames", "n_frames": len(source)}
    return {"type": getattr(source, "__qualname__", type(source).__qualname__)}


def source_frame(get_frame, shot, side: str, where: str) -> tuple:
    """The ``(radiance, pose)`` of one shot and camera from the source, the pose checked."""
    item = get_frame(shot, side)
    try:
        radiance, pose = item
    except (TypeError, ValueError):
        raise SourceError(
            f"{where}: the source must return (radiance, pose), got {type(item).__name__}"
        ) from None
    return radiance, check_pose(pose, where)


def check_rig(left: np.ndarray, right: np.ndarray, baseline_m: float, where: str) -> None:
    """Refuse a right pose that is not the left one moved ``baseline_m`` along its x axis (:data:`RIG_TOL`)."""
    expected = left[:3, 3] + baseline_m * left[:3, 0]
    if not np.allclose(right[:3, :3], left[:3, :3], atol=RIG_TOL) or not np.allclose(
        right[:3, 3], expected, atol=RIG_TOL
    ):
        raise SourceError(
            f"{where}: the right camera must have the left one's orientation and sit baseline_m = "
            f"{baseline_m:g} m along its x axis (expected position {expected.tolist()}, got "
            f"{right[:3, 3].tolist()})"
        )
