"""validation.live.monte_carlo: the headline family as validate live draws it, with its Monte Carlo error."""

import math

import numpy as np
import pytest

from validation.live.config import CONDITIONS, HEADLINE_METRICS, METHODS, SCENES
from validation.live.monte_carlo import headline_family, pvalue_interval, verdict_stability, wilson
from validation.verdicts.agreement import bound_pvalues
from validation.verdicts.simulate import Scales, simulate_tables


def test_wilson_and_the_pvalue_interval_at_the_bootstrap_resolution():
    lo, hi = wilson(0, 1000, 0.99)
    z2 = 2.5758293035489004 ** 2
    assert lo == 0.0 and math.isclose(hi, z2 / (1000 + z2), rel_tol=1e-9)
    # every replicate below the margin: p_agrees is 0.5 / 1000 at the point, up to the Wilson bound of 1 - g
    reps = np.linspace(0.0, 0.1, 1000)
    iv = pvalue_interval(reps, None)
    assert bound_pvalues(reps, None)[0] == pytest.approx(0.0005)
    assert iv["p_agrees"][0] == pytest.approx(0.0005) and iv["p_agrees"][1] == pytest.approx(z2 / (1000 + z2))
    # 15 verdicts in the family: even a verdict with no replicate beyond the margin is not certain at 1000 resamples
    assert 15 * iv["p_agrees"][1] > 0.05
    assert 15 * pvalue_interval(np.linspace(0.0, 0.1, 4000), None)["p_agrees"][1] < 0.05


def _tables(n_seeds=10):
    sim = simulate_tables("live-draw", 4 * n_seeds, Scales(sd_method=1.0, sd_walk_method=0.2, sd_noise=0.2), seed=3)
    live, emu = sim["live"][0], sim["emulated"][0]
    metrics = [m for m in HEADLINE_METRICS if m != "rpe_trans_rank"]
    tables = {run: {m: t for m in metrics} for run, t in ((CONDITIONS["cycle-rate live"], live),
                                                          (CONDITIONS["native-rate live"], live),
                                                          (CONDITIONS["emulated"], emu),
                                                          (CONDITIONS["emulated native"], emu))}
    walks = [f"{s}/seed{k}" for k in range(n_seeds) for s in SCENES]
    return tables, walks


def test_the_family_is_validate_live_s_and_a_sure_verdict_needs_enough_resamples():
    from validation.live.evidence import judge_metrics

    tables, walks = _tables()
    got = headline_family(tables, walks, METHODS, seed=5)
    ref = judge_metrics(tables, METHODS, seed=5, power=False, walks=walks, calibration_studies=0)
    assert len(got) == 12  # 3 headline comparisons x 4 metrics
    for label, c in ref["headlines"]["comparisons"].items():
        for m, r in c["metrics"].items():
            g = got[f"{label}: {m}"]
            assert (g["verdict"], g["p_agrees_adjusted"], g["p_disagrees_adjusted"]) == (
                r["verdict"], r["p_agrees_adjusted"], r["p_disagrees_adjusted"])
    # the emulator agrees on every verdict; with no replicate beyond the margin, the Monte Carlo interval of the
    # smallest p reaches 0.66 % at 1000 resamples: times 12 above 5 %, so no verdict is sure
    assert {r["verdict"] for r in got.values()} == {"agrees"}
    assert {r["verdict_mc"] for r in got.values()} == {"undetermined (Monte Carlo)"}
    sure = headline_family(tables, walks, METHODS, seed=5, n_resamples=4000)
    assert {r["verdict_mc"] for r in sure.values()} == {"agrees"}


def test_stability_over_bootstrap_seeds_counts_each_verdict():
    tables, walks = _tables()
    st = verdict_stability(tables, walks, METHODS, seeds=range(3), n_resamples=200)
    assert st["n_seeds"] == 3 and all(sum(v.values()) == 3 for v in st["counts"].values())
    assert st["changed"] == sorted(k for k, v in st["counts"].items() if len(v) > 1)


def _controlled(n_seeds=12, omega2=0.2):
    """Headline tables near the margin (p's away from the bootstrap's floor) with a re-seeded control for each live
    reference whose walks 3 and 17 have a missing value: judge drops those walks from its comparison."""
    from validation.live.config import RESEEDED

    sim = simulate_tables("exact", 4 * n_seeds, Scales(sd_method=1.0, sd_walk_method=0.5, sd_noise=0.3), seed=11,
                          omega2_true=omega2)
    live, emu, ctrl = sim["live"][0], sim["emulated"][0], sim["control"][0].copy()
    ctrl[[3, 17], 2] = np.nan
    metrics = [m for m in HEADLINE_METRICS if m != "rpe_trans_rank"]
    runs = {CONDITIONS["cycle-rate live"]: live, CONDITIONS["emulated"]: emu,
            RESEEDED[CONDITIONS["cycle-rate live"]]: ctrl}
    tables = {run: {m: t for m in metrics} for run, t in runs.items()}
    return tables, [f"{s}/seed{k}" for k in range(n_seeds) for s in SCENES]


def test_the_family_is_drawn_on_judge_s_walks_when_the_control_misses_some():
    from validation.live.evidence import judge_metrics

    tables, walks = _controlled()
    got = headline_family(tables, walks, METHODS, seed=2)
    ref = judge_metrics(tables, METHODS, seed=2, power=False, walks=walks, calibration_studies=0)
    c = ref["comparisons"]["emulated vs cycle-rate live"]["metrics"]
    ps = []
    for m, r in c.items():
        if f"emulated vs cycle-rate live: {m}" not in got:  # outside the headline family
            continue
        g = got[f"emulated vs cycle-rate live: {m}"]
        assert g["n_walks"] == r["n_walks"] == 46  # the two walks without a control value are left out by both
        assert (g["verdict"], g["verdict_alone"], g["p_agrees"], g["p_disagrees"]) == (
            r["verdict"], r["verdict_alone"], r["p_agrees"], r["p_disagrees"])
        assert (g["p_agrees_adjusted"], g["p_disagrees_adjusted"]) == (r["p_agrees_adjusted"],
                                                                       r["p_disagrees_adjusted"])
        ps += [g["p_agrees"], g["p_disagrees"]]
    assert any(0.01 < p < 0.99 for p in ps)  # p's off the floor: another walk set would move them
    # the rule applied inside judge_metrics accepts the family (it refuses one of other walks)
    ruled = judge_metrics(tables, METHODS, seed=2, power=False, walks=walks, calibration_studies=0,
                          monte_carlo_rule=True)
    for m, r in ruled["comparisons"]["emulated vs cycle-rate live"]["metrics"].items():
        key = f"emulated vs cycle-rate live: {m}"
        assert key not in got or r["verdict_mc"] == got[key]["verdict_mc"]


def test_the_family_of_one_method_is_undetermined_not_an_error():
    tables, walks = _controlled()
    one = {run: {m: t[:, :1] for m, t in per.items()} for run, per in tables.items()}
    got = headline_family(one, walks, METHODS[:1], seed=2)
    assert got and {r["verdict"] for r in got.values()} == {"undetermined"}
    assert {r["verdict_mc"] for r in got.values()} == {"undetermined"}
    assert all(r["adjusted_mc"] == {"p_agrees": [1.0, 1.0], "p_disagrees": [1.0, 1.0]} for r in got.values())
