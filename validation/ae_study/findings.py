"""The paper's qualitative findings of section V-D, evaluated on the study's numbers.

Every finding is a comparison of measured values with a stated rule; no sentence of the
paragraph is written by hand.
"""

from __future__ import annotations

import math

import numpy as np

from emulator.cells import format_number
from validation.ae_study.config import GRADIENT_METHODS, PAPER_NAMES, SIMILAR_RPE_RATIO
from validation.verdicts.findings import evaluate, unit_tables

__all__ = ["evaluate_findings", "findings_with_evidence", "findings_paragraph"]


def _values(overall: dict, key, methods=None) -> dict[str, float]:
    """Method to a finite value of ``overall[method]`` at ``key`` (a key or a path tuple)."""
    out = {}
    for name, o in overall.items():
        if methods is not None and name not in methods:
            continue
        v = o
        for k in (key if isinstance(key, tuple) else (key,)):
            v = v.get(k) if isinstance(v, dict) else None
        if v is not None and math.isfinite(float(v)):
            out[name] = float(v)
    return out


def _vo_basis(summary: dict) -> tuple[str, dict[str, float], dict[str, float]]:
    """RPE per method for the VO findings, and the rule that chose the scenes.

    The scenes where every method's VO converged (the paper's rule: RPE of converged
    runs); if there is none, the scenes where every method has an RPE, failed runs
    included (their failed frames carry the constant-velocity prediction); if none
    either, no RPE.  The value per method is the mean over those scenes of the minimal
    median RPE.
    """
    per_scene = summary["per_scene"]

    def every(rows, test):
        return bool(rows) and all(e["vo"] is not None and test(e["vo"]) for e in rows.values())

    converged = [s for s, rows in per_scene.items() if every(rows, lambda v: v["status"] == "success")]
    with_rpe = [s for s, rows in per_scene.items()
                if every(rows, lambda v: v["rpe_trans_pct"] is not None and v["rpe_rot_deg_per_m"] is not None)]
    if converged:
        basis = f"mean over the scenes where every method's VO converged ({', '.join(converged)})"
        scenes_used = converged
    elif with_rpe:
        basis = (f"mean over the scenes where every method has an RPE ({', '.join(with_rpe)}), failed VO runs "
                 "included: no scene where every method's VO converged")
        scenes_used = with_rpe
    else:
        basis = "no scene where every method has an RPE"
        scenes_used = []
    trans, rot = {}, {}
    for name in summary["overall"]:
        t = [per_scene[s][name]["vo"]["rpe_trans_pct"] for s in scenes_used
             if name in per_scene[s] and per_scene[s][name]["vo"] is not None]
        r = [per_scene[s][name]["vo"]["rpe_rot_deg_per_m"] for s in scenes_used
             if name in per_scene[s] and per_scene[s][name]["vo"] is not None]
        if t and all(x is not None for x in t):
            trans[name] = float(np.mean(t))
        if r and all(x is not None for x in r):
            rot[name] = float(np.mean(r))
    return basis, trans, rot


def _finding(fid: str, claim: str, paper: str, holds, measured: dict, detail: str) -> dict:
    return {"id": fid, "claim": claim, "paper": paper, "holds": None if holds is None else bool(holds),
            "measured": measured, "detail": detail}


def _all_equal(values: dict[str, float]) -> bool:
    """True when a ranking claim cannot be decided: every method has the same value."""
    vals = list(values.values())
    return len(vals) > 1 and max(vals) == min(vals)


def _ties(values: dict[str, float], target: str) -> str:
    """" (tied with ...)" when other methods share ``target``'s value, else ""."""
    if target not in values:
        return ""
    tied = [PAPER_NAMES.get(k, k) for k, v in values.items() if k != target and v == values[target]]
    return f" ({PAPER_NAMES.get(target, target)} tied with {', '.join(tied)})" if tied else ""


def _undecided_if_equal(finding: dict, values: dict[str, float]) -> dict:
    if finding["holds"] is not None and _all_equal(values):
        finding["holds"] = None
        finding["detail"] += " (all methods equal: no ranking)"
    return finding


def _named(values: dict[str, float], spec: str = ".3g") -> str:
    return ", ".join(f"{PAPER_NAMES.get(k, k)} {format_number(v, spec)}" for k, v in sorted(values.items(), key=lambda kv: kv[1]))


