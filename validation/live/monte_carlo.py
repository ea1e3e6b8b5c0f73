"""The bootstrap's Monte Carlo error in the headline verdicts.

A headline verdict is decided by a p-value read from 1000 bootstrap replicates
(:func:`validation.verdicts.agreement.bound_pvalues`), then Holm across the family; at the margin the
verdict can depend on which replicates were drawn.  Two measurements:

* :func:`headline_family`: the headline family recomputed exactly as ``validate live`` computes it
  (the same seeds, so the same verdicts), with each p-value's Monte Carlo interval: the p of
  the rule at both ends of a Wilson interval (99 %) for the fraction of replicates at or below
  the margin, the bias correction held; Holm is monotone in every p, so the adjusted p's interval
  is Holm at both ends.  A verdict whose adjusted p's interval holds the level is
  ``undetermined (Monte Carlo)``: another draw of the replicates could decide it either way;
* :func:`verdict_stability`: the family over many bootstrap seeds (the study's seed replaced), and
  how many of its verdicts change.

``exposim validate monte-carlo OUT [--seeds 20] [--resamples 1000,4000]`` prints both for a
study folder's ``walks.csv`` without writing into the folder (:mod:`validation.verdict_studies.live_checks`).
"""

from __future__ import annotations

import math

import numpy as np

from emulator.core.stats import holm, rng_of
from validation.live.config import COMPARISONS, HEADLINE_COMPARISONS, HEADLINE_METRICS, JUDGED_METRICS, RESEEDED
from validation.live.headline import apply_family, with_derived
from validation.verdicts.agreement import (
    ALPHA,
    MIN_WALKS,
    OMEGA2_MAX,
    VERDICTS,
    complete_walks,
    judge_batch,
    omega2_over_plan,
    pvalues_of_fraction,
)
from validation.verdicts.ranking import cluster_plan, finite_or_none, walk_labels

__all__ = ["MC_CONFIDENCE", "MC_UNDETERMINED", "wilson", "pvalue_interval", "headline_family", "ruled_verdict",
           "apply_monte_carlo_rule", "verdict_stability"]

#: Confidence of the Monte Carlo interval of a p-value.
MC_CONFIDENCE = 0.99
#: A verdict whose Holm-adjusted p's Monte Carlo interval holds the level.
MC_UNDETERMINED = "undetermined (Monte Carlo)"


