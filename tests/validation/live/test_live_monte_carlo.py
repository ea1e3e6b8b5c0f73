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
