"""The paper's findings (section V-D) as statistics, each tested as the paper states it.

The unit is an independent walk (a scene of the AE study with its seeds): per walk and
method the study's figures (``ae_study.summarise(...)["per_scene"][scene][method]``).
Every finding has

* ``effect``: its statistic on the methods' walk means, signed so that a positive effect is
  the paper's claim (``vo_similar``: the ratio largest / smallest itself);
* ``ci95``: percentile interval of the effect over a cluster bootstrap of the walks;
* a **test of the claim as stated** (:mod:`validation.verdicts.claims`): a claim about
  every other method ("M_fixed has the most matches": fixed beats classical-30 *and*
  classical-50 *and* ...) is the intersection of one-sided paired comparisons, and holds
  only when each of them rejects (intersection-union: ``p`` is the largest of the parts'
  p-values); "M_fixed is not the best" holds when one other method beats it (Bonferroni
  over the others); the equivalence ``vo_similar`` (largest / smallest method mean
  translation RPE at most 1.5) holds when every ordered pair satisfies
  ``mean_i <= 1.5 mean_j`` significantly, one paired test per pair (intersection-union);
* ``p_adjusted``: Holm across every tested claim, ``vo_similar`` included (the family
  ``holds``); the p-values of the opposite claims (a method significantly ahead of the
  claimed one: ``p_contradicted``) form a second family with its own Holm adjustment;
* ``verdict``: ``holds`` (``p_adjusted < alpha``), ``contradicted``
  (``p_contradicted_adjusted < alpha``), ``undetermined`` otherwise or with fewer than
  :data:`~validation.verdicts.agreement.MIN_WALKS` walks, and ``by-construction`` for the
  findings that cannot fail whatever the methods do (not tested, not counted): success can
  only fall as tau rises, and "VO fails on some run" holds on one failed frame of one run.

The error rates of these tests on tied and near-tied configurations (a claim that is false
by nothing or by little) are measured by :func:`false_holds_rates`; docs/verdicts.md has
the numbers.
"""

from __future__ import annotations

import math

import numpy as np

from emulator.core.stats import percentile_interval, rng_of
from validation.verdicts.agreement import ALPHA, MIN_WALKS
from validation.verdicts.claims import Claim, claim_pvalues, holm_rows

__all__ = ["FINDINGS", "SPECS", "BY_CONSTRUCTION", "CLAIMED", "SIMILAR_RATIO", "FAMILY", "unit_tables", "claim_of",
           "finding_effects", "evaluate", "batch_verdicts", "simulated_tables", "configuration_shift",
           "false_holds_rates", "finding_power"]

_METHODS = ("fixed", "classical-30", "classical-50", "classical-70", "shim", "zhang", "kim")

#: Per-unit figure of each metric the findings use: path into a per-scene summary entry.
_PATHS = {
    "matches": ("median_matches",),
    "uniformity": ("median_uniformity",),
    "success_seq_hi": ("sequence_success", "{hi}"),
    "success_seg_hi": ("segment_success", "{hi}", "rate"),
    "rpe_trans": ("vo", "rpe_trans_pct"),
    "rpe_rot": ("vo", "rpe_rot_deg_per_m"),
    "vo_failed": ("vo", "n_failed_frames"),
}
#: The equivalence finding: largest / smallest translation RPE at most this.
SIMILAR_RATIO = 1.5

