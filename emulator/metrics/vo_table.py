"""The stereo VO of each method in figures that need no reference trajectory, and the ranking on them.

Without a reference the relative pose error cannot be computed, so ``exposim bench vo`` ranks the
methods on what the VO itself shows (:func:`vo_ranking`): frames tracked, PnP inliers per step and
stereo points per frame (:func:`vo_summary`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["vo_summary", "vo_ranking"]


def _median(values) -> float | None:
    kept = [float(v) for v in values if v is not None and np.isfinite(v)]
    return float(np.median(kept)) if kept else None


def vo_summary(frames: dict, positions_xyz) -> dict:
    """One method's VO in figures that need no reference: frames tracked, the median stereo points per
    frame, PnP inliers per step (the first frame has no step) and row offset after rectification (px),
    and the length of the VO path (m, the sum of the steps)."""
    xyz = np.asarray(positions_xyz, dtype=np.float64).reshape(-1, 3)
    steps = np.linalg.norm(np.diff(xyz, axis=0), axis=1) if len(xyz) > 1 else np.zeros(0)
    return {
        "n_tracked": int(sum(bool(t) for t in frames["tracked"])),
        "n_frames": len(frames["tracked"]),
        "median_stereo_points": _median(frames["n_stereo_points"]),
        "median_inliers": _median(frames["n_inliers"][1:]),
        "median_row_offset_px": _median(frames["row_offset_px"]),
        "path_length_m": float(steps[np.isfinite(steps)].sum()),
    }


def vo_ranking(method_results: dict) -> list[str]:
    """Methods ranked without a reference: most frames tracked first, then the most PnP inliers per step
    (median), then the most stereo points per frame (median)."""
    def key(name):
        s = method_results[name]["summary"]
        return (-s["n_tracked"], -(s["median_inliers"] or 0.0), -(s["median_stereo_points"] or 0.0), name)

    return sorted((n for n, e in method_results.items() if e.get("summary")), key=key)
