"""The verdict rule calibrated on the study's own walks (a plasmode), not on a model of them.

A plasmode study is drawn from the real walks tables: ``k`` seeds, each with its walks
(one per scene: a seed is a cluster, so every draw keeps each scene's share of the walks),
drawn with replacement.  On each one the project's verdict rule itself
(:func:`validation.verdicts.agreement.judge`, what ``validate live`` runs, with the drawn
seeds as its clusters) judges an emulator whose truth is known:

* ``perfect``: the re-seeded live run of the same walks (same condition, other
  capture-noise seeds) stands in for the emulated table: everything a perfect emulator
  would still differ by (capture noise and the closed loop's response to it), as measured.
  Its method means minus live's over the study's walks are centred away (in a finite study
  they are noise; resampled as they are, they would become a true interaction of the
  plasmode's population, which the more walks are drawn the surer the rule finds);
* ``injected``: the re-seeded run plus known method effects whose variance over the methods
  is ``omega2`` times the live method-effect variance (measured on all the walks; a random
  direction per plasmode study, rescaled to that variance exactly), plus per-walk noise:
  Student t with 3 degrees of freedom (heavy tails), each method at the SD of its own
  residual in re-seeded - live, and one method (``noisy_method``, by default M_Kim where the
  study runs it, else the method with the largest residual) ``noisy_factor`` times noisier;
* ``random``: the re-seeded run with its method labels permuted (one permutation per
  plasmode study): method effects of the same spread, unrelated to live.

Reported per (reference, re-seeded) pair and metric: the rates of ``agrees`` /
``disagrees`` / ``undetermined`` of each emulator at the study's own number of seeds, and
the number of walks at which the perfect emulator is judged ``agrees`` in at least 80 % of
plasmode studies (a search over seed counts; counts beyond the study's seeds resample more
seeds than exist: an extrapolation, flagged).

Limits: the plasmode knows only the study's scenes and seeds (a seed drawn twice is two
walks with the same noise); the injected interactions are the kinds named above, not every
way an emulator can fail; with few seeds every draw repeats the same few walks.
"""

from __future__ import annotations

import math

import numpy as np

from emulator.core.stats import rng_of, variance_components
from validation.verdicts.agreement import MIN_WALKS, VERDICTS, judge

__all__ = ["STUDIES", "INJECTED_OMEGA2", "NOISY_FACTOR", "TARGET", "RESEEDED_SUFFIX", "WALK_CANDIDATES",
           "CALIBRATION_FILE", "first_reaching", "control_pairs", "seed_clusters", "draw_study", "scenario_tables",
           "metric_calibration", "calibrate", "calibration_markdown", "residual_sd"]

#: Plasmode studies per emulator and size (``validate live --calibration-studies``).
STUDIES = 100
#: True omega2 of the injected interactions.
INJECTED_OMEGA2 = (0.3, 0.5)
#: The noisy method's injected per-walk noise, in units of its own residual SD.
NOISY_FACTOR = 3.0
#: Fraction of plasmode studies the perfect emulator must be judged ``agrees`` in.
TARGET = 0.8
#: A live condition re-seeded (other capture-noise seeds) is named ``<run>-reseeded``.
RESEEDED_SUFFIX = "-reseeded"
#: Study sizes (walks) the search for the walks ``agrees`` needs runs over.
WALK_CANDIDATES = (10, 15, 20, 30, 45, 60, 90, 120, 180, 240)
#: The calibration's file in the study folder.
CALIBRATION_FILE = "calibration.json"
#: Fewest seeds and complete walks a plasmode resamples (fewer: every draw repeats the same one or two walks).
MIN_SEEDS, MIN_COMPLETE_WALKS = 2, 4
#: The method made noisy in the injected emulator, where the study runs it.
NOISY_DEFAULT = "kim"


def _seed(seed, *more) -> list[int]:
    """A seed sequence's entropy: ``seed`` (an int or a list of ints) followed by ``more``."""
    return [int(v) for v in np.atleast_1d(seed)] + [int(v) for v in more]


def control_pairs(tables) -> list[tuple[str, str]]:
    """(reference run, re-seeded run) for every run ``X-reseeded`` of ``tables`` whose ``X`` is there too."""
    return sorted((r[:-len(RESEEDED_SUFFIX)], r) for r in tables
                  if r.endswith(RESEEDED_SUFFIX) and r[:-len(RESEEDED_SUFFIX)] in tables)


