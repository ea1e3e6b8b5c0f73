"""The verdict rule calibrated on the emulator's own residuals.

The plasmode (:mod:`validation.verdicts.plasmode`) takes the re-seeded live run as its perfect
emulator; on the committed 48-walk studies the emulator's own walk x method residuals are 1.2-1.5
times larger (cycle-rate emulation) and 2-3.5 times larger (emulated native), so that calibration is
optimistic.  Here the perfect emulator is the emulated table itself with its per-method mean bias
removed within each scene:

    perfect = live + r,   r[w, m] = (d[w, m] - mean of d[., m] over the walks of w's scene) * sqrt(n / (n - 1))

with ``d = emulated - live`` and ``n`` the scene's walks (the factor undoes the shrinkage of removing a
mean from ``n`` values).  A study of ``k`` seeds is drawn with replacement from the study's seeds (each
with its walks: the walk cluster), and the emulator of a scenario is ``perfect`` plus method effects of
a known omega2 (a random direction per drawn study, its variance over the methods exactly ``omega2``
times the live method-effect variance): :data:`SCENARIOS` 0 (perfect), 0.1, 0.2 (the margin) and 0.3.
The verdict rule (:func:`validation.verdicts.agreement.judge_batch`, the one ``validate live`` runs, with
the drawn seeds as its clusters) judges each drawn study, at the verdict's own 5 % level and at the
level its family judges it at: for the headline, Holm's first step, 5 % over the family's size (a
Holm-adjusted verdict lies between the two).  ``walks_to_decide`` is then the fewest walks at which a
study whose true omega2 is the observed one is judged as the estimate points in 80 % of drawn studies,
at that level.

Only seeds whose every walk is complete for the metric (in both tables) are drawn.  Like the plasmode,
it knows only the study's scenes and seeds.  ``exposim validate own-residuals OUT`` prints
it for a study folder's ``walks.csv`` without writing into the folder
(:mod:`validation.verdict_studies.own_residuals`); a pre-registered study's final look stores it
(:mod:`validation.live.final_checks`).
"""

from __future__ import annotations

import math

import numpy as np

from emulator.core.stats import rng_of, variance_components
from validation.verdicts.agreement import ALPHA, MIN_WALKS, OMEGA2_MAX, judge_batch, omega2_untruncated
from validation.verdicts.plasmode import TARGET, WALK_CANDIDATES, first_reaching, residual_sd
from validation.verdicts.ranking import cluster_plan, walk_labels

__all__ = ["SCENARIOS", "STUDIES", "RESAMPLES", "DEFINITION", "own_residuals", "scenario_rates",
           "metric_own_calibration", "study_own_calibration"]

#: True omega2 of the scenarios: perfect, half the margin, the margin, beyond it.
SCENARIOS = (0.0, 0.1, 0.2, 0.3)
#: Drawn studies per scenario and size (simulation error of a rate near 80 %: 2.8 points).
STUDIES = 200
#: Bootstrap resamples of the verdict rule in each drawn study (the rule's own count).
RESAMPLES = 1000
#: How the calibration is made, in words.
DEFINITION = ("perfect emulator = the emulated table less its per-method mean bias within each scene (the emulator's "
              "own walk x method residuals, rescaled by sqrt(n/(n-1))); studies of the study's own seeds (each with "
              "its walks) drawn with replacement; scenario omega2 = method effects of exactly that omega2 times the "
              "live method variance added, a random direction per drawn study; judged by the verdict rule at its own "
              "5 % and at Holm's first step of the family (5 % / family size)")


def own_residuals(live, emulated, scenes) -> tuple[np.ndarray, np.ndarray]:
    """(residuals, complete): ``emulated - live`` less its per-method mean within each scene, scaled by
    ``sqrt(n / (n - 1))`` (``n``: the scene's complete walks); NaN on incomplete walks and in scenes of one walk."""
    L, E = np.asarray(live, dtype=np.float64), np.asarray(emulated, dtype=np.float64)
    ok = np.all(np.isfinite(L) & np.isfinite(E), axis=1)
    d = E - L
    r = np.full_like(d, np.nan)
    scenes = np.asarray(list(scenes))
    for s in np.unique(scenes):
        rows = (scenes == s) & ok
        n = int(rows.sum())
        if n >= 2:
            r[rows] = (d[rows] - d[rows].mean(axis=0)) * math.sqrt(n / (n - 1))
    return r, ok & np.all(np.isfinite(r), axis=1)


