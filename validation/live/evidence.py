"""The replicated verdicts of issue 22: per-walk metric tables, omega2 per metric, three conditions.

The unit is an independent walk: a scene with its trajectory, render and capture-noise
seeds (one experiment seed; replicates add seeds).  On each walk every run (emulated,
live at the cycle rate, live at the native rate where run, the re-seeded live control)
shares the walk's renders, so the walk x method part of every metric is common to the
runs (common random numbers) and cancels in their differences.

* :func:`walk_values`: from the per-run benchmark summaries of one or more experiment
  records (``raw.json``) to ``{run: {metric: (walks, methods) array}}``;
* :func:`judge_metrics`: results.json's ``metrics`` (the verdict per metric,
  :func:`validation.verdicts.agreement.judge`, emulated vs the reference live condition),
  ``comparisons`` (the same on every pair of :data:`~validation.live.config.COMPARISONS`),
  ``conditions`` (the three conditions side by side: per metric and method the walk mean
  with a cluster-bootstrap interval) and ``power`` (per metric, from the measured variance
  components: the smallest interaction the study detects and the walks a decision needs).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from emulator.core.stats import percentile_interval, rng_of
from emulator.io.files import read_text, write_results, write_text
from validation.live.config import (
    COMPARISONS,
    CONDITIONS,
    CONFIG_CHANGES,
    CONTROL,
    EQUIVALENCE_MARGINS,
    HEADLINE_COMPARISONS,
    HEADLINE_METRICS,
    JUDGED_METRICS,
    REFERENCE_LIVE,
    RESEEDED,
    LiveError,
)
from validation.live.headline import apply_family, headlines, walks_to_decide, with_derived
from validation.live.monte_carlo import apply_monte_carlo_rule, headline_family
from validation.verdicts.agreement import ALPHA, MIN_WALKS, judge
from validation.verdicts.plasmode import CALIBRATION_FILE, STUDIES, calibrate
from validation.verdicts.power import power_summary, scales_from_tables
from validation.verdicts.ranking import cluster_plan, over_plan, walk_labels

__all__ = ["WALK_METRICS", "WALKS_TABLE", "walk_value", "walk_values", "walk_labels", "walks_table_csv",
           "parse_walks_table", "store_walks_table", "table_refusal", "condition_table", "metric_scales", "judge_metrics",
           "pilot_reason", "calibration", "store_calibration"]

#: The study's per-walk table in its folder: one row per walk, method and condition, every metric.
WALKS_TABLE = "walks.csv"

#: Per-walk value of each ranked metric, from one method's entry of
#: ``ae_study.summarise(...)["per_scene"][scene]`` (the walk's own figures).
WALK_METRICS = {
    "median_uniformity": ("median_uniformity",),
    "median_matches": ("median_matches",),
    "success_rate_tau100": ("sequence_success", "100"),
    "segment_success_rate_tau100": ("segment_success", "100", "rate"),
    "vo_failed_frames": ("vo", "n_failed_frames"),
    "rpe_trans_pct": ("vo", "rpe_trans_pct"),
}


def walk_value(entry: dict, metric: str) -> float:
    """One method's value of ``metric`` on one walk (NaN where it does not exist; True/False as 1/0)."""
    v = entry
    for k in WALK_METRICS[metric]:
        v = v.get(k) if isinstance(v, dict) else None
    if v is None:
        return math.nan
    v = float(v)
    return v if math.isfinite(v) else math.nan


def walk_values(records: list[dict], methods) -> tuple[list[str], dict[str, dict[str, np.ndarray]]]:
    """Walk names and ``{run: {metric: (walks, methods) float array}}`` of experiment records.

    ``records``: raw records (``raw.json`` content: ``config`` and ``summaries``); each
    scene of each record is one walk, named ``<scene>/seed<seed>``.  A run missing from a
    record gives NaN rows there.
    """
    names = list(methods)
    walks, rows = [], {}
    runs = sorted({r for rec in records for r in (rec.get("summaries") or {})})
    for rec in records:
        seed = rec["config"]["seed"]
        for scene in rec["config"]["scenes"]:
            if "per_scene" in rec and scene not in rec["per_scene"]:
                continue  # a walk that failed (listed in the record's failed_walks)
            walks.append(f"{scene}/seed{seed}")
            for r in runs:
                per = ((rec.get("summaries") or {}).get(r) or {}).get("per_scene", {}).get(scene, {})
                for metric in WALK_METRICS:
                    rows.setdefault(r, {}).setdefault(metric, []).append(
                        [walk_value(per[m], metric) if m in per else math.nan for m in names])
    tables = {r: {metric: np.asarray(v, dtype=np.float64).reshape(len(walks), len(names))
                  for metric, v in per.items()} for r, per in rows.items()}
    return walks, tables


