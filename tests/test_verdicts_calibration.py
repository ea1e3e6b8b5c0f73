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
    assert out["omega2_ci95"][1] <= 0.2
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
