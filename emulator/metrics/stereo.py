"""Stereo calibration and rectification for the stereo VO (paper section V-D-2).

Calibration: ROS ``camera_info`` YAML files ``left.yaml`` and ``right.yaml``
(:func:`emulator.io.camera_info.read_camera_info`).  The rig's relative pose is built from the files'
rectification matrices R_l, R_r and the baseline ``b = -P_r[0, 3] / P_r[0, 0]`` (ROS:
``Tx = -fx' b``): ``R = R_r^T R_l``, ``T = -R_r^T [b, 0, 0]`` (left to right camera).
The images are then rectified by ``cv2.stereoRectify`` from K, D of both cameras and
(R, T), with ``alpha = 0`` (only valid pixels) and zero disparity at infinity.  The
files' own projection matrices are *not* used for rectification: in the BorealHDR
September 2023 files they are not a rectified pair (the two P differ in fy and cy), and
their rectification matrices are identity, so ``R = I`` and ``T = [-b, 0, 0]`` with
``b = 180 / 1009.77 = 0.178 m``.

That identity rotation is not the real rig's: on the shared sample, matches are 16 px
apart vertically after rectification (a relative pitch of about 0.8 deg), so no stereo
match survives the row check and the VO reports ``too_few_stereo_points`` with the
measured row offset.  :func:`estimate_stereo_extrinsics` re-estimates the pitch and roll of R from
left-right matches of a few frames, and the baseline's direction (yaw and the
baseline length keep their calibrated values); with it the row offset on the sample
drops to 0.1-0.3 px.  Whether the data need
it is measured (:func:`epipolar_residual_px` of left-right matches under the given
calibration); ``bench vo`` refines by default when that residual exceeds half the VO's
row tolerance, and records the measurement and the decision in its results.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from emulator.errors import CalibrationError, MetricsError
from emulator.io.camera_info import CameraInfo, read_camera_info
from emulator.metrics.features import detect_sift, match_descriptors

__all__ = [
    "StereoCalibration",
    "load_stereo_calibration",
    "find_calibration",
    "choose_calibration",
    "StereoMatches",
    "stereo_matches",
    "epipolar_residual_px",
    "ExtrinsicsEstimate",
    "estimate_stereo_extrinsics",
    "StereoRectification",
    "stereo_rectification",
    "rotation_angle_deg",
]


def rotation_angle_deg(R: np.ndarray) -> float:
    """Rotation angle of a 3x3 rotation matrix, degrees (``acos((tr R - 1) / 2)``, clipped)."""
    c = (np.trace(R) - 1.0) / 2.0
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


# --------------------------------------------------------------------------- calibration


@dataclass(frozen=True)
class StereoCalibration:
    """A calibrated stereo rig.

    Attributes
    ----------
    left, right : CameraInfo
    baseline_m : float
        Distance between the optical centres, metres (``-P_r[0, 3] / P_r[0, 0]``).
    R : numpy.ndarray
        (3, 3) rotation from the left to the right camera frame, ``R_r^T R_l``.
    T : numpy.ndarray
        (3,) translation from the left to the right camera frame, metres,
        ``-R_r^T [b, 0, 0]`` (``X_r = R X_l + T``, OpenCV's ``stereoRectify`` convention).
    """

    left: CameraInfo
    right: CameraInfo
    baseline_m: float
    R: np.ndarray
    T: np.ndarray

    @property
    def image_size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return (self.left.width, self.left.height)

    def with_extrinsics(self, R: np.ndarray, T: np.ndarray) -> "StereoCalibration":
        """The same cameras with another relative pose (left to right, ``X_r = R X_l + T``)."""
        R = np.asarray(R, dtype=np.float64).reshape(3, 3)
        T = np.asarray(T, dtype=np.float64).reshape(3)
        return StereoCalibration(self.left, self.right, float(np.linalg.norm(T)), R, T)

    def check_image_shape(self, shape: tuple[int, ...], image: str | Path = "image") -> None:
        """Raise :class:`CalibrationError` unless ``shape`` (H, W) matches the calibration."""
        if tuple(shape[:2]) != (self.left.height, self.left.width):
            raise CalibrationError(
                f"{image}: image is {shape[1]}x{shape[0]} but the calibration {self.left.path} is for "
                f"{self.left.width}x{self.left.height} images; use the calibration of this rig (--calibration DIR)"
            )


def load_stereo_calibration(directory: str | Path, *, baseline_m: float | None = None) -> StereoCalibration:
    """Load ``left.yaml`` and ``right.yaml`` from a calibration folder.

    Parameters
    ----------
    directory : str or pathlib.Path
        Folder with ``left.yaml`` and ``right.yaml`` (ROS ``camera_info``).
    baseline_m : float, optional
        Override the baseline, metres (default: ``-P_r[0, 3] / P_r[0, 0]`` from the
        right file).  The BorealHDR April 2023 files give 180 / 1171.9 = 0.154 m this
        way, while the rig's baseline is 0.18 m (their commented-out rectified P gives
        207.3 / 1148.1 = 0.181 m).

    Returns
    -------
    StereoCalibration

    Raises
    ------
    CalibrationError
        When a file is missing or malformed, the two image sizes differ, or the right
        projection matrix does not give a positive baseline.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise CalibrationError(f"{directory}: calibration folder does not exist")
    left = read_camera_info(directory / "left.yaml")
    right = read_camera_info(directory / "right.yaml")
    if (left.width, left.height) != (right.width, right.height):
        raise CalibrationError(
            f"{directory}: left is {left.width}x{left.height} but right is {right.width}x{right.height}"
        )
    if baseline_m is not None:
        if not (math.isfinite(baseline_m) and baseline_m > 0):
            raise CalibrationError(f"baseline_m must be a positive number of metres, got {baseline_m}")
        baseline = float(baseline_m)
    else:
        fx_r, tx = right.P[0, 0], right.P[0, 3]
        if fx_r <= 0 or not tx < 0:
            raise CalibrationError(
                f"{right.path}: projection_matrix must hold Tx = P[0,3] = -fx * baseline < 0 "
                f"(the right camera to the right of the left one), got P[0,3] = {tx}"
            )
        baseline = float(-tx / fx_r)
    R = right.R.T @ left.R
    T = -right.R.T @ np.array([baseline, 0.0, 0.0])
    return StereoCalibration(left, right, baseline, R, T)


