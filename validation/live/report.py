"""The experiment's figures and ``report.md``: exposure trajectories, metric bars, the verdict in words."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from validation.live.config import (
    CONTROL,
    GOAL_EXPOSURE_LOG2_MEDIAN,
    GOAL_TAU_MIN,
    METRICS,
    VARIANTS,
)
from validation.live.verdicts import FLIP_CAUSES

__all__ = ["plot_trajectories", "plot_metrics", "report_markdown", "headline", "fmt"]


def plot_trajectories(trajectories: dict, path: Path, title: str = "") -> Path:
    """Exposure against cycle per method: emulated (plain, consistent) and live (variants)."""
    from emulator.report.figures import new_figure, save

    runs = list(trajectories)
    names = list(next(iter(trajectories.values())))
    ncols = 4
    nrows = math.ceil(len(names) / ncols)
    fig, axes = new_figure(ncols, 4.0, 3.0, nrows=nrows)
    styles = {"emulated-plain": ("C0", "-", "o"), "emulated-consistent": ("C1", "--", "s"),
              "live-same-instant": ("k", "-", "."), "live-fixed-instant": ("C2", ":", "x"),
              f"live-{CONTROL}": ("0.6", "-.", "")}
    for ax, name in zip(axes, names):
        for r in runs:
            y = trajectories[r][name]["target_ms"]
            c, ls, mk = styles.get(r, ("C3", "-", ""))
            ax.step(range(len(y)), y, where="post", color=c, ls=ls, marker=mk, ms=3, lw=1.1, label=r)
        for b in (1, 2, 4, 8, 16, 32):
            ax.axhline(b, color="0.9", lw=0.6, zorder=0)
        ax.set_yscale("log")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("cycle")
        ax.set_ylabel("exposure [ms]")
    for ax in axes[len(names):]:
        ax.axis("off")
    axes[0].legend(fontsize=6)
    fig.suptitle(f"Exposure per cycle, live vs emulated: {title}")
    return save(fig, path, dpi=90)


def plot_metrics(results: dict, path: Path) -> Path:
    """Per metric, bars per method: live (variants) and emulated (plain, consistent)."""
    from emulator.report.figures import new_figure, save

    values = results["metric_values"]
    runs = list(values)
    metrics = list(METRICS)
    names = results["config"]["methods"]
    ncols = math.ceil(len(metrics) / 2)
    fig, axes = new_figure(ncols, 16.0 / ncols, 3.5, nrows=2)
    w = 0.8 / len(runs)
    for ax, metric in zip(axes, metrics):
        for i, r in enumerate(runs):
            ys = [values[r][metric].get(m) for m in names]
            ax.bar(np.arange(len(names)) + (i - (len(runs) - 1) / 2) * w, [np.nan if y is None else y for y in ys],
                   w, label=r)
        tau = results["rank_kendall_tau"].get(metric)
        ax.set_title(f"{metric} (tau {'n/a' if tau is None else f'{tau:.2f}'})", fontsize=9)
        ax.set_xticks(range(len(names)))
        ax.set_xticklabels(names, rotation=45, fontsize=7)
    for ax in axes[len(metrics):]:
        ax.axis("off")
    axes[0].legend(fontsize=6)
    return save(fig, path, dpi=90)


def fmt(v, spec=".3g") -> str:
    """A figure for the report: ``n/a`` for None, yes/no for a flag."""
    if v is None:
        return "n/a"
    if isinstance(v, bool):
        return "yes" if v else "no"
    return format(float(v), spec)


def report_markdown(results: dict) -> str:
    """The report: verdict in words, generated from the numbers."""
    cfg = results["config"]
    best = results["headline_noise"]
    goals = results["goals"]
    lines = [
        "# Live versus emulated closed loop",
        "",
        f"{len(cfg['scenes'])} synthetic stereo walks ({', '.join(cfg['scenes'])}), {cfg['n_cycles']} cycles each, "
        f"{cfg['width']}x{cfg['height']} px at {cfg['spp']} spp, {len(cfg['methods'])} AE methods, seed {cfg['seed']}. "
        f"Fixed instant of the fixed-instant variant: {cfg['fixed_instant']}.",
        f"Command: `{results.get('command')}`",
        "",
        "## Verdict",
        "",
    ]
    tau_min = results["rank_kendall_tau_min"]
    tmb = results["rank_kendall_tau_min_by_noise"]
    verdict = []
    if tau_min is not None:
        verdict.append(
            f"The emulated benchmark ranks the methods as the live camera does with Kendall tau >= "
            f"{fmt(tau_min, '.2f')} on every metric (worst timing variant, {best} emulation; plain "
            f"{fmt(tmb.get('plain'), '.2f')}, consistent {fmt(tmb.get('consistent'), '.2f')}). Goal tau_min >= "
            f"{GOAL_TAU_MIN}: {'met' if goals['rank_kendall_tau_min_ge_0.9'] else 'NOT met'}.")
    verdict.append(
        f"Same-instant exposure trajectories differ by a median |log2| of {fmt(results['exposure_log2_error_median'])} "
        f"(max {fmt(results['exposure_log2_error_max'])}); goal <= {GOAL_EXPOSURE_LOG2_MEDIAN}: "
        f"{'met' if goals['exposure_log2_error_median_le_0.05_same_instant'] else 'NOT met'}.")
    detail = results["rank_kendall_tau_detail"]
    if "live/control" in detail:
        ctl = {m: detail["live/control"][m]["tau"] for m in METRICS}
        for v in VARIANTS:
            emu = {m: detail[f"{best}/{v}"][m]["tau"] for m in METRICS}
            ok = [m for m in METRICS if emu[m] is not None and ctl[m] is not None and emu[m] >= ctl[m] - 1e-12]
            below = [f"{m} ({fmt(emu[m], '.3f')} vs {fmt(ctl[m], '.3f')})" for m in METRICS
                     if emu[m] is not None and ctl[m] is not None and emu[m] < ctl[m] - 1e-12]
            verdict.append(
                f"{v.capitalize()}: emulated vs live agrees at least as well as two live runs that differ only in "
                f"capture noise (tau of the control) on {len(ok)} of {len(METRICS)} metrics"
                + (f"; below the control on {', '.join(below)}." if below else "."))
    ctrl = results.get("exposure_live_control")
    if ctrl:
        verdict.append(f"Two live runs that differ only in their capture-noise seeds differ by a median |log2| of "
                       f"{fmt(ctrl['median'])} (max {fmt(ctrl['max'])}): the floor any emulator is measured against.")
    nvr = results["noise_variance_ratio"]
    verdict.append(f"Noise variance emulated / live (darkening pairs, median over intensity bins): plain "
                   f"{fmt(nvr['plain'])}, consistent {fmt(nvr['consistent'])}.")
    use, up = results.get("emulation_ratio_use"), results.get("noise_variance_ratio_brightening")
    if use and up:
        dark = float(np.mean([d["darkening"] for d in use[best].values()]))
        bright = float(np.mean([d["brightening"] for d in use[best].values()]))
        verdict.append(
            f"But the loops darken a bracket (the only case consistent emulation can correct) in "
            f"{fmt(100 * dark, '.0f')} % of the cycles (mean over methods) and brighten one in "
            f"{fmt(100 * bright, '.0f')} %, "
            f"because HigherNoSat's higher bracket is saturated above 1 %; brightened images carry "
            f"{fmt(up['plain'], '.2f')} times the live noise variance, with either option.")
    lines += [" ".join(verdict), ""]
    if results["rank_kendall_tau_detail"]:
        lines += ["## Ranking agreement (Kendall tau-b, live vs emulated)", "",
                  "| metric | " + " | ".join(results["rank_kendall_tau_detail"]) + " |",
                  "| --- | " + " | ".join("---:" for _ in results["rank_kendall_tau_detail"]) + " |"]
        for metric in METRICS:
            cells = []
            for key, d in results["rank_kendall_tau_detail"].items():
                r = d[metric]
                extra = ""
                if r["discordant"]:
                    extra = f" ({len(r['discordant'])} disc."
                    if "discordant_beyond_live_spread" in r and key != "live/control":
                        extra += f", {r['discordant_beyond_live_spread']} beyond spread"
                    extra += ")"
                if r.get("tied_on_one_side_only"):
                    extra += f" [{r['tied_on_one_side_only']} tied one side]"
                cells.append(fmt(r["tau"], ".2f") + extra)
            lines.append(f"| {metric} | " + " | ".join(cells) + " |")
        lines += ["", "`live/control`: two live same-instant runs with different capture-noise seeds.", ""]
        lines += ["## Metric values", "", "| metric | method | " + " | ".join(results["metric_values"]) + " |",
                  "| --- | --- | " + " | ".join("---:" for _ in results["metric_values"]) + " |"]
        for metric in METRICS:
            for m in cfg["methods"]:
                lines.append(f"| {metric} | {m} | " + " | ".join(fmt(results["metric_values"][r][metric][m])
                                                                  for r in results["metric_values"]) + " |")
        lines += ["", "![metric bars](metrics.png)", ""]
    lines += ["## Exposure trajectories", "",
              "| noise / variant | median abs log2 | max | image RMSE % median | valid fraction |",
              "| --- | ---: | ---: | ---: | ---: |"]
    for key, e in results["exposure"].items():
        im = results["images"][key]
        lines.append(f"| {key} | {fmt(e['pooled']['median'])} | {fmt(e['pooled']['max'])} | "
                     f"{fmt(im['pooled']['median'])} | {fmt(im['valid_fraction_mean'])} |")
    lines += ["", "| method | " + " | ".join(f"{k} median" for k in results["exposure"]) + " |",
              "| --- | " + " | ".join("---:" for _ in results["exposure"]) + " |"]
    for m in cfg["methods"]:
        lines.append(f"| {m} | " + " | ".join(fmt(results["exposure"][k]["methods"][m]["median"])
                                             for k in results["exposure"]) + " |")
    lines += [""] + [f"![{s}](exposure_{s}.png)" for s in cfg["scenes"]] + [""]
    if results["findings_flips"]:
        lines += ["## Paper findings that flip (live vs emulated)", ""]
        for key, fl in results["findings_flips"].items():
            txt = "; ".join(f"{f['id']} (live {fmt(f['live'])}, emulated {fmt(f['emulated'])})" for f in fl) or "none"
            lines.append(f"- {key}: {txt}")
        lines.append("")
    if results["flip_causes"]:
        sp = results.get("live_spread") or {}
        lines += ["## Why rankings flip", "",
                  "Each pair of methods ordered oppositely live and emulated, attributed to the first cause that "
                  "applies (`flip_causes` in validation/live/verdicts.py): within the live spread (both differences "
                  "at most the largest |live - live re-seeded| of the metric over the methods: "
                  + ", ".join(f"{m} {fmt(v)}" for m, v in sp.items()) + "), motion (fixed-instant only), noise level "
                  "(plain only), exposure divergence (median |log2| > 0.05), else image difference at equal exposures.",
                  "", "| noise / variant | " + " | ".join(FLIP_CAUSES) + " |",
                  "| --- | " + " | ".join("---:" for _ in FLIP_CAUSES) + " |"]
        for key, counts in results["flip_cause_counts"].items():
            lines.append(f"| {key} | " + " | ".join(str(counts[c]) for c in FLIP_CAUSES) + " |")
        beyond = [r for r in results["flip_causes"] if r["noise"] == best and r["cause"] != FLIP_CAUSES[0]]
        lines += ["", f"Flips beyond the live spread ({best} emulation):", ""]
        if beyond:
            lines += ["| variant | metric | pair | cause | live | emulated | live spread | exposure log2 err median |",
                      "| --- | --- | --- | --- | --- | --- | ---: | --- |"]
            for r in beyond[:60]:
                a, b = r["pair"]
                lines.append(
                    f"| {r['variant']} | {r['metric']} | {a} vs {b} | {r['cause']} | {fmt(r['live'][a])} vs "
                    f"{fmt(r['live'][b])} | {fmt(r['emulated'][a])} vs {fmt(r['emulated'][b])} | "
                    f"{fmt(r['live_spread'])} | "
                    f"{fmt(r['exposure_log2_error_median'][a])}, {fmt(r['exposure_log2_error_median'][b])} |")
            if len(beyond) > 60:
                lines.append(f"| ... {len(beyond) - 60} more in results.json | | | | | | | |")
        else:
            lines.append("none.")
        lines.append("")
    nd = results["noise_variance_ratio_detail"]
    lines += ["## Noise variance ratio (measured)", "",
              f"{nd['repeats']} captures per exposure of one rendered frame, pairs (source ms, target ms) "
              f"{nd['pairs_ms']}; per intensity bin emulated / live variance. Plain {fmt(nd['plain'])} (theory "
              f"{fmt(nd['theory_plain'])}), consistent {fmt(nd['consistent'])} (largest deviation from 1 in a bin: "
              f"{fmt(nd['consistent_max_abs_deviation'])}).", ""]
    up = results.get("noise_variance_ratio_brightening_detail")
    if up:
        lines += [f"Brightening pairs {up['pairs_ms']} (the source is the noisier one; {up['input']}): plain "
                  f"{fmt(up['plain'])}, consistent {fmt(up['consistent'])} (theory {fmt(up['theory_plain'])}): the "
                  "excess noise that no emulation can remove.", ""]
    use = results.get("emulation_ratio_use")
    if use:
        lines += ["How often the emulated loop darkened (k < 1, where consistent emulation adds noise), copied "
                  "(k = 1) or brightened (k > 1, excess noise) its bracket:", "",
                  "| method | darkening | identity | brightening |", "| --- | ---: | ---: | ---: |"]
        for m, d in use[best].items():
            lines.append(f"| {m} | {fmt(d['darkening'], '.2f')} | {fmt(d['identity'], '.2f')} | "
                         f"{fmt(d['brightening'], '.2f')} |")
        lines.append("")
    t = results.get("timings", {})
    lines += [f"Total time {fmt(t.get('total_s', 0) / 60, '.1f')} min."]
    return "\n".join(lines) + "\n"


def headline(results: dict) -> str:
    """One line of the headline figures and goals (what the command prints)."""
    g = results["goals"]
    return (f"rank_kendall_tau_min {fmt(results['rank_kendall_tau_min'], '.3f')} ({results['headline_noise']}; goal "
          f">= {GOAL_TAU_MIN}: {fmt(g['rank_kendall_tau_min_ge_0.9'])}), exposure_log2_error_median "
          f"{fmt(results['exposure_log2_error_median'], '.4f')} (goal <= {GOAL_EXPOSURE_LOG2_MEDIAN}: "
          f"{fmt(g['exposure_log2_error_median_le_0.05_same_instant'])}), noise_variance_ratio plain "
          f"{fmt(results['noise_variance_ratio']['plain'], '.3f')} consistent "
          f"{fmt(results['noise_variance_ratio']['consistent'], '.3f')}")
