"""A pre-registered study's final look: stopped by a rule that does not read the data, judged once on its complete
seeds, with the plan's Monte Carlo rule and the checks beside the verdicts (validation.live.final_checks)."""

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

from validation.live.config import SCENES, LiveConfig, LiveError
from validation.live.final_checks import LEVEL_SHIFT_WALKS, TARGETS, checks_markdown, targets
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


def _study(tmp_path, n_complete: int, partial: tuple = (), command: str | None = None):
    """A pre-registered folder of 12 seeds (48 walks): seeds 0 .. n_complete-1 with every walk record, raw.json and
    their results (an empty results.json), seed n_complete with the walk records of ``partial`` only; ``command``: the study's command line, recorded by
    each complete walk's VO benchmark (``{out}`` is the folder)."""
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
            if command is not None and k < n_complete:
                (exp / "vo" / s / "live-same-instant").mkdir(parents=True)
                (exp / "vo" / s / "live-same-instant" / "results.json").write_text(
                    json.dumps({"command": command.format(out=out)}))
        if k < n_complete:
            (exp / "raw.json").write_text(json.dumps(recs[k]))
            (exp / "results.json").write_text("{}")
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


def _judged(verdict, alone, pa, pd, n=40):
    return {"verdict": verdict, "verdict_alone": alone, "n_walks": n, "p_agrees_adjusted": pa,
            "p_disagrees_adjusted": pd}


def test_the_monte_carlo_rule_leaves_undetermined_what_the_bootstrap_draws_decide():
    comparisons = {"c": {"metrics": {"a": {**_judged("agrees", "agrees", 0.04, 1.0), "reason": "bounds"},
                                     "b": {**_judged("disagrees", "disagrees", 1.0, 0.002), "reason": "bounds"},
                                     "u": {**_judged("undetermined", "agrees", 0.07, 1.0), "reason": "family"}}}}
    family = {"c: a": {**_judged("agrees", "agrees", 0.04, 1.0), "verdict_mc": MC_UNDETERMINED,
                       "adjusted_mc": {"p_agrees": [0.031, 0.062], "p_disagrees": [1.0, 1.0]}},
              "c: b": {**_judged("disagrees", "disagrees", 1.0, 0.002), "verdict_mc": "disagrees",
                       "adjusted_mc": {"p_agrees": [1.0, 1.0], "p_disagrees": [0.001, 0.004]}},
              "c: u": {**_judged("undetermined", "agrees", 0.07, 1.0), "verdict_mc": MC_UNDETERMINED,
                       "adjusted_mc": {"p_agrees": [0.045, 0.09], "p_disagrees": [1.0, 1.0]}}}
    apply_monte_carlo_rule(comparisons, family)
    a, b, u = (comparisons["c"]["metrics"][k] for k in "abu")
    assert a["verdict"] == "undetermined" and "interval [0.031, 0.062] holds the level" in a["reason"]
    assert b["verdict"] == "disagrees" and b["reason"] == "bounds" and b["adjusted_mc"]["p_disagrees"] == [0.001, 0.004]
    # undetermined at the family level already: the rule changes nothing and adds no reason
    assert u["verdict"] == "undetermined" and u["reason"] == "family" and u["verdict_mc"] == MC_UNDETERMINED
    assert [ruled_verdict(r) for r in family.values()] == ["undetermined", "disagrees", "undetermined"]
    with pytest.raises(ValueError, match="differ in verdict .agrees against undetermined"):
        apply_monte_carlo_rule(comparisons, family)  # 'a' was ruled undetermined: other draws than the family's


@pytest.mark.parametrize("key,value", [("n_walks", 36), ("p_agrees_adjusted", 0.041), ("verdict_alone", "undetermined")])
def test_the_monte_carlo_rule_refuses_a_family_of_other_walks_or_draws(key, value):
    comparisons = {"c": {"metrics": {"a": {**_judged("agrees", "agrees", 0.04, 1.0), "reason": "bounds"}}}}
    member = {**_judged("agrees", "agrees", 0.04, 1.0), "verdict_mc": "agrees",
              "adjusted_mc": {"p_agrees": [0.03, 0.045], "p_disagrees": [1.0, 1.0]}, key: value}
    with pytest.raises(ValueError, match=f"differ in {key} "):
        apply_monte_carlo_rule(comparisons, {"c: a": member})
    assert "adjusted_mc" not in comparisons["c"]["metrics"]["a"]


