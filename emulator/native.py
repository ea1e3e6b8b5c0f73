"""Native-rate emulation's numeric core: the native selector and the rotation warp (no file I/O).

At native rate (the recorder's own frame rate) an AE method reads every recorded frame, and
frame k's image at the applied exposure ``t`` is emulated from the bracket of frame k itself
or of a nearby frame (:class:`emulator.playback.native.NativeProvider`).  This module holds
the two numeric parts of that:

* **the native selector** (:func:`native_select`): among the candidate frames within
  :data:`WINDOW_CYCLES` recorder cycle of frame k, those that lose at most :data:`SATURATION_LIMIT`
  more of the image to clipping than the least clipped candidate are kept (pixels at black
  emulated upwards, at white downwards); of those, the one of least cost

      cost = max(0, log2(t / bracket)) + MOTION_STOPS_PER_FRAME * |offset|

  is chosen: the first term is the noise an upward emulation adds (in stops: emulating up
  by 2x makes the image's relative noise sqrt(2) times a capture's), the second the motion
  between frame k and the source (``offset`` in frames; the warp undoes the rotation, not
  the translation nor the gyro's errors).  Ties go to the smaller ``|offset|``, then to the
  earlier frame.  Frame k's own bracket is therefore used whenever it can give ``t`` from
  above (cost 0) without clipping more than the others, and an upward emulation of it is kept
  while it costs less than the nearest kept neighbour.
* **the warp** (:func:`warp_to_instant`): a source frame taken at another instant is moved
  to frame k's instant by the infinite homography of the camera's rotation between the two
  (``H = K R^T K^-1``, :func:`emulator.blur.rotation_homography`), each RGGB site on its own
  grid, in linear exposure, resampled by :data:`WARP_RESAMPLE` (Lanczos: a bilinear warp at a
  fractional offset averages neighbouring sites and removes the fine detail SIFT detects).
  Pixels that come from outside the source image are reported through the inside fraction.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import cv2
import numpy as np

from emulator.blur import _forward_dn
from emulator.errors import EmulationError

__all__ = [
    "WINDOW_CYCLES",
    "MOTION_STOPS_PER_FRAME",
    "SATURATION_LIMIT",
    "NativeCandidate",
    "native_cost",
    "native_select",
    "invalid_fraction",
    "rotation_between",
    "warp_to_instant",
    "WARP_RESAMPLE",
    "RESAMPLERS",
]

#: Candidate source frames lie within this many recorder cycles (sweeps) of frame k, each side.
WINDOW_CYCLES = 1
#: Cost of one frame of time offset, in stops of upward emulation (docs/native.md).
MOTION_STOPS_PER_FRAME = 1.0
#: A candidate is kept when at most this fraction more of its pixels than the least clipped candidate's
#: cannot give the target (docs/native.md: measured on a synthetic walk, motion costs more than clipping).
SATURATION_LIMIT = 0.2
#: The warp's resamplers (OpenCV's interpolation flags) and the one native runs use.  Measured on a
#: real 8 ms frame of the shared sample (480x300 window, SIFT as ``bench features``): shifted by half a
#: pixel in x and y it keeps 174 of 612 keypoints bilinearly, 491 bicubically and 573 with Lanczos
#: (``docs/native.md``); native emulation lost about 50 matches per walk against native live with the
#: bilinear warp, all of them on the walks whose benchmarked frames a neighbour served.
RESAMPLERS = {"linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC, "lanczos4": cv2.INTER_LANCZOS4}
WARP_RESAMPLE = "lanczos4"


@dataclass(frozen=True)
class NativeCandidate:
    """A frame that could serve frame k: its offset (frames, source - k), bracket and clipped share.

    ``invalid_fraction``: the share of the source's pixels that cannot give the target
    (:func:`invalid_fraction`).
    """

    offset: int
    bracket_ms: float
    invalid_fraction: float


def invalid_fraction(hist: np.ndarray, ratio: float, *, white_level: int, black_level: int) -> float:
    """Share of a source's pixels (its DN histogram) whose emulation at ``ratio`` carries no radiance.

    Emulating upwards (``ratio > 1``) a black pixel is lost (a white one stays white);
    downwards a white pixel is lost (:func:`emulator.emulate.validity_mask`).
    """
    n = float(hist.sum())
    if ratio == 1.0 or n == 0:
        return 0.0
    lost = hist[: black_level + 1].sum() if ratio > 1.0 else hist[white_level:].sum()
    return float(lost) / n


def native_cost(target_ms: float, candidate: NativeCandidate, motion_stops_per_frame: float = MOTION_STOPS_PER_FRAME
                ) -> float:
    """The selector's cost of ``candidate`` for ``target_ms`` (see the module notes)."""
    up = max(0.0, math.log2(float(target_ms) / float(candidate.bracket_ms)))
    return up + float(motion_stops_per_frame) * abs(int(candidate.offset))


