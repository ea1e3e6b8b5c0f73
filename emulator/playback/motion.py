"""Motion of a recording: its gyro and stereo intrinsics joined to predict each frame's blur.

:func:`recording_motion` builds a :class:`RecordingMotion` from a :class:`~emulator.core.dataset.Sequence`
with an IMU (``Sequence.imu``) and the ROS ``camera_info`` files of its cameras
(:func:`find_camera_calibration`); the numbers come from :mod:`emulator.core.blur`.  Used by
``exposim info`` (blur per cycle and bracket), ``exposim emulate --blur consistent`` and
``exposim run --blur consistent`` (:func:`blur_hook`).  Conventions and assumptions:
``docs/blur.md``.
"""

from __future__ import annotations

import datetime as _dt
import math
import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from emulator.core.blur import (
    BLUR_MODES,
    DEFAULT_PLACEMENT,
    DEFAULT_STAMP,
    R_CAM_IMU_FLU,
    STAMP_CONVENTIONS,
    AngularVelocity,
    FrameBlur,
    as_angular_velocity,
    blur_homographies,
    blur_mismatch_px,
    emulate_blur_consistent,
    GyroBias,
    gyro_in_camera,
    still_gyro_bias,
    predict_blur,
    scale_intrinsics,
)
from emulator.errors import CalibrationError, EmulationError
from emulator.core.select import blur_aware, select
from emulator.io.blurtable import write_blur_table
from emulator.io.camera_info import read_camera_info

__all__ = ["RecordingMotion", "recording_motion", "find_camera_calibration", "blur_table", "BlurHook", "blur_hook"]

_MONTHS = ("january", "february", "march", "april", "may", "june", "july", "august", "september", "october",
           "november", "december")


def find_camera_calibration(sequence, override=None) -> Path | None:
    """The folder with ``left.yaml``/``right.yaml`` for a recording, or None.

    ``override`` if given (must hold ``left.yaml``); else ``<seq>/calibration``; else, in
    ``<seq>/../calibration/``, the sub-folder named ``<month>_<year>`` of the recording's
    first timestamp (BorealHDR: ``september_2023``), or the only one.
    """
    if override is not None:
        folder = Path(override)
        if not (folder / "left.yaml").is_file():
            raise CalibrationError(f"{folder}: no left.yaml (ROS camera_info) in this folder")
        return folder
    seq_path = Path(sequence.path)
    own = seq_path / "calibration"
    if (own / "left.yaml").is_file():
        return own
    parent = seq_path.parent / "calibration"
    if not parent.is_dir():
        return None
    found = sorted(d for d in parent.iterdir() if (d / "left.yaml").is_file())
    if len(found) == 1:
        return found[0]
    if not found or not sequence.cycles:
        return None
    when = _dt.datetime.fromtimestamp(sequence.cycles[0].timestamp_ns * 1e-9, tz=_dt.timezone.utc)
    name = f"{_MONTHS[when.month - 1]}_{when.year}"
    for d in found:
        if d.name.lower() == name:
            return d
    return None


@dataclass
class RecordingMotion:
    """A recording's gyro (camera axes) and per-camera intrinsics.

    Attributes
    ----------
    omega : AngularVelocity
        Angular velocity in camera axes over time in s since ``origin_ns``.
    origin_ns : int
        Timestamp (ns) of ``t = 0``.
    intrinsics : dict of str to (numpy.ndarray, (int, int))
        Per camera: K (3x3) and the (width, height) it is calibrated for.
    stamp : str
        Timestamp convention (:data:`emulator.core.blur.STAMP_CONVENTIONS`).
    """

    omega: AngularVelocity
    origin_ns: int
    intrinsics: dict
    stamp: str = DEFAULT_STAMP
    R_cam_imu: np.ndarray = field(default_factory=lambda: R_CAM_IMU_FLU.copy())
    #: The gyro offset subtracted (None: none, e.g. a synthetic ``omega``).
    bias: GyroBias | None = None

    def t_s(self, timestamp_ns: int) -> float:
        return (int(timestamp_ns) - self.origin_ns) * 1e-9

    def K(self, camera: str, size: tuple[int, int] | None = None) -> tuple[np.ndarray, tuple[int, int]]:
        """K for ``camera`` (the left camera's when it has none) at image ``size`` (default: calibrated)."""
        K, calib_size = self.intrinsics.get(camera) or self.intrinsics["left"]
        if size is None or tuple(size) == tuple(calib_size):
            return K, tuple(calib_size)
        return scale_intrinsics(K, calib_size, size), tuple(size)

    def frame_blur(self, camera: str, timestamp_ns: int, exposure_ms: float, size=None) -> FrameBlur:
        K, sz = self.K(camera, size)
        return predict_blur(self.omega, K, sz, self.t_s(timestamp_ns), exposure_ms, self.stamp)

    def mismatch_px(self, camera: str, timestamp_ns: int, source_ms: float, target_ms: float, size=None) -> float:
        K, sz = self.K(camera, size)
        return blur_mismatch_px(self.omega, K, sz, self.t_s(timestamp_ns), source_ms, target_ms, self.stamp)

    def homographies(self, camera: str, timestamp_ns: int, source_ms: float, target_ms: float, size=None):
        K, sz = self.K(camera, size)
        return blur_homographies(self.omega, K, sz, self.t_s(timestamp_ns), source_ms, target_ms, self.stamp)