#: Tested findings: id -> (metric, form, claimed methods, what a positive effect says).  Forms:
#: ``above_every`` (each claimed method above every other), ``below_every`` (each below every other),
#: ``below_mean`` (each below the mean of the others), ``not_lowest`` (some other method below the claimed one).
#: A finding that names several methods tests every one of them (the gradient findings were one
#: contrast of the two methods' mean, which held when one of them alone was ahead).
SPECS = {
    "fixed_most_matches": ("matches", "above_every", ("fixed",), "M_fixed's median matches minus the best other's"),
    "uniformity_70_kim_lower": ("uniformity", "below_mean", ("classical-70", "kim"),
                                "mean uniformity of the others minus the higher of M_70% and M_Kim"),
    "fixed_best_success_sequences": ("success_seq_hi", "above_every", ("fixed",),
                                     "M_fixed's sequence success at the largest tau minus the best other's"),
    "poorest_success_30_70_kim_sequences": ("success_seq_hi", "below_every", ("classical-30", "classical-70", "kim"),
                                            "the lowest sequence success of the others minus the best of M_30%, "
                                            "M_70%, M_Kim"),
    "fixed_best_success_segments": ("success_seg_hi", "above_every", ("fixed",),
                                    "M_fixed's segment success rate minus the best other's"),
    "poorest_success_30_70_kim_segments": ("success_seg_hi", "below_every", ("classical-30", "classical-70", "kim"),
                                           "the lowest segment success of the others minus the best of M_30%, "
                                           "M_70%, M_Kim"),
    "rpe_trans_best_50": ("rpe_trans", "below_every", ("classical-50",),
                          "the best other translation RPE minus M_50%'s (%)"),
    "rpe_trans_worst_kim": ("rpe_trans", "above_every", ("kim",),
                            "M_Kim's translation RPE minus the worst other's (%)"),
    "rpe_rot_best_zhang_50": ("rpe_rot", "below_every", ("zhang", "classical-50"),
                              "the lowest other rotation RPE minus the higher of M_Zhang and M_50% (deg/m)"),
    "fixed_not_best_vo": ("rpe_trans", "not_lowest", ("fixed",),
                          "M_fixed's translation RPE minus the best other's (%)"),
    "gradient_ahead_vo": ("rpe_trans", "below_mean", ("shim", "zhang"),
                          "others' mean translation RPE minus the higher of M_Shim's and M_Zhang's (%)"),
    "gradient_fewer_vo_failures": ("vo_failed", "below_mean", ("shim", "zhang"),
                                   "others' mean failed VO frames minus the higher of M_Shim's and M_Zhang's"),
}
#: The test of each form, in words (the reports' ``test``).
_TESTS = {
    "above_every": "each claimed method above each other one: every one-sided paired t-test rejects "
                   "(intersection-union)",
    "below_every": "each claimed method below each other one: every one-sided paired t-test rejects "
                   "(intersection-union)",
    "below_mean": "each claimed method below the others' mean: every one-sided paired t-test rejects "
                  "(intersection-union)",
    "not_lowest": "some other method below the claimed one: the smallest one-sided paired t-test p, Bonferroni "
                  "over the others",
    "similar": f"every ordered pair: mean_i <= {SIMILAR_RATIO} mean_j, every one-sided paired t-test rejects "
               "(intersection-union)",
}
#: The multiplicity family of every tested finding's verdict, in words.
FAMILY = ("the AE findings: Holm across the 13 tested claims (vo_similar included) for holds, and across their "
          "opposites for contradicted")
#: Findings that cannot fail whatever the methods do: id -> why.
BY_CONSTRUCTION = {
    "success_falls_with_tau_sequences": "a run whose every pair has >= tau_hi matches has >= tau_lo matches too: the "
                                        "success rate cannot rise with tau",
    "success_falls_with_tau_segments": "as for sequences: a segment succeeding at the larger tau succeeds at the "
                                       "smaller",
    "vo_fails_on_some_runs": "holds on one failed VO frame of one run; no comparison of methods",
}


def _split(methods, group):
    g = [methods.index(n) for n in group]
    return g, [k for k, m in enumerate(methods) if m not in group]


def _effect(form: str, group) -> callable:
    def f(mean, methods):
        g, o = _split(list(methods), group)
        mg, mo = mean[..., g], mean[..., o]
        if form == "above_every":
            return mg.min(axis=-1) - mo.max(axis=-1)
        if form == "below_every":
            return mo.min(axis=-1) - mg.max(axis=-1)
        if form == "below_mean":
            return mo.mean(axis=-1) - mg.max(axis=-1)
        return mg[..., 0] - mo.min(axis=-1)  # not_lowest
    return f


