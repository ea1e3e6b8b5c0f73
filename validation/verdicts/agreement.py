"""Does an emulated condition judge the AE methods as a live one does?  One metric, many walks.

The unit of replication is an independent walk (scene x trajectory seed x render seed x
noise seed).  On each walk every method runs live, emulated, and live again with other
capture-noise seeds (the control); all three share the walk's renders (common random
numbers).  For one metric this gives three walks x methods tables ``live``, ``emulated``
and ``control``.

Estimand (per metric): the method x condition interaction, the method contrasts
emulated minus the same contrasts live.  With :func:`emulator.core.stats.variance_components`
(two-way, walks x methods, unbiased for the variance of the method effects over the
methods)::

    omega2 = var_m(method effect of emulated - live) / var_m(method effect of live)

0 for an emulator that orders and spaces the methods as live does, about 2 for one whose
method effects are unrelated to live's (same spread, random order), 1 for one that ties
every method.  The interval: the untruncated statistic (the interaction component may be
negative when noise explains it all) is bootstrapped over the walks (the seeds as clusters
where the study gives them: :func:`validation.verdicts.ranking.cluster_plan`); its one-sided
95 % lower bound is the bias-corrected (BC) percentile 5 % of the replicates, its upper bound
the plain percentile 95 % (the BC upper bound was measured too low: :func:`one_sided_bounds`),
and both are truncated at 0 afterwards (``omega2_ci90``: each end a one-sided 95 % bound).
Error rates of the rule, measured on simulated studies, are in docs/verdicts.md.

Verdict (:func:`judge`), in this order:

1. ``undetermined`` with fewer than :data:`MIN_WALKS` complete walks, or, where the walks are
   clustered by seed, fewer than :data:`MIN_WALKS` seeds (a bootstrap of so few units has too
   few distinct resamples to be an interval: 3 seeds give 10);
2. ``undetermined`` when live does not separate the methods (the live method effects are
   not significant: two-way F test, p >= :data:`ALPHA`; every method tied live included):
   there is no ranking to agree with, and a tie never counts as agreement;
3. ``agrees`` when the one-sided 95 % upper bound of omega2 is at most :data:`OMEGA2_MAX`;
4. ``disagrees`` when its one-sided 95 % lower bound is above :data:`OMEGA2_MAX`;
5. otherwise ``undetermined``: the interval straddles :data:`OMEGA2_MAX` (the reason
   gives the interval and the walks a decision needs, from :mod:`validation.verdicts.power`).

Beside it, a second primary check on pairs (:func:`validation.verdicts.ranking.pairs_check`):
per pair of methods that differs live (paired t-test, Holm over the pairs), a TOST
equivalence test of the difference of differences within the metric's stated margin
(``pairs_verdict``).  Reported, not part of either rule: the margin in ranking terms (the
expected Kendall tau and the probability that the best method changes at omega2 =
:data:`OMEGA2_MAX` on the study's live spacings), each method's emulation bias (emulated -
live) with its interval, the disattenuated correlation of the method effects between the
conditions (with interval), and Kendall tau-b of the walk-mean method values live vs
emulated against tau-b live vs control (its bootstrap distribution).
"""

from __future__ import annotations

import numpy as np

from emulator.core.stats import (
    covariance_components,
    holm,
    kendall_tau_b,
    percentile_interval,
    rng_of,
    tost_paired,
    variance_components,
)
from validation.verdicts.interaction import (
    ALPHA,
    OMEGA2_MAX,
    bound_pvalues,
    complete_walks,
    omega2,
    omega2_over_plan,
    omega2_untruncated,
    one_sided_bounds,
    pvalues_of_fraction,
)
from validation.verdicts.ranking import (
    cluster_plan,
    emulation_bias,
    finite_or_none,
    margin_in_ranking_terms,
    over_plan,
    pairs_check,
)

# ALPHA, OMEGA2_MAX and the omega2 statistics live in validation.verdicts.interaction; given here too, as before
__all__ = ["ALPHA", "OMEGA2_MAX", "MIN_WALKS", "VERDICTS", "complete_walks", "omega2", "omega2_untruncated",
           "omega2_over_plan", "one_sided_bounds", "bound_pvalues", "pvalues_of_fraction", "judge_batch", "judge"]