_TABLE_HEAD = ("walk", "scene", "seed", "method", "condition")


def walks_table_csv(walks, tables: dict, methods) -> str:
    """The per-walk table as CSV text: ``walk, scene, seed, method, condition`` and every metric of
    :data:`WALK_METRICS` (exact: each float as its shortest round-trip text; empty where it does not exist)."""
    scenes, seeds = walk_labels(walks)
    lines = [",".join(_TABLE_HEAD + tuple(WALK_METRICS))]
    for run in sorted(tables):
        for w, name in enumerate(walks):
            for k, m in enumerate(methods):
                vals = [tables[run][metric][w, k] for metric in WALK_METRICS]
                lines.append(",".join([name, scenes[w], str(seeds[w]), m, run]
                                      + ["" if not math.isfinite(v) else repr(float(v)) for v in vals]))
    return "\n".join(lines) + "\n"


def parse_walks_table(text: str, name: str = WALKS_TABLE) -> tuple[list[str], list[str], dict]:
    """(walks, methods, ``{run: {metric: (walks, methods)}}``) of :func:`walks_table_csv` text, in its order.

    A malformed table is a :class:`~validation.live.config.LiveError` naming the file and the line.
    """
    rows = [r for r in text.splitlines() if r.strip()]
    head = tuple(rows[0].split(",")) if rows else ()
    metrics = head[len(_TABLE_HEAD):]
    if head[:len(_TABLE_HEAD)] != _TABLE_HEAD or sorted(metrics) != sorted(WALK_METRICS):
        raise LiveError(f"{name}: line 1 must be {','.join(_TABLE_HEAD)} followed by each metric name once "
                        f"({', '.join(WALK_METRICS)}), got {rows[0] if rows else 'an empty file'!r}")
    walks, methods, runs, cells = [], [], [], {}
    for n, row in enumerate(rows[1:], start=2):
        f = row.split(",")
        if len(f) != len(head):
            raise LiveError(f"{name}: line {n} has {len(f)} fields, the header {len(head)}")
        try:
            vals = [float(v) if v else math.nan for v in f[len(_TABLE_HEAD):]]
        except ValueError:
            raise LiveError(f"{name}: line {n}: a metric value is not a number: {row!r}") from None
        for lst, v in ((walks, f[0]), (methods, f[3]), (runs, f[4])):
            if v not in lst:
                lst.append(v)
        if (f[4], f[0], f[3]) in cells:
            raise LiveError(f"{name}: line {n} repeats walk {f[0]}, method {f[3]}, condition {f[4]}")
        cells[(f[4], f[0], f[3])] = vals
    tables = {}
    for run in runs:
        tables[run] = {metric: np.full((len(walks), len(methods)), np.nan) for metric in metrics}
        for w, walk in enumerate(walks):
            for k, m in enumerate(methods):
                vals = cells.get((run, walk, m))
                if vals is None:
                    raise LiveError(f"{name}: no row for walk {walk}, method {m}, condition {run}")
                for metric, v in zip(metrics, vals):
                    tables[run][metric][w, k] = v
    return walks, methods, tables


def store_walks_table(out, walks, tables: dict, methods, name: str = WALKS_TABLE) -> str:
    """Write the per-walk table into the study folder ``out`` (``name``: :data:`WALKS_TABLE`); returns its name.

    An existing table with the same content is left alone, one whose every row the new table
    keeps is completed (a resumed study adds walks); one whose rows differ is never
    overwritten (a :class:`~validation.live.config.LiveError` says so).
    """
    path = Path(out) / name
    text = walks_table_csv(walks, tables, methods)
    refusal = table_refusal(path, text)
    if refusal is not None:
        raise LiveError(refusal)
    if not path.is_file() or read_text(path) != text:
        write_text(path, text, overwrite=True)
    return name


def table_refusal(path, text: str) -> str | None:
    """Why the per-walk table ``text`` may not be written to ``path`` (a table there with a row ``text`` does not
    keep), or None (no table, the same, or one that ``text`` completes)."""
    path = Path(path)
    if not path.is_file():
        return None
    old = read_text(path)
    if old == text or set(old.splitlines()) <= set(text.splitlines()):
        return None
    return f"{path}: differs from the walks recomputed from this folder's raw records; move it away to write it again"


