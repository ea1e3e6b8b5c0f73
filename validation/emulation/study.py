"""Running the emulation study: the sweeps per scene and camera, pooled into the results dict."""

from __future__ import annotations

import math

import numpy as np

from validation.common import (
    PAPER_MAX_RMSE_PERCENT,
    PAPER_MEDIAN_RMSE_PERCENT,
    Progress,
    camera_summary,
    camera_vignetting,
    gt_exposures,
    make_camera,
    seed_for,
    static_radiance,
    study_scene,
    summary_stats,
    to_percent,
)
from validation.emulation.config import EmulationConfig
from validation.emulation.measure import (
    selector_series as _selector_series,
    stats_block as _stats_block,
    choose_brackets,
    hard_cases,
    sweep_static,
)

__all__ = ["run_emulation"]


# ---------------------------------------------------------------------------------- the study
def _nearest_indices(exposures: np.ndarray, wanted) -> list[int]:
    out = []
    for w in wanted:
        i = int(np.argmin(np.abs(np.log(exposures) - math.log(float(w)))))
        if i not in out:
            out.append(i)
    return out


def run_emulation(config: EmulationConfig, *, progress=None, keep_sweeps: bool = False) -> dict:
    """Run the emulation study.

    Returns a dict: ``results`` (JSON-ready: headline figures, per scene and camera
    statistics, per-exposure series, hard cases), ``arrays`` (numpy arrays behind the
    plots, for ``arrays.npz``), ``plots`` (what the report module draws) and, with
    ``keep_sweeps``, the :class:`SweepResult` objects keyed by (scene, camera label).
    """
    import scenes

    tick = Progress(progress)
    exposures = gt_exposures(config.n_exposures, config.lo_ms, config.hi_ms)
    hist_idx = _nearest_indices(exposures, config.hist_exposures_ms)
    cams = config.cameras()
    main_label = _camera_label(*cams[0])

    per = {}  # (scene, label) -> series
    arrays = {"exposures_ms": exposures, "brackets_ms": np.asarray(config.brackets_ms)}
    sweeps = {}
    scene_info = {}
    hard = {}
    for s_i, key in enumerate(config.scenes):
        radiance = static_radiance(key, width=config.width, height=config.height, spp=config.spp,
                                   seed=0, cache_dir=config.cache_dir)
        spec = study_scene(key)
        dr = float(scenes.dynamic_range_db(radiance))
        scene_info[key] = {"scene": spec.scene, "params": dict(spec.params), "lighting": spec.lighting,
                           "dynamic_range_db": dr, "over_100_db": dr > 100.0,
                           "radiance_percentiles": [float(v) for v in np.percentile(
                               scenes.luminance(radiance), [0.1, 50, 99.9])]}
        tick(1)
        for c_i, (resp, vig) in enumerate(cams):
            camera = make_camera(resp, vig, width=config.width, height=config.height)
            label = _camera_label(resp, vig)
            sw = sweep_static(radiance, camera, exposures_ms=exposures, brackets_ms=config.brackets_ms,
                              repeats=config.repeats, seed=seed_for(config.seed, key, label),
                              hist_indices=hist_idx if c_i == 0 else (), progress=tick)
            idx = choose_brackets(sw, config.selector)
            idx_c = choose_brackets(sw, config.selector, clean=True)
            series = _selector_series(sw, idx, idx_c)
            per[(key, label)] = {"series": series, "stats": _stats_block(series),
                                 "camera": camera_summary(camera), "vignetting": camera_vignetting(camera),
                                 "response": resp}
            if c_i == 0:
                tag = f"{key}"
                arrays[f"{tag}/sub_all"] = to_percent(sw.subtracted("all"), sw.white_level, sw.black_level)
                arrays[f"{tag}/sub_valid"] = to_percent(sw.subtracted("valid"), sw.white_level, sw.black_level)
                arrays[f"{tag}/clean_all"] = sw.percent("clean_all")
                arrays[f"{tag}/clean_valid"] = sw.percent("clean_valid")
                arrays[f"{tag}/raw_all"] = sw.percent("raw_all")
                arrays[f"{tag}/pair_all"] = sw.percent("pair_all")
                arrays[f"{tag}/exact_all"] = sw.percent("exact_all")
                arrays[f"{tag}/valid_fraction"] = sw.valid_frac_noisy
                arrays[f"{tag}/selected"] = idx
                arrays[f"{tag}/hist_edges"] = sw.hist_edges
                for h_i, h in sw.hist.items():
                    arrays[f"{tag}/hist{h_i}/gt"] = h["gt"]
                    arrays[f"{tag}/hist{h_i}/emulated"] = h["emulated"]
            if keep_sweeps:
                sweeps[(key, label)] = sw
        if config.hard_cases and s_i == 0:
            hard = hard_cases(radiance, make_camera(*cams[0], width=config.width, height=config.height),
                              seed=seed_for(config.seed, "hard"), progress=tick)

    results = _assemble(config, exposures, hist_idx, per, scene_info, hard, main_label)
    out = {"results": results, "arrays": arrays}
    if keep_sweeps:
        out["sweeps"] = sweeps
    return out


def _camera_label(response: str, vignetting: float | None) -> str:
    return response if vignetting is None else f"{response}+vig{vignetting:g}"


def _pool(per: dict, keys, field_: str) -> list:
    vals = []
    for k in keys:
        vals.extend(per[k]["series"][field_])
    return vals


