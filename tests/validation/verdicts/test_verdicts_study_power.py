"""validation.verdict_studies.study_power (exposim validate study-power): what a finished study can decide, from its own walks."""

import json

import numpy as np
import pytest

from emulator.commands.cli import main as exposim
from validation.verdict_studies.study_power import PAPER_EFFECTS, paper_sized_power, study_units

METHODS = ("fixed", "classical-30", "classical-50", "classical-70", "shim", "zhang", "kim")


def test_paper_effects_are_the_findings_on_the_papers_numbers():
    e = {fid: (round(r["paper_effect"], 6), round(r["paper_level"], 6), r["transfer"])
         for fid, r in PAPER_EFFECTS.items()}
    assert e == {
        "rpe_trans_worst_kim": (0.65, round((4.21 + 5.75 + 5.1) / 3, 6), "relative"),  # 5.75 - 5.1
        "rpe_trans_best_50": (0.89, round((4.21 + 5.75 + 5.1) / 3, 6), "relative"),  # 5.1 - 4.21
        "fixed_not_best_vo": (0.89, round((4.21 + 5.75 + 5.1) / 3, 6), "relative"),
        "rpe_rot_best_zhang_50": (0.02, round((0.07 + 0.07 + 0.09) / 3, 6), "relative"),
        "fixed_best_success_sequences": (0.24, round((0.44 + 3 * 0.2) / 4, 6), "absolute"),  # 44 % against 20 %
        "poorest_success_30_70_kim_sequences": (0.24, round((0.44 + 3 * 0.2) / 4, 6), "absolute"),
    }


def _units(rpe):
    return [{m: {"median_matches": 10.0, "vo": {"rpe_trans_pct": float(rpe[w, k]), "rpe_rot_deg_per_m": 0.1}}
             for k, m in enumerate(METHODS)} for w in range(rpe.shape[0])]


def test_paper_sized_effect_in_the_studys_residual_sds(tmp_path):
    rng = np.random.default_rng(1)
    r = rng.normal(size=(12, 7))
    r = r - r.mean(axis=0) - r.mean(axis=1, keepdims=True) + r.mean()  # walk x method part only
    a = rng.normal(size=(12, 1))
    rpe = 2.0 + (a - a.mean()) + r  # level 2 %, no method effect
    row = paper_sized_power(_units(rpe), n_seeds=5, candidates=(12,))["rpe_trans_worst_kim"]
    sd = np.sqrt((r ** 2).sum() / (11 * 6))  # the two-way residual
    assert row["level"] == pytest.approx(2.0) and row["sd_residual"] == pytest.approx(sd)
    assert row["effect_study_units"] == pytest.approx(0.65 * 2.0 / ((4.21 + 5.75 + 5.1) / 3))
    assert row["effect_noise_sd"] == pytest.approx(row["effect_study_units"] / sd)
    assert 0.0 <= row["power_at_size"] <= 1.0 and row["n_walks_power"] == 12
    assert row["effect_noise_sd_by_method_sd"] == 0.0  # no method effect here: the other transfer gives 0
    # a live study folder: the walks of one run, from each replicate's raw.json
    for seed in (0, 1):
        units = _units(rpe[6 * seed:6 * seed + 6])
        per_scene = {f"s{k}": u for k, u in enumerate(units)}
        rec = {"config": {"scenes": list(per_scene)}, "summaries": {"emulated-plain": {"per_scene": per_scene}}}
        (tmp_path / "replicates" / f"seed{seed}").mkdir(parents=True)
        (tmp_path / "replicates" / f"seed{seed}" / "raw.json").write_text(json.dumps(rec))
    kind, got = study_units(tmp_path)
    assert kind == "live" and len(got) == 12 and got[7]["kim"]["vo"]["rpe_trans_pct"] == rpe[7, 6]
    assert exposim(["validate", "study-power", str(tmp_path / "nowhere")]) == 1
