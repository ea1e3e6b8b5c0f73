"""The headline of the live study: both live references with equal weight, one family of verdicts.

* :func:`with_derived`: the judged metrics derived from the walks table's columns (translation
  RPE with a lost VO ranked worst, :data:`~validation.live.config.RPE_RANK`);
* :func:`apply_family`: Holm across the headline family (the distinct metrics of
  :data:`~validation.live.config.HEADLINE_METRICS` x the comparisons of
  :data:`~validation.live.config.HEADLINE_COMPARISONS`), in each direction (agrees,
  disagrees); every other verdict is its own family, and says so;
* :func:`walks_to_decide`: for an ``undetermined`` verdict, the walks at which a study with the
  measured variance components and the observed omega2 decides it in 80 % of simulated studies
  at the family's strictest level;
* :func:`headlines` and :func:`headlines_markdown`: results.json's ``headlines`` and the report's
  first section (each verdict with its interval, its family and the live-against-live control of
  its reference beside it).
"""

from __future__ import annotations

import math

import numpy as np

from emulator.core.stats import holm
from validation.live.config import (
    HEADLINE_COMPARISONS,
    HEADLINE_METRICS,
    JUDGED_METRICS,
    LIVE_LIVE,
    RPE_RANK,
)
from validation.verdicts.agreement import OMEGA2_MAX, VERDICTS, judge_batch
from validation.verdicts.simulate import simulate_tables
from emulator.cells import format_number

__all__ = ["rpe_rank_table", "with_derived", "HEADLINE_FAMILY", "OWN_FAMILY", "apply_family", "walks_to_decide",
           "headlines", "headlines_markdown", "headline_lines"]

#: Walk counts tried by :func:`walks_to_decide`.
DECIDE_CANDIDATES = (10, 15, 20, 30, 45, 60, 90, 120, 180, 240)


def rpe_rank_table(rpe, failed_frames) -> np.ndarray:
    """Per walk (row), each method's rank of translation RPE (1 = lowest; ties share the mean rank); a method
    whose VO ran but gave no RPE (its VO was lost) ranks below every method with one, the lost ones tied.
    A walk where some method's VO did not run at all (no failed-frame count) stays NaN."""
    from scipy.stats import rankdata

    R = np.asarray(rpe, dtype=np.float64)
    F = np.asarray(failed_frames, dtype=np.float64)
    out = np.full(R.shape, np.nan)
    for w in range(R.shape[0]):
        if np.all(np.isfinite(F[w])):
            out[w] = rankdata(np.where(np.isfinite(R[w]), R[w], np.inf), method="average")
    return out


def with_derived(tables: dict) -> dict:
    """``tables`` ({run: {metric: (walks, methods)}}) with :data:`RPE_RANK` added to every run that has both the
    RPE and the failed-frame columns (a new dict; the inputs are not changed)."""
    out = {}
    for run, per in tables.items():
        out[run] = dict(per)
        if "rpe_trans_pct" in per and "vo_failed_frames" in per:
            out[run][RPE_RANK] = rpe_rank_table(per["rpe_trans_pct"], per["vo_failed_frames"])
    return out


def _family_text(n: int, n_metrics: int, n_comparisons: int) -> str:
    return (f"headline: {n} verdicts ({n_metrics} distinct metrics x {n_comparisons} comparisons), Holm across them "
            "in each direction (agrees, disagrees) at 5 %; the interval is the verdict's own one-sided 95 % bounds")


#: Family of a headline verdict (formatted with the family's size by :func:`apply_family`).
HEADLINE_FAMILY = _family_text
#: Family of every other verdict.
OWN_FAMILY = ("its own: one metric and one comparison, outside the headline family, not corrected across "
              "metrics or comparisons")
_NOT_COUNTED = {"success_rate_tau100": "outside the headline family: the same per-pair matches as "
                                       "segment_success_rate_tau100 (counted once, there), not corrected",
                "rpe_trans_pct": "outside the headline family: the sensitivity analysis of rpe_trans_rank (complete "
                                 "walks only: every method kept its VO in both conditions), not corrected"}