def condition_table(table: np.ndarray, methods, *, n_resamples: int = 1000, seed=0, clusters=None) -> dict:
    """Per method: the walk mean of one metric with its bootstrap 95 % interval (walks with a value; the walks
    of one ``clusters`` label, the seed, drawn together)."""
    t = np.asarray(table, dtype=np.float64)
    out = {}
    rng = rng_of(seed)
    for k, m in enumerate(methods):
        ok = np.isfinite(t[:, k])
        v = t[:, k][ok]
        if v.size == 0:
            out[m] = {"mean": None, "ci95": [None, None], "n_walks": 0}
            continue
        ci = [None, None]
        if v.size >= 2:
            plan = cluster_plan(v.size, n_resamples, rng, None if clusters is None else np.asarray(clusters)[ok])
            lo, hi = percentile_interval(over_plan(lambda x: x.mean(axis=-1), plan, v))
            ci = [float(lo), float(hi)]
        out[m] = {"mean": float(v.mean()), "ci95": ci, "n_walks": int(v.size)}
    return out


def metric_scales(tables: dict, metric: str, *, min_walks: int = 2, reference: str | None = None):
    """``(Scales, complete walks, None)`` of one metric measured on a study's walk tables, or ``(None, n, reason)``.

    The reference live condition's table gives the method SD and its residual; the run
    noise comes from two live runs that differ only in their capture-noise seeds (the
    reference and its re-seeded run, or in studies without one, same-instant and its
    re-seeded control: their difference's residual is twice the run noise variance), and the
    rest of the reference's residual is walk x method.  Without a control all of the
    residual counts as noise (conservative).
    """
    ref = reference or CONDITIONS[REFERENCE_LIVE]
    live = tables.get(ref, {}).get(metric)
    if live is None:
        return None, 0, f"run {ref} not in this study"
    pair = (ref, RESEEDED.get(ref)) if RESEEDED.get(ref) in tables else (
        ("live-same-instant", f"live-{CONTROL}") if reference is None else (ref, None))
    control = tables.get(pair[1], {}).get(metric)
    ok = np.all(np.isfinite(live), axis=1)
    if control is not None:
        ok &= np.all(np.isfinite(control), axis=1)
    n = int(ok.sum())
    if n < min_walks:
        return None, n, f"{n} complete walks, fewer than {min_walks}: no variance components to size the study from"
    sc = scales_from_tables(live[ok])
    same = tables.get(pair[0], {}).get(metric)
    if control is not None and same is not None:
        both = ok & np.all(np.isfinite(same), axis=1)
        if both.sum() >= 2:
            noise = scales_from_tables(same[both], control=control[both]).sd_noise
            resid = sc.sd_noise ** 2 + sc.sd_walk_method ** 2
            sc = type(sc)(sd_method=sc.sd_method, sd_walk_method=float(np.sqrt(max(resid - noise ** 2, 0.0))),
                          sd_noise=float(min(noise, np.sqrt(resid))), sd_walk=sc.sd_walk)
    if sc.sd_method <= 0:
        return None, n, "live shows no method effect at this size (variance component <= 0)"
    return sc, n, None


def _not_run_reason(cname: str, run: str) -> str:
    if run in RESEEDED.values():
        return ("the re-seeded live runs were skipped (--no-control) or the study predates them"
                + (", or the native-rate condition was not run" if "native" in run else ""))
    if cname in ("native-rate live", "emulated native"):
        return "no native-rate live loop was given to this experiment"
    return f"run {run} not made"