def _tracking_findings(overall: dict) -> list[dict]:
    """F1 and F2: M_fixed tracks the most features; M_70% and M_Kim have a lower uniformity."""
    out = []
    # F1 -- M_fixed tracks the most features
    matches = _values(overall, "median_matches")
    holds = None if "fixed" not in matches or len(matches) < 2 else matches["fixed"] >= max(matches.values())
    out.append(_undecided_if_equal(_finding(
        "fixed_most_matches", "M_fixed tracks the most features between consecutive images (highest median matches)",
        "M_fixed has the highest median, 674 matches", holds, matches,
        f"median matches over all images: {_named(matches)}{_ties(matches, 'fixed')}"), matches))

    # F2 -- M_70 and M_Kim have a reduced uniformity
    uni = _values(overall, "median_uniformity")
    pair = ("classical-70", "kim")
    if all(p in uni for p in pair) and len(uni) > 2:
        others = [v for k, v in uni.items() if k not in pair]
        mean_others = float(np.mean(others))
        holds = all(uni[p] < mean_others for p in pair)
        detail = (f"median uniformity {PAPER_NAMES['classical-70']} {format_number(100 * uni['classical-70'])} %, "
                  f"{PAPER_NAMES['kim']} {format_number(100 * uni['kim'])} %, mean of the other methods "
                  f"{format_number(100 * mean_others)} %")
    else:
        holds, detail = None, "uniformity of M_70% or M_Kim missing"
    out.append(_undecided_if_equal(_finding(
        "uniformity_70_kim_lower", "M_70% and M_Kim have a lower keypoint uniformity than the other methods (both below "
        "the others' mean)", "median uniformity 67.3 % (M_70%) and 66.0 % (M_Kim), the others slightly higher", holds,
        uni, detail), uni))
    return out


def _success_findings(overall: dict, lo_tau: str, hi_tau: str) -> list[dict]:
    """F3 and F4, on sequences and on segments: success falls with tau; at the higher tau M_fixed is the most
    successful, M_30%, M_70% and M_Kim the least."""
    out = []
    # F3 -- success rate falls with tau, on sequences and on segments
    for basis, key in (("sequences", ("sequence_success_rate",)), ("segments", ("segment_success",))):
        lo = _values(overall, key + ((lo_tau, "rate") if basis == "segments" else (lo_tau,)))
        hi = _values(overall, key + ((hi_tau, "rate") if basis == "segments" else (hi_tau,)))
        common = sorted(set(lo) & set(hi))
        if common:
            m_lo, m_hi = float(np.mean([lo[k] for k in common])), float(np.mean([hi[k] for k in common]))
            holds = m_hi < m_lo
            detail = (f"mean success rate over the methods ({basis}): {format_number(100 * m_lo, '.0f')} % at tau = {lo_tau}, "
                      f"{format_number(100 * m_hi, '.0f')} % at tau = {hi_tau}")
        else:
            holds, detail = None, f"no success rate on {basis}"
        out.append(_finding(
            f"success_falls_with_tau_{basis}", f"robustness decreases as tau grows (success rate on {basis} lower at "
            f"tau = {hi_tau} than at tau = {lo_tau})", "the success rate decreases rapidly with tau_matches", holds,
            {"tau_lo": lo, "tau_hi": hi}, detail))

    # F4 -- at tau = 100 M_fixed is the most successful, M_30, M_70, M_Kim the least
    for basis, key in (("sequences", ("sequence_success_rate", hi_tau)), ("segments", ("segment_success", hi_tau, "rate"))):
        rate = _values(overall, key)
        holds = None if "fixed" not in rate or len(rate) < 2 else rate["fixed"] >= max(rate.values())
        out.append(_undecided_if_equal(_finding(
            f"fixed_best_success_{basis}", f"M_fixed has the highest success rate at tau = {hi_tau} ({basis})",
            "M_fixed succeeds on 44 % of the sequences, the most", holds, rate,
            f"success rate at tau = {hi_tau} on {basis} (%): " + _named({k: 100 * v for k, v in rate.items()}, ".0f")
            + _ties(rate, "fixed")), rate))
        poor = ("classical-30", "classical-70", "kim")
        if all(p in rate for p in poor) and len(rate) > 3:
            rest = [v for k, v in rate.items() if k not in poor]
            # each of the three strictly below the mean of the other methods
            holds = all(rate[p] < float(np.mean(rest)) for p in poor)
            detail = (f"at tau = {hi_tau} on {basis}: M_30%, M_70%, M_Kim "
                      f"{', '.join(format_number(100 * rate[p], '.0f') for p in poor)} %, mean of the others "
                      f"{format_number(100 * float(np.mean(rest)), '.0f')} %")
        else:
            holds, detail = None, f"success rates missing ({basis})"
        out.append(_undecided_if_equal(_finding(
            f"poorest_success_30_70_kim_{basis}", f"M_30%, M_70% and M_Kim have the poorest success rate at tau = {hi_tau} "
            f"({basis}; each below the others' mean)", "M_30%, M_70% and M_Kim succeed on 20 % of the sequences, the least",
            holds, rate, detail), rate))
    return out