def apply_family(comparisons: dict, alpha: float = 0.05, min_walks: int = 10, excluded: dict | None = None) -> dict:
    """Holm across the headline family, in place: each headline verdict's ``verdict`` becomes the family's (an
    ``agrees`` or ``disagrees`` whose Holm-adjusted p is above ``alpha`` becomes ``undetermined``), with
    ``verdict_alone`` (at its own level), ``p_agrees_adjusted``, ``p_disagrees_adjusted`` and ``family``; every
    other verdict gets its ``family``.  A verdict that cannot be decided at all (fewer than ``min_walks``
    walks, or seeds where the walks are clustered, live not separating the methods) counts in the family with p = 1.
    ``excluded``: headline metrics left out of the family before any data (metric -> reason; a pre-registered
    study's, :func:`validation.live.preregistration.headline_exclusions`).  Returns the family's summary."""
    excluded = excluded or {}
    metrics = [m for m in HEADLINE_METRICS if m not in excluded]
    members = [(label, m) for label in HEADLINE_COMPARISONS if comparisons.get(label, {}).get("status") == "run"
               for m in metrics if m in comparisons[label]["metrics"]]
    text = _family_text(len(members), len(metrics), len({lab for lab, _ in members}))
    outside = {m: f"outside the headline family: {why}, not corrected" for m, why in excluded.items()}
    for label, c in comparisons.items():
        for metric, r in (c.get("metrics") or {}).items():
            r["family"] = text if (label, metric) in members else (
                {**_NOT_COUNTED, **outside}.get(metric, OWN_FAMILY) if label in HEADLINE_COMPARISONS else OWN_FAMILY)
    extra = {"excluded": dict(excluded)} if excluded else {}  # only pre-registered studies leave a metric out
    if not members:
        return {"size": 0, "definition": text, "members": [], **extra}
    res = [comparisons[label]["metrics"][m] for label, m in members]

    def decidable(r) -> bool:
        p = r.get("live_method_p")
        units = r["n_walks"] if r.get("n_clusters") is None else r["n_clusters"]
        return units >= min_walks and p is not None and p < alpha

    pa = holm([r["p_agrees"] if decidable(r) and r.get("p_agrees") is not None else 1.0 for r in res])
    pd = holm([r["p_disagrees"] if decidable(r) and r.get("p_disagrees") is not None else 1.0 for r in res])
    for r, a, d in zip(res, pa, pd):
        r["verdict_alone"], r["p_agrees_adjusted"], r["p_disagrees_adjusted"] = r["verdict"], float(a), float(d)
        if r["verdict"] == "agrees" and not a <= alpha:
            r["verdict"] = "undetermined"
            r["reason"] += f"; but not at the family's level (Holm-adjusted p = {a:.2g} > {alpha})"
        elif r["verdict"] == "disagrees" and not d <= alpha:
            r["verdict"] = "undetermined"
            r["reason"] += f"; but not at the family's level (Holm-adjusted p = {d:.2g} > {alpha})"
    return {"size": len(members), "definition": text, "members": [f"{lab}: {m}" for lab, m in members], **extra}


def _decided_rate(scales, n_walks: int, omega2: float, target: str, alpha: float, n_seeds: int,
                  n_resamples: int, seed) -> float:
    from emulator.core.stats import rng_of

    rng = rng_of(seed)
    t = simulate_tables("exact", n_walks, scales, n_seeds=n_seeds, seed=rng, omega2_true=omega2)
    v = judge_batch(t["live"], t["emulated"], n_resamples=n_resamples, seed=rng, alpha=alpha)["verdict"]
    return float(np.mean(v == VERDICTS.index(target)))


