"""Calibration of the verdicts on simulated metric tables (validation.verdicts; no renders).

Scales: method effects with SD 1 over 7 methods, walk x method interaction SD 0.5, run
noise SD 1.0 (median matches) or 2.8 (RPE) per walk: what the live study's control implies
(validation.verdicts.NOISE_TO_METHOD_SD).
"""

import numpy as np
import pytest

from validation.verdicts import NOISE_TO_METHOD_SD, STUDY_WALKS
from validation.verdicts.agreement import judge
from validation.verdicts.power import scales_from_tables, verdict_rates
from validation.verdicts.simulate import Scales, simulate_tables

MATCHES = Scales(sd_method=1.0, sd_walk_method=0.5, sd_noise=NOISE_TO_METHOD_SD["matches"])
RPE = Scales(sd_method=1.0, sd_walk_method=0.5, sd_noise=NOISE_TO_METHOD_SD["rpe"])


def calibrated(perfect: dict, random: dict) -> bool:
    """The issue's criteria at the study's size: a perfect emulator agrees >= 80 % and disagrees <= 5 %,
    a random one disagrees >= 80 % and agrees <= 5 %."""
    return (perfect["agrees"] >= 0.8 and perfect["disagrees"] <= 0.05 and random["disagrees"] >= 0.8
            and random["agrees"] <= 0.05)


def test_undetermined_everywhere_fails_the_criteria():
    never = {"agrees": 0.0, "disagrees": 0.0, "undetermined": 1.0}
    assert not calibrated(never, never)
    # and the criteria are not vacuous: the verdict rule meets them at the study's size (slow test below)


@pytest.mark.parametrize("scales", [MATCHES, RPE], ids=["matches", "rpe"])
def test_small_studies_make_no_false_claims(scales):
    # 10 walks: too few to decide agreement at these noise levels, but never the wrong way
    perfect = verdict_rates("live-draw", 10, scales, n_seeds=200, n_resamples=200, seed=1)
    random = verdict_rates("random", 10, scales, n_seeds=200, n_resamples=200, seed=2)
    assert perfect["disagrees"] <= 0.05
    assert random["agrees"] <= 0.05


def test_quick_sized_study_is_undetermined():
    # --quick: 4 walks (one per scene): every verdict undetermined, whatever the emulator
    for kind in ("live-draw", "random", "tied"):
        r = verdict_rates(kind, 4, MATCHES, n_seeds=50, n_resamples=100, seed=3)
        assert r["undetermined"] == 1.0


@pytest.mark.slow
def test_perfect_and_random_emulators_at_the_study_size():
    perfect = verdict_rates("live-draw", STUDY_WALKS, MATCHES, n_seeds=300, n_resamples=200, seed=11)
    random = verdict_rates("random", STUDY_WALKS, MATCHES, n_seeds=300, n_resamples=200, seed=12)
    assert calibrated(perfect, random), (perfect, random)
    # at the RPE noise level the study makes no false claim either
    perfect = verdict_rates("live-draw", STUDY_WALKS, RPE, n_seeds=300, n_resamples=200, seed=13)
    random = verdict_rates("random", STUDY_WALKS, RPE, n_seeds=300, n_resamples=200, seed=14)
    assert perfect["disagrees"] <= 0.05 and random["agrees"] <= 0.05


def test_tied_emulator_and_tied_live():
    # an emulator that ties every method is not agreement: omega2 is 1 (it loses every contrast)
    r = verdict_rates("tied", 30, Scales(1.0, 0.2, 0.5), n_seeds=100, n_resamples=200, seed=4)
    assert r["agrees"] == 0.0 and r["disagrees"] >= 0.9
    # live ties every method: undetermined with that reason, whatever the emulator does
    live = np.zeros((20, 7))
    emu = np.random.default_rng(0).normal(size=(20, 7))
    out = judge(live, emu, np.zeros((20, 7)), n_resamples=100)
    assert out["verdict"] == "undetermined" and "ties live" in out["reason"]
    assert out["tau_live_emulated"] is None and out["tau_live_live"] is None