def _clusters(complete, seeds) -> list[np.ndarray]:
    """Row indices of each seed whose every walk is complete, keeping the seeds of the commonest size (a drawn
    study then resamples with one plan)."""
    seeds = np.asarray(list(seeds))
    full = [np.flatnonzero(seeds == s) for s in np.unique(seeds) if np.all(complete[seeds == s])]
    if not full:
        return []
    sizes = [c.size for c in full]
    common = max(set(sizes), key=sizes.count)
    return [c for c in full if c.size == common]


def _batch(live, resid, clusters, k, omega2, live_var, n_studies, rng, n_resamples: int = RESAMPLES) -> dict:
    """The rule's arrays (:func:`~validation.verdicts.agreement.judge_batch`) over ``n_studies`` drawn studies of
    ``k`` seeds whose true omega2 is ``omega2`` (``n_resamples``: the rule's bootstrap resamples)."""
    members = np.stack(clusters)  # (seeds, walks per seed)
    rows = members[rng.integers(0, len(clusters), size=(n_studies, k))].reshape(n_studies, -1)
    m = live.shape[1]
    delta = rng.normal(size=(n_studies, m))
    delta -= delta.mean(axis=1, keepdims=True)
    sd = delta.std(axis=1, ddof=1, keepdims=True)
    delta *= np.where(sd > 0, math.sqrt(max(omega2, 0.0) * live_var) / np.where(sd > 0, sd, 1.0), 0.0)
    L = live[rows]
    E = L + resid[rows] + delta[:, None, :]
    plan = cluster_plan(rows.shape[1], n_resamples, rng, np.repeat(np.arange(k), members.shape[1]))
    return judge_batch(L, E, n_resamples=n_resamples, seed=rng, plan=plan, n_units=k)


def scenario_rates(batch: dict, k: int, levels: dict) -> dict:
    """{level name: {agrees, disagrees, undetermined}} of a batch, each verdict at its level's ``alpha`` (the
    p-values of the rule's one-sided bounds; undecidable: fewer than the rule's seeds, live not separating the
    methods at 5 %, or a tie)."""
    decidable = (k >= MIN_WALKS) & (batch["live_p"] < ALPHA) & ~batch["tied"]
    out = {}
    for name, a in levels.items():
        agrees = decidable & (batch["p_agrees"] <= a)
        disagrees = decidable & (batch["p_disagrees"] <= a) & ~agrees
        out[name] = {"agrees": float(agrees.mean()), "disagrees": float(disagrees.mean()),
                     "undetermined": float(1.0 - agrees.mean() - disagrees.mean())}
    return out


def _walks_to_decide(live, resid, clusters, omega2, live_var, alpha, n_studies, seed, target=TARGET,
                     n_resamples: int = RESAMPLES) -> dict:
    """Fewest walks (:data:`~validation.verdicts.plasmode.WALK_CANDIDATES`, bisected; the rule's fewest seeds at
    least) at which studies of true ``omega2`` are judged as it points (agrees at or below the margin) in
    ``target`` of them at level ``alpha``."""
    towards = "agrees" if omega2 <= OMEGA2_MAX else "disagrees"
    per = clusters[0].size
    ks = sorted({max(MIN_WALKS, math.ceil(n / per)) for n in WALK_CANDIDATES})
    tried = {}

    def rate(i):
        if i not in tried:
            b = _batch(live, resid, clusters, ks[i], omega2, live_var, n_studies, rng_of([*seed, ks[i]]), n_resamples)
            tried[i] = scenario_rates(b, ks[i], {"level": alpha})["level"][towards]
        return tried[i]

    i = first_reaching(rate, 0, len(ks) - 1, target)
    found = None if i is None else ks[i]
    return {"omega2": float(omega2), "towards": towards, "walks": None if found is None else found * per,
            "seeds": found, "extrapolated": None if found is None else found > len(clusters), "alpha": alpha,
            "target": target, "sizes_tried": [{"walks": ks[i] * per, towards: tried[i]} for i in sorted(tried)]}


