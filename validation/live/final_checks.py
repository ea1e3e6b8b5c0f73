"""What a pre-registered study's final look reports beside its headline verdicts.

A study folder with a pre-registration (:mod:`validation.live.preregistration`) is judged once, at its final
look: at the planned walks, or at the walks of the seeds complete when a rule that does not read the data (a
budget) stopped it (:func:`validation.live.preregistration.stop_record`).  There :func:`final_checks` computes,
from the per-walk tables the verdicts were drawn from, and results.json keeps under ``final_checks``:

* ``monte_carlo``: per headline verdict its Holm-adjusted p's 99 % Monte Carlo interval and the verdict after the
  plan's Monte Carlo rule (``undetermined`` where the interval holds the level;
  :func:`validation.live.monte_carlo.headline_family`);
* ``stability``: the headline family, after the rule, over :data:`STABILITY_SEEDS` bootstrap seeds
  (:func:`validation.live.monte_carlo.verdict_stability`), and the verdicts that change;
* ``second_margin``: the family judged at omega2 :data:`SECOND_MARGIN` as well as at the headline's 0.2;
* ``level_shifts``: per headline comparison and metric the relative level shift against the plan's margin
  (:func:`validation.live.level_shift.level_shift`) and, per scene, omega2 and the shift
  (:func:`~validation.live.level_shift.per_scene`); ``leave_one_scene_out``: the scenes that carry a verdict;
* ``own_calibration``: the rule calibrated on the emulator's own residuals at the study's walks
  (:func:`validation.verdicts.own_calibration.study_own_calibration`, the plan's resamples, twice the plasmode's
  drawn studies), with the walks an undetermined verdict needs at its family level;
* ``stochastic_shares``: each stochastic method's share of the emulated-minus-live residual
  (:func:`validation.live.seeds.residual_shares`);
* ``targets``: each of these against what a study that decides must show (:data:`TARGETS`), met or not, per
  headline verdict.
"""

from __future__ import annotations

import numpy as np

from emulator.cells import format_number
from validation.live.config import COMPARISONS, HEADLINE_COMPARISONS, RESEEDED
from validation.live.evidence import walk_labels
from validation.live.headline import with_derived
from validation.live.level_shift import SHIFT_METRICS, leave_one_scene_out, level_shift, per_scene
from validation.live.monte_carlo import headline_family, ruled_verdict, verdict_stability
from validation.live.seeds import residual_shares, stochastic_methods
from validation.verdicts.agreement import ALPHA, omega2_untruncated
from validation.verdicts.own_calibration import study_own_calibration

__all__ = ["STABILITY_SEEDS", "SECOND_MARGIN", "TARGETS", "OWN_STUDIES_PER_PLASMODE", "final_checks", "targets",
           "checks_markdown"]

#: Bootstrap seeds over which no headline verdict may change.
STABILITY_SEEDS = 20
#: The second margin the headline family is judged at (beside the plan's 0.2).
SECOND_MARGIN = 0.1
#: What a study that decides shows: a perfect emulator (own residuals) ``agrees`` in at least 80 % of drawn studies
#: and one at omega2 0.3 ``disagrees`` in at least 80 %, each at the verdict's family level; one at the margin
#: ``disagrees`` in at most 5 % at the verdict's own 5 % (the rule's error rate as a test: at the family's stricter
#: level it would be met more easily); a stochastic method carries at most 40 % of the residual.
TARGETS = {"perfect_agrees_min": 0.80, "beyond_disagrees_min": 0.80, "margin_disagrees_max": 0.05,
           "stochastic_share_max": 0.40}
#: The own-residuals calibration draws this many times the plasmode's studies (100 by default: 200).
OWN_STUDIES_PER_PLASMODE = 2


def _level_shifts(tables: dict, walks, metrics, seed: int, n_resamples: int, margin: float) -> dict:
    scenes, seeds = walk_labels(walks)
    out: dict = {}
    for c, label in enumerate(HEADLINE_COMPARISONS):
        ref, other = COMPARISONS[label]
        if ref not in tables or other not in tables:
            continue
        for i, m in enumerate([*metrics, *(x for x in SHIFT_METRICS if x not in metrics)]):
            if m not in tables[ref] or m not in tables[other]:
                continue
            L, E = tables[ref][m], tables[other][m]
            ok = np.all(np.isfinite(L) & np.isfinite(E), axis=1)
            o2 = float(omega2_untruncated(L[ok], E[ok])) if ok.sum() >= 2 else float("nan")
            entry = {"omega2_untruncated": o2 if np.isfinite(o2) else None, "per_scene": per_scene(L, E, scenes)}
            if m in SHIFT_METRICS:
                entry["shift"] = level_shift(L, E, seeds, n_resamples=n_resamples, seed=[seed, 44_004, c, i],
                                             margin=margin)
            out.setdefault(label, {})[m] = entry
    return out


