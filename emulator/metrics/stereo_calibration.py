"""Stereo calibration files: the rig (K, D of both cameras, R, T) from ROS ``camera_info`` YAML.

Split out of :mod:`emulator.metrics.stereo` (which re-exports every name here; its docstring
describes the conventions).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from emulator.errors import CalibrationError
from emulator.io.camera_info import CameraInfo, read_camera_info
from emulator.io.layout import CalibrationChoice, choose_stereo_calibration

__all__ = [
    "rotation_angle_deg",
    "StereoCalibration",
    "load_stereo_calibration",
    "choose_calibration",
    "find_calibration",
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
