"""The paper's findings (section V-D) as statistics: effect size, cluster-bootstrap interval,
label-permutation null, Holm across findings.

The unit is an independent walk (a scene of the AE study with its seeds): per walk and
method the study's figures (``ae_study.summarise(...)["per_scene"][scene][method]``).
Every finding is an effect computed from the methods' walk means, signed so that a
positive effect is the paper's claim:

* ``effect``: on the observed walks;
* ``ci95``: percentile interval over a cluster bootstrap of the walks;
* ``p``: two-sided label-permutation test: the methods' labels are permuted within each
  walk (the null: the methods are interchangeable), the effect recomputed; ``p = 2 *
  min(P(perm >= obs), P(perm <= obs))`` with the +1 correction;
* ``p_adjusted``: Holm across the findings that are tested;
* ``verdict``: ``holds`` (p_adjusted < alpha, effect above the null), ``contradicted``
  (p_adjusted < alpha, effect below the null), ``undetermined`` otherwise or with fewer than
  :data:`~validation.verdicts.agreement.MIN_WALKS` walks, and ``by-construction`` for the
  findings that cannot fail whatever the methods do (not tested, not counted):
  success can only fall as tau rises (a run that keeps >= tau matches keeps >= a smaller
  tau), and "VO fails on some run" holds on one failed frame of one run.

``vo_similar`` (all methods similar in VO: largest / smallest translation RPE at most
1.5) is an equivalence claim, true under interchangeable methods, so it has no
permutation test: ``holds`` when the bootstrap interval of the ratio lies at or below 1.5,
``contradicted`` when above, else ``undetermined`` (noise alone no longer fails it).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from emulator.stats import holm, percentile_interval, rng_of
from validation.verdicts.agreement import ALPHA, MIN_WALKS

__all__ = ["FINDINGS", "BY_CONSTRUCTION", "CLAIMED", "unit_tables", "finding_effects", "evaluate", "simulated_tables",
           "finding_power"]

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


def _idx(methods, names):
    return [methods.index(n) for n in names]


def _others(methods, names):
    return [k for k, m in enumerate(methods) if m not in names]


def _top_vs_rest(target: str, higher: bool = True) -> Callable:
    """target minus the best of the others (higher), or the best of the others minus target (lower)."""
    def f(mean, methods):
        t = mean[..., methods.index(target)]
        o = mean[..., _others(methods, (target,))]
        return t - o.max(axis=-1) if higher else o.min(axis=-1) - t
    return f


def _group_below_rest(group, higher_is_worse: bool = False) -> Callable:
    """Each of ``group`` below the mean of the others: mean(others) - max(group) (or, for a metric where
    lower is better and the group is claimed worst, min(group) - mean(others))."""
    def f(mean, methods):
        g = mean[..., _idx(methods, group)]
        rest = mean[..., _others(methods, group)].mean(axis=-1)
        return g.min(axis=-1) - rest if higher_is_worse else rest - g.max(axis=-1)
    return f


def _mean_gap(group, lower_is_better: bool = True) -> Callable:
    """mean(others) - mean(group): the group is better on a lower-is-better metric."""
    def f(mean, methods):
        g = mean[..., _idx(methods, group)].mean(axis=-1)
        rest = mean[..., _others(methods, group)].mean(axis=-1)
        return rest - g if lower_is_better else g - rest
    return f


def _two_lowest(pair) -> Callable:
    """min of the others - max of the pair: both of the pair below every other method."""
    def f(mean, methods):
        return mean[..., _others(methods, pair)].min(axis=-1) - mean[..., _idx(methods, pair)].max(axis=-1)
    return f


def _fixed_not_best(mean, methods):
    """fixed minus the best (lowest) of the others: positive when some method beats fixed."""
    return mean[..., methods.index("fixed")] - mean[..., _others(methods, ("fixed",))].min(axis=-1)


#: Tested findings: id -> (metric, effect of the method walk means, what a positive effect says).
FINDINGS = {
    "fixed_most_matches": ("matches", _top_vs_rest("fixed"), "M_fixed's median matches minus the best other's"),
    "uniformity_70_kim_lower": ("uniformity", _group_below_rest(("classical-70", "kim")),
                                "mean uniformity of the others minus the higher of M_70% and M_Kim"),
    "fixed_best_success_sequences": ("success_seq_hi", _top_vs_rest("fixed"),
                                     "M_fixed's sequence success at the largest tau minus the best other's"),
    "poorest_success_30_70_kim_sequences": ("success_seq_hi", _group_below_rest(("classical-30", "classical-70", "kim")),
                                            "others' mean sequence success minus the best of M_30%, M_70%, M_Kim"),
    "fixed_best_success_segments": ("success_seg_hi", _top_vs_rest("fixed"),
                                    "M_fixed's segment success rate minus the best other's"),
    "poorest_success_30_70_kim_segments": ("success_seg_hi", _group_below_rest(("classical-30", "classical-70", "kim")),
                                           "others' mean segment success minus the best of M_30%, M_70%, M_Kim"),
    "rpe_trans_best_50": ("rpe_trans", _top_vs_rest("classical-50", higher=False),
                          "the best other translation RPE minus M_50%'s (%)"),
    "rpe_trans_worst_kim": ("rpe_trans", _top_vs_rest("kim", higher=True),
                            "M_Kim's translation RPE minus the worst other's (%)"),
    "rpe_rot_best_zhang_50": ("rpe_rot", _two_lowest(("zhang", "classical-50")),
                              "the lowest other rotation RPE minus the higher of M_Zhang and M_50% (deg/m)"),
    "fixed_not_best_vo": ("rpe_trans", _fixed_not_best, "M_fixed's translation RPE minus the best other's (%)"),
    "gradient_ahead_vo": ("rpe_trans", _mean_gap(("shim", "zhang")),
                          "others' mean translation RPE minus M_Shim's and M_Zhang's mean (%)"),
    "gradient_fewer_vo_failures": ("vo_failed", _mean_gap(("shim", "zhang")),
                                   "others' mean failed VO frames minus M_Shim's and M_Zhang's mean"),
}
#: Findings that cannot fail whatever the methods do: id -> why.
BY_CONSTRUCTION = {
    "success_falls_with_tau_sequences": "a run whose every pair has >= tau_hi matches has >= tau_lo matches too: the "
                                        "success rate cannot rise with tau",
    "success_falls_with_tau_segments": "as for sequences: a segment succeeding at the larger tau succeeds at the "
                                       "smaller",
    "vo_fails_on_some_runs": "holds on one failed VO frame of one run; no comparison of methods",
}
#: The equivalence finding: largest / smallest translation RPE at most this.
SIMILAR_RATIO = 1.5


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


def evaluate(tables: dict[str, np.ndarray], methods=_METHODS, *, n_resamples: int = 1000,
             n_permutations: int = 2000, seed=0, alpha: float = ALPHA, min_walks: int = MIN_WALKS) -> list[dict]:
    """Every finding of :data:`FINDINGS`, :data:`BY_CONSTRUCTION` and ``vo_similar`` with its evidence.

    ``tables``: :func:`unit_tables`.  Units with a missing value of a finding's metric are
    left out of that finding.  Returns a list of ``{id, effect, ci95, p, p_adjusted, verdict,
    n_walks, definition, reason}``.
    """
    rng = rng_of(seed)
    methods = list(methods)
    n_units = next(iter(tables.values())).shape[0]
    # one set of within-walk label permutations for every finding (each test stays exact; Holm allows dependence)
    perms = np.argsort(rng.random((n_permutations, n_units, len(methods))), axis=-1)
    rows = []
    for fid, (metric, f, definition) in FINDINGS.items():
        t = tables[metric]
        ok = np.all(np.isfinite(t), axis=1)
        t = t[ok]
        u = t.shape[0]
        row = {"id": fid, "effect": None, "ci95": [None, None], "p": None, "p_adjusted": None,
               "verdict": "undetermined", "n_walks": int(u), "definition": definition, "reason": ""}
        absent = [m for m in CLAIMED[fid] if m not in methods]
        if absent or len(methods) <= len(CLAIMED[fid]):
            row["reason"] = (f"method(s) {', '.join(absent)} not in this study" if absent
                             else "no other method to compare with")
            rows.append(row)
            continue
        if u == 0:
            row["reason"] = f"no walk with a {metric} value for every method"
            rows.append(row)
            continue
        est = float(f(t.mean(axis=0), methods))
        row["effect"] = est
        if u >= 2:
            boot = f(t[rng.integers(0, u, (n_resamples, u))].mean(axis=1), methods)
            lo, hi = percentile_interval(boot, 1.0 - alpha)
            row["ci95"] = [float(lo), float(hi)]
        # label permutation within each walk
        null = f(np.take_along_axis(t[None], perms[:, ok], axis=-1).mean(axis=1), methods)
        p_hi = (1 + np.sum(null >= est - 1e-12)) / (n_permutations + 1)
        p_lo = (1 + np.sum(null <= est + 1e-12)) / (n_permutations + 1)
        row["p"] = float(min(1.0, 2 * min(p_hi, p_lo)))
        row["_direction"] = "holds" if p_hi < p_lo else "contradicted"
        rows.append(row)
    tested = [r for r in rows if r["p"] is not None]
    adj = holm([r["p"] for r in tested])
    for r, a in zip(tested, adj):
        r["p_adjusted"] = float(a)
        direction = r.pop("_direction")
        if r["n_walks"] < min_walks:
            r["reason"] = f"{r['n_walks']} walks, fewer than {min_walks}: no interval over so few walks"
        elif a < alpha:
            r["verdict"] = direction
            r["reason"] = (f"permutation p = {r['p']:.3g}, Holm-adjusted {a:.3g} < {alpha}: the effect lies "
                           f"{'above' if direction == 'holds' else 'below'} what interchangeable methods give")
        else:
            r["reason"] = f"Holm-adjusted permutation p = {a:.3g} >= {alpha}: interchangeable methods give as much"
    rows.append(_similar(tables["rpe_trans"], rng, n_resamples, alpha, min_walks))
    for fid, why in BY_CONSTRUCTION.items():
        rows.append({"id": fid, "effect": None, "ci95": [None, None], "p": None, "p_adjusted": None,
                     "verdict": "by-construction", "n_walks": None, "definition": None,
                     "reason": f"cannot fail, not counted: {why}"})
    return rows


def _similar(t: np.ndarray, rng, n_resamples: int, alpha: float, min_walks: int) -> dict:
    t = t[np.all(np.isfinite(t), axis=1)]
    u = t.shape[0]
    row = {"id": "vo_similar", "effect": None, "ci95": [None, None], "p": None, "p_adjusted": None,
           "verdict": "undetermined", "n_walks": int(u),
           "definition": f"largest / smallest method mean translation RPE (holds at or below {SIMILAR_RATIO})",
           "reason": ""}
    if u == 0:
        row["reason"] = "no walk with a translation RPE for every method"
        return row

    def ratio(mean):
        mn = mean.min(axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(mn > 0, mean.max(axis=-1) / mn, np.inf)

    row["effect"] = float(ratio(t.mean(axis=0)))
    if u >= 2:
        lo, hi = percentile_interval(ratio(t[rng.integers(0, u, (n_resamples, u))].mean(axis=1)), 1.0 - alpha)
        row["ci95"] = [float(lo), None if not math.isfinite(hi) else float(hi)]
    else:
        lo, hi = -math.inf, math.inf
    if u < min_walks:
        row["reason"] = f"{u} walks, fewer than {min_walks}: no interval over so few walks"
    elif hi <= SIMILAR_RATIO:
        row["verdict"], row["reason"] = "holds", f"95 % interval [{lo:.3g}, {hi:.3g}] at or below {SIMILAR_RATIO}"
    elif lo > SIMILAR_RATIO:
        row["verdict"], row["reason"] = "contradicted", f"95 % interval [{lo:.3g}, {hi:.3g}] above {SIMILAR_RATIO}"
    else:
        row["reason"] = f"95 % interval [{lo:.3g}, {hi:.3g}] straddles {SIMILAR_RATIO}: equivalence not shown"
    return row


#: The methods a finding's claim is about, and the sign of the shift that makes the claim true on its metric.
CLAIMED = {
    "fixed_most_matches": ({"fixed": 1.0}),
    "uniformity_70_kim_lower": ({"classical-70": -1.0, "kim": -1.0}),
    "fixed_best_success_sequences": ({"fixed": 1.0}),
    "poorest_success_30_70_kim_sequences": ({"classical-30": -1.0, "classical-70": -1.0, "kim": -1.0}),
    "fixed_best_success_segments": ({"fixed": 1.0}),
    "poorest_success_30_70_kim_segments": ({"classical-30": -1.0, "classical-70": -1.0, "kim": -1.0}),
    "rpe_trans_best_50": ({"classical-50": -1.0}),
    "rpe_trans_worst_kim": ({"kim": 1.0}),
    "rpe_rot_best_zhang_50": ({"zhang": -1.0, "classical-50": -1.0}),
    "fixed_not_best_vo": ({"fixed": 1.0}),
    "gradient_ahead_vo": ({"shim": -1.0, "zhang": -1.0}),
    "gradient_fewer_vo_failures": ({"shim": -1.0, "zhang": -1.0}),
}


def simulated_tables(n_walks: int, *, effect_noise_sd: dict | None = None, noise_sd: float = 1.0, seed=0,
                     methods=_METHODS) -> dict[str, np.ndarray]:
    """Per-unit tables of every metric with interchangeable methods (noise ``noise_sd`` per walk and method, a
    walk level common to the methods), plus, per finding id in ``effect_noise_sd``, its claimed methods
    shifted in the claim's direction by that many noise SDs (:data:`CLAIMED`)."""
    rng = rng_of(seed)
    methods = list(methods)
    out = {m: 5.0 + rng.normal(0.0, noise_sd, (n_walks, len(methods))) + rng.normal(0.0, 1.0, (n_walks, 1))
           for m in _PATHS}
    for fid, d in (effect_noise_sd or {}).items():
        metric = FINDINGS[fid][0]
        shift = np.zeros(len(methods))
        for m, sign in CLAIMED[fid].items():
            shift[methods.index(m)] = sign * d * noise_sd
        out[metric] = out[metric] + shift
    return out


def finding_power(fid: str, effect_noise_sd: float, n_walks: int, *, n_seeds: int = 100, seed=0,
                  n_permutations: int = 2000) -> float:
    """Fraction of simulated studies of ``n_walks`` in which finding ``fid`` with a true effect of
    ``effect_noise_sd`` per-walk noise SDs is judged ``holds`` (Holm across all findings included)."""
    rng = rng_of(seed)
    hits = 0
    for _ in range(n_seeds):
        t = simulated_tables(n_walks, effect_noise_sd={fid: effect_noise_sd}, seed=rng)
        res = {r["id"]: r for r in evaluate(t, n_resamples=100, n_permutations=n_permutations, seed=rng)}
        hits += res[fid]["verdict"] == "holds"
    return hits / n_seeds
