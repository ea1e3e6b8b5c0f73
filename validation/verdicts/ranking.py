"""What the live-versus-emulated verdict needs beside omega2: the resampling plan over the study's design,
the margin in ranking terms, each method's emulation bias, and the pairwise check.

* :func:`walk_labels`: the scene and the seed of each walk name ``<scene>/seed<S>``;
* :func:`cluster_plan`: bootstrap resamples of the walks with the seeds as clusters (the
  walks of one seed are drawn together, so every resample keeps each scene's share of the
  walks: stratified by scene); without labels every walk is its own cluster;
* :func:`over_plan`: a statistic of walks x methods tables over every resample of a plan;
* :func:`margin_in_ranking_terms`: what an interaction of a given omega2 does to the
  ranking of the study's live method means: the expected Kendall tau between live and
  emulated, and the probability that the best method changes;
* :func:`emulation_bias`: per method the walk mean of emulated - live with its interval and
  its share of the interaction's residual variance (a method whose emulation is far noisier
  than the others' shows there, instead of being averaged into omega2);
* :func:`pairs_check`: the pairwise primary check beside omega2: on every pair of methods
  that live separates, is the difference of differences (emulated - live) within the
  metric's equivalence margin?
"""

from __future__ import annotations

import math

import numpy as np

from emulator.core.stats import kendall_tau_b, percentile_interval, rng_of
from validation.verdicts.claims import holm_rows, one_sided_p

__all__ = ["walk_labels", "finite_or_none", "cluster_plan", "over_plan", "margin_in_ranking_terms", "emulation_bias",
           "pairs_check"]


def walk_labels(walks) -> tuple[list[str], list[int]]:
    """(scenes, seeds) of walk names ``<scene>/seed<S>`` (the names of :mod:`validation.live.evidence`; the seed
    is the walk's cluster in :func:`cluster_plan`); a malformed name is a ValueError."""
    scenes, seeds = [], []
    for w in walks:
        scene, _, seed = str(w).rpartition("/seed")
        if not scene or not seed.isdigit():
            raise ValueError(f"walk name {w!r} is not <scene>/seed<S>")
        scenes.append(scene)
        seeds.append(int(seed))
    return scenes, seeds


def cluster_plan(n_walks: int, n_resamples: int, seed=0, clusters=None):
    """Resamples of ``n_walks`` walks: an (n_resamples, n_walks) index array when every cluster has as many
    walks, else a list of index arrays (a resample has the walks of the clusters it draws).

    ``clusters``: one label per walk (the walk's seed); None: each walk its own cluster.
    """
    rng = rng_of(seed)
    if clusters is None:
        return rng.integers(0, n_walks, size=(n_resamples, n_walks))
    labels = np.asarray(list(clusters))
    if labels.shape != (n_walks,):
        raise ValueError(f"clusters must give one label per walk ({n_walks}), got {labels.shape}")
    _, inv = np.unique(labels, return_inverse=True)
    members = [np.flatnonzero(inv == k) for k in range(inv.max() + 1)] if n_walks else []
    pick = rng.integers(0, len(members), size=(n_resamples, len(members)))
    if len({m.size for m in members}) <= 1:
        return np.stack(members)[pick].reshape(n_resamples, -1)
    return [np.concatenate([members[c] for c in row]) for row in pick]


def over_plan(fn, plan, *tables) -> np.ndarray:
    """``fn(*resampled tables)`` for every resample of ``plan`` (vectorised when the plan is one array)."""
    if isinstance(plan, np.ndarray):
        return np.asarray(fn(*(t[plan] for t in tables)))
    return np.array([fn(*(t[p] for t in tables)) for p in plan])


def margin_in_ranking_terms(live_means, omega2: float, *, higher_is_better: bool = True, n_draws: int = 4000,
                            seed=0) -> dict | None:
    """Expected Kendall tau-b (live vs emulated method means) and the probability that the best method changes
    when the emulated method effects are the live ones plus an interaction of variance ``omega2`` times theirs.

    Computed on ``live_means`` (the study's live walk means per method: its spacings), with
    ``n_draws`` Gaussian draws of the interaction.  None when live ties every method.
    """
    b = np.asarray(live_means, dtype=np.float64)
    if b.size < 2 or not np.all(np.isfinite(b)) or np.ptp(b) == 0:
        return None
    b = b - b.mean()
    sd = float(b.std(ddof=1))
    rng = rng_of(seed)
    e = b + rng.normal(0.0, math.sqrt(max(omega2, 0.0)) * sd, (n_draws, b.size))
    sign = 1.0 if higher_is_better else -1.0
    tau = kendall_tau_b(np.broadcast_to(b, e.shape), e)
    return {"omega2": float(omega2), "expected_kendall_tau": float(np.nanmean(tau)),
            "best_method_changes_probability": float(np.mean(np.argmax(sign * e, axis=1) != np.argmax(sign * b))),
            "draws": int(n_draws)}


