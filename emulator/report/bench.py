"""Figures and markdown reports of the feature and VO benchmarks (:mod:`emulator.metrics.bench`).

Matplotlib is imported lazily and drives an Agg canvas directly
(:func:`emulator.report.figures.new_figure`), so the functions work headless and never
open a window.  Every figure is drawn from the dictionaries the benchmarks save in
``results.json``, so it can be redrawn without recomputing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from emulator.report.features_plot import features_figure, plot_features, weakest_pairs
from emulator.report.figures import legend_outside, new_figure, plural, save
from emulator.report.verdicts import (
    DASH_NOTE,
    matches_verdict,
    rpe_verdict,
    success_verdict,
    uniformity_verdict,
    vo_failure_verdict,
)

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
#: The paper's Fig. 6 numbers (section V-D-2), for the report.
PAPER_VO = {
    "VO failures": "11 of 55 trajectories (20 %)",
    "minimal translation error, best (classical-50)": "4.21 %",
    "minimal translation error, worst (kim)": "5.75 %",
    "minimal rotation error, best (zhang, classical-50)": "0.07 deg/m",
    "fixed": "5.1 % and 0.09 deg/m",
}


def _trans_percent(entry: dict):
    """Translation statistics (%) of one RPE ``deltas`` entry; results written before the key
    was ``trans_percent`` have ``trans_pct``."""
    value = entry.get("trans_percent")
    return entry.get("trans_pct") if value is None else value


#: Line style of a method whose VO failed on some frames (its RPE is drawn, dotted, and named so in the legend).
FAILED_STYLE = ":"


def rpe_figure(results: dict):
    """The figure of :func:`plot_rpe` (a matplotlib Figure; two axes, translation and rotation).

    A method whose VO converged is a solid line; one whose VO failed on some frames (RPE
    computed anyway, ``rpe_on_failure``) is dotted and labelled "(VO failed on N frames)".
    """
    fig, (a, b) = new_figure(2)
    drawn = False
    for name, method in results["methods"].items():
        rpe = method.get("rpe")
        if not rpe:
            continue
        d = [e["delta_m"] for e in rpe["deltas"] if _trans_percent(e)]
        if not d:
            continue
        failed = method["status"] != "success"
        style = FAILED_STYLE if failed else "-"
        label = f"{name} (VO failed on {plural(len(method.get('failures', [])), 'frame')})" if failed else name
        a.plot(d, [_trans_percent(e)["median"] for e in rpe["deltas"] if _trans_percent(e)], style, marker="o",
               label=label)
        b.plot(d, [e["rot_deg_per_m"]["median"] for e in rpe["deltas"] if e["rot_deg_per_m"]], style, marker="o",
               label=label)
        drawn = True
    for ax, label in ((a, "median translation error (% of the pair length)"), (b, "median rotation error (deg/m)")):
        ax.set_xlabel("pair length delta (m)")
        ax.set_ylabel(label)
        if drawn:
            if ax is b:  # one legend, outside the data, for both panels
                legend_outside(ax, title="dotted: VO failed (RPE shown anyway)"
                               if any(m["status"] != "success" and m.get("rpe") for m in results["methods"].values())
                               else None, title_fontsize="small")
        else:
            ax.text(0.5, 0.5, "no RPE (no reference or every run failed)", ha="center", va="center",
                    transform=ax.transAxes)
    a.set_title("RPE, translation")
    b.set_title("RPE, rotation")
    return fig


def plot_rpe(results: dict, path: str | Path) -> Path:
    """Paper Fig. 6: median translation (%) and rotation (deg/m) RPE against the pair length."""
    return save(rpe_figure(results), path)


#: Largest ratio of the two axis extents drawn to scale (equal aspect); a thinner path gets
#: its own tight limits on each axis, and the title says "not to scale".
MAX_EQUAL_ASPECT = 4.0
#: Margin around the data, as a fraction of each axis' extent.
MARGIN = 0.05


def _tight(ax, lo, hi, axis: str, other_span: float) -> None:
    span = float(hi - lo)
    pad = MARGIN * span if span > 0 else max(0.5 * MARGIN * other_span, 0.05)
    (ax.set_xlim if axis == "x" else ax.set_ylim)(lo - pad, hi + pad)


def trajectories_figure(trajectories: dict, reference_xyz: np.ndarray | None):
    """The figure of :func:`plot_trajectories`: axis limits from the data (5 % margin), equal
    aspect when the two extents are within :data:`MAX_EQUAL_ASPECT` of each other."""
    fig, (ax,) = new_figure(1, 6.0, 5.0)
    everything = [np.asarray(x).reshape(-1, 3) for x in trajectories.values()]
    if reference_xyz is not None and len(reference_xyz):
        everything.append(np.asarray(reference_xyz).reshape(-1, 3))
    stacked = np.concatenate(everything) if everything else np.zeros((1, 3))
    stacked = stacked[np.all(np.isfinite(stacked), axis=1)] if np.isfinite(stacked).any() else np.zeros((1, 3))
    # Top view.  Without a reference the poses are in the first left camera's axes (OpenCV: x right,
    # y down, z forward): the ground plane is x-z.  Aligned to a reference, in the reference's frame:
    # the two axes along which the trajectories extend most (x-y for a z-up lidar map).
    no_ref = reference_xyz is None or not len(reference_xyz)
    a, b = (0, 2) if no_ref else sorted(np.argsort(np.ptp(stacked, axis=0))[-2:])
    if reference_xyz is not None and len(reference_xyz):
        ax.plot(reference_xyz[:, a], reference_xyz[:, b], "k--", lw=2, label="reference")
    for name, xyz in trajectories.items():
        xyz = np.asarray(xyz)
        ax.plot(xyz[:, a], xyz[:, b], marker=".", label=name)
    ax.set_xlabel(f"{'xyz'[a]} (m)")
    ax.set_ylabel(f"{'xyz'[b]} (m)")
    lo, hi = stacked[:, [a, b]].min(axis=0), stacked[:, [a, b]].max(axis=0)
    span_x, span_y = float(hi[0] - lo[0]), float(hi[1] - lo[1])
    _tight(ax, lo[0], hi[0], "x", span_y)
    _tight(ax, lo[1], hi[1], "y", span_x)
    to_scale = min(span_x, span_y) > 0 and max(span_x, span_y) / min(span_x, span_y) <= MAX_EQUAL_ASPECT
    if to_scale:
        ax.set_aspect("equal", adjustable="box")
    legend_outside(ax)
    plane = f"plane {'xyz'[a]}-{'xyz'[b]}"
    title = (f"VO trajectories (Sim(3)-aligned to the reference), {plane}" if reference_xyz is not None
             else f"VO trajectories, top view ({plane}: first left camera, x right, z forward)")
    ax.set_title(title + ("" if to_scale else "\naxes not to scale"))
    return fig


def plot_trajectories(trajectories: dict, reference_xyz: np.ndarray | None, path: str | Path) -> Path:
    """Top view of VO trajectories, limits from the data: x-z of the first left camera without a reference,
    the two axes of largest extent of the reference's frame with one; the title names the plane.

    Parameters
    ----------
    trajectories : dict of str to numpy.ndarray
        (N, 3) positions per method, metres (aligned to the reference when one exists).
    reference_xyz : numpy.ndarray or None
        (M, 3) reference positions, metres.
    """
    return save(trajectories_figure(trajectories, reference_xyz), path)


def _fmt(value, spec: str = ".1f") -> str:
    return "-" if value is None else format(value, spec)


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


def vo_verdicts(results: dict) -> list[str]:
    """One sentence per result of the VO benchmark (failures, RPE): expected or not beside the paper, and why."""
    methods = results["methods"]
    reasons: dict[str, int] = {}
    for m in methods.values():
        for f in m["failures"]:
            reasons[f["reason"]] = reasons.get(f["reason"], 0) + 1
    n_failed = sum(1 for m in methods.values() if m["status"] != "success")
    trans, rot, deltas, on_failed = {}, {}, [], 0
    for name, m in methods.items():
        rpe = m.get("rpe")
        if not rpe:
            continue
        t = [_trans_percent(e)["median"] for e in rpe["deltas"] if _trans_percent(e)]
        r = [e["rot_deg_per_m"]["median"] for e in rpe["deltas"] if e.get("rot_deg_per_m")]
        deltas += [e["delta_m"] for e in rpe["deltas"] if _trans_percent(e)]
        if t:
            trans[name] = min(t)
            on_failed += m["status"] != "success"
        if r:
            rot[name] = min(r)
    return [vo_failure_verdict(n_failed, len(methods), reasons), rpe_verdict(trans, rot, deltas, on_failed)]


def features_intervals(results: dict) -> dict:
    """Median matches (over consecutive pairs) and median uniformity (over images) per method with 95 %
    circular-block-bootstrap intervals, and each method's difference from the best
    (:func:`emulator.stats.compare_methods`; pairs and images are time series)."""
    from emulator.stats import compare_methods

    methods = list(results["methods"])
    matches = {m: [c for run in results["runs"] for c in run["methods"].get(m, {}).get("matches", [])]
               for m in methods}
    uniformity = {m: [u for run in results["runs"] for u in run["methods"].get(m, {}).get("uniformity", [])]
                  for m in methods}
    return {"median_matches": compare_methods(matches, "median", block=True, seed=0),
            "median_uniformity": compare_methods(uniformity, "median", block=True, seed=1)}


def features_intervals_markdown(results: dict) -> list[str]:
    """The tables of :func:`features_intervals` (nothing when no method has a pair)."""
    from emulator.report.intervals import comparison_table

    from emulator.report.intervals import mark_trending

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


def vo_intervals_markdown(results: dict) -> list[str]:
    """Per pair length, the methods' median translation RPE with 95 % intervals and the difference from the
    best (results ``rpe_intervals``, :func:`emulator.metrics.vo_bench.rpe_intervals`); nothing without them."""
    from emulator.report.intervals import comparison_table

    iv = results.get("rpe_intervals") or []
    if not iv:
        return []
    lines = ["", "Methods compared with 95 % intervals (median translation RPE, % of the pair length; circular "
             "block bootstrap over segments of the run as long as a pair, methods on the same pairs resampled "
             "together; \"cannot tell apart\": the difference's interval holds 0):"]
    for d in iv:
        n_seg = max((r["n_segments"] for r in d["methods"].values()), default=0)
        lines += ["", f"Pair length {d['delta_m']:.2f} m ({n_seg} segments):", ""]
        lines += comparison_table(d, "median translation error (% of the pair length)", spec=".2f")
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
            f"| {name} | {m['n_runs']} | {m['n_images']} | {_fmt(None if u is None else 100 * u)} | "
            f"{_fmt(m['median_matches'], '.0f')} | {_fmt(m['min_matches'], 'd')} | "
            f"{_fmt(None if m['success_at_100'] is None else 100 * m['success_at_100'], '.0f')} |"
        )
    lines += ["", FEATURES_DASH_NOTE, ""]
    lines += features_intervals_markdown(results)
    lines += ["", "Paper (55 trajectories, 1920x1200 images):", ""]
    lines += [f"- {k}: {v}" for k, v in PAPER_FEATURES.items()]
    lines += ["", "## Verdicts", ""] + [f"- {v}" for v in features_verdicts(results)]
    lines += ["", f"Command: `{results.get('command') or '(library call)'}`", ""]
    return "\n".join(lines)


def extrinsics_sentence(ext: dict) -> str:
    """The stereo-extrinsics check of ``results["calibration"]["extrinsics"]`` in words: the
    decision, the measurement and the rule, each a sentence.

    >>> extrinsics_sentence({"mode": "auto", "epipolar_residual_px": 0.14, "refined": False,
    ...                      "reason": "the given calibration fits the images", "criterion": "residual > 1 px"})
    'Stereo extrinsics (auto): the given calibration fits the images. Measured 0.14 px. Refinement rule: residual > 1 px.'
    """
    after = ext.get("estimate", {}).get("epipolar_residual_after_px") if ext.get("refined") else None
    return (f"Stereo extrinsics ({ext['mode']}): {ext['reason']}. Measured {ext['epipolar_residual_px']:.2f} px"
            + (f", {after:.2f} px after refinement" if after is not None else "")
            + f". Refinement rule: {ext['criterion']}.")


def vo_table_markdown(results: dict) -> list[str]:
    """The per-method VO table that needs no reference (stereo points, PnP inliers, row offset, path
    length, frames tracked), ranked as :func:`emulator.metrics.vo_table.vo_ranking` ranks them when the
    run has no reference; empty for results written before the table existed."""
    methods = {n: m["summary"] for n, m in results["methods"].items() if m.get("summary")}
    if not methods:
        return []
    ranking = results.get("ranking_without_reference") or list(methods)
    ranked = results.get("reference") is None
    lines = ["", "## VO by method, without a reference" if ranked else "## VO by method", ""]
    if ranked:
        lines += ["Without a reference trajectory the RPE cannot tell the methods apart; they are ranked here "
                  "on the VO itself: most frames tracked, then most PnP inliers per step (median), then most "
                  "stereo points per frame (median). The path length is the VO's own (not scale-aligned); "
                  "methods on one recording should agree on it, a method far from the others has drifted.", ""]
    lines += ["| " + ("rank | " if ranked else "") + "method | frames tracked | median stereo points per frame | "
              "median PnP inliers per step | median row offset after rectification (px) | VO path length (m) |",
              "| " + ("--- | " if ranked else "") + "--- | --- | --- | --- | --- | --- |"]
    for k, name in enumerate([n for n in ranking if n in methods], 1):
        m = methods[name]
        lines.append("| " + (f"{k} | " if ranked else "") + f"{name} | {m['n_tracked']}/{m['n_frames']} | "
                     f"{_fmt(m['median_stereo_points'], '.0f')} | {_fmt(m['median_inliers'], '.0f')} | "
                     f"{_fmt(m['median_row_offset_px'], '.2f')} | {m['path_length_m']:.3f} |")
    return lines


def vo_report(results: dict, figures: dict[str, str]) -> str:
    """Markdown report of the stereo VO benchmark, beside the paper's Fig. 6 numbers."""
    p = results["parameters"]
    n_failed = sum(1 for m in results["methods"].values() if m["status"] != "success")
    lines = [
        "# Stereo visual odometry (paper section V-D-2, Fig. 6)",
        "",
        f"Run folder: `{results['run_dir']}`; calibration: `{results['calibration']['folder']}` "
        f"(baseline {results['calibration']['baseline_m']:.4f} m, rectified fx "
        f"{results['calibration']['rectified_fx_px']:.1f} px, image scale {p['scale']}); "
        f"reference: `{results['reference'] or 'none'}`.",
        "",
        "Minimal OpenCV stereo VO: rectification, SIFT left-right matches for depth, PnP with RANSAC "
        f"between consecutive left images (inlier threshold {p['vo']['pnp_reprojection_px']} px), poses chained. "
        f"Failure policy: {results['failure_policy']}",
        "",
        f"RPE through evo: estimate scale corrected ({'on' if p['align_scale'] else 'off'}), pairs of "
        f"reference path length delta +/- {100 * p['rel_delta_tol']:.0f} %, translation in % of the pair's "
        "length, rotation in deg/m.",
        "",
        f"VO failed on {n_failed} of {len(results['methods'])} method run(s).",
        "",
    ]
    choice = results["calibration"].get("choice")
    ext = results["calibration"].get("extrinsics")
    if choice:
        when = (" (a synthetic recording, written by exposim synth: it has no recording date)"
                if choice.get("synthetic") else
                f" (recording date {choice['recording_date']})" if choice.get("recording_date") else "")
        lines += [f"Calibration choice: {choice['reason']}{when}.", ""]
    if ext and ext.get("epipolar_residual_px") is not None:
        lines += [extrinsics_sentence(ext), ""]
    if results.get("limitations"):
        lines += ["## What could not be computed, and why", ""] + [f"- {n}" for n in results["limitations"]] + [""]
    lines += [
        "| method | status | frames | tracked | failures | scale | relative pose error, translation: median over "
        "pose pairs (% of the pair length), per pair length (m) | relative pose error, rotation: median over pose "
        "pairs (deg/m), per pair length (m) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for name, m in results["methods"].items():
        rpe = m.get("rpe")
        if rpe:
            trans = ", ".join(
                f"{e['delta_m']:.2f} m: {_fmt(_trans_percent(e) and _trans_percent(e)['median'], '.2f')}"
                for e in rpe["deltas"]
            )
            rot = ", ".join(
                f"{e['delta_m']:.2f} m: {_fmt(e['rot_deg_per_m'] and e['rot_deg_per_m']['median'], '.3f')}"
                for e in rpe["deltas"]
            )
            scale = f"{rpe['scale']:.4f}"
        else:
            trans = rot = m.get("rpe_skipped") or "-"
            scale = "-"
        reasons = sorted({f["reason"] for f in m["failures"]})
        lines.append(
            f"| {name} | {m['status']} | {m['n_frames']} | {m['n_tracked']} | "
            f"{len(m['failures'])}{' (' + ', '.join(reasons) + ')' if reasons else ''} | {scale} | {trans} | {rot} |"
        )
    lines += vo_table_markdown(results)
    lines += vo_intervals_markdown(results)
    rpe_figure_note = (" In the relative pose error figure a dotted line is a method whose VO failed on some frames "
                       "(RPE computed anyway); its legend entry says so.")
    lines += ["", DASH_NOTE + (rpe_figure_note if any("fig6" in f for f in figures.values()) else ""), ""]
    for title, fig in figures.items():
        lines += [f"![{title}]({fig})", ""]
    lines += ["Paper (55 trajectories, lidar reference, 1920x1200 images):", ""]
    lines += [f"- {k}: {v}" for k, v in PAPER_VO.items()]
    lines += ["", "## Verdicts", ""] + [f"- {v}" for v in vo_verdicts(results)]
    lines += ["", f"Command: `{results.get('command') or '(library call)'}`", ""]
    return "\n".join(lines)


def write_vo_report(out: Path, results: dict, aligned_xyz: dict, reference_xyz, sheet, *, with_rpe: bool) -> None:
    """The VO benchmark's figures (``fig6_rpe.png`` only ``with_rpe``, where there is a reference;
    ``trajectories.png``), ``report.md``, ``report.html`` (with ``sheet``) and ``results.json`` in ``out``."""
    from emulator.io.files import RESULTS_FILE, write_results
    from emulator.report.html import write_report

    figures = {"trajectories": "trajectories.png"}
    if with_rpe:
        plot_rpe(results, out / "fig6_rpe.png")
        figures = {"RPE against trajectory length (Fig. 6)": "fig6_rpe.png", **figures}
    plot_trajectories(aligned_xyz, reference_xyz, out / "trajectories.png")
    write_report(out, vo_report(results, figures), figures=list(figures.values()), sheets=[sheet])
    write_results(out / RESULTS_FILE, results)
