"""ROS ``camera_info`` YAML files (as written by ``camera_calibration``), reader and writer.

The keys used: ``image_width``, ``image_height``, ``camera_name``, ``distortion_model``
and the matrices ``camera_matrix`` (K, 3x3), ``distortion_coefficients`` (D, 1xN),
``rectification_matrix`` (R, 3x3) and ``projection_matrix`` (P, 3x4) as
``rows/cols/data: [...]`` blocks.  Parsed with PyYAML (``yaml.safe_load``), so any YAML
spelling of the same content reads the same: block or flow style, re-written by
``yaml.safe_dump``, comments, multi-line lists with a trailing comma.  On a right camera,
``P[0, 3] = -fx' * baseline`` (ROS).  :func:`write_camera_info` writes the same layout
with every number at full precision, so that reading it back gives the same arrays.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from emulator.errors import CalibrationError
from emulator.io.files import atomic_write_bytes

__all__ = ["CameraInfo", "read_camera_info", "format_camera_info", "write_camera_info", "DISTORTION_MODELS"]

#: Supported distortion models and their numbers of coefficients.
DISTORTION_MODELS = {"plumb_bob": (4, 5, 8), "rational_polynomial": (8,), "none": (0,), "": (0,)}


@dataclass(frozen=True)
class CameraInfo:
    """One camera of a ROS ``camera_info`` file.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    K : numpy.ndarray
        (3, 3) intrinsic matrix, pixels.
    D : numpy.ndarray
        Distortion coefficients (OpenCV order k1, k2, p1, p2[, k3, ...]).
    R : numpy.ndarray
        (3, 3) rectification rotation.
    P : numpy.ndarray
        (3, 4) projection matrix; ``P[0, 3] = -fx' * baseline`` on the right camera.
    distortion_model : str
    name : str
    path : pathlib.Path or None
        The YAML file it was read from.
    """

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray
    R: np.ndarray
    P: np.ndarray
    distortion_model: str = "plumb_bob"
    name: str = ""
    path: Path | None = None


def _load_yaml(path: Path) -> dict:
    import yaml

    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise CalibrationError(f"{path}: not a text file (ROS camera_info YAML)") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise CalibrationError(f"{path}: not valid YAML{where}: {problem}") from None
    if not isinstance(data, dict):
        raise CalibrationError(f"{path}: expected a YAML mapping of camera_info fields, got {type(data).__name__}")
    return data


def _scalar(data: dict, key: str, path: Path, required: bool = True) -> str | None:
    value = data.get(key)
    if value is None or value == "":
        if required:
            raise CalibrationError(f"{path}: missing '{key}'")
        return None
    if isinstance(value, (dict, list)):
        raise CalibrationError(f"{path}: '{key}' must be a single value, got a {type(value).__name__}")
    return str(value).strip()


def _integer(data: dict, key: str, path: Path) -> int:
    value = data.get(key)
    if value is None:
        raise CalibrationError(f"{path}: missing '{key}'")
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise CalibrationError(f"{path}: '{key}' must be an integer, got {value!r}")
    try:
        number = float(value)
    except ValueError:
        raise CalibrationError(f"{path}: '{key}' must be an integer, got {value!r}") from None
    if not number.is_integer():
        raise CalibrationError(f"{path}: '{key}' must be an integer, got {value!r}")
    return int(number)


def _matrix(data: dict, key: str, path: Path, shape: tuple[int, int] | None) -> np.ndarray:
    block = data.get(key)
    if not isinstance(block, dict) or not {"rows", "cols", "data"} <= set(block):
        raise CalibrationError(f"{path}: missing or malformed '{key}' (expected rows, cols, data: [...])")
    try:
        rows, cols = int(block["rows"]), int(block["cols"])
    except (TypeError, ValueError):
        raise CalibrationError(f"{path}: '{key}' rows and cols must be integers") from None
    values = block["data"]
    if not isinstance(values, list):
        raise CalibrationError(f"{path}: '{key}' data must be a list of numbers, got {values!r}")
    try:
        values = np.array([float(v) for v in values], dtype=np.float64)
    except (TypeError, ValueError):
        raise CalibrationError(f"{path}: '{key}' data holds a non-number") from None
    if values.size != rows * cols:
        raise CalibrationError(f"{path}: '{key}' has {values.size} values for rows={rows} cols={cols}")
    if shape is not None and (rows, cols) != shape:
        raise CalibrationError(f"{path}: '{key}' must be {shape[0]}x{shape[1]}, got {rows}x{cols}")
    if not np.all(np.isfinite(values)):
        raise CalibrationError(f"{path}: '{key}' holds a non-finite value")
    return values.reshape(rows, cols)


def read_camera_info(path: str | os.PathLike) -> CameraInfo:
    """Read a ROS ``camera_info`` YAML file (PyYAML ``safe_load``: any YAML layout, block or
    flow style, as written by ``camera_calibration``, ``yaml.safe_dump`` or by hand).

    Raises
    ------
    CalibrationError
        One line naming the file and the field: the file is missing or not YAML, a key is
        missing or a matrix is malformed, the distortion model is unsupported, or R is not a
        rotation.
    """
    path = Path(path)
    if not path.is_file():
        raise CalibrationError(f"{path}: calibration file does not exist")
    data = _load_yaml(path)
    width = _integer(data, "image_width", path)
    height = _integer(data, "image_height", path)
    if width < 1 or height < 1:
        raise CalibrationError(f"{path}: image size must be positive, got {width}x{height}")
    K = _matrix(data, "camera_matrix", path, (3, 3))
    D = _matrix(data, "distortion_coefficients", path, None).ravel()
    R = _matrix(data, "rectification_matrix", path, (3, 3))
    P = _matrix(data, "projection_matrix", path, (3, 4))
    model = (_scalar(data, "distortion_model", path, required=False) or "plumb_bob").lower()
    if model not in DISTORTION_MODELS:
        raise CalibrationError(
            f"{path}: distortion_model {model!r} is not supported; use one of plumb_bob, rational_polynomial"
        )
    if D.size not in DISTORTION_MODELS[model] and not (D.size == 0 or np.all(D == 0)):
        raise CalibrationError(f"{path}: {D.size} distortion coefficients do not fit the {model} model")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise CalibrationError(f"{path}: camera_matrix must have positive focal lengths")
    if abs(np.linalg.det(R) - 1.0) > 1e-3:
        raise CalibrationError(f"{path}: rectification_matrix is not a rotation (det = {np.linalg.det(R):.6f})")
    name = _scalar(data, "camera_name", path, required=False) or ""
    return CameraInfo(width, height, K, D, R, P, model, name, path)


def _block(key: str, m: np.ndarray) -> str:
    m = np.atleast_2d(np.asarray(m, dtype=np.float64))
    data = "[" + ", ".join(repr(float(v) + 0.0) for v in m.ravel()) + "]"
    return f"{key}:\n  rows: {m.shape[0]}\n  cols: {m.shape[1]}\n  data: {data}\n"


def format_camera_info(info: CameraInfo) -> str:
    """The YAML text of a :class:`CameraInfo` (layout of ROS ``camera_calibration``)."""
    K = np.asarray(info.K, dtype=np.float64)
    R = np.asarray(info.R, dtype=np.float64)
    P = np.asarray(info.P, dtype=np.float64)
    if K.shape != (3, 3) or R.shape != (3, 3) or P.shape != (3, 4):
        raise CalibrationError(f"camera_info: need K 3x3, R 3x3, P 3x4, got {K.shape}, {R.shape}, {P.shape}")
    return (
        f"image_width: {int(info.width)}\n"
        f"image_height: {int(info.height)}\n"
        f"camera_name: {info.name}\n"
        + _block("camera_matrix", K)
        + f"distortion_model: {info.distortion_model}\n"
        + _block("distortion_coefficients", np.asarray(info.D, dtype=np.float64).reshape(1, -1))
        + _block("rectification_matrix", R)
        + _block("projection_matrix", P)
    )


def write_camera_info(path: str | os.PathLike, info: CameraInfo, *, overwrite: bool = False) -> Path:
    """Write a ROS ``camera_info`` YAML file atomically."""
    return atomic_write_bytes(path, format_camera_info(info).encode(), overwrite=overwrite)