def wilson(k: float, n: int, confidence: float = MC_CONFIDENCE) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ``k / n``."""
    from scipy.stats import norm

    z = float(norm.ppf(0.5 + confidence / 2))
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(centre - half, 0.0), min(centre + half, 1.0)


def pvalue_interval(replicates, estimate, omega2_max: float = OMEGA2_MAX,
                    confidence: float = MC_CONFIDENCE) -> dict:
    """``{"p_agrees": [lo, hi], "p_disagrees": [lo, hi]}``: the Monte Carlo interval of the rule's p-values
    (:func:`~validation.verdicts.agreement.pvalues_of_fraction` at the ends of the Wilson interval of the fraction
    of replicates at or below ``omega2_max``; the bias correction ``z0`` held at its value)."""
    from scipy.stats import norm

    r = np.asarray(replicates, dtype=np.float64).ravel()
    r = np.where(np.isnan(r), np.inf, r)
    n = r.size
    z0 = 0.0
    if estimate is not None and math.isfinite(float(estimate)):
        frac = (np.sum(r < estimate) + 0.5 * np.sum(r == estimate)) / n
        z0 = float(norm.ppf(min(max(frac, 0.5 / n), 1.0 - 0.5 / n)))
    g_lo, g_hi = wilson(float(np.sum(r <= omega2_max)), n, confidence)
    a_hi, d_lo = pvalues_of_fraction(g_lo, z0, n)  # p_agrees falls and p_disagrees grows with the fraction
    a_lo, d_hi = pvalues_of_fraction(g_hi, z0, n)
    return {"p_agrees": [a_lo, a_hi], "p_disagrees": [d_lo, d_hi]}


def _member(live, emulated, control, clusters, n_resamples: int, seed, omega2_max: float = OMEGA2_MAX) -> dict:
    """One headline verdict at its own level as :func:`validation.verdicts.agreement.judge` draws it (the same
    walks: those complete in ``live``, ``emulated`` and the re-seeded ``control`` where there is one; the same
    random stream), with its replicates' Monte Carlo interval (``omega2_max``: the margin it is judged at)."""
    L, E = np.asarray(live, dtype=np.float64), np.asarray(emulated, dtype=np.float64)
    ok = complete_walks(L, E, None if control is None else np.asarray(control, dtype=np.float64))
    L, E = L[ok], E[ok]
    labels = np.asarray(list(clusters))[ok]
    units = int(np.unique(labels).size)
    if L.shape[0] < 2 or L.shape[1] < 2:  # nothing to compare (judge's rule): undecidable, p = 1 in the family
        return {"verdict": "undetermined", "reason": "", "n_walks": int(L.shape[0]), "n_clusters": units,
                "live_method_p": None, "p_agrees": None, "p_disagrees": None, "omega2_untruncated": None,
                "mc": {"p_agrees": [1.0, 1.0], "p_disagrees": [1.0, 1.0]}}
    rng = rng_of(seed)
    plan = cluster_plan(L.shape[0], n_resamples, rng, labels)
    b = judge_batch(L[None], E[None], n_resamples=n_resamples, seed=rng, omega2_max=omega2_max, plan=plan,
                    n_units=units)
    boot = omega2_over_plan(plan, L, E)
    return {"verdict": VERDICTS[int(b["verdict"][0])], "reason": "", "n_walks": int(L.shape[0]),
            "n_clusters": units, "live_method_p": float(b["live_p"][0]), "p_agrees": finite_or_none(b["p_agrees"][0]),
            "p_disagrees": finite_or_none(b["p_disagrees"][0]),
            "omega2_untruncated": finite_or_none(b["omega2_untruncated"][0]),
            "mc": pvalue_interval(boot, float(b["omega2_untruncated"][0]), omega2_max)}


def headline_family(tables: dict, walks, methods, *, seed: int = 0, n_resamples: int = 1000,
                    alpha: float = ALPHA, excluded: dict | None = None, omega2_max: float = OMEGA2_MAX) -> dict:
    """``{"<comparison>: <metric>": {verdict, verdict_alone, p_agrees_adjusted, p_disagrees_adjusted, mc,
    adjusted_mc, verdict_mc}}`` of the headline family (``seed``: the study's; the same as results.json's
    headline when it is the study's seed and ``n_resamples`` the study's: 1000, or a pre-registered study's
    ``bootstrap_resamples`` with its ``excluded_from_headline`` as ``excluded``).  ``omega2_max``: the margin the
    family is judged at (the headline's 0.2; another one reports the verdicts at that margin)."""
    excluded = excluded or {}
    tables = with_derived(tables)
    clusters = walk_labels(walks)[1]
    comparisons = {}
    for label in HEADLINE_COMPARISONS:
        ref, other = COMPARISONS[label]
        if ref not in tables or other not in tables:
            continue
        c = list(COMPARISONS).index(label)
        control = tables.get(RESEEDED.get(ref))  # judge_metrics' control: its walks are judge's walks
        comparisons[label] = {"status": "run", "metrics": {
            m: _member(tables[ref][m], tables[other][m], None if control is None else control[m], clusters,
                       n_resamples, [seed, 22_001, c, list(JUDGED_METRICS).index(m)], omega2_max)
            for m in HEADLINE_METRICS if m in tables[ref] and m in tables[other] and m not in excluded}}
    apply_family(comparisons, alpha=alpha, min_walks=MIN_WALKS, excluded=excluded)
    members = [(label, m, r) for label, c in comparisons.items() for m, r in c["metrics"].items()]

    def decidable(r):  # no live p: fewer than two walks or methods, nothing to compare
        return r["n_clusters"] >= MIN_WALKS and r["live_method_p"] is not None and r["live_method_p"] < alpha

    ends = {}
    for key in ("p_agrees", "p_disagrees"):
        ends[key] = [holm([r["mc"][key][i] if decidable(r) else 1.0 for _, _, r in members]) for i in (0, 1)]
    out = {}
    for j, (label, m, r) in enumerate(members):
        adj = {key: [float(ends[key][0][j]), float(ends[key][1][j])] for key in ends}
        key = {"agrees": "p_agrees", "disagrees": "p_disagrees"}.get(r["verdict_alone"])
        verdict_mc = r["verdict"]
        if key is not None and adj[key][0] <= alpha < adj[key][1]:
            verdict_mc = MC_UNDETERMINED
        out[f"{label}: {m}"] = {k: r[k] for k in ("verdict", "verdict_alone", "n_walks", "omega2_untruncated",
                                                  "p_agrees", "p_disagrees", "p_agrees_adjusted",
                                                  "p_disagrees_adjusted", "mc")}
        out[f"{label}: {m}"].update(adjusted_mc=adj, verdict_mc=verdict_mc)
    return out


