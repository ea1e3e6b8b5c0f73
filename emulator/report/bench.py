"""Figures and markdown reports of the feature and VO benchmarks (:mod:`emulator.metrics.bench`); the VO
side lives in :mod:`emulator.report.vo` and is re-exported here.

Matplotlib is imported lazily and drives an Agg canvas directly
(:func:`emulator.report.figures.new_figure`), so the functions work headless and never
open a window.  Every figure is drawn from the dictionaries the benchmarks save in
``results.json``, so it can be redrawn without recomputing.
"""

from __future__ import annotations

import numpy as np

from emulator.report.features_plot import features_figure, plot_features, weakest_pairs
from emulator.report.intervals import comparison_table, mark_trending
from emulator.report.verdicts import dash_cell, matches_verdict, success_verdict, uniformity_verdict
from emulator.report.vo import (  # re-exported: the VO report lives in emulator.report.vo
    FAILED_STYLE,
    MAX_EQUAL_ASPECT,
    PAPER_VO,
    extrinsics_sentence,
    plot_rpe,
    plot_trajectories,
    rpe_figure,
    trajectories_figure,
    vo_report,
    vo_table_markdown,
    vo_verdicts,
    write_vo_report,
)
from emulator.core.stats import compare_methods

__all__ = [
    "plot_features",
    "features_figure",
    "weakest_pairs",
    "plot_rpe",
    "rpe_figure",
    "plot_trajectories",
    "trajectories_figure",
    "FAILED_STYLE",
    "MAX_EQUAL_ASPECT",
    "features_report",
    "features_intervals",
    "features_intervals_markdown",
    "features_verdicts",
    "vo_report",
    "vo_table_markdown",
    "write_vo_report",
    "extrinsics_sentence",
    "vo_verdicts",
    "PAPER_FEATURES",
    "PAPER_VO",
]

#: The paper's Fig. 4 numbers (section V-D-1), for the report.
PAPER_FEATURES = {
    "median matches of fixed": 674,
    "success rate at tau = 100, best (fixed)": "44 %",
    "success rate at tau = 100, worst (classical-30, classical-70, kim)": "20 %",
}
def _feature_facts(results: dict) -> dict:
    """Image size, largest and smallest pair match count, median keypoints per image, over all runs and methods."""
    seqs = [s for run in results["runs"] for s in run["methods"].values()]
    matches = [c for s in seqs for c in s.get("matches", [])]
    keypoints = [k for s in seqs for k in s.get("n_keypoints", [])]
    shapes = [tuple(s["image_shape"]) for s in seqs if s.get("image_shape") and s["image_shape"][0]]
    h, w = max(set(shapes), key=shapes.count) if shapes else (0, 0)
    return {"image_wh": (w, h), "max_matches": max(matches) if matches else None,
            "min_matches": min(matches) if matches else None,
            "median_keypoints": float(np.median(keypoints)) if keypoints else None}


def features_verdicts(results: dict) -> list[str]:
    """One sentence per result of the feature benchmark: expected or not beside the paper, and why."""
    facts = _feature_facts(results)
    methods = results["methods"]
    if not facts["image_wh"][0]:
        return ["No image was analysed: nothing to compare with the paper."]
    uni = {k: None if m["median_uniformity"] is None else 100 * m["median_uniformity"] for k, m in methods.items()}
    med = {k: m["median_matches"] for k, m in methods.items() if m["median_matches"] is not None}
    name = "fixed" if "fixed" in med else (max(med, key=med.get) if med else "fixed")
    rates = {k: None if m["success_at_100"] is None else 100 * m["success_at_100"] for k, m in methods.items()}
    return [
        uniformity_verdict(uni, facts["median_keypoints"], results["parameters"]["grid"]),
        matches_verdict(med.get(name), facts["image_wh"], name),
        success_verdict(100, rates, facts["max_matches"], facts["min_matches"], facts["image_wh"]),
    ]