def walks_to_decide(scales, omega2_hat: float | None, *, alpha: float = 0.05, n_seeds: int = 100,
                    n_resamples: int = 400, seed=0, candidates=DECIDE_CANDIDATES) -> dict:
    """Fewest walks (on ``candidates``, bisected) at which studies with the measured ``scales`` and a true omega2
    equal to the observed one (``omega2_hat``, truncated at 0) are judged as it points (``agrees`` at or below
    the margin, ``disagrees`` above) in at least 80 % of ``n_seeds`` simulated studies at level ``alpha`` (the
    headline family's Bonferroni level ``0.05 / size``: Holm's strictest step, so the count is an upper bound
    for the family's verdict)."""
    if omega2_hat is None or not math.isfinite(omega2_hat) or scales is None or scales.sd_method <= 0:
        return {"walks": None, "towards": None, "reason": "no measured method effect or omega2 to simulate from"}
    target = "agrees" if omega2_hat <= OMEGA2_MAX else "disagrees"
    o = max(float(omega2_hat), 0.0)

    def rate(w: int) -> float:
        return _decided_rate(scales, w, o, target, alpha, n_seeds, n_resamples, [*np.atleast_1d(seed).tolist(), w])

    lo, hi, best = 0, len(candidates), None
    while lo < hi:  # the fewest candidate that decides, assuming more walks never decide less often
        mid = (lo + hi) // 2
        r = rate(candidates[mid])
        if r >= 0.8:
            hi, best = mid, (candidates[mid], r)
        else:
            lo = mid + 1
    if best is None:
        return {"walks": None, "towards": target, "level": alpha, "reason": f"not within {candidates[-1]} walks"}
    return {"walks": int(best[0]), "towards": target, "rate": best[1], "level": alpha}


def _compact(r: dict) -> dict:
    keys = ("verdict", "verdict_alone", "omega2", "omega2_ci90", "p_agrees_adjusted", "p_disagrees_adjusted",
            "family", "reason", "n_walks", "pairs_verdict", "walks_to_decide")
    out = {k: r[k] for k in keys if k in r}
    if isinstance(out.get("pairs_verdict"), dict):
        out["pairs_verdict"] = out["pairs_verdict"].get("verdict")
    return out


def headlines(comparisons: dict, family: dict) -> dict:
    """results.json's ``headlines``: per headline comparison (in order) what it answers, and per judged metric
    its verdict, interval and family, with the live-against-live control of its reference beside it."""
    out = {"family": family, "distinct_metrics": [m for m in HEADLINE_METRICS if m not in family.get("excluded", {})],
           "comparisons": {}}
    for label, question in HEADLINE_COMPARISONS.items():
        c = comparisons.get(label) or {"status": "not run"}
        entry = {"answers": question, "status": c["status"], "reference": c.get("reference"),
                 "compared": c.get("compared"), "live_live": LIVE_LIVE.get(c.get("reference"))}
        if c["status"] != "run":
            entry["reason"] = c.get("reason")
        else:
            ctl = comparisons.get(entry["live_live"]) or {}
            entry["metrics"] = {}
            for m in JUDGED_METRICS:
                if m not in c["metrics"]:
                    continue
                entry["metrics"][m] = _compact(c["metrics"][m])
                if ctl.get("status") == "run" and m in ctl["metrics"]:
                    entry["metrics"][m]["live_live"] = {k: ctl["metrics"][m][k]
                                                        for k in ("verdict", "omega2", "omega2_ci90", "n_walks")}
        out["comparisons"][label] = entry
    return out


def _ci(iv) -> str:
    if not iv or iv[0] is None and iv[1] is None:
        return "n/a"
    return f"[{format_number(iv[0])}, {'inf' if iv[1] is None else format_number(iv[1])}]"