def test_judge_details_on_a_clear_case():
    t = simulate_tables("live-draw", 40, Scales(1.0, 0.3, 0.3), seed=5)
    names = ["a", "b", "c", "d", "e", "f", "g"]
    out = judge(t["live"][0], t["emulated"][0], t["control"][0], methods=names, margin=0.5, n_resamples=300)
    assert out["verdict"] == "agrees"
    assert out["omega2_ci90"][1] <= 0.2
    assert out["disattenuated_correlation"] > 0.95
    assert out["tau_live_emulated"] > 0.8 and out["tau_live_live"] > 0.8
    # adjacent methods differ by 0.54 (method SD 1 over 7 evenly spaced): most pairs differ live,
    # and every significant pair is equivalent within 0.5 (noise of a 40-walk mean of a difference: ~0.07)
    assert out["pairs_live_significant"] >= 19
    assert out["pairs_equivalent"] == out["pairs_live_significant"]
    assert out["pairs_reversed"] == 0
    # a walk with a missing value is left out
    live = t["live"][0].copy()
    live[3, 2] = np.nan
    assert judge(live, t["emulated"][0], n_resamples=50, detail=False)["n_walks"] == 39


def test_scales_from_tables_recovers_the_components():
    sc = Scales(sd_method=2.0, sd_walk_method=1.0, sd_noise=0.5, sd_walk=3.0)
    t = simulate_tables("live-draw", 400, sc, seed=6)
    got = scales_from_tables(t["live"][0], control=t["control"][0])
    assert got.sd_method == pytest.approx(2.0, rel=0.05)
    assert got.sd_noise == pytest.approx(0.5, rel=0.1)
    assert got.sd_walk_method == pytest.approx(1.0, rel=0.1)
    assert got.sd_walk == pytest.approx(3.0, rel=0.15)


def test_one_sided_bounds_are_bias_corrected_below_and_truncated():
    from validation.verdicts.agreement import one_sided_bounds

    r = np.linspace(-1.0, 1.0, 2001)  # replicates centred on the estimate: no bias to correct
    lo, hi = one_sided_bounds(r, 0.0)
    assert lo == 0.0 and hi == pytest.approx(0.9)  # the 5 % percentile -0.9, truncated at 0
    lo, hi = one_sided_bounds(r + 2.0, 2.0)
    assert (lo, hi) == pytest.approx((1.1, 2.9))
    # replicates biased upwards (an estimate at their 16th percentile): the lower bound moves down, by
    # 2 z0; the upper bound keeps the plain percentile (the corrected one was measured too low)
    from scipy.stats import norm

    est = float(np.quantile(r, norm.cdf(-1.0)))
    lo, hi = one_sided_bounds(r + 2.0, est + 2.0)
    assert lo == pytest.approx(2.0 + np.quantile(r, norm.cdf(-2.0 - 1.6448536)), abs=2e-3)
    assert hi == pytest.approx(2.9)


def test_the_rule_at_the_margin_keeps_its_level():
    # true omega2 exactly 0.2 (the margin): agrees and disagrees each in at most 5 % of 300 studies (plus
    # three binomial standard errors); a perfect emulator still agrees at 56 walks
    tol = 3 * np.sqrt(0.05 * 0.95 / 300)
    r = verdict_rates("exact", 30, MATCHES, n_seeds=300, n_resamples=200, seed=21, omega2_true=0.2)
    assert r["agrees"] <= 0.05 + tol and r["disagrees"] <= 0.05 + tol, r
    assert verdict_rates("live-draw", 56, MATCHES, n_seeds=100, n_resamples=200, seed=22)["agrees"] >= 0.8


def test_exact_interaction_is_exact():
    t = simulate_tables("exact", 5, Scales(1.0, 0.0, 0.0, 0.0), n_seeds=3, seed=1, omega2_true=0.2)
    from validation.verdicts.agreement import omega2

    np.testing.assert_allclose(omega2(t["live"], t["emulated"]), 0.2)  # no noise: the estimate is the truth


def test_cluster_plan_draws_whole_seeds():
    from validation.verdicts.ranking import cluster_plan

    seeds = np.repeat(np.arange(5), 4)  # 5 seeds x 4 scenes, walks ordered by seed
    plan = cluster_plan(20, 50, 0, seeds)
    assert plan.shape == (50, 20)
    blocks = plan.reshape(50, 5, 4)
    assert np.all(blocks == blocks[..., :1] + np.arange(4))  # each block is one seed's 4 walks, in scene order
    uneven = cluster_plan(5, 30, 0, [0, 0, 1, 1, 1])
    assert isinstance(uneven, list) and all(len(p) in (4, 5, 6) for p in uneven)
    assert cluster_plan(6, 10, 0).shape == (10, 6)
    with pytest.raises(ValueError, match="one label per walk"):
        cluster_plan(6, 10, 0, [0, 1])