def emulation_bias(live, emulated, methods, plan, *, confidence: float = 0.95) -> dict:
    """Per method: walk mean of emulated - live with its bootstrap interval over ``plan``, the SD over walks,
    and its share of the residual (walk x method) variance of emulated - live."""
    d = np.asarray(emulated, dtype=np.float64) - np.asarray(live, dtype=np.float64)
    boot = over_plan(lambda x: x.mean(axis=-2), plan, d)
    lo, hi = percentile_interval(boot, confidence, axis=0)
    r = d - d.mean(axis=0) - d.mean(axis=1, keepdims=True) + d.mean()
    ss = (r ** 2).sum(axis=0)
    share = ss / ss.sum() if ss.sum() > 0 else np.full(d.shape[1], np.nan)
    out = {}
    for k, m in enumerate(methods):
        out[m] = {"mean": float(d[:, k].mean()), "ci95": [finite_or_none(lo[k]), finite_or_none(hi[k])],
                  "sd_over_walks": float(d[:, k].std(ddof=1)) if d.shape[0] > 1 else None,
                  "residual_variance_share": finite_or_none(share[k])}
    return out


def finite_or_none(v) -> float | None:
    """``v`` as a float, or None where it is None or not finite (how a verdict records a p or an omega2)."""
    return None if v is None or not math.isfinite(float(v)) else float(v)


def pairs_check(dod, margin: float | None, *, alpha: float = 0.05) -> dict:
    """The pairwise verdict on the pairs live separates: ``dod`` (walks, pairs) of emulated - live differences.

    ``agrees`` when every pair's difference of differences lies within ``(-margin, margin)``
    (TOST per pair at ``alpha``, all of them: intersection-union, so no correction; the same
    as every pair's 90 % t interval inside the margin); ``disagrees`` when some pair lies
    significantly outside it (one-sided t-test beyond the margin on either side, both sides
    and every pair in one Holm family); ``undetermined`` otherwise, without a margin, or
    when live separates no pair.  ``bound``: the largest |end| of the pairs' 90 % intervals.
    """
    from scipy.stats import t as student_t

    d = np.asarray(dod, dtype=np.float64)
    out = {"verdict": "undetermined", "reason": "", "n_pairs": int(d.shape[1]) if d.ndim == 2 else 0,
           "margin": margin, "bound": None, "p_outside_adjusted": None,
           "family": "per metric and comparison: the pairs live separates (Holm across the pairs)"}
    if margin is None:
        out["reason"] = "no equivalence margin for this metric"
        return out
    if d.ndim != 2 or d.shape[1] == 0:
        out["reason"] = "live separates no pair of methods: nothing to check"
        return out
    n = d.shape[0]
    mean, se = d.mean(axis=0), d.std(axis=0, ddof=1) / math.sqrt(n)
    q = student_t.ppf(1.0 - alpha, n - 1)
    bound = float(np.max(np.maximum(np.abs(mean - q * se), np.abs(mean + q * se))))
    above, _ = one_sided_p(d - margin, axis=0)
    _, below = one_sided_p(d + margin, axis=0)
    p_out = float(np.nanmin(holm_rows(np.concatenate([above, below]))))
    out.update(bound=bound, p_outside_adjusted=p_out)
    if bound < margin:
        out["verdict"] = "agrees"
        out["reason"] = f"every pair's 90 % interval of the difference of differences within +-{margin:g} ({bound:.3g})"
    elif p_out < alpha:
        out["verdict"] = "disagrees"
        out["reason"] = f"a pair lies beyond the margin {margin:g} (Holm-adjusted p = {p_out:.2g})"
    else:
        out["reason"] = f"the widest pair interval reaches {bound:.3g}, beyond the margin {margin:g}: not decided"
    return out
