"""The one check of a camera pose, for the synthetic layer and the scenes that render for it."""

from __future__ import annotations

import numpy as np

from synth.errors import PoseError

__all__ = ["check_pose"]


def check_pose(pose, where: str = "camera") -> np.ndarray:
    """Validate a 4x4 rigid camera-to-world pose; return it as float64.

    Raises :class:`synth.errors.PoseError` (a ``ValueError``) naming ``where`` and the problem: not a
    numeric array, wrong shape or a non-finite value, a bottom row other than (0, 0, 0, 1), or a 3x3 block
    that is not a rotation (orthonormal to 1e-6, determinant +1).

    >>> check_pose(np.eye(4)).shape
    (4, 4)
    >>> check_pose(np.eye(3), "frame 2")
    Traceback (most recent call last):
    synth.errors.PoseError: frame 2: pose must be a finite 4x4 matrix, got shape (3, 3)
    """
    try:
        m = np.asarray(pose, dtype=np.float64)
    except (TypeError, ValueError):
        raise PoseError(f"{where}: pose must be a finite 4x4 matrix, got {type(pose).__name__} "
                        f"that is not a numeric array") from None
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise PoseError(f"{where}: pose must be a finite 4x4 matrix, got shape {m.shape}"
                        + ("" if m.shape != (4, 4) else " with a value that is not finite"))
    if not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0), atol=1e-12):
        raise PoseError(f"{where}: pose bottom row must be (0, 0, 0, 1), got {m[3].tolist()}")
    r = m[:3, :3]
    if not np.allclose(r.T @ r, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
        raise PoseError(f"{where}: the pose's 3x3 block is not a rotation")
    return m