#: Tested findings: id -> (metric, effect of the method walk means, what a positive effect says).
FINDINGS = {fid: (metric, _effect(form, group), definition) for fid, (metric, form, group, definition) in SPECS.items()}


def claim_of(fid: str, methods) -> Claim:
    """The claim of finding ``fid`` (or ``"vo_similar"``) over ``methods`` as contrasts of the method columns."""
    methods = list(methods)
    m = len(methods)
    if fid == "vo_similar":
        rows, labels = [], []
        for i in range(m):
            for j in range(m):
                if i != j:
                    w = np.zeros(m)
                    w[j] += SIMILAR_RATIO
                    w[i] -= 1.0
                    rows.append(w)
                    labels.append(f"{methods[i]} <= {SIMILAR_RATIO} x {methods[j]}")
        return Claim(rows, "all", labels)
    _, form, group, _ = SPECS[fid]
    g, o = _split(methods, group)
    rows, labels = [], []

    def unit(k):
        w = np.zeros(m)
        w[k] = 1.0
        return w

    if form in ("above_every", "below_every"):
        sign = 1.0 if form == "above_every" else -1.0
        for a in g:
            for b in o:
                rows.append(sign * (unit(a) - unit(b)))
                labels.append(f"{methods[a]} {'>' if sign > 0 else '<'} {methods[b]}")
    elif form == "below_mean":
        rest = np.zeros(m)
        rest[o] = 1.0 / len(o)
        for a in g:
            rows.append(rest - unit(a))
            labels.append(f"{methods[a]} < the others' mean")
    else:  # not_lowest: some other below the claimed one
        for b in o:
            rows.append(unit(g[0]) - unit(b))
            labels.append(f"{methods[b]} < {methods[g[0]]}")
    return Claim(rows, "any" if form == "not_lowest" else "all", labels)


def _value(entry: dict | None, path) -> float:
    v = entry
    for k in path:
        v = v.get(k) if isinstance(v, dict) else None
    if v is None:
        return math.nan
    v = float(v)
    return v if math.isfinite(v) else math.nan


def unit_tables(units: list[dict], methods=_METHODS, hi_tau: int = 100) -> dict[str, np.ndarray]:
    """``{metric: (units, methods) array}`` from per-unit summaries (``{method: per-scene entry}`` each)."""
    out = {}
    for metric, path in _PATHS.items():
        p = tuple(k.format(hi=hi_tau) for k in path)
        out[metric] = np.array([[_value(u.get(m), p) for m in methods] for u in units], dtype=np.float64)
    return out


def finding_effects(tables: dict[str, np.ndarray], methods=_METHODS) -> dict[str, np.ndarray]:
    """The effect of every tested finding, vectorised over leading axes of the (..., units, methods) tables."""
    methods = list(methods)
    return {fid: f(np.nanmean(tables[metric], axis=-2), methods) for fid, (metric, f, _) in FINDINGS.items()}