def test_margin_in_ranking_terms_for_two_methods_is_analytic():
    from scipy.stats import norm

    from validation.verdicts.ranking import margin_in_ranking_terms

    # two methods g apart: the interaction moves their difference by N(0, omega2 g^2), so the best
    # changes with probability Phi(-1 / sqrt(omega2)), and tau = 1 - 2 P
    r = margin_in_ranking_terms([0.0, 3.0], 0.2, n_draws=40000, seed=0)
    p = norm.cdf(-1.0 / np.sqrt(0.2))
    assert r["best_method_changes_probability"] == pytest.approx(p, abs=0.003)
    assert r["expected_kendall_tau"] == pytest.approx(1 - 2 * p, abs=0.006)
    assert margin_in_ranking_terms([1.0, 2.0, 3.0], 0.0)["expected_kendall_tau"] == 1.0
    assert margin_in_ranking_terms([2.0, 2.0, 2.0], 0.2) is None
    low = margin_in_ranking_terms([0.0, 3.0], 0.2, higher_is_better=False, n_draws=40000, seed=0)
    assert low["best_method_changes_probability"] == pytest.approx(p, abs=0.003)


def test_emulation_bias_and_the_noisy_method():
    from validation.verdicts.ranking import cluster_plan, emulation_bias

    rng = np.random.default_rng(3)
    live = rng.normal(size=(40, 3))
    emu = live + [0.0, 0.5, 0.0] + rng.normal(size=(40, 3)) * [0.01, 0.01, 3.0]  # the third far noisier
    b = emulation_bias(live, emu, ["a", "b", "c"], cluster_plan(40, 500, 0))
    d = emu - live
    assert b["b"]["mean"] == pytest.approx(d[:, 1].mean()) and b["b"]["ci95"][0] > 0.49
    assert b["a"]["ci95"][0] < 0 < b["a"]["ci95"][1]
    assert b["c"]["sd_over_walks"] == pytest.approx(d[:, 2].std(ddof=1))
    assert b["c"]["residual_variance_share"] > 0.6  # two thirds or more of the interaction's residual


def test_pairs_check_exact_cases():
    from validation.verdicts.ranking import pairs_check

    d = np.array([[0.1, -0.1], [0.0, 0.1], [-0.1, 0.0], [0.05, 0.0]])
    r = pairs_check(d, 1.0)
    assert r["verdict"] == "agrees" and r["bound"] < 1.0
    assert pairs_check(d + 5.0, 1.0)["verdict"] == "disagrees"
    assert pairs_check(d, None)["verdict"] == "undetermined" and "margin" in pairs_check(d, None)["reason"]
    assert "no pair" in pairs_check(d[:, :0], 1.0)["reason"]
    wide = pairs_check(np.array([[3.0], [-3.0], [2.0], [-2.0]]), 1.0)
    assert wide["verdict"] == "undetermined"


def test_a_taus_interval_holds_its_own_estimate():
    """Kendall tau at its bound of 1: the bootstrap replicates all lie below, and a percentile interval left
    the estimate out (1.0 [0.24, 0.90] in a 48-walk study); the interval is widened to hold it."""
    from validation.verdicts.agreement import _covering

    assert _covering(1.0, 0.24, 0.90) == (0.24, 1.0)
    assert _covering(-1.0, -0.9, 0.2) == (-1.0, 0.2)
    assert _covering(0.5, 0.2, 0.9) == (0.2, 0.9)
    assert _covering(float("nan"), 0.2, 0.9) == (0.2, 0.9)
    # seven methods 0.2 apart under noise of 1, a perfect emulator (a re-drawn live run): this draw's means
    # order alike (tau 1), while the bootstrap's percentile interval alone would be [0.33, 0.90]
    rng = np.random.default_rng(29)
    effects = np.linspace(0.0, 1.2, 7)
    live, control = effects + rng.normal(0.0, 1.0, (40, 7)), effects + rng.normal(0.0, 1.0, (40, 7))
    r = judge(live, control.copy(), control, n_resamples=300, seed=0)
    assert r["tau_live_live"] == 1.0 and r["tau_live_live_ci95"][1] == 1.0
    assert r["tau_live_live_ci95"][0] == pytest.approx(1 / 3)
    for key in ("tau_live_emulated", "tau_live_live"):
        lo, hi = r[key + "_ci95"]
        assert lo <= r[key] <= hi