def _vo_run_failures(overall: dict) -> dict:
    """The VO fails on part of the method runs."""
    failed_runs = {k: o["vo_failed_runs"] for k, o in overall.items()}
    n_runs = sum(o["n_sequences"] for o in overall.values())
    total_failed = sum(failed_runs.values())
    return _finding(
        "vo_fails_on_some_runs", "the stereo VO fails on part of the runs (paper: 20 % of the trajectories)",
        "11 of 55 trajectories failed", (total_failed > 0) if n_runs else None,
        {"failed_runs": failed_runs, "runs": n_runs},
        f"{total_failed} of {n_runs} method runs had at least one failed VO frame "
        f"({format_number(100 * total_failed / n_runs if n_runs else None, '.0f')} %)")


def _vo_rpe_findings(trans: dict[str, float], rot: dict[str, float]) -> list[dict]:
    """The RPE rankings: M_50% lowest and M_Kim highest translation RPE, M_Zhang and M_50% the two lowest
    rotation RPE, M_fixed not the best in VO, the gradient-based methods ahead."""
    out = []

    def vo_rank(fid, claim, paper, values, target, best=True, unit="%"):
        if target not in values or len(values) < 2:
            return _finding(fid, claim, paper, None, values, f"RPE of {PAPER_NAMES.get(target, target)} missing")
        ext = min(values.values()) if best else max(values.values())
        holds = values[target] <= ext if best else values[target] >= ext
        return _undecided_if_equal(_finding(fid, claim, paper, holds, values,
                                            f"{_named(values)} {unit}{_ties(values, target)}"), values)

    out.append(vo_rank("rpe_trans_best_50", "M_50% has the lowest translation RPE", "M_50%: 4.21 %, the lowest",
                       trans, "classical-50"))
    out.append(vo_rank("rpe_trans_worst_kim", "M_Kim has the highest translation RPE", "M_Kim: 5.75 %, the highest",
                       trans, "kim", best=False))
    if all(k in rot for k in ("zhang", "classical-50")) and len(rot) > 2:
        two = sorted(rot.values())[:2]
        holds = rot["zhang"] <= two[1] and rot["classical-50"] <= two[1]
        detail = f"{_named(rot, '.3g')} deg/m"
    else:
        holds, detail = None, "rotation RPE of M_Zhang or M_50% missing"
    out.append(_undecided_if_equal(_finding("rpe_rot_best_zhang_50", "M_Zhang and M_50% have the two lowest rotation "
                                            "RPE", "0.07 deg/m for both, the lowest", holds, rot, detail), rot))
    if "fixed" in trans and len(trans) > 1:
        holds = trans["fixed"] > min(trans.values())
        detail = f"M_fixed {format_number(trans['fixed'])} %, best {format_number(min(trans.values()))} %"
    else:
        holds, detail = None, "translation RPE of M_fixed missing"
    out.append(_finding("fixed_not_best_vo", "M_fixed, the best at feature tracking, is not the best in VO",
                        "M_fixed: 5.1 % and 0.09 deg/m, behind M_50% (4.21 %)", holds, {"trans": trans}, detail))
    grad = [trans[k] for k in GRADIENT_METHODS if k in trans]
    rest = [v for k, v in trans.items() if k not in GRADIENT_METHODS]
    if len(grad) == len(GRADIENT_METHODS) and rest:
        holds = float(np.max(grad)) < float(np.mean(rest))  # each of them ahead, not their mean
        detail = (f"translation RPE of M_Shim and M_Zhang {', '.join(format_number(g) for g in grad)} % (each must lie "
                  f"below the others' mean), of the other methods mean {format_number(np.mean(rest))} %")
    else:
        holds, detail = None, "translation RPE missing"
    out.append(_finding("gradient_ahead_vo", "gradient-based methods (M_Shim, M_Zhang) are ahead in VO (each with "
                        "a lower translation RPE than the others' mean)",
                        "a small advantage for gradient-based methods",
                        holds, {"trans": trans}, detail))
    return out