def _checks(perfect, margin, beyond, share, changed=()):
    def rates(agrees, disagrees, own_disagrees=0.0):
        return {"own 5 %": {"agrees": 1.0, "disagrees": own_disagrees},
                "family: 5 % / 4": {"agrees": agrees, "disagrees": disagrees}}
    cal = {"comparisons": {"c": {"metrics": {"m": {
        "status": "computed", "walks_to_decide": {"walks": 120, "towards": "agrees"},
        "scenarios": {"omega2 0": rates(perfect, 0.0), "omega2 0.1": rates(0.5, 0.0),
                      # the margin's target is read at the verdict's own 5 %; the family's rate is lower
                      "omega2 0.2": rates(0.1, margin / 4, own_disagrees=margin),
                      "omega2 0.3": rates(0.0, beyond, own_disagrees=0.99)}}}}}}
    return {"monte_carlo": {"c: m": {}}, "own_calibration": cal, "stability": {"changed": list(changed)},
            "stochastic_shares": {"c": {"m": {"kim": share}}}}


@pytest.mark.parametrize("values,met", [((0.80, 0.05, 0.80, 0.40), True), ((0.79, 0.05, 0.80, 0.40), False),
                                         ((0.80, 0.06, 0.80, 0.40), False), ((0.80, 0.05, 0.79, 0.40), False),
                                         ((0.80, 0.05, 0.80, 0.41), False)])
def test_each_target_is_judged_at_its_level_at_its_bound(values, met):
    t = targets(_checks(*values))
    entry = t["per_verdict"]["c: m"]
    assert entry["perfect_agrees"]["value"] == values[0] and entry["margin_disagrees"]["value"] == values[1]
    assert entry["beyond_disagrees"]["value"] == values[2] and entry["stochastic_share"]["value"] == values[3]
    assert t["all_met"] is met and entry["walks_to_decide"] == 120
    assert TARGETS["perfect_agrees_min"] == 0.80 and TARGETS["stochastic_share_max"] == 0.40


def test_a_verdict_that_changes_with_the_bootstrap_seed_fails_its_target():
    t = targets(_checks(0.9, 0.0, 0.9, 0.1, changed=["c: m"]))
    assert t["per_verdict"]["c: m"]["stable"] == {"value": None, "met": False} and not t["all_met"]


def test_a_calibration_target_not_computed_is_not_met_and_is_counted_apart():
    from validation.live.final_checks import _not_computed, _target_cell

    checks = _checks(0.9, 0.0, 0.9, None)
    checks["monte_carlo"]["c: flat"] = {}  # a metric the own-residuals calibration could not draw
    checks["own_calibration"]["comparisons"]["c"]["metrics"]["flat"] = {"status": "not computed"}
    t = targets(checks)
    per = t["per_verdict"]
    assert per["c: flat"]["perfect_agrees"] == {"value": None, "met": False} and not t["all_met"]
    assert _not_computed(per) == 3 and _not_computed({"c: m": per["c: m"]}) == 0
    assert _target_cell(per["c: flat"]["beyond_disagrees"], False) == "not computed (not met)"
    assert _target_cell(per["c: m"]["beyond_disagrees"], False) == "90 % (met)"
    assert _target_cell(per["c: m"]["stochastic_share"], True) == "n/a"  # no stochastic method measured