#: Fewest complete walks for a verdict other than undetermined: below 10, a perfect emulator was judged
#: ``disagrees`` in up to 7 % of simulated studies (5 walks, noise 2.8 method SD; docs/verdicts.md), at 10
#: and more in at most 2 % (noise 1 to 7 method SD).
MIN_WALKS = 10
#: The verdicts of :func:`judge`.
VERDICTS = ("agrees", "disagrees", "undetermined")


def _disattenuated(live, emulated) -> np.ndarray:
    s_l, _ = variance_components(live)
    s_e, _ = variance_components(emulated)
    c, _ = covariance_components(live, emulated)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = c / np.sqrt(s_l * s_e)
    return np.where((s_l > 0) & (s_e > 0), np.clip(r, -1.0, 1.0), np.nan)


def _live_f_test(live) -> tuple[np.ndarray, np.ndarray]:
    """(F, p) of the method effect in walks x methods tables (two-way, no replication; leading axes vectorised)."""
    from scipy.stats import f as f_dist

    live = np.asarray(live, dtype=np.float64)
    u, m = live.shape[-2:]
    s, resid = variance_components(live)
    ms_methods = s * u + resid
    with np.errstate(divide="ignore", invalid="ignore"):
        F = np.where(resid > 0, ms_methods / resid, np.where(ms_methods > 0, np.inf, 0.0))
    return F, f_dist.sf(F, m - 1, (u - 1) * (m - 1))


def judge_batch(live, emulated, *, n_resamples: int = 1000, seed=0, omega2_max: float = OMEGA2_MAX,
                alpha: float = ALPHA, min_walks: int = MIN_WALKS, chunk: int = 32, plan=None,
                n_units: int | None = None) -> dict[str, np.ndarray]:
    """The verdict rule of :func:`judge` on many complete studies at once (the calibration's loop).

    ``live``, ``emulated``: (studies, walks, methods), every value finite.  Returns arrays
    over the studies: ``verdict`` (index into :data:`VERDICTS`), ``omega2`` (truncated),
    ``omega2_untruncated``, ``lo``, ``hi`` (the one-sided 95 % bounds, :func:`one_sided_bounds`, over
    ``n_resamples`` bootstrap resamples: ``plan`` when given, one plan for every study, else walks drawn
    independently), ``live_p`` (F test of the live method effect), ``tied`` (every method ties live on
    every walk).  ``n_units``: the independent units the bootstrap resamples (the seeds of a cluster ``plan``;
    default the walks): fewer than ``min_walks`` of them is never decidable.
    """
    L = np.asarray(live, dtype=np.float64)
    E = np.asarray(emulated, dtype=np.float64)
    n, w, m = L.shape
    units = w if n_units is None else int(n_units)
    rng = rng_of(seed)
    raw = omega2_untruncated(L, E)
    est = np.maximum(raw, 0.0)
    _, p = _live_f_test(L)
    lo = np.empty(n)
    hi = np.empty(n)
    p_agrees, p_disagrees = np.empty(n), np.empty(n)
    for a in range(0, n, chunk):
        b = min(n, a + chunk)
        if plan is None:
            idx = rng.integers(0, w, size=(b - a, n_resamples, w))
            rows = np.arange(b - a)[:, None, None]
            boot = omega2_untruncated(L[a:b][rows, idx], E[a:b][rows, idx])  # (chunk, resamples)
        else:
            boot = np.stack([omega2_over_plan(plan, L[k], E[k]) for k in range(a, b)])
        for k in range(b - a):
            lo[a + k], hi[a + k] = one_sided_bounds(boot[k], raw[a + k], alpha)
            p_agrees[a + k], p_disagrees[a + k] = bound_pvalues(boot[k], raw[a + k], omega2_max)
    tied = np.all(np.ptp(L, axis=2) == 0, axis=1)
    verdict = np.full(n, VERDICTS.index("undetermined"))
    decidable = (units >= min_walks) & (p < alpha) & ~tied  # a tie's F is rounding noise: never decidable
    verdict[decidable & (hi <= omega2_max)] = VERDICTS.index("agrees")
    verdict[decidable & (lo > omega2_max)] = VERDICTS.index("disagrees")
    return {"verdict": verdict, "omega2": est, "omega2_untruncated": raw, "lo": lo, "hi": hi, "live_p": p,
            "tied": tied, "p_agrees": p_agrees, "p_disagrees": p_disagrees}


