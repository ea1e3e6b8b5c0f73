"""The verdicts: from the per-cycle comparisons and the benchmark summaries to results.json's numbers.

* :func:`assemble`: the headline figures, per-metric Kendall tau (live vs emulated, worst
  timing variant), the paper's findings that flip, the goals of issue 14;
* :func:`live_spread` and :func:`flip_causes`: why each discordant pair of methods flips
  (within the spread of two live runs, motion, noise level, exposure divergence, or image
  differences at equal exposures);
* :func:`ratio_use`: how often the emulated loops darkened, copied or brightened a bracket.
"""

from __future__ import annotations

import math

import numpy as np

from validation.live.compare import kendall_tau, stats
from validation.live.config import (
    CONTROL,
    GOAL_EXPOSURE_LOG2_MEDIAN,
    GOAL_TAU_MIN,
    METRICS,
    NOISE_OPTIONS,
    PRIMARY_NOISE,
    VARIANTS,
    LiveConfig,
)

__all__ = ["assemble", "HEADLINE_DEFINITIONS", "live_spread", "FLIP_CAUSES", "flip_causes", "flip_cause_counts", "ratio_use"]


def _value(overall: dict, method: str, path: tuple):
    v = overall.get(method)
    for k in path:
        v = v.get(k) if isinstance(v, dict) else None
    return None if v is None or not math.isfinite(float(v)) else float(v)


#: What each headline figure of results.json is (its ``headline_definitions``).
HEADLINE_DEFINITIONS = {
    "headline_noise": "the emulation noise option declared primary (PRIMARY_NOISE: plain, the benchmark's "
                      "default), whatever its figures; never the better of the two",
    "exposure_log2_error_median": "same-instant live vs emulated (headline noise), |log2(emulated_ms / "
                                  "live_ms)| pooled over scenes, methods and cycles 1..",
    "exposure_log2_error_max": "the same, maximum",
    "image_rmse_percent_median": "same-instant, left images, emulation's valid pixels, % of the DN range",
    "rank_kendall_tau": "per metric, Kendall tau-b of the methods' values live vs emulated, worst of the "
                        "two timing variants (headline noise)",
    "rank_kendall_tau_min": "minimum over the metrics of rank_kendall_tau (undefined taus left out)",
    "noise_variance_ratio": "median over intensity bins of emulated / live capture noise variance, "
                            "darkening pairs (source cleaner than target), measured",
}


def _exposure_and_images(cfg: LiveConfig, per_scene: dict, names, variants) -> tuple[dict, dict, dict | None]:
    """(exposure, images, control exposure): the per-cycle exposure and image errors of each comparison, pooled
    over the scenes per method and over the methods; the live control's exposure differences (None without)."""
    exposure, images = {}, {}
    for opt in NOISE_OPTIONS:
        for v in variants:
            key = f"{opt}/{v}"
            per_method = {}
            pooled_e, pooled_r, pooled_v = [], [], []
            for m in names:
                e = np.concatenate([per_scene[s]["comparison"][key][m]["exposure_log2_error"] for s in per_scene])
                r = np.concatenate([per_scene[s]["comparison"][key][m]["rmse_percent"] for s in per_scene])
                val = np.concatenate([per_scene[s]["comparison"][key][m]["valid_fraction"] for s in per_scene])
                per_method[m] = {"exposure_log2_error": stats(e), "image_rmse_percent": stats(r),
                                 "valid_fraction_mean": float(val.mean()) if val.size else None,
                                 "per_scene_exposure_log2_error_median": {
                                     s: stats(per_scene[s]["comparison"][key][m]["exposure_log2_error"])["median"]
                                     for s in per_scene}}
                pooled_e.append(e)
                pooled_r.append(r)
                pooled_v.append(val)
            e, r, val = np.concatenate(pooled_e), np.concatenate(pooled_r), np.concatenate(pooled_v)
            exposure[key] = {"pooled": stats(e), "methods": {m: per_method[m]["exposure_log2_error"] for m in names}}
            images[key] = {"pooled": stats(r), "valid_fraction_mean": float(val.mean()) if val.size else None,
                           "methods": per_method}
    control_exposure = None
    if cfg.control:
        ce = np.concatenate([per_scene[s]["comparison"]["live/control"][m]["exposure_log2_error"]
                             for s in per_scene for m in names])
        control_exposure = stats(ce)
    return exposure, images, control_exposure