def metric_own_calibration(live, emulated, scenes, seeds, *, reseeded=None, family_size: int = 1,
                           n_studies: int = STUDIES, seed=0, walks_to_decide: bool = True,
                           n_resamples: int = RESAMPLES) -> dict:
    """The calibration of one metric and comparison on the emulator's own residuals (see the module).

    Parameters
    ----------
    live, emulated : array_like
        (walks, methods) tables of the reference live run and the compared run.
    scenes, seeds : sequence
        Each walk's scene (the bias is removed within it) and seed (the walk cluster).
    reseeded : array_like, optional
        The reference re-seeded: the ratio of the emulator's residual SD to live-against-live's is reported.
    family_size : int
        Verdicts in the family (Holm's first step judges at 5 % / family_size).
    n_studies, seed
        Drawn studies per scenario and size; the draws' seed (an int or a list of ints).
    n_resamples : int
        Bootstrap resamples of the rule in each drawn study (the study's own: 1000, a pre-registered study's plan).
    """
    L, E = np.asarray(live, dtype=np.float64), np.asarray(emulated, dtype=np.float64)
    resid, complete = own_residuals(L, E, scenes)
    clusters = _clusters(complete, seeds)
    seed = [int(v) for v in np.atleast_1d(seed)]
    out = {"n_walks": int(L.shape[0]), "complete_walks": int(complete.sum()), "seeds_drawn_from": len(clusters),
           "family_size": int(family_size), "n_studies": int(n_studies),
           **({} if n_resamples == RESAMPLES else {"n_resamples": int(n_resamples)})}
    ok = np.zeros(L.shape[0], bool)
    if clusters:
        ok[np.concatenate(clusters)] = True
    if len(clusters) < 2 or ok.sum() < 4:
        return {**out, "status": "not computed", "reason": f"{len(clusters)} seed(s) with every walk complete: "
                "nothing to resample"}
    live_var = float(variance_components(L[ok])[0])
    est = float(omega2_untruncated(L[ok], E[ok]))
    own_sd = residual_sd(L[ok], E[ok])
    out.update(status="computed", live_method_variance=live_var, omega2_untruncated=est if math.isfinite(est) else None,
               residual_sd={"emulated": float(np.sqrt(np.mean(own_sd ** 2)))})
    if reseeded is not None:
        R = np.asarray(reseeded, dtype=np.float64)
        both = ok & np.all(np.isfinite(R), axis=1)
        if both.sum() >= 4:
            rs = float(np.sqrt(np.mean(residual_sd(L[both], R[both]) ** 2)))
            out["residual_sd"].update(reseeded=rs, ratio=out["residual_sd"]["emulated"] / rs if rs > 0 else None)
    if live_var <= 0:
        return {**out, "status": "not computed", "reason": "live shows no method effect on these walks"}
    levels = {"own 5 %": ALPHA, f"family: 5 % / {family_size}": ALPHA / max(family_size, 1)}
    k = len(clusters)
    out["scenarios"] = {f"omega2 {o:g}": scenario_rates(
        _batch(L, resid, clusters, k, o, live_var, n_studies, rng_of([*seed, 1, j]), n_resamples), k, levels)
        for j, o in enumerate(SCENARIOS)}
    if walks_to_decide and math.isfinite(est):
        out["walks_to_decide"] = _walks_to_decide(L, resid, clusters, max(est, 0.0), live_var,
                                                  ALPHA / max(family_size, 1), n_studies, [*seed, 2],
                                                  n_resamples=n_resamples)
    return out


def study_own_calibration(tables: dict, walks, *, comparisons: dict, metrics, family_size: int,
                          reseeded: dict | None = None, n_studies: int = STUDIES, seed: int = 0, **kw) -> dict:
    """:func:`metric_own_calibration` for every comparison (label -> (reference run, compared run)) and metric of
    ``tables`` ({run: {metric: walks x methods}}); ``walks``: names ``<scene>/seed<S>``; ``reseeded``: reference
    run -> its re-seeded run."""
    scenes, seeds = walk_labels(walks)
    out = {"definition": DEFINITION, "scenarios": list(SCENARIOS),
           "n_studies": int(n_studies), "seed": int(seed), "family_size": int(family_size), "comparisons": {}}
    for c, (label, (ref, other)) in enumerate(comparisons.items()):
        if ref not in tables or other not in tables:
            out["comparisons"][label] = {"status": "not run"}
            continue
        rs = (reseeded or {}).get(ref)
        out["comparisons"][label] = {"reference": ref, "compared": other, "metrics": {
            metric: metric_own_calibration(tables[ref][metric], tables[other][metric], scenes, seeds,
                                           reseeded=tables[rs][metric] if rs in tables else None,
                                           family_size=family_size, n_studies=n_studies, seed=[seed, 44_001, c, i],
                                           **kw)
            for i, metric in enumerate(metrics) if metric in tables[ref] and metric in tables[other]}}
    return out