def test_the_level_shift_table_reads_the_walks_complete_in_live_and_emulated_not_in_the_control():
    from validation.live.final_checks import _level_shifts
    from validation.verdicts.agreement import omega2_untruncated

    rng = np.random.default_rng(7)
    walks = [f"{s}/seed{k}" for k in range(6) for s in ("a", "b")]
    L = rng.normal(0, 1, (12, 4)) + np.arange(4)
    E = L + rng.normal(0, 0.3, (12, 4)) + 0.5
    C = L + rng.normal(0, 0.3, (12, 4))
    C[0, 1], E[3, 2] = np.nan, np.nan  # one walk without a value in the control, one in emulated
    tables = {"live-fixed-instant": {"median_matches": L}, "emulated-plain": {"median_matches": E},
              "live-fixed-instant-reseeded": {"median_matches": C}}
    e = _level_shifts(tables, walks, ["median_matches"], 0, 200, 0.1)["emulated vs cycle-rate live"]["median_matches"]
    keep = np.arange(12) != 3  # walk 0 stays: its control gap does not drop it here
    assert e["omega2_untruncated"] == pytest.approx(float(omega2_untruncated(L[keep], E[keep])), abs=1e-12)
    all3 = keep & (np.arange(12) != 0)  # the headline's walks: complete in the control too
    assert e["omega2_untruncated"] != pytest.approx(float(omega2_untruncated(L[all3], E[all3])))
    assert sum(v["n_walks"] for v in e["per_scene"].values()) == 11


def test_the_checks_render_every_headline_verdict_with_its_targets(tmp_path):
    import validation.live.experiment as experiment

    out = _study(tmp_path, 10)
    res = experiment.stop_study(out, "budget", command="test", calibration_studies=0, when=WHEN)
    text = checks_markdown(res["final_checks"])
    first = text.split("### Level shifts")[0]
    rows = [ln for ln in first.splitlines() if ln.startswith("| emulated vs cycle-rate live: ")]
    assert len(rows) == res["final_checks"]["family_size"] == 4
    # no own calibration asked for: no target is computed, and none is met
    assert all(r.count("not computed (not met)") == 3 for r in rows)
    assert LEVEL_SHIFT_WALKS in text.split("### Level shifts")[1]
    assert "Every target met: no (12 calibration target(s) not computed, each counted as not met" in text and np.isfinite(res["final_checks"]["level_shifts"][
        "emulated vs cycle-rate live"]["median_matches"]["shift"]["relative"])


def test_the_command_line_stops_a_study_once_and_not_with_redraw_or_resume(tmp_path, capsys):
    from validation.live.cli import main

    out = _study(tmp_path, 10, command="exposim validate live -o {out} --cycles 8 --replicates 12")
    assert main(["-o", str(out), "--stop", "budget", "--redraw"]) == 1
    assert "--stop draws a stopped study's verdicts itself" in capsys.readouterr().err and not (out / STOP_FILE).exists()
    assert main(["-o", str(out), "--stop", "the budget: 24 h of two cores", "--calibration-studies", "0", "-q"]) == 0
    # results.json keeps the command that ran the walks (it reproduces the study); stop.json the stop's own
    res = json.loads((out / "results.json").read_text())
    assert res["command"] == "exposim validate live -o . --cycles 8 --replicates 12"
    stop = json.loads((out / STOP_FILE).read_text())
    assert stop["reason"] == "the budget: 24 h of two cores"
    assert stop["command"] == ("python -m validation.live -o . --stop 'the budget: 24 h of two cores' "
                               "--calibration-studies 0") and stop["calibration_studies"] == 0
    assert main(["-o", str(out), "--stop", "again"]) == 1 and "already stopped" in capsys.readouterr().err


def _files(out):
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