def _rankings(cfg: LiveConfig, summaries: dict, findings: dict, names, variants) -> tuple[dict, dict, dict]:
    """(values, taus, flips): each run's metric values per method, Kendall tau of each comparison per metric,
    and the paper's findings that flip per comparison (all empty without benchmark summaries)."""
    values, taus, flips = {}, {}, {}
    if not summaries:
        return values, taus, flips
    for r, summ in summaries.items():
        values[r] = {metric: {m: _value(summ["overall"], m, path) for m in names}
                     for metric, (path, _) in METRICS.items()}
    for opt in NOISE_OPTIONS:
        for v in variants:
            taus[f"{opt}/{v}"] = {metric: kendall_tau(values[f"live-{v}"][metric],
                                                      values[f"emulated-{opt}"][metric]) for metric in METRICS}
    if cfg.control:
        taus["live/control"] = {metric: kendall_tau(values["live-same-instant"][metric],
                                                    values[f"live-{CONTROL}"][metric]) for metric in METRICS}
    for opt in NOISE_OPTIONS:
        for v in variants:
            live_f = {f["id"]: f["holds"] for f in findings[f"live-{v}"]}
            emu_f = {f["id"]: f["holds"] for f in findings[f"emulated-{opt}"]}
            flips[f"{opt}/{v}"] = [{"id": fid, "live": live_f[fid], "emulated": emu_f.get(fid)}
                                   for fid in live_f if emu_f.get(fid) != live_f[fid]]
    return values, taus, flips


def _worst_taus(taus: dict) -> tuple[dict, dict]:
    """(per noise option the worst tau of the timing variants per metric, per noise option the smallest of
    those); both empty without taus."""
    def worst(opt):
        out = {}
        for metric in METRICS:
            vals = [taus[f"{opt}/{v}"][metric]["tau"] for v in VARIANTS]
            vals = [t for t in vals if t is not None]
            out[metric] = min(vals) if vals else None
        return out

    tau_by_noise = {opt: worst(opt) for opt in NOISE_OPTIONS} if taus else {}
    tau_min_by_noise = {opt: (min([t for t in d.values() if t is not None], default=None)) for opt, d in
                        tau_by_noise.items()}
    return tau_by_noise, tau_min_by_noise


def _add_flip_causes(results: dict, values: dict, taus: dict, names) -> None:
    """results.json's live spread, flip causes and their counts, and per comparison and metric the discordant
    pairs beyond the live spread (into ``taus``), in place."""
    results["live_spread"] = live_spread(values) if values else {}
    rows = flip_causes(results, names) if taus else []
    results["flip_causes"] = rows
    results["flip_cause_counts"] = flip_cause_counts(rows)
    for key, per_metric in taus.items():
        for metric, res in per_metric.items():
            res["discordant_beyond_live_spread"] = sum(
                1 for r in rows if f"{r['noise']}/{r['variant']}" == key and r["metric"] == metric
                and r["cause"] != FLIP_CAUSES[0])


def assemble(cfg: LiveConfig, per_scene: dict, summaries: dict, findings: dict, nvr: dict, names) -> dict:
    """results.json's numbers from the per-scene comparisons and the per-run benchmark summaries."""
    variants = VARIANTS + ((CONTROL,) if cfg.control else ())
    exposure, images, control_exposure = _exposure_and_images(cfg, per_scene, names, variants)
    values, taus, flips = _rankings(cfg, summaries, findings, names, variants)
    tau_by_noise, tau_min_by_noise = _worst_taus(taus)
    best = PRIMARY_NOISE  # declared before the data: never the better of the two options
    same = exposure[f"{best}/same-instant"]["pooled"]
    worst_max = max((exposure[f"{best}/{v}"]["pooled"]["max"] or 0.0) for v in VARIANTS)
    results = {
        "headline_noise": best,
        "exposure_log2_error_median": same["median"],
        "exposure_log2_error_max": same["max"],
        "image_rmse_percent_median": images[f"{best}/same-instant"]["pooled"]["median"],
        "rank_kendall_tau": tau_by_noise.get(best, {}),
        "rank_kendall_tau_min": tau_min_by_noise.get(best),
        "noise_variance_ratio": {"plain": nvr["plain"], "consistent": nvr["consistent"]},
        "headline_definitions": dict(HEADLINE_DEFINITIONS),
        "goals": {
            "rank_kendall_tau_min_ge_0.9": None if tau_min_by_noise.get(best) is None
            else tau_min_by_noise[best] >= GOAL_TAU_MIN,
            "exposure_log2_error_median_le_0.05_same_instant": same["median"] is not None
            and same["median"] <= GOAL_EXPOSURE_LOG2_MEDIAN,
            "noise_variance_ratio_consistent_within_10pct": abs(nvr["consistent"] - 1.0) <= 0.1,
        },
        "rank_kendall_tau_by_noise": tau_by_noise,
        "rank_kendall_tau_min_by_noise": tau_min_by_noise,
        "rank_kendall_tau_detail": taus,
        "exposure_worst_variant_max": worst_max,
        "exposure": exposure,
        "exposure_live_control": control_exposure,
        "images": images,
        "metric_values": values,
        "findings_flips": flips,
        "findings": {r: [{k: f[k] for k in ("id", "claim", "holds", "detail")} for f in fl]
                     for r, fl in findings.items()},
        "noise_variance_ratio_detail": nvr,
    }
    _add_flip_causes(results, values, taus, names)
    return results