def judge_metrics(tables: dict, methods, *, n_resamples: int = 1000, seed: int = 0, power: bool = True,
                  power_seeds: int = 100, walks=None, pilot: str | None = None,
                  calibration_studies: int | None = None, headline_exclusions: dict | None = None,
                  monte_carlo_rule: bool = False) -> dict:
    """results.json's ``metrics``, ``comparisons``, ``conditions``, ``power`` and ``n_walks`` from walk tables.

    ``tables``: :func:`walk_values`' second item.  ``walks``: their names (``<scene>/seed<S>``):
    the bootstrap then resamples the seeds as clusters (the walks of one seed together, so
    each resample keeps every scene's share).  A comparison whose runs were not made (the
    native-rate live loop where none was given) is ``{"status": "not run"}``.  ``pilot``: why this
    study decides nothing (a pipeline check): every verdict is then ``undetermined`` with that reason.
    ``calibration``: the verdict
    rule calibrated on these walks (:func:`calibration`; ``calibration_studies`` plasmode studies per
    emulator and size, the default where None, none where 0).  ``headline_exclusions``: headline metrics left out
    of the family (metric -> reason; a pre-registered study's).  ``monte_carlo_rule``: a headline verdict whose
    Holm-adjusted p's Monte Carlo interval holds the level is undetermined
    (:func:`validation.live.monte_carlo.apply_monte_carlo_rule`; a pre-registered study's rule).
    """
    names = list(methods)
    clusters = None if walks is None else walk_labels(walks)[1]
    tables = with_derived(tables)
    comparisons = {}
    for label, (ref, other) in COMPARISONS.items():
        if ref not in tables or other not in tables:
            missing = [r for r in (ref, other) if r not in tables]
            comparisons[label] = {"status": "not run", "reference": ref, "compared": other,
                                  "reason": f"run(s) {', '.join(missing)} not made in this experiment"}
            continue
        control = tables.get(RESEEDED.get(ref))  # like for like: the reference itself, re-seeded
        per_metric = {}
        for metric, higher in JUDGED_METRICS.items():
            if metric not in tables[ref] or metric not in tables[other]:
                continue
            res = judge(tables[ref][metric], tables[other][metric],
                        None if control is None else control[metric], methods=names,
                        margin=EQUIVALENCE_MARGINS.get(metric), higher_is_better=higher, n_resamples=n_resamples,
                        seed=[seed, 22_001, list(COMPARISONS).index(label), list(JUDGED_METRICS).index(metric)],
                        clusters=clusters)
            per_metric[metric] = res
        comparisons[label] = {"status": "run", "reference": ref, "compared": other,
                              "control": RESEEDED.get(ref) if control is not None else None, "metrics": per_metric}
    if pilot:
        _decide_nothing(comparisons, pilot)
    family = apply_family(comparisons, alpha=ALPHA, min_walks=MIN_WALKS, excluded=headline_exclusions)
    if monte_carlo_rule and walks is not None and not pilot:
        apply_monte_carlo_rule(comparisons, headline_family(tables, walks, names, seed=seed, n_resamples=n_resamples,
                                                            excluded=headline_exclusions))
    if power:
        _walks_to_decide(tables, comparisons, power_seeds, seed, ALPHA / max(family["size"], 1))
    headline = next(iter(COMPARISONS))
    n_walks = int(next(iter(next(iter(tables.values())).values())).shape[0]) if tables else 0
    metrics = {}
    if comparisons[headline]["status"] == "run":
        for metric, res in comparisons[headline]["metrics"].items():
            metrics[metric] = {k: res[k] for k in ("omega2", "omega2_ci90", "tau_live_emulated", "tau_live_live",
                                                   "verdict", "reason", "family")}
            metrics[metric].update({k: res[k] for k in ("verdict_alone", "p_agrees", "p_disagrees",
                                                        "p_agrees_adjusted", "p_disagrees_adjusted",
                                                        "adjusted_mc", "verdict_mc", "walks_to_decide") if k in res})
            metrics[metric].update({k: res[k] for k in ("n_walks", "omega2_untruncated", "omega2_interval",
                                                        "pairs_verdict", "margin_in_ranking_terms", "emulation_bias",
                                                        "disattenuated_correlation",
                                                        "disattenuated_correlation_ci95", "live_method_p",
                                                        "tau_live_emulated_ci95", "tau_live_live_ci95",
                                                        "tau_emulated_below_control_fraction",
                                                        "pairs_live_significant", "pairs_equivalent",
                                                        "pairs_reversed", "margin") if k in res})
    conditions = {}
    for cname, run in CONDITIONS.items():
        if run not in tables:
            conditions[cname] = {"run": run, "status": "not run", "reason": _not_run_reason(cname, run)}
            continue
        conditions[cname] = {"run": run, "status": "run", "metrics": {
            metric: condition_table(tables[run][metric], names, n_resamples=n_resamples,
                                    seed=[seed, 22_002, list(JUDGED_METRICS).index(metric)], clusters=clusters)
            for metric in JUDGED_METRICS if metric in tables[run]}}
    power_out = {}
    for metric in JUDGED_METRICS:
        if not power or CONDITIONS[REFERENCE_LIVE] not in tables:
            break
        sc, n, reason = metric_scales(tables, metric, min_walks=MIN_WALKS)
        if sc is None:
            power_out[metric] = {"status": "not computed", "reason": reason}
            continue
        power_out[metric] = {"status": "computed", **power_summary(n, sc, n_seeds=power_seeds, seed=[seed, 22_003])}
    return {"n_walks": n_walks, "reference_condition": REFERENCE_LIVE, "headlines": headlines(comparisons, family),
            "metrics": metrics, "comparisons": comparisons, "conditions": conditions, "power": power_out,
            "calibration": calibration(tables, walks, names, seed=seed, n_studies=calibration_studies)}