def _cell(r: dict) -> str:
    txt = f"**{r['verdict']}** {format_number(r['omega2'])} {_ci(r['omega2_ci90'])}"
    if r.get("verdict_alone") and r["verdict_alone"] != r["verdict"]:
        txt += f" ({r['verdict_alone']} alone)"
    wd = r.get("walks_to_decide")
    if r["verdict"] == "undetermined" and wd:
        txt += (f"; decided ({wd['towards']}) at {wd['walks']} walks" if wd.get("walks")
                else f"; walks to decide: {wd.get('reason', 'n/a')}")
    ll = r.get("live_live")
    if ll:
        txt += f"; live vs live: {ll['verdict']} {format_number(ll['omega2'])} {_ci(ll['omega2_ci90'])}"
    return txt


def _one_segment_note(config: dict) -> str:
    """A sentence where a walk is one segment (its match pairs no more than a segment's): the segment
    success rate is then the sequence success rate, not a second view of the walks."""
    cycles, seg = config.get("n_cycles"), config.get("segment_pairs")
    if not (isinstance(cycles, int) and isinstance(seg, int)) or cycles - 1 > seg:
        return ""
    return (f" At this walk length ({cycles - 1} match pairs per walk, segments of {seg}) a walk is one segment: "
            "the segment success rate is the sequence success rate.")


def headlines_markdown(results: dict) -> str:
    """The report's first section: a row per metric, a column per headline comparison."""
    h = results.get("headlines")
    if not h:
        return ""
    comps = h["comparisons"]
    fam = h.get("family") or {}
    lines = ["## Headline: emulated against both live references, equal weight", "",
             " ".join(f"*{label}*: {c['answers']}." for label, c in comps.items()),
             f"Each cell: the verdict, omega2 with its one-sided 95 % bounds, and the same comparison of the reference "
             f"live camera against itself re-seeded (live vs live: what a perfect emulator scores). Family of the "
             f"verdicts in this table: {fam.get('definition', 'n/a')}. The sequence success rate is not counted "
             "(the same per-pair matches as the segment success rate); RPE counts a lost VO as the worst outcome "
             "(rpe_trans_rank: per walk the methods' RPE rank, a method that lost its VO ranked last), with the "
             "complete walks alone (rpe_trans_pct) as the sensitivity analysis below the family. Where a verdict "
             "is undetermined, the walks at which a study of this noise and this omega2 decides it in 80 % of "
             "simulated studies, at Holm's strictest level (5 % divided by the family's size), which is enough "
             f"at any step of Holm's order.{_one_segment_note(results.get('config') or {})}", ""]
    ran = {k: c for k, c in comps.items() if c["status"] == "run"}
    for k, c in comps.items():
        if c["status"] != "run":
            lines += [f"- {k}: not run ({c.get('reason')}).", ""]
    if ran:
        metrics = list(next(iter(ran.values()))["metrics"])
        lines += ["| metric | " + " | ".join(ran) + " |", "| --- | " + " | ".join("---" for _ in ran) + " |"]
        for m in metrics:
            tag = "" if m in h.get("distinct_metrics", HEADLINE_METRICS) else " (outside the family)"
            lines.append(f"| {m}{tag} | " + " | ".join(_cell(c["metrics"][m]) if m in c["metrics"] else "n/a"
                                                      for c in ran.values()) + " |")
    return "\n".join(lines) + "\n\n"


def headline_lines(results: dict) -> list[str]:
    """What the command prints first: per headline comparison and distinct metric, the verdict with its bounds."""
    h = results.get("headlines")
    if not h:
        return []
    lines = [f"headline over {results.get('n_walks', 0)} walks ({(h.get('family') or {}).get('definition', '')}):"]
    for label, c in h["comparisons"].items():
        if c["status"] != "run":
            lines.append(f"  {label}: not run")
            continue
        cells = [f"{m} {c['metrics'][m]['verdict']} {format_number(c['metrics'][m]['omega2'])} "
                 f"{_ci(c['metrics'][m]['omega2_ci90'])}" for m in h.get("distinct_metrics", HEADLINE_METRICS)
                 if m in c["metrics"]]
        lines.append(f"  {label}: " + "; ".join(cells))
    return lines
