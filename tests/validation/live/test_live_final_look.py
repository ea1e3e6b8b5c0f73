"""A pre-registered study's final look: stopped by a rule that does not read the data, judged once on its complete
seeds, with the plan's Monte Carlo rule and the checks beside the verdicts (validation.live.final_checks)."""

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

from validation.live.config import SCENES, LiveConfig, LiveError
from validation.live.final_checks import TARGETS, checks_markdown, targets
from validation.live.monte_carlo import MC_UNDETERMINED, apply_monte_carlo_rule, ruled_verdict
from validation.live.preregistration import (
    PREREG_FILE,
    STOP_FILE,
    complete_seeds,
    interim_reason,
    preregistration,
    stop_record,
)
from tests.validation.live.test_live_preregistration import _records

WHEN = "2026-12-05T01:00:00Z"


def _study(tmp_path, n_complete: int, partial: tuple = ()):
    """A pre-registered folder of 12 seeds (48 walks): seeds 0 .. n_complete-1 with every walk record and raw.json,
    seed n_complete with the walk records of ``partial`` only."""
    import validation.live.experiment as experiment

    cfg = replace(LiveConfig(scenes=tuple(SCENES), n_cycles=8), seed=0)
    out = tmp_path / "study"
    out.mkdir(parents=True)
    (out / experiment.STUDY_FILE).write_text(json.dumps({"config": cfg.to_dict(), "replicates": 12}))
    (out / PREREG_FILE).write_text(json.dumps(preregistration(cfg, 12)))
    recs = _records(12, 8)
    for k in range(n_complete + 1):
        exp = out / "replicates" / f"seed{k}"
        (exp / "walks").mkdir(parents=True)
        for s in (SCENES if k < n_complete else partial):
            (exp / "walks" / f"{s}.json").write_text("{}")
        if k < n_complete:
            (exp / "raw.json").write_text(json.dumps(recs[k]))
    return out


def test_the_stop_record_names_the_complete_seeds_and_the_walks_left_out(tmp_path):
    out = _study(tmp_path, 10, partial=(SCENES[0], SCENES[2]))
    plan = json.loads((out / PREREG_FILE).read_text())
    assert complete_seeds(out, plan) == (list(range(10)), {10: [SCENES[0], SCENES[2]]})
    rec = stop_record(out, " the budget of 24 h of two cores ", when=WHEN)
    assert rec == {"stopped": WHEN, "reason": "the budget of 24 h of two cores", "n_walks": 40, "n_walks_planned": 48,
                   "seeds": list(range(10)), "left_out": {"seed10": [SCENES[0], SCENES[2]]},
                   "look": "final: 40 of the 48 pre-registered walks, the seeds complete at the stop"}
    # the stopped size is the final look; any other size is refused, and without a stop 40 of 48 is interim
    assert interim_reason(plan, 40, rec) is None and "interim look at 40 of the 48" in interim_reason(plan, 40)
    with pytest.raises(LiveError, match="stopped at 40 walks, but 36 are judged"):
        interim_reason(plan, 36, rec)
    with pytest.raises(LiveError, match="needs its reason"):
        stop_record(out, "  ", when=WHEN)
    with pytest.raises(LiveError, match="only a pre-registered study is stopped"):
        stop_record(tmp_path, "budget", when=WHEN)
    empty = _study(tmp_path / "e", 0, partial=(SCENES[1],))
    with pytest.raises(LiveError, match="no seed has every walk finished"):
        stop_record(empty, "budget", when=WHEN)