def live_spread(values: dict) -> dict:
    """Per metric, the largest |same-instant - re-seeded control| over the methods: how far two live
    runs of the same walk that differ only in capture noise put one method (None without control)."""
    a, b = values.get("live-same-instant"), values.get(f"live-{CONTROL}")
    if a is None or b is None:
        return {}
    out = {}
    for metric in a:
        d = [abs(a[metric][m] - b[metric][m]) for m in a[metric]
             if a[metric][m] is not None and b[metric].get(m) is not None]
        out[metric] = max(d) if d else None
    return out


#: Causes of a ranking flip, in the order they are tested (:func:`flip_causes`).
FLIP_CAUSES = ("within live spread", "motion", "noise level", "exposure divergence (closed loop, selector)",
               "image difference at equal exposures (noise realisation, quantisation)")


def flip_causes(results: dict, names) -> list[dict]:
    """Why each discordant pair of methods (per metric) flips, with the numbers.

    Per noise option, timing variant and metric, a pair ordered oppositely live and
    emulated is attributed to the first that applies:

    1. ``within live spread``: both differences (live a - b, emulated a - b) are at most
       the metric's live spread (:func:`live_spread`): two live runs differing only in
       capture noise disagree by as much, so the metric cannot order the pair;
    2. ``motion``: the pair flips in ``fixed-instant`` but not in ``same-instant``;
    3. ``noise level``: it flips with plain emulation but not with consistent;
    4. ``exposure divergence``: one of the two methods' exposure trajectories differ by a
       median |log2| above the goal (0.05): the closed loops went apart (the selector's
       bracket, the method's sensitivity to small image differences);
    5. ``image difference at equal exposures``: otherwise (the loops chose the same
       exposures; the images differ by the source's noise realisation and quantisation).
    """
    detail = results["rank_kendall_tau_detail"]
    values = results["metric_values"]
    spread = results.get("live_spread") or {}
    rows = []
    for key, per_metric in detail.items():
        opt, variant = key.split("/")
        if variant not in VARIANTS:
            continue
        live_key = f"live-{variant}"
        other_opt = "consistent" if opt == "plain" else "plain"
        exp = results["exposure"][key]["methods"]
        for metric, res in per_metric.items():
            for a, b in res["discordant"]:
                pair = [a, b]
                lv = {m: values[live_key][metric][m] for m in pair}
                ev = {m: values[f"emulated-{opt}"][metric][m] for m in pair}
                d_live, d_emu = abs(lv[a] - lv[b]), abs(ev[a] - ev[b])
                sp = spread.get(metric)
                if sp is not None and max(d_live, d_emu) <= sp:
                    cause = FLIP_CAUSES[0]
                elif variant == "fixed-instant" and pair not in detail[f"{opt}/same-instant"][metric]["discordant"]:
                    cause = FLIP_CAUSES[1]
                elif opt == "plain" and pair not in detail[f"{other_opt}/{variant}"][metric]["discordant"]:
                    cause = FLIP_CAUSES[2]
                elif max((exp[m]["median"] or 0.0) for m in pair) > GOAL_EXPOSURE_LOG2_MEDIAN:
                    cause = FLIP_CAUSES[3]
                else:
                    cause = FLIP_CAUSES[4]
                rows.append({
                    "noise": opt, "variant": variant, "metric": metric, "pair": pair, "cause": cause,
                    "live": lv, "emulated": ev, "live_difference": d_live, "emulated_difference": d_emu,
                    "live_spread": sp,
                    "exposure_log2_error_median": {m: exp[m]["median"] for m in pair},
                })
    return rows


def flip_cause_counts(rows: list[dict]) -> dict:
    """Counts of :func:`flip_causes` rows per ``noise/variant`` and cause."""
    out: dict = {}
    for r in rows:
        d = out.setdefault(f"{r['noise']}/{r['variant']}", {c: 0 for c in FLIP_CAUSES})
        d[r["cause"]] += 1
    return out


def ratio_use(per_scene: dict, names) -> dict:
    """Per emulated run and method: the fraction of cycles whose emulation darkened (k < 1),
    copied (k = 1) or brightened (k > 1) the bracket (HigherNoSat brightens when the higher
    bracket saturates)."""
    out = {}
    for opt in NOISE_OPTIONS:
        run = f"emulated-{opt}"
        out[opt] = {}
        for m in names:
            k = np.concatenate([np.asarray(per_scene[s]["trajectories"][run][m]["target_ms"], dtype=np.float64)
                                / np.asarray(per_scene[s]["trajectories"][run][m]["bracket_ms"], dtype=np.float64)
                                for s in per_scene])
            n = max(k.size, 1)
            out[opt][m] = {"darkening": float(np.sum(k < 1) / n), "identity": float(np.sum(k == 1) / n),
                           "brightening": float(np.sum(k > 1) / n)}
    return out