def ruled_verdict(member: dict) -> str:
    """A family member's verdict under the Monte Carlo rule: ``undetermined`` where its adjusted p's Monte Carlo
    interval holds the level, else its verdict."""
    return "undetermined" if member["verdict_mc"] == MC_UNDETERMINED else member["verdict"]


def apply_monte_carlo_rule(comparisons: dict, family: dict) -> None:
    """The Monte Carlo rule on a judged headline, in place: each member of ``family`` (:func:`headline_family` of
    the same tables, seed and resamples) gets its ``adjusted_mc`` and ``verdict_mc`` in ``comparisons``, and a
    family verdict (``agrees`` or ``disagrees``) whose adjusted p's interval holds the level becomes
    ``undetermined`` with the reason: the interval of the p its verdict alone was read from.  A member whose
    verdicts, walks or adjusted p's differ from ``comparisons``' (other tables or draws) is refused with
    ValueError."""
    for key, r in family.items():
        label, _, metric = key.partition(": ")
        res = comparisons[label]["metrics"][metric]
        differs = [k for k in ("verdict", "verdict_alone", "n_walks", "p_agrees_adjusted", "p_disagrees_adjusted")
                   if res.get(k) != r.get(k)]
        if differs:
            raise ValueError(f"{key}: the Monte Carlo family and the headline differ in {', '.join(differs)} "
                             f"({', '.join(f'{r.get(k)} against {res.get(k)}' for k in differs)}): not the same "
                             "tables, walks, seed or resamples")
        res["adjusted_mc"], res["verdict_mc"] = r["adjusted_mc"], r["verdict_mc"]
        if r["verdict_mc"] == MC_UNDETERMINED and r["verdict"] in ("agrees", "disagrees"):
            p = r["adjusted_mc"]["p_agrees" if r["verdict_alone"] == "agrees" else "p_disagrees"]
            res["verdict"] = "undetermined"
            res["reason"] += (f"; but not beyond the bootstrap's Monte Carlo error (the Holm-adjusted p's "
                              f"{MC_CONFIDENCE:.0%} interval [{p[0]:.2g}, {p[1]:.2g}] holds the level)")


def verdict_stability(tables: dict, walks, methods, *, seeds, n_resamples: int = 1000,
                      excluded: dict | None = None, monte_carlo_rule: bool = False) -> dict:
    """The headline family over bootstrap ``seeds``: per member the count of each verdict, and the members whose
    verdict is not the same on every seed (``changed``) or is Monte Carlo undetermined on some seed.
    ``monte_carlo_rule``: the verdict counted is the one after the Monte Carlo rule (a pre-registered study's:
    ``undetermined`` where the adjusted p's interval holds the level)."""
    seeds, counts, mc = list(seeds), {}, {}
    for s in seeds:
        for key, r in headline_family(tables, walks, methods, seed=int(s), n_resamples=n_resamples,
                                      excluded=excluded).items():
            if monte_carlo_rule:
                r = {**r, "verdict": ruled_verdict(r)}
            counts.setdefault(key, {}).setdefault(r["verdict"], 0)
            counts[key][r["verdict"]] += 1
            mc[key] = mc.get(key, 0) + (r["verdict_mc"] == MC_UNDETERMINED)
    return {"n_seeds": len(seeds), "n_resamples": int(n_resamples), "counts": counts,
            "changed": sorted(k for k, v in counts.items() if len(v) > 1),
            "mc_undetermined_on_some_seed": sorted(k for k, v in mc.items() if v)}