def test_a_stopped_study_is_judged_once_on_its_complete_seeds_and_redraws_to_the_byte(tmp_path):
    import validation.live.experiment as experiment

    out = _study(tmp_path, 10, partial=(SCENES[1],))
    res = experiment.stop_study(out, "budget", command="test", calibration_studies=0, when=WHEN)
    stop = json.loads((out / STOP_FILE).read_text())
    assert stop["seeds"] == list(range(10)) and stop["left_out"] == {"seed10": [SCENES[1]]}
    pre = res["preregistration"]
    assert res["n_walks"] == 40 and pre["look"].startswith("final: 40 of the 48") and pre["reason"] is None
    assert pre["stop"] == {"file": STOP_FILE, "stopped": WHEN, "reason": "budget"}
    # a final look decides: the simulated emulator is a live draw, so matches agree (an interim look cannot)
    assert res["metrics"]["median_matches"]["verdict"] == "agrees"
    checks = res["final_checks"]
    assert checks["n_walks"] == 40 and checks["bootstrap_resamples"] == 4000 and checks["family_size"] == 4
    # the headline is the Monte Carlo family's verdict after the rule, member by member, with the same adjusted p
    fam = res["comparisons"]["emulated vs cycle-rate live"]["metrics"]
    for key, mc in checks["monte_carlo"].items():
        r = fam[key.partition(": ")[2]]
        assert r["verdict"] == mc["ruled"] and r["p_agrees_adjusted"] == mc["p_agrees_adjusted"]
    assert set(checks["stability"]["counts"]) == set(checks["monte_carlo"])
    assert all(sum(c.values()) == 20 for c in checks["stability"]["counts"].values())
    shift = checks["level_shifts"]["emulated vs cycle-rate live"]["median_matches"]
    assert set(shift["per_scene"]) == set(SCENES) and shift["shift"]["margin"] == 0.1
    assert checks["own_calibration"]["status"] == "not computed"  # calibration_studies 0
    text = (out / "report.md").read_text()
    assert "this look: final: 40 of the 48" in text and "stopped 2026-12-05T01:00:00Z (stop.json): budget" in text
    assert "## The final look's checks" in text and "### Leave one scene out" in text
    # resumed or stopped again: refused; the folder is unchanged
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    cfg = replace(LiveConfig(scenes=tuple(SCENES), n_cycles=8), seed=0)
    with pytest.raises(LiveError, match="a stopped study is not resumed"):
        experiment.run_replicated(out, cfg, 12, command="test", resume=True)
    with pytest.raises(LiveError, match="already stopped 2026-12-05T01:00:00Z"):
        experiment.stop_study(out, "again", when=WHEN)
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before
    # --redraw: from the replicates the stop names, and from walks.csv alone, the same bytes
    experiment.redraw(out, calibration_studies=0)
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before
    table = tmp_path / "table"
    table.mkdir()
    for name in ("results.json", "walks.csv", PREREG_FILE, STOP_FILE, "study.json"):
        shutil.copy(out / name, table / name)
    experiment.redraw(table, calibration_studies=0)
    for name in ("walks.csv", PREREG_FILE, STOP_FILE):
        assert (table / name).read_bytes() == (out / name).read_bytes()
    again = json.loads((table / "results.json").read_text())
    assert again["final_checks"] == json.loads((out / "results.json").read_text())["final_checks"]
    assert again["metrics"] == res["metrics"]


def test_the_monte_carlo_rule_leaves_undetermined_what_the_bootstrap_draws_decide():
    comparisons = {"c": {"metrics": {"a": {"verdict": "agrees", "reason": "bounds"},
                                     "b": {"verdict": "disagrees", "reason": "bounds"}}}}
    family = {"c: a": {"verdict": "agrees", "verdict_mc": MC_UNDETERMINED,
                       "adjusted_mc": {"p_agrees": [0.031, 0.062], "p_disagrees": [1.0, 1.0]}},
              "c: b": {"verdict": "disagrees", "verdict_mc": "disagrees",
                       "adjusted_mc": {"p_agrees": [1.0, 1.0], "p_disagrees": [0.001, 0.004]}}}
    apply_monte_carlo_rule(comparisons, family)
    a, b = comparisons["c"]["metrics"]["a"], comparisons["c"]["metrics"]["b"]
    assert a["verdict"] == "undetermined" and "interval [0.031, 0.062] holds the level" in a["reason"]
    assert b["verdict"] == "disagrees" and b["reason"] == "bounds" and b["adjusted_mc"]["p_disagrees"] == [0.001, 0.004]
    assert [ruled_verdict(r) for r in family.values()] == ["undetermined", "disagrees"]
    with pytest.raises(ValueError, match="the Monte Carlo family says agrees, the headline undetermined"):
        apply_monte_carlo_rule(comparisons, family)  # 'a' was ruled undetermined: other draws than the family's