def _interval(lo, hi):
    """[lo, hi] for results.json: an unbounded end is None (JSON has no infinity)."""
    return [finite_or_none(lo), finite_or_none(hi)]


def _covering(estimate, lo, hi):
    """A percentile interval widened, where needed, to hold its own estimate.

    Kendall tau is bounded and takes few values: at 1 (or -1) every bootstrap replicate lies on one
    side, and the percentile interval can leave the estimate out (tau live-live 1.0 [0.24, 0.90] in
    a 48-walk study).  The end beyond the estimate moves to it; an interval that holds it is kept."""
    if not np.isfinite(estimate):
        return lo, hi
    return (min(lo, estimate) if np.isfinite(lo) else lo), (max(hi, estimate) if np.isfinite(hi) else hi)


def _tau_interval(L, X, plan, alpha):
    """Kendall tau between the method means of ``L`` and ``X`` (walks x methods), its replicates over
    ``plan``, and its interval for results.json (:func:`_covering`: it holds the estimate)."""
    tau = kendall_tau_b(L.mean(axis=0), X.mean(axis=0))
    reps = over_plan(lambda a, b: kendall_tau_b(a.mean(axis=-2), b.mean(axis=-2)), plan, L, X)
    return tau, reps, _interval(*_covering(tau, *_nan_interval(reps, alpha)))


