"""The replicated verdicts in ``report.md``: one section per part of the evidence (the verdicts per metric, every
comparison, the emulation bias, the three conditions, what the study's size can decide, the calibration), and
the cell formats the live study's reports share (:func:`fmt`, :func:`ci_text`)."""

from __future__ import annotations

from emulator.cells import format_number
from validation.live.final_checks import checks_markdown
from validation.live.headline import headlines_markdown
from validation.verdicts.agreement import OMEGA2_MAX
from validation.verdicts.plasmode import calibration_markdown

__all__ = ["fmt", "ci_text", "family_short", "evidence_markdown"]


#: A figure for the report: ``n/a`` for None, yes/no for a flag (the house rule, one copy).
fmt = format_number


def ci_text(iv, spec=".3g") -> str:
    """An interval ``[lo, hi]`` for the report: ``n/a`` without ends, ``inf`` for an unbounded upper end."""
    if not iv or iv[0] is None and iv[1] is None:
        return "n/a"
    lo, hi = iv
    return f"[{fmt(lo, spec)}, {'inf' if hi is None else fmt(hi, spec)}]"


def family_short(text) -> str:
    """A verdict's family in a table cell: the headline family with its size, or the verdict's own."""
    if not text:
        return "n/a"
    if text.startswith("headline:"):
        return f"headline, Holm over {text.split()[1]}"
    return "own, not corrected"


def _look_lines(results: dict) -> list[str]:
    """A pre-registered study's look (final, stopped, or interim: futility only), or nothing."""
    pre = results.get("preregistration")
    if not pre:
        return []
    stop = pre.get("stop")
    return [f"Pre-registered ({pre['file']}, {pre['n_walks_planned']} walks planned); this look: {pre['look']}"
            + ("" if not pre.get("reason") else f" ({pre['reason']})")
            + ("" if not stop else f"; stopped {stop['stopped']} ({stop['file']}): {stop['reason']}") + ".", ""]


def _verdicts_intro(results: dict) -> list[str]:
    """The headline, then the heading and the rule of the verdicts per metric."""
    return [headlines_markdown(results).rstrip("\n"), "", *_look_lines(results),
            f"## Verdicts per metric, emulated vs {results.get('reference_condition')} (omega2, bootstrap over "
            "walks, the seeds as clusters)", "",
            f"{results.get('n_walks', 0)} independent walks ({', '.join(results.get('walks', []))}). Emulated "
            f"(plain, the benchmark's default, declared before the data) against {results.get('reference_condition')}."
            " omega2 = var over the methods of (emulated - live method effects) / var of the live method effects; "
            f"agrees: its one-sided 95 % upper bound at or below {OMEGA2_MAX}; disagrees: its one-sided 95 % lower "
            "bound above it; undetermined otherwise, or when live does not separate the methods (a tie is not "
            "agreement), or with fewer than 10 walks. The headline's verdicts are one family (Holm, in the family "
            "column; 'alone' is the verdict at its own level); the other comparisons' verdicts are each their own "
            "family, not corrected. The pairwise check: every pair of methods that live separates has its "
            "difference of differences (emulated - live) within the metric's margin (90 % interval; TOST). The "
            f"margin in ranking terms: at omega2 = {OMEGA2_MAX} on this study's live spacings, the expected Kendall "
            "tau between the live and the emulated ranking and the probability that the best method changes. "
            "The inference holds for the scenes of this study.", ""]


def _metrics_table(metrics: dict) -> list[str]:
    """Per metric the verdict, omega2 and its bounds, the pairwise check and what is reported beside them."""
    lines = ["| metric | verdict | omega2 | one-sided 95 % bounds | family | pairwise check, its own family: the pairs "
             "live separates (widest pair bound vs margin) | "
             "margin: expected tau, P(best changes) | disattenuated r | tau live-emulated | tau live-live | "
             "pairs differing live / equivalent / reversed | reason |",
             "| --- | --- | ---: | --- | --- | --- | --- | ---: | ---: | ---: | --- | --- |"]
    for m, r in metrics.items():
        pv, mr = r.get("pairs_verdict") or {}, r.get("margin_in_ranking_terms") or {}
        alone = (f" ({r['verdict_alone']} alone)" if r.get("verdict_alone") not in (None, r["verdict"]) else "")
        lines.append(f"| {m} | **{r['verdict']}**{alone} | {fmt(r['omega2'])} | {ci_text(r['omega2_ci90'])} | "
                     f"{family_short(r.get('family'))} | "
                     f"{pv.get('verdict', 'n/a')} ({fmt(pv.get('bound'))} vs {fmt(pv.get('margin'))}) | "
                     f"{fmt(mr.get('expected_kendall_tau'), '.2f')}, "
                     f"{fmt(mr.get('best_method_changes_probability'), '.2f')} | "
                     f"{fmt(r.get('disattenuated_correlation'), '.2f')} | {fmt(r['tau_live_emulated'], '.2f')} | "
                     f"{fmt(r['tau_live_live'], '.2f')} | {r.get('pairs_live_significant', 'n/a')} / "
                     f"{r['pairs_equivalent'] if r.get('pairs_equivalent') is not None else 'n/a'} / "
                     f"{r.get('pairs_reversed', 'n/a')} (margin {fmt(r.get('margin'))}) | {r['reason']} |")
    return lines