def choose_calibration(
    sequence: str | Path | None, override: str | Path | None = None, first_timestamp_ns: int | None = None
):
    """The stereo calibration folder of a recording, and why it was chosen.

    ``override`` if given; else the layout and the recording's date decide
    (:func:`emulator.io.layout.choose_stereo_calibration`): ``<sequence>/calibration``,
    ``calibration/<month>_<year>/`` beside the recording (the BorealHDR sample), or
    ``calibration_files/calibration_vo/<month>_<year>/`` of a BorealHDR clone.

    Returns
    -------
    emulator.io.layout.CalibrationChoice

    Raises
    ------
    CalibrationError
        When nothing holds ``left.yaml`` and ``right.yaml``, or the date cannot choose.
    """
    from emulator.io.layout import CalibrationChoice, choose_stereo_calibration

    if override is not None:
        folder = Path(override)
        if not ((folder / "left.yaml").is_file() and (folder / "right.yaml").is_file()):
            raise CalibrationError(f"{folder}: no left.yaml and right.yaml (ROS camera_info) in this folder")
        return CalibrationChoice(folder, "given (--calibration)")
    if sequence is None:
        raise CalibrationError(
            "no stereo calibration: the run's sequence is unknown or missing; pass --calibration DIR "
            "(a folder with left.yaml and right.yaml)"
        )
    choice = choose_stereo_calibration(sequence, first_timestamp_ns)
    if choice.folder is None:
        raise CalibrationError(f"{sequence}: no stereo calibration chosen: {choice.reason}; pass --calibration DIR "
                               "(a folder with left.yaml and right.yaml)")
    return choice


def find_calibration(sequence: str | Path | None, override: str | Path | None = None,
                     first_timestamp_ns: int | None = None) -> Path:
    """The calibration folder (:func:`choose_calibration` without the reason)."""
    return choose_calibration(sequence, override, first_timestamp_ns).folder


