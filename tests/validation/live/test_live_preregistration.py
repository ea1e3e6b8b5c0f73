"""validation.live.preregistration: a study's plan fixed before its first walk, checked on resume, decided at N only."""

import json
from dataclasses import replace

import numpy as np
import pytest

from validation.live.config import CONDITIONS, METHODS, SCENES, LiveConfig, LiveError
from validation.live.preregistration import (
    PREREG_FILE,
    check_preregistration,
    headline_exclusions,
    interim_reason,
    preregistration,
    segments_per_walk,
    write_preregistration,
)
from validation.verdicts.simulate import Scales, simulate_tables


def test_the_segment_success_leaves_the_headline_when_a_walk_has_fewer_than_three_segments():
    short = LiveConfig(n_cycles=8)  # the committed studies: 7 pairs, one segment of 10
    assert segments_per_walk(short) == 1 and "1 segment(s) of 10 pairs" in headline_exclusions(short)[
        "segment_success_rate_tau100"]
    long = LiveConfig(n_cycles=31)  # 30 pairs: three segments
    assert segments_per_walk(long) == 3 and headline_exclusions(long) == {}
    plan = preregistration(short, 12)
    assert plan["n_walks"] == 48 and plan["seeds"] == list(range(12)) and plan["format"] == 3
    assert "segment_success_rate_tau100" not in plan["metrics"] and plan["omega2_margin"] == 0.2
    assert plan["render"]["n_cycles"] == 8 and plan["bootstrap_resamples"] == 4000


def test_a_registered_plan_is_never_changed(tmp_path):
    plan = preregistration(LiveConfig(n_cycles=31), 10, draws=3)
    write_preregistration(tmp_path, plan)
    write_preregistration(tmp_path, plan)  # the same plan again: accepted
    with pytest.raises(LiveError, match="with other draws_per_stochastic_method, looks, n_walks, seeds;"):
        check_preregistration(tmp_path, preregistration(LiveConfig(n_cycles=31), 11, draws=1))
    assert json.loads((tmp_path / PREREG_FILE).read_text())["draws_per_stochastic_method"] == 3
    check_preregistration(tmp_path / "elsewhere", plan)  # no plan registered there: nothing to check
    assert interim_reason(plan, 40) is None and "interim look at 39 of the 40" in interim_reason(plan, 39)
    assert interim_reason(None, 3) is None


def _records(n_seeds: int, n_cycles: int) -> list[dict]:
    sim = simulate_tables("live-draw", 4 * n_seeds, Scales(sd_method=1.0, sd_walk_method=0.2, sd_noise=0.2), seed=2)
    tables = {CONDITIONS["cycle-rate live"]: sim["live"][0], CONDITIONS["emulated"]: sim["emulated"][0]}
    cfg = LiveConfig(scenes=tuple(SCENES), n_cycles=n_cycles).to_dict()
    keys = ("median_uniformity", "median_matches")
    return [{"config": {**cfg, "seed": k}, "timings": {"total_s": 1.0}, "per_scene": {s: {} for s in SCENES},
             "summaries": {
        run: {"per_scene": {s: {m: {**{key: float(v) for key in keys}, "segment_success": {"100": {"rate": float(v)}}}
                                for m, v in zip(METHODS, t[k * len(SCENES) + i])} for i, s in enumerate(SCENES)}}
        for run, t in tables.items()}} for k in range(n_seeds)]


def test_a_study_writes_its_plan_first_and_decides_at_n_only(tmp_path, monkeypatch):
    import validation.live.experiment as experiment

    cfg = replace(LiveConfig(scenes=tuple(SCENES), n_cycles=8), seed=0)
    recs = _records(12, 8)
    monkeypatch.setattr(experiment, "run_study", lambda exps, **kw: recs[:len(exps)])
    res = experiment.run_replicated(tmp_path / "s", cfg, 12, command="test", calibration_studies=0)
    plan = json.loads((tmp_path / "s" / PREREG_FILE).read_text())
    assert plan["n_walks"] == 48 and res["preregistration"]["look"] == "final"
    fam = res["headlines"]["family"]
    assert fam["size"] == 4 and "segment_success_rate_tau100" in fam["excluded"]  # one comparison, 4 metrics
    seg = res["comparisons"]["emulated vs cycle-rate live"]["metrics"]["segment_success_rate_tau100"]
    assert seg["family"].startswith("outside the headline family: 1 segment(s)")
    assert res["metrics"]["median_matches"]["verdict"] == "agrees"
    assert "| segment_success_rate_tau100 (outside the family) |" in (tmp_path / "s" / "report.md").read_text()
    from validation.live.headline import headline_lines

    assert "segment_success" not in headline_lines(res)[1] and "median_matches agrees" in headline_lines(res)[1]
    # a resume must not change the plan
    (tmp_path / "s" / PREREG_FILE).write_text(json.dumps({**plan, "bootstrap_resamples": 1000}))
    with pytest.raises(LiveError, match="pre-registered with other bootstrap_resamples"):
        experiment.run_replicated(tmp_path / "s", cfg, 12, command="test", calibration_studies=0, resume=True)
    # an interim look (40 of 48 walks): futility only, nothing agrees or disagrees
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / PREREG_FILE).write_text(json.dumps(plan))
    early = experiment.finish_replicated(tmp_path / "t", recs[:10], command="test", calibration_studies=0)
    assert early["preregistration"]["look"] == "interim: futility only" and early["n_walks"] == 40
    verdicts = {r["verdict"] for c in early["comparisons"].values() for r in (c.get("metrics") or {}).values()}
    assert verdicts == {"undetermined"}
    assert early["metrics"]["median_matches"]["reason"].startswith("interim look at 40 of the 48 pre-registered")


def test_a_study_without_a_plan_is_judged_as_before(tmp_path):
    from validation.live.experiment import finish_replicated

    res = finish_replicated(tmp_path, _records(10, 8), command="test", power_seeds=0, calibration_studies=0)
    assert "preregistration" not in res and "excluded" not in res["headlines"]["family"]
    assert res["headlines"]["distinct_metrics"][2] == "segment_success_rate_tau100"
    assert np.isfinite(res["metrics"]["median_matches"]["omega2"])


def test_the_folder_analyses_refuse_a_preregistered_study(tmp_path):
    """monte_carlo, level_shift, own_residuals and study_calibration read a folder through read_folder_table; they
    judge the family as the studies before pre-registration did, so a pre-registered folder is refused in words."""
    from validation.live.config import LiveError
    from validation.live.preregistration import PREREG_FILE
    from validation.live.table_check import read_folder_table

    (tmp_path / PREREG_FILE).write_text("{}")
    with pytest.raises(LiveError, match="pre-registered study") as err:
        read_folder_table(tmp_path)
    assert str(tmp_path) in str(err.value)