def judge(live, emulated, control=None, *, methods=None, margin: float | None = None,
          higher_is_better: bool = True, n_resamples: int = 1000, seed=0, omega2_max: float = OMEGA2_MAX,
          alpha: float = ALPHA, min_walks: int = MIN_WALKS, detail: bool = True, clusters=None) -> dict:
    """The verdict on one metric: does ``emulated`` order the methods as ``live`` does?

    Parameters
    ----------
    live, emulated : array_like
        (walks, methods) values of the metric; walks with a non-finite value in either
        (or in ``control``) are left out.
    control : array_like, optional
        (walks, methods), live again with other capture-noise seeds: tau(live, live).
    methods : sequence of str, optional
        Names of the columns (for the pair tests and the biases).
    margin : float, optional
        Equivalence margin of the difference of differences, in the metric's unit
        (the pairwise check is undetermined without one).
    higher_is_better : bool
        Orients the reported pair differences and "the best method".
    n_resamples, seed
        Bootstrap over walks.
    detail : bool
        Also compute the pairwise check, biases, margin in ranking terms, pair tests and taus
        (False: the verdict and omega2 only; what the calibration loops need).
    clusters : sequence, optional
        One label per walk (its seed): the walks of one label are resampled together
        (:func:`validation.verdicts.ranking.cluster_plan`); None: every walk on its own.

    Returns
    -------
    dict
        ``verdict``, ``reason``, ``family``, ``n_walks``, ``omega2``, ``omega2_untruncated``,
        ``omega2_ci90`` ([lo, hi]: one-sided 95 % bounds; None for an unbounded end),
        ``live_method_f``/``live_method_p``, and with ``detail`` ``pairs_verdict`` (the
        pairwise check), ``margin_in_ranking_terms``, ``emulation_bias`` (per method),
        ``disattenuated_correlation`` (+ ``_ci95``), ``tau_live_emulated``,
        ``tau_live_live`` (+ ``_ci95`` and ``tau_emulated_below_control_fraction``),
        ``pairs`` (per pair of methods: live difference, its Holm-adjusted p, and for the
        significant ones the difference of differences with TOST p against ``margin``).
    """
    L = np.asarray(live, dtype=np.float64)
    E = np.asarray(emulated, dtype=np.float64)
    C = None if control is None else np.asarray(control, dtype=np.float64)
    if L.shape != E.shape or L.ndim != 2 or (C is not None and C.shape != L.shape):
        raise ValueError(f"live, emulated (and control) must be walks x methods tables of one shape, got "
                         f"{L.shape}, {E.shape}{'' if C is None else ', ' + str(C.shape)}")
    if clusters is not None and len(clusters) != L.shape[0]:
        raise ValueError(f"clusters must give one label per walk ({L.shape[0]}), got {len(clusters)}")
    ok = complete_walks(L, E, C) if L.shape[0] else np.zeros(0, bool)
    L, E = L[ok], E[ok]
    C = None if C is None else C[ok]
    w, m = L.shape
    names = list(methods) if methods is not None else [str(i) for i in range(m)]
    out = {"n_walks": int(w), "n_clusters": None, "verdict": "undetermined", "reason": "", "family": FAMILY, "omega2": None,
           "omega2_untruncated": None, "omega2_ci90": [None, None], "omega2_max": omega2_max,
           "omega2_interval": INTERVAL, "live_method_f": None, "live_method_p": None, "p_agrees": None,
           "p_disagrees": None}
    if detail:
        out.update({"pairs_verdict": None, "margin_in_ranking_terms": None, "emulation_bias": None,
                    "disattenuated_correlation": None, "disattenuated_correlation_ci95": [None, None],
                    "tau_live_emulated": None, "tau_live_emulated_ci95": [None, None], "tau_live_live": None,
                    "tau_live_live_ci95": [None, None], "tau_emulated_below_control_fraction": None,
                    "pairs": [], "margin": margin})
    if m < 2 or w < 2:
        out["reason"] = f"{w} complete walk(s) x {m} method(s): nothing to compare"
        return out
    rng = rng_of(seed)
    labels = None if clusters is None else np.asarray(list(clusters))[ok]
    units = w if labels is None else int(np.unique(labels).size)
    out["n_clusters"] = None if labels is None else units
    plan = cluster_plan(w, n_resamples, rng, labels)
    batch = judge_batch(L[None], E[None], n_resamples=n_resamples, seed=rng, omega2_max=omega2_max, alpha=alpha,
                        min_walks=min_walks, plan=plan, n_units=units)
    F, p = _live_f_test(L)
    p = float(p)
    out["live_method_f"], out["live_method_p"] = finite_or_none(F), p
    out["omega2"] = finite_or_none(batch["omega2"][0])
    out["omega2_untruncated"] = finite_or_none(batch["omega2_untruncated"][0])
    lo, hi = float(batch["lo"][0]), float(batch["hi"][0])
    out["omega2_ci90"] = _interval(lo, hi)
    out["p_agrees"], out["p_disagrees"] = finite_or_none(batch["p_agrees"][0]), finite_or_none(batch["p_disagrees"][0])
    if detail:
        _details(out, L, E, C, plan, names, margin, higher_is_better, alpha, omega2_max, rng)
        if units < min_walks:
            out["pairs_verdict"].update(verdict="undetermined", reason=_too_few(w, units, labels, min_walks))
    out["verdict"] = VERDICTS[int(batch["verdict"][0])]
    bounds = f"omega2 one-sided 95 % bounds [{lo:.3g}, {hi:.3g}]"
    if units < min_walks:
        out["reason"] = _too_few(w, units, labels, min_walks) + ": a bootstrap over so few is no interval"
    elif not p < alpha:
        out["reason"] = ("every method ties live on every walk: no ranking to agree with" if batch["tied"][0] else
                         f"live does not separate the methods (F test p = {p:.2g} >= {alpha}): no ranking to "
                         "agree with at this size")
    elif out["verdict"] == "agrees":
        out["reason"] = f"{bounds}: the upper bound is at or below {omega2_max}"
    elif out["verdict"] == "disagrees":
        out["reason"] = f"{bounds}: the lower bound is above {omega2_max}"
    else:
        out["reason"] = f"{bounds} straddle {omega2_max}: more walks needed"
    return out