def recording_motion(sequence, calibration=None, *, stamp: str = DEFAULT_STAMP, R_cam_imu=R_CAM_IMU_FLU,
                     omega=None, origin_ns: int = 0, remove_bias: bool = True,
                     intrinsics: dict | None = None) -> RecordingMotion | None:
    """The motion of a recording, or None when it has no IMU (and no ``omega`` is given).

    ``calibration``: a folder with ``left.yaml`` (and ``right.yaml``), or None to find one
    (:func:`find_camera_calibration`); :class:`CalibrationError` when none is found.
    ``omega``: angular velocity in camera axes (anything
    :func:`emulator.core.blur.as_angular_velocity` takes, times in s since ``origin_ns``),
    used instead of the IMU (synthetic walks).  ``remove_bias``: subtract the gyro offset
    measured where the IMU is still (:func:`emulator.core.blur.still_gyro_bias`; on the
    BorealHDR sample 0.4-0.8 deg/s, as much as the sample's cycles turn).  ``intrinsics``:
    camera -> (K (3x3), (width, height)) instead of calibration files (synthetic cameras).
    """
    if stamp not in STAMP_CONVENTIONS:
        raise EmulationError(f"stamp must be one of {', '.join(STAMP_CONVENTIONS)}, got {stamp!r}")
    if omega is None:
        if getattr(sequence, "imu", None) is None:
            return None
        imu = sequence.imu
        bias = still_gyro_bias(imu.timestamp_ns, imu.gyro_rad_s, imu.acc_m_s2) if remove_bias else None
        omega, origin_ns = gyro_in_camera(imu, R_cam_imu, bias_rad_s=None if bias is None else bias.bias_rad_s)
    else:
        omega, bias = as_angular_velocity(omega), None
    if intrinsics is not None:
        intrinsics = {cam: (np.asarray(K, dtype=np.float64), (int(size[0]), int(size[1])))
                      for cam, (K, size) in intrinsics.items()}
        return RecordingMotion(omega, int(origin_ns), intrinsics, stamp, np.asarray(R_cam_imu, dtype=np.float64),
                               bias)
    folder = find_camera_calibration(sequence, calibration)
    if folder is None:
        raise CalibrationError(
            f"{sequence.path}: no camera calibration (left.yaml) in calibration/ beside or inside the recording; "
            "pass --calibration DIR to predict blur in pixels")
    intrinsics = {}
    for cam in ("left", "right"):
        path = folder / f"{cam}.yaml"
        if path.is_file():
            info = read_camera_info(path)
            intrinsics[cam] = (np.asarray(info.K, dtype=np.float64), (int(info.width), int(info.height)))
    return RecordingMotion(omega, int(origin_ns), intrinsics, stamp, np.asarray(R_cam_imu, dtype=np.float64), bias)


def blur_table(sequence, motion: RecordingMotion, camera: str = "left") -> list[dict]:
    """One row per frame of ``camera``: cycle, exposure_ms, timestamp_ns and the :class:`FrameBlur`."""
    rows = []
    for c in sequence.cycles:
        for e, fr in sorted(c.frames.get(camera, {}).items()):
            b = motion.frame_blur(camera, fr.timestamp_ns, e)
            rows.append({"cycle": c.index, "exposure_ms": e, "timestamp_ns": fr.timestamp_ns, **b.to_dict()})
    return rows


