"""``report.md`` and the summary figure of the AE study (markdown and matplotlib only)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from emulator.cells import format_number
from emulator.io.files import save_figure
from emulator.metrics.features import GRID_CELLS
from emulator.report.verdicts import (
    dash_note,
    matches_verdict,
    rpe_verdict,
    success_verdict,
    uniformity_verdict,
    vo_failure_verdict,
)
from validation.ae_study.config import PAPER, PAPER_NAMES, VO_CONFIGURATION_NOTE

__all__ = ["report_markdown", "plot_summary", "study_verdicts", "WALK_COMPARISONS", "method_intervals",
           "method_intervals_markdown"]

#: Per-walk figures compared across methods over walks: name -> (key path in a per-scene entry, label,
#: higher is better, display scale).
WALK_COMPARISONS = {
    "median_uniformity": (("median_uniformity",), "median uniformity (%)", True, 100.0),
    "median_matches": (("median_matches",), "median matches", True, 1.0),
    "vo_failed_frames": (("vo", "n_failed_frames"), "VO failed frames", False, 1.0),
    "rpe_trans_pct": (("vo", "rpe_trans_pct"), "RPE trans. (%, minimal median)", False, 1.0),
}


def _paper_cell(key: str, method: str, spec: str = "") -> str:
    v = PAPER.get(key, {}).get(method) if isinstance(PAPER.get(key), dict) else None
    return "" if v is None else f" ({v}{spec})"


def method_intervals(per_scene: dict, seed: int = 0) -> dict:
    """Per figure of :data:`WALK_COMPARISONS`: each method's mean over the walks (``per_scene``: walk -> method
    -> entry of :func:`~validation.ae_study.summary.summarise`) with a 95 % bootstrap interval over walks,
    and its difference from the best with a paired bootstrap over walks (:func:`emulator.core.stats.compare_methods`)."""
    from emulator.core.stats import compare_methods

    methods = [m for rows in per_scene.values() for m in rows]
    methods = list(dict.fromkeys(methods))
    out = {}
    for k, (name, (path, _, higher, _)) in enumerate(WALK_COMPARISONS.items()):
        series = {}
        for m in methods:
            vals = []
            for rows in per_scene.values():
                v = rows.get(m)
                for key in path:
                    v = v.get(key) if isinstance(v, dict) else None
                vals.append(np.nan if v is None else float(v))
            series[m] = vals
        out[name] = compare_methods(series, "mean", higher_is_better=higher, seed=[seed, k])
    return out


def method_intervals_markdown(per_scene: dict, seed: int = 0) -> list[str]:
    """The tables of :func:`method_intervals` (the unit is the walk)."""
    from emulator.report.intervals import comparison_table

    iv = method_intervals(per_scene, seed)
    lines = [f"Methods compared over the {len(per_scene)} walk(s) with 95 % intervals (mean over walks, bootstrap "
             "over walks, differences paired by walk; \"cannot tell apart\": the difference's interval holds 0; "
             "one walk gives no interval):"]
    for name, (_, label, _, scale) in WALK_COMPARISONS.items():
        if iv[name]["best"] is not None:
            lines += [""] + comparison_table(iv[name], label, spec=".3g", scale=scale)
    return lines


def _config_lines(results: dict) -> list[str]:
    """The report's title and the study's configuration, in words."""
    cfg = results["config"]
    return [
        "# Synthetic AE study: the paper's section V-D on synthetic stereo walks",
        "",
        f"Scenes {', '.join(cfg['scenes'])}; {cfg['n_cycles']} bracket cycles each (1..32 ms, 22 frames/s, "
        f"{cfg['n_cycles'] * 6 / 22:.1f} s of walk at 2 km/h), {cfg['width']}x{cfg['height']} px, {cfg['spp']} spp, "
        f"stereo, synthetic BorealHDR camera with noise; seeds: scene {cfg['scene_seed']}, camera {cfg['camera_seed']}, "
        f"render {cfg['render_seed']}; VO ratio test {cfg['vo_ratio']} (features: the paper's 0.8). "
        f"{cfg['renders']} renders; wall time {results['timings'].get('total_s', 0) / 60:.1f} min.",
        "",
        "Paper numbers (55 real BorealHDR trajectories, full resolution) are in parentheses where the paper gives "
        "one for that method. RPE: the paper's *minimal* error, i.e. the smallest median over the pair lengths "
        "(here 10..50 % of the path, so metres, not the paper's tens of metres); a dagger marks an RPE computed on "
        "a run whose VO failed on some frames (the paper leaves those out). Success on one sequence is yes/no; "
        f"the segment rate cuts each run into segments of {cfg['segment_pairs']} consecutive pairs.",
        "",
    ]


def _scene_section(scene: str, rows: dict, lo: str, hi: str, results: dict) -> list[str]:
    """One scene's table (a row per method), its VO failure reasons and missing RPE, and its figures."""
    head = ("| method | median exposure (ms) | median uniformity (%) | median matches | "
            f"success tau={lo} | success tau={hi} | segments ok tau={lo} | segments ok tau={hi} | "
            "VO failed frames | RPE trans. (% of delta; minimal median @ its pair length delta) | "
            "RPE rot. (deg/m; minimal median @ its pair length delta) |")
    sep = "|" + " --- |" * 11
    lines = [f"## {scene}", "", head, sep]
    for name, e in rows.items():
        v = e["vo"] or {}
        dagger = " †" if v.get("rpe_on_failed_run") else ""
        seg = e["segment_success"]
        lines.append(
            f"| {PAPER_NAMES.get(name, name)} | {format_number(e['median_exposure_ms'])} | "
            f"{format_number(None if e['median_uniformity'] is None else 100 * e['median_uniformity'], '.1f')}"
            f"{_paper_cell('median_uniformity_pct', name)} | {format_number(e['median_matches'], '.0f')}"
            f"{_paper_cell('median_matches', name)} | {format_number(e['sequence_success'][lo])} | "
            f"{format_number(e['sequence_success'][hi])} | {seg[lo]['succeeded']}/{seg[lo]['segments']} | "
            f"{seg[hi]['succeeded']}/{seg[hi]['segments']} | "
            f"{v.get('n_failed_frames', 'n/a')} of {max(0, v.get('n_frames', 1) - 1)} | "
            f"{_at(v.get('rpe_trans_pct'), v.get('rpe_trans_delta_m'), '.2f')}{dagger} | "
            f"{_at(v.get('rpe_rot_deg_per_m'), v.get('rpe_rot_delta_m'), '.3f')}{dagger} |")
    vos = [e["vo"] for e in rows.values() if e["vo"] is not None]
    reasons = Counter()
    for v in vos:
        reasons.update(v["failure_reasons"])
    stereo = [v["median_stereo_points"] for v in vos if v["median_stereo_points"] is not None]
    missing = sorted({v["rpe_missing_reason"] for v in vos if v.get("rpe_missing_reason")})
    lines += ["", dash_note("n/a") + " † = RPE of a run whose VO failed on some frames.", ""]
    if reasons:
        lines.append("VO failures by reason, all methods: " + ", ".join(f"{k} {n}" for k, n in reasons.most_common())
                     + (f"; median stereo points per frame {format_number(min(stereo), '.0f')}..{format_number(max(stereo), '.0f')} "
                        f"(tracking needs {results.get('vo_parameters', {}).get('min_stereo_points', 20)})"
                        if stereo else "") + ".")
    for reason in missing:
        lines.append(f"RPE n/a: {reason}.")
    lines += ["", f"![exposure per cycle](runs/{scene}/exposure.png) ![VO RPE](vo/{scene}/fig6_rpe.png) "
                  f"![trajectories](vo/{scene}/trajectories.png)", ""]
    return lines