def _too_few(w: int, units: int, labels, min_walks: int) -> str:
    if labels is None:
        return f"{w} complete walks, fewer than {min_walks}"
    return (f"{w} complete walks in {units} seeds, fewer than {min_walks} seeds (the bootstrap resamples seeds, "
            "each with its walks)")


#: How the omega2 interval is made, in words (results.json's ``omega2_interval``).
INTERVAL = ("bootstrap of the untruncated omega2 over walks (seeds as clusters where given): lower end the "
            "bias-corrected 5 % percentile, upper end the 95 % percentile (each a one-sided 95 % bound), truncated "
            "at 0")
#: The multiplicity family of an agreement verdict, in words.
FAMILY = ("one metric and one comparison: omega2's one-sided 95 % bounds, not corrected across metrics or "
          "comparisons")


def _details(out, L, E, C, plan, names, margin, higher_is_better, alpha, omega2_max, rng) -> None:
    from scipy.stats import ttest_1samp

    w, m = L.shape
    out["disattenuated_correlation"] = finite_or_none(_disattenuated(L, E))
    out["disattenuated_correlation_ci95"] = _interval(*_nan_interval(over_plan(_disattenuated, plan, L, E), alpha))
    mean_l = L.mean(axis=0)
    tau, tle, ci = _tau_interval(L, E, plan, alpha)
    out["tau_live_emulated"], out["tau_live_emulated_ci95"] = finite_or_none(tau), ci
    if C is not None:
        tau, tll, ci = _tau_interval(L, C, plan, alpha)
        out["tau_live_live"], out["tau_live_live_ci95"] = finite_or_none(tau), ci
        both = np.isfinite(tle) & np.isfinite(tll)
        out["tau_emulated_below_control_fraction"] = float(np.mean(tle[both] < tll[both])) if both.any() else None
    out["margin_in_ranking_terms"] = margin_in_ranking_terms(mean_l, omega2_max, higher_is_better=higher_is_better,
                                                             seed=rng)
    out["emulation_bias"] = emulation_bias(L, E, names, plan)
    i, j = np.triu_indices(m, 1)
    d_live = L[:, i] - L[:, j]  # (walks, pairs)
    d_emu = E[:, i] - E[:, j]
    with np.errstate(divide="ignore", invalid="ignore"):
        p_live = ttest_1samp(d_live, 0.0, axis=0).pvalue
    p_live = np.where(np.isnan(p_live), np.where(d_live.mean(axis=0) == 0, 1.0, 0.0), p_live)
    p_adj = holm(p_live)
    dod = d_emu - d_live
    p_tost = tost_paired(dod, margin) if margin is not None else np.full(i.size, np.nan)
    sign = 1.0 if higher_is_better else -1.0
    pairs = []
    for k in range(i.size):
        sig = bool(p_adj[k] < alpha)
        row = {"pair": [names[i[k]], names[j[k]]], "live_difference": float(sign * d_live[:, k].mean()),
               "emulated_difference": float(sign * d_emu[:, k].mean()), "live_p_adjusted": float(p_adj[k]),
               "live_significant": sig, "difference_of_differences": float(sign * dod[:, k].mean()),
               "tost_p": None, "equivalent": None}
        if sig and margin is not None:
            row["tost_p"] = float(p_tost[k])
            row["equivalent"] = bool(p_tost[k] < alpha)
        pairs.append(row)
    out["pairs"] = pairs
    sig = [r for r in pairs if r["live_significant"]]
    out["pairs_live_significant"] = len(sig)
    out["pairs_equivalent"] = sum(1 for r in sig if r["equivalent"]) if margin is not None else None
    out["pairs_reversed"] = sum(1 for r in sig if r["live_difference"] * r["emulated_difference"] < 0)
    out["pairs_verdict"] = pairs_check(dod[:, p_adj < alpha], margin, alpha=alpha)


def _nan_interval(rep, alpha):
    rep = np.asarray(rep, dtype=np.float64)
    rep = rep[np.isfinite(rep)]
    if rep.size < 2:
        return None, None
    return percentile_interval(rep, 1.0 - alpha)