def _vo_frame_failures(summary: dict, overall: dict) -> dict:
    """The gradient-based methods lose VO tracking less often, on the scenes that tell the methods apart."""
    # failed frames, on the scenes that tell the methods apart (not every method failing every frame)
    per_scene = summary["per_scene"]
    telling = [s for s, rows in per_scene.items()
               if rows and all(e["vo"] is not None for e in rows.values())
               and not all(e["vo"]["n_failed_frames"] >= e["vo"]["n_frames"] - 1 for e in rows.values())]
    fails = {k: float(sum(per_scene[s][k]["vo"]["n_failed_frames"] for s in telling if k in per_scene[s]))
             for k in overall} if telling else {}
    grad_f = [fails[k] for k in GRADIENT_METHODS if k in fails]
    rest_f = [v for k, v in fails.items() if k not in GRADIENT_METHODS]
    if len(grad_f) == len(GRADIENT_METHODS) and rest_f:
        holds = float(np.max(grad_f)) < float(np.mean(rest_f))  # each of them, not their mean
        left_out = [s for s in per_scene if s not in telling]
        detail = (f"failed VO frames on {', '.join(telling)}"
                  + (f" ({', '.join(left_out)} left out: every method failed on every frame)" if left_out else "")
                  + f": M_Shim {format_number(fails['shim'], '.0f')}, M_Zhang {format_number(fails['zhang'], '.0f')} (mean "
                  f"{format_number(np.mean(grad_f))}), the other methods mean {format_number(np.mean(rest_f))} "
                  f"({', '.join(f'{PAPER_NAMES.get(k, k)} {v:.0f}' for k, v in fails.items() if k not in GRADIENT_METHODS)})")
    else:
        holds, detail = None, "no scene where the VO failure counts tell the methods apart"
    return _undecided_if_equal(_finding(
        "gradient_fewer_vo_failures", "gradient-based methods (M_Shim, M_Zhang) lose VO tracking less often (fewer "
        "failed frames on average than the other methods; not a paper figure, the paper's claim is on RPE)",
        "a small advantage for gradient-based methods", holds, fails, detail), fails)


def _vo_similar(trans: dict[str, float]) -> dict:
    """All methods perform similarly in VO (largest / smallest translation RPE within the paper's ratio)."""
    if len(trans) > 1 and min(trans.values()) > 0:
        spread = max(trans.values()) / min(trans.values())
        holds = spread <= SIMILAR_RPE_RATIO
        detail = f"largest / smallest translation RPE = {format_number(spread)} (paper 5.75 / 4.21 = 1.37)"
    else:
        spread, holds, detail = None, None, "translation RPE missing"
    return _finding("vo_similar", f"all methods perform similarly in VO (largest / smallest translation RPE <= "
                    f"{SIMILAR_RPE_RATIO})", "4.21 % to 5.75 %", holds, {"ratio": spread}, detail)


def evaluate_findings(summary: dict, taus=(5, 100)) -> list[dict]:
    """Test the paper's qualitative findings of section V-D on the study's numbers.

    Every finding is a comparison of measured values with a stated rule; ``holds`` is
    True, False, or None when the numbers needed are missing.  Ties count for the claim
    (a method tied for the highest value "has the highest", and the detail names the
    ties); a ranking claim is undecided (None) when every method has the same value.

    Returns
    -------
    list of dict
        ``id``, ``claim``, ``paper`` (the paper's evidence), ``holds``, ``measured`` (the
        numbers compared) and ``detail`` (one sentence with the numbers).
    """
    overall = summary["overall"]
    lo_tau, hi_tau = str(min(taus)), str(max(taus))
    out = _tracking_findings(overall) + _success_findings(overall, lo_tau, hi_tau)
    # VO findings on a stated basis
    basis, trans, rot = _vo_basis(summary)
    out.append(_vo_run_failures(overall))
    out += _vo_rpe_findings(trans, rot)
    out += [_vo_frame_failures(summary, overall), _vo_similar(trans)]
    for f in out:
        f["vo_basis"] = basis if f["id"].startswith(("rpe_", "fixed_not", "gradient_ahead", "vo_similar")) else None
    return out