@dataclass(frozen=True)
class ExtrinsicsEstimate:
    """The rig's relative pose estimated from left-right matches.

    Attributes
    ----------
    R : numpy.ndarray
        (3, 3) rotation left to right camera.
    T : numpy.ndarray
        (3,) translation left to right, metres: the estimated direction at the
        calibration's baseline length.
    rotation_deg : list of float
        ``R`` as a rotation vector in degrees (x: pitch, y: yaw, z: roll offsets).
    rotation_change_deg : float
        Angle between the estimated and the calibrated rotation, degrees.
    n_matches, n_inliers : int
        Left-right matches used, and those within 3 px of their epipolar line under the
        estimate.
    residual_before_px, residual_after_px : float
        Median epipolar distance of the matches (:func:`epipolar_residual_px`) under the
        calibrated and under the estimated extrinsics, pixels.
    """

    R: np.ndarray
    T: np.ndarray
    rotation_deg: list[float]
    rotation_change_deg: float
    n_matches: int
    n_inliers: int
    residual_before_px: float = float("nan")
    residual_after_px: float = float("nan")

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        return {
            "R": self.R.tolist(),
            "T_m": self.T.tolist(),
            "rotation_deg": [float(v) for v in self.rotation_deg],
            "rotation_change_deg": float(self.rotation_change_deg),
            "n_matches": self.n_matches,
            "n_inliers": self.n_inliers,
            "epipolar_residual_before_px": round(float(self.residual_before_px), 4),
            "epipolar_residual_after_px": round(float(self.residual_after_px), 4),
        }


@dataclass(frozen=True)
class StereoMatches:
    """Left-right SIFT matches of unrectified stereo pairs, as undistorted normalised points.

    Attributes
    ----------
    left, right : numpy.ndarray
        (N, 2) ``float64`` normalised image coordinates (``K^-1`` and distortion removed).
    n_pairs : int
        Stereo pairs the matches come from.
    """

    left: np.ndarray
    right: np.ndarray
    n_pairs: int

    @property
    def n_matches(self) -> int:
        return int(self.left.shape[0])


def stereo_matches(
    calibration: StereoCalibration,
    pairs: Iterable[tuple[np.ndarray, np.ndarray]],
    *,
    ratio: float = 0.7,
    seed: int = 0,
) -> StereoMatches:
    """SIFT matches (ratio test) between the left and right images of unrectified pairs.

    Parameters
    ----------
    calibration : StereoCalibration
        Its K and D undistort the points.
    pairs : iterable of (left8, right8)
        (H, W) ``uint8`` stereo pairs of the calibration's size.
    ratio : float
        Ratio test threshold (stricter than for tracking).
    seed : int
    """
    nl, nr, n = [], [], 0
    for left8, right8 in pairs:
        n += 1
        calibration.check_image_shape(left8.shape, "left image")
        fl, fr = detect_sift(left8), detect_sift(right8)
        m = match_descriptors(fl.descriptors, fr.descriptors, ratio=ratio, seed=seed)
        if m.shape[0] == 0:
            continue
        nl.append(cv2.undistortPoints(fl.points[m[:, 0]].reshape(-1, 1, 2).astype(np.float64),
                                      calibration.left.K, calibration.left.D).reshape(-1, 2))
        nr.append(cv2.undistortPoints(fr.points[m[:, 1]].reshape(-1, 1, 2).astype(np.float64),
                                      calibration.right.K, calibration.right.D).reshape(-1, 2))
    empty = np.zeros((0, 2))
    return StereoMatches(np.concatenate(nl) if nl else empty, np.concatenate(nr) if nr else empty, n)


def epipolar_residual_px(calibration: StereoCalibration, matches: StereoMatches,
                         R: np.ndarray | None = None, T: np.ndarray | None = None) -> float:
    """Median distance of the right points to their epipolar lines, in pixels.

    With ``E = [T]x R`` (the calibration's R and T unless given), the line of a left point
    ``x_l`` in the right image is ``E x_l`` (normalised coordinates); the distance of
    ``x_r`` to it is ``|x_r^T E x_l| / ||(E x_l)[:2]||``, scaled by the left focal length.
    For a rectified rig it is the row offset ``|y_l - y_r|`` of the rectified images, so it
    compares directly with the VO's row tolerance (``VOParameters.max_row_diff_px``).  The
    median keeps wrong matches from deciding.  NaN without matches.
    """
    if matches.n_matches == 0:
        return float("nan")
    R = calibration.R if R is None else np.asarray(R, dtype=np.float64)
    T = calibration.T if T is None else np.asarray(T, dtype=np.float64).ravel()
    tx = np.array([[0.0, -T[2], T[1]], [T[2], 0.0, -T[0]], [-T[1], T[0], 0.0]])
    E = tx @ R
    xl = np.c_[matches.left, np.ones(matches.n_matches)]
    xr = np.c_[matches.right, np.ones(matches.n_matches)]
    lines = xl @ E.T
    d = np.abs(np.sum(xr * lines, axis=1)) / np.maximum(np.hypot(lines[:, 0], lines[:, 1]), 1e-15)
    return float(np.median(d) * calibration.left.K[0, 0])


