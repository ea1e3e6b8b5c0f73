"""Exposure-time integration: a shot of t ms averages the radiance over its exposure window.

Mitsuba 3 has no animated transforms (a shutter only stamps ray times), so motion blur is
made here, from one render per shot:

1. Predict the blur length in pixels over the window (:func:`predicted_blur_px`): the
   longest image path of a grid of scene points at :data:`NEAR_DEPTH_M` (the nearest
   surface a head-mounted camera meets) between the window's start and end, rotation and
   translation together.
2. ``n = ceil(SUBINSTANTS_PER_PX * blur)`` sub-instants at the midpoints of n equal parts of
   the window (at most :data:`MAX_SUBINSTANTS`).  A frame at rest (n = 1) is one plain
   :func:`scenes.render` at the window's middle: it costs what a still frame costs.
3. Otherwise render once, at the window's middle pose, with a margin on every side of the
   longer image path from the middle to either end of the window plus 2 pixels (same focal
   length, wider field of view), plus a depth pass (Mitsuba's ``aov`` integrator,
   ``dd.y:depth``: the distance along each pixel's ray, turned into z-depth here), and warp
   that render to every sub-instant's pose: a backward warp by the rotation homography plus
   the parallax of the source depth (three fixed-point iterations on the destination's
   inverse depth), bilinear (OpenCV ``remap``).  The shot is the mean of the warped images.

The timestamp convention of synthetic shots: a shot with timestamp t and exposure T
integrates over ``[t, t + T]`` (the trigger starts the exposure).  Surfaces hidden at the
middle pose and seen at a sub-instant (disocclusions) take the colour of what hides them:
a one-pixel-scale effect for the motion within one exposure.
"""

from __future__ import annotations

import math
import time

import numpy as np

from scenes.camera import DEFAULT_FOV_DEG, intrinsics
from scenes.errors import RenderError

__all__ = [
    "SUBINSTANTS_PER_PX",
    "MAX_SUBINSTANTS",
    "NEAR_DEPTH_M",
    "INTERPOLATIONS",
    "exposure_window_s",
    "predicted_blur_px",
    "n_subinstants",
    "subinstant_times_s",
    "warp_to_pose",
    "ShotRenderer",
    "render_exposure",
]

#: Sub-instants per pixel of predicted blur (2: consecutive sub-images at most half a pixel apart).
SUBINSTANTS_PER_PX = 2.0
#: Cap on the sub-instants of one shot.
MAX_SUBINSTANTS = 96
#: Depth of the nearest surface assumed by the blur prediction, m.
NEAR_DEPTH_M = 1.0
#: Resamplers of the warps: name -> OpenCV interpolation flag.
INTERPOLATIONS = {"linear": "INTER_LINEAR", "cubic": "INTER_CUBIC", "lanczos4": "INTER_LANCZOS4"}
#: Blur (px) below which a shot is one sub-instant.
_AT_REST_PX = 0.25
_GRID = np.linspace(0.0, 1.0, 5)
_PATH_SAMPLES = 5


def exposure_window_s(timestamp_s: float, exposure_ms: float) -> tuple[float, float]:
    """``(start, end)`` of the exposure of a shot triggered at ``timestamp_s``, seconds."""
    return float(timestamp_s), float(timestamp_s) + float(exposure_ms) * 1e-3


def _project(points_w: np.ndarray, pose: np.ndarray, k: np.ndarray) -> np.ndarray:
    pc = (points_w - pose[:3, 3]) @ pose[:3, :3]
    return (pc[:, :2] / pc[:, 2:3]) * (k[0, 0], k[1, 1]) + (k[0, 2], k[1, 2])