def native_select(target_ms: float, candidates: Iterable[NativeCandidate], *,
                  motion_stops_per_frame: float = MOTION_STOPS_PER_FRAME,
                  saturation_limit: float = SATURATION_LIMIT) -> NativeCandidate:
    """The candidate frame that serves ``target_ms`` (see the module notes).

    Raises :class:`EmulationError` when there is no candidate, or ``target_ms`` or the motion
    weight is not a finite number of the right sign.
    """
    cands = list(candidates)
    if not cands:
        raise EmulationError("native selector: no candidate frame to emulate from")
    if not (math.isfinite(float(target_ms)) and float(target_ms) > 0):
        raise EmulationError(f"native selector: target_ms must be a finite positive number, got {target_ms!r}")
    if not (math.isfinite(float(motion_stops_per_frame)) and float(motion_stops_per_frame) >= 0):
        raise EmulationError(f"native selector: the motion weight must be finite and >= 0, got "
                             f"{motion_stops_per_frame!r}")

    def order(c: NativeCandidate) -> tuple:
        return (round(native_cost(target_ms, c, motion_stops_per_frame), 12), abs(c.offset), c.offset)

    least = min(c.invalid_fraction for c in cands)
    return min((c for c in cands if c.invalid_fraction <= least + saturation_limit), key=order)


# ============================================================================ the warp
def rotation_between(omega, t_from_s: float, t_to_s: float) -> np.ndarray | None:
    """The camera's rotation from ``t_from_s`` to ``t_to_s`` (3x3), or None where the gyro does not cover it."""
    from emulator.blur import as_angular_velocity, integrate_rotation

    omega = as_angular_velocity(omega)
    if not omega.covers(t_from_s, t_to_s):
        return None
    _, R = integrate_rotation(omega, t_from_s, t_to_s)
    return R[-1] if np.all(np.isfinite(R[-1])) else None


def _plane_homography(H: np.ndarray, px: int, py: int) -> np.ndarray:
    A = np.array([[2.0, 0.0, px], [0.0, 2.0, py], [0.0, 0.0, 1.0]])
    return np.linalg.inv(A) @ H @ A


def _inside_fraction(H: np.ndarray, width: int, height: int) -> float:
    """Share of the destination image whose source pixel (``H^-1 x``) lies inside the source: the area of
    the source's outline moved by ``H`` (a convex quadrilateral for any rotation that keeps the view)
    within the image, over the image's area."""
    corners = np.array([[-0.5, -0.5], [width - 0.5, -0.5], [width - 0.5, height - 0.5], [-0.5, height - 0.5]])
    moved = cv2.perspectiveTransform(corners[None], H)[0]
    area, _ = cv2.intersectConvexConvex(moved.astype(np.float32), corners.astype(np.float32))
    return float(min(1.0, max(0.0, area / (width * height))))


#: Grid of the DN lookup after a warp (:func:`emulator.blur._forward_dn`): 2**20 cells leave few pixels to
#: search on a real response (7x faster than 2**16 on the sample; the same bytes).
_DN_GRID = 1 << 20


def warp_to_instant(image: np.ndarray, H: np.ndarray, response, *, bayer: bool = True,
                    resample: str = WARP_RESAMPLE) -> tuple[np.ndarray, float]:
    """``image`` (DN) moved by the homography ``H`` (source pixel -> destination pixel).

    The warp is done in linear exposure (``g(DN)``, resampled by ``resample``, a key of
    :data:`RESAMPLERS`, each RGGB site on its own grid when ``bayer``) and brought back through
    the response (``rint(f(.))``, clipped to the camera's range, which also clips the Lanczos
    kernel's overshoot), so that an identity ``H`` returns the image byte for byte.  Pixels from
    outside the source repeat its border.  Returns ``(image, inside_fraction)``.
    """
    H = np.asarray(H, dtype=np.float64)
    if H.shape != (3, 3) or not np.all(np.isfinite(H)):
        raise EmulationError(f"warp: the homography must be a finite 3x3 matrix, got {H.tolist()}")
    if resample not in RESAMPLERS:
        raise EmulationError(f"warp: unknown resampler {resample!r} (one of {', '.join(RESAMPLERS)})")
    height, width = image.shape
    h = response.inverse(image).astype(np.float32)
    out = np.empty_like(h)
    phases = [(0, 0), (1, 0), (0, 1), (1, 1)] if bayer else [(None, None)]
    for px, py in phases:
        sl = (slice(None), slice(None)) if px is None else (slice(py, None, 2), slice(px, None, 2))
        plane = np.ascontiguousarray(h[sl])
        Hp = H if px is None else _plane_homography(H, px, py)
        out[sl] = cv2.warpPerspective(plane, Hp, (plane.shape[1], plane.shape[0]), flags=RESAMPLERS[resample],
                                      borderMode=cv2.BORDER_REPLICATE)
    return _forward_dn(response, out, _DN_GRID), _inside_fraction(H, width, height)