def test_a_stop_checks_everything_before_it_writes_and_a_redraw_mends_one_cut_short(tmp_path, monkeypatch):
    import validation.live.experiment as experiment

    recs = _records(12, 8)
    assembled, finished = [], []

    def assemble(exp, cfg, failed, command=None):
        assembled.append((exp.name, cfg.seed, failed))
        return recs[cfg.seed]

    monkeypatch.setattr(experiment, "assemble_raw", assemble)
    monkeypatch.setattr(experiment, "finish", lambda exp, raw: finished.append(exp.name))
    # a stale, larger walks.csv (an earlier look with another seed's walks): refused before anything is written,
    # the raw.json of a seed assembled for the stop included
    out = _study(tmp_path / "a", 10)
    ref = _study(tmp_path / "r", 10)
    experiment.stop_study(ref, "budget", calibration_studies=0, when=WHEN)
    (out / "walks.csv").write_bytes((ref / "walks.csv").read_bytes() + b"lake/seed99,lake,99,fixed,live,1\n")
    (out / "replicates" / "seed2" / "raw.json").unlink()
    before = _files(out)
    with pytest.raises(LiveError, match="walks.csv: differs from the walks recomputed.*nothing was written"):
        experiment.stop_study(out, "budget", calibration_studies=0, when=WHEN)
    assert _files(out) == before and not (out / STOP_FILE).exists() and assembled == [("seed2", 2, {})]
    assert finished == []
    # a seed's raw.json from a run with a failed walk, or without a scene, is not reused: the seed is assembled
    # from its walk records and finished; a whole one with its results is kept as it is
    out = _study(tmp_path / "b", 10)
    stale = {**recs[3], "failed_walks": [{"walk": f"{SCENES[1]}/seed3", "error": "killed"}]}
    (out / "replicates" / "seed3" / "raw.json").write_text(json.dumps(stale))
    short = {**recs[4], "per_scene": {s: {} for s in SCENES[:3]}}
    (out / "replicates" / "seed4" / "raw.json").write_text(json.dumps(short))
    assembled.clear()
    res = experiment.stop_study(out, "budget", calibration_studies=0, when=WHEN)
    assert assembled == [("seed3", 3, {}), ("seed4", 4, {})] and finished == ["seed3", "seed4"]
    assert json.loads((out / "replicates" / "seed3" / "raw.json").read_text()) == recs[3]
    assert (out / "results.json").read_bytes() == (ref / "results.json").read_bytes()
    assert res["metrics"] == json.loads((ref / "results.json").read_text())["metrics"]
    # cut short after stop.json: seed7's results fail after its raw.json is written, seed8 is never reached; a
    # plain --redraw finishes seed7, assembles seed8 and draws the look with the stop's walks command and count of
    # calibration studies (stop.json keeps it), to the same bytes as a stop that was not cut short
    cmd = "exposim validate live -o {out} --cycles 8 --replicates 12"
    ref = _study(tmp_path / "rc", 10, command=cmd)
    experiment.stop_study(ref, "budget", calibration_studies=0, when=WHEN)
    out = _study(tmp_path / "c", 10, command=cmd)
    for k in (7, 8):
        for name in ("raw.json", "results.json"):
            (out / "replicates" / f"seed{k}" / name).unlink()

    def crash(exp, raw):
        raise RuntimeError("disk full")

    monkeypatch.setattr(experiment, "finish", crash)
    with pytest.raises(RuntimeError, match="disk full"):
        experiment.stop_study(out, "budget", calibration_studies=0, when=WHEN)
    assert (out / STOP_FILE).read_bytes() == (ref / STOP_FILE).read_bytes() and not (out / "results.json").exists()
    assert (out / "replicates" / "seed7" / "raw.json").is_file()
    assert not (out / "replicates" / "seed8" / "raw.json").exists()
    finished.clear()
    assembled.clear()
    monkeypatch.setattr(experiment, "finish", lambda exp, raw: finished.append(exp.name))
    experiment.redraw(out)
    assert finished == ["seed7", "seed8"] and assembled == [("seed8", 8, {})]
    for name in ("results.json", "walks.csv", "report.md", "power.json", "calibration.json"):
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name
    assert json.loads((out / "results.json").read_text())["command"] == cmd.format(out=".")