def predicted_blur_px(poses: np.ndarray, width: int, height: int, fov_deg: float = DEFAULT_FOV_DEG, *,
                      near_depth_m: float = NEAR_DEPTH_M) -> float:
    """Longest image path (px) of a 5x5 grid of points at ``near_depth_m``, along ``poses``.

    Parameters
    ----------
    poses : numpy.ndarray
        (N, 4, 4) camera-to-world poses over the exposure window, in time order (N >= 2;
        the path is the sum of the segments between them).
    width, height, fov_deg :
        The image (as :func:`scenes.camera.intrinsics`).
    """
    poses = np.asarray(poses, dtype=np.float64)
    fx, fy, cx, cy = intrinsics(width, height, fov_deg)
    k = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    u, v = np.meshgrid(_GRID * (width - 1), _GRID * (height - 1))
    rays = np.stack([(u.ravel() - cx) / fx, (v.ravel() - cy) / fy, np.ones(u.size)], axis=1)
    mid = poses[len(poses) // 2]
    points = mid[:3, 3] + (rays * near_depth_m) @ mid[:3, :3].T
    tracks = np.stack([_project(points, p, k) for p in poses])
    return float(np.max(np.sum(np.linalg.norm(np.diff(tracks, axis=0), axis=2), axis=0))) if len(poses) > 1 else 0.0


def n_subinstants(blur_px: float, samples_per_px: float = SUBINSTANTS_PER_PX) -> int:
    """Sub-instants a shot with ``blur_px`` of blur needs (1 at rest, at most :data:`MAX_SUBINSTANTS`)."""
    if not (math.isfinite(blur_px) and blur_px >= 0):
        raise RenderError(f"blur_px must be finite and >= 0, got {blur_px!r}")
    if blur_px < _AT_REST_PX:
        return 1
    return int(min(MAX_SUBINSTANTS, max(2, math.ceil(samples_per_px * blur_px))))


def subinstant_times_s(t0_s: float, t1_s: float, n: int) -> np.ndarray:
    """Midpoints of ``n`` equal parts of ``[t0_s, t1_s]`` (float64 seconds)."""
    return t0_s + (np.arange(n) + 0.5) * (t1_s - t0_s) / n


def _z_depth(distance: np.ndarray, k: np.ndarray) -> np.ndarray:
    h, w = distance.shape
    u, v = np.meshgrid((np.arange(w) - k[0, 2]) / k[0, 0], (np.arange(h) - k[1, 2]) / k[1, 1])
    return distance / np.sqrt(u * u + v * v + 1.0)


def warp_to_pose(radiance: np.ndarray, inv_depth: np.ndarray, pose_src: np.ndarray, k_src: np.ndarray,
                 pose_dst: np.ndarray, k_dst: np.ndarray, width: int, height: int, *,
                 iterations: int = 3, interpolation: int | None = None) -> np.ndarray:
    """The image a camera at ``pose_dst`` sees, backward-warped from a render at ``pose_src``.

    Parameters
    ----------
    radiance : numpy.ndarray
        float32 (Hs, Ws, C) source render.
    inv_depth : numpy.ndarray
        float32 (Hs, Ws) source inverse z-depth, 1/m (0: at infinity, the sky).
    pose_src, pose_dst : numpy.ndarray
        4x4 camera-to-world poses (OpenCV frame).
    k_src, k_dst : numpy.ndarray
        3x3 camera matrices of the source and destination images.
    width, height : int
        Destination size.

    Returns
    -------
    numpy.ndarray
        float32 (height, width, C); pixels that map outside the source take the nearest
        border pixel (the margin keeps them inside).
    """
    import cv2

    interpolation = cv2.INTER_LINEAR if interpolation is None else interpolation
    r_sd = pose_src[:3, :3].T @ pose_dst[:3, :3]
    t_sd = pose_src[:3, :3].T @ (pose_dst[:3, 3] - pose_src[:3, 3])
    # per-component float32 arithmetic (R_sd r_d, one row of the rotation at a time): a third of
    # the CPU of (H, W, 3) float64 matrix products, maps exact to float32 rounding as before
    xn = ((np.arange(width) - k_dst[0, 2]) / k_dst[0, 0]).astype(np.float32)[None, :]
    yn = ((np.arange(height) - k_dst[1, 2]) / k_dst[1, 1]).astype(np.float32)[:, None]
    rx, ry, rz = (np.float32(r[0]) * xn + np.float32(r[1]) * yn + np.float32(r[2]) for r in r_sd)
    t = t_sd.astype(np.float32)
    moving = bool(np.any(t_sd))
    fx, cx, fy, cy = (np.float32(v) for v in (k_src[0, 0], k_src[0, 2], k_src[1, 1], k_src[1, 2]))
    q = None
    for it in range(iterations + 1):
        px, py, pz = (rx, ry, rz) if q is None else (rx + q * t[0], ry + q * t[1], rz + q * t[2])
        inv_z = 1.0 / np.maximum(pz, np.float32(1e-9))
        map_x = fx * px * inv_z + cx
        map_y = fy * py * inv_z + cy
        if it == iterations or not moving:
            break
        q_s = cv2.remap(inv_depth, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        q = q_s * rz / np.maximum(1.0 - t[2] * q_s, np.float32(1e-6))
    out = cv2.remap(np.ascontiguousarray(radiance, dtype=np.float32), map_x, map_y, interpolation,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(height, width, -1)


class ShotRenderer:
    """One render (with margin and depth) that serves every exposure window of one shot.

    The render is made at ``anchor_s`` (default: the middle of the longest window,
    ``t0_s + max_exposure_ms / 2``) with a margin sized for the blur of the longest window;
    :meth:`radiance` then warps it to the sub-instants of any window ``[t0_s, t0_s + T]``,
    ``T <= max_exposure_ms``.  When even the longest window is at rest (predicted blur below
    a quarter pixel) the render is a plain :func:`scenes.render` at the anchor, returned for
    every exposure: a still frame costs what it costs without blur.  ``adaptive``: as
    :func:`scenes.render` (left out of the render's arguments when None).
    """

    def __init__(self, scene, pose_at, t0_s: float, max_exposure_ms: float, *, width: int, height: int,
                 spp: int, seed: int = 0, fov_deg: float = DEFAULT_FOV_DEG, cache_dir=None, variant=None,
                 denoise=None, samples_per_px: float = SUBINSTANTS_PER_PX, near_depth_m: float = NEAR_DEPTH_M,
                 anchor_s: float | None = None, interpolation: str = "linear", supersample: int = 1,
                 margin_step_px: int = 1, adaptive=None):
        if isinstance(margin_step_px, bool) or not isinstance(margin_step_px, int) or margin_step_px < 1:
            raise RenderError(f"margin_step_px must be an integer >= 1, got {margin_step_px!r}")
        self.margin_step_px = margin_step_px
        if isinstance(supersample, bool) or not isinstance(supersample, int) or supersample < 1:
            raise RenderError(f"supersample must be an integer >= 1, got {supersample!r}")
        self.supersample = supersample
        if interpolation not in INTERPOLATIONS:
            raise RenderError(f"interpolation must be one of {', '.join(INTERPOLATIONS)}, got {interpolation!r}")
        self.interpolation = interpolation
        if not (math.isfinite(t0_s) and math.isfinite(max_exposure_ms) and max_exposure_ms >= 0):
            raise RenderError(f"need a finite t0_s and max_exposure_ms >= 0, got {t0_s!r}, {max_exposure_ms!r}")
        self.scene, self.pose_at, self.t0_s = scene, pose_at, float(t0_s)
        self.max_exposure_ms = float(max_exposure_ms)
        self.width, self.height, self.fov_deg = int(width), int(height), float(fov_deg)
        self.render_args = dict(spp=spp, seed=seed, cache_dir=cache_dir, variant=variant, denoise=denoise,
                                **({} if adaptive is None else {"adaptive": adaptive}))
        self.samples_per_px, self.near_depth_m = float(samples_per_px), float(near_depth_m)
        t1 = self.t0_s + 1e-3 * self.max_exposure_ms
        self.anchor_s = 0.5 * (self.t0_s + t1) if anchor_s is None else float(anchor_s)
        self.max_blur_px = self.blur_px(self.max_exposure_ms)
        self.at_rest = n_subinstants(self.max_blur_px, self.samples_per_px) <= 1
        self.info = {"max_blur_px": self.max_blur_px, "at_rest": self.at_rest, "margin_px": 0, "render_s": 0.0,
                     "depth_s": 0.0, "warp_s": 0.0, "cache_hit": None}
        self._src = None

    def blur_px(self, exposure_ms: float) -> float:
        """Predicted blur (px) of the window ``[t0_s, t0_s + exposure_ms]``, plus the anchor's offset."""
        t1 = self.t0_s + 1e-3 * float(exposure_ms)
        times = np.linspace(min(self.t0_s, getattr(self, "anchor_s", self.t0_s)), t1, _PATH_SAMPLES)
        return predicted_blur_px(np.asarray(self.pose_at(times), dtype=np.float64), self.width, self.height,
                                 self.fov_deg, near_depth_m=self.near_depth_m)

    def margin_px(self) -> int:
        """Pixels of margin the render needs: the longer image path from the anchor to either end
        of the span (points at ``near_depth_m``), rounded up, plus 2 for the interpolation, then up to a
        multiple of ``margin_step_px`` (renders of a walk then share a few sizes: Dr.Jit compiles its
        kernels again for every new image size, about a second each on 2 cores)."""
        t1 = self.t0_s + 1e-3 * self.max_exposure_ms
        halves = [(self.t0_s, self.anchor_s), (self.anchor_s, t1)]
        reach = max(predicted_blur_px(np.asarray(self.pose_at(np.linspace(a, b, _PATH_SAMPLES)), dtype=np.float64),
                                      self.width, self.height, self.fov_deg, near_depth_m=self.near_depth_m)
                    for a, b in halves if b > a)
        step = self.margin_step_px
        return -(-(int(math.ceil(reach)) + 2) // step) * step

    def render_job(self) -> dict:
        """The :func:`scenes.render` keyword arguments of the one render (for a Dask prefetch)."""
        anchor = np.asarray(self.pose_at(np.array([self.anchor_s])), dtype=np.float64)[0]
        if self.at_rest:
            return dict(scene=self.scene, pose=anchor, width=self.width, height=self.height, fov_deg=self.fov_deg,
                        **self.render_args)
        margin = self.margin_px()
        fx = intrinsics(self.width, self.height, self.fov_deg)[0]
        ws, hs = self.width + 2 * margin, self.height + 2 * margin
        ss = self.supersample  # ss x ss pixels per output pixel, the same samples per output pixel in all
        args = {**self.render_args, "spp": max(1, int(round(self.render_args["spp"] / (ss * ss))))}
        return dict(scene=self.scene, pose=anchor, width=ss * ws, height=ss * hs,
                    fov_deg=math.degrees(2.0 * math.atan(0.5 * ws / fx)), **args)

    def _prepare(self) -> None:
        from scenes.render import render_depth, render_with_info

        if self._src is not None:
            return
        job = self.render_job()
        anchor, ws, hs, fov_src = job["pose"], job["width"], job["height"], job["fov_deg"]
        t = time.perf_counter()
        src, rinfo = render_with_info(**job)
        self.info.update(render_s=time.perf_counter() - t, cache_hit=rinfo["cache_hit"])
        if self.at_rest:
            self._src = (src, None, anchor, None)
            return
        self.info["margin_px"] = (ws // self.supersample - self.width) // 2
        fx = self.supersample * intrinsics(self.width, self.height, self.fov_deg)[0]
        t = time.perf_counter()
        k_src = np.array([[fx, 0, (ws - 1) / 2.0], [0, fx, (hs - 1) / 2.0], [0, 0, 1.0]])
        dist = render_depth(self.scene, anchor, width=ws, height=hs, fov_deg=fov_src, spp=1,
                            seed=self.render_args["seed"], variant=self.render_args["variant"])
        z = _z_depth(dist, k_src)
        inv_depth = np.where(z > 0, 1.0 / np.maximum(z, 1e-6), 0.0).astype(np.float32)
        self.info["depth_s"] = time.perf_counter() - t
        self._src = (src, inv_depth, anchor, k_src)

    def radiance(self, exposure_ms: float, *, start_s: float | None = None,
                 n_subinstants_override: int | None = None,
                 interpolation: str | None = None) -> tuple[np.ndarray, dict]:
        """Mean radiance over ``[start, start + exposure_ms]`` (``start`` default ``t0_s``; the window
        must lie in ``[t0_s, t0_s + max_exposure_ms]``): float32 (H, W, 3), and ``{blur_px, n_subinstants}``.
        ``interpolation`` (default the renderer's) names the resampler of the warps (:data:`INTERPOLATIONS`)."""
        import cv2

        interpolation = self.interpolation if interpolation is None else interpolation
        if interpolation not in INTERPOLATIONS:
            raise RenderError(f"interpolation must be one of {', '.join(INTERPOLATIONS)}, got {interpolation!r}")
        exposure_ms = float(exposure_ms)
        start = self.t0_s if start_s is None else float(start_s)
        t1 = start + 1e-3 * exposure_ms
        end = self.t0_s + 1e-3 * self.max_exposure_ms
        if not (exposure_ms >= 0.0 and self.t0_s - 1e-9 <= start and t1 <= end + 1e-9):
            raise RenderError(f"the window [{start:.6f}, {t1:.6f}] s must lie in [{self.t0_s:.6f}, {end:.6f}] s")
        self._prepare()
        src, inv_depth, anchor, k_src = self._src
        blur = predicted_blur_px(np.asarray(self.pose_at(np.linspace(start, t1, _PATH_SAMPLES))), self.width,
                                 self.height, self.fov_deg, near_depth_m=self.near_depth_m)
        if self.at_rest:
            return src, {"blur_px": blur, "n_subinstants": 1}
        n = (n_subinstants(blur, self.samples_per_px) if n_subinstants_override is None
             else int(n_subinstants_override))
        fx, ss = k_src[0, 0], self.supersample
        wd, hd = ss * self.width, ss * self.height
        k_dst = np.array([[fx, 0, (wd - 1) / 2.0], [0, fx, (hd - 1) / 2.0], [0, 0, 1.0]])
        t = time.perf_counter()
        acc = np.zeros((hd, wd, src.shape[2]), dtype=np.float64)
        for pose in np.asarray(self.pose_at(subinstant_times_s(start, t1, n)), dtype=np.float64):
            acc += warp_to_pose(src, inv_depth, anchor, k_src, pose, k_dst, wd, hd,
                                interpolation=getattr(cv2, INTERPOLATIONS[interpolation]))
        out = (acc / n).astype(np.float32)
        if ss > 1:  # the mean of each ss x ss block: the output pixel's area
            out = cv2.resize(out, (self.width, self.height), interpolation=cv2.INTER_AREA).reshape(
                self.height, self.width, -1)
        self.info["warp_s"] += time.perf_counter() - t
        if interpolation != "linear":  # the cubic and Lanczos kernels overshoot below zero at edges
            np.maximum(out, 0.0, out=out)
        return out, {"blur_px": blur, "n_subinstants": n}


def render_exposure(scene, pose_at, t0_s: float, t1_s: float, **kwargs) -> tuple[np.ndarray, dict]:
    """The radiance a shot integrates over ``[t0_s, t1_s]`` (mean over the window), and what it took.

    One :class:`ShotRenderer` anchored at the window's middle; ``kwargs`` as its constructor
    (``width``, ``height``, ``spp``, ``seed``, ``fov_deg``, ``cache_dir``, ``variant``,
    ``denoise``, ``samples_per_px``, ``near_depth_m``) plus ``n_subinstants_override``.

    Returns
    -------
    radiance : numpy.ndarray
        float32 (height, width, 3), W m^-2 sr^-1.
    info : dict
        ``blur_px`` (predicted), ``n_subinstants``, ``margin_px``, ``render_s``, ``depth_s``,
        ``warp_s`` (wall-clock seconds) and ``cache_hit``.
    """
    if not (math.isfinite(t0_s) and math.isfinite(t1_s) and t1_s >= t0_s):
        raise RenderError(f"exposure window must satisfy t0_s <= t1_s, got [{t0_s!r}, {t1_s!r}]")
    override = kwargs.pop("n_subinstants_override", None)
    shot = ShotRenderer(scene, pose_at, t0_s, 1e3 * (t1_s - t0_s), **kwargs)
    image, sub = shot.radiance(1e3 * (t1_s - t0_s), n_subinstants_override=override)
    return image, {**shot.info, **sub}