def _decide_nothing(comparisons: dict, why: str) -> None:
    """Every verdict (and pairwise check) of ``comparisons`` undetermined, in place, the reason first."""
    for c in comparisons.values():
        for r in (c.get("metrics") or {}).values():
            r["verdict"], r["reason"] = "undetermined", f"{why}; {r['reason']}"
            r["p_agrees"] = r["p_disagrees"] = None
            if isinstance(r.get("pairs_verdict"), dict):
                r["pairs_verdict"].update(verdict="undetermined", reason=why)


def pilot_reason(config) -> str | None:
    """Why a study of this configuration decides nothing (walks as short as ``--quick``'s: a pipeline check),
    or None."""
    n = CONFIG_CHANGES["quick"]["n_cycles"]
    if config.n_cycles <= n:
        return (f"walks of {config.n_cycles} cycles (--quick's length, {n} or fewer) are a pipeline check and "
                "decide nothing")
    return None


def _walks_to_decide(tables: dict, comparisons: dict, power_seeds: int, seed: int, alpha: float) -> None:
    """Each undetermined headline verdict gets ``walks_to_decide`` (:func:`validation.live.headline.walks_to_decide`
    with the variance components of its reference live run), in place."""
    for k, label in enumerate(HEADLINE_COMPARISONS):
        c = comparisons.get(label) or {}
        if c.get("status") != "run":
            continue
        for metric in HEADLINE_METRICS:
            r = c["metrics"].get(metric)
            if r is None or r["verdict"] != "undetermined":
                continue
            sc, n, reason = metric_scales(tables, metric, min_walks=MIN_WALKS, reference=c["reference"])
            r["walks_to_decide"] = ({"walks": None, "towards": None, "reason": reason} if sc is None else
                                    walks_to_decide(sc, r["omega2_untruncated"], alpha=alpha, n_seeds=power_seeds,
                                                    seed=[seed, 22_004, k, list(JUDGED_METRICS).index(metric)]))
            _seed_floor(r, MIN_WALKS)


def _seed_floor(r: dict, min_units: int) -> None:
    """Where the walks are clustered by seed, no fewer walks than ``min_units`` seeds of the study's walks each
    (the rule's minimum counts seeds there), in place."""
    need, seeds = r["walks_to_decide"].get("walks"), r.get("n_clusters")
    if need is None or not seeds:
        return
    floor = math.ceil(min_units * r["n_walks"] / seeds)
    if need < floor:
        r["walks_to_decide"].update(walks=floor, floor=f"at least {min_units} seeds of {r['n_walks'] / seeds:g} "
                                                      "walks each: the rule's minimum counts seeds")


def calibration(tables: dict, walks, methods, *, seed: int = 0, n_studies: int | None = None) -> dict:
    """results.json's ``calibration``: the plasmode calibration of the verdict rule on the study's own walks
    (:func:`validation.verdicts.plasmode.calibrate`) for every live condition that was run re-seeded."""
    n = STUDIES if n_studies is None else int(n_studies)
    if n <= 0 or walks is None:
        return {"status": "not computed", "reason": "no plasmode studies asked for" if n <= 0 else
                "the walks' scenes and seeds are not known", **({"n_studies": 0} if n <= 0 else {})}
    return calibrate(tables, walk_labels(walks)[1], methods, metrics=list(JUDGED_METRICS), n_studies=n, seed=seed)


def store_calibration(out, cal: dict) -> str:
    """Write the calibration into the study folder ``out`` (:data:`~validation.verdicts.plasmode.CALIBRATION_FILE`,
    rewritten with results.json by ``--redraw``); returns its name."""
    write_results(Path(out) / CALIBRATION_FILE, cal)
    return CALIBRATION_FILE