@dataclass
class BlurHook:
    """What a closed loop needs for ``--blur consistent``: one call per emulated image.

    :meth:`emulate` returns the blur-consistent image and the blur mismatch (px, the
    source's excess blur over a capture at the target; > 0 only where the target is
    shorter than the source bracket, the added blur makes it 0 where it is longer).
    :meth:`apply` is the loop's entry (:mod:`emulator.playback`): it also records one row per
    emulated image for ``blur.csv`` (:meth:`write_table`).
    """

    motion: RecordingMotion
    response: object
    #: Select brackets with :func:`emulator.core.select.blur_aware` instead of HigherNoSat.
    blur_aware: bool = False
    _rows: dict = field(default_factory=dict, repr=False)
    _lock: object = field(default_factory=threading.Lock, repr=False)

    def describe(self) -> dict:
        """What ``run.json`` records under ``"blur"``."""
        m = self.motion
        return {"mode": "consistent", "blur_aware": bool(self.blur_aware), "stamp": m.stamp,
                "placement": DEFAULT_PLACEMENT,
                "R_cam_imu": m.R_cam_imu.tolist(),
                "gyro_bias": None if m.bias is None else m.bias.to_dict(),
                "focal_px": {cam: float(K[0, 0]) for cam, (K, _) in m.intrinsics.items()}}

    def select(self, selector: str, cycle, camera: str, target_ms: float, brackets, select_kw: dict):
        """The loop's bracket choice: ``selector``, or :func:`emulator.core.select.blur_aware` when
        :attr:`blur_aware` (``selector`` must then be ``higher-no-sat``)."""
        if not self.blur_aware:
            return select(selector, target_ms, brackets, **select_kw)
        if selector != "higher-no-sat":
            raise EmulationError(f"the blur-aware selection refines higher-no-sat, not {selector!r}")
        frames = cycle.frames[camera]
        return blur_aware(target_ms, brackets, **select_kw, excess_blur_px=lambda b: self.motion.mismatch_px(
            camera, frames[b].timestamp_ns, b, target_ms))

    def apply(self, cycle, camera: str, source_ms: float, ratio: float, raw: np.ndarray,
              plain: np.ndarray) -> np.ndarray:
        """The emulated image of ``raw`` (``plain``: its exact emulation at ``ratio``), blur-consistent."""
        target_ms = source_ms * ratio
        frame = cycle.frames[camera][source_ms]
        size = (raw.shape[1], raw.shape[0])
        src = self.motion.frame_blur(camera, frame.timestamp_ns, source_ms, size).max_px
        tgt = self.motion.frame_blur(camera, frame.timestamp_ns, target_ms, size).max_px
        added = target_ms > source_ms and math.isfinite(tgt)  # outside the gyro's span: plain emulation
        out = plain
        if added:
            Hs, ws = self.motion.homographies(camera, frame.timestamp_ns, source_ms, target_ms, size)
            out, _ = emulate_blur_consistent(raw, source_ms, target_ms, self.response, Hs, ws)
        excess = 0.0 if added else (max(0.0, src - tgt) if math.isfinite(src - tgt) else math.nan)
        row = {"cycle": cycle.index, "camera": camera, "timestamp_ns": frame.timestamp_ns, "bracket_ms": source_ms,
               "target_ms": target_ms, "source_blur_px": src, "target_blur_px": tgt, "excess_blur_px": excess,
               "added": added}
        with self._lock:
            self._rows[(cycle.index, camera, source_ms, target_ms)] = row
        return out

    def rows(self) -> list[dict]:
        with self._lock:
            return list(self._rows.values())

    def write_table(self, run_dir) -> Path:
        """Write the recorded rows to ``<run_dir>/blur.csv`` (:mod:`emulator.io.blurtable`)."""
        return write_blur_table(run_dir, self.rows())

    def emulate(self, camera: str, timestamp_ns: int, raw: np.ndarray, source_ms: float, target_ms: float):
        size = (raw.shape[1], raw.shape[0])
        Hs, ws = self.motion.homographies(camera, timestamp_ns, source_ms, target_ms, size)
        img, _ = emulate_blur_consistent(raw, source_ms, target_ms, self.response, Hs, ws)
        return img, self.excess_px(camera, timestamp_ns, source_ms, target_ms, size)

    def excess_px(self, camera: str, timestamp_ns: int, source_ms: float, target_ms: float, size=None) -> float:
        m = self.motion.mismatch_px(camera, timestamp_ns, source_ms, target_ms, size)
        return max(0.0, m) if math.isfinite(m) else m


def blur_hook(mode: str, sequence, response, *, calibration=None, stamp: str = DEFAULT_STAMP,
              blur_aware: bool = False) -> BlurHook | None:
    """None for ``mode="none"``; for ``"consistent"`` a :class:`BlurHook` (needs an IMU and a calibration).

    ``blur_aware``: the hook also selects brackets (:meth:`BlurHook.select`).  Raises
    :class:`EmulationError` for an unknown mode, ``blur_aware`` without ``"consistent"``, or
    a recording without an IMU.
    """
    if mode not in BLUR_MODES:
        raise EmulationError(f"blur must be one of {', '.join(BLUR_MODES)}, got {mode!r}")
    if mode == "none":
        if blur_aware:
            raise EmulationError("the blur-aware selection needs blur 'consistent' (--blur consistent)")
        return None
    motion = recording_motion(sequence, calibration, stamp=stamp)
    if motion is None:
        raise EmulationError(f"{sequence.path}: --blur consistent needs the recording's gyro (imu/imu.csv), "
                             "and this recording has none")
    return BlurHook(motion, response, bool(blur_aware))
