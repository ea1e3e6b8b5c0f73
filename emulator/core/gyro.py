"""The gyro as angular velocity in camera axes: samples or a function, its offset, its smoothing.

Split out of :mod:`emulator.core.blur` (which re-exports every name here): the IMU side of the
blur prediction.  Numeric core, no file I/O; see :mod:`emulator.core.blur` for the conventions.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from emulator.errors import EmulationError

__all__ = [
    "R_CAM_IMU_FLU",
    "AngularVelocity",
    "as_angular_velocity",
    "GyroBias",
    "still_gyro_bias",
    "GYRO_SMOOTH_S",
    "smooth_angular_velocity",
    "gyro_in_camera",
]

#: IMU (ROS body frame: x forward, y left, z up) to camera optical frame (x right, y down,
#: z forward): the assumed mounting, ``omega_cam = R_CAM_IMU_FLU @ omega_imu``.
R_CAM_IMU_FLU = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


#: A gap between two gyro samples longer than this (s), or than ten median sample periods, is a hole: an
#: interval across it is not covered (interpolating over it would guess the rotation).
GYRO_HOLE_S = 0.1


class AngularVelocity:
    """Angular velocity over time in camera axes: ``omega(t_s) -> (N, 3)`` rad/s.

    Built from samples ``(t_s, omega_rad_s)`` (linear interpolation; NaN outside the span)
    or from a callable.  ``span_s`` is the time range covered ((-inf, inf) for a callable);
    ``holes_s`` the gaps between samples longer than :data:`GYRO_HOLE_S` (or ten median
    periods), which :meth:`covers` treats as not covered.
    """

    def __init__(self, t_s=None, omega_rad_s=None, *, function: Callable | None = None) -> None:
        self.holes_s = np.empty((0, 2))
        if function is not None:
            self._f = function
            self.span_s = (-math.inf, math.inf)
            return
        t = np.asarray(t_s, dtype=np.float64)
        w = np.asarray(omega_rad_s, dtype=np.float64)
        if t.ndim != 1 or w.shape != (t.size, 3) or t.size < 2:
            raise EmulationError(f"angular velocity samples must be t_s (N,) and omega (N, 3) with N >= 2, got "
                                 f"{t.shape} and {w.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(w))) or np.any(np.diff(t) <= 0):
            raise EmulationError("angular velocity samples must be finite with strictly increasing times")
        self._t, self._w = t, w
        self._f = None
        self.span_s = (float(t[0]), float(t[-1]))
        dt = np.diff(t)
        hole = dt > max(GYRO_HOLE_S, 10.0 * float(np.median(dt)))
        self.holes_s = np.stack([t[:-1][hole], t[1:][hole]], axis=1)

    def __call__(self, t_s) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        if self._f is not None:
            out = np.asarray(self._f(t), dtype=np.float64)
            return np.broadcast_to(out, (t.size, 3)).copy() if out.shape != (t.size, 3) else out
        out = np.stack([np.interp(t, self._t, self._w[:, i]) for i in range(3)], axis=1)
        out[(t < self._t[0]) | (t > self._t[-1])] = np.nan
        return out

    def covers(self, t0_s: float, t1_s: float) -> bool:
        """Whether samples cover ``[t0_s, t1_s]`` (either order): inside the span and across no hole."""
        lo, hi = min(t0_s, t1_s), max(t0_s, t1_s)
        if not (self.span_s[0] <= lo and hi <= self.span_s[1]):
            return False
        return not len(self.holes_s) or not bool(np.any((self.holes_s[:, 0] < hi) & (self.holes_s[:, 1] > lo)))


def as_angular_velocity(source) -> AngularVelocity:
    """An :class:`AngularVelocity` from itself, a callable ``omega(t_s)``, or a pair ``(t_s, omega)``."""
    if isinstance(source, AngularVelocity):
        return source
    if callable(source):
        return AngularVelocity(function=source)
    try:
        t, w = source
    except (TypeError, ValueError):
        raise EmulationError("angular velocity must be a callable omega(t_s), a pair (t_s, omega) or an "
                             f"AngularVelocity, got {type(source).__name__}") from None
    return AngularVelocity(t, w)


@dataclass(frozen=True)
class GyroBias:
    """The gyro's offset, estimated where the IMU is still.

    Attributes
    ----------
    bias_rad_s : numpy.ndarray
        (3,) offset in the IMU's axes, rad/s (zeros when no still window was found).
    noise_rad_s : numpy.ndarray
        (3,) standard deviation of one sample about the offset in the still windows, rad/s
        (NaN without any).
    n_samples : int
        Samples in the still windows.
    still_s : list of (float, float)
        The still windows, s since the first sample.
    """

    bias_rad_s: np.ndarray
    noise_rad_s: np.ndarray
    n_samples: int
    still_s: list

    def to_dict(self) -> dict:
        return {"bias_deg_s": np.degrees(self.bias_rad_s).tolist(), "noise_deg_s": np.degrees(self.noise_rad_s).tolist(),
                "n_samples": self.n_samples, "still_s": [list(w) for w in self.still_s]}


def still_gyro_bias(timestamp_ns, gyro_rad_s, acc_m_s2, *, window_s: float = 1.0,
                    acc_std_max_m_s2: float = 0.1) -> GyroBias:
    """The gyro offset from the windows where the IMU is still (zero-velocity update).

    The samples are cut into windows of ``window_s``; a window is still when every axis of
    the accelerometer varies by less than ``acc_std_max_m_s2`` (standard deviation; a walk
    shakes it by 0.5-2 m/s^2, a standing recorder by ~0.05).  The offset is the mean gyro
    over the still windows, the noise its per-axis standard deviation about it.
    """
    t = (np.asarray(timestamp_ns, dtype=np.int64) - int(timestamp_ns[0])) * 1e-9
    g = np.asarray(gyro_rad_s, dtype=np.float64)
    a = np.asarray(acc_m_s2, dtype=np.float64)
    idx = np.floor(t / window_s).astype(np.int64)
    keep = np.zeros(t.size, dtype=bool)
    windows = []
    for w in np.unique(idx):
        m = idx == w
        if m.sum() >= 5 and np.all(a[m].std(axis=0) < acc_std_max_m_s2):
            keep |= m
            windows.append((float(w * window_s), float((w + 1) * window_s)))
    if not keep.any():
        return GyroBias(np.zeros(3), np.full(3, np.nan), 0, [])
    return GyroBias(g[keep].mean(axis=0), g[keep].std(axis=0), int(keep.sum()), windows)


#: Default width of the boxcar the gyro is smoothed with, s (docs/blur.md: the gyro's noise
#: otherwise reads as ~1 px of blur at 32 ms on a recorder at rest; a walk's 1.5 Hz gait
#: loses 1 % of its amplitude).
GYRO_SMOOTH_S = 0.05


def smooth_angular_velocity(t_s, omega, width_s: float) -> np.ndarray:
    """``omega`` (N, 3) averaged over a centred window of ``width_s`` (boxcar; irregular samples welcome).

    The window mean is the difference of the trapezoidal integral at its ends, so the
    rotation over any interval longer than the window is kept; ends use what is inside.
    """
    t = np.asarray(t_s, dtype=np.float64)
    w = np.asarray(omega, dtype=np.float64)
    if width_s <= 0 or t.size < 2:
        return w.copy()
    cum = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t)[:, None], axis=0)])
    lo = np.clip(t - width_s / 2, t[0], t[-1])
    hi = np.clip(t + width_s / 2, t[0], t[-1])
    span = (hi - lo)[:, None]
    out = np.stack([np.interp(hi, t, cum[:, i]) - np.interp(lo, t, cum[:, i]) for i in range(3)], axis=1)
    return np.where(span > 0, out / np.where(span > 0, span, 1.0), w)


def gyro_in_camera(imu, R_cam_imu=R_CAM_IMU_FLU, *, origin_ns: int | None = None,
                   bias_rad_s=None, smooth_s: float = GYRO_SMOOTH_S) -> tuple[AngularVelocity, int]:
    """The IMU's gyro in camera axes, ``omega_cam = R_cam_imu @ (omega_imu - bias)``, over time in s.

    Returns ``(omega, origin_ns)``: times are ``(timestamp_ns - origin_ns) * 1e-9``
    (default origin: the first IMU sample), so a frame's window is
    :func:`exposure_window_s` of ``timestamp_ns - origin_ns``.  ``bias_rad_s``: the gyro
    offset (3,) in IMU axes to subtract (:func:`still_gyro_bias`), default none;
    ``smooth_s``: boxcar width the gyro is averaged over (:func:`smooth_angular_velocity`;
    0: raw samples).
    """
    R = np.asarray(R_cam_imu, dtype=np.float64)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) <= 0:
        raise EmulationError(f"R_cam_imu must be a 3x3 rotation matrix, got {R.tolist()}")
    origin = int(imu.timestamp_ns[0] if origin_ns is None else origin_ns)
    t_s = (imu.timestamp_ns - origin).astype(np.float64) * 1e-9
    bias = np.zeros(3) if bias_rad_s is None else np.asarray(bias_rad_s, dtype=np.float64).reshape(3)
    omega = smooth_angular_velocity(t_s, imu.gyro_rad_s - bias, float(smooth_s))
    return AngularVelocity(t_s, omega @ R.T), origin