#: What the figures of the study's results mean (``results["definitions"]``).
_DEFINITIONS = {
    "rmse_percent": "100 * RMSE(DN) / (white_level - black_level)",
    "valid": "over the validity mask of the emulated image (emulator.core.emulate return_mask)",
    "all": "over all pixels",
    "invalid": "over the pixels outside the validity mask",
    "ground_truth": "one noisy capture (repeat 0 of the repeats) at the target exposure",
    "noise_estimator": "per-pixel variance sigma^2 = mean over the consecutive repeat pairs of "
                       "(c[i+1] - c[i])^2 / 2, averaged over the same pixels as the RMSE; "
                       "pair = sqrt(2) sigma, the RMSE between two captures (the paper's camera noise)",
    "sub": "sqrt(max(raw^2 - sigma^2, 0)): the ground truth's noise removed in quadrature; estimates "
           "'exact' (headline)",
    "sub_pair": "sqrt(max(raw^2 - pair^2, 0)): the paper's 'error between consecutive images' removed in "
                "quadrature; clamps to 0 wherever the emulated image is less noisy than a capture",
    "sub_linear": "max(raw - pair, 0): the paper's 'subtract this noise' taken literally",
    "exact": "noisy emulation against the exact noiseless ground truth",
    "clean": "noiseless bracket against noiseless ground truth (emulation error only)",
}


def _extreme_exposures(config, per, labels, exposures) -> dict:
    """Per scene and camera, the figures at the shortest and the longest target exposure."""
    extremes = {}
    for s in config.scenes:
        for lbl in labels:
            ser = per[(s, lbl)]["series"]
            for pos, name in ((0, "shortest"), (-1, "longest")):
                extremes.setdefault(s, {}).setdefault(lbl, {})[name] = {
                    "target_ms": float(exposures[pos]), "bracket_ms": ser["bracket_ms"][pos],
                    "valid_fraction": ser["valid_fraction"][pos], "sub_valid": ser["sub_valid"][pos],
                    "sub_all": ser["sub_all"][pos], "exact_invalid": ser["exact_invalid"][pos],
                    "clean_valid": ser["clean_valid"][pos], "clean_all": ser["clean_all"][pos]}
    return extremes


def _assemble(config, exposures, hist_idx, per, scene_info, hard, main_label) -> dict:
    labels = list(dict.fromkeys(lbl for (_, lbl) in per))
    main_keys = [(s, main_label) for s in config.scenes]
    pooled = {f: summary_stats(_pool(per, main_keys, f)) for f in (
        "sub_valid", "sub_all", "sub_pair_valid", "sub_pair_all", "sub_linear_valid", "sub_linear_all",
        "raw_valid", "raw_all", "pair_valid", "pair_all", "exact_valid",
        "exact_all", "clean_valid", "clean_all", "valid_fraction")}
    by_camera = {}
    for lbl in labels:
        keys = [(s, lbl) for s in config.scenes]
        first = per[keys[0]]
        by_camera[lbl] = {
            "response": first["response"], "vignetting": first["vignetting"],
            "sub_valid": summary_stats(_pool(per, keys, "sub_valid")),
            "sub_all": summary_stats(_pool(per, keys, "sub_all")),
            "clean_valid": summary_stats(_pool(per, keys, "clean_valid")),
            "clean_all": summary_stats(_pool(per, keys, "clean_all")),
            "bound_ok": all(per[k]["stats"]["bound_ok"] for k in keys),
            "selected_bracket_ms_by_scene": {s: per[(s, lbl)]["series"]["bracket_ms"] for s in config.scenes},
        }
    med = [by_camera[lbl]["sub_valid"]["median"] for lbl in labels]
    mx = [by_camera[lbl]["sub_valid"]["max"] for lbl in labels]
    # how often each camera's selector choice equals the main camera's, per scene and exposure
    agree = {}
    for lbl in labels:
        same = [a == b for s in config.scenes for a, b in zip(per[(s, lbl)]["series"]["bracket_ms"],
                                                               per[(s, main_label)]["series"]["bracket_ms"])]
        agree[lbl] = float(np.mean(same))
    per_scene = {}
    for s in config.scenes:
        per_scene[s] = {lbl: per[(s, lbl)]["stats"] for lbl in labels}
        per_scene[s]["info"] = scene_info[s]
    series = {s: {lbl: per[(s, lbl)]["series"] for lbl in labels} for s in config.scenes}
    bound_ok = all(v["bound_ok"] for v in by_camera.values())
    extremes = _extreme_exposures(config, per, labels, exposures)
    return {
        # headline: the selector, noise subtracted, valid pixels, main camera, all scenes and exposures
        "median_rmse_percent": pooled["sub_valid"]["median"],
        "max_rmse_percent": pooled["sub_valid"]["max"],
        "noiseless_max_rmse_percent": pooled["clean_valid"]["max"],
        "noiseless_median_rmse_percent": pooled["clean_valid"]["median"],
        "median_rmse_percent_all_pixels": pooled["sub_all"]["median"],
        "max_rmse_percent_all_pixels": pooled["sub_all"]["max"],
        "noiseless_max_rmse_percent_all_pixels": pooled["clean_all"]["max"],
        "paper": {"median_rmse_percent": PAPER_MEDIAN_RMSE_PERCENT, "max_rmse_percent": PAPER_MAX_RMSE_PERCENT},
        "selector": config.selector,
        "main_camera": main_label,
        "noiseless_within_analytic_bound": bound_ok,
        "pooled": pooled,
        "by_camera": by_camera,
        "camera_spread": {"median_sub_valid_min": min(med), "median_sub_valid_max": max(med),
                          "max_sub_valid_min": min(mx), "max_sub_valid_max": max(mx),
                          "selector_choice_agreement_with_main": agree},
        "per_scene": per_scene,
        "extreme_exposures": extremes,
        "hard_cases": hard,
        "exposures_ms": [float(t) for t in exposures],
        "hist_exposures_ms": [float(exposures[i]) for i in hist_idx],
        "series": series,
        "definitions": dict(_DEFINITIONS),
    }
