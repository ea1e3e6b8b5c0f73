"""validation.live.headline: RPE with a lost VO ranked worst, the headline family (Holm), walks to decide."""

import numpy as np
import pytest

from validation.live.config import CONDITIONS, HEADLINE_COMPARISONS, HEADLINE_METRICS, METHODS, RPE_RANK
from validation.live.headline import OWN_FAMILY, apply_family, rpe_rank_table, walks_to_decide, with_derived
from validation.verdicts.agreement import bound_pvalues, judge_batch, one_sided_bounds
from validation.verdicts.simulate import Scales, simulate_tables


def test_a_lost_vo_ranks_worst_and_an_unrun_vo_stays_missing():
    nan = np.nan
    rpe = [[1.0, nan, 3.0, 2.0], [nan, 2.0, nan, 1.0], [1.0, 2.0, 3.0, 4.0], [nan, nan, nan, nan]]
    failed = [[0, 5, 0, 0], [3, 0, 7, 0], [0, 0, 0, nan], [1, 1, 1, 1]]
    r = rpe_rank_table(rpe, failed)
    np.testing.assert_array_equal(r[0], [1, 4, 3, 2])
    np.testing.assert_array_equal(r[1], [3.5, 2, 3.5, 1])  # two lost: tied at the two worst ranks
    assert np.all(np.isnan(r[2]))  # one method's VO never ran: not an outcome, missing
    np.testing.assert_array_equal(r[3], [2.5] * 4)  # every method lost it: a tie, the walk kept
    t = with_derived({"live": {"rpe_trans_pct": np.asarray(rpe), "vo_failed_frames": np.asarray(failed, float)},
                      "other": {"median_matches": np.ones((4, 4))}})
    assert RPE_RANK in t["live"] and RPE_RANK not in t["other"]


def test_rpe_keeps_the_walks_where_vo_was_lost_and_the_complete_walks_are_the_sensitivity():
    from validation.live.evidence import judge_metrics

    sim = simulate_tables("live-draw", 40, Scales(sd_method=1.0, sd_walk_method=0.3, sd_noise=0.3), seed=5)
    live, emu = sim["live"][0] + 10, sim["emulated"][0] + 10
    tables = {}
    for run, t in ((CONDITIONS["cycle-rate live"], live.copy()), (CONDITIONS["emulated"], emu.copy())):
        t[:12, -1] = np.nan  # the last method loses its VO on 12 walks, in both conditions
        tables[run] = {m: t for m in ("median_uniformity", "median_matches", "success_rate_tau100",
                                      "segment_success_rate_tau100", "rpe_trans_pct")}
        tables[run]["vo_failed_frames"] = np.where(np.isnan(t), 4.0, 0.0)
    walks = [f"s{k % 4}/seed{k // 4}" for k in range(40)]
    res = judge_metrics(tables, METHODS, power=False, walks=walks, n_resamples=200)
    comp = res["comparisons"]["emulated vs cycle-rate live"]["metrics"]
    assert comp[RPE_RANK]["n_walks"] == 40 and comp["rpe_trans_pct"]["n_walks"] == 28
    live_rank = with_derived(tables)[CONDITIONS["cycle-rate live"]][RPE_RANK]
    assert np.all(live_rank[:12, -1] == 7)  # the lost VO ranks last of seven
    assert res["metrics"]["rpe_trans_pct"]["family"].startswith("outside the headline family: the sensitivity")
    assert res["metrics"][RPE_RANK]["family"].startswith("headline: 5 verdicts (5 distinct metrics x 1 comparisons)")
    assert res["metrics"]["success_rate_tau100"]["family"].startswith("outside the headline family: the same")


def _fake(p_agrees: dict, verdicts: dict) -> dict:
    comps = {}
    for label in list(HEADLINE_COMPARISONS)[:2] + ["emulated vs same-instant live"]:
        comps[label] = {"status": "run", "reference": "live-fixed-instant", "metrics": {}}
        for m in HEADLINE_METRICS + ("success_rate_tau100",):
            comps[label]["metrics"][m] = {"verdict": verdicts.get((label, m), "undetermined"), "reason": "bounds",
                                          "n_walks": 40, "live_method_p": 1e-6,
                                          "p_agrees": p_agrees.get((label, m), 0.9), "p_disagrees": 0.9}
    comps[list(HEADLINE_COMPARISONS)[2]] = {"status": "not run"}
    return comps


