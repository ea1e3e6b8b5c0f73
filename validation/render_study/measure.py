"""Render study measures: bright-pixel errors, walk repeatability, denoiser speed-ups, the real frames' statistics."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from validation.render_study.config import TARGET_TOLERANCE

__all__ = ["bright_errors", "walk_repeatability", "speedups", "real_stats", "within_real"]


# ------------------------------------------------------------------------------------------ measures
def _luminance(img: np.ndarray) -> np.ndarray:
    return img[..., 0] * 0.2126 + img[..., 1] * 0.7152 + img[..., 2] * 0.0722


def bright_errors(img: np.ndarray, ref: np.ndarray, *, fraction: float = 0.001, halo_px: int = 3) -> dict:
    """Error in the brightest ``fraction`` of the reference's pixels, and the smear around them.

    Returns ``bright_rel_err`` (relative RMS luminance error over those pixels) and
    ``bright_halo`` (mean luminance over the reference's, minus 1, in the ring within
    ``halo_px`` pixels of them; NaN-free: 0 when the ring is empty).
    """
    import cv2

    y, yr = _luminance(img).astype(np.float64), _luminance(ref).astype(np.float64)
    n = max(1, int(round(fraction * yr.size)))
    thresh = np.partition(yr.ravel(), yr.size - n)[yr.size - n]
    core = yr >= thresh
    rel = float(np.sqrt(np.mean(((y[core] - yr[core]) / np.maximum(yr[core], 1e-12)) ** 2)))
    k = 2 * int(halo_px) + 1
    ring = cv2.dilate(core.astype(np.uint8), np.ones((k, k), np.uint8)).astype(bool) & ~core
    halo = float(y[ring].mean() / max(yr[ring].mean(), 1e-12) - 1.0) if ring.any() else 0.0
    return {"bright_rel_err": rel, "bright_halo": halo}


def walk_repeatability(points_a, depth_a: np.ndarray, pose_a, pose_b, points_b, *, width: int, height: int,
                       fov_deg: float, radius_px: float = 1.5) -> float:
    """Repeatability of frame A's keypoints in frame B through the exact depth and poses.

    Keypoints of A are lifted to 3-D with A's depth (ray distance, metres; 0 = sky),
    projected into B; those that land outside B or see the sky are dropped.  Returns the
    fraction of the rest with a keypoint of B within ``radius_px`` (NaN when none is left).
    """
    import scenes
    from scenes.image_stats import keypoint_repeatability

    pa = np.asarray(points_a, dtype=np.float64).reshape(-1, 2)
    if pa.shape[0] == 0:
        return float("nan")
    fx, fy, cx, cy = scenes.intrinsics(width, height, fov_deg)
    iu = np.clip(np.round(pa[:, 0]).astype(int), 0, width - 1)
    iv = np.clip(np.round(pa[:, 1]).astype(int), 0, height - 1)
    d = depth_a[iv, iu].astype(np.float64)
    rays = np.stack([(pa[:, 0] - cx) / fx, (pa[:, 1] - cy) / fy, np.ones(len(pa))], -1)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    pts = rays * d[:, None] @ np.asarray(pose_a)[:3, :3].T + np.asarray(pose_a)[:3, 3]
    uv = scenes.project(pts, pose_b, width, height, fov_deg)
    ok = (d > 0) & np.all(np.isfinite(uv), axis=1) & (uv[:, 0] >= 0) & (uv[:, 0] <= width - 1) & \
        (uv[:, 1] >= 0) & (uv[:, 1] <= height - 1)
    if not ok.any():
        return float("nan")
    return keypoint_repeatability(uv[ok], points_b, radius_px)


def speedups(rows: list[dict]) -> list[dict]:
    """For each denoised row: the raw time for the same error (log-log on the raw curve) / denoised time."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        raw = sorted((r for r in rows if r["scene"] == scene and r["denoise"] == "off"), key=lambda r: r["time_s"])
        if len(raw) < 2:
            continue
        lt = np.log([r["time_s"] for r in raw])
        le = np.log([max(r["rmse_pct"], 1e-12) for r in raw])
        for r in rows:
            if r["scene"] != scene or r["denoise"] == "off":
                continue
            e = np.log(max(r["rmse_pct"], 1e-12))
            extrapolated = bool(e < le.min() or e > le.max())
            if not extrapolated:
                # raw error falls with time: walk the segments, interpolate on the first that brackets e
                t_eq = None
                for i in range(len(raw) - 1):
                    lo, hi = sorted((le[i], le[i + 1]))
                    if lo <= e <= hi and le[i] != le[i + 1]:
                        t_eq = lt[i] + (e - le[i]) * (lt[i + 1] - lt[i]) / (le[i + 1] - le[i])
                        break
                if t_eq is None:
                    extrapolated = True
            if extrapolated:
                i0, i1 = (len(raw) - 2, len(raw) - 1) if e < le.min() else (0, 1)
                slope = (le[i1] - le[i0]) / (lt[i1] - lt[i0]) if lt[i1] != lt[i0] else -0.5
                slope = slope if slope < 0 else -0.5  # never extrapolate a flat or rising curve
                t_eq = lt[i1] + (e - le[i1]) / slope
            t_raw = float(np.exp(t_eq))
            out.append({"scene": scene, "spp": r["spp"], "denoise": r["denoise"], "denoised_time_s": r["time_s"],
                        "denoised_rmse_pct": r["rmse_pct"], "raw_time_same_error_s": t_raw,
                        "speedup": t_raw / r["time_s"], "extrapolated": extrapolated})
    return out


# ------------------------------------------------------------------------------------------ the study
def real_stats(sequence, size, exposure_ms) -> dict | None:
    """Keypoint density and median gradient of the real sequence's frames at ``exposure_ms`` (None without one)."""
    from scenes.image_stats import image_stats, real_frames_gray8

    if sequence is None or not Path(sequence).is_dir():
        return None
    frames = real_frames_gray8(sequence, exposure_ms=exposure_ms, size=tuple(size))
    st = [image_stats(g) for _, _, g in frames]
    return {"kp_per_mp": float(np.mean([s.keypoints_per_mp for s in st])),
            "median_gradient": float(np.mean([s.median_gradient for s in st])),
            "n_frames": len(st), "per_frame": [s.to_dict() for s in st]}


def within_real(value, real) -> bool | None:
    """Whether ``value`` is within TARGET_TOLERANCE of the real figure (None when either is missing)."""
    if real is None or value is None:
        return None
    return bool(abs(value / real - 1.0) <= TARGET_TOLERANCE)
