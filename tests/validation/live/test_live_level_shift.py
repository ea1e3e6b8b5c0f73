"""validation.live.level_shift: level shifts beside omega2, per scene, and the scene that carries a verdict."""

import numpy as np
import pytest

from validation.live.config import CONDITIONS, METHODS
from validation.live.level_shift import leave_one_scene_out, level_shift, per_scene

SCENES = ("a", "b", "c", "d")


def _design(n_seeds=12):
    scenes = [s for _ in range(n_seeds) for s in SCENES]
    return scenes, [k for k in range(n_seeds) for _ in SCENES], [f"{s}/seed{k}" for k in range(n_seeds) for s in SCENES]


def test_a_level_shift_that_omega2_cannot_see_is_measured_against_its_margin():
    rng = np.random.default_rng(1)
    scenes, seeds, _ = _design()
    live = 100.0 + np.arange(7.0) + rng.normal(size=(48, 7))
    far = level_shift(live, 0.8 * live, seeds)  # every method 20 % lower: omega2 of a pure scale change is small
    assert far["relative"] == pytest.approx(-0.2) and far["relative_ci95"] == pytest.approx([-0.2, -0.2])
    assert far["verdict"] == "beyond" and far["absolute"] == pytest.approx(-0.2 * live.mean())
    near = level_shift(live, live + 1.0, seeds)
    assert near["relative"] == pytest.approx(1.0 / live.mean()) and near["verdict"] == "within"
    assert level_shift(np.zeros((8, 7)), np.ones((8, 7)))["relative"] is None  # no level to be relative to


def test_per_scene_omega2_and_shift():
    rng = np.random.default_rng(2)
    scenes, _, _ = _design()
    live = np.arange(7.0) + 1.0 + rng.normal(scale=0.1, size=(48, 7))
    emulated = live.copy()
    d = np.array([s == "d" for s in scenes])
    emulated[d] = live[d][:, ::-1]  # scene d: the methods' order reversed
    got = per_scene(live, emulated, scenes)
    assert list(got) == list(SCENES) and got["a"] == {"n_walks": 12, "omega2_untruncated": 0.0, "relative_shift": 0.0}
    assert got["d"]["omega2_untruncated"] > 3 and got["d"]["relative_shift"] == pytest.approx(0.0, abs=1e-12)
    flat = np.ones((48, 7))  # live ties every method (no VO failure anywhere): omega2 is undefined, not huge
    assert {v["omega2_untruncated"] for v in per_scene(flat, flat + 1.0, scenes).values()} == {None}


def test_leave_one_scene_out_names_the_scene_that_carries_a_verdict():
    rng = np.random.default_rng(3)
    scenes, _, walks = _design()
    live = np.arange(7.0) + rng.normal(scale=0.3, size=(48, 7))
    emulated = live + rng.normal(scale=0.05, size=(48, 7))
    d = np.array([s == "d" for s in scenes])
    emulated[d] -= 4.0 * np.arange(7.0)  # scene d alone moves the methods: the interaction is all its own
    tables = {CONDITIONS["cycle-rate live"]: {"median_matches": live},
              CONDITIONS["emulated"]: {"median_matches": emulated}}
    got = leave_one_scene_out(tables, walks, METHODS)
    r = got["emulated vs cycle-rate live: median_matches"]
    assert r["verdict"] == "disagrees" and r["carried_by"] == ["d"] and r["without"]["d"] == "agrees"
    assert {r["without"][s] for s in "abc"} == {"disagrees"}