def test_holm_across_the_headline_family():
    a, b = list(HEADLINE_COMPARISONS)[:2]
    strong, weak = (a, "median_matches"), (b, "median_uniformity")
    comps = _fake({strong: 0.001, weak: 0.01}, {strong: "agrees", weak: "agrees"})
    fam = apply_family(comps)
    assert fam["size"] == 10 and len(fam["members"]) == 10  # 5 distinct metrics x the 2 comparisons that ran
    s, w = comps[a]["metrics"]["median_matches"], comps[b]["metrics"]["median_uniformity"]
    assert s["verdict"] == "agrees" and s["p_agrees_adjusted"] == pytest.approx(0.01)  # 0.001 x 10
    assert w["verdict"] == "undetermined" and w["verdict_alone"] == "agrees"
    assert w["p_agrees_adjusted"] == pytest.approx(0.09)  # 0.01 x 9
    assert "not at the family's level" in w["reason"]
    assert s["family"].startswith("headline: 10 verdicts (5 distinct metrics x 2 comparisons), Holm")
    assert comps[a]["metrics"]["success_rate_tau100"]["family"].startswith("outside the headline family")
    assert comps["emulated vs same-instant live"]["metrics"]["median_matches"]["family"] == OWN_FAMILY
    # a verdict that cannot be decided counts in the family with p = 1 (never a smaller family)
    comps = _fake({strong: 0.004}, {strong: "agrees"})
    for r in comps[b]["metrics"].values():
        r["live_method_p"] = 0.5
    apply_family(comps)
    assert comps[a]["metrics"]["median_matches"]["p_agrees_adjusted"] == pytest.approx(0.04)


def test_bound_pvalues_are_the_bounds_levels():
    r = np.arange(1000) / 1000.0
    pa, pd = bound_pvalues(r, 0.4995, 0.2)  # z0 = 0: plain and bias-corrected coincide
    assert pd == pytest.approx(0.201) and pa == pytest.approx(0.799)
    # on simulated studies the verdict from the p-values is the verdict from the bounds (up to interpolation)
    sim = simulate_tables("exact", 30, Scales(1.0, 0.5, 1.0), seed=3, n_seeds=150, omega2_true=0.1)
    b = judge_batch(sim["live"], sim["emulated"], n_resamples=400, seed=1)
    assert np.mean((b["hi"] <= 0.2) == (b["p_agrees"] <= 0.05)) >= 0.97
    assert np.mean((b["lo"] > 0.2) == (b["p_disagrees"] <= 0.05)) >= 0.97
    lo, hi = one_sided_bounds(r, 0.4995)  # one order statistic either side of the upper bound
    assert bound_pvalues(r, 0.4995, hi + 0.002)[0] <= 0.05 < bound_pvalues(r, 0.4995, hi - 0.002)[0]
    assert bound_pvalues(r, 0.4995, lo - 0.002)[1] <= 0.05 < bound_pvalues(r, 0.4995, lo + 0.002)[1]


def test_walks_to_decide_points_the_way_the_estimate_does():
    sc = Scales(sd_method=1.0, sd_walk_method=0.1, sd_noise=0.1)
    near = walks_to_decide(sc, 0.0, n_seeds=20, seed=1)
    assert near == {"walks": 10, "towards": "agrees", "rate": 1.0, "level": 0.05}
    far = walks_to_decide(sc, 3.0, n_seeds=20, seed=1, alpha=0.05 / 15)
    assert far["towards"] == "disagrees" and far["walks"] == 10 and far["level"] == pytest.approx(0.05 / 15)
    # at the margin itself nothing decides (omega2 = 0.2 exactly is neither side's)
    edge = walks_to_decide(Scales(1.0, 0.5, 1.0), 0.2, n_seeds=20, seed=1, candidates=(10, 30))
    assert edge["walks"] is None and edge["reason"] == "not within 30 walks"
    assert walks_to_decide(Scales(0.0, 0.1, 0.1), 0.0)["walks"] is None
    assert walks_to_decide(sc, None)["reason"].startswith("no measured")


def test_the_report_says_when_a_walk_is_one_segment_and_the_level_walks_to_decide_uses():
    import json
    from pathlib import Path

    from validation.live.headline import headlines_markdown

    study = Path(__file__).resolve().parents[3] / "docs" / "results" / "live-study-2026-11-28" / "results.json"
    results = json.loads(study.read_text())  # a study of 8-cycle walks, segments of 10 pairs
    assert (results["config"]["n_cycles"], results["config"]["segment_pairs"]) == (8, 10)
    short = headlines_markdown(results)
    assert ("At this walk length (7 match pairs per walk, segments of 10) a walk is one segment: the segment "
            "success rate is the sequence success rate." in short)
    assert "at Holm's strictest level (5 % divided by the family's size)" in short
    assert "the verdict's own level" not in short
    for cycles, one in ((11, True), (12, False), (40, False)):  # 11 pairs: segments of 10, the tail dropped
        text = headlines_markdown({**results, "config": {**results["config"], "n_cycles": cycles}})
        assert ("a walk is one segment" in text) is one
