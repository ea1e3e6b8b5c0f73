"""Figures and markdown report of the VO benchmark (:func:`emulator.metrics.vo_bench.bench_vo`): RPE
against pair length (Fig. 6), the trajectories from above, the VO table, verdicts and intervals.

Split out of :mod:`emulator.report.bench`, which re-exports every name here.  Matplotlib is imported
lazily (:func:`emulator.report.figures.new_figure`); every figure is drawn from ``results.json``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from emulator.io.files import RESULTS_FILE, write_results
from emulator.report.figures import legend_outside, new_figure, plural, save
from emulator.report.html import write_report
from emulator.report.intervals import comparison_table
from emulator.report.verdicts import DASH_NOTE, dash_cell, rpe_verdict, vo_failure_verdict

__all__ = [
    "PAPER_VO",
    "FAILED_STYLE",
    "MAX_EQUAL_ASPECT",
    "rpe_figure",
    "plot_rpe",
    "trajectories_figure",
    "plot_trajectories",
    "vo_verdicts",
    "vo_intervals_markdown",
    "extrinsics_sentence",
    "vo_table_markdown",
    "vo_report",
    "write_vo_report",
]

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


def vo_intervals_markdown(results: dict) -> list[str]:
    """Per pair length, the methods' median translation RPE with 95 % intervals and the difference from the
    best (results ``rpe_intervals``, :func:`emulator.metrics.vo_bench.rpe_intervals`); nothing without them."""
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
                     f"{dash_cell(m['median_stereo_points'], '.0f')} | {dash_cell(m['median_inliers'], '.0f')} | "
                     f"{dash_cell(m['median_row_offset_px'], '.2f')} | {m['path_length_m']:.3f} |")
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
                f"{e['delta_m']:.2f} m: {dash_cell(_trans_percent(e) and _trans_percent(e)['median'], '.2f')}"
                for e in rpe["deltas"]
            )
            rot = ", ".join(
                f"{e['delta_m']:.2f} m: {dash_cell(e['rot_deg_per_m'] and e['rot_deg_per_m']['median'], '.3f')}"
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
    figures = {"trajectories": "trajectories.png"}
    if with_rpe:
        plot_rpe(results, out / "fig6_rpe.png")
        figures = {"RPE against trajectory length (Fig. 6)": "fig6_rpe.png", **figures}
    plot_trajectories(aligned_xyz, reference_xyz, out / "trajectories.png")
    write_report(out, vo_report(results, figures), figures=list(figures.values()), sheets=[sheet])
    write_results(out / RESULTS_FILE, results)
