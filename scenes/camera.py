"""Pinhole camera model shared by the renderer and the visual-odometry code.

Poses are 4x4 camera-to-world matrices in the OpenCV / robotics camera frame:
x right, y down, z forward (optical axis).  Mitsuba's perspective sensor looks
along its local +z with +y up and +x to the *left* of the image, so its
``to_world`` is the pose times ``diag(-1, -1, 1, 1)``: a half turn about the
optical axis, which keeps the frame right-handed.  Pixel (0, 0) is the centre of
the top-left pixel (OpenCV convention), so the principal point of a centred
sensor is ((W - 1) / 2, (H - 1) / 2).
"""

from __future__ import annotations

import math

import numpy as np

from scenes.errors import RenderError
from synth.pose import check_pose

__all__ = ["DEFAULT_FOV_DEG", "DEFAULT_SATURATE_MS", "intrinsics", "intrinsics_matrix", "pose_to_mitsuba", "check_pose",
           "project", "check_size", "check_fov"]

#: Horizontal field of view matching the BorealHDR cameras (fx ~ 1180 px at
#: 1920 px wide): 2 * atan(960 / 1180) = 78.26 degrees.
DEFAULT_FOV_DEG = math.degrees(2.0 * math.atan(960.0 / 1180.0))

#: A white surface facing the sun (a scene's reference radiance) fills the synthetic camera's well at
#: this exposure (ms) by default (scenes.synthesize, scenes.image_stats, scenes.adaptive): sunlit snow
#: then sits near the top of the 1 ms bracket and deep shade needs the 32 ms one.
DEFAULT_SATURATE_MS = 1.0

#: OpenCV camera frame -> Mitsuba camera frame (half turn about z).
_CV_TO_MITSUBA = np.diag([-1.0, -1.0, 1.0, 1.0])


def check_size(width: int, height: int) -> None:
    """A RenderError unless ``width`` and ``height`` are positive integers."""
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise RenderError(f"{name} must be a positive integer, got {v!r}")


def check_fov(fov_deg: float) -> float:
    """``fov_deg`` as a float, or a RenderError unless it is finite and in [1, 170] degrees."""
    f = float(fov_deg)
    if not (math.isfinite(f) and 1.0 <= f <= 170.0):
        raise RenderError(f"fov_deg must be in [1, 170] degrees, got {fov_deg!r}")
    return f


def intrinsics(width: int, height: int, fov_deg: float = DEFAULT_FOV_DEG) -> tuple[float, float, float, float]:
    """Pinhole intrinsics (fx, fy, cx, cy) in pixels of a render.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    fov_deg : float
        Horizontal field of view in degrees (the render's ``fov_deg``).

    Returns
    -------
    tuple of float
        ``fx = fy = (W / 2) / tan(fov / 2)`` (square pixels), ``cx = (W - 1) / 2``,
        ``cy = (H - 1) / 2`` (OpenCV pixel-centre convention).

    Examples
    --------
    >>> fx, fy, cx, cy = intrinsics(1920, 1200)
    >>> round(fx), cx, cy
    (1180, 959.5, 599.5)
    """
    check_size(width, height)
    f = check_fov(fov_deg)
    fx = (width / 2.0) / math.tan(math.radians(f) / 2.0)
    return fx, fx, (width - 1) / 2.0, (height - 1) / 2.0


def intrinsics_matrix(width: int, height: int, fov_deg: float = DEFAULT_FOV_DEG) -> np.ndarray:
    """The 3x3 camera matrix K (float64) of :func:`intrinsics`."""
    fx, fy, cx, cy = intrinsics(width, height, fov_deg)
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def pose_to_mitsuba(pose) -> np.ndarray:
    """Mitsuba sensor ``to_world`` (4x4 float64) of an OpenCV-frame camera-to-world pose."""
    return check_pose(pose) @ _CV_TO_MITSUBA


def project(points_world, pose, width: int, height: int, fov_deg: float = DEFAULT_FOV_DEG) -> np.ndarray:
    """Pixel coordinates (u, v) of world points; rows behind the camera are NaN.

    Parameters
    ----------
    points_world : array-like
        (N, 3) points, metres.
    pose : array-like
        4x4 camera-to-world pose (OpenCV frame).

    Returns
    -------
    numpy.ndarray
        float64 (N, 2).
    """
    fx, fy, cx, cy = intrinsics(width, height, fov_deg)
    m = check_pose(pose)
    p = np.atleast_2d(np.asarray(points_world, dtype=np.float64))
    pc = (p - m[:3, 3]) @ m[:3, :3]
    z = np.where(pc[:, 2] > 0, pc[:, 2], np.nan)
    return np.stack([fx * pc[:, 0] / z + cx, fy * pc[:, 1] / z + cy], axis=-1)