def seed_clusters(seeds) -> list[np.ndarray]:
    """Row indices of the walks of each seed (``seeds``: one per walk), in seed order."""
    seeds = np.asarray(list(seeds))
    return [np.flatnonzero(seeds == s) for s in np.unique(seeds)]


def draw_study(clusters, k: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """(walk rows, cluster label per row) of one plasmode study of ``k`` seeds drawn with replacement;
    a seed drawn twice is two clusters."""
    pick = rng.integers(0, len(clusters), size=k)
    rows = np.concatenate([clusters[c] for c in pick])
    labels = np.repeat(np.arange(k), [clusters[c].size for c in pick])
    return rows, labels


def residual_sd(live, reseeded) -> np.ndarray:
    """Per method, the SD of the walk x method residual of ``reseeded - live`` (complete walks); its squares
    average to the two-way residual mean square."""
    d = reseeded - live
    w, m = d.shape
    r = d - d.mean(axis=0) - d.mean(axis=1, keepdims=True) + d.mean()
    return np.sqrt((r ** 2).sum(axis=0) / max(w - 1, 1) * m / max(m - 1, 1))


def scenario_tables(live, reseeded, rows, scenario: str, rng, *, omega2: float = 0.0, live_var: float = 0.0,
                    noise_sd=None) -> tuple[np.ndarray, np.ndarray]:
    """(live, emulated) tables of one plasmode study (walk ``rows`` of the real tables) for ``scenario``
    (``perfect``, ``injected``, ``random``); the injected effects have variance ``omega2 * live_var`` over the
    methods, the injected per-walk noise SD ``noise_sd`` per method (t3, unit variance times it)."""
    L, E = live[rows], reseeded[rows].copy()
    m = L.shape[1]
    if scenario == "random":
        E = E[:, rng.permutation(m)]
    elif scenario == "injected":
        delta = rng.normal(size=m)
        delta -= delta.mean()
        sd = delta.std(ddof=1)
        delta *= math.sqrt(omega2 * live_var) / sd if sd > 0 else 0.0
        t3 = rng.standard_t(3.0, size=E.shape) / math.sqrt(3.0)
        E = E + delta + t3 * np.asarray(noise_sd)
    elif scenario != "perfect":
        raise ValueError(f"scenario must be perfect, injected or random, got {scenario!r}")
    return L, E


def _rates(live, reseeded, clusters, k, scenario, n_studies, seed, **kw) -> dict:
    """Verdict rates of ``n_studies`` plasmode studies of ``k`` seeds, and their median complete walks."""
    rng = rng_of(seed)
    counts = dict.fromkeys(VERDICTS, 0)
    walks = []
    for _ in range(n_studies):
        rows, labels = draw_study(clusters, k, rng)
        L, E = scenario_tables(live, reseeded, rows, scenario, rng, **kw)
        res = judge(L, E, detail=False, clusters=labels, seed=rng)
        counts[res["verdict"]] += 1
        walks.append(res["n_walks"])
    return {**{v: counts[v] / n_studies for v in VERDICTS}, "complete_walks_median": float(np.median(walks))}


def first_reaching(rate, lo: int, hi: int, target: float) -> int | None:
    """The smallest index ``i`` in ``[lo, hi]`` with ``rate(i) >= target``, by bisection (the rate taken to grow with
    ``i``), or None (none reaches it, or the range is empty)."""
    top = hi
    while lo < hi:
        mid = (lo + hi) // 2
        if rate(mid) >= target:
            hi = mid
        else:
            lo = mid + 1
    return lo if lo <= top and rate(lo) >= target else None


def _walks_needed(live, reseeded, clusters, n_studies, seed, candidates, target, own_rate) -> dict:
    """Smallest study size (walks: ``candidates`` and the study's own) at which the perfect emulator is judged
    ``agrees`` in at least ``target`` of the plasmode studies: a bisection on the side of the study's own size
    (``own_rate``) that holds the answer, the rate taken to grow with the walks; every size tried is listed,
    those with more seeds than the study has flagged as extrapolated."""
    per_seed = float(np.mean([c.size for c in clusters]))
    own = len(clusters)
    ks = sorted({max(2, math.ceil(n / per_seed)) for n in candidates} | {own, MIN_WALKS})  # the rule's fewest seeds
    tried = {ks.index(own): own_rate}

    def rate(i):
        if i not in tried:
            tried[i] = _rates(live, reseeded, clusters, ks[i], "perfect", n_studies, _seed(seed, ks[i]))["agrees"]
        return tried[i]

    lo, hi = (0, ks.index(own)) if own_rate >= target else (ks.index(own) + 1, len(ks) - 1)
    found = first_reaching(rate, lo, hi, target)
    sizes = [{"seeds": ks[i], "walks": round(ks[i] * per_seed), "agrees": tried[i],
              "extrapolated": ks[i] > own} for i in sorted(tried)]
    return {"walks": None if found is None else round(ks[found] * per_seed),
            "seeds": None if found is None else ks[found],
            "extrapolated": None if found is None else ks[found] > own,
            "target": target, "largest_tried_walks": round(ks[-1] * per_seed), "sizes_tried": sizes}


def metric_calibration(live, reseeded, seeds, methods, *, n_studies: int = STUDIES, seed=0,
                       omega2s=INJECTED_OMEGA2, noisy_method: str | None = None, noisy_factor: float = NOISY_FACTOR,
                       candidates=WALK_CANDIDATES, target: float = TARGET) -> dict:
    """The plasmode calibration of one metric: ``live`` (the reference condition) and ``reseeded`` (the same
    condition re-seeded), walks x methods tables; ``seeds``: each walk's seed (the walks of a seed, one per
    scene, are drawn together)."""
    L = np.asarray(live, dtype=np.float64)
    R = np.asarray(reseeded, dtype=np.float64)
    names = list(methods)
    if L.shape != R.shape or L.ndim != 2 or L.shape[1] != len(names) or L.shape[0] != len(seeds):
        raise ValueError(f"live and re-seeded tables must be walks x methods ({len(seeds)} x {len(names)}), got "
                         f"{L.shape} and {R.shape}")
    ok = np.all(np.isfinite(L) & np.isfinite(R), axis=1)
    clusters = seed_clusters(seeds)
    n_seeds = len(clusters)
    out = {"status": "not computed", "n_walks": int(L.shape[0]), "complete_walks": int(ok.sum()),
           "n_seeds": n_seeds, "n_studies": int(n_studies)}
    if n_seeds < MIN_SEEDS or ok.sum() < MIN_COMPLETE_WALKS:
        out["reason"] = (f"{n_seeds} seed(s) and {int(ok.sum())} complete walk(s): a plasmode needs at least "
                         f"{MIN_SEEDS} seeds and {MIN_COMPLETE_WALKS} complete walks to resample")
        return out
    live_var = float(variance_components(L[ok])[0])
    noise = residual_sd(L[ok], R[ok])
    # the re-seeded run's method means minus live's, over these walks, are noise; resampled, they would become a
    # true interaction of the plasmode's population: removed, so that the perfect emulator's is exactly 0
    bias = (R[ok] - L[ok]).mean(axis=0)
    R = R - (bias - bias.mean())
    noisy = noisy_method if noisy_method is not None else (
        NOISY_DEFAULT if NOISY_DEFAULT in names else names[int(np.argmax(noise))])
    if noisy not in names:
        raise ValueError(f"noisy method {noisy!r} is not one of the study's methods ({', '.join(names)})")
    noise_sd = noise.copy()
    noise_sd[names.index(noisy)] *= noisy_factor
    out.update(status="computed", live_method_variance=live_var,
               residual_sd={m: float(s) for m, s in zip(names, noise)}, noisy_method=noisy,
               noisy_factor=float(noisy_factor))
    rates = {"perfect": _rates(L, R, clusters, n_seeds, "perfect", n_studies, _seed(seed, 1))}
    for j, o in enumerate(omega2s):
        key = f"injected omega2 {o:g}"
        if live_var > 0:
            rates[key] = _rates(L, R, clusters, n_seeds, "injected", n_studies, _seed(seed, 2, j), omega2=float(o),
                                live_var=live_var, noise_sd=noise_sd)
        else:
            rates[key] = {"status": "not computed", "reason": "live shows no method effect on these walks "
                          "(variance component <= 0): an omega2 relative to it is undefined"}
    rates["random"] = _rates(L, R, clusters, n_seeds, "random", n_studies, _seed(seed, 3))
    out["rates"] = rates
    out["walks_needed_for_agrees"] = _walks_needed(L, R, clusters, n_studies, _seed(seed, 4), candidates, target,
                                                   rates["perfect"]["agrees"])
    return out


def calibrate(tables, seeds, methods, *, metrics=None, n_studies: int = STUDIES, seed: int = 0,
              pairs=None, **kw) -> dict:
    """results.json's ``calibration``: :func:`metric_calibration` for every (reference, re-seeded) pair of
    ``tables`` (``{run: {metric: walks x methods}}``; :func:`control_pairs` unless ``pairs`` names them)
    and every metric (``metrics``: those of the tables by default); ``seeds``: each walk's seed.  Seeded: the
    same tables and options give the same numbers."""
    pairs = control_pairs(tables) if pairs is None else [tuple(p) for p in pairs]
    out = {"definition": DEFINITION, "n_studies": int(n_studies), "seed": int(seed), "target": TARGET,
           "min_walks": MIN_WALKS, "pairs": {}}
    if not pairs:
        out["status"] = "not computed"
        out["reason"] = "no live condition was run twice with other capture-noise seeds (re-seeded) in this study"
        return out
    for p, (ref, other) in enumerate(pairs):
        for run in (ref, other):
            if run not in tables:
                raise ValueError(f"run {run!r} is not in the walks table (runs: {', '.join(sorted(tables))})")
        names = list(metrics) if metrics is not None else list(tables[ref])
        out["pairs"][f"{ref} vs {other}"] = {"reference": ref, "reseeded": other, "metrics": {
            metric: metric_calibration(tables[ref][metric], tables[other][metric], seeds, methods,
                                       n_studies=n_studies, seed=[seed, 33_001, p, i], **kw)
            for i, metric in enumerate(names) if metric in tables[other]}}
    out["status"] = "computed"
    return out


#: How the calibration is made, in words (results.json's ``calibration.definition``).
DEFINITION = ("plasmode: studies of the study's own seeds (each with its walks, one per scene) drawn with "
              "replacement from its walks table, judged by the same verdict rule; perfect emulator = the re-seeded "
              "live run of the same walks; injected = the re-seeded run plus method effects of a known omega2, t3 "
              "per-walk noise at each method's measured residual SD and one method several times noisier; random = "
              "the re-seeded run with its method labels permuted; sizes beyond the study's seeds are extrapolations")


def _rate(r: dict, verdict: str) -> str:
    return "n/a (no live method effect)" if r.get("status") == "not computed" else f"{100 * r[verdict]:.0f} %"


def calibration_markdown(cal: dict | None) -> str:
    """The report's section on the calibration (empty without one)."""
    if not cal:
        return ""
    lines = ["", "### How often the verdict rule is right on this study's own walks (plasmode calibration)", ""]
    if cal.get("status") != "computed":
        return "\n".join(lines + [f"Not computed: {cal.get('reason')}.", ""])
    lines += [f"{cal['n_studies']} plasmode studies per emulator and size, each the study's own number of seeds drawn "
              "with replacement from its walks, judged by the same rule as above. Perfect emulator: a re-seeded live "
              "run of the same walks. Injected: the re-seeded run plus a known interaction (omega2 as named), "
              "heavy-tailed (t3) per-walk noise and one noisier method. Random: the re-seeded run with its method "
              "labels permuted. Walks for `agrees`: the smallest size at which the perfect emulator is judged "
              f"`agrees` in at least {100 * cal['target']:.0f} % of plasmode studies (\"extrapolated\": more seeds "
              "than the study has, resampled).", ""]
    for label, pair in cal["pairs"].items():
        keys = next((list(c["rates"]) for c in pair["metrics"].values() if c["status"] == "computed"), [])
        lines += [f"Reference `{pair['reference']}`, perfect emulator `{pair['reseeded']}`:", "",
                  "| metric | walks | perfect: agrees | " + " | ".join(f"{k}: disagrees" for k in keys[1:]) +
                  " | walks for agrees |",
                  "| --- | ---: | ---: | " + " | ".join("---:" for _ in keys[1:]) + " | ---: |"]
        for metric, c in pair["metrics"].items():
            if c["status"] != "computed":
                lines.append(f"| {metric} | {c['n_walks']} | {c['reason']} | " + " | ".join("" for _ in keys[1:])
                             + " | |")
                continue
            cells = [_rate(c["rates"][keys[0]], "agrees")] + [_rate(c["rates"][k], "disagrees") for k in keys[1:]]
            need = c["walks_needed_for_agrees"]
            cells.append(f"> {need['largest_tried_walks']}" if need["walks"] is None else
                         f"{need['walks']}{' (extrapolated)' if need['extrapolated'] else ''}")
            lines.append(f"| {metric} | {c['complete_walks']} of {c['n_walks']} | " + " | ".join(cells) + " |")
        noisy = next((c for c in pair["metrics"].values() if c["status"] == "computed"), None)
        if noisy is not None:
            lines += ["", f"Noisier method in the injected emulator: {noisy['noisy_method']} "
                      f"({noisy['noisy_factor']:g} x its own residual SD).", ""]
    return "\n".join(lines) + "\n"

