"""A minimal stereo visual odometry with OpenCV (paper section V-D-2).

Pipeline, per frame ``k`` (left and right 8-bit grey images of one capture):

1. **Rectification** from the stereo calibration (:func:`stereo_rectification`).
2. **Stereo depth**: SIFT on both rectified images, left-right matches with the ratio
   test, kept when on the same row (``|y_l - y_r| <= max_row_diff_px``) with a disparity
   in ``[min_disparity_px, max_disparity_px]``; depth ``Z = f b / d``.
3. **Motion**: SIFT matches between the left images of frames ``k - 1`` and ``k``; the
   3-D points of frame ``k - 1`` and their 2-D positions in frame ``k`` give the motion
   by PnP inside RANSAC (``cv2.solvePnPRansac``, seeded by ``cv2.setRNGSeed``), refined by
   Levenberg-Marquardt on the inliers.
4. **Chaining**: ``T_world_k = T_world_(k-1) @ inv(T_(k)_(k-1))``; the first frame is the
   world origin.  Poses are of the *left camera* (unrectified), camera-to-world, OpenCV
   axes (x right, y down, z forward), in metres.

Failures are detected, never hidden.  A frame fails when the previous frame has too few
stereo points, there are too few temporal matches, PnP finds no solution, it has too
few inliers, or the motion is implausible (a jump larger than ``max_step_m`` or
``max_step_deg`` between consecutive frames).

Failure policy (explicit, see :class:`VOResult`): a failed frame gets the previous
frame's motion again (constant velocity; identity when no motion was estimated yet), it
is recorded in ``VOResult.failures`` with its index, timestamp and reason, and tracking
re-initialises from the failed frame's own stereo points.  A run with any failure is
*failed* (``VOResult.succeeded`` is False); the benchmark computes its RPE only on
request, like the paper, which reports RPE for the runs where VO converged.

Calibration and rectification live in :mod:`emulator.metrics.stereo`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass, field

import cv2
import numpy as np

from emulator.errors import CalibrationError, MetricsError
from emulator.metrics.features import RATIO_TEST, SiftFeatures, detect_sift, match_descriptors
from emulator.metrics.stereo import StereoRectification, rotation_angle_deg

__all__ = [
    "VOParameters",
    "VOFailure",
    "VOResult",
    "FAILURE_REASONS",
    "run_stereo_vo",
]

#: Why a frame failed, as recorded in :class:`VOFailure`.
FAILURE_REASONS = {
    "too_few_stereo_points": "the previous frame has too few left-right matches with valid depth",
    "too_few_matches": "too few matches between the previous and the current left image",
    "pnp_failed": "PnP with RANSAC found no pose",
    "too_few_inliers": "the PnP pose has too few RANSAC inliers",
    "implausible_jump": "the motion between consecutive frames exceeds max_step_m or max_step_deg",
}



# --------------------------------------------------------------------------- odometry


@dataclass(frozen=True)
class VOParameters:
    """Parameters of :func:`run_stereo_vo` (pixels refer to the rectified images).

    Attributes
    ----------
    ratio : float
        Lowe's ratio test threshold for left-right and temporal matches.
    n_features : int
        SIFT keypoints kept per image (0: all, the OpenCV default).
    matcher : {"flann", "bf"}
    max_row_diff_px : float
        Largest row difference of a left-right match, pixels.
    min_disparity_px, max_disparity_px : float
        Accepted disparity range, pixels (``min`` bounds the depth: ``Z <= f b / min``).
    pnp_reprojection_px : float
        RANSAC inlier threshold of the reprojection error, pixels.
    pnp_iterations : int
    pnp_confidence : float
    min_stereo_points : int
        Fewest 3-D points a frame needs to be tracked from.
    min_matches : int
        Fewest temporal 3-D to 2-D matches for PnP.
    min_inliers : int
        Fewest RANSAC inliers for an accepted pose.
    max_step_m : float
        Largest plausible translation between consecutive frames, metres.
    max_step_deg : float
        Largest plausible rotation between consecutive frames, degrees.
    seed : int
        Seed of OpenCV's RNG (``cv2.setRNGSeed``) before every RANSAC and kd-tree search.
    """

    ratio: float = RATIO_TEST
    n_features: int = 0
    matcher: str = "flann"
    max_row_diff_px: float = 2.0
    min_disparity_px: float = 1.0
    max_disparity_px: float = 400.0
    pnp_reprojection_px: float = 2.0
    pnp_iterations: int = 500
    pnp_confidence: float = 0.999
    min_stereo_points: int = 20
    min_matches: int = 20
    min_inliers: int = 15
    max_step_m: float = 1.0
    max_step_deg: float = 30.0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.min_inliers < 4 or self.min_matches < self.min_inliers:
            raise MetricsError(
                f"need 4 <= min_inliers <= min_matches, got min_inliers={self.min_inliers}, "
                f"min_matches={self.min_matches}"
            )
        if not 0 < self.min_disparity_px < self.max_disparity_px:
            raise MetricsError("need 0 < min_disparity_px < max_disparity_px")
        if self.max_step_m <= 0 or self.max_step_deg <= 0:
            raise MetricsError("max_step_m and max_step_deg must be positive")


@dataclass(frozen=True)
class VOFailure:
    """A frame the odometry could not track.

    Attributes
    ----------
    index : int
        Frame index in the run (0-based).
    timestamp_ns : int
    reason : str
        One of :data:`FAILURE_REASONS`.
    detail : str
        Counts or values behind the decision.
    """

    index: int
    timestamp_ns: int
    reason: str
    detail: str = ""


@dataclass
class VOResult:
    """Output of :func:`run_stereo_vo`.

    Attributes
    ----------
    timestamps_ns : numpy.ndarray
        (N,) ``int64`` frame timestamps.
    poses : numpy.ndarray
        (N, 4, 4) camera-to-world poses of the left camera, metres; frame 0 is identity.
        Failed frames hold the constant-velocity prediction.
    tracked : numpy.ndarray
        (N,) ``bool``: the pose was measured (frame 0 counts as tracked).
    n_stereo, n_matches, n_inliers : numpy.ndarray
        (N,) ``int64``: 3-D points of the frame, temporal matches and PnP inliers into the
        frame (0 for frame 0).
    row_offset_px : numpy.ndarray
        (N,) ``float64`` median ``y_left - y_right`` of the frame's left-right matches in
        the rectified images, pixels (about 0 when the calibration is right; NaN without
        matches).
    failures : list of VOFailure
    """

    timestamps_ns: np.ndarray
    poses: np.ndarray
    tracked: np.ndarray
    n_stereo: np.ndarray
    n_matches: np.ndarray
    n_inliers: np.ndarray
    row_offset_px: np.ndarray
    failures: list[VOFailure] = field(default_factory=list)

    @property
    def succeeded(self) -> bool:
        """True when every frame was tracked (no failure)."""
        return not self.failures

    def failures_as_dicts(self) -> list[dict]:
        """The failures as JSON-ready dictionaries."""
        return [asdict(f) for f in self.failures]


def _stereo_points(
    left: SiftFeatures, right: SiftFeatures, rect: StereoRectification, p: VOParameters
) -> tuple[SiftFeatures, np.ndarray, float]:
    """Left features with valid stereo depth, their 3-D points (rectified left frame), and
    the median row offset y_l - y_r of all left-right matches (pixels; NaN if none)."""
    pairs = match_descriptors(left.descriptors, right.descriptors, ratio=p.ratio, matcher=p.matcher, seed=p.seed)
    if pairs.shape[0] == 0:
        return left.subset(np.zeros(0, np.int64)), np.zeros((0, 3)), float("nan")
    pl = left.points[pairs[:, 0]].astype(np.float64)
    pr = right.points[pairs[:, 1]].astype(np.float64)
    row_offset = float(np.median(pl[:, 1] - pr[:, 1]))
    disparity = pl[:, 0] - pr[:, 0]
    ok = (
        (np.abs(pl[:, 1] - pr[:, 1]) <= p.max_row_diff_px)
        & (disparity >= p.min_disparity_px)
        & (disparity <= p.max_disparity_px)
    )
    # One 3-D point per left keypoint: drop left keypoints matched twice (duplicates).
    idx = pairs[ok, 0]
    _, first = np.unique(idx, return_index=True)
    keep = np.flatnonzero(ok)[first]
    pl, d = pl[keep], disparity[keep]
    fx, fy, cx, cy = rect.K[0, 0], rect.K[1, 1], rect.K[0, 2], rect.K[1, 2]
    Z = fx * rect.baseline_m / d
    X = (pl[:, 0] - cx) * Z / fx
    Y = (pl[:, 1] - cy) * Z / fy
    return left.subset(pairs[keep, 0]), np.column_stack([X, Y, Z]), row_offset


def _estimate_motion(
    prev_feats: SiftFeatures,
    prev_points3d: np.ndarray,
    prev_row_offset: float,
    cur: SiftFeatures,
    rect: StereoRectification,
    p: VOParameters,
) -> tuple[np.ndarray | None, str | None, str, int, int]:
    """(T_cur_prev 4x4 in the rectified frame or None, failure reason, detail, matches, inliers)."""
    if prev_points3d.shape[0] < p.min_stereo_points:
        detail = f"{prev_points3d.shape[0]} < {p.min_stereo_points}"
        if np.isfinite(prev_row_offset) and abs(prev_row_offset) > p.max_row_diff_px:
            detail += (
                f"; median row offset of the left-right matches {prev_row_offset:.1f} px: the calibration does "
                "not rectify these images (refine the extrinsics: --refine-extrinsics N)"
            )
        return None, "too_few_stereo_points", detail, 0, 0
    pairs = match_descriptors(prev_feats.descriptors, cur.descriptors, ratio=p.ratio, matcher=p.matcher, seed=p.seed)
    n_matches = int(pairs.shape[0])
    if n_matches < p.min_matches:
        return None, "too_few_matches", f"{n_matches} < {p.min_matches}", n_matches, 0
    obj = np.ascontiguousarray(prev_points3d[pairs[:, 0]], dtype=np.float64)
    img = np.ascontiguousarray(cur.points[pairs[:, 1]], dtype=np.float64)
    cv2.setRNGSeed(int(p.seed))
    try:
        ok, rvec, tvec, inliers = cv2.solvePnPRansac(
            obj,
            img,
            rect.K,
            None,
            iterationsCount=p.pnp_iterations,
            reprojectionError=p.pnp_reprojection_px,
            confidence=p.pnp_confidence,
            flags=cv2.SOLVEPNP_EPNP,
        )
    except cv2.error as exc:  # degenerate configurations
        return None, "pnp_failed", f"OpenCV: {str(exc).strip().splitlines()[-1]}", n_matches, 0
    if not ok or inliers is None:
        return None, "pnp_failed", "no consensus", n_matches, 0
    inliers = inliers.ravel()
    n_inliers = int(inliers.size)
    if n_inliers < p.min_inliers:
        return None, "too_few_inliers", f"{n_inliers} < {p.min_inliers} (of {n_matches} matches)", n_matches, n_inliers
    rvec, tvec = cv2.solvePnPRefineLM(obj[inliers], img[inliers], rect.K, None, rvec, tvec)
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    if not np.all(np.isfinite(T)):
        return None, "pnp_failed", "non-finite pose", n_matches, n_inliers
    return T, None, "", n_matches, n_inliers


def run_stereo_vo(
    frames: Iterable[tuple[int, np.ndarray, np.ndarray]],
    rectification: StereoRectification,
    parameters: VOParameters = VOParameters(),
) -> VOResult:
    """Track a stereo sequence and chain the poses of the left camera.

    Parameters
    ----------
    frames : iterable of (timestamp_ns, left8, right8)
        Unrectified (H, W) ``uint8`` grey stereo pairs in time order, matching the
        calibration's image size.  Consumed lazily.
    rectification : StereoRectification
        From :func:`stereo_rectification`.
    parameters : VOParameters

    Returns
    -------
    VOResult
        See the module docstring for the failure policy.

    Raises
    ------
    CalibrationError
        When an image does not have the calibration's size.
    MetricsError
        When no frame is given.
    """
    p = parameters
    C = np.eye(4)
    C[:3, :3] = rectification.R1  # left camera frame -> rectified left frame
    C_inv = np.linalg.inv(C)
    width, height = rectification.input_size
    stamps, poses, tracked, n_stereo, n_matches, n_inliers, row_offsets = [], [], [], [], [], [], []
    prev_row_offset = float("nan")
    failures: list[VOFailure] = []
    prev_feats: SiftFeatures | None = None
    prev_points: np.ndarray | None = None
    last_motion = np.eye(4)  # T_(k-1)_k in the left camera frame (constant velocity)
    pose = np.eye(4)
    for k, (timestamp_ns, left8, right8) in enumerate(frames):
        for name, img in (("left", left8), ("right", right8)):
            if img.shape[:2] != (height, width):
                raise CalibrationError(
                    f"frame {k} ({timestamp_ns}): {name} image is {img.shape[1]}x{img.shape[0]} but the "
                    f"calibration is for {width}x{height} images"
                )
        left_r, right_r = rectification.rectify(left8, right8)
        feats_l = detect_sift(left_r, n_features=p.n_features)
        feats_r = detect_sift(right_r, n_features=p.n_features)
        stereo_feats, points3d, row_offset = _stereo_points(feats_l, feats_r, rectification, p)
        m = i = 0
        ok = True
        if prev_feats is not None:
            T_rect, reason, detail, m, i = _estimate_motion(
                prev_feats, prev_points, prev_row_offset, feats_l, rectification, p
            )
            if T_rect is not None:
                T_cur_prev = C_inv @ T_rect @ C  # in the (unrectified) left camera frame
                motion = np.linalg.inv(T_cur_prev)  # T_prev_cur
                step_m = float(np.linalg.norm(motion[:3, 3]))
                step_deg = rotation_angle_deg(motion[:3, :3])
                if step_m > p.max_step_m or step_deg > p.max_step_deg:
                    reason = "implausible_jump"
                    detail = f"{step_m:.3f} m, {step_deg:.2f} deg (limits {p.max_step_m} m, {p.max_step_deg} deg)"
                else:
                    last_motion = motion
            if reason is not None:
                ok = False
                failures.append(VOFailure(k, int(timestamp_ns), reason, detail))
            pose = pose @ last_motion
        stamps.append(int(timestamp_ns))
        poses.append(pose.copy())
        tracked.append(ok)
        n_stereo.append(points3d.shape[0])
        n_matches.append(m)
        n_inliers.append(i)
        row_offsets.append(row_offset)
        prev_feats, prev_points, prev_row_offset = stereo_feats, points3d, row_offset
    if not stamps:
        raise MetricsError("run_stereo_vo: no frames")
    return VOResult(
        timestamps_ns=np.asarray(stamps, dtype=np.int64),
        poses=np.asarray(poses),
        tracked=np.asarray(tracked, dtype=bool),
        n_stereo=np.asarray(n_stereo, dtype=np.int64),
        n_matches=np.asarray(n_matches, dtype=np.int64),
        n_inliers=np.asarray(n_inliers, dtype=np.int64),
        row_offset_px=np.asarray(row_offsets, dtype=np.float64),
        failures=failures,
    )