def final_checks(tables: dict, walks, methods, *, prereg: dict, seed: int, calibration_studies: int | None = None,
                 plasmode_default: int = 100) -> dict:
    """The final look's checks (see the module) of the per-walk ``tables`` ({run: {metric: walks x methods}}, the
    stochastic methods' per-walk means) over ``walks`` (``<scene>/seed<S>``), judged by the plan ``prereg``;
    ``seed``: the study's.  ``calibration_studies``: the plasmode's drawn studies (None: ``plasmode_default``);
    the own-residuals calibration draws :data:`OWN_STUDIES_PER_PLASMODE` times as many (0: skipped)."""
    tables = with_derived(tables)
    walks, methods = list(walks), list(methods)
    R, excluded = int(prereg["bootstrap_resamples"]), dict(prereg.get("excluded_from_headline") or {})
    metrics = list(prereg["metrics"])
    family = headline_family(tables, walks, methods, seed=seed, n_resamples=R, excluded=excluded)
    stability = verdict_stability(tables, walks, methods, seeds=range(STABILITY_SEEDS), n_resamples=R,
                                  excluded=excluded, monte_carlo_rule=True)
    second = headline_family(tables, walks, methods, seed=seed, n_resamples=R, excluded=excluded,
                             omega2_max=SECOND_MARGIN)
    n_plasmode = plasmode_default if calibration_studies is None else int(calibration_studies)
    own_n = OWN_STUDIES_PER_PLASMODE * n_plasmode
    comps = {label: COMPARISONS[label] for label in HEADLINE_COMPARISONS}
    own = {"status": "not computed", "reason": "no drawn studies asked for"} if own_n <= 0 else study_own_calibration(
        tables, walks, comparisons=comps, metrics=metrics, family_size=max(len(family), 1), reseeded=RESEEDED,
        n_studies=own_n, seed=seed, n_resamples=R)
    stoch = stochastic_methods(methods)
    shares = residual_shares(tables, methods, comps, metrics) if stoch else {}
    out = {"n_walks": len(walks), "bootstrap_resamples": R, "level": ALPHA, "family_size": len(family),
           "monte_carlo": {k: {"verdict": r["verdict"], "verdict_mc": r["verdict_mc"], "ruled": ruled_verdict(r),
                               "p_agrees_adjusted": r["p_agrees_adjusted"],
                               "p_disagrees_adjusted": r["p_disagrees_adjusted"], "adjusted_mc": r["adjusted_mc"]}
                           for k, r in family.items()},
           "stability": stability,
           "second_margin": {"omega2_max": SECOND_MARGIN, "verdicts": {
               k: {"ruled": ruled_verdict(r), "omega2_untruncated": r["omega2_untruncated"]} for k, r in second.items()}},
           "level_shifts": _level_shifts(tables, walks, metrics, seed, R, float(prereg["level_shift_margin"])),
           "leave_one_scene_out": leave_one_scene_out(tables, walks, methods, seed=seed, n_resamples=R,
                                                      excluded=excluded, monte_carlo_rule=True),
           "own_calibration": own,
           "stochastic_shares": {label: {m: {s: e["share"][s] for s in stoch} for m, e in per.items()}
                                 for label, per in shares.items()}}
    out["targets"] = targets(out)
    return out


def _rate(cal: dict, label: str, metric: str, scenario: str, verdict: str, level: str = "family"):
    """The rate of ``verdict`` in a scenario of the own-residuals calibration at its ``level`` ("family": the
    family's, "own": the verdict's own 5 %), or None where not computed."""
    r = ((cal.get("comparisons") or {}).get(label, {}).get("metrics") or {}).get(metric) or {}
    if r.get("status") != "computed":
        return None
    sc = r["scenarios"][scenario]
    return float(sc[[k for k in sc if k.startswith(level)][0]][verdict])


def targets(checks: dict) -> dict:
    """Per headline verdict (``"<comparison>: <metric>"``) each target of :data:`TARGETS` with the measured value
    (None where not measured) and whether it is met; ``stable``: the verdict is the same on every bootstrap seed;
    ``all_met``: every target of every verdict met."""
    cal = checks["own_calibration"]
    out: dict = {}
    changed = set(checks["stability"]["changed"])
    for key in checks["monte_carlo"]:
        label, _, metric = key.partition(": ")
        perfect = _rate(cal, label, metric, "omega2 0", "agrees")
        margin = _rate(cal, label, metric, "omega2 0.2", "disagrees", level="own")
        beyond = _rate(cal, label, metric, "omega2 0.3", "disagrees")
        share = [v for v in ((checks["stochastic_shares"].get(label) or {}).get(metric) or {}).values()]
        worst = max((v for v in share if v is not None), default=None)
        wd = (((cal.get("comparisons") or {}).get(label, {}).get("metrics") or {}).get(metric) or {}).get(
            "walks_to_decide") or {}
        entry = {
            "perfect_agrees": {"value": perfect, "met": perfect is not None and perfect >= TARGETS["perfect_agrees_min"]},
            "margin_disagrees": {"value": margin, "met": margin is not None and margin <= TARGETS["margin_disagrees_max"]},
            "beyond_disagrees": {"value": beyond, "met": beyond is not None and beyond >= TARGETS["beyond_disagrees_min"]},
            "stochastic_share": {"value": worst, "met": worst is None or worst <= TARGETS["stochastic_share_max"]},
            "stable": {"value": None, "met": key not in changed},
            "walks_to_decide": wd.get("walks"), "walks_to_decide_towards": wd.get("towards")}
        out[key] = entry
    out_all = all(t["met"] for e in out.values() for t in e.values() if isinstance(t, dict))
    return {"per_verdict": out, "all_met": bool(out) and out_all}


