"""Level shifts, scenes, and the scene that carries a verdict.

omega2 compares the methods' effects: an emulator that moves every method by the same amount
(emulated native's matches 48-109 below live in the committed studies) scores 0.  Beside it:

* :func:`level_shift`: per metric the paired mean difference emulated minus live over the
  walks and methods, relative to live's mean, with a bootstrap interval over the walk clusters
  (the seeds), judged against a stated margin (:data:`LEVEL_MARGIN`, 10 % of live's level):
  ``within`` when the 90 % interval lies inside it (two one-sided tests at 5 %), ``beyond``
  when it lies wholly outside, else ``undetermined``;
* :func:`per_scene`: omega2 (untruncated) and the relative level shift on each scene's walks;
* :func:`leave_one_scene_out`: the headline family (:func:`validation.live.monte_carlo.headline_family`,
  Holm included) recomputed with each scene's walks left out; a verdict that changes when one
  scene goes is carried by that scene (``carried_by``).

``exposim validate level-shift OUT`` prints them for a study folder's ``walks.csv``
without writing into the folder (:mod:`validation.verdict_studies.live_checks`).
"""

from __future__ import annotations

import numpy as np

from emulator.core.stats import percentile_interval, variance_components
from validation.live.config import COMPARISONS, HEADLINE_COMPARISONS
from validation.live.monte_carlo import headline_family, ruled_verdict
from validation.verdicts.agreement import omega2_untruncated
from validation.verdicts.ranking import cluster_plan, over_plan, walk_labels

__all__ = ["LEVEL_MARGIN", "SHIFT_METRICS", "level_shift", "per_scene", "leave_one_scene_out"]

#: Largest relative level shift (emulated minus live, over live's mean) that counts as none.
LEVEL_MARGIN = 0.10
#: Metrics with a level (the RPE rank's mean is fixed by construction).
SHIFT_METRICS = ("median_uniformity", "median_matches", "segment_success_rate_tau100", "vo_failed_frames",
                 "rpe_trans_pct")


def _relative(live, emulated):
    lm = live.mean(axis=(-2, -1))
    return np.where(lm != 0, (emulated - live).mean(axis=(-2, -1)) / np.where(lm != 0, lm, 1.0), np.nan)


def level_shift(live, emulated, clusters=None, *, n_resamples: int = 1000, seed=0,
                margin: float = LEVEL_MARGIN) -> dict:
    """The relative level shift of ``emulated`` against ``live`` ((walks, methods) tables; complete walks):
    ``relative`` = mean(emulated - live) / mean(live), its 95 % and 90 % percentile intervals over a bootstrap of
    the walks (``clusters``: one label per walk, resampled together), the absolute mean difference with its 95 %
    interval, and ``verdict`` against ``margin`` (see the module)."""
    L, E = np.asarray(live, dtype=np.float64), np.asarray(emulated, dtype=np.float64)
    ok = np.all(np.isfinite(L) & np.isfinite(E), axis=1)
    L, E = L[ok], E[ok]
    out = {"n_walks": int(L.shape[0]), "margin": margin, "relative": None, "relative_ci95": [None, None],
           "relative_ci90": [None, None], "absolute": None, "absolute_ci95": [None, None], "verdict": "undetermined"}
    if L.shape[0] < 2:
        return out
    plan = cluster_plan(L.shape[0], n_resamples, seed, None if clusters is None else np.asarray(clusters)[ok])
    absolute = over_plan(lambda a, b: (b - a).mean(axis=(-2, -1)), plan, L, E)
    out["absolute"] = float((E - L).mean())
    out["absolute_ci95"] = [float(v) for v in percentile_interval(absolute, 0.95)]
    rel = float(_relative(L, E))
    if not np.isfinite(rel):
        out["reason"] = "live's mean is 0: no relative shift"
        return out
    reps = over_plan(_relative, plan, L, E)
    lo90, hi90 = (float(v) for v in percentile_interval(reps, 0.90))
    out.update(relative=rel, relative_ci95=[float(v) for v in percentile_interval(reps, 0.95)],
               relative_ci90=[lo90, hi90])
    if -margin <= lo90 and hi90 <= margin:
        out["verdict"] = "within"
    elif lo90 > margin or hi90 < -margin:
        out["verdict"] = "beyond"
    return out


def per_scene(live, emulated, scenes) -> dict:
    """{scene: {n_walks, omega2_untruncated, relative_shift}} on each scene's complete walks (omega2 None where live
    shows no method effect on the scene: its method variance component at or below 0)."""
    L, E = np.asarray(live, dtype=np.float64), np.asarray(emulated, dtype=np.float64)
    ok = np.all(np.isfinite(L) & np.isfinite(E), axis=1)
    scenes = np.asarray(list(scenes))
    out = {}
    for s in dict.fromkeys(scenes.tolist()):
        rows = ok & (scenes == s)
        n = int(rows.sum())
        separates = n >= 2 and variance_components(L[rows])[0] > 1e-12 * max(1.0, float(np.mean(L[rows] ** 2)))
        o2 = float(omega2_untruncated(L[rows], E[rows])) if separates else None  # no live method effect: undefined
        rel = float(_relative(L[rows], E[rows])) if n else None
        out[s] = {"n_walks": n, "omega2_untruncated": o2 if o2 is None or np.isfinite(o2) else None,
                  "relative_shift": rel if rel is None or np.isfinite(rel) else None}
    return out


def leave_one_scene_out(tables: dict, walks, methods, *, seed: int = 0, n_resamples: int = 1000,
                        excluded: dict | None = None, monte_carlo_rule: bool = False) -> dict:
    """Per headline verdict (``"<comparison>: <metric>"``): its family verdict on every walk, on the walks of each
    scene but one (``without``: scene -> verdict), and ``carried_by``: the scenes whose leaving out changes it.
    ``excluded``, ``monte_carlo_rule``: a pre-registered study's family (metrics left out) and its verdicts after
    the Monte Carlo rule (:func:`validation.live.monte_carlo.ruled_verdict`)."""
    walks = list(walks)
    scenes = walk_labels(walks)[0]

    def verdicts(tabs, names):
        fam = headline_family(tabs, names, methods, seed=seed, n_resamples=n_resamples, excluded=excluded)
        return {k: ruled_verdict(r) if monte_carlo_rule else r["verdict"] for k, r in fam.items()}

    out = {k: {"verdict": v, "without": {}, "carried_by": []} for k, v in verdicts(tables, walks).items()}
    for s in dict.fromkeys(scenes):
        keep = np.array([x != s for x in scenes])
        sub = {run: {m: np.asarray(t)[keep] for m, t in per.items()} for run, per in tables.items()}
        for k, v in verdicts(sub, [w for w, k in zip(walks, keep) if k]).items():
            out[k]["without"][s] = v
            if v != out[k]["verdict"]:
                out[k]["carried_by"].append(s)
    return out