def _checks(perfect, margin, beyond, share, changed=()):
    def rates(agrees, disagrees):
        return {"own 5 %": {"agrees": 1.0, "disagrees": 0.0}, "family: 5 % / 4": {"agrees": agrees,
                                                                                 "disagrees": disagrees}}
    cal = {"comparisons": {"c": {"metrics": {"m": {
        "status": "computed", "walks_to_decide": {"walks": 120, "towards": "agrees"},
        "scenarios": {"omega2 0": rates(perfect, 0.0), "omega2 0.1": rates(0.5, 0.0),
                      "omega2 0.2": rates(0.1, margin), "omega2 0.3": rates(0.0, beyond)}}}}}}
    return {"monte_carlo": {"c: m": {}}, "own_calibration": cal, "stability": {"changed": list(changed)},
            "stochastic_shares": {"c": {"m": {"kim": share}}}}


@pytest.mark.parametrize("values,met", [((0.80, 0.05, 0.80, 0.40), True), ((0.79, 0.05, 0.80, 0.40), False),
                                         ((0.80, 0.06, 0.80, 0.40), False), ((0.80, 0.05, 0.79, 0.40), False),
                                         ((0.80, 0.05, 0.80, 0.41), False)])
def test_each_target_is_judged_at_the_family_level_at_its_bound(values, met):
    t = targets(_checks(*values))
    entry = t["per_verdict"]["c: m"]
    assert entry["perfect_agrees"]["value"] == values[0] and entry["margin_disagrees"]["value"] == values[1]
    assert entry["beyond_disagrees"]["value"] == values[2] and entry["stochastic_share"]["value"] == values[3]
    assert t["all_met"] is met and entry["walks_to_decide"] == 120
    assert TARGETS["perfect_agrees_min"] == 0.80 and TARGETS["stochastic_share_max"] == 0.40


def test_a_verdict_that_changes_with_the_bootstrap_seed_fails_its_target():
    t = targets(_checks(0.9, 0.0, 0.9, 0.1, changed=["c: m"]))
    assert t["per_verdict"]["c: m"]["stable"] == {"value": None, "met": False} and not t["all_met"]


def test_the_checks_render_every_headline_verdict_with_its_targets(tmp_path):
    import validation.live.experiment as experiment

    out = _study(tmp_path, 10)
    res = experiment.stop_study(out, "budget", command="test", calibration_studies=0, when=WHEN)
    text = checks_markdown(res["final_checks"])
    first = text.split("### Level shifts")[0]
    rows = [ln for ln in first.splitlines() if ln.startswith("| emulated vs cycle-rate live: ")]
    assert len(rows) == res["final_checks"]["family_size"] == 4
    assert all("n/a (not met)" in r for r in rows)  # no own calibration asked for: no target can be met
    assert "Every target met: no." in text and np.isfinite(res["final_checks"]["level_shifts"][
        "emulated vs cycle-rate live"]["median_matches"]["shift"]["relative"])


def test_the_command_line_stops_a_study_once_and_not_with_redraw_or_resume(tmp_path, capsys):
    from validation.live.cli import main

    out = _study(tmp_path, 10)
    assert main(["-o", str(out), "--stop", "budget", "--redraw"]) == 1
    assert "--stop draws a stopped study's verdicts itself" in capsys.readouterr().err and not (out / STOP_FILE).exists()
    assert main(["-o", str(out), "--stop", "the budget: 24 h of two cores", "--calibration-studies", "0", "-q"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["command"] == "python -m validation.live -o . --stop 'the budget: 24 h of two cores'"
    assert json.loads((out / STOP_FILE).read_text())["reason"] == "the budget: 24 h of two cores"
    assert main(["-o", str(out), "--stop", "again"]) == 1 and "already stopped" in capsys.readouterr().err