def _pct(v) -> str:
    return format_number(None if v is None else 100 * v, ".0f", missing="n/a") + ("" if v is None else " %")


#: Which walks the level-shift table reads, in words (its omega2 can differ from the headline's).
LEVEL_SHIFT_WALKS = ("This table reads the walks complete in live and emulated; the headline's omega2 reads those "
                     "complete in the re-seeded live control too, so the two omega2 differ where a walk has no value "
                     "in the control.")
#: The targets read from the own-residuals calibration (None where it could not be computed for a verdict).
CALIBRATION_TARGETS = ("perfect_agrees", "margin_disagrees", "beyond_disagrees")


def _target_cell(t: dict, optional: bool) -> str:
    """A target's cell: the value and met / not met; an optional one not measured (no stochastic method, or no
    walk complete for the metric) is 'n/a' alone, a calibration target not computed is not met and says so."""
    if t["value"] is None:
        return "n/a" if optional else "not computed (not met)"
    return f"{_pct(t['value'])} ({'met' if t['met'] else 'not met'})"


def _not_computed(per: dict) -> int:
    """How many calibration targets of the verdicts ``per`` were not computed."""
    return sum(e[k]["value"] is None for e in per.values() for k in CALIBRATION_TARGETS)


def checks_markdown(checks: dict) -> str:
    """The final look's checks as Markdown (report.md's last section)."""
    lines = ["## The final look's checks", "",
             f"{checks['n_walks']} walks, {checks['bootstrap_resamples']} bootstrap resamples, Holm across "
             f"{checks['family_size']} headline verdicts at {checks['level']:.0%}. A verdict whose Holm-adjusted p's "
             "99 % Monte Carlo interval holds the level is undetermined (the plan's rule); the targets are judged at "
             "each verdict's family level, the margin's at its own 5 %.", "",
             "| verdict | family verdict | after the Monte Carlo rule | over 20 bootstrap seeds | at omega2 0.1 | "
             "perfect agrees (>= 80 %) | margin disagrees (<= 5 %) | 0.3 disagrees (>= 80 %) | stochastic share "
             "(<= 40 %) | walks to decide |", "|" + " --- |" * 10]
    per = checks["targets"]["per_verdict"]
    counts = checks["stability"]["counts"]
    for key, mc in checks["monte_carlo"].items():
        t = per[key]
        seeds = ", ".join(f"{v} {n}" for v, n in sorted(counts.get(key, {}).items()))
        wd = t["walks_to_decide"]
        lines.append(" | ".join([
            f"| {key}", mc["verdict"], mc["ruled"], seeds, checks["second_margin"]["verdicts"][key]["ruled"],
            *(_target_cell(t[k], k not in CALIBRATION_TARGETS) for k in (*CALIBRATION_TARGETS, "stochastic_share")),
            "n/a" if t["walks_to_decide_towards"] is None else
            f"{wd if wd is not None else 'beyond the sizes tried'} ({t['walks_to_decide_towards']})"]) + " |")
    missing = _not_computed(per)
    lines += ["", f"Every target met: {'yes' if checks['targets']['all_met'] else 'no'}"
              + (f" ({missing} calibration target(s) not computed, each counted as not met: the own-residuals "
                 "calibration could not be drawn for that verdict)" if missing else "") + ".", "",
              "### Level shifts (emulated minus live, relative to live's mean) and scenes", "",
              LEVEL_SHIFT_WALKS, "",
              "| comparison | metric | omega2 | level shift [95 %] | verdict | per scene: omega2 / shift |",
              "| --- | --- | --- | --- | --- | --- |"]
    for label, per_metric in checks["level_shifts"].items():
        for m, e in per_metric.items():
            sh = e.get("shift")
            shift = "n/a (no level)" if sh is None else (
                f"{format_number(sh['relative'], '+.1%')} [{format_number(sh['relative_ci95'][0], '+.1%')}, "
                f"{format_number(sh['relative_ci95'][1], '+.1%')}]")
            scenes = "; ".join(f"{s} {format_number(v['omega2_untruncated'], '.2g')} / "
                               f"{format_number(v['relative_shift'], '+.0%')}" for s, v in e["per_scene"].items())
            lines.append(f"| {label} | {m} | {format_number(e['omega2_untruncated'], '.3g')} | {shift} | "
                         f"{'' if sh is None else sh['verdict']} | {scenes} |")
    lines += ["", "### Leave one scene out", "", "| verdict | on all walks | carried by |", "| --- | --- | --- |"]
    lines += [f"| {k} | {r['verdict']} | " + (", ".join(f"{s} ({r['without'][s]} without it)" for s in r["carried_by"])
                                              or "no single scene") + " |"
              for k, r in checks["leave_one_scene_out"].items()]
    return "\n".join(lines) + "\n"
