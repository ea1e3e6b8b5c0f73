"""Per scene and per method figures of the AE study, and the figures pooled over the scenes."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np

from emulator.cells import median_finite
from validation.ae_study.config import METHODS, StudyConfig

__all__ = ["segment_success", "summarise"]


def segment_success(matches, segment_pairs: int, tau: int) -> tuple[int, int]:
    """Segments of ``segment_pairs`` consecutive pairs whose every pair has >= ``tau`` matches.

    The sequence of pair match counts is cut into ``len(matches) // segment_pairs``
    non-overlapping segments from the start (a shorter tail is dropped; a sequence shorter
    than one segment counts as one segment).

    Returns
    -------
    (successes, segments) : tuple of int

    Examples
    --------
    >>> segment_success([120, 130, 90, 200, 150, 160], 2, 100)
    (2, 3)
    """
    m = np.asarray(matches, dtype=np.int64)
    if m.size == 0:
        return 0, 0
    n = max(1, m.size // segment_pairs)
    size = min(segment_pairs, m.size)
    ok = sum(int(m[i * size:(i + 1) * size].min() >= tau) for i in range(n))
    return ok, n


def _minimal_median(rpe: dict | None, key: str) -> tuple[float | None, float | None]:
    """(smallest median over the pair lengths, its pair length in m) of ``trans_pct`` / ``rot_deg_per_m``."""
    if not rpe:
        return None, None
    best = None
    for d in rpe.get("deltas", []):
        stats = d.get(key)
        if d.get("n_pairs") and stats and stats.get("median") is not None and math.isfinite(stats["median"]):
            if best is None or stats["median"] < best[0]:
                best = (float(stats["median"]), float(d["delta_m"]))
    return best if best is not None else (None, None)


def _mean(values) -> float | None:
    vals = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return float(np.mean(vals)) if vals else None


def _vo_entry(v: dict) -> dict:
    """One method's VO figures on one scene from its entry in the VO benchmark's ``results.json``: status,
    failures, the minimal median RPE (translation and rotation) at its pair length, and why it is missing."""
    trans, trans_delta = _minimal_median(v.get("rpe"), "trans_pct")
    rot, rot_delta = _minimal_median(v.get("rpe"), "rot_deg_per_m")
    return {
        "status": v["status"],
        "n_frames": v["n_frames"],
        "n_failed_frames": len(v["failures"]),
        "failure_reasons": dict(Counter(fl["reason"] for fl in v["failures"])),
        "median_stereo_points": median_finite(v["frames"]["n_stereo_points"]),
        "median_inliers": median_finite(v["frames"]["n_inliers"][1:]),
        "rpe_trans_pct": trans,
        "rpe_trans_delta_m": trans_delta,
        "rpe_rot_deg_per_m": rot,
        "rpe_rot_delta_m": rot_delta,
        "rpe_on_failed_run": v["status"] != "success" and v.get("rpe") is not None,
        "rpe_missing_reason": None if trans is not None else (
            v.get("rpe_skipped") or "no pose pair of the tested lengths (see rpe_by_delta)"),
        "rpe_by_delta": [
            {"delta_m": d["delta_m"], "n_pairs": d["n_pairs"],
             "trans_pct_median": (d["trans_pct"] or {}).get("median"),
             "rot_deg_per_m_median": (d["rot_deg_per_m"] or {}).get("median")}
            for d in ((v.get("rpe") or {}).get("deltas") or [])
        ],
    }


def summarise(config: StudyConfig, features: dict, vo: dict[str, dict], runs: dict[str, dict]) -> dict:
    """Per scene and per method figures, and the figures pooled over the scenes.

    Parameters
    ----------
    config : StudyConfig
    features : dict
        ``results.json`` of :func:`~emulator.metrics.bench.bench_features` over all scenes'
        runs (runs in the order of ``config.scenes``).
    vo : dict
        Scene name to the ``results.json`` of :func:`~emulator.metrics.bench.bench_vo`.
    runs : dict
        Scene name to the closed-loop summary (``runs/<scene>/results.json``).

    Returns
    -------
    dict
        ``{"per_scene": {scene: {method: {...}}}, "overall": {method: {...}}}``; a figure
        that could not be measured is None, with the reason beside it.
    """
    taus = [int(t) for t in config.taus]
    per_scene: dict[str, dict] = {}
    for scene, frun in zip(config.scenes, features["runs"]):
        rows = {}
        for name, f in frun["methods"].items():
            matches = f["matches"]
            run_m = runs.get(scene, {}).get("methods", {}).get(name, {})
            v = vo.get(scene, {}).get("methods", {}).get(name)
            seg = {str(t): segment_success(matches, config.segment_pairs, t) for t in taus}
            entry = {
                "median_exposure_ms": run_m.get("median_exposure_ms"),
                "mean_saturated_fraction": run_m.get("mean_saturated_fraction"),
                "n_images": f["n_images"],
                "median_uniformity": f["median_uniformity"],
                "median_matches": f["median_matches"],
                "min_matches": f["min_matches"],
                "max_matches": max(matches) if matches else None,
                "median_keypoints": float(np.median(f["n_keypoints"])) if f.get("n_keypoints") else None,
                "sequence_success": {str(t): (bool(min(matches) >= t) if matches else None) for t in taus},
                "segment_success": {k: {"succeeded": a, "segments": b, "rate": (a / b if b else None)}
                                    for k, (a, b) in seg.items()},
            }
            entry["vo"] = None if v is None else _vo_entry(v)
            rows[name] = entry
        per_scene[scene] = rows

    names = [m for m in METHODS if any(m in rows for rows in per_scene.values())]
    names += [m for rows in per_scene.values() for m in rows if m not in names]
    curve = features["success_curve"]
    overall = {}
    for name in names:
        f = features["methods"].get(name, {})
        entries = [rows[name] for rows in per_scene.values() if name in rows]
        rate = curve["rate"].get(name)
        seq_rate = {}
        for t in taus:
            seq_rate[str(t)] = (float(rate[curve["taus"].index(t)]) if rate is not None and t in curve["taus"]
                                else None)
        seg = {}
        for t in taus:
            a = sum(e["segment_success"][str(t)]["succeeded"] for e in entries)
            b = sum(e["segment_success"][str(t)]["segments"] for e in entries)
            seg[str(t)] = {"succeeded": a, "segments": b, "rate": a / b if b else None}
        vos = [e["vo"] for e in entries if e["vo"] is not None]
        converged = [x for x in vos if x["status"] == "success"]
        overall[name] = {
            "n_sequences": len(entries),
            "median_uniformity": f.get("median_uniformity"),
            "median_matches": f.get("median_matches"),
            "quartiles_matches": f.get("quartiles_matches"),
            "min_matches": min((e["min_matches"] for e in entries if e["min_matches"] is not None), default=None),
            "max_matches": max((e["max_matches"] for e in entries if e["max_matches"] is not None), default=None),
            "median_keypoints": median_finite(e["median_keypoints"] for e in entries),
            "sequence_success_rate": seq_rate,
            "segment_success": seg,
            "vo_failed_frames": sum(x["n_failed_frames"] for x in vos),
            "vo_frames": sum(x["n_frames"] for x in vos),
            "vo_failed_runs": sum(1 for x in vos if x["status"] != "success"),
            "rpe_trans_pct_mean_over_scenes": _mean(x["rpe_trans_pct"] for x in vos),
            "rpe_rot_deg_per_m_mean_over_scenes": _mean(x["rpe_rot_deg_per_m"] for x in vos),
            "rpe_trans_pct_mean_converged": _mean(x["rpe_trans_pct"] for x in converged),
            "rpe_rot_deg_per_m_mean_converged": _mean(x["rpe_rot_deg_per_m"] for x in converged),
        }
    return {"per_scene": per_scene, "overall": overall}