def findings_with_evidence(summary: dict, findings: list[dict], taus=(5, 100), seed: int = 0) -> list[dict]:
    """``findings`` (:func:`evaluate_findings`) with each one's evidence over the walks (issue 22).

    The walks are the summary's scenes (each an independent walk with its seeds); per finding
    :func:`validation.verdicts.findings.evaluate` adds ``effect`` (signed: positive is the
    paper's claim), ``ci95`` (cluster bootstrap over walks), ``p`` and ``p_adjusted``
    (the claim tested as stated: every one-sided paired comparison it needs, Holm across the
    findings), ``verdict`` (holds / contradicted /
    undetermined / by-construction, the last not counted), ``n_walks``, ``effect_definition``
    and ``verdict_reason``.  ``holds`` stays the point comparison of issue 7.
    """
    units = list(summary["per_scene"].values())
    methods = [m for m in summary["overall"]]
    ev = {r["id"]: r for r in evaluate(unit_tables(units, methods, hi_tau=max(int(t) for t in taus)), methods,
                                       seed=[int(seed), 22_004])}
    out = []
    for f in findings:
        r = ev.get(f["id"])
        g = dict(f)
        if r is None:
            g.update({"effect": None, "ci95": [None, None], "p": None, "p_adjusted": None, "verdict": "undetermined",
                      "n_walks": len(units), "effect_definition": None, "verdict_reason": "no statistic defined"})
        else:
            g.update({"effect": r["effect"], "ci95": r["ci95"], "p": r["p"], "p_adjusted": r["p_adjusted"],
                      "verdict": r["verdict"], "n_walks": r["n_walks"], "effect_definition": r["definition"],
                      "verdict_reason": r["reason"], "test": r.get("test"), "family": r.get("family")})
        out.append(g)
    return out


def findings_paragraph(findings: list[dict]) -> str:
    """One paragraph, generated from the evaluated findings (no claim is written by hand)."""
    if findings and "verdict" in findings[0]:
        return _verdicts_paragraph(findings)
    held = [f for f in findings if f["holds"] is True]
    failed = [f for f in findings if f["holds"] is False]
    unknown = [f for f in findings if f["holds"] is None]
    parts = [f"Of the {len(findings)} qualitative findings of the paper's section V-D tested here, "
             f"{len(held)} hold, {len(failed)} do not and {len(unknown)} cannot be decided on these synthetic "
             f"sequences."]
    if held:
        parts.append("Hold: " + "; ".join(f"{f['claim']} ({f['detail']})" for f in held) + ".")
    if failed:
        parts.append("Do not hold: " + "; ".join(f"{f['claim']} ({f['detail']})" for f in failed) + ".")
    if unknown:
        parts.append("Undecided: " + "; ".join(f"{f['claim']} ({f['detail']})" for f in unknown) + ".")
    bases = sorted({f["vo_basis"] for f in findings if f.get("vo_basis")})
    if bases:
        parts.append("RPE compared as the " + "; ".join(bases) + ".")
    return " ".join(parts)


def _verdicts_paragraph(findings: list[dict]) -> str:
    """The paragraph from the verdicts with evidence (by-construction findings not counted)."""
    counted = [f for f in findings if f["verdict"] != "by-construction"]
    by = {v: [f for f in counted if f["verdict"] == v] for v in ("holds", "contradicted", "undetermined")}
    walks = max((f.get("n_walks") or 0 for f in counted), default=0)
    parts = [f"Of the {len(counted)} qualitative findings of the paper's section V-D that can fail, tested over "
             f"{walks} walks against interchangeable methods (label permutation, Holm across findings), "
             f"{len(by['holds'])} hold, {len(by['contradicted'])} are contradicted and {len(by['undetermined'])} are "
             f"undetermined; {len(findings) - len(counted)} hold by construction and are not counted."]
    for v in ("holds", "contradicted"):
        if by[v]:
            parts.append(f"{v.capitalize()}: " + "; ".join(
                f"{f['claim']} (effect {format_number(f['effect'])}, 95 % interval {format_number(f['ci95'][0])}..{format_number(f['ci95'][1])}, "
                f"adjusted p {format_number(f['p_adjusted'], '.2g')})" for f in by[v]) + ".")
    if by["undetermined"]:
        reasons = sorted({f["verdict_reason"].split(":")[0] for f in by["undetermined"]})
        parts.append("Undetermined (" + "; ".join(reasons) + "): "
                     + ", ".join(f["id"] for f in by["undetermined"]) + ".")
    return " ".join(parts)