def _pooled_section(summary: dict, lo: str, hi: str) -> list[str]:
    """The table pooled over the scenes (a row per method)."""
    deltas = [v[k] for rows in summary["per_scene"].values() for e in rows.values() if (v := e["vo"])
             for k in ("rpe_trans_delta_m", "rpe_rot_delta_m") if v.get(k) is not None]
    delta_range = (f"{min(deltas):.2g}..{max(deltas):.2g} m" if deltas and min(deltas) != max(deltas)
                   else f"{deltas[0]:.2g} m" if deltas else "n/a")
    lines = ["## All scenes together", "",
             f"| method | median uniformity (%) | median matches | success rate tau={lo} (sequences) | "
             f"success rate tau={hi} (sequences) | success rate tau={lo} (segments) | success rate tau={hi} "
             f"(segments) | VO failed runs | VO failed frames | RPE trans. (% of delta), mean over scenes of the "
             f"minimal medians (delta {delta_range}) | RPE rot. (deg/m), mean over scenes of the minimal medians "
             f"(delta {delta_range}) |", "|" + " --- |" * 11]
    for name, o in summary["overall"].items():
        sr, sg = o["sequence_success_rate"], o["segment_success"]
        lines.append(
            f"| {PAPER_NAMES.get(name, name)} | "
            f"{format_number(None if o['median_uniformity'] is None else 100 * o['median_uniformity'], '.1f')}"
            f"{_paper_cell('median_uniformity_pct', name)} | {format_number(o['median_matches'], '.0f')}"
            f"{_paper_cell('median_matches', name)} | {format_number(None if sr[lo] is None else 100 * sr[lo], '.0f')} | "
            f"{format_number(None if sr[hi] is None else 100 * sr[hi], '.0f')}{_paper_cell('success_rate_tau100_pct', name)} | "
            f"{format_number(None if sg[lo]['rate'] is None else 100 * sg[lo]['rate'], '.0f')} | "
            f"{format_number(None if sg[hi]['rate'] is None else 100 * sg[hi]['rate'], '.0f')} | "
            f"{o['vo_failed_runs']} of {o['n_sequences']} | {o['vo_failed_frames']} | "
            f"{format_number(o['rpe_trans_pct_mean_over_scenes'], '.2f')}{_paper_cell('rpe_trans_pct', name)} | "
            f"{format_number(o['rpe_rot_deg_per_m_mean_over_scenes'], '.3f')}{_paper_cell('rpe_rot_deg_per_m', name)} |")
    lines += ["", dash_note("n/a") + " These are point figures pooled over the scenes; the intervals follow.", ""]
    return lines