def features_intervals(results: dict) -> dict:
    """Median matches (over consecutive pairs) and median uniformity (over images) per method with 95 %
    circular-block-bootstrap intervals, and each method's difference from the best
    (:func:`emulator.core.stats.compare_methods`; pairs and images are time series)."""
    methods = list(results["methods"])
    matches = {m: [c for run in results["runs"] for c in run["methods"].get(m, {}).get("matches", [])]
               for m in methods}
    uniformity = {m: [u for run in results["runs"] for u in run["methods"].get(m, {}).get("uniformity", [])]
                  for m in methods}
    return {"median_matches": compare_methods(matches, "median", block=True, seed=0),
            "median_uniformity": compare_methods(uniformity, "median", block=True, seed=1)}


def features_intervals_markdown(results: dict) -> list[str]:
    """The tables of :func:`features_intervals` (nothing when no method has a pair)."""
    iv = features_intervals(results)
    if iv["median_matches"]["best"] is None:
        return []
    trending = {m: t for run in results["runs"] for m, t in (run.get("still_trending") or {}).items()}
    lines = ["Methods compared with 95 % intervals (circular block bootstrap over consecutive pairs / images; "
             "\"cannot tell apart\": the difference's interval holds 0):", ""]
    lines += comparison_table(mark_trending(iv["median_matches"], trending), "median matches", spec=".1f")
    if iv["median_uniformity"]["best"] is not None:
        lines += [""] + comparison_table(mark_trending(iv["median_uniformity"], trending), "median uniformity (%)",
                                         spec=".1f", scale=100.0)
    if trending:
        lines += ["", "**Too short to settle:** the methods marked \"still rising\" or \"still falling\" had not "
                  "settled at the end of the run (their exposure moved one way by 5 % or more over the last 3 "
                  "recorder cycles): their \"best\" or \"differs\" describes the approach, not where they settle."]
    return lines


#: The note under the features table: its "-" cells (no RPE in this benchmark).
FEATURES_DASH_NOTE = ("A \"-\" cell means the figure does not exist for that row: no image pair (matches, success) "
                      "or no image (uniformity).")


def features_report(results: dict, figure: str) -> str:
    """Markdown report of the feature benchmark, beside the paper's Fig. 4 numbers."""
    p = results["parameters"]
    lines = [
        "# Feature tracking and uniformity (paper section V-D-1, Fig. 4)",
        "",
        f"Run folders: {', '.join('`' + r['run_dir'] + '`' for r in results['runs'])}",
        "",
        f"SIFT (OpenCV defaults, n_features={p['n_features']}) on the emulated left images, "
        f"image scale {p['scale']}; 8-bit conversion: {p['conversion']}. "
        f"Uniformity: fraction of the {p['grid'][0]}x{p['grid'][1]} grid cells with a keypoint. "
        f"Matches: {p['matcher']} nearest neighbours with Lowe's ratio test < {p['ratio']}. "
        "A run succeeds for tau when every consecutive pair has at least tau matches.",
        "",
        f"![Fig. 4]({figure})",
        "",
        "| method | runs | images | median uniformity (%) | median matches | min matches | success at tau=100 (%) |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for name, m in results["methods"].items():
        u = m["median_uniformity"]
        lines.append(
            f"| {name} | {m['n_runs']} | {m['n_images']} | {dash_cell(None if u is None else 100 * u)} | "
            f"{dash_cell(m['median_matches'], '.0f')} | {dash_cell(m['min_matches'], 'd')} | "
            f"{dash_cell(None if m['success_at_100'] is None else 100 * m['success_at_100'], '.0f')} |"
        )
    lines += ["", FEATURES_DASH_NOTE, ""]
    lines += features_intervals_markdown(results)
    lines += ["", "Paper (55 trajectories, 1920x1200 images):", ""]
    lines += [f"- {k}: {v}" for k, v in PAPER_FEATURES.items()]
    lines += ["", "## Verdicts", ""] + [f"- {v}" for v in features_verdicts(results)]
    lines += ["", f"Command: `{results.get('command') or '(library call)'}`", ""]
    return "\n".join(lines)