def _ratio(mean):
    mn = mean.min(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(mn > 0, mean.max(axis=-1) / mn, np.inf)


def _tested_ids():
    return list(FINDINGS) + ["vo_similar"]


def _metric_of(fid):
    return "rpe_trans" if fid == "vo_similar" else FINDINGS[fid][0]


def _decide(p_holds, p_contra, n_walks, alpha, min_walks):
    """Holm in both families (last axis: the findings), then the verdict codes: 1 holds, -1 contradicted, 0 not."""
    a_h, a_c = holm_rows(p_holds), holm_rows(p_contra)
    holds = (a_h < alpha) & ~(a_c < alpha)
    contra = (a_c < alpha) & ~(a_h < alpha)
    code = np.where(holds, 1, np.where(contra, -1, 0))
    return np.where(np.asarray(n_walks) >= min_walks, code, 0), a_h, a_c


def evaluate(tables: dict[str, np.ndarray], methods=_METHODS, *, n_resamples: int = 1000, seed=0,
             alpha: float = ALPHA, min_walks: int = MIN_WALKS) -> list[dict]:
    """Every finding of :data:`FINDINGS`, ``vo_similar`` and :data:`BY_CONSTRUCTION` with its evidence.

    ``tables``: :func:`unit_tables`.  Units with a missing value of a finding's metric are
    left out of that finding.  Returns a list of ``{id, effect, ci95, p, p_adjusted,
    p_contradicted, p_contradicted_adjusted, verdict, n_walks, definition, test, family,
    parts, reason}`` (``parts``: per one-sided comparison its walk-mean contrast and p-values).
    """
    rng = rng_of(seed)
    methods = list(methods)
    rows = []
    for fid in _tested_ids():
        t = tables[_metric_of(fid)]
        t = t[np.all(np.isfinite(t), axis=1)]
        u = t.shape[0]
        similar = fid == "vo_similar"
        form = "similar" if similar else SPECS[fid][1]
        definition = (f"largest / smallest method mean translation RPE (holds at or below {SIMILAR_RATIO})" if similar
                      else FINDINGS[fid][2])
        row = {"id": fid, "effect": None, "ci95": [None, None], "p": None, "p_adjusted": None,
               "p_contradicted": None, "p_contradicted_adjusted": None, "verdict": "undetermined", "n_walks": int(u),
               "definition": definition, "test": _TESTS[form], "family": FAMILY, "parts": [], "reason": ""}
        claimed = () if similar else SPECS[fid][2]
        absent = [m for m in claimed if m not in methods]
        if absent or len(methods) <= len(claimed) or len(methods) < 2:
            row["reason"] = (f"method(s) {', '.join(absent)} not in this study" if absent
                             else "no other method to compare with")
            rows.append(row)
            continue
        if u == 0:
            row["reason"] = f"no walk with a {_metric_of(fid)} value for every method"
            rows.append(row)
            continue
        stat = _ratio if similar else (lambda mean, f=FINDINGS[fid][1]: f(mean, methods))
        row["effect"] = float(stat(t.mean(axis=0)))
        if u >= 2:
            lo, hi = percentile_interval(stat(t[rng.integers(0, u, (n_resamples, u))].mean(axis=1)), 1.0 - alpha)
            row["ci95"] = [float(lo), None if not math.isfinite(hi) else float(hi)]
        claim = claim_of(fid, methods)
        pv = claim_pvalues(claim, t)
        row["p"], row["p_contradicted"] = float(pv["holds"]), float(pv["contradicted"])
        row["parts"] = [{"comparison": lab, "mean": float(pv["part_mean"][k]), "p_above": float(pv["part_p_above"][k]),
                         "p_below": float(pv["part_p_below"][k])} for k, lab in enumerate(claim.labels)]
        rows.append(row)
    tested = [r for r in rows if r["p"] is not None]
    if tested:
        codes, a_h, a_c = _decide(np.array([r["p"] for r in tested]), np.array([r["p_contradicted"] for r in tested]),
                                  np.array([r["n_walks"] for r in tested]), alpha, min_walks)
        for r, code, ah, ac in zip(tested, codes, a_h, a_c):
            r["p_adjusted"], r["p_contradicted_adjusted"] = float(ah), float(ac)
            r["verdict"] = {1: "holds", -1: "contradicted", 0: "undetermined"}[int(code)]
            r["reason"] = _reason(r, alpha, min_walks)
    for fid, why in BY_CONSTRUCTION.items():
        rows.append({"id": fid, "effect": None, "ci95": [None, None], "p": None, "p_adjusted": None,
                     "verdict": "by-construction", "n_walks": None, "definition": None,
                     "reason": f"cannot fail, not counted: {why}"})
    return rows


def _reason(r: dict, alpha: float, min_walks: int) -> str:
    if r["n_walks"] < min_walks:
        return f"{r['n_walks']} walks, fewer than {min_walks}: no verdict over so few walks"
    if r["verdict"] == "holds":
        return (f"every comparison the claim needs rejects: p = {r['p']:.3g}, Holm-adjusted {r['p_adjusted']:.3g} "
                f"< {alpha}")
    if r["verdict"] == "contradicted":
        return (f"a comparison goes significantly against the claim: p = {r['p_contradicted']:.3g}, Holm-adjusted "
                f"{r['p_contradicted_adjusted']:.3g} < {alpha}")
    weakest = max(r["parts"], key=lambda q: q["p_above"]) if r["parts"] else None
    where = f" (weakest comparison: {weakest['comparison']}, p = {weakest['p_above']:.3g})" if weakest else ""
    return f"Holm-adjusted p = {r['p_adjusted']:.3g} >= {alpha}: the claim is not shown{where}"


def batch_verdicts(tables: dict[str, np.ndarray], methods=_METHODS, *, alpha: float = ALPHA,
                   min_walks: int = MIN_WALKS) -> dict[str, dict[str, np.ndarray]]:
    """The verdicts of :func:`evaluate` on many complete studies at once (no intervals: the calibration's loop).

    ``tables``: ``{metric: (studies, walks, methods)}``, every value finite.  Returns per
    tested finding ``{"raw_holds": p < alpha (no Holm: the worst case, every other claim
    rejected), "verdict": 1 holds / -1 contradicted / 0 undetermined}``, arrays over the studies.
    """
    methods = list(methods)
    ids = [f for f in _tested_ids() if all(m in methods for m in (() if f == "vo_similar" else SPECS[f][2]))]
    ph, pc = [], []
    for fid in ids:
        pv = claim_pvalues(claim_of(fid, methods), tables[_metric_of(fid)])
        ph.append(pv["holds"])
        pc.append(pv["contradicted"])
    ph, pc = np.stack(ph, axis=-1), np.stack(pc, axis=-1)
    n_walks = next(iter(tables.values())).shape[-2]
    codes, _, _ = _decide(ph, pc, n_walks, alpha, min_walks)
    return {fid: {"raw_holds": ph[..., k] < alpha, "verdict": codes[..., k]} for k, fid in enumerate(ids)}


#: The methods a finding's claim is about, and the sign of the shift that makes the claim true on its metric.
CLAIMED = {fid: {m: (1.0 if form in ("above_every", "not_lowest") else -1.0) for m in group}
           for fid, (_, form, group, _) in SPECS.items()}


def simulated_tables(n_walks: int, *, effect_noise_sd: dict | None = None, noise_sd: float = 1.0, seed=0,
                     methods=_METHODS, n_studies: int | None = None, shifts: dict | None = None,
                     noisy: dict | None = None, df: float | None = None, level: float = 5.0) -> dict[str, np.ndarray]:
    """Per-unit tables of every metric: a walk level common to the methods plus noise per walk and method.

    ``effect_noise_sd``: per finding id, its claimed methods shifted in the claim's direction by
    that many noise SDs (:data:`CLAIMED`); ``shifts``: per metric, a shift per method (noise
    SDs) added on top; ``noisy``: per method a factor on its noise SD (a method like M_Kim,
    far noisier than the others); ``df``: Student-t noise with ``df`` degrees of freedom
    (heavy tails; scaled to the same SD) instead of Gaussian.  ``n_studies``: a leading
    axis of independent studies (shape (n_studies, n_walks, methods)).
    """
    rng = rng_of(seed)
    methods = list(methods)
    lead = () if n_studies is None else (int(n_studies),)
    sd = np.full(len(methods), float(noise_sd))
    for m, k in (noisy or {}).items():
        sd[methods.index(m)] *= float(k)

    def noise(shape):
        if df is None:
            return rng.normal(0.0, 1.0, shape)
        return rng.standard_t(df, shape) * math.sqrt((df - 2.0) / df)

    out = {m: level + noise(lead + (n_walks, len(methods))) * sd + rng.normal(0.0, 1.0, lead + (n_walks, 1))
           for m in _PATHS}
    for fid, d in (effect_noise_sd or {}).items():
        shift = np.zeros(len(methods))
        for m, sign in CLAIMED[fid].items():
            shift[methods.index(m)] = sign * d * noise_sd
        out[FINDINGS[fid][0]] = out[FINDINGS[fid][0]] + shift
    for metric, s in (shifts or {}).items():
        out[metric] = out[metric] + np.asarray(s, dtype=np.float64) * noise_sd
    return out


def configuration_shift(fid: str, methods=_METHODS, *, gap: float = 0.5, delta: float = 0.0,
                        level: float = 5.0) -> np.ndarray:
    """Per-method shift (noise SDs) on ``fid``'s metric that makes its claim false by ``delta``.

    ``delta = 0`` is the tied configuration (the boundary of the claim, where a test is most
    likely to say ``holds`` for a false claim): the claimed methods ``gap`` ahead of the rest,
    and one other method (the rival) tied with them; ``delta > 0`` puts the rival ``delta``
    ahead of the claimed methods (near-tied).  ``vo_similar``: the last method at exactly
    ``SIMILAR_RATIO`` times the first (plus ``delta``), the others 1.2 times it.
    """
    methods = list(methods)
    s = np.zeros(len(methods))
    if fid == "vo_similar":  # only the pair (last, first) at the boundary; the others in between
        s[1:-1] = 0.2 * level
        s[-1] = (SIMILAR_RATIO - 1.0) * level + delta
        return s
    _, form, group, _ = SPECS[fid]
    g, o = _split(methods, group)
    rival = o[0]
    if form in ("above_every", "below_every"):
        sign = 1.0 if form == "above_every" else -1.0
        s[g] = sign * gap
        s[rival] = sign * (gap + delta)
    elif form == "below_mean":  # the first claimed method at the others' mean, the rest of the group below it
        s[g] = -gap
        s[g[0]] = delta
    else:  # not_lowest: the claimed method tied lowest with the rival
        s[g] = -gap - delta
        s[rival] = -gap
    return s


def false_holds_rates(fid: str, n_walks: int, *, delta: float = 0.0, gap: float = 0.5, n_studies: int = 400,
                      seed=0, noisy: dict | None = None, df: float | None = None) -> dict[str, float]:
    """Fraction of ``n_studies`` simulated studies in which the false claim ``fid`` (:func:`configuration_shift`)
    is judged ``holds``: ``raw`` (its own test at alpha: the worst case, every other claim of the family
    rejected) and ``verdict`` (Holm across the family, the other claims false as well)."""
    metric = _metric_of(fid)
    t = simulated_tables(n_walks, seed=seed, n_studies=n_studies, noisy=noisy, df=df,
                         shifts={metric: configuration_shift(fid, gap=gap, delta=delta)})
    v = batch_verdicts(t)[fid]
    return {"raw": float(np.mean(v["raw_holds"])), "verdict": float(np.mean(v["verdict"] == 1))}


def finding_power(fid: str, effect_noise_sd: float, n_walks: int, *, n_seeds: int = 100, seed=0,
                  noisy: dict | None = None, df: float | None = None) -> float:
    """Fraction of simulated studies of ``n_walks`` in which finding ``fid`` with a true effect of
    ``effect_noise_sd`` per-walk noise SDs is judged ``holds`` (Holm across all findings included)."""
    t = simulated_tables(n_walks, effect_noise_sd={fid: effect_noise_sd}, seed=seed, n_studies=n_seeds, noisy=noisy,
                         df=df)
    return float(np.mean(batch_verdicts(t)[fid]["verdict"] == 1))
