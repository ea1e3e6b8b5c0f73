"""validation.verdict_studies.own_residuals: the verdict rule calibrated on the emulator's own residuals."""

import math

import numpy as np

from validation.verdict_studies.own_residuals import metric_own_calibration, own_residuals, scenario_rates

SCENES = ("a", "b", "c", "d")


def _design(n_seeds: int):
    scenes = [s for _ in range(n_seeds) for s in SCENES]
    seeds = [k for k in range(n_seeds) for _ in SCENES]
    return scenes, seeds


def test_the_bias_is_removed_within_each_scene_and_the_residual_rescaled():
    live = np.zeros((4, 2))
    emulated = np.array([[1.0, 5.0], [3.0, 5.0], [10.0, 0.0], [10.0, 2.0]])
    r, ok = own_residuals(live, emulated, ["x", "x", "y", "y"])
    # scene x: d = (1, 3) on method 0, mean 2 -> (-1, 1) * sqrt(2); method 1 constant -> 0
    np.testing.assert_allclose(r, [[-math.sqrt(2), 0], [math.sqrt(2), 0], [0, -math.sqrt(2)], [0, math.sqrt(2)]])
    assert ok.all()
    # a missing value leaves its walk out; a scene with a single complete walk has no residual
    emulated[0, 1] = np.nan
    r, ok = own_residuals(live, emulated, ["x", "x", "y", "y"])
    assert ok.tolist() == [False, False, True, True] and np.isnan(r[1]).all()


def test_rates_at_the_own_and_the_family_level():
    batch = {"live_p": np.array([0.01, 0.01, 0.01, 0.2]), "tied": np.array([False, False, False, False]),
             "p_agrees": np.array([0.001, 0.02, 0.9, 0.001]), "p_disagrees": np.array([0.9, 0.9, 0.004, 0.9])}
    got = scenario_rates(batch, 10, {"own": 0.05, "family": 0.05 / 15})
    assert got["own"] == {"agrees": 0.5, "disagrees": 0.25, "undetermined": 0.25}  # the 4th: live ties at 5 %
    assert got["family"] == {"agrees": 0.25, "disagrees": 0.0, "undetermined": 0.75}
    assert scenario_rates(batch, 9, {"own": 0.05})["own"]["undetermined"] == 1.0  # fewer than 10 seeds


def test_a_biased_emulator_without_residual_is_perfect_and_injected_interactions_are_found():
    rng = np.random.default_rng(4)
    scenes, seeds = _design(12)
    live = np.arange(7.0) + rng.normal(scale=0.5, size=(48, 7))
    bias = {s: rng.normal(scale=3.0, size=7) for s in SCENES}  # a large per-scene, per-method bias, nothing else
    emulated = live + np.array([bias[s] for s in scenes])
    res = metric_own_calibration(live, emulated, scenes, seeds, family_size=15, n_studies=40, seed=1)
    assert res["status"] == "computed" and res["seeds_drawn_from"] == 12 and res["omega2_untruncated"] > 0.2
    perfect = res["scenarios"]["omega2 0"]
    assert perfect["own 5 %"]["agrees"] == 1.0 and perfect["family: 5 % / 15"]["agrees"] == 1.0
    assert res["scenarios"]["omega2 0.3"]["own 5 %"]["agrees"] == 0.0
    assert res["walks_to_decide"]["towards"] == "disagrees"
    # the observed omega2 lies far above the margin: decided at the rule's fewest seeds
    assert res["walks_to_decide"]["walks"] == 40 and res["walks_to_decide"]["alpha"] == 0.05 / 15


def test_the_residual_ratio_to_live_against_live():
    rng = np.random.default_rng(5)
    scenes, seeds = _design(12)
    live = np.arange(7.0) + rng.normal(size=(48, 7))
    noise = rng.normal(size=(48, 7))
    res = metric_own_calibration(live, live + 2.0 * noise, scenes, seeds, reseeded=live + noise, n_studies=5,
                                 walks_to_decide=False)
    assert math.isclose(res["residual_sd"]["ratio"], 2.0, rel_tol=1e-12)


def test_the_bisection_finds_the_first_size_that_reaches_the_target():
    from validation.verdicts.plasmode import first_reaching

    rates = [0.1, 0.5, 0.85, 0.95]
    asked = []

    def rate(i):
        asked.append(i)
        return rates[i]

    assert first_reaching(rate, 0, 3, 0.8) == 2 and 0 not in asked  # bisected, not scanned
    assert first_reaching(rate, 0, 3, 0.99) is None
    assert first_reaching(rate, 4, 3, 0.8) is None  # an empty range


def test_a_metric_on_which_live_ties_every_method_is_not_computed_and_can_be_written():
    from emulator.io.files import to_jsonable

    scenes, seeds = _design(12)
    flat = np.ones((48, 7))
    res = metric_own_calibration(flat, flat + np.random.default_rng(6).normal(size=(48, 7)), scenes, seeds,
                                 n_studies=5)
    assert res["status"] == "not computed" and res["omega2_untruncated"] is None
    to_jsonable(res)  # every figure finite: a --json file can hold it