def _comparisons_table(results: dict, metrics: dict) -> list[str]:
    """Every comparison's verdict per metric (omega2, its bounds, its family)."""
    lines = ["", "### Every comparison (verdict, omega2, one-sided 95 % bounds, family)", "",
             "| comparison | " + " | ".join(metrics) + " |", "| --- | " + " | ".join("---" for _ in metrics) + " |"]
    for label, c in (results.get("comparisons") or {}).items():
        if c["status"] != "run":
            lines.append(f"| {label} | " + " | ".join("not run" for _ in metrics) + " |")
            continue
        lines.append(f"| {label} | " + " | ".join(
            f"{c['metrics'][m]['verdict']} {fmt(c['metrics'][m]['omega2'], '.2f')} "
            f"{ci_text(c['metrics'][m]['omega2_ci90'], '.2f')}, {family_short(c['metrics'][m].get('family'))}"
            if m in c["metrics"] else "n/a" for m in metrics) + " |")
    return lines


def _bias_table(metrics: dict) -> list[str]:
    """Each method's emulation bias per metric with its interval and share of the residual (none without)."""
    bias = {m: r["emulation_bias"] for m, r in metrics.items() if r.get("emulation_bias")}
    if not bias:
        return []
    meths = list(next(iter(bias.values())))
    lines = ["", "### Emulation bias per method (walk mean of emulated - live, 95 % interval; share of the "
             "interaction's residual variance)", "", "| metric | " + " | ".join(meths) + " |",
             "| --- | " + " | ".join("---" for _ in meths) + " |"]
    for m, b in bias.items():
        lines.append(f"| {m} | " + " | ".join(
            f"{fmt(b[k]['mean'])} {ci_text(b[k]['ci95'])}, {fmt(100 * b[k]['residual_variance_share'], '.0f')} %"
            if b[k].get("residual_variance_share") is not None else f"{fmt(b[k]['mean'])} {ci_text(b[k]['ci95'])}"
            for k in meths) + " |")
    return lines


def _conditions_table(results: dict, metrics: dict) -> list[str]:
    """The three conditions side by side: per metric and method the walk mean with its interval."""
    conds = results.get("conditions") or {}
    ran = {k: c for k, c in conds.items() if c["status"] == "run"}
    lines = ["", "### Three conditions side by side (walk mean, 95 % cluster-bootstrap interval)", ""]
    for k, c in conds.items():
        if c["status"] != "run":
            lines.append(f"- {k} (`{c['run']}`): not run, {c['reason']}.")
    if ran:
        methods = list(next(iter(next(iter(ran.values()))["metrics"].values())))
        lines += ["", "| metric | method | " + " | ".join(ran) + " |", "| --- | --- | " + " | ".join("---" for _ in ran)
                  + " |"]
        for m in metrics:
            for meth in methods:
                cells = [f"{fmt(c['metrics'][m][meth]['mean'])} {ci_text(c['metrics'][m][meth]['ci95'])}"
                         if m in c["metrics"] else "n/a" for c in ran.values()]
                lines.append(f"| {m} | {meth} | " + " | ".join(cells) + " |")
    return lines


def _power_table(power: dict) -> list[str]:
    """What the study's size can decide per metric (none without a power analysis)."""
    if not power:
        return []
    lines = ["", "### What this size can decide (simulated studies with the measured variance components)", "",
             "| metric | noise / method SD | smallest detectable omega2 (80 %) | walks for agrees (80 %) | "
             "perfect emulator agrees | random emulator disagrees |", "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for m, p in power.items():
        if p["status"] != "computed":
            lines.append(f"| {m} | {p['reason']} | | | | |")
            continue
        lines.append(f"| {m} | {fmt(p['noise_to_method_sd'], '.2f')} | {fmt(p['smallest_detectable_omega2'])} | "
                     f"{p['walks_needed_for_agrees'] if p['walks_needed_for_agrees'] else '> 240'} | "
                     f"{fmt(100 * p['perfect_emulator_rates']['agrees'], '.0f')} % | "
                     f"{fmt(100 * p['random_emulator_rates']['disagrees'], '.0f')} % |")
    return lines


def evidence_markdown(results: dict) -> str:
    """The replicated verdicts (issue 22): per metric omega2 with its interval and the verdict, the
    other comparisons, the three conditions side by side, and what the study's size can decide."""
    lines = _verdicts_intro(results)
    metrics = results.get("metrics") or {}
    if not metrics:
        lines += [results.get("reason", "No metrics."), ""]
        return "\n".join(lines) + "\n"
    lines += _metrics_table(metrics) + _comparisons_table(results, metrics) + _bias_table(metrics)
    not_run = [f"{k}: {c['reason']}" for k, c in (results.get("comparisons") or {}).items() if c["status"] != "run"]
    if not_run:
        lines += ["", "Not run: " + "; ".join(not_run) + "."]
    lines += _conditions_table(results, metrics) + _power_table(results.get("power") or {})
    return ("\n".join(lines) + "\n" + calibration_markdown(results.get("calibration"))
            + ("" if "final_checks" not in results else "\n" + checks_markdown(results["final_checks"])))
