"""Motion blur from the gyro: prediction in pixels, and blur-consistent emulation (numeric core, no file I/O).

A shot of ``t`` ms integrates the scene over its exposure window.  While the camera turns
at angular velocity omega(tau) (rad/s, camera axes: x right, y down, z forward), a static
world point seen at pixel ``x`` at the reference instant is seen at ``H(tau) x`` with the
infinite homography ``H(tau) = K R(tau)^T K^-1``, where ``R(tau)`` is the camera's
orientation at ``tau`` relative to the reference (``dR/dtau = R [omega]_x``).  Translation
is left out: at walking speed and for scenery beyond a few metres it moves a point by far
less than a pixel within 32 ms (2 km/h x 32 ms = 1.8 cm).  Lens distortion is left out
(pinhole K).

Conventions (see ``docs/blur.md``):

* **angular velocity**: anything :func:`as_angular_velocity` accepts, a callable
  ``omega(t_s) -> (N, 3)`` rad/s in camera axes, a pair ``(t_s, omega)`` of samples
  (linearly interpolated), or an :class:`AngularVelocity`.  Real data: the IMU through
  :func:`gyro_in_camera` (rotated by ``R_cam_imu``); synthetic walks: their own function.
* **timestamp convention** ``stamp``: where in its exposure window a frame's timestamp
  lies, ``"start"``, ``"middle"`` or ``"end"`` (default; fitted on BorealHDR, docs/blur.md).
* **blur length**: the path length, in pixels, of a point's image over the window, on a
  3x3 grid of image points (corners, edge centres, centre); :class:`FrameBlur` keeps the
  centre's and the largest.

Blur-consistent emulation (:func:`emulate_blur_consistent`): where the target exposure
``T`` is longer than the source bracket ``S``, the target's window is the source's plus
extra time (placed by ``stamp``).  In linear exposure (``h = g(DN)``) the target is the
source plus the source re-projected to each sub-instant of the extra time,
``h_T = h_S + sum_j (w_j / S) warp_{H_j}(h_S)`` with ``sum_j w_j = T - S``, then
``DN_T = f(h_T)``; only the source's structure is moved, not its noise
(``structure_sigma_px``).  At rest every ``H_j`` is the identity and the result is the plain
emulation, byte for byte.  Where ``T < S`` the source's extra blur cannot be removed;
:func:`blur_mismatch_px` measures it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from emulator.errors import EmulationError
from emulator.core.lut import apply_lut, check_exposure, forward_dn
from emulator.core.structure import STRUCTURE_FILTERS, STRUCTURE_SIGMA_PX, structure_of
from emulator.core.gyro import (  # re-exported: the IMU side lives in emulator.core.gyro
    GYRO_SMOOTH_S,
    R_CAM_IMU_FLU,
    AngularVelocity,
    GyroBias,
    as_angular_velocity,
    gyro_in_camera,
    smooth_angular_velocity,
    still_gyro_bias,
)

__all__ = [
    "STAMP_CONVENTIONS",
    "DEFAULT_STAMP",
    "R_CAM_IMU_FLU",
    "BLUR_MODES",
    "AngularVelocity",
    "as_angular_velocity",
    "gyro_in_camera",
    "GyroBias",
    "GYRO_SMOOTH_S",
    "smooth_angular_velocity",
    "still_gyro_bias",
    "exposure_window_s",
    "integrate_rotation",
    "rotation_homography",
    "scale_intrinsics",
    "grid_points",
    "blur_length_px",
    "FrameBlur",
    "predict_blur",
    "blur_mismatch_px",
    "blur_homographies",
    "PLACEMENTS",
    "DEFAULT_PLACEMENT",
    "emulate_blur_consistent",
    "STRUCTURE_SIGMA_PX",
    "STRUCTURE_FILTERS",
    "structure_of",
    "window_blur",
]

#: Where a frame's timestamp lies in its exposure window.
STAMP_CONVENTIONS = ("start", "middle", "end")
#: The default convention: on the BorealHDR sample the image shifts between consecutive shots
#: match the gyro best with the stamp at the end of the exposure (docs/blur.md).
DEFAULT_STAMP = "end"
#: Blur options of emulation: ``none`` (exact eq. 2) and ``consistent`` (add the blur of the extra time).
BLUR_MODES = ("none", "consistent")
#: Where blur-consistent emulation places the moved copies of the source (:func:`blur_homographies`).
PLACEMENTS = ("tiled", "uniform")
DEFAULT_PLACEMENT = "tiled"
#: Largest step of the rotation integration, s.
_MAX_STEP_S = 0.5e-3
#: Largest displacement between two consecutive sub-instants of blur-consistent emulation, px.
_SUBSTEP_PX = 0.5
#: At most this many sub-instants per extra interval.
_MAX_SUBSTEPS = 64
#: Below this displacement (px) a homography is the identity (the emulation stays exact).
_REST_PX = 1e-6


def exposure_window_s(t_s: float, exposure_ms: float, stamp: str = DEFAULT_STAMP) -> tuple[float, float]:
    """(start, end) of the exposure window, s, of a frame stamped ``t_s`` under ``stamp``.

    >>> exposure_window_s(1.0, 10.0, "middle")
    (0.995, 1.005)
    """
    if stamp not in STAMP_CONVENTIONS:
        raise EmulationError(f"stamp must be one of {', '.join(STAMP_CONVENTIONS)}, got {stamp!r}")
    e = float(exposure_ms) * 1e-3
    start = t_s - {"start": 0.0, "middle": 0.5, "end": 1.0}[stamp] * e
    return start, start + e


def _so3_exp(v: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) for rotation vectors (N, 3) (Rodrigues)."""
    v = np.atleast_2d(v)
    th = np.linalg.norm(v, axis=1)
    K = np.zeros((v.shape[0], 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    small = th < 1e-8
    a = np.where(small, 1.0 - th**2 / 6.0, np.sin(th) / np.where(small, 1.0, th))
    b = np.where(small, 0.5 - th**2 / 24.0, (1.0 - np.cos(th)) / np.where(small, 1.0, th) ** 2)
    return np.eye(3)[None] + a[:, None, None] * K + b[:, None, None] * (K @ K)


def integrate_rotation(omega, t0_s: float, t1_s: float, *, max_step_s: float = _MAX_STEP_S
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Orientation of the camera over ``[t0_s, t1_s]`` relative to ``t0_s``.

    ``t1_s`` may be before ``t0_s`` (integrates backwards).  Midpoint rule on steps of at
    most ``max_step_s``.  Returns ``(times (M,), R (M, 3, 3))`` with ``R[0] = I``; NaN where
    the angular velocity is unknown.
    """
    omega = as_angular_velocity(omega)
    n = max(1, int(math.ceil(abs(t1_s - t0_s) / max_step_s)))
    times = np.linspace(t0_s, t1_s, n + 1)
    mids = 0.5 * (times[:-1] + times[1:])
    steps = _so3_exp(omega(mids) * np.diff(times)[:, None])
    R = np.empty((n + 1, 3, 3))
    R[0] = np.eye(3)
    for k in range(n):
        R[k + 1] = R[k] @ steps[k]
    return times, R


def rotation_homography(K: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``K R^T K^-1``: pixel at the reference -> pixel when the camera has turned by ``R`` ((..., 3, 3))."""
    K = np.asarray(K, dtype=np.float64)
    return K @ np.swapaxes(R, -1, -2) @ np.linalg.inv(K)


def scale_intrinsics(K: np.ndarray, from_size: tuple[int, int], to_size: tuple[int, int]) -> np.ndarray:
    """K of a calibration made at ``from_size`` (width, height) for images of ``to_size`` (pixel-centre convention)."""
    K = np.asarray(K, dtype=np.float64).copy()
    sx, sy = to_size[0] / from_size[0], to_size[1] / from_size[1]
    K[0, 0] *= sx
    K[0, 1] *= sx
    K[1, 1] *= sy
    K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
    K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
    return K


def grid_points(width: int, height: int) -> np.ndarray:
    """(9, 2) pixel coordinates: the corners, edge centres and centre (centre first)."""
    xs, ys = (0.0, (width - 1) / 2.0, width - 1.0), (0.0, (height - 1) / 2.0, height - 1.0)
    pts = [(xs[1], ys[1])] + [(x, y) for y in ys for x in xs if (x, y) != (xs[1], ys[1])]
    return np.array(pts, dtype=np.float64)


def _project(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(M, P, 2): points (P, 2) mapped by homographies (M, 3, 3)."""
    ph = np.concatenate([pts, np.ones((pts.shape[0], 1))], axis=1)
    q = np.einsum("mij,pj->mpi", H, ph)
    return q[..., :2] / q[..., 2:3]


def blur_length_px(K: np.ndarray, rotations: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Path length (px, (P,)) of each image point over the rotations (M, 3, 3) of a window."""
    tracks = _project(rotation_homography(K, rotations), np.asarray(points, dtype=np.float64))
    return np.linalg.norm(np.diff(tracks, axis=0), axis=2).sum(axis=0)


@dataclass(frozen=True)
class FrameBlur:
    """Predicted blur of one frame.

    Attributes
    ----------
    centre_px, max_px : float
        Path length of the image centre, and the largest over the 3x3 grid, px (NaN when
        the gyro does not cover the window).
    rotation_deg : float
        Angle turned over the window, degrees.
    mean_rate_deg_s : float
        ``rotation_deg`` over the exposure time, deg/s.
    """

    centre_px: float
    max_px: float
    rotation_deg: float
    mean_rate_deg_s: float

    def to_dict(self) -> dict:
        return {"centre_px": self.centre_px, "max_px": self.max_px, "rotation_deg": self.rotation_deg,
                "mean_rate_deg_s": self.mean_rate_deg_s}


_NAN_BLUR = FrameBlur(math.nan, math.nan, math.nan, math.nan)


def window_blur(omega: AngularVelocity, K, size, t0_s, t1_s) -> FrameBlur:
    """The blur of an exposure window [t0_s, t1_s] from the gyro (NaN where the gyro does not cover it)."""
    if not omega.covers(t0_s, t1_s):
        return _NAN_BLUR
    _, R = integrate_rotation(omega, t0_s, t1_s)
    if not np.all(np.isfinite(R)):
        return _NAN_BLUR
    lengths = blur_length_px(K, R, grid_points(*size))
    angle = math.degrees(float(np.linalg.norm(cv2.Rodrigues(R[-1])[0])))
    dt = abs(t1_s - t0_s)
    return FrameBlur(float(lengths[0]), float(lengths.max()), angle, angle / dt if dt > 0 else 0.0)


def predict_blur(omega, K: np.ndarray, size: tuple[int, int], t_s: float, exposure_ms: float,
                 stamp: str = DEFAULT_STAMP) -> FrameBlur:
    """Blur of a frame stamped ``t_s`` (s, on ``omega``'s clock) exposed ``exposure_ms``.

    ``K``: (3, 3) intrinsics for images of ``size`` = (width, height) pixels.
    """
    t0, t1 = exposure_window_s(t_s, exposure_ms, stamp)
    return window_blur(as_angular_velocity(omega), K, size, t0, t1)


def blur_mismatch_px(omega, K, size, t_s: float, source_ms: float, target_ms: float,
                     stamp: str = DEFAULT_STAMP) -> float:
    """Source blur minus the blur of a capture at ``target_ms`` at the same stamp, px (largest over the grid).

    Positive: excess blur an emulated image keeps (target shorter than the source);
    negative: blur plain emulation leaves out (target longer).
    """
    omega = as_angular_velocity(omega)
    src = window_blur(omega, K, size, *exposure_window_s(t_s, source_ms, stamp))
    tgt = window_blur(omega, K, size, *exposure_window_s(t_s, target_ms, stamp))
    return src.max_px - tgt.max_px


def blur_homographies(omega, K, size, t_s: float, source_ms: float, target_ms: float,
                      stamp: str = DEFAULT_STAMP, placement: str = DEFAULT_PLACEMENT
                      ) -> tuple[list[np.ndarray], list[float]]:
    """Homographies and weights (ms) of the extra exposure time of a target longer than its source.

    The source image stands for the scene over its own window, centred on the window's middle.
    The extra time (the target window minus the source window, both placed at ``t_s`` by
    ``stamp``) is made of copies of the source, each moved to a part of the extra time:

    * ``placement="tiled"`` (default): copies a whole source window apart, tiling the extra
      time; a last part shorter than the source gets one copy of that duration at its middle.
      The source already carries the blur of its own window, so ``k`` copies tile ``k`` windows:
      exact for a constant angular velocity where each side's extra time is a whole number of
      source windows (with ``stamp="middle"`` at twice the source, half a window a side, never).
      Where the copies would be closer than 0.5 px (a source blurred by less than that: at rest,
      or a short source), the part takes the ``"uniform"`` sub-instants instead, which are then
      fewer and err by under 0.25 px.
    * ``placement="uniform"``: sub-instants no more than 0.5 px apart, as if the source were
      sharp; every copy adds the source's own blur again, so the blur is too long by up to
      one source window (the over-correction measured in docs/motion.md).

    Returns ``([H_j], [w_j])`` with ``sum(w_j) = target_ms - source_ms``; empty lists when the
    target is not longer.  Raises :class:`EmulationError` when the angular velocity does not
    cover the window, an exposure is not a finite positive number or ``placement`` is unknown.
    """
    if placement not in PLACEMENTS:
        raise EmulationError(f"placement must be one of {', '.join(PLACEMENTS)}, got {placement!r}")
    source_ms = check_exposure(source_ms, "source_ms")
    target_ms = check_exposure(target_ms, "target_ms")
    omega = as_angular_velocity(omega)
    if target_ms <= source_ms:
        return [], []
    s0, s1 = exposure_window_s(t_s, source_ms, stamp)
    e0, e1 = exposure_window_s(t_s, target_ms, stamp)
    if not omega.covers(e0, e1):
        raise EmulationError(f"the angular velocity (span {omega.span_s[0]:.6g}..{omega.span_s[1]:.6g} s) does not "
                             f"cover the exposure window {e0:.6g}..{e1:.6g} s")
    ref = 0.5 * (s0 + s1)
    span = s1 - s0
    pts = grid_points(*size)
    taus: list[float] = []
    ws: list[float] = []
    for a, b, sign in ((s0, e0, -1.0), (s1, e1, 1.0)):  # from the source's edge outwards
        length = sign * (b - a)
        if length <= 0:
            continue
        _, R = integrate_rotation(omega, min(a, b), max(a, b))
        n_steps = max(1, math.ceil(blur_length_px(K, R, pts).max() / _SUBSTEP_PX))  # sub-instants 0.5 px apart
        full = int(math.floor(length / span + 1e-9))
        rest = length - full * span
        if placement == "tiled" and full + (rest > 1e-9 * span) <= n_steps:
            # copies a source window apart are at least _SUBSTEP_PX apart: tile; closer (a source blur
            # under half a pixel), sub-instants _SUBSTEP_PX apart are as good and fewer
            for k in range(1, full + 1):
                taus.append(ref + sign * k * span)
                ws.append(span * 1e3)
            if rest > 1e-9 * span:
                taus.append(a + sign * (full * span + 0.5 * rest))
                ws.append(rest * 1e3)
        else:
            n = min(n_steps, _MAX_SUBSTEPS)
            for j in range(n):
                taus.append(min(a, b) + (j + 0.5) * length / n)
                ws.append(length * 1e3 / n)
    Hs = []
    for tau in taus:
        _, Rt = integrate_rotation(omega, ref, tau)
        Hs.append(rotation_homography(K, Rt[-1]))
    return Hs, ws


def _bayer_plane_homography(H: np.ndarray, px: int, py: int) -> np.ndarray:
    A = np.array([[2.0, 0.0, px], [0.0, 2.0, py], [0.0, 0.0, 1.0]])
    return np.linalg.inv(A) @ H @ A


def _is_identity(H: np.ndarray, size) -> bool:
    pts = grid_points(*size)
    return bool(np.abs(_project(H[None], pts)[0] - pts).max() < _REST_PX)


#: Resamplers of :func:`emulate_blur_consistent`'s warps: name -> OpenCV flag.
_RESAMPLE = {"linear": "INTER_LINEAR", "cubic": "INTER_CUBIC"}

#: The DN lookup after a warp, under the name emulator.core.native imported before it moved to emulator.core.lut.


def emulate_blur_consistent(raw: np.ndarray, source_ms: float, target_ms: float, response,
                            homographies, weights_ms, *, bayer: bool = True,
                            structure_sigma_px: float = STRUCTURE_SIGMA_PX,
                            resample: str = "linear", structure: str = "wiener",
                            noise_var=None) -> tuple[np.ndarray, np.ndarray]:
    """Emulate ``raw`` (a ``source_ms`` shot) at ``target_ms`` with the blur of the extra time.

    Parameters
    ----------
    raw : numpy.ndarray
        (H, W) ``uint16`` DN, RGGB Bayer mosaic (``bayer=True``: each of the four colour
        sites is warped on its own grid) or one plane.
    source_ms, target_ms : float
        Exposure times, ms.
    response : CameraResponse
        g and f, and the clip levels.
    homographies, weights_ms : lists
        From :func:`blur_homographies` (full-resolution pixels); weights sum to
        ``target_ms - source_ms``.
    structure_sigma_px, structure, noise_var
        The blur moves the source's structure, not its noise: ``h_T = (T/S) h_S +
        sum_j (w_j/S) (warp_j(s) - s)`` with ``s`` the structure of the source
        (:func:`structure_of`: by default an adaptive Wiener filter over a Gaussian window of
        ``structure_sigma_px`` px of one Bayer plane, with the noise variance ``noise_var``
        measured on the image when None; ``structure="gaussian"`` smooths everything, the
        form before tiled copies).  ``structure_sigma_px=0``, or ``noise_var=0`` with the Wiener
        filter (the Gaussian form ignores ``noise_var``): ``s = h_S``,
        exact for a noiseless source; on a noisy one the warps then also average its noise,
        which a live capture's noise never is (on the BorealHDR sample at rest that made
        32 ms frames emulated from 8 ms up to 1.6x their noise away from plain emulation).
    resample : {"linear", "cubic"}
        Interpolation of the warps (each Bayer plane on its own grid); bilinear at fractional
        offsets also low-passes the plane, which the blur it models does not do.

    Returns
    -------
    (image, valid) : (numpy.ndarray, numpy.ndarray)
        ``uint16`` DN and the validity mask: the plain emulation's, less pixels that a
        clipped source pixel blurs into.  Without homographies, or when they are all the
        identity, exactly :func:`emulator.core.emulate.emulate`'s output.
    """
    source_ms = check_exposure(source_ms, "source_ms")
    target_ms = check_exposure(target_ms, "target_ms")
    if resample not in _RESAMPLE:
        raise EmulationError(f"resample must be one of {', '.join(_RESAMPLE)}, got {resample!r}")
    if structure not in STRUCTURE_FILTERS:
        raise EmulationError(f"structure must be one of {', '.join(STRUCTURE_FILTERS)}, got {structure!r}")
    ratio = target_ms / source_ms
    table, valid_table = response.lut(ratio)
    plain = apply_lut(table, raw)
    valid = valid_table[raw]
    size = (raw.shape[1], raw.shape[0])
    moving = [(H, w) for H, w in zip(homographies, weights_ms) if not _is_identity(np.asarray(H), size)]
    if not moving:
        return plain, valid
    if abs(sum(weights_ms) - (target_ms - source_ms)) > 1e-6 * target_ms:
        raise EmulationError(f"blur weights sum to {sum(weights_ms):.6g} ms, expected target - source = "
                             f"{target_ms - source_ms:.6g} ms")
    flag = getattr(cv2, _RESAMPLE[resample])
    h = response.inverse(raw).astype(np.float32)
    clipped = ((raw >= response.white_level) | (raw <= response.black_level)).astype(np.float32)
    acc = h * np.float32(target_ms / source_ms)
    touched = clipped.copy()
    phases = [(0, 0), (1, 0), (0, 1), (1, 1)] if bayer else [(None, None)]
    sites = []  # (slice, offset, the structure the blur moves, the clipped mask), once per colour site
    for px, py in phases:
        sl = (slice(None), slice(None)) if px is None else (slice(py, None, 2), slice(px, None, 2))
        plane = np.ascontiguousarray(h[sl])
        if structure_sigma_px > 0:
            plane = structure_of(plane, structure_sigma_px, structure, noise_var, exclude=clipped[sl] > 0)
        sites.append((sl, px, py, plane, np.ascontiguousarray(clipped[sl])))
    for H, w in moving:
        H = np.asarray(H, dtype=np.float64)
        for sl, px, py, plane, clip_site in sites:
            Hp = H if px is None else _bayer_plane_homography(H, px, py)
            dsize = (plane.shape[1], plane.shape[0])
            acc[sl] += np.float32(w / source_ms) * (cv2.warpPerspective(
                plane, Hp, dsize, flags=flag, borderMode=cv2.BORDER_REPLICATE) - plane)
            touched[sl] = np.maximum(touched[sl], cv2.warpPerspective(
                clip_site, Hp, dsize, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE))
    out = forward_dn(response, acc)
    all_high = raw >= response.white_level
    valid = valid & ((touched == 0) | (all_high & (out >= response.white_level)))
    return out, valid