def _epipolar_signed_px(R: np.ndarray, T: np.ndarray, matches: StereoMatches, focal_px: float) -> np.ndarray:
    tx = np.array([[0.0, -T[2], T[1]], [T[2], 0.0, -T[0]], [-T[1], T[0], 0.0]])
    E = tx @ R
    xl = np.c_[matches.left, np.ones(matches.n_matches)]
    xr = np.c_[matches.right, np.ones(matches.n_matches)]
    lines = xl @ E.T
    return np.sum(xr * lines, axis=1) / np.maximum(np.hypot(lines[:, 0], lines[:, 1]), 1e-15) * focal_px


def estimate_stereo_extrinsics(
    calibration: StereoCalibration,
    pairs: Iterable[tuple[np.ndarray, np.ndarray]] | StereoMatches,
    *,
    ratio: float = 0.7,
    threshold_px: float = 1.0,
    seed: int = 0,
) -> ExtrinsicsEstimate:
    """Re-estimate the rig's relative rotation from left-right SIFT matches (self-calibration).

    For rigs whose files carry intrinsics and a baseline but no measured relative
    rotation (the BorealHDR September 2023 files hold identity rectification matrices,
    yet their images are 16 px apart vertically after rectification: a relative pitch
    of about 0.8 deg).  The matches of all given pairs, undistorted with each camera's K
    and D, fix a small rotation ``dR`` about the right camera's x (pitch) and z (roll)
    axes, ``R = dR R_calibrated``, and a tilt of the baseline direction (about z: a
    vertical component; about y: a forward one), by robust least squares on their signed
    epipolar distances (``scipy.optimize.least_squares``, soft-L1 loss of scale
    ``threshold_px``, then plain least squares on the matches within ``3 threshold_px``).
    The baseline length and the yaw stay as calibrated: a yaw error shifts every disparity
    by about ``f tan(yaw)`` and so changes the depth scale, which left-right matches cannot
    tell from a different scene depth (an essential-matrix estimate with free yaw on the
    synthetic box room was off by 0.9 deg of yaw and scaled the VO by 1.6).

    Parameters
    ----------
    calibration : StereoCalibration
    pairs : iterable of (left8, right8), or StereoMatches
        Unrectified (H, W) ``uint8`` stereo pairs of the calibration's size, or their
        matches from :func:`stereo_matches`.
    ratio : float
        Ratio test threshold (stricter than for tracking).
    threshold_px : float
        Scale of the robust loss and inlier threshold (x3) on the epipolar distance, pixels
        of the left focal length.
    seed : int
        Seed of the matcher (the fit itself is deterministic).

    Returns
    -------
    ExtrinsicsEstimate

    Raises
    ------
    CalibrationError
        When there are fewer than 50 matches, or fewer than 20 % of them fit the estimate.
    """
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    matches = pairs if isinstance(pairs, StereoMatches) else stereo_matches(calibration, pairs, ratio=ratio, seed=seed)
    n_matches = matches.n_matches
    if n_matches < 50:
        raise CalibrationError(f"estimate_stereo_extrinsics: only {n_matches} left-right matches (need 50)")
    R0, T0 = calibration.R, calibration.T
    baseline = float(np.linalg.norm(T0))
    focal = float(calibration.left.K[0, 0])

    def pose(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R = Rotation.from_rotvec([p[0], 0.0, p[1]]).as_matrix() @ R0
        T = Rotation.from_rotvec([0.0, p[3], p[2]]).as_matrix() @ T0
        return R, T

    def residuals(p: np.ndarray, subset: StereoMatches) -> np.ndarray:
        return _epipolar_signed_px(*pose(p), subset, focal)

    fit = least_squares(residuals, np.zeros(4), args=(matches,), loss="soft_l1", f_scale=threshold_px)
    inlier = np.abs(residuals(fit.x, matches)) <= 3.0 * threshold_px
    n_inliers = int(inlier.sum())
    if n_inliers < max(20, 0.2 * n_matches):
        raise CalibrationError(
            f"estimate_stereo_extrinsics: only {n_inliers} of {n_matches} left-right matches fit a corrected "
            f"rotation within {3 * threshold_px:g} px; estimate rejected")
    subset = StereoMatches(matches.left[inlier], matches.right[inlier], matches.n_pairs)
    fit = least_squares(residuals, fit.x, args=(subset,))
    R, T = pose(fit.x)
    T = T * (baseline / float(np.linalg.norm(T)))
    return ExtrinsicsEstimate(
        R=R,
        T=T,
        rotation_deg=list(np.degrees(Rotation.from_matrix(R).as_rotvec())),
        rotation_change_deg=rotation_angle_deg(R @ R0.T),
        n_matches=n_matches,
        n_inliers=int((np.abs(residuals(fit.x, matches)) <= 3.0 * threshold_px).sum()),
        residual_before_px=epipolar_residual_px(calibration, matches),
        residual_after_px=epipolar_residual_px(calibration, matches, R, T),
    )


@dataclass(frozen=True)
class StereoRectification:
    """Rectification maps and the rectified camera of a stereo rig.

    Attributes
    ----------
    K : numpy.ndarray
        (3, 3) intrinsic matrix of both rectified images, pixels.
    baseline_m : float
        Rectified baseline, metres.
    R1 : numpy.ndarray
        (3, 3) rotation from the left camera frame to the rectified left frame.
    size : tuple of int
        (width, height) of the rectified images, pixels.
    input_size : tuple of int
        (width, height) of the images to rectify (the calibration's), pixels.
    """

    K: np.ndarray
    baseline_m: float
    R1: np.ndarray
    size: tuple[int, int]
    input_size: tuple[int, int]
    _maps: tuple = field(repr=False, default=())

    def rectify(self, left8: np.ndarray, right8: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rectify a left/right pair of (H, W) ``uint8`` images (bilinear)."""
        (l1, l2), (r1, r2) = self._maps
        if self.size != self.input_size:
            sigma = 0.5 * self.input_size[0] / self.size[0]
            left8 = cv2.GaussianBlur(left8, (0, 0), sigma)
            right8 = cv2.GaussianBlur(right8, (0, 0), sigma)
        return (
            cv2.remap(left8, l1, l2, cv2.INTER_LINEAR),
            cv2.remap(right8, r1, r2, cv2.INTER_LINEAR),
        )


def stereo_rectification(
    calibration: StereoCalibration, *, alpha: float = 0.0, scale: float = 1.0
) -> StereoRectification:
    """Rectification of a stereo rig by ``cv2.stereoRectify`` (zero disparity at infinity).

    Parameters
    ----------
    calibration : StereoCalibration
    alpha : float
        OpenCV's free scaling: 0 keeps only valid pixels (no black borders, which would
        add spurious SIFT keypoints), 1 keeps all source pixels.
    scale : float
        Size of the rectified images relative to the calibration's, in (0, 1]; below 1
        the rectification also downsamples (bilinear, after a Gaussian pre-filter of
        ``sigma = 0.5 / scale`` pixels against aliasing), for quick runs.

    Returns
    -------
    StereoRectification
    """
    if not 0.0 < scale <= 1.0:
        raise MetricsError(f"scale must lie in (0, 1], got {scale}")
    size = calibration.image_size
    out_size = (max(1, round(size[0] * scale)), max(1, round(size[1] * scale)))
    R1, R2, P1, P2, *_ = cv2.stereoRectify(
        calibration.left.K,
        calibration.left.D,
        calibration.right.K,
        calibration.right.D,
        size,
        calibration.R,
        calibration.T.reshape(3, 1),
        flags=cv2.CALIB_ZERO_DISPARITY,
        alpha=alpha,
        newImageSize=out_size,
    )
    maps = (
        cv2.initUndistortRectifyMap(calibration.left.K, calibration.left.D, R1, P1, out_size, cv2.CV_16SC2),
        cv2.initUndistortRectifyMap(calibration.right.K, calibration.right.D, R2, P2, out_size, cv2.CV_16SC2),
    )
    baseline = float(-P2[0, 3] / P2[0, 0])
    if not baseline > 0:
        raise CalibrationError(f"{calibration.right.path}: rectification gives a non-positive baseline {baseline}")
    return StereoRectification(
        K=P1[:3, :3].copy(), baseline_m=baseline, R1=R1.copy(), size=out_size, input_size=size, _maps=maps
    )
