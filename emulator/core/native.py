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
  (``H = K R^T K^-1``, :func:`emulator.core.blur.rotation_homography`), each RGGB site on its own
  grid, in linear exposure, resampled by :data:`WARP_RESAMPLE` (Lanczos: a bilinear warp at a
  fractional offset averages neighbouring sites and removes the fine detail SIFT detects).
  Pixels that come from outside the source image are reported through the inside fraction.
* **the blur-aware selector** (opt-in, ``native_select(..., blur_stops_per_px=w)``): a candidate's
  cost also counts the motion blur its exposure window carries beyond a capture at the target
  (:attr:`NativeCandidate.excess_blur_px`, predicted from the gyro), ``w`` stops per pixel; a
  candidate more than :data:`BLUR_LIMIT_PX` beyond is dropped while one within it is kept; ties go
  to the less blurred candidate, then the nearer frame.
* **the flow warp** (:func:`flow_velocity`, :func:`warp_with_flow`): the rotation warp followed by
  the image motion the rotation leaves (translation parallax, the gyro's errors), measured by a
  dense optical flow (OpenCV's DIS) between the neighbours on either side of frame k, each turned to
  frame k's instant and normalised to radiance, and scaled linearly in time to the source's instant.
  ``flow-sharp`` (:data:`DEFAULT_NATIVE_WARP`) is the flow warp where that move is at least
  :data:`SHARP_MOTION_PX` (:func:`median_motion_px`), and no resampling below it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import cv2
import numpy as np

from emulator.core.lut import forward_dn
from emulator.errors import EmulationError
from emulator.core.blur import as_angular_velocity, integrate_rotation

__all__ = [
    "NATIVE_RATE",
    "RATES",
    "run_rate",
    "is_native_run",
    "native_record",
    "tick_unit",
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
    "BLUR_LIMIT_PX",
    "BLUR_STOPS_PER_PX",
    "WARP_MODES",
    "radiance_gray",
    "flow_velocity",
    "instant_maps",
    "warp_with_flow",
    "move_mask",
    "SHARP_MOTION_PX",
    "DEFAULT_NATIVE_WARP",
    "median_motion_px",
    "plane_homography",
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
#: The blur-aware selector drops a candidate whose window blurs more than this beyond the target's (px) while
#: one within it is kept, and weighs each pixel of excess blur as this many stops of upward emulation.
BLUR_LIMIT_PX = 1.0
BLUR_STOPS_PER_PX = 1.0
#: ``run.json``'s ``rate`` of a run after every recorded frame, and the key of its record of the native provider.
NATIVE_RATE = "native"
#: How often a method proposes: once per bracket sweep (the paper's, the default) or after every recorded frame.
RATES = ("cycle", NATIVE_RATE)


def run_rate(info) -> str:
    """The rate a ``run.json`` (or a run's summary) records: a folder from before ``--rate`` is at cycle rate."""
    return (info or {}).get("rate") or RATES[0]


def is_native_run(info) -> bool:
    """Whether a ``run.json`` (or a run's summary, or a comparison's input) is of a native-rate run."""
    return run_rate(info) == NATIVE_RATE


def native_record(info) -> dict:
    """What a native-rate ``run.json`` records of its provider (window, warp, frames; empty at cycle rate)."""
    record = (info or {}).get(NATIVE_RATE)
    return record if isinstance(record, dict) else {}


def tick_unit(info) -> str:
    """What one row of a run's tables is: ``frames`` at native rate, else ``cycles``."""
    return "frames" if is_native_run(info) else "cycles"


#: How a neighbour frame is moved to frame k's instant: not at all, by the gyro's rotation, by the rotation and
#: then the optical flow between the neighbours on either side of frame k, or as ``flow`` but only where that
#: move is at least :data:`SHARP_MOTION_PX` (``flow-sharp``, the default of native runs: docs/native.md).
WARP_MODES = ("none", "rotation", "flow", "flow-sharp")
#: What ``exposim run --rate native`` uses without ``--warp`` (a NativeProvider's own default is ``rotation``).
DEFAULT_NATIVE_WARP = "flow-sharp"
#: ``flow-sharp`` leaves a neighbour as recorded where the median move of its pixels (:func:`median_motion_px`)
#: is below this (full-resolution px): a resampling at a sub-pixel offset smooths more than it aligns (on the
#: upstream BorealHDR sample at rest, a Lanczos warp of 0.3-1 px cost SIFT good matches; see docs/native.md).
SHARP_MOTION_PX = 1.0


@dataclass(frozen=True)
class NativeCandidate:
    """A frame that could serve frame k: its offset (frames, source - k), bracket and clipped share.

    ``invalid_fraction``: the share of the source's pixels that cannot give the target
    (:func:`invalid_fraction`).
    """

    offset: int
    bracket_ms: float
    invalid_fraction: float
    #: Blur of the candidate's window beyond a capture at the target, px (blur-aware selector only).
    excess_blur_px: float = 0.0


def invalid_fraction(hist: np.ndarray, ratio: float, *, white_level: int, black_level: int) -> float:
    """Share of a source's pixels (its DN histogram) whose emulation at ``ratio`` carries no radiance.

    Emulating upwards (``ratio > 1``) a black pixel is lost (a white one stays white);
    downwards a white pixel is lost (:func:`emulator.core.emulate.validity_mask`).
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
                  saturation_limit: float = SATURATION_LIMIT, blur_stops_per_px: float | None = None
                  ) -> NativeCandidate:
    """The candidate frame that serves ``target_ms`` (see the module notes).

    ``blur_stops_per_px``: None (default) leaves blur out; a number makes the selector blur-aware
    (each candidate's ``excess_blur_px`` costs that many stops per pixel, those more than
    :data:`BLUR_LIMIT_PX` beyond the target are dropped while one within it is kept, ties go to
    the less blurred).  Raises :class:`EmulationError` when there is no candidate, or
    ``target_ms`` or a weight is not a finite number of the right sign.
    """
    cands = list(candidates)
    if not cands:
        raise EmulationError("native selector: no candidate frame to emulate from")
    if not (math.isfinite(float(target_ms)) and float(target_ms) > 0):
        raise EmulationError(f"native selector: target_ms must be a finite positive number, got {target_ms!r}")
    if not (math.isfinite(float(motion_stops_per_frame)) and float(motion_stops_per_frame) >= 0):
        raise EmulationError(f"native selector: the motion weight must be finite and >= 0, got "
                             f"{motion_stops_per_frame!r}")
    least = min(c.invalid_fraction for c in cands)
    kept = [c for c in cands if c.invalid_fraction <= least + saturation_limit]
    if blur_stops_per_px is None:
        def order(c: NativeCandidate) -> tuple:
            return (round(native_cost(target_ms, c, motion_stops_per_frame), 12), abs(c.offset), c.offset)

        return min(kept, key=order)
    w = float(blur_stops_per_px)
    if not (math.isfinite(w) and w >= 0):
        raise EmulationError(f"native selector: the blur weight must be finite and >= 0, got {blur_stops_per_px!r}")

    def excess(c: NativeCandidate) -> float:
        return max(0.0, float(c.excess_blur_px)) if math.isfinite(float(c.excess_blur_px)) else 0.0

    sharp = [c for c in kept if excess(c) <= BLUR_LIMIT_PX]
    return min(sharp or kept, key=lambda c: (round(native_cost(target_ms, c, motion_stops_per_frame) + w * excess(c),
                                                   12), round(excess(c), 12), abs(c.offset), c.offset))


# ============================================================================ the warp
def rotation_between(omega, t_from_s: float, t_to_s: float) -> np.ndarray | None:
    """The camera's rotation from ``t_from_s`` to ``t_to_s`` (3x3), or None where the gyro does not cover it."""
    omega = as_angular_velocity(omega)
    if not omega.covers(t_from_s, t_to_s):
        return None
    _, R = integrate_rotation(omega, t_from_s, t_to_s)
    return R[-1] if np.all(np.isfinite(R[-1])) else None


def plane_homography(H: np.ndarray, px: int, py: int) -> np.ndarray:
    """Homography ``H`` of full-resolution pixels as one on the half-resolution Bayer plane at offset (px, py)."""
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


#: Grid of the DN lookup after a warp (:func:`emulator.core.lut.forward_dn`): 2**20 cells leave few pixels to
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
        Hp = H if px is None else plane_homography(H, px, py)
        out[sl] = cv2.warpPerspective(plane, Hp, (plane.shape[1], plane.shape[0]), flags=RESAMPLERS[resample],
                                      borderMode=cv2.BORDER_REPLICATE)
    return forward_dn(response, out, _DN_GRID), _inside_fraction(H, width, height)


# ============================================================================ the flow warp
#: The flow's input: log2 radiance mapped to 8 bits between these percentiles of the two images.
_FLOW_PERCENTILES = (1.0, 99.0)
#: A neighbour's grey is smoothed by this Gaussian (sigma, binned pixels) before the flow: short brackets are noisy.
_FLOW_SIGMA = 1.0


def radiance_gray(image: np.ndarray, exposure_ms: float, response) -> np.ndarray:
    """log2 radiance (linear exposure over ``exposure_ms``) of a Bayer image, 2x2 binned: (H/2, W/2) float32.

    Binned pixel (u, v) covers the RGGB sites (2u..2u+1, 2v..2v+1), the grid of each Bayer plane.
    """
    h = response.inverse(image)
    hh, ww = (image.shape[0] // 2) * 2, (image.shape[1] // 2) * 2
    h = h[:hh, :ww]
    binned = 0.25 * (h[0::2, 0::2] + h[1::2, 0::2] + h[0::2, 1::2] + h[1::2, 1::2]) / float(exposure_ms)
    return np.log2(np.maximum(binned, 1e-9)).astype(np.float32)


def _binned_homography(H: np.ndarray) -> np.ndarray:
    """``H`` (full-resolution pixels) on the 2x2 binned grid (binned pixel u is centred on full pixel 2u + 0.5)."""
    A = np.array([[2.0, 0.0, 0.5], [0.0, 2.0, 0.5], [0.0, 0.0, 1.0]])
    return np.linalg.inv(A) @ H @ A


def flow_velocity(gray_a: np.ndarray, H_a: np.ndarray, gray_b: np.ndarray, H_b: np.ndarray, dt_s: float
                  ) -> np.ndarray:
    """Image velocity at frame k's instant, full-resolution px/s on the binned grid: (H/2, W/2, 2) float32.

    ``gray_a``, ``gray_b``: :func:`radiance_gray` of the neighbours before and after frame k (never frame
    k's own image); ``H_a``, ``H_b``: the rotation homographies that turn each to frame k's instant
    (full-resolution pixels); ``dt_s``: the time from a to b.  The residual motion between the two turned
    images (OpenCV's DIS optical flow, medium preset) is taken as constant over ``dt_s``.
    """
    size = (gray_a.shape[1], gray_a.shape[0])
    turned = [cv2.warpPerspective(g, _binned_homography(H), size, flags=cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_REPLICATE) for g, H in ((gray_a, H_a), (gray_b, H_b))]
    both = np.concatenate([t.ravel() for t in turned])
    lo, hi = np.percentile(both, _FLOW_PERCENTILES)
    scale = 255.0 / max(float(hi - lo), 1e-6)
    u8 = [cv2.GaussianBlur(np.clip((t - lo) * scale, 0, 255), (0, 0), _FLOW_SIGMA).round().astype(np.uint8)
          for t in turned]
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    flow = dis.calc(u8[0], u8[1], None)
    return (flow * (2.0 / float(dt_s))).astype(np.float32)


def instant_maps(H: np.ndarray, displacement: np.ndarray | None, shape: tuple[int, int], *, bayer: bool = True
                 ) -> list[tuple[tuple, np.ndarray, np.ndarray, np.ndarray]]:
    """Where each destination pixel comes from: the homography ``H`` (source -> destination), after the
    destination is moved back by ``displacement`` ((H/2, W/2, 2) full-resolution px on the binned grid; None:
    none).  Returns per Bayer site (or once for the whole image when not ``bayer``) ``(slices, map_x, map_y,
    inside)``: ``cv2.remap`` maps on that site's grid and where the source pixel lies inside the source."""
    height, width = shape
    Hinv = np.linalg.inv(np.asarray(H, dtype=np.float64))
    out = []
    for px, py in ([(0, 0), (1, 0), (0, 1), (1, 1)] if bayer else [(None, None)]):
        step, ox, oy = (1, 0, 0) if px is None else (2, px, py)
        ys, xs = np.mgrid[oy:height:step, ox:width:step].astype(np.float64)
        if displacement is not None:
            d = displacement if px is not None else cv2.resize(displacement, (width, height),
                                                               interpolation=cv2.INTER_LINEAR)
            xs = xs - d[: xs.shape[0], : xs.shape[1], 0]
            ys = ys - d[: ys.shape[0], : ys.shape[1], 1]
        den = Hinv[2, 0] * xs + Hinv[2, 1] * ys + Hinv[2, 2]
        zx = (Hinv[0, 0] * xs + Hinv[0, 1] * ys + Hinv[0, 2]) / den
        zy = (Hinv[1, 0] * xs + Hinv[1, 1] * ys + Hinv[1, 2]) / den
        inside = (zx >= -0.5) & (zx <= width - 0.5) & (zy >= -0.5) & (zy <= height - 0.5)
        sl = (slice(None), slice(None)) if px is None else (slice(py, None, 2), slice(px, None, 2))
        out.append((sl, ((zx - ox) / step).astype(np.float32), ((zy - oy) / step).astype(np.float32), inside))
    return out


def warp_with_flow(image: np.ndarray, H: np.ndarray, displacement: np.ndarray | None, response, *,
                   resample: str = WARP_RESAMPLE) -> tuple[np.ndarray, float]:
    """``image`` (DN) moved by ``H`` and then by ``displacement`` (:func:`instant_maps`), each Bayer site on its
    own grid, in linear exposure, as :func:`warp_to_instant`.  Returns ``(image, inside_fraction)``."""
    h = response.inverse(image).astype(np.float32)
    out = np.empty_like(h)
    n_in = 0
    for sl, mx, my, inside in instant_maps(H, displacement, image.shape):
        out[sl] = cv2.remap(np.ascontiguousarray(h[sl]), mx, my, RESAMPLERS[resample], borderMode=cv2.BORDER_REPLICATE)
        n_in += int(inside.sum())
    return forward_dn(response, out, _DN_GRID), n_in / float(image.size)


def median_motion_px(H: np.ndarray, displacement: np.ndarray | None, shape: tuple[int, int]) -> float:
    """The median length (full-resolution px) of the move :func:`warp_with_flow` gives a source image of ``shape``:
    ``H(x) - x`` plus ``displacement`` (None: none), over the 2x2 binned grid (the displacement's)."""
    height, width = shape
    ys, xs = np.mgrid[0:height - 1:2, 0:width - 1:2].astype(np.float64) + 0.5
    H = np.asarray(H, dtype=np.float64)
    den = H[2, 0] * xs + H[2, 1] * ys + H[2, 2]
    dx = (H[0, 0] * xs + H[0, 1] * ys + H[0, 2]) / den - xs
    dy = (H[1, 0] * xs + H[1, 1] * ys + H[1, 2]) / den - ys
    if displacement is not None:
        dx = dx + displacement[: dx.shape[0], : dx.shape[1], 0]
        dy = dy + displacement[: dy.shape[0], : dy.shape[1], 1]
    return float(np.median(np.hypot(dx, dy)))


def move_mask(mask: np.ndarray, H: np.ndarray | None, displacement: np.ndarray | None = None) -> np.ndarray:
    """A source's pixel mask moved as :func:`warp_with_flow` moves its image (nearest site; outside: False)."""
    if H is None:
        return mask.copy()
    out = np.zeros(mask.shape, dtype=bool)
    m8 = mask.astype(np.uint8)
    for sl, mx, my, inside in instant_maps(H, displacement, mask.shape):
        out[sl] = (cv2.remap(np.ascontiguousarray(m8[sl]), mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                             borderValue=0) > 0) & inside
    return out