def _findings_section(results: dict) -> list[str]:
    """The findings' paragraph, their table (verdict, effect, interval, adjusted p, point comparison) and how
    they were tested."""
    lines = ["",
             "## Which of the paper's qualitative findings hold", "", results["findings_paragraph"], "",
             "| finding | paper | verdict | effect (95 % interval) | adjusted p | point comparison | measured |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for f in results["findings"]:
        ci = f.get("ci95") or [None, None]
        lines.append(f"| {f['claim']} | {f['paper']} | {f.get('verdict', 'n/a')} | {format_number(f.get('effect'))} "
                     f"({format_number(ci[0])}..{format_number(ci[1])}) | {format_number(f.get('p_adjusted'), '.2g')} | "
                     f"{format_number(f['holds']) if f['holds'] is not None else 'undecided'} | {f['detail']} |")
    lines += ["", "Verdict: each claim tested as the paper states it (a \"best\" or \"poorest\" method against each "
              "other method: every one-sided paired comparison over walks must reject); family: Holm across the "
              "tested claims for holds, and across their opposites for contradicted; undetermined with fewer than 10 "
              "walks; by-construction findings cannot fail and are not counted. The effect is signed, positive = the "
              "paper's claim (see `effect_definition` in results.json). The point comparison is the single-number "
              "test, without evidence."]
    return lines


def _appendix_lines(results: dict) -> list[str]:
    """The figures, why the study's size and VO ratio, and the command."""
    return ["", "## Figures", "", "![summary](ae_study_summary.png)", "",
           "![features (Fig. 4)](features/fig4_features.png)", "",
           "## Why this size and VO ratio", "", f"- symptom: {VO_CONFIGURATION_NOTE['symptom']}",
           f"- cause: {VO_CONFIGURATION_NOTE['cause']}",
           "- fraction of failed VO steps (forest_winter, 12 cycles, 7 methods), ratio 0.8 then 0.9: "
           + "; ".join(f"{k}: {v[0]:.2f}, {v[1]:.2f}" for k, v in VO_CONFIGURATION_NOTE['failed_steps_ratio_0.8_then_0.9'].items()),
           f"- forest_edge: {VO_CONFIGURATION_NOTE['forest_edge']}",
           "- on the study's own runs (256x160, 8 spp, 100 cycles, 7 methods), failed VO frames with ratio 0.8 then "
           "0.9: " + "; ".join(f"{k}: {v[0]}, {v[1]}" for k, v in
                              VO_CONFIGURATION_NOTE["study_100_cycles_failed_frames_ratio_0.8_then_0.9"].items()),
           "", f"Command: `{results.get('command') or ''}`", ""]


def report_markdown(results: dict) -> str:
    """``report.md``: configuration, a table per scene, pooled table, findings, figures."""
    cfg = results["config"]
    taus = [str(t) for t in cfg["taus"]]
    lo, hi = taus[0], taus[-1]
    summary = results["summary"]
    lines = _config_lines(results)
    for scene, rows in summary["per_scene"].items():
        lines += _scene_section(scene, rows, lo, hi, results)
    lines += _pooled_section(summary, lo, hi)
    lines += method_intervals_markdown(summary["per_scene"])
    lines += ["", f"Paper: VO failed on {PAPER['vo_failed_runs']}.", "",
              _tau_note(summary, int(hi)), "", "## Verdicts beside the paper's numbers", ""]
    lines += [f"- {v}" for v in study_verdicts(results)]
    lines += _findings_section(results)
    lines += _appendix_lines(results)
    return "\n".join(lines)


def _at(value, delta_m, spec: str) -> str:
    """``value @ delta m`` (the pair length the minimal median was found at), or n/a."""
    if value is None:
        return "n/a"
    return f"{format_number(value, spec)} @ {delta_m:.2g} m" if delta_m is not None else format_number(value, spec)


def study_verdicts(results: dict) -> list[str]:
    """One sentence per result beside the paper's numbers (uniformity, matches, success at the largest tau,
    VO failures, RPE), from the pooled figures and the image size (:mod:`emulator.report.verdicts`)."""
    cfg, summary = results["config"], results["summary"]
    overall = summary["overall"]
    wh = (cfg["width"], cfg["height"])
    hi = str(max(int(t) for t in cfg["taus"]))
    uni = {k: None if o["median_uniformity"] is None else 100 * o["median_uniformity"] for k, o in overall.items()}
    keypoints = [o.get("median_keypoints") for o in overall.values() if o.get("median_keypoints") is not None]
    med = {k: o["median_matches"] for k, o in overall.items() if o["median_matches"] is not None}
    name = "fixed" if "fixed" in med else (max(med, key=med.get) if med else "fixed")
    maxima = [o["max_matches"] for o in overall.values() if o.get("max_matches") is not None]
    minima = [o["min_matches"] for o in overall.values() if o.get("min_matches") is not None]
    rates = {k: None if o["sequence_success_rate"].get(hi) is None else 100 * o["sequence_success_rate"][hi]
             for k, o in overall.items()}
    vos = [e["vo"] for rows in summary["per_scene"].values() for e in rows.values() if e["vo"] is not None]
    reasons: Counter = Counter()
    for v in vos:
        reasons.update(v["failure_reasons"])
    trans = {k: o["rpe_trans_pct_mean_over_scenes"] for k, o in overall.items()}
    rot = {k: o["rpe_rot_deg_per_m_mean_over_scenes"] for k, o in overall.items()}
    deltas = [v["rpe_trans_delta_m"] for v in vos if v.get("rpe_trans_delta_m") is not None]
    return [
        uniformity_verdict(uni, float(np.median(keypoints)) if keypoints else None, GRID_CELLS),
        matches_verdict(med.get(name), wh, PAPER_NAMES.get(name, name)),
        success_verdict(int(hi), rates, max(maxima) if maxima else None, min(minima) if minima else None, wh),
        vo_failure_verdict(sum(1 for v in vos if v["status"] != "success"), len(vos), reasons),
        rpe_verdict(trans, rot, deltas, sum(1 for v in vos if v.get("rpe_on_failed_run"))),
    ]


def _tau_note(summary: dict, tau: int) -> str:
    """Where ``tau`` sits among the methods' match quartiles (the paper chose 100 below all first quartiles)."""
    q = {k: o.get("quartiles_matches") for k, o in summary["overall"].items() if o.get("quartiles_matches")}
    if not q:
        return ""
    q1 = {k: v[0] for k, v in q.items()}
    med = {k: o["median_matches"] for k, o in summary["overall"].items() if o.get("median_matches") is not None}
    above_q1 = [PAPER_NAMES.get(k, k) for k, v in q1.items() if tau > v]
    above_med = [PAPER_NAMES.get(k, k) for k, v in med.items() if tau > v]
    text = (f"The paper set tau = 100 \"largely under any first quartile\" of its match counts (median 674 for "
            f"M_fixed at 1920x1200). Here the first quartiles of the matches are {format_number(min(q1.values()), '.0f')}.."
            f"{format_number(max(q1.values()), '.0f')} and the medians {format_number(min(med.values()), '.0f')}.."
            f"{format_number(max(med.values()), '.0f')}: tau = {tau} is ")
    if not above_q1:
        return text + "under every first quartile, as in the paper."
    return text + (f"above the first quartile of {len(above_q1)} of {len(q1)} methods"
                   + (f" and above the median of {', '.join(above_med)}" if above_med else "")
                   + ", so it is a much stricter threshold than the paper's, relative to the match counts of these "
                   "small images.")


def plot_summary(results: dict, path: Path) -> Path:
    """One figure: per method and scene, exposure, uniformity, matches, segment success, VO failures, RPE."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    summary = results["summary"]
    scenes = list(summary["per_scene"])
    methods = list(summary["overall"])
    hi = str(results["config"]["taus"][-1])
    panels = [
        ("median exposure (ms)", lambda e: e["median_exposure_ms"], True),
        ("median uniformity (%)", lambda e: None if e["median_uniformity"] is None else 100 * e["median_uniformity"], False),
        ("median matches", lambda e: e["median_matches"], False),
        (f"segments succeeding at tau={hi} (%)",
         lambda e: None if e["segment_success"][hi]["rate"] is None else 100 * e["segment_success"][hi]["rate"], False),
        ("VO failed frames", lambda e: None if e["vo"] is None else e["vo"]["n_failed_frames"], False),
        ("minimal median RPE, translation (%)", lambda e: None if e["vo"] is None else e["vo"]["rpe_trans_pct"], False),
    ]
    fig = Figure(figsize=(16, 8), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 3).ravel()
    width = 0.8 / max(1, len(scenes))
    x = np.arange(len(methods))
    for ax, (title, get, logy) in zip(axes, panels):
        for i, scene in enumerate(scenes):
            rows = summary["per_scene"][scene]
            vals = [get(rows[m]) if m in rows else None for m in methods]
            ax.bar(x + (i - (len(scenes) - 1) / 2) * width, [np.nan if v is None else v for v in vals], width,
                   label=scene)
        ax.set_xticks(x, [PAPER_NAMES.get(m, m) for m in methods], rotation=30)
        ax.set_title(title)
        if logy:
            ax.set_yscale("log")
        ax.grid(True, axis="y", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Synthetic AE study: {results['config']['n_cycles']} cycles, "
                 f"{results['config']['width']}x{results['config']['height']} px, {results['config']['spp']} spp")
    save_figure(fig, path, dpi=100)
    return path