def test_a_stopped_study_binds_every_later_look_to_its_seeds(tmp_path):
    import validation.live.experiment as experiment

    out = _study(tmp_path, 10)
    plan = json.loads((out / PREREG_FILE).read_text())
    rec = stop_record(out, "budget", when=WHEN)
    # the planned size, or the stopped size on other seeds, is not the stopped study's look
    with pytest.raises(LiveError, match="stopped at 40 walks, but 48 are judged"):
        interim_reason(plan, 48, rec)
    with pytest.raises(LiveError, match=r"stopped with seeds \[0, 1, .*9\] judged, but the walks judged are of "
                                        r"seeds \[0, 1, .*8, 10\]"):
        interim_reason(plan, 40, rec, seeds=[*range(9), 10])
    assert interim_reason(plan, 40, rec, seeds=[k for k in range(10) for _ in SCENES]) is None
    experiment.stop_study(out, "budget", calibration_studies=0, when=WHEN)
    recs = _records(12, 8)
    with pytest.raises(LiveError, match=r"stopped with seeds .* judged; the records given are of seeds"):
        experiment.finish_replicated(out, recs[:9] + recs[10:11], calibration_studies=0)
    # every planned seed finished: judged at its planned size, never stopped
    # a stopped folder without study.json redraws the stop's seeds only, not a seed begun after the stop
    before = (out / "results.json").read_bytes()
    (out / "replicates" / "seed10" / "raw.json").write_text(json.dumps(recs[10]))
    (out / "study.json").unlink()
    experiment.redraw(out)
    assert (out / "results.json").read_bytes() == before
    full = _study(tmp_path / "full", 12)
    with pytest.raises(LiveError, match="every one of the 48 pre-registered walks is finished"):
        experiment.stop_study(full, "budget", when=WHEN)
    assert not (full / STOP_FILE).exists()


def test_a_copied_stopped_study_needs_its_plan_and_stop_and_redraws_with_its_calibration(tmp_path):
    import validation.live.experiment as experiment

    out = _study(tmp_path, 10)
    res = experiment.stop_study(out, "budget", calibration_studies=0, when=WHEN)
    assert res["study_folder"]["missing_files"] == []
    cal = json.loads((out / "calibration.json").read_text())
    assert cal["status"] == "not computed" and cal["n_studies"] == 0
    before = _files(out)
    experiment.redraw(out)  # the folder's own count of studies (0), not the default
    assert _files(out) == before
    for missing in (STOP_FILE, PREREG_FILE):
        table = tmp_path / f"without-{missing}"
        table.mkdir()
        for name in ("results.json", "walks.csv", PREREG_FILE, STOP_FILE, "study.json"):
            if name != missing:
                shutil.copy(out / name, table / name)
        copied = _files(table)
        with pytest.raises(LiveError, match=f"{missing}: not found, but .*results.json was judged by it"):
            experiment.redraw(table)
        assert _files(table) == copied


def test_a_stopped_study_with_the_own_calibration_on_judges_its_targets(tmp_path):
    import validation.live.experiment as experiment

    out = _study(tmp_path, 10)
    res = experiment.stop_study(out, "budget", calibration_studies=3, when=WHEN)
    checks = res["final_checks"]
    own = checks["own_calibration"]
    assert own["n_studies"] == 6 and own["family_size"] == 4  # twice the plasmode's drawn studies
    per = own["comparisons"]["emulated vs cycle-rate live"]["metrics"]["median_matches"]
    assert per["status"] == "computed" and per["n_resamples"] == 4000 and per["seeds_drawn_from"] == 10
    t = checks["targets"]["per_verdict"]["emulated vs cycle-rate live: median_matches"]
    fam = next(k for k in per["scenarios"]["omega2 0"] if k.startswith("family"))
    assert t["perfect_agrees"]["value"] == per["scenarios"]["omega2 0"][fam]["agrees"]
    assert t["beyond_disagrees"]["value"] == per["scenarios"]["omega2 0.3"][fam]["disagrees"]
    assert t["margin_disagrees"]["value"] == per["scenarios"]["omega2 0.2"]["own 5 %"]["disagrees"]
    for entry in (t["perfect_agrees"], t["beyond_disagrees"], t["margin_disagrees"]):  # rates of 6 drawn studies
        assert entry["value"] in {k / 6 for k in range(7)}
    share = checks["stochastic_shares"]["emulated vs cycle-rate live"]["median_matches"]["kim"]
    assert t["stochastic_share"] == {"value": share, "met": share <= 0.40} and 0.0 < share < 1.0
    before = _files(out)
    experiment.redraw(out)
    assert _files(out) == before
